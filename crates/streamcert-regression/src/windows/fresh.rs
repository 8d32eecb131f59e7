//! The change guard's first-order estimate of a span from the segment sums of
//! [`moments`](super::moments): the look's solve on the span's sums, and each block's
//! first-order influence summed as a quadratic form in the second moments of the blocks'
//! sums ([`InstrumentedWindows::fresh_estimate`]).

use super::moments::{Moments, upper};
use super::{InstrumentedWindows, Layout, Solve, WindowEstimate};

/// A span's first-order statistics fell below this share of their magnitude (the sum of the
/// absolute terms of the quadratic form): the difference of the segment sums may have lost
/// the digits, and the caller falls back to a pass over the blocks.
pub(super) const CANCELLATION: f64 = 1e-9;

/// `cᵀ M r` and the sum of its terms' magnitudes, `M` symmetric `n × n` given by its upper
/// triangle row by row.
#[inline(always)]
fn quadratic_upper(m: &[f64], n: usize, c: &[f64], r: &[f64]) -> (f64, f64) {
    let (mut v, mut mag) = (0.0, 0.0);
    let mut at = 0;
    for a in 0..n {
        let row = &m[at..at + n - a];
        at += n - a;
        let (ca, ra) = (c[a], r[a]);
        let diag = ca * ra * row[0];
        v += diag;
        mag += diag.abs();
        for ((&u, &cb), &rb) in row[1..].iter().zip(&c[a + 1..]).zip(&r[a + 1..]) {
            let t = u * (ca * rb + cb * ra);
            v += t;
            mag += u.abs() * ((ca * rb).abs() + (cb * ra).abs());
        }
    }
    (v, mag)
}

impl InstrumentedWindows {
    /// A first-order estimate of window `w`'s blocks older than its newest `skip`, in `O(1)`
    /// of the window's length: for a comparison that spends no risk (the calibrated
    /// certificate's change guard), not for a certificate. With the span's sums from the
    /// segment sums (module docs), the solve of [`estimate`](Self::estimate) (the same `Θ̂`,
    /// `ν` weights and refusals but the leverage), and in place of the delete-one-block
    /// changes the first-order influence of each block,
    ///
    /// ```text
    /// G_j = r_j Q A⁻¹,   r_j = Cw_j − Θ̂ N_j,   S_j = vec(sym(G_j T)) = C v_j
    /// Ω̂ = c_h · B/(B − d) · Σ_j S_j S_jᵀ = c_h · B/(B − d) · C (Σ_j v_j v_jᵀ) Cᵀ
    /// Σ_j w_j = ⟨Σ_j H_j, X Xᵀ⟩,   Σ_j w_j² = mᵀ (Σ_j h_j h_jᵀ) m
    /// ```
    ///
    /// (`v_j = [vec N_j; vec Cw_j]`, `C` linear in `Θ̂` and `X`, `h_j` the distinct entries of
    /// `H_j` and `m` their weights in `tr(Xᵀ H_j X)`), and the exact-identity refusal on
    /// `Σ_j ‖r_j‖²` from the same moments. The first-order variance is the one the
    /// certificate used before the jackknife: without the leverage, `B/(B − d)` for the
    /// fitted directions. Where a quadratic form falls below `10⁻⁹` (`CANCELLATION`) of its
    /// magnitude, or with batches of more than one block, or without
    /// [`with_moments`](Self::with_moments), it is [`estimate`](Self::estimate)'s pass over
    /// the blocks instead (the jackknife). `out.leverage_pivot` is 1 (not computed).
    pub fn fresh_estimate(
        &mut self,
        w: usize,
        skip: usize,
        solve: Solve<'_>,
        out: &mut WindowEstimate,
    ) {
        let span = self.span(w, skip);
        if self.batch != 1 || self.moments.is_none() {
            self.estimate_older(w, skip, solve, out);
            return;
        }
        let Some(mut mo) = self.moments.take() else { return };
        let mut record = std::mem::take(&mut mo.span);
        self.segment_span(&mo, span, mo.len, &mut record);
        mo.span = record;
        let stride = self.layout().stride();
        out.sums.copy_from_slice(&mo.span[..stride]);
        let blocks = span.0.saturating_sub(span.1);
        let solved = self.solve_sums(blocks, solve, out);
        let exact = solved && !self.first_order(&mut mo, blocks, solve.rate.symmetric_part(), out);
        self.moments = Some(mo);
        if exact {
            self.estimate_older(w, skip, solve, out);
        }
    }

    /// The first-order statistics of [`fresh_estimate`](Self::fresh_estimate) after a solve;
    /// `false` where cancellation is detected (the caller then takes the exact pass).
    fn first_order(
        &self,
        mo: &mut Moments,
        blocks: usize,
        t: &[f64],
        out: &mut WindowEstimate,
    ) -> bool {
        let lay = self.layout();
        match (lay.p, lay.d, lay.k) {
            (1, 2, 2) => self.first_order_dims(mo, blocks, t, out, (1, 2, 2)),
            (1, 3, 3) => self.first_order_dims(mo, blocks, t, out, (1, 3, 3)),
            dims => self.first_order_dims(mo, blocks, t, out, dims),
        }
    }

    /// [`first_order`](Self::first_order) with the dimensions passed in: literal for the
    /// single-output shapes through the origin and with the intercept, so that the compiler
    /// unrolls the quadratic forms (the same operations in the same order, so the same bits).
    #[inline(always)]
    fn first_order_dims(
        &self,
        mo: &mut Moments,
        blocks: usize,
        t: &[f64],
        out: &mut WindowEstimate,
        (p, d, k): (usize, usize, usize),
    ) -> bool {
        let lay = Layout { p, d, k };
        let (nv, nh, pp) = ((d + p) * k, k * (k + 1) / 2, p * p);
        debug_assert_eq!((nv, nh), (mo.nv, mo.nh));
        let stride = lay.stride();
        // Σ v vᵀ, its upper triangle row by row.
        let m2 = &mo.span[stride..stride + nv * (nv + 1) / 2];
        let mh = stride + nv * (nv + 1) / 2;
        // X' = Q A⁻¹ T (k × p), as the block pass forms `G_j T` (the raw `T`).
        product(&out.qa[..k * d], t, &mut mo.xt, (k, d, p));
        // C: row (i, jj) of sym(G T); G T[i][jj] = Σ_b r[i][b] X'[b][jj].
        mo.coef.fill(0.0);
        for i in 0..p {
            for jj in 0..p {
                let row = &mut mo.coef[(i * p + jj) * nv..(i * p + jj + 1) * nv];
                for (src, dst, half) in [(i, jj, 0.5), (jj, i, 0.5)] {
                    // ½ (G T)[src][dst]: the symmetric part (both halves the same entry
                    // when src = dst).
                    for b in 0..k {
                        let x = half * mo.xt[b * p + dst];
                        row[d * k + src * k + b] += x;
                        for c in 0..d {
                            row[c * k + b] -= out.theta[src * d + c] * x;
                        }
                    }
                }
            }
        }
        // Ω̂ = c_h B/(B − d) C M2 Cᵀ, with the magnitude of each diagonal entry.
        let scale = super::batch::overlap_factor(1, self.horizon) * blocks as f64
            / (blocks as f64 - d as f64);
        for s in 0..pp {
            for r in s..pp {
                let (cs, cr) = (&mo.coef[s * nv..(s + 1) * nv], &mo.coef[r * nv..(r + 1) * nv]);
                let (v, mag) = quadratic_upper(m2, nv, cs, cr);
                if s == r && !(v > CANCELLATION * mag) {
                    return false;
                }
                out.score_cov[s * pp + r] = v * scale;
                out.score_cov[r * pp + s] = v * scale;
            }
        }
        let (residual, raw, mag) = residual_moments(m2, nv, &out.theta, (p, d, k));
        if !(residual > CANCELLATION * mag) {
            return false;
        }
        // ν's weights: w_j = ⟨H_j, X Xᵀ⟩ over the distinct entries of H_j.
        let x = &out.x[..p * k];
        let mut c = 0;
        for a in 0..k {
            for b in a..k {
                let mut v = 0.0;
                for xi in x.chunks_exact(k) {
                    v += xi[a] * xi[b];
                }
                mo.wh[c] = if a == b { v } else { 2.0 * v };
                c += 1;
            }
        }
        let hsum = &mo.span[lay.h()..stride];
        let mut sum_w = 0.0;
        let mut c = 0;
        for a in 0..k {
            for b in a..k {
                sum_w += mo.wh[c] * hsum[a * k + b];
                c += 1;
            }
        }
        let mut sum_w2 = 0.0;
        for a in 0..nh {
            for b in a..nh {
                let m = mo.span[mh + upper(a, b, nh)];
                sum_w2 +=
                    if a == b { m * mo.wh[a] * mo.wh[a] } else { 2.0 * m * mo.wh[a] * mo.wh[b] };
            }
        }
        out.effective_blocks = if sum_w2 > 0.0 { sum_w * sum_w / sum_w2 } else { 0.0 };
        out.leverage_pivot = 1.0;
        let finite = out.theta.iter().chain(&out.score_cov[..pp * pp]).all(|v| v.is_finite());
        out.ready = finite && residual > super::MIN_RESIDUAL_SHARE * raw;
        true
    }
}

/// The exact-identity refusal's moments from the span's `Σ v vᵀ` (`m2`, upper triangle of
/// `nv`): `(Σ_j ‖r_j‖², Σ_j ‖Cw_j‖², the residual's magnitude)`, each `r_{j,ib}` the
/// combination of `Cw_{j,ib}` (coefficient 1) and `N_{j,cb}` (coefficient −θ̂_ic).
#[inline(always)]
fn residual_moments(
    m2: &[f64],
    nv: usize,
    theta: &[f64],
    (p, d, k): (usize, usize, usize),
) -> (f64, f64, f64) {
    let (mut residual, mut raw, mut mag) = (0.0, 0.0, 0.0);
    for i in 0..p {
        for b in 0..k {
            let ci = d * k + i * k + b;
            let th = &theta[i * d..(i + 1) * d];
            // Σ_a c_a M2[a][·] c over the d + 1 entries (a = N_cb for c < d, then Cw_ib).
            for a in 0..=d {
                let (ia, ca) = if a < d { (a * k + b, -th[a]) } else { (ci, 1.0) };
                for bb in 0..=d {
                    let (ib, cb) = if bb < d { (bb * k + b, -th[bb]) } else { (ci, 1.0) };
                    let term = ca * m2[upper(ia.min(ib), ia.max(ib), nv)] * cb;
                    residual += term;
                    mag += term.abs();
                }
            }
            raw += m2[upper(ci, ci, nv)];
        }
    }
    (residual, raw, mag)
}

/// `out = a b` for `a` (`k × d`) and `b` (`d × p`), row-major (each entry summed over `d` in
/// order).
#[inline(always)]
pub(super) fn product(a: &[f64], b: &[f64], out: &mut [f64], (k, d, p): (usize, usize, usize)) {
    for r in 0..k {
        for j in 0..p {
            let mut v = 0.0;
            for c in 0..d {
                v += a[r * d + c] * b[c * p + j];
            }
            out[r * p + j] = v;
        }
    }
}
