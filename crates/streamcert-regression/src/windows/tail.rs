//! The first-order coefficient covariance of a window's trailing coefficients only: what a
//! Wald test of a larger fit's extra terms reads (the calibrated certificate's model guards),
//! for one output and batches of one block.
//!
//! [`estimate_coefficients_first_order`](InstrumentedWindows::estimate_coefficients_first_order)
//! forms every block's influence on all `d` coefficients and the whole `d × d` covariance; a
//! test of the last `q` coefficients reads a `q × q` corner of it. Here each block's
//! influence is formed on those `q` coefficients only (`d k + q k` products in place of
//! `d k + d k`) and only their `q (q + 1)/2` sums are kept (in place of `d (d + 1)/2`). Every
//! kept value is computed by the same operations in the same order as the whole pass, so the
//! corner is the whole covariance's corner bit for bit (tested).

use super::estimate::block_weight;
use super::jackknife::{MIN_LEVERAGE_PIVOT, MIN_RESIDUAL_SHARE};
use super::{InstrumentedWindows, Solve, WindowEstimate};

/// The most trailing coefficients [`InstrumentedWindows::estimate_tail_first_order`] serves.
pub const MAX_TAIL: usize = 8;

impl InstrumentedWindows {
    /// [`estimate_coefficients_first_order`](Self::estimate_coefficients_first_order) of
    /// window `w`, with the covariance of the coefficients `first .. d` only, `q = d − first`:
    ///
    /// ```text
    /// g_j = (r_j Q A⁻¹)[first..d],   Ω_tail = c_h · B/(B − d) · Σ_j g_j g_jᵀ    (q × q)
    /// ```
    ///
    /// into `cov` (row-major, `q²` values), bit for bit the corner `[first..d, first..d]` of
    /// the whole pass's covariance. `out` holds the same `Θ̂`, `effective_blocks` and
    /// `batches`; `out.ready` is `true` when every entry of `Θ̂` and of `Ω_tail` is finite and
    /// the residuals do not vanish. `None` (nothing written) where this shape is not served:
    /// more than one output, batches of more than one block, `first >= d` or more than
    /// [`MAX_TAIL`] coefficients; the caller then
    /// takes the whole pass.
    ///
    /// # Panics
    /// If `cov` is shorter than `q²`.
    pub fn estimate_tail_first_order(
        &self,
        w: usize,
        solve: Solve<'_>,
        first: usize,
        out: &mut WindowEstimate,
        cov: &mut [f64],
    ) -> Option<bool> {
        let lay = self.layout();
        if lay.p != 1 || self.batch != 1 || first >= lay.d || lay.d - first > MAX_TAIL {
            return None;
        }
        if !self.solve_span(self.span(w, 0), solve, out) {
            return Some(false);
        }
        let (d, k, q) = (lay.d, lay.k, lay.d - first);
        let (sum_w, sum_w2, residual, raw) = match (d, k, q) {
            (4, 4, 1) => self.tail_pass(w, out, cov, (4, 4, 3, 1)),
            (5, 5, 2) => self.tail_pass(w, out, cov, (5, 5, 3, 2)),
            _ => self.tail_pass(w, out, cov, (d, k, first, q)),
        };
        out.effective_blocks = if sum_w2 > 0.0 { sum_w * sum_w / sum_w2 } else { 0.0 };
        out.score_cov.fill(0.0);
        // First order: no leverage pivot is computed (1, as the whole pass leaves it), unless
        // the residuals vanish (an exact identity: nothing is identified).
        out.leverage_pivot = if residual > MIN_RESIDUAL_SHARE * raw { 1.0 } else { 0.0 };
        let batches = out.batches as f64;
        let fitted = batches / (batches - d as f64);
        let cov = &mut cov[..q * q];
        for v in cov.iter_mut() {
            *v *= fitted;
        }
        out.ready = out.leverage_pivot > MIN_LEVERAGE_PIVOT
            && out.theta.iter().chain(cov.iter()).all(|v| v.is_finite());
        Some(out.ready)
    }

    /// The pass over window `w`'s blocks: the tail's covariance into `cov` (scaled by the
    /// overlap factor), and `(Σ w_j, Σ w_j², Σ ‖r_j‖², Σ ‖Cw_j‖²)`. The dimensions are
    /// literal at the model guards' shapes, so the compiler unrolls the kernel.
    #[inline(always)]
    fn tail_pass(
        &self,
        w: usize,
        out: &WindowEstimate,
        cov: &mut [f64],
        (d, k, first, q): (usize, usize, usize, usize),
    ) -> (f64, f64, f64, f64) {
        let cov = &mut cov[..q * q];
        cov.fill(0.0);
        let (theta, qa, x) = (&out.theta[..d], &out.qa[..k * d], &out.x[..k]);
        let (cw, h) = (d * k, d * k + k);
        let stride = self.layout().stride();
        let (older, newer) = self.window_blocks(w);
        let (mut sum_w, mut sum_w2, mut residual, mut raw) = (0.0, 0.0, 0.0, 0.0);
        let mut g = [0.0f64; MAX_TAIL];
        let g = &mut g[..q];
        for blk in older.chunks_exact(stride).chain(newer.chunks_exact(stride)) {
            let (bn, bcw, bh) = (&blk[..cw], &blk[cw..h], &blk[h..stride]);
            g.fill(0.0);
            for b in 0..k {
                let r0 = bcw[b];
                let mut r = r0;
                for a in 0..d {
                    r -= theta[a] * bn[a * k + b];
                }
                residual += r * r;
                raw += r0 * r0;
                for (i, gi) in g.iter_mut().enumerate() {
                    *gi += r * qa[b * d + first + i];
                }
            }
            let weight = block_weight(bh, x, k);
            for i in 0..q {
                for j in i..q {
                    cov[i * q + j] += g[i] * g[j];
                }
            }
            sum_w += weight;
            sum_w2 += weight * weight;
        }
        for i in 0..q {
            for j in 0..i {
                cov[i * q + j] = cov[j * q + i];
            }
        }
        let scale = self.overlap(1);
        for v in cov.iter_mut() {
            *v *= scale;
        }
        (sum_w, sum_w2, residual, raw)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::RateMap;
    use proptest::prelude::*;

    proptest! {
        /// The tail's covariance is the whole pass's corner bit for bit, with the same
        /// estimate, effective number of blocks and readiness, at every look of a stream
        /// (the model guards' shapes `d = 4, 5` and a generic one, `d = 3` with `J = 2`).
        #[test]
        fn the_tail_is_the_corner_of_the_whole_covariance(
            (d, intervals, q) in prop_oneof![Just((4, 1, 1)), Just((5, 1, 2)), Just((3, 2, 2)), Just((5, 1, 4))],
            seed in any::<u64>(),
            columns in 60usize..260,
        ) {
            let h = 2;
            let mut windows = InstrumentedWindows::with_regressors(1, d, h, 0, intervals, &[24, 48]).unwrap();
            let (mut full, mut tail) = (
                WindowEstimate::with_regressors(1, d, intervals),
                WindowEstimate::with_regressors(1, d, intervals),
            );
            let (mut cov, mut corner) = (vec![0.0; d * d], vec![0.0; q * q]);
            let dir = vec![1.0; d];
            let mut state = seed | 1;
            let mut next = || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            };
            let first = d - q;
            let mut z = vec![0.0; d];
            for _ in 0..columns {
                for v in &mut z {
                    *v = next();
                }
                let dy = [0.3 * z[0] - 0.2 * z[1] + 0.05 * next()];
                windows.push_column(&z, &dy);
                for w in 0..2 {
                    let solve = Solve { ridge: 1e-6, rate: RateMap::SymmetricPart(&dir), min_pivot_ratio: 1e-9 };
                    let a = windows.estimate_coefficients_first_order(w, solve, &mut full, &mut cov);
                    let solve = Solve { ridge: 1e-6, rate: RateMap::SymmetricPart(&dir), min_pivot_ratio: 1e-9 };
                    let b = windows.estimate_tail_first_order(w, solve, first, &mut tail, &mut corner);
                    prop_assert_eq!(Some(a), b);
                    if !a {
                        continue;
                    }
                    prop_assert_eq!(&full.theta, &tail.theta);
                    prop_assert_eq!(full.effective_blocks.to_bits(), tail.effective_blocks.to_bits());
                    prop_assert_eq!(full.batches, tail.batches);
                    for i in 0..q {
                        for j in 0..q {
                            let whole = cov[(first + i) * d + first + j];
                            prop_assert_eq!(whole.to_bits(), corner[i * q + j].to_bits());
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn shapes_it_does_not_serve_are_refused() {
        let mut windows = InstrumentedWindows::with_regressors(2, 4, 2, 0, 1, &[24]).unwrap();
        let mut est = WindowEstimate::with_regressors(2, 4, 1);
        let dir = vec![1.0; 8];
        let solve =
            Solve { ridge: 1e-6, rate: RateMap::SymmetricPart(&dir), min_pivot_ratio: 1e-9 };
        assert!(windows.estimate_tail_first_order(0, solve, 3, &mut est, &mut [0.0; 1]).is_none());
        windows = InstrumentedWindows::with_regressors(1, 4, 2, 0, 1, &[24]).unwrap();
        let solve =
            Solve { ridge: 1e-6, rate: RateMap::SymmetricPart(&dir[..4]), min_pivot_ratio: 1e-9 };
        assert!(windows.estimate_tail_first_order(0, solve, 4, &mut est, &mut [0.0; 1]).is_none());
    }
}
