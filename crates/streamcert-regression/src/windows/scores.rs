//! A window's pass over its blocks at a look: each block's delete-one-block change of the
//! rate's direction, summed into the batch-means score covariance (and, fused, the second
//! covariance in batches) with the blocks' weights for the effective number.

use super::batch::Batches;
use super::estimate::block_weight;
use super::fresh::product;
use super::jackknife::{JackScratch, Jackknife, MIN_RESIDUAL_SHARE};
use super::outcome::WindowEstimate;
use super::{InstrumentedWindows, Layout};

/// Add a block's score changes `block` and weight to the open batch (`acc`, its weight);
/// where the block closes the batch, add the batch's outer product (times its factor) to
/// `cov` and its weight to the sums `(Σ w, Σ w²)`, and open the next.
#[inline(always)]
fn batch_step(
    (acc, batch_w): (&mut [f64], &mut f64),
    block: &[f64],
    weight: f64,
    batches: &mut Batches,
    cov: &mut [f64],
    (sum_w, sum_w2): (&mut f64, &mut f64),
) {
    for (c, &v) in acc.iter_mut().zip(block) {
        *c += v;
    }
    *batch_w += weight;
    if let Some(f) = batches.close() {
        let pp = acc.len();
        for a in 0..pp {
            for b in 0..pp {
                cov[a * pp + b] += f * acc[a] * acc[b];
            }
        }
        *sum_w += *batch_w;
        *sum_w2 += *batch_w * *batch_w;
        acc.fill(0.0);
        *batch_w = 0.0;
    }
}

/// `block = sym(G T)` (`p × p`) for the influence rows `G` (`p × d`) and `T` (`d × p`).
#[inline(always)]
fn sym_product(g: &[f64], t: &[f64], block: &mut [f64], p: usize, d: usize) {
    product(g, t, block, (p, d, p));
    for i in 0..p {
        for jj in i + 1..p {
            let s = 0.5 * (block[i * p + jj] + block[jj * p + i]);
            block[i * p + jj] = s;
            block[jj * p + i] = s;
        }
    }
}

impl InstrumentedWindows {
    /// The block sums of the scores of window `w`, each block's delete-one-block change of
    /// `sym(Θ̂ T)` ([`Jackknife::block`]), added as `Σ_j vec(S_j) vec(S_j)ᵀ` into
    /// `out.score_cov`, and `(Σ_j w_j, Σ_j w_j²)` for the weights `w_j = tr(X_jᵀ H_j X_j)`,
    /// from each block's sums (oldest first); `out.leverage_pivot` the smallest pivot ratio of
    /// `I − L_j`. The dimensions are passed in so that the call site for `p = m = 1`, `J = 1`
    /// gets unrolled code.
    ///
    /// With `second >= 2` (and batches of one block), the same blocks' changes are also
    /// summed in batches of `second` into `out.batched` (its covariance unscaled, its
    /// effective number of batches set), in the same pass.
    #[inline(always)]
    pub(super) fn block_scores(
        &self,
        span: (usize, usize),
        t: &[f64],
        out: &mut WindowEstimate,
        (p, d, k): (usize, usize, usize),
        second: usize,
    ) -> (f64, f64) {
        let lay = Layout { p, d, k };
        let pp = p * p;
        let score_cov = &mut out.score_cov[..pp * pp];
        score_cov.fill(0.0);
        let batched = &mut out.batched;
        let second_cov = &mut batched.score_cov[..if second >= 2 { pp * pp } else { 0 }];
        second_cov.fill(0.0);
        let jack = Jackknife::of(&out.theta, &out.qa, &out.diag, (p, d, k));
        let mut scratch = JackScratch::new(&jack, &mut out.jack, &mut out.jack_piv, &mut out.gj);
        let x = &out.x[..p * k];
        let block = &mut out.block[..pp];
        let (mut sum_w, mut sum_w2, mut cov) = (0.0, 0.0, 0.0);
        let mut least = 1.0f64;
        let (older, newer) = self.span_blocks(span);
        let stride = lay.stride();
        // Batches of `b > 1` blocks: the batch's score sum in `g` (p d >= p² values, free
        // here), its weight in `batch_w`.
        let batch = self.batch;
        let nblocks = (older.len() + newer.len()) / stride;
        let mut batches = Batches::new(nblocks, batch, self.horizon, self.coarse);
        // The batched sums: of the estimate's own batches (`batch > 1`), or of the second
        // covariance's (`second >= 2`, with batches of one block).
        let size = if batch > 1 { batch } else { second };
        let acc = &mut out.g[..if size > 1 { pp } else { 0 }];
        acc.fill(0.0);
        let mut batch_w = 0.0;
        let mut seconds = Batches::new(nblocks, second.max(1), self.horizon, self.coarse);
        let (mut sum_w_b, mut sum_w2_b) = (0.0, 0.0);
        for blk in older.chunks_exact(stride).chain(newer.chunks_exact(stride)) {
            let (bn, bcw, bh) = (&blk[..lay.cw()], &blk[lay.cw()..lay.h()], &blk[lay.h()..stride]);
            least = least.min(jack.block_shaped(bn, bcw, &mut scratch));
            sym_product(scratch.g, t, block, p, d);
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
                if second >= 2 {
                    let sums = (&mut sum_w_b, &mut sum_w2_b);
                    batch_step((acc, &mut batch_w), block, weight, &mut seconds, second_cov, sums);
                }
                continue;
            }
            let sums = (&mut sum_w, &mut sum_w2);
            batch_step((acc, &mut batch_w), block, weight, &mut batches, score_cov, sums);
        }
        out.leverage_pivot = least;
        if !(scratch.residual > MIN_RESIDUAL_SHARE * scratch.raw) {
            // An exact identity (see `MIN_RESIDUAL_SHARE`): nothing is identified.
            out.leverage_pivot = 0.0;
        }
        if batch == 1 && pp == 1 {
            score_cov[0] = cov;
        }
        if second >= 2 {
            batched.effective_blocks = if sum_w2_b > 0.0 && out.leverage_pivot > 0.0 {
                sum_w_b * sum_w_b / sum_w2_b
            } else {
                0.0
            };
        }
        (sum_w, sum_w2)
    }
}
