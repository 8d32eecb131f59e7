//! The certificate of order `n` (an addition to the paper): a lower confidence bound on the
//! closed loop's margin for a plant whose output is not its whole state, read from one output
//! through the order-`n` integral regression
//! ([`OrderNRecord`](streamcert_regression::OrderNRecord)), whose gate opens for a loop with
//! true margin below `β_margin` with probability at most `δ` over the whole run.
//!
//! ## Method
//!
//! **Model.** The plant from its inputs to its one output is linear of order at most `n`
//! (`n = 1, 2, 3`) over the region the run explores: `p(D) y = q(D) u + c` with
//! `p(s) = sⁿ + a_1 sⁿ⁻¹ + … + a_n`. Under the candidate `u = K y` the closed loop's
//! characteristic polynomial is `sⁿ + β_1 sⁿ⁻¹ + … + β_n`, `β = a − Σ_j K_j b_j`, and its
//! *margin* is minus its spectral abscissa (`−max Re s` over its roots; for `n = 1` the
//! paper's rate `β̂`).
//!
//! **Estimate and covariance.** At a look the window's last `N = min(M, available)` rows are
//! fitted by least squares with the model-structured covariance (white sensor noise and white
//! noise where the intercept enters, fitted from the residuals' autocovariances;
//! [`OrderNFit`](streamcert_regression::OrderNFit)), and mapped to the closed loop:
//! `β̂ = T θ̂`, `Σ_β = T V Tᵀ`.
//!
//! **Radius.** The covariance's scale is estimated from the same window, so the region is
//! calibrated by Fisher's F rather than `χ²`:
//!
//! ```text
//! E_k = {β : (β − β̂)ᵀ Σ_β⁻¹ (β − β̂) <= r_k²},   r_k² = n · F_{n, ν}(1 − δ_k)
//! ν   = ⌊N / (n h + 1)⌋ − d      (the window's disjoint spans, less one per coefficient)
//! ```
//!
//! Rows share `n h` of their `n h + 1` samples, so the residuals hold about one independent
//! value per span; `ν` counts those, not the rows. With `χ²` (as if the scale were known) the
//! first looks of a slow plant, with a few spans, opened where they should not: the scale
//! estimated from few spans is itself noisy. `d = n (1 + m) + 1` coefficients.
//!
//! **Test.** A look certifies when every member of `E_k` has all its roots left of
//! `−β_margin`: the exact zero-exclusion test ([`robustly_stable`](crate::robustly_stable)).
//! Its value is the largest such margin ([`robust_margin`](crate::robust_margin)), reported,
//! never above the truth for the members of `E_k`.
//!
//! **Looks and risk.** The first look comes at the first sample with `min_rows` rows (the
//! smallest window, at least `(d + 1)(n h + 1)` rows so that `ν >= 1`), then one every
//! `look_period` samples. The `k`-th look spends `δ_k = δ / (k (k + 1))`
//! ([`look_risk`](crate::look_risk)), which sums to `δ` over any number of looks: the gate
//! (open while the latest look certifies) opens for a loop whose margin is below `β_margin`
//! with probability at most `δ`, whatever the run's length and whenever it is stopped.
//!
//! **Identification.** A look whose column-scaled Gram matrix has
//! `λ_min <= min_excitation_ratio · λ_max` (an input held still: `u = K y + d` with `d`
//! constant is an affine function of `y`, and `a` cannot be told from `b`) certifies nothing
//! and closes the gate ([`NotCertified::InsufficientExcitation`]).
//!
//! **Hidden dynamics.** At every look the past-row test
//! ([`PastRowTest`](streamcert_regression::PastRowTest)) asks whether the regressand of the row
//! that ends before a row's span predicts what the model of order `n` leaves: under the model
//! it does not (`W ~ F(1, ν_g)`, `ν_g` the larger fit's disjoint spans less its `d + 1`
//! coefficients). Where `W` exceeds its `1 − guard_risk` quantile the look certifies nothing
//! ([`NotCertified::HiddenDynamics`]). The guard only closes: its risk costs power, not
//! validity. The rows take `y` linear between samples; where the signal is large against the
//! noise (a fast loop, a large dither, a short horizon) the guard can see that approximation
//! and refuse a loop the model holds. Measured: `ÿ + 3 ẏ + 2 y = u` under `u = −y_m + d`
//! with a dither of `±1`, `h = 10` and a sensor noise of `σ ≈ 0.006` was refused at
//! `W = 14.2` against `13.0`; with the dither at `±0.1` and `h = 50` it is certified (the
//! example below).
//!
//! **Nonlinearity.** At every look the curvature test
//! ([`CurvatureTest`](streamcert_regression::CurvatureTest)) asks whether the square and the
//! cube of the output, where the plant's static term enters, explain what the linear model
//! leaves: under linear dynamics they do not (`W / 2 ~ F(2, ν_c)`, `ν_c` the window's disjoint
//! spans less the larger fit's `d + 2` coefficients). Where `W` exceeds its `1 − guard_risk`
//! quantile the look certifies nothing ([`NotCertified::VaryingDynamics`]): a static term that
//! bends over the explored region (a stiffening spring, a valve's characteristic) gives a
//! closed loop whose rate varies over the region, and one linear fit certifies its average.
//! A nonlinearity in the damping terms only is not seen.
//!
//! **Plant change.** There is no change guard of its own: a look fits the window's last
//! `N` rows, so a plant change leaves every look once the window holds only the new plant's
//! rows (one window after the change; `cargo xtask validity --only-order` measures it).
//!
//! ## Assumptions
//! - linear dynamics of order at most `n` over the region (the hidden-dynamics guard tests
//!   the order, the nonlinearity guard the static term's curvature);
//! - white sensor noise on `y` and white noise entering where the intercept enters;
//! - the inputs applied are known exactly (the logged `u`).
//!
//! ## Cost
//! A sample is stored in rings of `M + n h` samples (`O(1 + m)`, no allocation). A look fits
//! its window and decides the exact test, paid once per look. On equally spaced samples the
//! fits come from an [`OrderNWindow`](streamcert_regression::OrderNWindow), which keeps each
//! row and the filtered rows' products over units of samples: a look computes what is new
//! since the last (`O(P n h d)` for `P` samples), the two edges, the fits from sums
//! (`O(N d²)`) and the residuals' autocovariances (`O(N n h)`); otherwise it fits the samples
//! ([`OrderNRecord`](streamcert_regression::OrderNRecord), `O(N n h d)`). The same estimate
//! up to rounding; what is kept is not checkpointed and a restored look is the same bits.

use serde::{Deserialize, Serialize};
use streamcert_regression::{OrderNConfig, RegressionError};

use crate::look::hotelling::f_quantile;
use crate::look::quantile::look_risk;
use crate::rate::order_n::{Ellipsoid, robust_margin, robustly_stable};
use crate::{CertifyError, NotCertified};

mod fits;
mod look;
use fits::{Fits, Kept};
pub use look::{OrderNLook, OrderNRegion};

/// Configuration of [`OrderNCertificate`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OrderNCertificateConfig {
    /// The regression: the order, the inputs `m`, the horizon `h`, the window `M` (rows), the
    /// smallest window a look uses (`min_rows`, at least `(d + 1)(n h + 1)`) and the
    /// identification threshold. `refresh_period` is not used.
    pub regression: OrderNConfig,
    /// The candidate gain `K`, `m` values (`u = K y`).
    pub gain: Vec<f64>,
    /// `β_margin` (1/s): the margin the gate asks for.
    pub margin: f64,
    /// `δ ∈ (0, 1)`: the probability, over the whole run, that the gate opens for a loop
    /// whose margin is below `β_margin`.
    pub delta: f64,
    /// Samples between looks (`>= 1`). Default `M / 10`.
    pub look_period: usize,
    /// The reported margin's bisection tolerance (1/s, `> 0`). Default `1e-4`. The decision
    /// at `β_margin` is exact whatever it is.
    pub tolerance: f64,
    /// The hidden-dynamics guard (default on): at every look, the past-row test
    /// ([`PastRowTest`](streamcert_regression::PastRowTest)) at risk
    /// [`guard_risk`](Self::guard_risk); where it rejects, the look certifies nothing
    /// ([`NotCertified::HiddenDynamics`]), and where it cannot run, neither
    /// ([`NotCertified::OrderUntested`]). Off, a plant with a state beyond the order is
    /// certified on a model that does not describe it, which `δ` does not cover.
    pub hidden_dynamics: bool,
    /// The nonlinearity guard (default on): at every look, the curvature test
    /// ([`CurvatureTest`](streamcert_regression::CurvatureTest): the square and the cube of
    /// the output where the static term enters) at risk [`guard_risk`](Self::guard_risk);
    /// where it rejects, the look certifies nothing ([`NotCertified::VaryingDynamics`]), and
    /// where it cannot run, neither ([`NotCertified::LinearityUntested`]). Off, a loop whose
    /// static term bends over the explored region is certified on its average slope, which
    /// `δ` does not cover.
    #[serde(default = "default_true")]
    pub nonlinearity: bool,
    /// Each guard's risk per look, in `(0, 1)`: the chance that it closes the gate of a loop
    /// the model holds (a guard only closes, so it costs power, never validity). Default `δ`.
    pub guard_risk: f64,
}

fn default_true() -> bool {
    true
}

impl OrderNCertificateConfig {
    /// The documented defaults: looks every `M / 10` samples (at least 1), a tolerance of
    /// `1e-4`, the hidden-dynamics and nonlinearity guards on at risk `δ` per look each; the
    /// first look when the
    /// window is full (`min_rows = M`, as `regression` has it).
    #[must_use]
    pub fn new(regression: OrderNConfig, gain: Vec<f64>, margin: f64, delta: f64) -> Self {
        Self {
            regression,
            gain,
            margin,
            delta,
            look_period: (regression.window / 10).max(1),
            tolerance: 1e-4,
            hidden_dynamics: true,
            nonlinearity: true,
            guard_risk: delta,
        }
    }

    /// The smallest window a look may use, so that each fit holds at least one disjoint
    /// span more than it has coefficients (`ν >= 1`, a guard whose test has no degree of
    /// freedom could not refuse): `(d + 1)(n h + 1)` rows for the certificate's fit,
    /// `(d + 3)(n h + 1)` with the nonlinearity guard (its fit has `d + 2` coefficients) and
    /// `(d + n + 3)(n h + 1)` with the hidden-dynamics guard (its fit has `d + n + 1`
    /// coefficients and loses the first `n h + 1` rows, which have no past row).
    #[must_use]
    pub fn smallest_window(&self) -> usize {
        let (d, n) = (self.regression.width(), self.regression.model.order());
        let mut spans = d + 1;
        if self.nonlinearity {
            spans = spans.max(d + 3);
        }
        if self.hidden_dynamics {
            spans = spans.max(d + n + 3);
        }
        spans * (self.regression.span() + 1)
    }

    /// Check every field.
    ///
    /// # Errors
    /// [`CertifyError::InvalidConfig`] naming the field and what is accepted, or
    /// [`CertifyError::Regression`] for the regression's own fields.
    pub fn validate(&self) -> Result<(), CertifyError> {
        let mut probe = self.regression;
        probe.refresh_period = probe.refresh_period.clamp(1, probe.window.max(1));
        probe.validate()?;
        let m = self.regression.inputs;
        if self.gain.len() != m {
            return CertifyError::refuse(
                "gain",
                format!("must have one value per input ({m}), got {}", self.gain.len()),
            );
        }
        if self.gain.iter().any(|k| !k.is_finite()) {
            return CertifyError::refuse("gain", "must be finite".into());
        }
        if !self.margin.is_finite() {
            return CertifyError::refuse("margin", "must be finite".into());
        }
        if !(self.delta > 0.0 && self.delta < 1.0) {
            return CertifyError::refuse(
                "delta",
                format!("must lie in (0, 1), got {}", self.delta),
            );
        }
        if self.look_period == 0 {
            return CertifyError::refuse("look_period", "must be at least 1 sample".into());
        }
        if !(self.tolerance > 0.0 && self.tolerance.is_finite()) {
            return CertifyError::refuse("tolerance", "must be finite and positive".into());
        }
        if !(self.guard_risk > 0.0 && self.guard_risk < 1.0) {
            return CertifyError::refuse(
                "guard_risk",
                format!("must lie in (0, 1), got {}", self.guard_risk),
            );
        }
        let smallest = self.smallest_window();
        if self.regression.min_rows < smallest {
            return CertifyError::refuse(
                "min_rows",
                format!(
                    "must be at least {smallest} rows ((d + 1)(n h + 1); (d + 3)(n h + 1) \
                     with the nonlinearity guard, (d + n + 3)(n h + 1) with the hidden-dynamics \
                     guard), got {}: a smaller window holds no disjoint span beyond a fit's \
                     coefficients to estimate the noise's scale from (raise the window or \
                     shorten the horizon)",
                    self.regression.min_rows
                ),
            );
        }
        Ok(())
    }
}

/// The certificate of order `n` over a stream of samples (module docs: method, risk,
/// assumptions).
///
/// ```
/// use streamcert_certificate::{OrderNCertificate, OrderNCertificateConfig};
/// use streamcert_regression::{LoopModel, OrderNConfig};
/// let regression = OrderNConfig::new(LoopModel::of_order(2).unwrap(), 1, 2000, 50);
/// let cfg = OrderNCertificateConfig::new(regression, vec![-1.0], 0.05, 0.01);
/// let mut cert = OrderNCertificate::new(cfg)?;
/// // ÿ + 3 ẏ + 2 y = u (y = x₀ − x₁, modes e^{−t} and e^{−2t}, exact zero-order hold) at
/// // 100 Hz, under u = −y_m + d with d a dither and y_m = y + e, e a small sensor noise.
/// let (dt, mut x, mut seed) = (0.01f64, [0.0f64, 0.0], 1u64);
/// let mut noise = || {
///     seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
///     ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.02
/// };
/// for k in 0..4000 {
///     let d = if (k / 100) % 3 == 0 { 0.1 } else { -0.1 };
///     let y = x[0] - x[1] + noise();
///     let u = -y + d;
///     cert.push(k as f64 * dt, y, &[u])?;
///     x[0] = (-dt).exp() * x[0] + (1.0 - (-dt).exp()) * u;
///     x[1] = (-2.0 * dt).exp() * x[1] + (1.0 - (-2.0 * dt).exp()) / 2.0 * u;
/// }
/// // The closed loop s² + 3 s + 3 has margin 1.5.
/// let look = cert.latest().unwrap();
/// assert!(look.certified() && cert.open(), "{look:?}");
/// # Ok::<(), streamcert_certificate::CertifyError>(())
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OrderNCertificate {
    cfg: OrderNCertificateConfig,
    /// Rings of the newest `M + n h` samples: time, output, inputs (`m` per sample).
    t: Vec<f64>,
    y: Vec<f64>,
    u: Vec<f64>,
    /// The next slot to write, and the samples held.
    head: usize,
    held: usize,
    /// The previous sample's time (the rings' newest), for the time check.
    previous: Option<f64>,
    /// Samples since the first sample with `min_rows` rows (that sample is 0).
    since_first: Option<usize>,
    looks: u64,
    latest: Option<OrderNLook>,
    /// The rows and filtered products kept across looks (not part of a checkpoint).
    #[serde(skip)]
    kept: Kept,
}

impl OrderNCertificate {
    /// A certificate with no samples.
    ///
    /// # Errors
    /// As [`OrderNCertificateConfig::validate`].
    pub fn new(cfg: OrderNCertificateConfig) -> Result<Self, CertifyError> {
        cfg.validate()?;
        let capacity = cfg.regression.window + cfg.regression.span();
        let m = cfg.regression.inputs;
        Ok(Self {
            t: vec![0.0; capacity],
            y: vec![0.0; capacity],
            u: vec![0.0; capacity * m],
            head: 0,
            held: 0,
            previous: None,
            since_first: None,
            looks: 0,
            latest: None,
            kept: Kept::default(),
            cfg,
        })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &OrderNCertificateConfig {
        &self.cfg
    }

    /// The latest look, held until the next.
    #[must_use]
    pub fn latest(&self) -> Option<&OrderNLook> {
        self.latest.as_ref()
    }

    /// Whether the gate is open: the latest look certifies the margin.
    #[must_use]
    pub fn open(&self) -> bool {
        self.latest.as_ref().is_some_and(OrderNLook::certified)
    }

    /// The rows the window holds now, `min(M, samples − n h)`.
    #[must_use]
    pub fn rows(&self) -> usize {
        self.held.saturating_sub(self.cfg.regression.span()).min(self.cfg.regression.window)
    }

    /// Forget every sample, and the latest look, after a gap: the window starts again at the
    /// next sample. The looks keep their count, so the risk schedule goes on where it was and
    /// the whole run, gaps included, spends at most `δ`.
    pub fn reset(&mut self) {
        (self.head, self.held, self.previous, self.since_first) = (0, 0, None, None);
        self.latest = None;
        self.kept.clear();
    }

    /// Whether the state is consistent with its configuration (what a restored checkpoint is
    /// checked for): the rings' lengths, the positions within them, a latest look no later
    /// than the newest sample.
    #[must_use]
    pub fn is_consistent(&self) -> bool {
        let capacity = self.cfg.regression.window + self.cfg.regression.span();
        let m = self.cfg.regression.inputs;
        self.t.len() == capacity
            && self.y.len() == capacity
            && self.u.len() == capacity * m
            && self.head < capacity
            && self.held <= capacity
            && (self.held == 0) == self.previous.is_none()
            && self.since_first.is_none_or(|_| self.rows() >= self.cfg.regression.min_rows)
            && self
                .latest
                .as_ref()
                .is_none_or(|l| l.index <= self.looks && self.previous.is_some_and(|t| l.time <= t))
    }

    /// The time of the newest sample taken since the start or the last reset.
    #[must_use]
    pub fn last_time(&self) -> Option<f64> {
        self.previous
    }

    /// Take one sample `(t, y, u)` and look when the schedule says so. Returns the look when
    /// one was made at this sample.
    ///
    /// # Errors
    /// A sample with a non-finite value, a time not after the previous one, or the wrong
    /// number of inputs is rejected ([`CertifyError::Regression`]), and nothing changes.
    pub fn push(&mut self, t: f64, y: f64, u: &[f64]) -> Result<Option<&OrderNLook>, CertifyError> {
        let m = self.cfg.regression.inputs;
        self.cfg.regression.check_sample(self.previous, t, y, u)?;
        let capacity = self.t.len();
        self.t[self.head] = t;
        self.y[self.head] = y;
        self.u[self.head * m..(self.head + 1) * m].copy_from_slice(u);
        self.head = (self.head + 1) % capacity;
        self.held = (self.held + 1).min(capacity);
        self.previous = Some(t);
        if self.since_first.is_none() && self.rows() >= self.cfg.regression.min_rows {
            self.since_first = Some(0);
        } else if let Some(s) = self.since_first.as_mut() {
            *s += 1;
        }
        match self.since_first {
            Some(s) if s % self.cfg.look_period == 0 => {
                self.latest = Some(self.look(t));
                Ok(self.latest.as_ref())
            }
            _ => Ok(None),
        }
    }

    /// The look at the newest sample (time `t`): the window's fit, its region and the test.
    fn look(&mut self, t: f64) -> OrderNLook {
        self.looks += 1;
        let (k, rows) = (self.looks, self.rows());
        let risk = look_risk(self.cfg.delta, 1.0, k);
        let outcome = self.region(rows, risk);
        OrderNLook { index: k, time: t, rows, risk, outcome }
    }

    fn region(&mut self, rows: usize, risk: f64) -> Result<OrderNRegion, NotCertified> {
        let cfg = &self.cfg.regression;
        let (n, m, span, d) = (cfg.model.order(), cfg.inputs, cfg.span(), cfg.width());
        // The window's samples in time order (paid at the look).
        let count = rows + span;
        let capacity = self.t.len();
        let first = (self.head + capacity - count) % capacity;
        let index = |i: usize| (first + i) % capacity;
        let t: Vec<f64> = (0..count).map(|i| self.t[index(i)]).collect();
        let y: Vec<f64> = (0..count).map(|i| self.y[index(i)]).collect();
        let mut u = Vec::with_capacity(count * m);
        for i in 0..count {
            u.extend_from_slice(&self.u[index(i) * m..(index(i) + 1) * m]);
        }
        let unidentified = |e: RegressionError| match e {
            RegressionError::NotIdentified(_) => NotCertified::InsufficientExcitation,
            _ => NotCertified::WarmingUp { columns: rows, needed: cfg.min_rows },
        };
        // The window's first sample, counted from the start or the last reset: the samples
        // held when the first look came (`min_rows + n h`) and one a sample since.
        let total = (self.since_first.unwrap_or(0) + cfg.min_rows + span) as u64;
        let first = total.saturating_sub(count as u64);
        let mut fits = Fits::new(&mut self.kept, cfg, first, &t, &y, &u).map_err(unidentified)?;
        let fit = fits.fit().map_err(unidentified)?;
        if self.cfg.hidden_dynamics {
            let test =
                fits.past_row_test().map_err(|_| NotCertified::OrderUntested { window: rows })?;
            let q = test.coefficients.len() as f64;
            let dof = (test.rows / (span + 1)).saturating_sub(d + n + 1);
            if dof == 0 {
                return Err(NotCertified::OrderUntested { window: rows });
            }
            let threshold = q * f_quantile(q, dof as f64, self.cfg.guard_risk);
            let statistic = test.statistic();
            if !(statistic <= threshold) {
                return Err(NotCertified::HiddenDynamics {
                    window: rows,
                    statistic,
                    threshold,
                    order: n,
                });
            }
        }
        if self.cfg.nonlinearity {
            let test = fits
                .curvature_test()
                .map_err(|_| NotCertified::LinearityUntested { window: rows })?;
            let dof = (test.rows / (span + 1)).saturating_sub(d + 2);
            if dof == 0 {
                return Err(NotCertified::LinearityUntested { window: rows });
            }
            let threshold = 2.0 * f_quantile(2.0, dof as f64, self.cfg.guard_risk);
            let statistic = test.statistic();
            if !(statistic <= threshold) {
                return Err(NotCertified::VaryingDynamics { window: rows, statistic, threshold });
            }
        }
        let closed = fit
            .closed_loop(&self.cfg.gain)
            .map_err(|_| NotCertified::WarmingUp { columns: rows, needed: cfg.min_rows })?;
        let dof = (rows / (span + 1)).saturating_sub(d);
        let radius2 = n as f64 * f_quantile(n as f64, dof as f64, risk);
        let e = Ellipsoid { centre: &closed.beta, covariance: &closed.covariance, radius2 };
        let certified = radius2.is_finite() && robustly_stable(&e, self.cfg.margin);
        let margin = if radius2.is_finite() { robust_margin(&e, self.cfg.tolerance) } else { None };
        Ok(OrderNRegion {
            beta: closed.beta,
            covariance: closed.covariance,
            dof,
            radius2,
            margin,
            certified,
        })
    }
}

#[cfg(test)]
mod tests;
