//! Solving the window: `Θ̂` by Cholesky (ridge) or LU (instrumented), the excitation test,
//! `RMS(R)` from the sufficient statistics, and residuals over the newest interval or column.

use super::SlidingRegression;

/// From this width `d = p + m` on, the ordinary solve takes every output row in one pass and
/// reads `RSS` off the forward substitution ([`SlidingRegression::solve_wide`]); below it the
/// row-by-row solve and the quadratic-form `RSS` are kept, so the paper's and the validity
/// study's small regressions give what they gave bit for bit.
const WIDE_FROM: usize = 8;
use crate::{Estimate, EstimateStatus, Estimator, FastPath, ResidualSource, linalg};

impl SlidingRegression {
    /// Residual `out ← ΔY − Θ̂ Z` (length `p`) over the chosen interval, with the `Θ̂` of the
    /// latest [`estimate`](Self::estimate) call. Call it only after an estimate whose status
    /// was [`EstimateStatus::Ready`]; returns `false` (leaving `out` alone) when the interval
    /// does not exist yet.
    #[inline(always)]
    pub fn residual(&self, source: ResidualSource, out: &mut [f64]) -> bool {
        // Literal dimensions for the paper's p = m = 1 let the compiler unroll the products.
        if self.fast_path() == FastPath::Scalar {
            self.residual_dims(source, out, 1, 2)
        } else {
            self.residual_dims(source, out, self.cfg.outputs, self.d())
        }
    }

    /// [`residual`](Self::residual) with the configured dimensions passed in.
    #[inline(always)]
    fn residual_dims(&self, source: ResidualSource, out: &mut [f64], p: usize, d: usize) -> bool {
        let pair = match source {
            ResidualSource::OneStep => self.newest_interval(),
            ResidualSource::Horizon => self.newest_column(),
        };
        let Some((z, dy)) = pair else { return false };
        let (z, dy, theta) = (&z[..d], &dy[..p], &self.theta[..p * d]);
        for ((o, &dyi), th) in out[..p].iter_mut().zip(dy).zip(theta.chunks_exact(d)) {
            *o = dyi - th.iter().zip(z).map(|(a, b)| a * b).sum::<f64>();
        }
        if self.affine() {
            // − ĉ τ over the same interval.
            let span = match source {
                ResidualSource::OneStep => self.newest_interval_span(),
                ResidualSource::Horizon => self.newest_column_span(),
            };
            let tau = span.unwrap_or(0.0);
            for (o, &c) in out[..p].iter_mut().zip(&self.intercept[..p]) {
                *o -= c * tau;
            }
        }
        true
    }

    /// Solve the window: `O(d³ + p d²)`, no allocation. Under the affine model the solve
    /// sees the centred statistics (see [`Model::Affine`](crate::Model::Affine)) and
    /// [`Estimate::intercept`] is `ĉ = (a_y − Θ̂ a_z)/T`.
    #[inline]
    pub fn estimate(&mut self) -> Estimate<'_> {
        let affine = self.affine();
        if affine {
            self.enter_centred();
        }
        let mut out = self.estimate_raw();
        if affine {
            self.leave_centred(&mut out);
        }
        self.attach(out)
    }

    /// The estimate without its borrowed vectors (the solve on whatever statistics are in
    /// place).
    #[inline(always)]
    fn estimate_raw(&mut self) -> Estimate<'static> {
        if self.fast_path() == FastPath::Scalar {
            self.estimate_dims(1, 1)
        } else {
            self.estimate_dims(self.cfg.outputs, self.cfg.inputs)
        }
    }

    /// `out` with `Θ̂` and `ĉ` attached when it is ready.
    #[inline(always)]
    fn attach(&self, out: Estimate<'static>) -> Estimate<'_> {
        if out.status != EstimateStatus::Ready {
            return out;
        }
        let (p, d) = (self.cfg.outputs, self.d());
        let intercept: &[f64] = if self.affine() { &self.intercept[..p] } else { &[] };
        Estimate { theta: &self.theta[..p * d], intercept, ..out }
    }

    /// Put the centred statistics `G − a_z a_zᵀ/T`, `C − a_y a_zᵀ/T`, `S − a_y a_yᵀ/T` (and
    /// the instrumented `ZWᵀ − a_z a_wᵀ/T`, `ΔYWᵀ − a_y a_wᵀ/T`) where the solve reads the
    /// running sums (the buffers are swapped, no copy back). `O(d²)`. With `T = 0` (no
    /// column) the sums are left as they are (the estimate is then warming up).
    #[inline(always)]
    fn enter_centred(&mut self) {
        if self.fast_path() == FastPath::Scalar && self.cfg.estimator == Estimator::Ordinary {
            // p = m = 1, ordinary: the same arithmetic as the general loops below, in
            // registers (the paper's case, every sample).
            let inv = if self.tt > 0.0 { 1.0 / self.tt } else { 0.0 };
            let (z0, z1, y0) = (self.zt[0], self.zt[1], self.dyt[0]);
            let (a0, a1, ay) = (z0 * inv, z1 * inv, y0 * inv);
            let (g, c, s) = (&self.g[..4], &self.c[..2], &self.s[..1]);
            let out = &mut self.centred;
            out.g[..4].copy_from_slice(&[
                g[0] - a0 * z0,
                g[1] - a0 * z1,
                g[2] - a1 * z0,
                g[3] - a1 * z1,
            ]);
            out.c[..2].copy_from_slice(&[c[0] - ay * z0, c[1] - ay * z1]);
            out.s[0] = s[0] - ay * y0;
            self.swap_centred();
            return;
        }
        let (p, d) = (self.cfg.outputs, self.d());
        let tt = self.tt;
        let inv = if tt > 0.0 { 1.0 / tt } else { 0.0 };
        let (zt, dyt, wt) = (&self.zt[..d], &self.dyt[..p], &self.wt[..d]);
        let instrumented = self.cfg.estimator == crate::Estimator::Instrumented;
        // `G`, `C`, `S` by the column's own span (the ordinary sums are those already).
        let (zo, dyo, inv_o) = if instrumented {
            (&self.zto[..d], &self.dyto[..p], if self.tto > 0.0 { 1.0 / self.tto } else { 0.0 })
        } else {
            (zt, dyt, inv)
        };
        let c = &mut self.centred;
        let centre = |out: &mut [f64], raw: &[f64], a: &[f64], b: &[f64], inv: f64| {
            for (i, &ai) in a.iter().enumerate() {
                let ai = ai * inv;
                let (o, r) = (&mut out[i * b.len()..(i + 1) * b.len()], &raw[i * b.len()..]);
                for ((o, &r), &bj) in o.iter_mut().zip(r).zip(b) {
                    *o = r - ai * bj;
                }
            }
        };
        centre(&mut c.g, &self.g, zo, zo, inv_o);
        centre(&mut c.c, &self.c, dyo, zo, inv_o);
        centre(&mut c.s, &self.s, dyo, dyo, inv_o);
        if instrumented {
            centre(&mut c.gw, &self.gw, zt, wt, inv);
            centre(&mut c.cw, &self.cw, dyt, wt, inv);
        }
        self.swap_centred();
    }

    /// Swap the running sums back in; with a ready estimate, `ĉ = (a_y − Θ̂ a_z)/T`, and
    /// for the instrumented estimator `RMS(R)` with that `ĉ`: the centred sums give the
    /// residual sum of squares at the least-squares intercept given `Θ̂`,
    /// `c_LS = (Σ ΔY τ − Θ̂ Σ Z τ)/Σ τ²`, and `RSS = RSS_LS + Σ_i (c_LS,i − ĉ_i)² Σ τ²`.
    #[inline(always)]
    fn leave_centred(&mut self, out: &mut Estimate<'static>) {
        self.swap_centred();
        if out.status != EstimateStatus::Ready {
            return;
        }
        let (p, d) = (self.cfg.outputs, self.d());
        let inv = 1.0 / self.tt;
        let instrumented = self.cfg.estimator == crate::Estimator::Instrumented;
        let mut extra = 0.0;
        for i in 0..p {
            let th = &self.theta[i * d..(i + 1) * d];
            let fitted: f64 = th.iter().zip(&self.zt[..d]).map(|(a, b)| a * b).sum();
            self.intercept[i] = (self.dyt[i] - fitted) * inv;
            if instrumented {
                let own: f64 = th.iter().zip(&self.zto[..d]).map(|(a, b)| a * b).sum();
                let c_ls = (self.dyto[i] - own) / self.tto;
                extra += (c_ls - self.intercept[i]).powi(2) * self.tto;
            }
        }
        if instrumented {
            let n = (p * out.columns) as f64;
            out.rms_residual = (out.rms_residual.powi(2) + extra / n).sqrt();
        }
    }

    fn swap_centred(&mut self) {
        let c = &mut self.centred;
        std::mem::swap(&mut self.g, &mut c.g);
        std::mem::swap(&mut self.c, &mut c.c);
        std::mem::swap(&mut self.s, &mut c.s);
        std::mem::swap(&mut self.gw, &mut c.gw);
        std::mem::swap(&mut self.cw, &mut c.cw);
    }

    /// [`estimate`](Self::estimate) with the dimensions passed in (literals at the call site
    /// for the paper's `p = m = 1` unroll the small kernels).
    #[inline(always)]
    fn estimate_dims(&mut self, p: usize, m: usize) -> Estimate<'static> {
        let d = p + m;
        let n = self.col_len;
        let mut out = Self::pending(p, m, n);
        if n < self.cfg.min_columns {
            out.status = EstimateStatus::WarmingUp { columns: n, needed: self.cfg.min_columns };
            return out;
        }
        let (lo, hi) = linalg::psd_eig_extremes(&self.g, d, &mut self.work);
        // Full window (every sample after warm-up): the reciprocal computed at construction.
        let inv_n = if n == self.cfg.window { self.inv_window } else { 1.0 / n as f64 };
        out.gram_lambda_min = lo * inv_n;
        out.gram_lambda_max = hi * inv_n;
        if !(hi > 0.0 && lo > self.cfg.min_excitation_ratio * hi) {
            out.status = EstimateStatus::InsufficientExcitation { lambda_min: lo, lambda_max: hi };
            return out;
        }
        let ridge = self.cfg.ridge;
        match self.cfg.estimator {
            Estimator::Ordinary if d == 2 => {
                // p = m = 1: the 2 × 2 system by its closed-form inverse.
                let g = &self.g[..4];
                let (a, b, c) = (g[0] + ridge, g[1], g[3] + ridge);
                let det = a * c - b * b;
                if !(a > 0.0 && det > 0.0 && det.is_finite()) {
                    out.status =
                        EstimateStatus::InsufficientExcitation { lambda_min: lo, lambda_max: hi };
                    return out;
                }
                let inv = 1.0 / det;
                let (c0, c1) = (self.c[0], self.c[1]);
                let theta = &mut self.theta[..2];
                theta[0] = (c * c0 - b * c1) * inv;
                theta[1] = (a * c1 - b * c0) * inv;
            }
            Estimator::Ordinary => {
                if !self.factor_ridge(d) {
                    out.status =
                        EstimateStatus::InsufficientExcitation { lambda_min: lo, lambda_max: hi };
                    return out;
                }
                if d >= WIDE_FROM {
                    out.rms_residual = self.solve_wide(p, d, inv_n);
                    return out;
                }
                for i in 0..p {
                    let row = &mut self.theta[i * d..(i + 1) * d];
                    row.copy_from_slice(&self.c[i * d..(i + 1) * d]);
                    linalg::cholesky_solve_in_place(&self.work, d, row);
                }
            }
            Estimator::Instrumented => {
                // Row i of Θ solves (Z Wᵀ + λI)ᵀ x = (ΔY Wᵀ)[i, :].
                for i in 0..d {
                    for j in 0..d {
                        self.work2[i * d + j] =
                            self.gw[j * d + i] + if i == j { ridge } else { 0.0 };
                    }
                }
                let ratio = linalg::lu_in_place(&mut self.work2, d, &mut self.piv);
                if !(ratio > self.cfg.min_excitation_ratio) {
                    out.status = EstimateStatus::WeakInstruments { pivot_ratio: ratio };
                    return out;
                }
                for i in 0..p {
                    let row = &mut self.theta[i * d..(i + 1) * d];
                    row.copy_from_slice(&self.cw[i * d..(i + 1) * d]);
                    linalg::lu_solve_in_place(&self.work2, d, &self.piv, row);
                }
            }
        }
        let rss = self.rss(p, d);
        out.rms_residual = (rss.max(0.0) * inv_n / p as f64).sqrt();
        out
    }

    /// The residual sum of squares of the solved `Θ` from the running sums,
    /// `RSS = tr S − 2 tr(Θ Cᵀ) + tr(Θ G Θᵀ)`.
    #[inline(always)]
    fn rss(&self, p: usize, d: usize) -> f64 {
        // Views of exactly the configured lengths (no bounds checks with literal p, d).
        let (g, c, s) = (&self.g[..d * d], &self.c[..p * d], &self.s[..p * p]);
        let mut rss = 0.0;
        for i in 0..p {
            rss += s[i * p + i];
            let th = &self.theta[i * d..(i + 1) * d];
            let mut quad = 0.0;
            for a in 0..d {
                rss -= 2.0 * th[a] * c[i * d + a];
                quad += th[a] * th[a] * g[a * d + a];
                for b in a + 1..d {
                    quad += 2.0 * th[a] * th[b] * g[a * d + b];
                }
            }
            rss += quad;
        }
        rss
    }

    /// [`estimate`](Self::estimate), and `λ_max` of the symmetric `m × m` matrix that `form`
    /// writes into `sym` (upper triangle read) from `Θ̂` (`p × d`, row-major), NaN when the
    /// estimate is not ready (`form` is then not called, or its matrix not used). The
    /// `Estimate` is bit for bit `estimate()`'s and `λ_max` bit for bit
    /// [`linalg::sym_eig_max`]'s of the matrix formed. For the ordinary estimator of a wide
    /// regression (`d >= 8`, the one-pass solve) the solve comes first and the Gram matrix's
    /// extremes and `λ_max` are then computed by [`linalg::psd_extremes_and_sym_max`] (side by
    /// side when both matrices are at least `10 × 10`); the certifier forms `sym Ĵ_cl` this
    /// way. `sym_work` is at least
    /// [`linalg::eig_work_len`]`(m)` long. (`Θ̂` is overwritten even when the Gram matrix
    /// then fails the excitation test; [`residual`](Self::residual) is for ready estimates.)
    pub fn estimate_and_sym_max(
        &mut self,
        sym: &mut [f64],
        m: usize,
        sym_work: &mut [f64],
        form: impl FnOnce(&[f64], &mut [f64]),
    ) -> (Estimate<'_>, f64) {
        let affine = self.affine();
        if affine {
            self.enter_centred();
        }
        let (mut out, top) = self.estimate_and_sym_max_raw(sym, m, sym_work, form);
        if affine {
            self.leave_centred(&mut out);
        }
        (self.attach(out), top)
    }

    /// [`estimate_and_sym_max`](Self::estimate_and_sym_max) on whatever statistics are in
    /// place, without the borrowed vectors.
    fn estimate_and_sym_max_raw(
        &mut self,
        sym: &mut [f64],
        m: usize,
        sym_work: &mut [f64],
        form: impl FnOnce(&[f64], &mut [f64]),
    ) -> (Estimate<'static>, f64) {
        let (p, inputs) = (self.cfg.outputs, self.cfg.inputs);
        let (d, n) = (p + inputs, self.col_len);
        if !(self.cfg.estimator == Estimator::Ordinary
            && d >= WIDE_FROM
            && n >= self.cfg.min_columns)
        {
            let est = self.estimate_raw();
            if est.status != EstimateStatus::Ready {
                return (est, f64::NAN);
            }
            form(&self.theta[..p * d], sym);
            let top = linalg::sym_eig_max(sym, m, sym_work);
            return (est, top);
        }
        let inv_n = if n == self.cfg.window { self.inv_window } else { 1.0 / n as f64 };
        let mut out = Self::pending(p, inputs, n);
        let factored = self.factor_ridge(d);
        let (rms, (lo, hi), top) = if factored {
            let rms = self.solve_wide(p, d, inv_n);
            form(&self.theta[..p * d], sym);
            let (pair, top) =
                linalg::psd_extremes_and_sym_max(&self.g, d, &mut self.work, sym, m, sym_work);
            (rms, pair, top)
        } else {
            (f64::NAN, linalg::psd_eig_extremes(&self.g, d, &mut self.work), f64::NAN)
        };
        out.gram_lambda_min = lo * inv_n;
        out.gram_lambda_max = hi * inv_n;
        // The excitation test of `estimate`, then its factorisation's (same status).
        if !(factored && hi > 0.0 && lo > self.cfg.min_excitation_ratio * hi) {
            out.status = EstimateStatus::InsufficientExcitation { lambda_min: lo, lambda_max: hi };
            return (out, f64::NAN);
        }
        out.rms_residual = rms;
        (out, top)
    }

    /// An estimate of `n` columns with nothing filled in yet: status `Ready`, no `Θ̂`, NaN
    /// statistics (the solve paths fill or replace each).
    #[inline(always)]
    fn pending(p: usize, m: usize, n: usize) -> Estimate<'static> {
        Estimate {
            status: EstimateStatus::Ready,
            theta: &[],
            intercept: &[],
            outputs: p,
            inputs: m,
            rms_residual: f64::NAN,
            gram_lambda_min: f64::NAN,
            gram_lambda_max: f64::NAN,
            columns: n,
        }
    }

    /// The Cholesky factor `L` of `A = G + λI` in `work` (lower triangle; the strict upper
    /// triangle is not written): `false` when `A` is not numerically positive definite. Out of
    /// line, so the inlined `p = m = 1` path stays small.
    #[inline(never)]
    fn factor_ridge(&mut self, d: usize) -> bool {
        // The lower triangle and diagonal of G + λI (all the factorisation reads), from G's
        // upper triangle.
        for i in 0..d {
            for j in 0..i {
                self.work[i * d + j] = self.g[j * d + i];
            }
            self.work[i * d + i] = self.g[i * d + i] + self.cfg.ridge;
        }
        linalg::cholesky_in_place(&mut self.work, d)
    }

    /// The ordinary solve of a wide regression (`d >= WIDE_FROM`), after the Cholesky factor
    /// `L` of `A = G + λI` is in `work`: all `p` rows of `Θ̂ = C A⁻¹` at once (forward and
    /// back substitution with the reciprocal diagonal, the rows independent so their products
    /// interleave), and
    ///
    /// ```text
    /// RSS = tr S − 2 tr(Θ̂ Cᵀ) + tr(Θ̂ G Θ̂ᵀ) = tr S − Σ_i ‖y_i‖² − λ ‖Θ̂‖²_F,   y_i = L⁻¹ c_iᵀ
    /// ```
    ///
    /// (`tr(Θ̂Cᵀ) = tr(C A⁻¹ Cᵀ) = Σ‖y_i‖²`, `tr(Θ̂GΘ̂ᵀ) = tr(CA⁻¹Cᵀ) − λ‖Θ̂‖²`): `O(p d²)`
    /// with no second pass over `G`.
    /// Returns `RMS(R)`; `Θ̂` is in `theta`.
    fn solve_wide(&mut self, p: usize, d: usize, inv_n: f64) -> f64 {
        let (l, rdiag) = self.work.split_at_mut(d * d);
        let rdiag = &mut rdiag[..d];
        for a in 0..d {
            rdiag[a] = 1.0 / l[a * d + a];
        }
        let theta = &mut self.theta[..p * d];
        theta.copy_from_slice(&self.c[..p * d]);
        // Forward: row a of L against every output row.
        let mut yy = 0.0;
        for a in 0..d {
            let la = &l[a * d..a * d + a];
            for row in theta.chunks_exact_mut(d) {
                let (done, rest) = row.split_at_mut(a);
                let v = (rest[0] - linalg::dot(la, done)) * rdiag[a];
                rest[0] = v;
                yy += v * v;
            }
        }
        // Back: θ_i = L⁻ᵀ y_i.
        let mut tt = 0.0;
        for a in (0..d).rev() {
            let la = &l[a * d..a * d + a];
            for row in theta.chunks_exact_mut(d) {
                let v = row[a] * rdiag[a];
                row[a] = v;
                tt += v * v;
                for (r, &lab) in row[..a].iter_mut().zip(la) {
                    *r -= lab * v;
                }
            }
        }
        let trace: f64 = (0..p).map(|i| self.s[i * p + i]).sum();
        let rss = trace - yy - self.cfg.ridge * tt;
        (rss.max(0.0) * inv_n / p as f64).sqrt()
    }
}
