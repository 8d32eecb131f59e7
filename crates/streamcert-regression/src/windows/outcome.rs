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
    /// `T` (`d × p`, row-major): the rate's matrix is `sym(Θ̂ T)` (for the closed loop
    /// `T = [I; K]`, with a zero row for the affine model's intercept).
    pub t: &'a [f64],
    /// The smallest accepted pivot ratio of `A` equilibrated to a unit diagonal: at or below
    /// it the window is singular to working precision and not ready.
    pub min_pivot_ratio: f64,
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
}
