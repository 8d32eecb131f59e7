//! Solving one window of [`InstrumentedWindows`] at a look: two-stage least squares from the
//! window's block sums, and the batch-means covariance of the scores with its effective
//! number of blocks.

use serde::{Deserialize, Serialize};

use super::batch::{Batches, overlap_factor};
use super::{InstrumentedWindows, Layout};
use crate::linalg;

/// The outcome of [`InstrumentedWindows::estimate`] for one window, in buffers the caller owns
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
    /// Pivot ratio of the LU factorisation of `A = N H⁻¹ Nᵀ + λI` equilibrated to a unit
    /// diagonal (instrument strength, in no unit).
    pub pivot_ratio: f64,
    /// Effective number of blocks `(Σ_j w_j)² / Σ_j w_j²`, `w_j = Σ_{q in block j} ‖g_q‖²`:
    /// the Welch–Satterthwaite degrees of freedom of `Ω̂` when the blocks carry unequal weight
    /// (at most `B`, equal to `B` for equal weights).
    pub effective_blocks: f64,
    /// Batches behind `score_cov`: `⌈B/b⌉` for `B` blocks in batches of `b`
    /// ([`InstrumentedWindows::with_batch`]; `B` when `b = 1`).
    #[serde(default)]
    pub batches: usize,
    // Scratch: Cholesky factor of H + λI (then the equilibrated A's LU factor, for the pivot
    // ratio), Q = (H + λI)⁻¹ Nᵀ (k × d, stored as d rows of k),
    // the LU factor of A and its pivots, X (p rows of k), one block's score sum.
    hfac: Vec<f64>,
    pub(super) q: Vec<f64>,
    pub(super) lu: Vec<f64>,
    pub(super) piv: Vec<usize>,
    pub(super) x: Vec<f64>,
    row: Vec<f64>,
    block: Vec<f64>,
    pub(super) sums: Vec<f64>,
    // One block's coefficient influence (p × d), and `Q A⁻¹` (k rows of d), for
    // `coefficient_covariance`.
    #[serde(default)]
    pub(super) g: Vec<f64>,
    #[serde(default)]
    pub(super) qa: Vec<f64>,
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
        }
    }

    /// [`new`](Self::new) for windows built with
    /// [`InstrumentedWindows::with_regressors`]: `regressors` regressors per column.
    #[must_use]
    pub fn with_regressors(outputs: usize, regressors: usize, intervals: usize) -> Self {
        Self::new(outputs, regressors.saturating_sub(outputs), intervals)
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
    }
}

/// A block's weight `w_j = tr(Xᵀ H_j X)` (`bh` the block's `H_j`, `k × k`; `x` the `p` rows of
/// `k` of `X`), summed in one fixed order (so that every pass gets the same bits).
#[inline(always)]
pub(super) fn block_weight(bh: &[f64], x: &[f64], k: usize) -> f64 {
    let mut weight = 0.0;
    for xj in x.chunks_exact(k) {
        for a in 0..k {
            let mut ha = 0.0;
            for b in 0..k {
                ha += bh[a * k + b] * xj[b];
            }
            weight += xj[a] * ha;
        }
    }
    weight
}

/// `Q A⁻¹ v` (`k` values, handed to `put(b, value)`), with `A` given by its LU factors and `Q`
/// as `d` rows of `k`; `v` (`d` values) is overwritten by `A⁻¹ v`.
#[inline(always)]
pub(super) fn q_ainv(
    lu: &[f64],
    piv: &[usize],
    q: &[f64],
    d: usize,
    k: usize,
    v: &mut [f64],
    mut put: impl FnMut(usize, f64),
) {
    linalg::lu_solve_in_place(lu, d, piv, v);
    for b in 0..k {
        let mut acc = 0.0;
        for a in 0..d {
            acc += q[a * k + b] * v[a];
        }
        put(b, acc);
    }
}

impl InstrumentedWindows {
    /// Solve window `w` with ridge `λ` for the candidate directions `t` (`d × p` row-major,
    /// `T = [I_p; K]`) into `out` (built with this structure's `p`, `m`, `J`):
    ///
    /// ```text
    /// Q = (H + λI)⁻¹ Nᵀ,   A = N Q + λI,   Θ̂ = Cw Q A⁻¹         (two-stage least squares)
    /// X = Q A⁻¹ T,   R_q = ΔY_q − Θ̂ Z_q,   g_q = Xᵀ W_q
    /// u_q = vec(sym(R_q g_qᵀ))        (p² values; Σ_q over the errors is vec(sym ΔJ_cl))
    /// S_j = Σ_{q in block j} u_q      (the window's B blocks of h columns)
    /// Ω̂  = c_h · B/(B − d) · Σ_j S_j S_jᵀ,   c_h = 3h² / (2h² + 1)
    /// ```
    ///
    /// With `J = 1` this is the instrumental-variables estimator `Θ̂ = Cw N⁻¹` (up to the
    /// ridge). Batch means: a block sum is a sum of `h` consecutive scores, so `Ω̂` is positive
    /// semi-definite by construction and the blocks are nearly independent. Neighbouring
    /// blocks still share the overlap of their columns: for white process noise the column
    /// errors have the triangular autocorrelation `1 − |l|/h`, a block's variance is then
    /// `h² − (h² − 1)/3` and the long-run variance per block `h²` (in units of one column's),
    /// hence `c_h`. White sensor noise makes neighbouring blocks negatively correlated (a sample
    /// enters `ΔY_q` and `ΔY_{q+h}` with opposite signs), so there `Ω̂` is conservative.
    /// `B/(B − d)` makes up for the `d` fitted directions. With
    /// [`with_batch`](InstrumentedWindows::with_batch)`(b)`, `b > 1`, the block sums are first
    /// summed over batches of `b` consecutive blocks (the oldest batch holds the remainder
    /// `r = B mod b` and is weighted by `c_{r,h}/c_{b,h}`), `B` is the number of batches
    /// `⌈B/b⌉` and `c_h` becomes `c_{b,h} = 3bh²/(3bh² − h² + 1)`; the effective number is
    /// then over batch weights. (A Bartlett weight ½ on neighbouring
    /// blocks, exact in expectation and less conservative under sensor noise, raised the
    /// false-opening rate of the study's scalar cell at `M = 150` to 16 in 1000: not used.) Cost `O(n (k d + p²) + B p⁴ + k³)`:
    /// the calibrated certificate calls it at its looks and its change guard at the guard's
    /// pace, never per sample.
    ///
    /// `out.ready` is `false` when the window holds fewer than `h (p + m + 1)` columns,
    /// `H + λI` is not positive definite, `A` is singular to working precision (the pivot
    /// ratio of `A` equilibrated to a unit diagonal at most `min_pivot_ratio`, the same in any
    /// units of the regressors), or a value is not finite.
    pub fn estimate(
        &self,
        w: usize,
        ridge: f64,
        t: &[f64],
        min_pivot_ratio: f64,
        out: &mut WindowEstimate,
    ) {
        self.estimate_span(self.span(w, 0), ridge, t, min_pivot_ratio, out);
    }

    /// As [`estimate`](Self::estimate), on window `w`'s blocks older than its newest `skip`
    /// (disjoint from a window of `skip` blocks ending now): a two-sample comparison's part.
    pub fn estimate_older(
        &self,
        w: usize,
        skip: usize,
        ridge: f64,
        t: &[f64],
        min_pivot_ratio: f64,
        out: &mut WindowEstimate,
    ) {
        self.estimate_span(self.span(w, skip), ridge, t, min_pivot_ratio, out);
    }

    fn estimate_span(
        &self,
        span: (usize, usize),
        ridge: f64,
        t: &[f64],
        min_pivot_ratio: f64,
        out: &mut WindowEstimate,
    ) {
        if !self.solve_span(span, ridge, t, min_pivot_ratio, out) {
            return;
        }
        let lay = self.layout();
        let (p, d, k) = (lay.p, lay.d, lay.k);
        let (sum_w, sum_w2) = match (p, d, k) {
            (1, 2, 2) => self.block_scores(span, out, 1, 2, 2),
            (1, 3, 3) => self.block_scores(span, out, 1, 3, 3),
            (1, 4, 4) => self.block_scores(span, out, 1, 4, 4),
            (1, 5, 5) => self.block_scores(span, out, 1, 5, 5),
            (1, 6, 6) => self.block_scores(span, out, 1, 6, 6),
            _ => self.block_scores(span, out, p, d, k),
        };
        out.effective_blocks = if sum_w2 > 0.0 { sum_w * sum_w / sum_w2 } else { 0.0 };
        let overlap = overlap_factor(self.batch, self.horizon);
        let scale = overlap * out.batches as f64 / (out.batches - d) as f64;
        for v in &mut out.score_cov {
            *v *= scale;
        }
        out.ready = out.theta.iter().chain(&out.score_cov).all(|v| v.is_finite());
    }

    /// The two-stage least-squares solve of [`estimate`](Self::estimate) on the blocks `span`
    /// selects, up to `X = Q A⁻¹ T` (into `out`; `out.ready` left `false`): `false` when the
    /// span has too few batches, `H + λI` is not positive definite or `A` is singular to
    /// working precision.
    pub(super) fn solve_span(
        &self,
        span: (usize, usize),
        ridge: f64,
        t: &[f64],
        min_pivot_ratio: f64,
        out: &mut WindowEstimate,
    ) -> bool {
        let lay = self.layout();
        let (p, d, k) = (lay.p, lay.d, lay.k);
        let blocks = span.0.saturating_sub(span.1);
        out.ready = false;
        out.columns = blocks * self.horizon;
        let batches = blocks.div_ceil(self.batch);
        out.batches = batches;
        if batches <= d {
            return false;
        }
        self.span_sums(span, &mut out.sums);
        let (nm, rest) = out.sums.split_at(lay.cw());
        let (cw, hm) = rest.split_at(p * k);
        // Q = (H + λI)⁻¹ Nᵀ: row i of Q stored as column i of Nᵀ solved against H.
        for i in 0..k {
            for j in 0..k {
                out.hfac[i * k + j] = hm[i * k + j] + if i == j { ridge } else { 0.0 };
            }
        }
        if !linalg::cholesky_in_place(&mut out.hfac, k) {
            return false;
        }
        for i in 0..d {
            let qi = &mut out.q[i * k..(i + 1) * k];
            qi.copy_from_slice(&nm[i * k..(i + 1) * k]);
            linalg::cholesky_solve_in_place(&out.hfac, k, qi);
        }
        // A = N Q + λI (d × d, symmetric): A[i][j] = N_i · Q_j.
        for i in 0..d {
            for j in 0..d {
                let mut v = if i == j { ridge } else { 0.0 };
                for a in 0..k {
                    v += nm[i * k + a] * out.q[j * k + a];
                }
                out.lu[i * d + j] = v;
            }
        }
        // The instruments' strength is the pivot ratio of A equilibrated, `S A S` with
        // `S = diag(A)^(−1/2)` (factored in the free Cholesky buffer, `d <= k`): in no unit, so
        // that an output logged in mK instead of K (its powers in the guards' fits then span
        // twelve more decades) is not refused for its unit. The solve factors A itself.
        for i in 0..d {
            let a = out.lu[i * d + i];
            if !(a > 0.0 && a.is_finite()) {
                out.pivot_ratio = 0.0;
                return false;
            }
            out.row[i] = 1.0 / a.sqrt();
        }
        for i in 0..d {
            for j in 0..d {
                out.hfac[i * d + j] = out.lu[i * d + j] * out.row[i] * out.row[j];
            }
        }
        let ratio = linalg::lu_in_place(&mut out.hfac[..d * d], d, &mut out.piv);
        out.pivot_ratio = ratio;
        if !(ratio > min_pivot_ratio) {
            return false;
        }
        if !(linalg::lu_in_place(&mut out.lu, d, &mut out.piv) > 0.0) {
            return false;
        }
        // Θ̂ row i: (Cw_i Qᵀ... ) — θ_i = (Cw_i Q̃) A⁻¹ with Q̃ = (H + λI)⁻¹Nᵀ, so
        // θ_iᵀ = A⁻¹ (N (H + λI)⁻¹ Cw_iᵀ) since A is symmetric: r_a = Q_a · Cw_i.
        for i in 0..p {
            let row = &mut out.row[..d];
            for a in 0..d {
                let mut v = 0.0;
                for b in 0..k {
                    v += out.q[a * k + b] * cw[i * k + b];
                }
                row[a] = v;
            }
            linalg::lu_solve_in_place(&out.lu, d, &out.piv, row);
            out.theta[i * d..(i + 1) * d].copy_from_slice(row);
        }
        // X = Q A⁻¹ T (k × p), stored as p rows of k: column j is Qᵀ-combination of A⁻¹ T_j.
        for j in 0..p {
            let row = &mut out.row[..d];
            for a in 0..d {
                row[a] = t[a * p + j];
            }
            q_ainv(&out.lu, &out.piv, &out.q, d, k, row, |b, v| out.x[j * k + b] = v);
        }
        true
    }

    /// The block sums of the scores of window `w`, `S_j = sym((Cw_j − Θ̂ N_j) X)`, added as
    /// `Σ_j vec(S_j) vec(S_j)ᵀ` into `out.score_cov`, and `(Σ_j w_j, Σ_j w_j²)` for the
    /// weights `w_j = tr(Xᵀ H_j X)`, from each block's sums (oldest first). The dimensions are
    /// passed in so that the call site for `p = m = 1`, `J = 1` gets unrolled code.
    #[inline(always)]
    fn block_scores(
        &self,
        span: (usize, usize),
        out: &mut WindowEstimate,
        p: usize,
        d: usize,
        k: usize,
    ) -> (f64, f64) {
        let lay = Layout { p, d, k };
        let pp = p * p;
        let score_cov = &mut out.score_cov[..pp * pp];
        score_cov.fill(0.0);
        let (theta, x) = (&out.theta[..p * d], &out.x[..p * k]);
        let (row, block) = (&mut out.row[..k], &mut out.block[..pp]);
        let (mut sum_w, mut sum_w2, mut cov) = (0.0, 0.0, 0.0);
        let (older, newer) = self.span_blocks(span);
        let stride = lay.stride();
        // Batches of `b > 1` blocks: the batch's score sum in `g` (p d >= p² values, free
        // here), its weight in `batch_w`.
        let batch = self.batch;
        let mut batches = Batches::new((older.len() + newer.len()) / stride, batch, self.horizon);
        let acc = &mut out.g[..if batch > 1 { pp } else { 0 }];
        acc.fill(0.0);
        let mut batch_w = 0.0;
        for blk in older.chunks_exact(stride).chain(newer.chunks_exact(stride)) {
            let (bn, bcw, bh) = (&blk[..lay.cw()], &blk[lay.cw()..lay.h()], &blk[lay.h()..stride]);
            for i in 0..p {
                // r = Cw_j,i − θ_i N_j (k values), then r · X_col.
                let th = &theta[i * d..(i + 1) * d];
                for b in 0..k {
                    let mut v = bcw[i * k + b];
                    for a in 0..d {
                        v -= th[a] * bn[a * k + b];
                    }
                    row[b] = v;
                }
                for jj in 0..p {
                    let xj = &x[jj * k..(jj + 1) * k];
                    let mut v = 0.0;
                    for b in 0..k {
                        v += row[b] * xj[b];
                    }
                    block[i * p + jj] = v;
                }
            }
            for i in 0..p {
                for jj in i + 1..p {
                    let s = 0.5 * (block[i * p + jj] + block[jj * p + i]);
                    block[i * p + jj] = s;
                    block[jj * p + i] = s;
                }
            }
            let weight = block_weight(bh, x, k);
            if batch == 1 {
                if pp == 1 {
                    // One output: the sum in a register (in memory, every block waited for
                    // the previous block's store to be read back), the same additions.
                    cov += block[0] * block[0];
                } else {
                    for a in 0..pp {
                        for b in 0..pp {
                            score_cov[a * pp + b] += block[a] * block[b];
                        }
                    }
                }
                sum_w += weight;
                sum_w2 += weight * weight;
                continue;
            }
            for (c, &v) in acc.iter_mut().zip(block.iter()) {
                *c += v;
            }
            batch_w += weight;
            if let Some(f) = batches.close() {
                for a in 0..pp {
                    for b in 0..pp {
                        score_cov[a * pp + b] += f * acc[a] * acc[b];
                    }
                }
                sum_w += batch_w;
                sum_w2 += batch_w * batch_w;
                acc.fill(0.0);
                batch_w = 0.0;
            }
        }
        if batch == 1 && pp == 1 {
            score_cov[0] = cov;
        }
        (sum_w, sum_w2)
    }
}
