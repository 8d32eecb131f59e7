//! [`CertifierConfig`]: the regression, the candidate gain, the paper's constants, the gate,
//! the bad-sample policy and the optional ambiguity model and calibration, validated once.

use serde::{Deserialize, Serialize};
use streamcert_ambiguity::AmbiguityConfig;
use streamcert_regression::{RegressionConfig, ResidualSource};

use crate::{Calibration, CertifyError, CouplingConfig, NonlinearConfig};

mod order_n;

/// What to do with a sample that has a NaN or infinite value, a non-increasing time or the
/// wrong number of values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BadSamplePolicy {
    /// Return the error; the sample is not absorbed (default).
    #[default]
    Reject,
    /// Count it, close the gates, and return evidence with [`NotCertified::SkippedSample`](crate::NotCertified::SkippedSample);
    /// the sample is not absorbed (integrals then span the gap, using the actual times).
    Skip,
}

/// Configuration of a [`Certifier`](crate::Certifier).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CertifierConfig {
    /// The regression window.
    pub regression: RegressionConfig,
    /// Candidate gain `K`, `m × p` row-major (`u = K y`).
    pub gain: Vec<f64>,
    /// Conservatism constant `c > 0` of eq. rho (the paper does not give its value).
    pub conservatism: f64,
    /// `β_margin` (finite).
    pub margin: f64,
    /// `n_s >= 1`: consecutive samples at or above the margin before the gate opens.
    pub consecutive: usize,
    /// Bad-sample policy (default [`BadSamplePolicy::Reject`]).
    #[serde(default)]
    pub bad_samples: BadSamplePolicy,
    /// Ambiguity radius of Section III; `None` reports the Gaussian certificate only.
    #[serde(default)]
    pub ambiguity: Option<AmbiguityConfig>,
    /// Residuals that feed `ε` (default [`ResidualSource::OneStep`]).
    #[serde(default)]
    pub residuals: ResidualSource,
    /// Gap detection (see [`NotCertified::Gap`](crate::NotCertified::Gap)): a step larger
    /// than this multiple of the reference step (the median of the last 32) resets the window
    /// and closes the gates. Default 5; must exceed 1.
    #[serde(default = "default_gap_factor")]
    pub gap_factor: f64,
    /// Calibrated certificate beside the paper's (`None`: not computed).
    #[serde(default)]
    pub calibration: Option<Calibration>,
    /// Nonlinear certificate over the explored region and the nonlinearity test that closes
    /// the linear calibrated gate (`None`: not computed; needs a calibration and one output).
    #[serde(default)]
    pub nonlinear: Option<NonlinearConfig>,
    /// Input channels that are neighbours' measured outputs, whose coefficient blocks are
    /// bounded as coupling gains (`None`: no coupling estimated; needs a calibration). See
    /// [`CouplingConfig`].
    #[serde(default)]
    pub couplings: Option<CouplingConfig>,
    /// The metric the rate is measured in, for `p >= 2`: weights `w_i > 0`, one per output
    /// (`P = diag(w)²`): every certificate is that of the outputs `w_i y_i`, so
    /// `β̂ = −λ_max(sym(W Ĵ_cl W⁻¹))`, `W = diag(w)` (the gain seen in those units is
    /// `K W⁻¹`). A contraction rate in the identity metric depends on the units of each
    /// output: an output logged in mm instead of m is the metric `w = 1000` on it. `None`:
    /// the identity metric of the units as logged. Regions are reported in the logged units.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metric: Option<Vec<f64>>,
    /// The calibrated certificate at several horizons side by side, the risk split over them
    /// ([`HorizonLadder`](crate::HorizonLadder)); `None`: at the regression's horizon only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ladder: Option<crate::HorizonLadder>,
    /// The calibrated certificate at several model orders side by side, the risk split over
    /// them ([`OrderLadder`](crate::OrderLadder), `order = "auto"`); `None`: at the
    /// regression's order only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orders: Option<crate::OrderLadder>,
}

fn default_gap_factor() -> f64 {
    5.0
}

impl CertifierConfig {
    /// The paper's certificates alone (no stated risk: see [`guarded`](Self::guarded) for the
    /// verdict with one); `bad_samples` defaults to [`BadSamplePolicy::Reject`], no ambiguity
    /// model (set [`ambiguity`](Self::ambiguity) for the Wasserstein certificate), one-step
    /// residuals, no calibration.
    #[must_use]
    pub fn new(
        regression: RegressionConfig,
        gain: Vec<f64>,
        conservatism: f64,
        margin: f64,
        consecutive: usize,
    ) -> Self {
        Self {
            regression,
            gain,
            conservatism,
            margin,
            consecutive,
            bad_samples: BadSamplePolicy::Reject,
            ambiguity: None,
            residuals: ResidualSource::OneStep,
            gap_factor: default_gap_factor(),
            calibration: None,
            nonlinear: None,
            couplings: None,
            metric: None,
            ladder: None,
            orders: None,
        }
    }

    /// The documented entry point: the calibrated certificate at risk `δ = 0.01` with all its
    /// guards (hidden dynamics, nonlinearity, plant change; [`Calibration::new`]) beside the
    /// paper's Gaussian certificate (conservatism `c = 0.1`, the reproduction's), no
    /// ambiguity model. The verdict to deploy on is [`Evidence::calibrated`]; its gate opens
    /// for a candidate whose true rate is below `margin` with probability at most `δ` over the
    /// run (see the `calibrated` module for the assumptions). For inputs held by a digital
    /// controller set `regression.input_integral` to
    /// [`InputIntegral::ZeroOrderHold`](streamcert_regression::InputIntegral::ZeroOrderHold)
    /// (the command line's default). [`new`](Self::new) gives the paper's certificates alone,
    /// which carry no stated risk.
    ///
    /// [`Evidence::calibrated`]: crate::Evidence::calibrated
    #[must_use]
    pub fn guarded(
        regression: RegressionConfig,
        gain: Vec<f64>,
        margin: f64,
        consecutive: usize,
    ) -> Self {
        Self {
            calibration: Some(Calibration::new(0.01)),
            ..Self::new(regression, gain, 0.1, margin, consecutive)
        }
    }

    /// The gain in the metric's units, `K W⁻¹` (`K` itself without a metric).
    #[must_use]
    pub fn metric_gain(&self) -> Vec<f64> {
        let p = self.regression.outputs;
        match &self.metric {
            Some(w) => self.gain.iter().enumerate().map(|(i, k)| k / w[i % p]).collect(),
            None => self.gain.clone(),
        }
    }

    /// Check every field.
    ///
    /// # Errors
    /// [`CertifyError::InvalidConfig`] or the regression's configuration error.
    pub fn validate(&self) -> Result<(), CertifyError> {
        if !self.regression.order.is_first_order() {
            return self.validate_order_n(self.regression.order);
        }
        self.regression.validate()?;
        let (p, m) = (self.regression.outputs, self.regression.inputs);
        let bad = CertifyError::refuse::<()>;
        if let Some(w) = &self.metric {
            if p < 2 {
                return bad(
                    "metric",
                    "needs at least two outputs: one output's rate does not depend on its unit \
                     (omit the metric)"
                        .into(),
                );
            }
            if w.len() != p || w.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
                return bad(
                    "metric",
                    format!("must hold p = {p} finite weights > 0 (one per output), got {w:?}"),
                );
            }
        }
        if self.gain.len() != m * p {
            return bad(
                "gain",
                format!("K must be m × p = {m} × {p} ({} values), got {}", m * p, self.gain.len()),
            );
        }
        if let Some(v) = self.gain.iter().find(|v| !v.is_finite()) {
            return bad("gain", format!("entries must be finite, got {v}"));
        }
        if !(self.conservatism > 0.0 && self.conservatism.is_finite()) {
            return bad(
                "conservatism",
                format!("c must be finite and > 0, got {}", self.conservatism),
            );
        }
        if !self.margin.is_finite() {
            return bad("margin", format!("must be finite, got {}", self.margin));
        }
        if self.consecutive == 0 {
            return bad("consecutive", "n_s must be at least 1".into());
        }
        if !(self.gap_factor > 1.0 && self.gap_factor.is_finite()) {
            return bad("gap_factor", format!("must be finite and > 1, got {}", self.gap_factor));
        }
        if let Some(a) = &self.ambiguity {
            a.validate()?;
        }
        if let Some(c) = &self.calibration {
            c.validate(&self.regression, self.margin)?;
        }
        if let Some(n) = &self.nonlinear {
            n.validate(&self.regression, self.calibration.as_ref())?;
        }
        if let Some(c) = &self.couplings {
            c.validate(&self.regression, &self.gain, self.calibration.is_some())?;
        }
        if let Some(l) = &self.ladder {
            l.validate(self)?;
            for &h in &l.horizons {
                self.rung(h).validate().map_err(|e| CertifyError::InvalidConfig {
                    field: "horizon",
                    reason: format!("the ladder's rung at h = {h}: {e}"),
                })?;
            }
        }
        if let Some(l) = &self.orders {
            l.validate(self)?;
            for &n in l.orders.iter().filter(|&&n| n > 1) {
                self.order_rung(n).validate().map_err(|e| CertifyError::InvalidConfig {
                    field: "regression.order",
                    reason: format!("the order ladder's rung at order {n}: {e}"),
                })?;
            }
        }
        Ok(())
    }
}
