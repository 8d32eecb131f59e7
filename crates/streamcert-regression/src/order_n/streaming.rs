//! [`OrderNRegression`]: the streaming estimator of order `n`.
//!
//! ## The row in `O(n² (1 + m))` per sample
//!
//! A row needs, for each signal `f` and each of its `n` knot intervals `[τ_j, τ_{j+1}]`, the
//! moments `μ_{j,p} = ∫_{τ_j}^{τ_{j+1}} (x − τ_j)^p f(x) dx`, `p < n`: then
//! `⟨M⁽ʳ⁾, f⟩ = Σ_j Σ_p M⁽ʳ⁾_{j,p} μ_{j,p}` with `M⁽ʳ⁾_{j,p}` the kernel's polynomial
//! coefficients on interval `j`. A knot interval is the last `h` sample intervals before a
//! sample, so every row's knot intervals are the same sliding quantity, taken `h` samples
//! apart: the moments of the `h` intervals ending at each sample are kept in a ring of
//! `(n − 1) h + 1`, and a row reads `n` of them.
//!
//! The sliding moments are kept about the newest sample time `t`,
//! `R_p = ∫_{t−…}^{t} (x − t)^p f`. A new sample moves the anchor by the binomial shift
//! `R_p ← Σ_q C(p, q) (t_prev − t)^{p−q} R_q`, adds the new interval's moments and subtracts the
//! departing one's (each exact for the linear interpolant of `y` and the held `u`), and every
//! `h` samples `R` is recomputed exactly from the ring of per-interval moments, so rounding
//! cannot accumulate. The moments about the knot interval's left end `a` are
//! `μ_p = Σ_q C(p, q) (t − a)^{p−q} R_q`.
//!
//! The window keeps `Σ [φ z]ᵀ[φ z]` over its `M` rows: a row is added and the departing one
//! subtracted (`O(d²)`), with an exact recompute every `refresh_period` rows.

use super::spline::{Kernel, divided_difference_weights};
use super::{MAX_ORDER, OrderNConfig, Shape, check_sample};
use crate::linalg::{cholesky_in_place, cholesky_solve_in_place, eig_work_len, psd_eig_extremes};
use crate::{LoopModel, RegressionError};

/// `C(p, q)` for `p, q < MAX_ORDER`.
const BINOMIAL: [[f64; MAX_ORDER]; MAX_ORDER] = [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 2.0, 1.0]];

/// `Σ_q C(p, q) off^{p−q} m_q`: the `p`-th moment `∫ (x − x₁)^p f` of an interval from its
/// moments `m_q = ∫ (x − x₀)^q f` about `x₀`, with `off = x₀ − x₁`.
#[inline(always)]
fn moment_about(m: &[f64], off: f64, p: usize) -> f64 {
    let (mut v, mut sp) = (0.0, 1.0);
    for q in (0..=p).rev() {
        v += BINOMIAL[p][q] * sp * m[q];
        sp *= off;
    }
    v
}

/// The streaming order-`n` regression (see the module docs of `order_n`): push samples, read
/// the window's least-squares coefficients `θ̂ = (a_1..a_n, b.., c)`.
///
/// ```
/// use streamcert_regression::{LoopModel, OrderNConfig, OrderNRegression};
/// // ÿ + 3 ẏ + 2 y = u, sampled at 100 Hz (exact zero-order-hold steps of its two modes).
/// let cfg = OrderNConfig::new(LoopModel::of_order(2).unwrap(), 1, 400, 20);
/// let mut reg = OrderNRegression::new(cfg)?;
/// let (dt, mut x) = (0.01f64, [0.0f64, 0.0]); // y = x[0] − x[1], modes e^{−t}, e^{−2t}
/// for k in 0..1000 {
///     let u = if (k / 37) % 2 == 0 { 1.0 } else { -1.0 };
///     reg.push(k as f64 * dt, x[0] - x[1], &[u])?;
///     x[0] = (-dt).exp() * x[0] + (1.0 - (-dt).exp()) * u;
///     x[1] = (-2.0 * dt).exp() * x[1] + (1.0 - (-2.0 * dt).exp()) / 2.0 * u;
/// }
/// let theta = reg.estimate()?;
/// assert!((theta[0] - 3.0).abs() < 1e-3 && (theta[1] - 2.0).abs() < 1e-3);
/// assert!(theta[2].abs() < 1e-3 && (theta[3] - 1.0).abs() < 1e-3);
/// # Ok::<(), streamcert_regression::RegressionError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct OrderNRegression {
    cfg: OrderNConfig,
    shape: Shape,
    // The origin `[y; u]` (the first sample since construction, kept across resets).
    origin: Vec<f64>,
    origin_set: bool,
    // The last `n h + 1` samples relative to the origin; `head` is the newest.
    t: Vec<f64>,
    y: Vec<f64>,
    u: Vec<f64>,
    head: usize,
    len: usize,
    // Per-interval moments about the interval's start, `(1 + m) × n` per interval, ring of `h`
    // aligned with the interval's start time in `starts`.
    local: Vec<f64>,
    starts: Vec<f64>,
    local_head: usize,
    intervals: usize,
    since_exact: usize,
    // `R`: the moments of the last `min(h, intervals)` intervals about the newest time.
    run: Vec<f64>,
    // Knot-interval moments about their left end, one per sample once `h` intervals are in,
    // ring of `(n − 1) h + 1`.
    mu: Vec<f64>,
    mu_head: usize,
    mu_len: usize,
    // Rows `[φ, z]`, ring of `M`, and their sums.
    rows: Vec<f64>,
    row_next: usize,
    row_len: usize,
    since_refresh: usize,
    sums: Vec<f64>,
    // Scratch.
    row: Vec<f64>,
    moments: Vec<f64>,
    gram: Vec<f64>,
    theta: Vec<f64>,
    scale: Vec<f64>,
    eig_work: Vec<f64>,
}

impl OrderNRegression {
    /// A regression with an empty window.
    ///
    /// # Errors
    /// [`RegressionError::InvalidConfig`] for a configuration [`OrderNConfig::validate`]
    /// refuses.
    pub fn new(cfg: OrderNConfig) -> Result<Self, RegressionError> {
        cfg.validate()?;
        let shape = cfg.shape();
        let (n, m, h, span, d) = (shape.n, shape.m, shape.h, shape.span(), shape.width());
        let signals = 1 + m;
        Ok(Self {
            cfg,
            shape,
            origin: vec![0.0; signals],
            origin_set: false,
            t: vec![0.0; span + 1],
            y: vec![0.0; span + 1],
            u: vec![0.0; (span + 1) * m],
            head: 0,
            len: 0,
            local: vec![0.0; h * signals * n],
            starts: vec![0.0; h],
            local_head: 0,
            intervals: 0,
            since_exact: 0,
            run: vec![0.0; signals * n],
            mu: vec![0.0; ((n - 1) * h + 1) * signals * n],
            mu_head: 0,
            mu_len: 0,
            rows: vec![0.0; cfg.window * (d + 1)],
            row_next: 0,
            row_len: 0,
            since_refresh: 0,
            sums: vec![0.0; (d + 1) * (d + 1)],
            row: vec![0.0; d + 1],
            moments: vec![0.0; signals * n],
            gram: vec![0.0; d * d],
            theta: vec![0.0; d],
            scale: vec![0.0; d],
            eig_work: vec![0.0; eig_work_len(d)],
        })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &OrderNConfig {
        &self.cfg
    }

    /// The model.
    #[must_use]
    pub fn model(&self) -> LoopModel {
        self.cfg.model
    }

    /// Rows in the window.
    #[must_use]
    pub fn rows(&self) -> usize {
        self.row_len
    }

    /// The newest row `[φ^y_1..φ^y_n, φ^u.., L̄ⁿ]` and its regressand `z`, relative to the
    /// origin; `None` before the first row.
    #[must_use]
    pub fn newest_row(&self) -> Option<(&[f64], f64)> {
        if self.row_len == 0 {
            return None;
        }
        let d = self.shape.width();
        let slot = (self.row_next + self.cfg.window - 1) % self.cfg.window;
        let r = &self.rows[slot * (d + 1)..(slot + 1) * (d + 1)];
        Some((&r[..d], r[d]))
    }

    /// The origin `[y₀; u₀]` the samples are taken relative to (the first sample's values).
    #[must_use]
    pub fn origin(&self) -> &[f64] {
        &self.origin
    }

    /// Empty the window and the sample history (after a gap: the next row is built from
    /// `n h + 1` new samples). The origin is kept.
    pub fn reset(&mut self) {
        self.len = 0;
        self.intervals = 0;
        self.since_exact = 0;
        self.mu_len = 0;
        self.row_len = 0;
        self.row_next = 0;
        self.since_refresh = 0;
        self.run.fill(0.0);
        self.sums.fill(0.0);
    }

    /// Absorb one sample: `O(n² (1 + m))` for the row, `O(d²)` for the window, no allocation.
    ///
    /// # Errors
    /// [`RegressionError::DimensionMismatch`], [`RegressionError::NonFinite`] or
    /// [`RegressionError::NonIncreasingTime`] (the sample is not absorbed);
    /// [`RegressionError::Overflow`] when finite samples give a non-finite row (the window is
    /// cleared).
    pub fn push(&mut self, t: f64, y: f64, u: &[f64]) -> Result<(), RegressionError> {
        let Shape { n, m, h } = self.shape;
        let cap = self.shape.span() + 1;
        let previous = (self.len > 0).then(|| self.t[self.head]);
        check_sample(previous, t, y, u, m)?;
        if !self.origin_set {
            self.origin[0] = y;
            self.origin[1..].copy_from_slice(u);
            self.origin_set = true;
        }
        let ys = y - self.origin[0];
        if self.len > 0 {
            self.absorb_interval(t, ys);
        }
        // The sample itself.
        self.head = if self.len == 0 { 0 } else { (self.head + 1) % cap };
        self.t[self.head] = t;
        self.y[self.head] = ys;
        for (j, uj) in u.iter().enumerate() {
            self.u[self.head * m + j] = uj - self.origin[1 + j];
        }
        self.len = (self.len + 1).min(cap);
        if self.intervals >= h {
            self.push_knot_moments(t);
        }
        if self.mu_len == (n - 1) * h + 1 {
            self.build_row();
            if self.row.iter().any(|v| !v.is_finite()) {
                self.reset();
                return Err(RegressionError::Overflow);
            }
            self.push_row();
        }
        Ok(())
    }

    /// The moments of the interval `[t_prev, t]` (about `t_prev`) into the ring and `R`.
    fn absorb_interval(&mut self, t: f64, ys: f64) {
        let Shape { n, m, h } = self.shape;
        let signals = 1 + m;
        let (tp, yp) = (self.t[self.head], self.y[self.head]);
        let dt = t - tp;
        // Local moments: y linear from yp to ys, u held at the previous sample's value.
        let mut pow = dt;
        for q in 0..n {
            let qf = q as f64;
            self.moments[q] = yp * pow / (qf + 1.0) + (ys - yp) * pow / (qf + 2.0);
            for j in 0..m {
                self.moments[(1 + j) * n + q] = self.u[self.head * m + j] * pow / (qf + 1.0);
            }
            pow *= dt;
        }
        // Move R's anchor from tp to t, then add the new interval (its start is at tp − t).
        let shift = tp - t;
        for s in 0..signals {
            let (run, add) = (&mut self.run[s * n..(s + 1) * n], &self.moments[s * n..(s + 1) * n]);
            let both: [f64; MAX_ORDER] =
                std::array::from_fn(|q| if q < n { run[q] + add[q] } else { 0.0 });
            for (p, r) in run.iter_mut().enumerate() {
                *r = moment_about(&both, shift, p);
            }
        }
        // The departing interval (when the ring is full) leaves R.
        let slot = self.local_head;
        if self.intervals >= h {
            let out = self.starts[slot] - t;
            for s in 0..signals {
                let local = &self.local[(slot * signals + s) * n..(slot * signals + s + 1) * n];
                for p in 0..n {
                    self.run[s * n + p] -= moment_about(local, out, p);
                }
            }
        }
        self.local[slot * signals * n..(slot + 1) * signals * n].copy_from_slice(&self.moments);
        self.starts[slot] = tp;
        self.local_head = (slot + 1) % h;
        self.intervals += 1;
        self.since_exact += 1;
        if self.since_exact >= h {
            self.exact_run(t);
        }
    }

    /// Recompute `R` from the ring of per-interval moments.
    fn exact_run(&mut self, t: f64) {
        let Shape { n, m, h } = self.shape;
        let signals = 1 + m;
        self.run.fill(0.0);
        for k in 0..self.intervals.min(h) {
            let slot = (self.local_head + h - 1 - k) % h;
            let off = self.starts[slot] - t;
            for s in 0..signals {
                let local = &self.local[(slot * signals + s) * n..(slot * signals + s + 1) * n];
                for p in 0..n {
                    self.run[s * n + p] += moment_about(local, off, p);
                }
            }
        }
        self.since_exact = 0;
    }

    /// The moments of the last `h` intervals about their left end, into the knot ring.
    fn push_knot_moments(&mut self, t: f64) {
        let Shape { n, m, h } = self.shape;
        let (signals, cap) = (1 + m, (n - 1) * h + 1);
        let left = self.sample_t(h);
        let off = t - left;
        self.mu_head = if self.mu_len == 0 { 0 } else { (self.mu_head + 1) % cap };
        let base = self.mu_head * signals * n;
        for s in 0..signals {
            for p in 0..n {
                self.mu[base + s * n + p] = moment_about(&self.run[s * n..(s + 1) * n], off, p);
            }
        }
        self.mu_len = (self.mu_len + 1).min(cap);
    }

    /// The time of the sample `age` samples before the newest.
    fn sample_t(&self, age: usize) -> f64 {
        let cap = self.t.len();
        self.t[(self.head + cap - age) % cap]
    }

    /// The newest row into `self.row` (`[φ, z]`).
    fn build_row(&mut self) {
        let Shape { n, m, h } = self.shape;
        let (signals, d, cap) = (1 + m, self.shape.width(), (n - 1) * h + 1);
        let cap_t = self.t.len();
        let mut tau = [0.0; MAX_ORDER + 1];
        let mut yk = [0.0; MAX_ORDER + 1];
        for j in 0..=n {
            let slot = (self.head + cap_t - (n - j) * h) % cap_t;
            tau[j] = self.t[slot];
            yk[j] = self.y[slot];
        }
        let kernel = Kernel::new(&tau, n);
        let scale = ((tau[n] - tau[0]) / n as f64).powi(n as i32);
        for k in 1..=n {
            let sign = if (n - k) % 2 == 0 { 1.0 } else { -1.0 };
            let pieces = &kernel.pieces[n - k];
            for s in 0..signals {
                let mut v = 0.0;
                for (j, piece) in pieces.iter().enumerate().take(n) {
                    let slot = (self.mu_head + cap - (n - 1 - j) * h) % cap;
                    let mu = &self.mu[(slot * signals + s) * n..(slot * signals + s + 1) * n];
                    v += piece.iter().zip(mu).map(|(c, x)| c * x).sum::<f64>();
                }
                let col = if s == 0 { k - 1 } else { n + (s - 1) * n + k - 1 };
                self.row[col] = if s == 0 { -scale * sign * v } else { scale * sign * v };
            }
        }
        self.row[d - 1] = scale;
        let dd = divided_difference_weights(&tau, n);
        let fact = (1..=n).product::<usize>() as f64;
        self.row[d] = scale * fact * (0..=n).map(|j| dd[j] * yk[j]).sum::<f64>();
    }

    /// `self.row` into the window and its sums.
    fn push_row(&mut self) {
        let (d1, cap) = (self.shape.width() + 1, self.cfg.window);
        let slot = self.row_next;
        if self.row_len == cap {
            let old = &self.rows[slot * d1..(slot + 1) * d1];
            for a in 0..d1 {
                for b in 0..d1 {
                    self.sums[a * d1 + b] -= old[a] * old[b];
                }
            }
        }
        self.rows[slot * d1..(slot + 1) * d1].copy_from_slice(&self.row);
        self.row_next = (slot + 1) % cap;
        self.row_len = (self.row_len + 1).min(cap);
        self.since_refresh += 1;
        if self.since_refresh >= self.cfg.refresh_period {
            self.refresh();
        } else {
            for a in 0..d1 {
                for b in 0..d1 {
                    self.sums[a * d1 + b] += self.row[a] * self.row[b];
                }
            }
        }
    }

    /// Recompute the window's sums exactly from its rows.
    fn refresh(&mut self) {
        let d1 = self.shape.width() + 1;
        self.sums.fill(0.0);
        for r in self.rows.chunks_exact(d1).take(self.row_len) {
            for a in 0..d1 {
                for b in 0..d1 {
                    self.sums[a * d1 + b] += r[a] * r[b];
                }
            }
        }
        self.since_refresh = 0;
    }

    /// The window's least-squares coefficients `θ̂ = (a_1..a_n, b.., c)` in the plant's
    /// coordinates (`c` with the origin added back). `O(d³)`, no allocation.
    ///
    /// # Errors
    /// [`RegressionError::InsufficientData`] before `min_rows` rows;
    /// [`RegressionError::NotIdentified`] when the column-scaled Gram matrix has
    /// `λ_min <= min_excitation_ratio · λ_max`.
    pub fn estimate(&mut self) -> Result<&[f64], RegressionError> {
        let (n, m, d) = (self.shape.n, self.shape.m, self.shape.width());
        let d1 = d + 1;
        if self.row_len < self.cfg.min_rows {
            let needed = self.cfg.min_rows + self.shape.span();
            return Err(RegressionError::InsufficientData {
                needed,
                got: self.row_len + self.shape.span(),
            });
        }
        for a in 0..d {
            self.scale[a] = self.sums[a * d1 + a].sqrt();
        }
        if self.scale.iter().any(|s| !(*s > 0.0 && s.is_finite())) {
            return Err(RegressionError::NotIdentified(
                "a regressor is zero over the window".into(),
            ));
        }
        for a in 0..d {
            for b in 0..d {
                self.gram[a * d + b] = self.sums[a * d1 + b] / (self.scale[a] * self.scale[b]);
            }
        }
        let (lo, hi) = psd_eig_extremes(&self.gram, d, &mut self.eig_work);
        if !(lo > self.cfg.min_excitation_ratio * hi) {
            return Err(RegressionError::NotIdentified(format!(
                "the column-scaled Gram matrix has λ_min/λ_max = {:.3e}, at most {:.1e}",
                lo / hi,
                self.cfg.min_excitation_ratio
            )));
        }
        if !cholesky_in_place(&mut self.gram, d) {
            return Err(RegressionError::NotIdentified(
                "the Gram matrix is not positive definite".into(),
            ));
        }
        for a in 0..d {
            self.theta[a] = self.sums[a * d1 + d] / self.scale[a];
        }
        cholesky_solve_in_place(&self.gram, d, &mut self.theta);
        for (th, s) in self.theta.iter_mut().zip(&self.scale) {
            *th /= s;
        }
        // c = c' + a_n y₀ − Σ_j b_{j,n} u₀_j.
        let mut c = self.theta[d - 1] + self.theta[n - 1] * self.origin[0];
        for j in 0..m {
            c -= self.theta[n + j * n + n - 1] * self.origin[1 + j];
        }
        self.theta[d - 1] = c;
        Ok(&self.theta)
    }
}
