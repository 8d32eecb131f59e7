//! The scalar path's steps (`p = m = 1`, the ordinary estimator): the interval regressors and
//! the affine sums in registers, inlined into [`SlidingRegression::push`].

use super::{SlidingRegression, next};
use crate::{InputIntegral, RegressionError};

impl SlidingRegression {
    /// The scalar path's interval regressors `[∫y, ∫u]` of the interval ending at this sample
    /// (relative to the working origin; zero through the origin: the same bits), stored in
    /// the ring, and `ΔY` of the interval; zeros for the first sample.
    #[inline(always)]
    pub(super) fn scalar_interval(
        &mut self,
        t: f64,
        y: f64,
        u: f64,
    ) -> Result<[f64; 2], RegressionError> {
        let cap = self.cfg.horizon + 1;
        let zoh = self.cfg.input_integral == InputIntegral::ZeroOrderHold;
        let (oy, ou) = (self.origin[0], self.origin[1]);
        if self.hist_len == 0 {
            self.hist_head = 0;
            return Ok([0.0; 2]);
        }
        let prev = self.hist_head;
        let t0 = self.hist_t[prev];
        if t <= t0 {
            return Err(RegressionError::NonIncreasingTime { previous: t0, got: t });
        }
        let (y0, u0) = (self.hist_y[prev], self.hist_u[prev]);
        let k = next(prev, cap);
        let dt = t - t0;
        let half = 0.5 * dt;
        // Relative to the working origin (zero through the origin: the same bits).
        let (ya, yb, ua, ub) = (y0 - oy, y - oy, u0 - ou, u - ou);
        let z1 = [half * (ya + yb), if zoh { dt * ua } else { half * (ua + ub) }];
        self.hist_z1[2 * k..2 * k + 2].copy_from_slice(&z1);
        self.hist_z1[2 * (k + cap)..2 * (k + cap) + 2].copy_from_slice(&z1);
        self.dy1[0] = y - y0;
        self.hist_head = k;
        Ok(z1)
    }

    /// The scalar path's affine sums in registers: the evicted column's products out, the new
    /// column's `(∫y, ∫u, ΔY)` times its span `τ` in (the same operations as
    /// `affine_column`: the same bits).
    #[inline(always)]
    pub(super) fn scalar_affine(&mut self, q: usize, tau: f64, (zy, zu, dy): (f64, f64, f64)) {
        let (mut z0, mut z1, mut d0, mut tt) = (self.zt[0], self.zt[1], self.dyt[0], self.tt);
        if self.col_len == self.cfg.window {
            let ot = self.col_tau[q];
            let (o0, o1, od) = (self.col_z[2 * q], self.col_z[2 * q + 1], self.col_dy[q]);
            let mt = -ot;
            z0 += o0 * mt;
            z1 += o1 * mt;
            d0 += od * mt;
            tt += mt * ot;
        }
        z0 += zy * tau;
        z1 += zu * tau;
        d0 += dy * tau;
        tt += tau * tau;
        (self.zt[0], self.zt[1], self.dyt[0], self.tt) = (z0, z1, d0, tt);
        self.col_tau[q] = tau;
    }
}
