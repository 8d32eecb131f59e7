//! The batch-means covariance of a window's coefficients (what a test of some coefficients,
//! or a certificate over a region of states, needs), after an estimate or fused with it.

use super::batch::Batches;
use super::estimate::block_weight;
use super::jackknife::{JackScratch, Jackknife, MIN_LEVERAGE_PIVOT, MIN_RESIDUAL_SHARE};
use super::{InstrumentedWindows, Layout, Solve, WindowEstimate};

impl InstrumentedWindows {
    /// The batch-means covariance of the coefficients, after a ready
    /// [`estimate`](Self::estimate) of the same window `w` (which leaves the factors in
    /// `out`): with `r_j = Cw_j − Θ̂ N_j` (one row per output) and block `j`'s
    /// delete-one-block change `G_j = r_j Q A⁻¹ (I − L_j)⁻ᵀ = Θ̂ − Θ̂_(j)` (`p × d`, exact for
    /// `J = 1`; `L_j = A⁻¹ Qᵀ N_jᵀ`, see [`estimate`](Self::estimate)),
    ///
    /// ```text
    /// Ω_θ = c_h · Σ_j vec(G_j) vec(G_j)ᵀ        ((p d) × (p d), row-major)
    /// ```
    ///
    /// with the same factors (and the same batches, see [`with_batch`](Self::with_batch)) as
    /// the score covariance of [`estimate`](Self::estimate). For a
    /// direction `T` (`d × p`), the score covariance of `estimate` is the image of `Ω_θ`
    /// under `vec(G) ↦ vec(sym(G T))`; for `p = 1` the variance of `(Θ̂ − Θ) T` is
    /// `Tᵀ Ω_θ T`, for every `T` at once (what a certificate over a region of states needs).
    /// `false` (and `cov` untouched) when `out` holds no ready estimate, or when a block alone
    /// identifies a direction (`out.leverage_pivot` at most [`MIN_LEVERAGE_PIVOT`]).
    /// `O(B (p k d + d² k + d³ + p² d²))`.
    ///
    /// # Panics
    /// If `cov` is shorter than `(p d)²`.
    pub fn coefficient_covariance(
        &self,
        w: usize,
        out: &mut WindowEstimate,
        cov: &mut [f64],
    ) -> bool {
        if !out.ready {
            return false;
        }
        self.influence_pass::<false, true>(w, out, cov);
        out.leverage_pivot > MIN_LEVERAGE_PIVOT
    }

    /// [`estimate`](Self::estimate) and [`coefficient_covariance`](Self::coefficient_covariance)
    /// of window `w` in one pass over its blocks, for a caller that needs `Θ̂`, `Ω_θ` and the
    /// effective number of blocks but not the score covariance: `out` holds the estimate's
    /// `Θ̂`, factors, `effective_blocks` and `batches` (bit for bit those of `estimate`; the
    /// weights `w_j = tr(Xᵀ H_j X)` are summed in the same order), `out.score_cov` is zero,
    /// and `out.ready` is `true` when every entry of `Θ̂` and `Ω_θ` is finite. Returns
    /// `out.ready`; `cov` is written whenever the solve succeeded. One block pass where the two
    /// calls take two.
    ///
    /// # Panics
    /// If `cov` is shorter than `(p d)²`.
    pub fn estimate_coefficients(
        &self,
        w: usize,
        solve: Solve<'_>,
        out: &mut WindowEstimate,
        cov: &mut [f64],
    ) -> bool {
        self.fused_coefficients::<true>(w, solve, out, cov)
    }

    /// The solve and the coefficient pass of [`estimate_coefficients`](Self::estimate_coefficients)
    /// (`JACK`) or of [`estimate_coefficients_first_order`](Self::estimate_coefficients_first_order).
    fn fused_coefficients<const JACK: bool>(
        &self,
        w: usize,
        solve: Solve<'_>,
        out: &mut WindowEstimate,
        cov: &mut [f64],
    ) -> bool {
        if !self.solve_span(self.span(w, 0), solve, out) {
            return false;
        }
        let (sum_w, sum_w2) = self.influence_pass::<true, JACK>(w, out, cov);
        out.effective_blocks = if sum_w2 > 0.0 { sum_w * sum_w / sum_w2 } else { 0.0 };
        out.score_cov.fill(0.0);
        let lay = self.layout();
        let n = lay.p * lay.d;
        if !JACK {
            let batches = out.batches as f64;
            let fitted = batches / (batches - lay.d as f64);
            for v in &mut cov[..n * n] {
                *v *= fitted;
            }
        }
        out.ready = out.leverage_pivot > MIN_LEVERAGE_PIVOT
            && out.theta.iter().chain(&cov[..n * n]).all(|v| v.is_finite());
        out.ready
    }

    /// As [`estimate_coefficients`](Self::estimate_coefficients), with the first-order
    /// influence of each block in place of its delete-one-block change,
    ///
    /// ```text
    /// G_j = r_j Q A⁻¹,   Ω_θ = c_h · B/(B − d) · Σ_j vec(G_j) vec(G_j)ᵀ
    /// ```
    ///
    /// (`B/(B − d)` for the fitted directions; `out.leverage_pivot` is 1, not computed): the
    /// covariance of a test that closes looks (the calibrated certificate's model guards),
    /// not of one that certifies. A block pass without a factorisation per block (for
    /// `d = 5` about a fifth of the jackknife's operations). Where an input moved in a few
    /// blocks only it understates the spread (a test on it rejects more often than on the
    /// jackknife).
    pub fn estimate_coefficients_first_order(
        &self,
        w: usize,
        solve: Solve<'_>,
        out: &mut WindowEstimate,
        cov: &mut [f64],
    ) -> bool {
        self.fused_coefficients::<false>(w, solve, out, cov)
    }

    /// The pass over window `w`'s blocks behind both: `Ω_θ` into `cov`, and with `WEIGHTS` the
    /// batch weights' `(Σ w, Σ w²)` (else zeros). Literal dimensions for the common shapes let
    /// the compiler unroll the kernels.
    fn influence_pass<const WEIGHTS: bool, const JACK: bool>(
        &self,
        w: usize,
        out: &mut WindowEstimate,
        cov: &mut [f64],
    ) -> (f64, f64) {
        let lay = self.layout();
        match (lay.p, lay.d, lay.k) {
            (1, 2, 2) => self.influence_dims::<WEIGHTS, JACK>(w, out, cov, 1, 2, 2),
            (1, 3, 3) => self.influence_dims::<WEIGHTS, JACK>(w, out, cov, 1, 3, 3),
            (1, 4, 4) => self.influence_dims::<WEIGHTS, JACK>(w, out, cov, 1, 4, 4),
            (1, 5, 5) => self.influence_dims::<WEIGHTS, JACK>(w, out, cov, 1, 5, 5),
            (1, 6, 6) => self.influence_dims::<WEIGHTS, JACK>(w, out, cov, 1, 6, 6),
            (p, d, k) => self.influence_dims::<WEIGHTS, JACK>(w, out, cov, p, d, k),
        }
    }

    /// [`influence_pass`](Self::influence_pass) with the dimensions passed in.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn influence_dims<const WEIGHTS: bool, const JACK: bool>(
        &self,
        w: usize,
        out: &mut WindowEstimate,
        cov: &mut [f64],
        p: usize,
        d: usize,
        k: usize,
    ) -> (f64, f64) {
        let lay = Layout { p, d, k };
        let n = p * d;
        let cov = &mut cov[..n * n];
        cov.fill(0.0);
        let blocks = self.windows[w].min(self.block_len);
        let stride = lay.stride();
        let (older, newer) = self.window_blocks(w);
        let jack = Jackknife::of(&out.theta, &out.qa, &out.diag, (p, d, k));
        let mut scratch = JackScratch::new(&jack, &mut out.jack, &mut out.jack_piv, &mut out.gj);
        let x = &out.x[..p * k];
        // Batches of `b > 1` blocks: the batch's influence sum in `sums` (free after the
        // estimate; `stride >= p d` values), its weight in `batch_w`.
        let batch = self.batch;
        let mut batches = Batches::new(blocks, batch, self.horizon, self.coarse);
        let acc = &mut out.sums[..if batch > 1 { n } else { 0 }];
        acc.fill(0.0);
        let (mut sum_w, mut sum_w2, mut batch_w) = (0.0, 0.0, 0.0);
        let mut least = 1.0f64;
        for blk in older.chunks_exact(stride).chain(newer.chunks_exact(stride)) {
            let (bn, bcw, bh) = (&blk[..lay.cw()], &blk[lay.cw()..lay.h()], &blk[lay.h()..stride]);
            // The block's delete-one-block change of `Θ̂` (the rows `g_{j,i}`).
            if JACK {
                least = least.min(jack.block_shaped(bn, bcw, &mut scratch));
            } else {
                jack.first_order(bn, bcw, &mut scratch);
            }
            // The block's weight, as `estimate` computes it on the undeleted direction.
            let weight = if WEIGHTS { block_weight(bh, x, k) } else { 0.0 };
            let g = &scratch.g[..n];
            if batch == 1 {
                for a in 0..n {
                    for b in a..n {
                        cov[a * n + b] += g[a] * g[b];
                    }
                }
                if WEIGHTS {
                    sum_w += weight;
                    sum_w2 += weight * weight;
                }
                continue;
            }
            for (c, &v) in acc.iter_mut().zip(g) {
                *c += v;
            }
            batch_w += weight;
            if let Some(f) = batches.close() {
                for a in 0..n {
                    for b in a..n {
                        cov[a * n + b] += f * acc[a] * acc[b];
                    }
                }
                acc.fill(0.0);
                if WEIGHTS {
                    sum_w += batch_w;
                    sum_w2 += batch_w * batch_w;
                }
                batch_w = 0.0;
            }
        }
        out.leverage_pivot = least;
        if !(scratch.residual > MIN_RESIDUAL_SHARE * scratch.raw) {
            // An exact identity (see `MIN_RESIDUAL_SHARE`): nothing is identified.
            out.leverage_pivot = 0.0;
        }
        for a in 0..n {
            for b in 0..a {
                cov[a * n + b] = cov[b * n + a];
            }
        }
        // The delete-one-block changes already carry each block's leverage: no `B/(B − d)`.
        let scale = self.overlap(batch);
        for v in cov.iter_mut() {
            *v *= scale;
        }
        (sum_w, sum_w2)
    }
}
