//! The affine model's part of the update (see [`Model::Affine`](crate::Model::Affine)): the
//! working origin and each column's `τ`-weighted sums.

use super::SlidingRegression;
use crate::Estimator;

impl SlidingRegression {
    /// Set the working origin to this sample's `[y; u]` (affine model; once since
    /// construction).
    #[cold]
    pub(super) fn set_origin(&mut self, y: &[f64], u: &[f64]) {
        if self.affine() {
            for (o, &v) in self.origin.iter_mut().zip(y.iter().chain(u)) {
                *o = v;
            }
            self.origin_set = true;
        }
    }

    /// Add `sign ×` the column in slot `q`'s affine sums: `Z τ_w`, `ΔY τ_w`, `τ τ_w`, and
    /// `W τ` for the instrumented estimator, whose intercept regressor `τ` is instrumented by
    /// the instrument's own span `τ_w` (so that `W` in working coordinates,
    /// `W − origin · τ_w`, spans what the recorded `W` spans, and the estimate does not depend
    /// on the origin under irregular sampling); `τ_w = τ` for the ordinary estimator.
    #[inline(always)]
    pub(super) fn affine_column(&mut self, q: usize, sign: f64) {
        let (p, d) = (self.cfg.outputs, self.d());
        let instrumented = self.cfg.estimator == Estimator::Instrumented;
        let tau = self.col_tau[q];
        let tau_w = if instrumented { self.col_tauw[q] } else { tau };
        let (tz, tw) = (sign * tau, sign * tau_w);
        for (a, &z) in self.zt.iter_mut().zip(&self.col_z[q * d..(q + 1) * d]) {
            *a += z * tw;
        }
        for (a, &v) in self.dyt.iter_mut().zip(&self.col_dy[q * p..(q + 1) * p]) {
            *a += v * tw;
        }
        self.tt += tz * tau_w;
        if instrumented {
            for (a, &w) in self.wt.iter_mut().zip(&self.col_w[q * d..(q + 1) * d]) {
                *a += w * tz;
            }
            for (a, &z) in self.zto.iter_mut().zip(&self.col_z[q * d..(q + 1) * d]) {
                *a += z * tz;
            }
            for (a, &v) in self.dyto.iter_mut().zip(&self.col_dy[q * p..(q + 1) * p]) {
                *a += v * tz;
            }
            self.tto += tz * tau;
        }
    }
}
