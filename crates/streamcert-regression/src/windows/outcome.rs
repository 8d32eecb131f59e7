//! [`WindowEstimate`]: what a look at one window of [`InstrumentedWindows`](super::InstrumentedWindows) gives, in
//! buffers its caller owns and reuses.

use serde::{Deserialize, Serialize};

use super::Layout;
// The type whose looks these are, for the links of the docs.
#[cfg(doc)]
use super::InstrumentedWindows;

/// How a window is solved and what its rate is read through: the settings every estimate of
/// [`InstrumentedWindows`] takes (`Copy`; the calibrated certificate holds one per state).
#[derive(Debug, Clone, Copy)]
pub struct Solve<'a> {
    /// The ridge `λ`, relative to each diagonal entry: the first stage solves
    /// `H + λ diag H`, so the estimate is the same in any units of the regressors.
    pub ridge: f64,
    /// What the rate is read through, and so which covariance the estimate carries.
    pub rate: RateMap<'a>,
    /// The smallest accepted pivot ratio of `A` equilibrated to a unit diagonal: at or below
    /// it the window is singular to working precision and not ready.
    pub min_pivot_ratio: f64,
}

/// What a window's rate is read through ([`Solve::rate`]): it decides which covariance an
/// estimate carries in [`WindowEstimate::score_cov`].
#[derive(Debug, Clone, Copy)]
#[non_exhaustive]
pub enum RateMap<'a> {
    /// The first-order rate (paper eq. beta), `−λ_max(sym(Θ̂ T))`, with `T` (`d × p`,
    /// row-major; for the closed loop `T = [I; K]`, with a zero row for the affine model's
    /// intercept). The estimate carries the long-run covariance of the direction of the
    /// symmetric part, `vec(sym((Θ̂ − Θ) T))`, `p² × p²`, not the coefficients' own.
    SymmetricPart(&'a [f64]),
}

impl<'a> RateMap<'a> {
    /// `T` of [`RateMap::SymmetricPart`].
    #[must_use]
    #[inline(always)]
    pub fn symmetric_part(self) -> &'a [f64] {
        match self {
            Self::SymmetricPart(t) => t,
        }
    }
}

/// The outcome of [`InstrumentedWindows::estimate`](super::InstrumentedWindows::estimate) for one window, in buffers the caller owns
/// (make one with [`WindowEstimate::new`] and reuse it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WindowEstimate {
    /// `true` when the fields below hold an estimate of this call.
    pub ready: bool,
    /// Instrumented columns in the window.
    pub columns: usize,
    /// `Θ̂`, `p × d` row-major (see [`InstrumentedWindows::estimate`]).
    pub theta: Vec<f64>,
    /// Long-run covariance of the score, `p² × p²` row-major: for a unit `v`, the variance of
    /// `vᵀ(Θ̂ − Θ)T v` is estimated by `vec(vvᵀ)ᵀ Ω̂ vec(vvᵀ) <= λ_max(Ω̂)`.
    pub score_cov: Vec<f64>,
    /// Pivot ratio of the LU factorisation of `A = N Q + λ diag(N Q)` equilibrated to a
    /// unit diagonal (instrument strength, in no unit).
    pub pivot_ratio: f64,
    /// Effective number of blocks `(Σ_j w_j)² / Σ_j w_j²`, `w_j = Σ_{q in block j} ‖g_q‖²`:
    /// the Welch–Satterthwaite degrees of freedom of `Ω̂` when the blocks carry unequal weight
    /// (at most `B`, equal to `B` for equal weights).
    pub effective_blocks: f64,
    /// Batches behind `score_cov`: `⌈B/b⌉` for `B` blocks in batches of `b`
    /// ([`InstrumentedWindows::with_batch`]; `B` when `b = 1`).
    #[serde(default)]
    pub batches: usize,
    // Scratch: Cholesky factor of H + λ diag H (then the equilibrated A's LU factor, for the pivot
    // ratio), Q = (H + λ diag H)⁻¹ Nᵀ (k × d, stored as d rows of k),
    // the LU factor of A and its pivots, X (p rows of k), one block's score sum.
    pub(super) hfac: Vec<f64>,
    pub(super) q: Vec<f64>,
    pub(super) lu: Vec<f64>,
    pub(super) piv: Vec<usize>,
    pub(super) x: Vec<f64>,
    pub(super) row: Vec<f64>,
    pub(super) block: Vec<f64>,
    pub(super) sums: Vec<f64>,
    // One block's coefficient influence (p × d), and `Q A⁻¹` (k rows of d), for
    // `coefficient_covariance`.
    #[serde(default)]
    pub(super) g: Vec<f64>,
    #[serde(default)]
    pub(super) qa: Vec<f64>,
    /// The smallest pivot ratio over the window's blocks of `I − L_j`, `L_j = A⁻¹ Qᵀ N_jᵀ`
    /// (block `j`'s leverage on the coefficients): 1 when no block has leverage, 0 when one
    /// block alone identifies a direction of `Θ` (deleting it leaves the fit singular).
    #[serde(default)]
    pub leverage_pivot: f64,
    // Scratch: the LU factor of `I − L_j` and its pivots, one block's influence rows (p × d).
    #[serde(default)]
    pub(super) jack: Vec<f64>,
    #[serde(default)]
    pub(super) jack_piv: Vec<usize>,
    #[serde(default)]
    pub(super) gj: Vec<f64>,
    /// Read the candidate directions `T` in standardised coefficients (default `false`): row
    /// `a` of `T` multiplied by `√A_aa`, the scale of regressor `a`'s instrumented column, so
    /// that `X = Q A⁻¹ diag(√A) T` weighs the blocks the same in any units of the regressors.
    /// For a direction that is not a rate (the model guards' tested coefficients, ones on
    /// regressors of different units); a rate direction `[I; K]` is already in the
    /// regressors' units.
    #[serde(default)]
    pub standardised: bool,
    // Scratch: `√A_aa` of the latest solve (d values).
    #[serde(default)]
    pub(super) diag: Vec<f64>,
    /// The covariance in batches of [`InstrumentedWindows::estimate_batched`] (not
    /// serialised: rewritten by every such call).
    #[serde(skip)]
    pub batched: BatchedCovariance,
}

/// The second covariance of [`InstrumentedWindows::estimate_batched`]: the same blocks'
/// delete-one-block changes in batches of `b` blocks (see
/// [`InstrumentedWindows::with_batch`]), beside the estimate's own in batches of one.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BatchedCovariance {
    /// `true` when the fields below hold a covariance of this call (more than `d` batches,
    /// every value finite, no block of leverage 1).
    pub ready: bool,
    /// `p² × p²`, as [`WindowEstimate::score_cov`].
    pub score_cov: Vec<f64>,
    /// The effective number of batches (as [`WindowEstimate::effective_blocks`]).
    pub effective_blocks: f64,
    /// The number of batches `⌈B/b⌉`.
    pub batches: usize,
}

impl WindowEstimate {
    /// Buffers for `p` outputs, `m` inputs and `intervals` instrument intervals.
    #[must_use]
    pub fn new(p: usize, m: usize, intervals: usize) -> Self {
        let d = p + m;
        let k = intervals * d;
        Self {
            ready: false,
            columns: 0,
            theta: vec![0.0; p * d],
            score_cov: vec![0.0; p * p * p * p],
            pivot_ratio: 0.0,
            effective_blocks: 0.0,
            batches: 0,
            hfac: vec![0.0; k * k],
            q: vec![0.0; d * k],
            lu: vec![0.0; d * d],
            piv: vec![0; d],
            x: vec![0.0; p * k],
            row: vec![0.0; k.max(d)],
            block: vec![0.0; p * p],
            sums: vec![0.0; Layout { p, d, k }.stride()],
            g: vec![0.0; p * d],
            qa: vec![0.0; k * d],
            leverage_pivot: 0.0,
            jack: vec![0.0; d * d],
            jack_piv: vec![0; d],
            gj: vec![0.0; p * d],
            standardised: false,
            diag: vec![0.0; d],
            batched: BatchedCovariance {
                score_cov: vec![0.0; p * p * p * p],
                ..BatchedCovariance::default()
            },
        }
    }

    /// [`new`](Self::new) for windows built with
    /// [`InstrumentedWindows::with_regressors`](super::InstrumentedWindows::with_regressors): `regressors` regressors per column.
    #[must_use]
    pub fn with_regressors(outputs: usize, regressors: usize, intervals: usize) -> Self {
        Self::new(outputs, regressors.saturating_sub(outputs), intervals)
    }

    /// This estimate with [`standardised`](Self::standardised) directions.
    #[must_use]
    pub fn standardised(mut self) -> Self {
        self.standardised = true;
        self
    }

    /// `true` when every buffer has the length of `other`'s (a restored state's check).
    #[must_use]
    pub fn matches(&self, other: &Self) -> bool {
        self.theta.len() == other.theta.len()
            && self.score_cov.len() == other.score_cov.len()
            && self.hfac.len() == other.hfac.len()
            && self.q.len() == other.q.len()
            && self.lu.len() == other.lu.len()
            && self.piv.len() == other.piv.len()
            && self.x.len() == other.x.len()
            && self.row.len() == other.row.len()
            && self.block.len() == other.block.len()
            && self.sums.len() == other.sums.len()
            && self.g.len() == other.g.len()
            && self.qa.len() == other.qa.len()
            && self.jack.len() == other.jack.len()
            && self.jack_piv.len() == other.jack_piv.len()
            && self.gj.len() == other.gj.len()
            && self.diag.len() == other.diag.len()
    }

    /// The share of regressor `target`'s variation that the regressors `by` do not explain,
    /// in the window of the latest estimate (read after a call on more than `d` batches, a
    /// refused one too: its sums are formed before the solve). With `N = Σ_q z_q w_qᵀ` the
    /// regressors' cross moments with the instruments (`d × k`) and `G = N Nᵀ`,
    ///
    /// ```text
    /// share = (G_tt − g_btᵀ G_bb⁺ g_bt) / G_tt   ∈ [0, 1]
    /// ```
    ///
    /// (`1 − R²` of row `t` of `N` on the rows `by`, a row that the earlier ones of `by`
    /// already span is left out), in no unit: a regressor in other units scales its row.
    /// `0` when `target` is a fixed linear combination of `by` over the window: an input
    /// held at its level is one of the intercept (`by` the intercept's row), an input
    /// `u = K y` with nothing added is one of the outputs' and the intercept's. `None` when
    /// an index is out of range, `target` is among `by`, `by` holds more than 15 rows, or
    /// `G_tt` is not positive and finite. `O(|by|² k)`, no allocation.
    #[must_use]
    pub fn unexplained_share(&self, target: usize, by: &[usize]) -> Option<f64> {
        const MAX: usize = 15;
        let k = self.hfac.len().isqrt();
        let d = self.lu.len().isqrt();
        if target >= d || by.len() > MAX || by.iter().any(|&b| b >= d || b == target) {
            return None;
        }
        let n = self.sums.get(..d * k)?;
        let dot = |i: usize, j: usize| -> f64 {
            n[i * k..(i + 1) * k].iter().zip(&n[j * k..(j + 1) * k]).map(|(a, b)| a * b).sum()
        };
        let gtt = dot(target, target);
        if !(gtt > 0.0 && gtt.is_finite()) {
            return None;
        }
        // Cholesky of G_bb row by row (a row whose remaining pivot is at most 1e-12 of its
        // diagonal lies in the span of the earlier ones and is left out), and c = L⁻¹ g_bt:
        // the explained part is ‖c‖².
        let mut l = [[0.0f64; MAX]; MAX];
        let mut c = [0.0f64; MAX];
        let mut kept = [false; MAX];
        let mut explained = 0.0;
        for i in 0..by.len() {
            let gii = dot(by[i], by[i]);
            let mut pivot = gii;
            for j in (0..i).filter(|&j| kept[j]) {
                let earlier: f64 = (0..j).filter(|&q| kept[q]).map(|q| l[i][q] * l[j][q]).sum();
                l[i][j] = (dot(by[i], by[j]) - earlier) / l[j][j];
                pivot -= l[i][j] * l[i][j];
            }
            if !(pivot > 1e-12 * gii) {
                continue;
            }
            kept[i] = true;
            l[i][i] = pivot.sqrt();
            let earlier: f64 = (0..i).filter(|&j| kept[j]).map(|j| l[i][j] * c[j]).sum();
            c[i] = (dot(by[i], target) - earlier) / l[i][i];
            explained += c[i] * c[i];
        }
        let share = (gtt - explained) / gtt;
        share.is_finite().then(|| share.clamp(0.0, 1.0))
    }
}

#[cfg(test)]
mod tests {
    use super::WindowEstimate;
    use nalgebra::{DMatrix, DVector};
    use proptest::prelude::*;

    /// An estimate of `p = 1`, `m = 3` (`d = 4`), two instrument intervals (`k = 8`) whose
    /// `N` is `n` (row-major, `d × k`).
    fn with_n(n: &[f64]) -> WindowEstimate {
        let mut est = WindowEstimate::new(1, 3, 2);
        est.sums[..n.len()].copy_from_slice(n);
        est
    }

    /// The oracle: `1 − g_btᵀ G_bb⁻¹ g_bt / G_tt` from a dense solve.
    fn dense_share(n: &[f64], t: usize, by: &[usize]) -> f64 {
        let k = 8;
        let row = |i: usize| DVector::from_column_slice(&n[i * k..(i + 1) * k]);
        let gtt = row(t).dot(&row(t));
        if by.is_empty() {
            return 1.0;
        }
        let gbb = DMatrix::from_fn(by.len(), by.len(), |a, b| row(by[a]).dot(&row(by[b])));
        let gbt = DVector::from_fn(by.len(), |a, _| row(by[a]).dot(&row(t)));
        let x = gbb.lu().solve(&gbt).expect("independent rows");
        1.0 - gbt.dot(&x) / gtt
    }

    proptest! {
        /// The share agrees with a dense solve on independent rows, and is 0 for a row that
        /// is a combination of the others, also when `by` holds a row twice over.
        #[test]
        fn the_share_is_one_minus_r_squared(
            n in prop::collection::vec(-3.0f64..3.0, 32),
            a in 0.5f64..2.0,
            b in -2.0f64..2.0,
        ) {
            let est = with_n(&n);
            for (t, by) in [(0, &[1, 2][..]), (3, &[0, 1, 2][..]), (2, &[3][..]), (1, &[][..])] {
                let got = est.unexplained_share(t, by).expect("a share");
                let want = dense_share(&n, t, by);
                prop_assert!((got - want).abs() <= 1e-9, "{} {}", got, want);
            }
            // Row 3 = a · row 0 + b · row 1; `by` with row 2 a copy of row 0.
            let mut dep = n.clone();
            for j in 0..8 {
                dep[16 + j] = dep[j];
                dep[24 + j] = a * dep[j] + b * dep[8 + j];
            }
            let est = with_n(&dep);
            let share = est.unexplained_share(3, &[0, 2, 1]).expect("a share");
            prop_assert!(share <= 1e-12, "{}", share);
            prop_assert!(est.unexplained_share(3, &[3]).is_none());
            prop_assert!(est.unexplained_share(4, &[0]).is_none());
        }
    }
}
