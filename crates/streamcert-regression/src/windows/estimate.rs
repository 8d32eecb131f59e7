//! Solving one window of [`InstrumentedWindows`] at a look: two-stage least squares from the
//! window's block sums, and the batch-means covariance of the scores with its effective
//! number of blocks.

use super::jackknife::MIN_LEVERAGE_PIVOT;
use super::outcome::{Solve, WindowEstimate};
use super::{InstrumentedWindows, Layout};
use crate::linalg;

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
    /// Solve window `w` with the ridge `λ = solve.ridge` *relative to each diagonal entry*
    /// for the candidate directions `solve.rate`'s `T` (`d × p` row-major, `T = [I_p; K]`) into `out`
    /// (built with this structure's `p`, `m`, `J`):
    ///
    /// ```text
    /// Q = (H + λ diag H)⁻¹ Nᵀ,   A = N Q + λ diag(N Q),   Θ̂ = Cw Q A⁻¹     (two-stage LS)
    /// r_j = Cw_j − Θ̂ N_j               (block j's residual scores, p × k)
    /// L_j = A⁻¹ Qᵀ N_jᵀ                 (block j's leverage on the coefficients, d × d)
    /// G_j = r_j Q A⁻¹ (I − L_j)⁻ᵀ        (Θ̂ − Θ̂_(j): the change when block j is deleted)
    /// S_j = vec(sym(G_j T))             (p² values, for the window's B blocks of h columns)
    /// Ω̂  = c_h · Σ_j S_j S_jᵀ,   c_h = 3h² / (2h² + 1)
    /// ```
    ///
    /// With `J = 1` this is the instrumental-variables estimator `Θ̂ = Cw N⁻¹`, and `G_j` is
    /// exactly `Θ̂ − Θ̂_(j)` with `Θ̂_(j) = (Cw − Cw_j)(N − N_j)⁻¹` (for `J >= 2` the first
    /// stage `H` is held). The delete-one-block jackknife: without the factor `(I − L_j)⁻¹`
    /// (the first-order influence, the variance as it was) a block that carries most of the
    /// information in a direction has its residual fitted away, and where an input moved in a
    /// few blocks only (a step test) the variance understated the spread many times over;
    /// with it the leverage is put back, and a block whose leverage reaches 1 (it alone
    /// identifies a direction) refuses the fit. `I − L_j` is factored equilibrated,
    /// `diag(√A) (I − L_j) diag(√A)⁻¹`, so its pivot ratio ([`MIN_LEVERAGE_PIVOT`]) is in no
    /// unit. The jackknife carries the fitted directions' price, so no `B/(B − d)`. Batch
    /// means: a block sum is a sum of `h` consecutive scores, so `Ω̂` is positive
    /// semi-definite by construction and the blocks are nearly independent. Neighbouring
    /// blocks still share the overlap of their columns: for white process noise the column
    /// errors have the triangular autocorrelation `1 − |l|/h`, a block's variance is then
    /// `h² − (h² − 1)/3` and the long-run variance per block `h²` (in units of one column's),
    /// hence `c_h`. White sensor noise makes neighbouring blocks negatively correlated (a sample
    /// enters `ΔY_q` and `ΔY_{q+h}` with opposite signs), so there `Ω̂` is conservative. With
    /// [`with_batch`](InstrumentedWindows::with_batch)`(b)`, `b > 1`, the blocks' changes are
    /// first summed over batches of `b` consecutive blocks (the oldest batch holds the
    /// remainder `r = B mod b` and is weighted by `c_{r,h}/c_{b,h}`), `B` is the number of
    /// batches `⌈B/b⌉` and `c_h` becomes `c_{b,h} = 3bh²/(3bh² − h² + 1)`; the effective
    /// number is then over batch weights, `w_j = tr(Xᵀ H_j X)`. A window whose residual
    /// moments vanish ([`MIN_RESIDUAL_SHARE`](crate::MIN_RESIDUAL_SHARE): an exact identity, not a noisy fit) is not
    /// ready. (A Bartlett weight ½ on
    /// neighbouring blocks, exact in expectation and less conservative under sensor noise,
    /// raised the false-opening rate of the study's scalar cell at `M = 150` to 16 in 1000:
    /// not used.) Cost `O(B (d² k + d³ + p⁴) + k³)`: the calibrated certificate calls it at
    /// its looks, never per sample (its change guard takes
    /// [`fresh_estimate`](Self::fresh_estimate), `O(1)` in the window's length).
    ///
    /// The ridge `λ` is relative to each diagonal entry: a regressor in other units scales
    /// its rows and columns and its ridge alike, so the estimate, its covariance and every
    /// refusal are in no unit; a regressor whose instrumented column is zero in the window
    /// (an input that never moved from the working origin) gets no ridge and is refused.
    ///
    /// `out.ready` is `false` when the window holds fewer than `h (p + m + 1)` columns,
    /// `H + λ diag H` is not positive definite, `A` is singular to working precision (the pivot
    /// ratio of `A` equilibrated to a unit diagonal at most `solve.min_pivot_ratio`, the same in
    /// any units of the regressors), a block alone identifies a direction (the equilibrated
    /// pivot ratio of `I − L_j` at most [`MIN_LEVERAGE_PIVOT`]), or a value is not finite.
    pub fn estimate(&self, w: usize, solve: Solve<'_>, out: &mut WindowEstimate) {
        self.estimate_span(self.span(w, 0), solve, out);
    }

    /// As [`estimate`](Self::estimate), on window `w`'s blocks older than its newest `skip`
    /// (disjoint from a window of `skip` blocks ending now): a two-sample comparison's part.
    pub fn estimate_older(
        &self,
        w: usize,
        skip: usize,
        solve: Solve<'_>,
        out: &mut WindowEstimate,
    ) {
        self.estimate_span(self.span(w, skip), solve, out);
    }

    /// As [`estimate`](Self::estimate) (batches of one block, which this structure must
    /// have), and in the same pass over the blocks the covariance in batches of `batch >= 2`
    /// blocks into `out.batched` (bit for bit what [`set_batch`](Self::set_batch)`(batch)`
    /// then [`estimate`](Self::estimate) would give): a look's two covariances for one solve
    /// and one pass.
    pub fn estimate_batched(
        &self,
        w: usize,
        batch: usize,
        solve: Solve<'_>,
        out: &mut WindowEstimate,
    ) {
        let pp = self.p * self.p;
        if out.batched.score_cov.len() != pp * pp {
            // Only on an estimate read back without it (the field is not serialised; the
            // calibrated certificate sizes it on restore).
            out.batched.score_cov.resize(pp * pp, 0.0);
        }
        out.batched.ready = false;
        let span = self.span(w, 0);
        let blocks = span.0.saturating_sub(span.1);
        out.batched.batches = blocks.div_ceil(batch.max(1));
        out.batched.effective_blocks = 0.0;
        let second = if self.batch == 1 && batch >= 2 && out.batched.batches > self.layout().d {
            batch
        } else {
            0
        };
        self.estimate_span_second(span, solve, out, second);
    }

    fn estimate_span(&self, span: (usize, usize), solve: Solve<'_>, out: &mut WindowEstimate) {
        self.estimate_span_second(span, solve, out, 0);
    }

    fn estimate_span_second(
        &self,
        span: (usize, usize),
        solve: Solve<'_>,
        out: &mut WindowEstimate,
        second: usize,
    ) {
        if !self.solve_span(span, solve, out) {
            return;
        }
        let lay = self.layout();
        let (p, d, k) = (lay.p, lay.d, lay.k);
        let (sum_w, sum_w2) = match (p, d, k) {
            (1, 2, 2) => {
                self.block_scores(span, solve.rate.symmetric_part(), out, (1, 2, 2), second)
            }
            (1, 3, 3) => {
                self.block_scores(span, solve.rate.symmetric_part(), out, (1, 3, 3), second)
            }
            (1, 4, 4) => {
                self.block_scores(span, solve.rate.symmetric_part(), out, (1, 4, 4), second)
            }
            (1, 5, 5) => {
                self.block_scores(span, solve.rate.symmetric_part(), out, (1, 5, 5), second)
            }
            (1, 6, 6) => {
                self.block_scores(span, solve.rate.symmetric_part(), out, (1, 6, 6), second)
            }
            _ => self.block_scores(span, solve.rate.symmetric_part(), out, (p, d, k), second),
        };
        out.effective_blocks =
            if sum_w2 > 0.0 && out.leverage_pivot > 0.0 { sum_w * sum_w / sum_w2 } else { 0.0 };
        // The delete-one-block changes already carry each block's leverage: no `B/(B − d)`.
        let overlap = self.overlap(self.batch);
        for v in &mut out.score_cov {
            *v *= overlap;
        }
        out.ready = out.leverage_pivot > MIN_LEVERAGE_PIVOT
            && out.theta.iter().chain(&out.score_cov).all(|v| v.is_finite());
        if second >= 2 {
            let b = &mut out.batched;
            let overlap = self.overlap(second);
            for v in &mut b.score_cov {
                *v *= overlap;
            }
            b.ready = out.leverage_pivot > MIN_LEVERAGE_PIVOT
                && out.theta.iter().chain(&b.score_cov).all(|v| v.is_finite());
        }
    }

    /// The two-stage least-squares solve of [`estimate`](Self::estimate) on the blocks `span`
    /// selects, up to `X = Q A⁻¹ T` (into `out`; `out.ready` left `false`): `false` when the
    /// span has too few batches, `H + λ diag H` is not positive definite or `A` is singular to
    /// working precision.
    pub(super) fn solve_span(
        &self,
        span: (usize, usize),
        solve: Solve<'_>,
        out: &mut WindowEstimate,
    ) -> bool {
        let blocks = span.0.saturating_sub(span.1);
        if blocks.div_ceil(self.batch) > self.layout().d {
            // A pass over the blocks (not the segment sums, whose subtractions can cost a
            // few digits on an ill-conditioned early window): the looks' sums as accurate as
            // a direct sum.
            self.span_sums(span, &mut out.sums);
        }
        self.solve_sums(blocks, solve, out)
    }

    /// [`solve_span`](Self::solve_span) on `blocks` blocks whose sums are in `out.sums`
    /// (read only when there are more than `d` batches).
    pub(super) fn solve_sums(
        &self,
        blocks: usize,
        solve: Solve<'_>,
        out: &mut WindowEstimate,
    ) -> bool {
        let lay = self.layout();
        match (lay.p, lay.d, lay.k) {
            (1, 2, 2) => self.solve_dims(blocks, solve, out, (1, 2, 2)),
            (1, 3, 3) => self.solve_dims(blocks, solve, out, (1, 3, 3)),
            (1, 4, 4) => self.solve_dims(blocks, solve, out, (1, 4, 4)),
            (1, 5, 5) => self.solve_dims(blocks, solve, out, (1, 5, 5)),
            dims => self.solve_dims(blocks, solve, out, dims),
        }
    }

    /// [`solve_sums`](Self::solve_sums) with the dimensions passed in (literal for the
    /// common single-output shapes, so that the compiler unrolls the small solves; the same
    /// operations in the same order).
    #[inline(always)]
    fn solve_dims(
        &self,
        blocks: usize,
        solve: Solve<'_>,
        out: &mut WindowEstimate,
        (p, d, k): (usize, usize, usize),
    ) -> bool {
        let Solve { ridge, rate, min_pivot_ratio } = solve;
        let t = rate.symmetric_part();
        out.ready = false;
        (out.pivot_ratio, out.effective_blocks, out.leverage_pivot) = (0.0, 0.0, 0.0);
        out.columns = blocks * self.coarse * self.horizon;
        let batches = blocks.div_ceil(self.batch);
        out.batches = batches;
        if batches <= d {
            return false;
        }
        let (nm, rest) = out.sums.split_at(Layout { p, d, k }.cw());
        let (cw, hm) = rest.split_at(p * k);
        // Q = (H + λ diag H)⁻¹ Nᵀ: row i of Q stored as column i of Nᵀ solved against H.
        // The ridge relative to each diagonal entry, `H + λ diag(H)`: a regressor in other
        // units scales its rows and columns of `H` and its ridge alike, so the estimate is in
        // no unit; an instrument that never moved (a zero diagonal) gets no ridge, and the
        // factorisation refuses it.
        for i in 0..k {
            for j in 0..k {
                out.hfac[i * k + j] = hm[i * k + j] * if i == j { 1.0 + ridge } else { 1.0 };
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
        // A = N Q + λ diag(N Q) (d × d, symmetric): A[i][j] = N_i · Q_j, the ridge relative
        // as for `H`.
        for i in 0..d {
            for j in 0..d {
                let mut v = 0.0;
                for a in 0..k {
                    v += nm[i * k + a] * out.q[j * k + a];
                }
                out.lu[i * d + j] = if i == j { v * (1.0 + ridge) } else { v };
            }
        }
        let Some(ratio) = equilibrated_pivot(
            &out.lu,
            (&mut out.hfac, &mut out.piv),
            &mut out.diag,
            &mut out.row,
            d,
        ) else {
            out.pivot_ratio = 0.0;
            return false;
        };
        out.pivot_ratio = ratio;
        if !(ratio > min_pivot_ratio) {
            return false;
        }
        if !(linalg::lu_in_place(&mut out.lu, d, &mut out.piv) > 0.0) {
            return false;
        }
        // Θ̂ row i: (Cw_i Qᵀ... ) — θ_i = (Cw_i Q̃) A⁻¹ with Q̃ = (H + λ diag H)⁻¹Nᵀ, so
        // θ_iᵀ = A⁻¹ (N (H + λ diag H)⁻¹ Cw_iᵀ) since A is symmetric: r_a = Q_a · Cw_i.
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
        // Q A⁻¹ (k × d): column a of A⁻¹ is the solve of the unit vector e_a (A is
        // symmetric, so row and column agree).
        for a in 0..d {
            let e = &mut out.row[..d];
            e.fill(0.0);
            e[a] = 1.0;
            q_ainv(&out.lu, &out.piv, &out.q, d, k, e, |b, v| out.qa[b * d + a] = v);
        }
        // X = Q A⁻¹ T (k × p), stored as p rows of k: column j is Qᵀ-combination of A⁻¹ T_j.
        for j in 0..p {
            let row = &mut out.row[..d];
            for a in 0..d {
                row[a] = t[a * p + j] * if out.standardised { out.diag[a] } else { 1.0 };
            }
            q_ainv(&out.lu, &out.piv, &out.q, d, k, row, |b, v| out.x[j * k + b] = v);
        }
        true
    }
}

/// The instruments' strength: the pivot ratio of `A` (in `out.lu`, `d × d`) equilibrated,
/// `S A S` with `S = diag(A)^(−1/2)` (factored in `factor`, the free Cholesky buffer, `d <= k`), with
/// `√A_aa` into `diag`; `None` where a diagonal entry is not positive and finite. In no unit,
/// so that an output logged in mK instead of K (its powers in the guards' fits then span
/// twelve more decades) is not refused for its unit. The solve factors `A` itself.
#[inline(always)]
fn equilibrated_pivot(
    lu: &[f64],
    (factor, piv): (&mut [f64], &mut [usize]),
    diag: &mut [f64],
    inv: &mut [f64],
    d: usize,
) -> Option<f64> {
    for i in 0..d {
        let a = lu[i * d + i];
        if !(a > 0.0 && a.is_finite()) {
            return None;
        }
        inv[i] = 1.0 / a.sqrt();
        diag[i] = a.sqrt();
    }
    for i in 0..d {
        for j in 0..d {
            factor[i * d + j] = lu[i * d + j] * inv[i] * inv[j];
        }
    }
    Some(linalg::lu_in_place(&mut factor[..d * d], d, piv))
}
