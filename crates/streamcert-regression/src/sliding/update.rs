//! The per-sample update: sample checks, interval and column construction, the `O(d²)`
//! add-and-evict update of the sufficient statistics, and their exact periodic refresh.

use super::{SlidingRegression, copy, finite3, next};
use crate::{Estimator, FastPath, InputIntegral, RegressionError, linalg};

impl SlidingRegression {
    /// Absorb one sample `(t, y, u)`: `O(h d + d²)`, no allocation.
    ///
    /// # Errors
    /// A sample error from [`check_sample`](Self::check_sample) leaves the state untouched.
    /// [`RegressionError::Overflow`] means finite samples overflowed a column or the window's
    /// sums; the window was cleared so no estimate is built on it.
    pub fn push(&mut self, t: f64, y: &[f64], u: &[f64]) -> Result<(), RegressionError> {
        if let (FastPath::Scalar, &[y], &[u]) = (self.fast_path(), y, u)
            && self.cfg.estimator == Estimator::Ordinary
        {
            return self.push_scalar(t, y, u);
        }
        self.push_dims(t, y, u, self.cfg.outputs, self.cfg.inputs)
    }

    /// [`push`](Self::push) for the paper's case `p = m = 1` with the ordinary estimator:
    /// the same arithmetic as the general path in the same order (so the same bits), written
    /// out for scalars so that the per-sample cost is a few dozen instructions.
    #[inline(always)]
    fn push_scalar(&mut self, t: f64, y: f64, u: f64) -> Result<(), RegressionError> {
        if !finite3(t, y, u) {
            // Reports which value is bad; it always fails here.
            self.check_sample(t, &[y], &[u])?;
        }
        let cap = self.cfg.horizon + 1;
        if !self.origin_set {
            self.set_origin(&[y], &[u]);
        }
        // This sample's interval regressors, kept in registers for the column below.
        let newest = self.scalar_interval(t, y, u)?;
        let k = self.hist_head;
        self.hist_t[k] = t;
        self.hist_y[k] = y;
        self.hist_u[k] = u;
        self.range.push([y, u]);
        self.hist_len = (self.hist_len + 1).min(cap);
        if self.hist_len < cap {
            return Ok(());
        }
        // The column: the `h` interval regressors after the oldest sample, oldest first. The
        // last is this sample's, added from registers rather than read back from the ring
        // (the same additions in the same order: the same bits). The pair was just stored
        // as two numbers, and a load of both at once is not forwarded from two stores: it
        // waited for them to reach the cache: 23.5 → 16 ns per update
        // (`examples/step_profile update`, 2·10⁷ samples).
        let oldest = next(k, cap);
        let (mut zy, mut zu) = (0.0, 0.0);
        for pair in self.hist_z1[2 * (oldest + 1)..2 * (oldest + cap - 1)].chunks_exact(2) {
            zy += pair[0];
            zu += pair[1];
        }
        zy += newest[0];
        zu += newest[1];
        let dy = y - self.hist_y[oldest];
        if !finite3(zy, zu, dy) {
            self.reset();
            return Err(RegressionError::Overflow);
        }
        let q = self.col_next;
        if self.affine() {
            self.scalar_affine(q, t - self.hist_t[oldest], (zy, zu, dy));
        }
        let (g, c, s) = (&mut self.g[..4], &mut self.c[..2], &mut self.s[..1]);
        let zo = &mut self.col_z[2 * q..2 * q + 2];
        let dyo = &mut self.col_dy[q..=q];
        if self.col_len == self.cfg.window {
            let (o0, o1, od) = (zo[0], zo[1], dyo[0]);
            g[0] += zy * zy - o0 * o0;
            g[1] += zy * zu - o0 * o1;
            g[3] += zu * zu - o1 * o1;
            c[0] += dy * zy - od * o0;
            c[1] += dy * zu - od * o1;
            s[0] += dy * dy - od * od;
        } else {
            g[0] += zy * zy;
            g[1] += zy * zu;
            g[3] += zu * zu;
            c[0] += dy * zy;
            c[1] += dy * zu;
            s[0] += dy * dy;
        }
        zo.copy_from_slice(&[zy, zu]);
        dyo[0] = dy;
        let finite = finite3(g[0], g[3], s[0]);
        let diagonals = [g[0], g[3], s[0]];
        if !(finite && self.tt.is_finite()) {
            self.reset();
            return Err(RegressionError::Overflow);
        }
        let dropped = dropped_below_peak(&mut self.peaks[..3], diagonals);
        self.finish_column(q, dropped)
    }

    /// [`push`](Self::push) with the configured dimensions passed in.
    #[inline(always)]
    fn push_dims(
        &mut self,
        t: f64,
        y: &[f64],
        u: &[f64],
        p: usize,
        m: usize,
    ) -> Result<(), RegressionError> {
        self.check_sample(t, y, u)?;
        if !self.origin_set {
            self.set_origin(y, u);
        }
        let h = self.cfg.horizon;
        let d = p + m;
        let cap = h + 1;
        self.hist_head = if self.hist_len == 0 { 0 } else { next(self.hist_head, cap) };
        let k = self.hist_head;
        self.hist_t[k] = t;
        copy(&mut self.hist_y[k * p..(k + 1) * p], y);
        copy(&mut self.hist_u[k * m..(k + 1) * m], u);
        self.range.push(y.iter().chain(u).copied());
        self.hist_len = (self.hist_len + 1).min(cap);
        if self.hist_len >= 2 {
            self.build_interval(p, m);
        }
        if self.hist_len < cap {
            return Ok(());
        }
        self.build_column(p, m);
        let mut finite = true;
        for v in self.z[..d].iter().chain(&self.dy[..p]) {
            finite &= v.is_finite();
        }
        if !finite {
            self.reset();
            return Err(RegressionError::Overflow);
        }
        if self.cfg.estimator == Estimator::Instrumented {
            self.zhist_head = if self.zhist_len == 0 { 0 } else { next(self.zhist_head, cap) };
            let q = self.zhist_head;
            self.zhist[q * d..(q + 1) * d].copy_from_slice(&self.z);
            self.zhist_tau[q] = self.tau;
            self.zhist_len = (self.zhist_len + 1).min(cap);
            if self.zhist_len < cap {
                return Ok(());
            }
        }
        self.insert_column(p, d)
    }

    /// The newest interval `[t_{k−1}, t_k]`: its regressor `[∫y; ∫u]` by the configured rules
    /// into the interval ring, and `dy1 = y_k − y_{k−1}`.
    #[inline(always)]
    fn build_interval(&mut self, p: usize, m: usize) {
        let (d, cap) = (p + m, self.cfg.horizon + 1);
        let b = self.hist_head;
        let a = if b == 0 { cap - 1 } else { b - 1 };
        let dt = self.hist_t[b] - self.hist_t[a];
        let half = 0.5 * dt;
        let (first, mirror) = self.hist_z1.split_at_mut(cap * d);
        let z1 = &mut first[b * d..(b + 1) * d];
        // Relative to the working origin (zero through the origin: the same bits).
        let origin = &self.origin[..d];
        for i in 0..p {
            let (ya, yb) = (self.hist_y[a * p + i], self.hist_y[b * p + i]);
            z1[i] = half * ((ya - origin[i]) + (yb - origin[i]));
            self.dy1[i] = yb - ya;
        }
        let zoh = self.cfg.input_integral == InputIntegral::ZeroOrderHold;
        for j in 0..m {
            let (ua, ub) =
                (self.hist_u[a * m + j] - origin[p + j], self.hist_u[b * m + j] - origin[p + j]);
            z1[p + j] = if zoh { dt * ua } else { half * (ua + ub) };
        }
        mirror[b * d..(b + 1) * d].copy_from_slice(z1);
    }

    /// Build `z = [∫y; ∫u]` (the sum of the last `h` interval regressors, oldest first) and
    /// `dy = y_new − y_old`.
    #[inline(always)]
    fn build_column(&mut self, p: usize, m: usize) {
        let d = p + m;
        let cap = self.cfg.horizon + 1;
        let newest = self.hist_head;
        let oldest = next(newest, cap);
        let z = &mut self.z[..d];
        z.fill(0.0);
        // The `h` intervals after the oldest sample, oldest first: one contiguous run of the
        // mirrored ring.
        for interval in self.hist_z1[(oldest + 1) * d..(oldest + cap) * d].chunks_exact(d) {
            for (zi, &vi) in z.iter_mut().zip(interval) {
                *zi += vi;
            }
        }
        self.tau = self.hist_t[newest] - self.hist_t[oldest];
        let (yn, yo) = (&self.hist_y[newest * p..(newest + 1) * p], &self.hist_y[oldest * p..]);
        for ((d, &vn), &vo) in self.dy[..p].iter_mut().zip(yn).zip(yo) {
            *d = vn - vo;
        }
    }

    /// Add `sign ×` the outer products of the column in slot `q` to the statistics.
    fn accumulate(&mut self, q: usize, sign: f64) {
        let (p, d) = (self.cfg.outputs, self.d());
        let z = &self.col_z[q * d..(q + 1) * d];
        let dy = &self.col_dy[q * p..(q + 1) * p];
        for (i, &zi) in z.iter().enumerate() {
            let zi = sign * zi;
            let row = &mut self.g[i * d..(i + 1) * d];
            for (g, &zj) in row[i..].iter_mut().zip(&z[i..]) {
                *g += zi * zj;
            }
        }
        for (i, &di) in dy.iter().enumerate() {
            let di = sign * di;
            for (c, &zj) in self.c[i * d..(i + 1) * d].iter_mut().zip(z) {
                *c += di * zj;
            }
            for (s, &dj) in self.s[i * p + i..(i + 1) * p].iter_mut().zip(&dy[i..]) {
                *s += di * dj;
            }
        }
        if self.cfg.estimator == Estimator::Instrumented {
            let w = &self.col_w[q * d..(q + 1) * d];
            for (i, &zi) in z.iter().enumerate() {
                let zi = sign * zi;
                for (g, &wj) in self.gw[i * d..(i + 1) * d].iter_mut().zip(w) {
                    *g += zi * wj;
                }
            }
            for (i, &di) in dy.iter().enumerate() {
                let di = sign * di;
                for (c, &wj) in self.cw[i * d..(i + 1) * d].iter_mut().zip(w) {
                    *c += di * wj;
                }
            }
        }
    }

    /// `true` when the running sums are finite. By Cauchy–Schwarz the diagonals of `G` and
    /// `S` bound `C`; the instrumented sums are checked whole.
    #[inline(always)]
    fn statistics_finite(&self, p: usize, d: usize) -> bool {
        (0..d).all(|i| self.g[i * d + i].is_finite())
            && (0..p).all(|i| self.s[i * p + i].is_finite())
            && self.tt.is_finite()
            && (self.cfg.estimator == Estimator::Ordinary
                || self.gw.iter().chain(self.cw.iter()).all(|v| v.is_finite()))
    }

    #[inline(always)]
    fn insert_column(&mut self, p: usize, d: usize) -> Result<(), RegressionError> {
        let mm = self.cfg.window;
        let q = self.col_next;
        let instrumented = self.cfg.estimator == Estimator::Instrumented;
        let affine = self.affine();
        if affine && self.col_len == mm {
            self.affine_column(q, -1.0);
        }
        if instrumented {
            let cap = self.cfg.horizon + 1;
            let oldest = next(self.zhist_head, cap);
            // The evicted column's instrument must leave the sums before it is overwritten.
            if self.col_len == mm {
                self.accumulate(q, -1.0);
            }
            self.col_z[q * d..(q + 1) * d].copy_from_slice(&self.z);
            self.col_dy[q * p..(q + 1) * p].copy_from_slice(&self.dy);
            self.col_w[q * d..(q + 1) * d]
                .copy_from_slice(&self.zhist[oldest * d..(oldest + 1) * d]);
            self.col_tauw[q] = self.zhist_tau[oldest];
            self.accumulate(q, 1.0);
        } else if self.col_len == mm {
            self.replace_column(q, p, d);
        } else {
            self.col_z[q * d..(q + 1) * d].copy_from_slice(&self.z);
            self.col_dy[q * p..(q + 1) * p].copy_from_slice(&self.dy);
            self.accumulate(q, 1.0);
        }
        if affine {
            self.col_tau[q] = self.tau;
            self.affine_column(q, 1.0);
        }
        if !self.statistics_finite(p, d) {
            self.reset();
            return Err(RegressionError::Overflow);
        }
        let dropped = self.magnitude_dropped();
        self.finish_column(q, dropped)
    }

    /// Advance the column ring past slot `q` and refresh the statistics when due (or when
    /// `dropped`, see [`dropped_below_peak`]).
    #[inline(always)]
    fn finish_column(&mut self, q: usize, dropped: bool) -> Result<(), RegressionError> {
        let mm = self.cfg.window;
        self.built += 1;
        self.col_next = next(q, mm);
        self.col_len = (self.col_len + 1).min(mm);
        self.since_refresh += 1;
        if self.since_refresh >= self.cfg.refresh_period || dropped {
            self.refresh();
        }
        Ok(())
    }

    /// [`dropped_below_peak`] over the diagonals of `G` then of `S`.
    #[inline(always)]
    fn magnitude_dropped(&mut self) -> bool {
        let (p, d) = (self.cfg.outputs, self.d());
        let (g_peaks, s_peaks) = self.peaks.split_at_mut(d);
        // The diagonals by stepping (no index to check), `G`'s then `S`'s.
        let g = dropped_below_peak(g_peaks, self.g.iter().step_by(d + 1).take(d).copied());
        let s = dropped_below_peak(s_peaks, self.s.iter().step_by(p + 1).take(p).copied());
        g | s
    }

    /// One pass that adds the new column (`self.z`, `self.dy`) and removes the one in slot
    /// `q`, then stores the new column in slot `q` (ordinary estimator). `p`, `d` are the
    /// configured dimensions, passed in so call sites with literals get unrolled code.
    #[inline(always)]
    fn replace_column(&mut self, q: usize, p: usize, d: usize) {
        // Views of exactly the configured lengths: with literal `p`, `d` every index below is
        // a constant the compiler proves in bounds.
        let (z, dy) = (&self.z[..d], &self.dy[..p]);
        let (g, c, s) = (&mut self.g[..d * d], &mut self.c[..p * d], &mut self.s[..p * p]);
        let zo = &mut self.col_z[q * d..(q + 1) * d];
        let dyo = &mut self.col_dy[q * p..(q + 1) * p];
        for i in 0..d {
            let (zi, oi) = (z[i], zo[i]);
            let row = &mut g[i * d..(i + 1) * d];
            for j in i..d {
                row[j] += zi * z[j] - oi * zo[j];
            }
        }
        for i in 0..p {
            let (di, oi) = (dy[i], dyo[i]);
            let row = &mut c[i * d..(i + 1) * d];
            for j in 0..d {
                row[j] += di * z[j] - oi * zo[j];
            }
            let row = &mut s[i * p..(i + 1) * p];
            for j in i..p {
                row[j] += di * dy[j] - oi * dyo[j];
            }
        }
        copy(zo, z);
        copy(dyo, dy);
    }

    /// Recompute every statistic exactly from the column ring (`O(M d²)`), discarding the
    /// rounding drift of the incremental updates. Called automatically every
    /// `refresh_period` columns.
    pub fn refresh(&mut self) {
        for v in [&mut self.g, &mut self.c, &mut self.s, &mut self.gw, &mut self.cw] {
            v.fill(0.0);
        }
        self.clear_affine();
        let mm = self.cfg.window;
        // Oldest to newest, so the sums are formed in a fixed order: the ring holds the
        // window as [start, mm) followed by [0, start) when it has wrapped.
        let start = (self.col_next + mm - self.col_len) % mm;
        let first = (mm - start).min(self.col_len);
        if self.cfg.estimator == Estimator::Ordinary {
            let (p, d) = (self.cfg.outputs, self.d());
            if self.fast_path() == FastPath::Scalar {
                self.sum_scalar_columns(start, first);
                self.sum_scalar_columns(0, self.col_len - first);
            } else {
                self.sum_columns(start, first, p, d);
                self.sum_columns(0, self.col_len - first, p, d);
            }
        } else {
            for k in 0..self.col_len {
                self.accumulate((start + k) % mm, 1.0);
            }
        }
        if self.affine() {
            for k in 0..self.col_len {
                self.affine_column((start + k) % mm, 1.0);
            }
        }
        self.since_refresh = 0;
        let (p, d) = (self.cfg.outputs, self.d());
        for i in 0..d {
            self.peaks[i] = self.g[i * d + i];
        }
        for i in 0..p {
            self.peaks[d + i] = self.s[i * p + i];
        }
    }

    /// [`sum_columns`](Self::sum_columns) for `p = 1`, `d = 2`: the six sums in locals (the
    /// same additions in the same order, so the same bits), written back once.
    fn sum_scalar_columns(&mut self, from: usize, count: usize) {
        let zs = self.col_z[2 * from..2 * (from + count)].chunks_exact(2);
        let dys = &self.col_dy[from..from + count];
        let (mut g0, mut g1, mut g3) = (self.g[0], self.g[1], self.g[3]);
        let (mut c0, mut c1, mut s0) = (self.c[0], self.c[1], self.s[0]);
        for (z, &dy) in zs.zip(dys) {
            let (z0, z1) = (z[0], z[1]);
            g0 += z0 * z0;
            g1 += z0 * z1;
            g3 += z1 * z1;
            c0 += dy * z0;
            c1 += dy * z1;
            s0 += dy * dy;
        }
        (self.g[0], self.g[1], self.g[3]) = (g0, g1, g3);
        (self.c[0], self.c[1], self.s[0]) = (c0, c1, s0);
    }

    /// Add the outer products of the contiguous slots `[from, from + count)` (ordinary
    /// statistics only; in vectors from `d = 8`, the same bits, see
    /// [`linalg::add_outer_products`]).
    #[inline(always)]
    fn sum_columns(&mut self, from: usize, count: usize, p: usize, d: usize) {
        let zs = &self.col_z[from * d..(from + count) * d];
        let dys = &self.col_dy[from * p..(from + count) * p];
        linalg::add_outer_products(zs, dys, (&mut self.g, &mut self.c, &mut self.s), p, d);
    }
}

/// Track the peak of each diagonal running sum since the last recompute; `true` when one has
/// fallen below `10⁻⁶` of its peak. A burst that left the window was removed by a subtraction
/// whose rounding error is of order `ε · peak`: past a `10⁶` drop that error is no longer
/// small against what remains, so the sums are recomputed at once. (Every peak is updated;
/// the scalar path passes its three diagonals as an array, which the compiler unrolls.)
#[inline(always)]
fn dropped_below_peak(peaks: &mut [f64], diagonals: impl IntoIterator<Item = f64>) -> bool {
    const DROP: f64 = 1e-6;
    let mut dropped = false;
    for (peak, v) in peaks.iter_mut().zip(diagonals) {
        if v > *peak {
            *peak = v;
        } else if v < *peak * DROP {
            dropped = true;
        }
    }
    dropped
}

#[cfg(test)]
mod tests;
