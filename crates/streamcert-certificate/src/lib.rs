//! # streamcert-certificate
//!
//! The streaming contraction certificate of the paper (Section II-B) for one subsystem with
//! `p` outputs, `m` inputs and a candidate output-feedback gain `K` (`m × p`):
//!
//! ```text
//! J_cl = J_obs + B_obs K                                         (Section II-B)
//! β̂   = −λ_max(½ (J_cl + J_clᵀ))                                 (eq. betahat)
//! ρ    = c (1 + ‖K‖₂) RMS(R) / √(λ_min(Z Zᵀ / M) + λ)             (eq. rho)
//! β_cert = β̂ − ρ                                                 (Gaussian certificate)
//! ```
//!
//! and the deployment gate: the controller may be deployed once `β_cert >= β_margin` for `n_s`
//! consecutive samples ([`Gate`]).
//!
//! [`Certifier`] takes one sample at a time and returns the full [`Evidence`]: `β̂`, `ρ`, the
//! certificate, the gate, and the reason whenever it does not certify. It never certifies from
//! a window with a bad value (bad samples are rejected before they enter the window), from a
//! window still warming up, or from a regression without excitation.
//!
//! With an ambiguity model configured ([`CertifierConfig::ambiguity`]), the same certifier also
//! reports the Wasserstein certificate of Section III-B, with its own gate:
//!
//! ```text
//! β_cert(t, ε) = β̂ − ρ (1 + 2ε(t))                              (eq. wass_cert)
//! ```
//!
//! Since `ρ >= 0` and `ε >= 0`, the Wasserstein certificate is never above the Gaussian one and
//! equals it at `ε = 0`. The paper's Table II reports the Wasserstein certificate valid *more*
//! often than the Gaussian one; the formulas as written cannot produce that, and the
//! experiments report it as a discrepancy.
//!
//! The radius `ρ` is the paper's heuristic with a tuned constant `c`, not a confidence bound.
//!
//! Which residuals feed `ε` is not said by the paper ([`ResidualSource`]). The default is the
//! one-step residual: the `h`-step column residual is a sum of `h` per-step noise increments,
//! whose excess kurtosis is `1/h` of the per-step one (`0.6` instead of `3` for Laplace noise at
//! `h = 5`) and in which a spike is diluted by the other `h − 1` steps; the one-step residual
//! keeps the tail shape that `ε` is meant to detect. With `p > 1` outputs each output has its
//! own estimator and `ε` is the largest of their radii.
//!
//! ```
//! use streamcert_certificate::{Certifier, CertifierConfig};
//! use streamcert_regression::RegressionConfig;
//! let cfg = CertifierConfig::new(RegressionConfig::new(1, 1, 100, 5, 1e-4), vec![-1.0], 0.2, 0.05, 10);
//! let mut cert = Certifier::new(cfg)?;
//! let ev = cert.push(0.0, &[0.0], &[0.0])?;
//! assert!(ev.cert_gauss.is_none() && !ev.gauss_gate.open);
//! # Ok::<(), streamcert_certificate::CertifyError>(())
//! ```

mod gate;

pub use gate::{Gate, GateState};

use serde::{Deserialize, Serialize};
use streamcert_ambiguity::{AmbiguityConfig, AmbiguityError, AmbiguityRadius};
pub use streamcert_regression::ResidualSource;
use streamcert_regression::{
    EstimateStatus, RegressionConfig, RegressionError, SlidingRegression, linalg,
};

/// `β_cert(ε) = β̂ − ρ (1 + 2ε)` (paper eq. wass_cert); `ε = 0` is the Gaussian certificate
/// `β̂ − ρ`.
#[must_use]
pub fn certificate_value(beta_hat: f64, rho: f64, eps: f64) -> f64 {
    beta_hat - rho * (1.0 + 2.0 * eps)
}

/// `β_cert(t, ε)` on a grid of radii for one step (the certificate surface of Fig. 3):
/// `out[i] = β̂ − ρ (1 + 2 eps[i])`.
///
/// # Panics
/// If `out` is shorter than `eps`.
pub fn certificate_surface(beta_hat: f64, rho: f64, eps: &[f64], out: &mut [f64]) {
    for (o, &e) in out[..eps.len()].iter_mut().zip(eps) {
        *o = certificate_value(beta_hat, rho, e);
    }
}

/// The calibrated certificate (an addition to the paper; see [`calibrated_radius`]).
///
/// The paper's `ρ = c (1 + ‖K‖) RMS(R) / √(λ_min + λ)` has a tuned constant `c` and is checked
/// at every sample, so it gives no stated probability of deploying a controller that does not
/// contract. The calibrated mode replaces `c` by a radius derived from the regression's own
/// uncertainty and spends the risk `δ` over all the looks of the run, so that
/// `P(the calibrated gate ever opens for a candidate whose true rate is below β_margin) <= δ`
/// under the assumptions stated in [`calibrated_radius`].
///
/// Method: a confidence bound for a least-squares coefficient (Gaussian or sub-Gaussian
/// tails; for `p > 1` the χ² tail of Laurent and Massart, Ann. Statist. 2000, with Weyl's
/// eigenvalue perturbation inequality), an overlap factor `h` for the serial correlation of
/// the columns (a Newey–West style bound with `Σ|ρ_l| = h`), and a union bound over looks with
/// a summable spending sequence (Bonferroni over a sequential test, as in alpha-spending;
/// valid for any stopping rule).
///
/// For a control engineer: the paper's `c` sets how many "uncertainty units" are subtracted
/// from `β̂`, but nobody says how large a unit is or how often the gate is allowed to be wrong.
/// Here the unit is one standard deviation of the `β̂` estimate computed from this window (how
/// noisy the residuals are and how well the data excite the direction of the candidate gain),
/// and the number of units grows slowly with every sample looked at, so that the chance of ever
/// deploying a non-contracting controller stays below `δ` however long the gate watches. The
/// price is power: when the window does not determine `J_cl` (short window, little excitation
/// in the direction `[I; K]`, several outputs), the calibrated gate stays closed where the
/// paper's would open; `cargo xtask validity` shows both effects.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// Risk `δ ∈ (0, 1)` over the whole run (default of the CLI: 0.01).
    pub delta: f64,
}

/// Risk spent at the `k`-th look (`k >= 1`): `δ_k = 6 δ / (π² k²)`, so `Σ_k δ_k = δ` over an
/// unbounded run (a union bound over every look, valid for any stopping rule).
#[must_use]
pub fn look_risk(delta: f64, k: u64) -> f64 {
    let k = k.max(1) as f64;
    6.0 * delta / (std::f64::consts::PI * std::f64::consts::PI * k * k)
}

/// The calibrated radius for one look:
///
/// ```text
/// ρ_cal = √( h · σ̂² · λ_max(Tᵀ (ZZᵀ + λI)⁻¹ T) · q(δ_k) ),   T = [I_p; K],   σ̂ = RMS(R)
/// q = 2 ln(1/δ_k)                              (p = 1: Gaussian Chernoff bound)
/// q = p² + 2 √(p² ln(1/δ_k)) + 2 ln(1/δ_k)     (p > 1: Laurent–Massart χ² bound)
/// ```
///
/// Derivation: `Θ̂ − Θ = R Zᵀ (ZZᵀ + λI)⁻¹` (ridge bias neglected), so
/// `ΔJ_cl = (Θ̂ − Θ) T`. Each column residual is the sum of the `h` per-step noise increments of
/// its interval; overlapping columns share up to `h − 1` of them, so the autocorrelation has
/// `Σ_l |ρ_l| = h` and, by Cauchy–Schwarz lag by lag, the variance of any linear functional is
/// at most `h` times the i.i.d. one, `σ² aᵀ(ZZᵀ+λI)⁻¹a`. For `p = 1`, `β̂ − β* = −ΔJ_cl` is a
/// scalar with variance at most `h σ² TᵀG⁻¹T`; for `p > 1`, Weyl's inequality gives
/// `|λ_max(sym J̃) − λ_max(sym J)| <= ‖ΔJ_cl‖₂ <= ‖ΔJ_cl‖_F`, a quadratic form bounded by the
/// `χ²_{p²}` tail. With probability at least `1 − δ_k`, `β̂ − ρ_cal <= β*`.
///
/// Assumptions (when they fail the guarantee is void, and the Wasserstein radius is the
/// paper's hedge against heavier tails): the system is linear (or its Jacobian constant) over
/// the window; the per-step process noise is white, independent of the inputs, with
/// (sub-)Gaussian tails for the window sum (heavy-tailed noise with finite variance is covered
/// only through the central limit theorem); the excitation is exogenous and dominates the
/// noise in the regressor (otherwise the ordinary estimate is biased, see
/// `Estimator::Instrumented`); `σ̂` is a plug-in estimate; the ridge bias is negligible.
#[must_use]
pub fn calibrated_radius(horizon: usize, rms: f64, form_max: f64, p: usize, risk: f64) -> f64 {
    let x = (1.0 / risk).ln();
    let q = if p == 1 {
        2.0 * x
    } else {
        let k = (p * p) as f64;
        k + 2.0 * (k * x).sqrt() + 2.0 * x
    };
    (horizon as f64 * rms * rms * form_max.max(0.0) * q).sqrt()
}

/// What to do with a sample that has a NaN or infinite value, a non-increasing time or the
/// wrong number of values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BadSamplePolicy {
    /// Return the error; the sample is not absorbed (default).
    #[default]
    Reject,
    /// Count it, close the gates, and return evidence with [`NotCertified::SkippedSample`];
    /// the sample is not absorbed (integrals then span the gap, using the actual times).
    Skip,
}

/// Configuration of a [`Certifier`].
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
    /// Calibrated certificate beside the paper's (`None`: not computed).
    #[serde(default)]
    pub calibration: Option<Calibration>,
}

impl CertifierConfig {
    /// Required quantities; `bad_samples` defaults to [`BadSamplePolicy::Reject`], no ambiguity
    /// model (set [`ambiguity`](Self::ambiguity) for the Wasserstein certificate), one-step
    /// residuals.
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
            calibration: None,
        }
    }

    /// Check every field.
    ///
    /// # Errors
    /// [`CertifyError::InvalidConfig`] or the regression's configuration error.
    pub fn validate(&self) -> Result<(), CertifyError> {
        self.regression.validate()?;
        let (p, m) = (self.regression.outputs, self.regression.inputs);
        let bad = |field: &'static str, reason: String| {
            Err(CertifyError::InvalidConfig { field, reason })
        };
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
        if let Some(a) = &self.ambiguity {
            a.validate()?;
        }
        if let Some(c) = &self.calibration {
            if !(c.delta > 0.0 && c.delta < 1.0) {
                return bad("calibration.delta", format!("must lie in (0, 1), got {}", c.delta));
            }
            if self.regression.estimator != streamcert_regression::Estimator::Ordinary {
                return bad(
                    "calibration",
                    "the calibrated radius is derived for the ordinary (ridge) estimator".into(),
                );
            }
        }
        Ok(())
    }
}

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CertifyError {
    /// A configuration field is out of range.
    #[error("invalid certifier configuration: `{field}` {reason}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// What is wrong and what is accepted.
        reason: String,
    },
    /// The regression rejected a sample or its configuration.
    #[error(transparent)]
    Regression(#[from] RegressionError),
    /// The ambiguity configuration is invalid.
    #[error(transparent)]
    Ambiguity(#[from] AmbiguityError),
    /// A checkpoint could not be written or read.
    #[error("checkpoint: {0}")]
    Checkpoint(String),
}

/// Why a sample is not certified.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "reason", rename_all = "snake_case")]
pub enum NotCertified {
    /// The window holds fewer columns than required.
    WarmingUp {
        /// Columns in the window.
        columns: usize,
        /// Columns needed.
        needed: usize,
    },
    /// The regression is singular or near-singular (no excitation).
    InsufficientExcitation,
    /// The instrumented regression is singular.
    WeakInstruments,
    /// The certificate is below the margin.
    BelowMargin {
        /// The certificate.
        certificate: f64,
        /// The margin.
        margin: f64,
    },
    /// At or above the margin, but not yet for `n_s` consecutive samples.
    Accumulating {
        /// Consecutive samples so far.
        streak: usize,
        /// Needed.
        needed: usize,
    },
    /// The sample was bad and skipped ([`BadSamplePolicy::Skip`]).
    SkippedSample,
    /// No ambiguity model is configured, so there is no Wasserstein certificate.
    NoAmbiguityModel,
}

impl std::fmt::Display for NotCertified {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::WarmingUp { columns, needed } => {
                write!(f, "warming up ({columns}/{needed} columns)")
            }
            Self::InsufficientExcitation => f.write_str("insufficient excitation"),
            Self::WeakInstruments => f.write_str("weak instruments"),
            Self::BelowMargin { certificate, margin } => {
                write!(f, "certificate {certificate:.4} below margin {margin}")
            }
            Self::Accumulating { streak, needed } => {
                write!(f, "above margin for {streak}/{needed} samples")
            }
            Self::SkippedSample => f.write_str("bad sample skipped"),
            Self::NoAmbiguityModel => f.write_str("no ambiguity model configured"),
        }
    }
}

/// Everything the certifier knows after one sample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Evidence {
    /// Sample time.
    pub t: f64,
    /// `β̂` (eq. betahat), when the regression is ready.
    pub beta_hat: Option<f64>,
    /// `ρ` (eq. rho), when the regression is ready.
    pub rho: Option<f64>,
    /// Gaussian certificate `β̂ − ρ`.
    pub cert_gauss: Option<f64>,
    /// The Gaussian certificate's gate.
    pub gauss_gate: GateState,
    /// Why the Gaussian gate is closed (`None` when open).
    pub reason: Option<NotCertified>,
    /// Ambiguity radius `ε(t)` (eq. eps_est), when configured.
    pub eps: Option<f64>,
    /// Excess kurtosis of the residual tail window (largest over outputs).
    pub kurtosis: Option<f64>,
    /// Spike fraction `ŝ(t)` (largest over outputs).
    pub spike_fraction: Option<f64>,
    /// Wasserstein certificate `β̂ − ρ(1 + 2ε)` (eq. wass_cert).
    pub cert_wass: Option<f64>,
    /// The Wasserstein certificate's gate.
    pub wass_gate: GateState,
    /// Why the Wasserstein gate is closed (`None` when open).
    pub wass_reason: Option<NotCertified>,
    /// Calibrated radius `ρ_cal` ([`calibrated_radius`]), when configured.
    pub rho_calibrated: Option<f64>,
    /// Calibrated certificate `β̂ − ρ_cal`.
    pub cert_calibrated: Option<f64>,
    /// The calibrated certificate's gate (false-deployment probability at most `δ`).
    pub calibrated_gate: GateState,
    /// `RMS(R)`.
    pub rms_residual: Option<f64>,
    /// `λ_min(Z Zᵀ / M)`.
    pub gram_lambda_min: Option<f64>,
    /// Columns in the window.
    pub columns: usize,
}

/// The streaming certifier. Serde-serialisable: [`Certifier::checkpoint`] and
/// [`Certifier::restore`] continue a run with bit-identical output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Certifier {
    cfg: CertifierConfig,
    regression: SlidingRegression,
    gain_norm: f64,
    gauss: Gate,
    samples: u64,
    skipped: u64,
    wass: Gate,
    calibrated: Gate,
    looks: u64,
    tmat: Vec<f64>,
    form: Vec<f64>,
    form_scratch: Vec<f64>,
    ambiguity: Vec<AmbiguityRadius>,
    resid: Vec<f64>,
    jcl: Vec<f64>,
    work: Vec<f64>,
    eig_work: Vec<f64>,
}

/// The regression's outcome, reduced to what the certificate needs.
#[derive(Debug, Clone, Copy)]
struct Ready {
    beta_hat: f64,
    rho: f64,
    rms: f64,
    lambda_min: f64,
    rho_cal: Option<f64>,
}

impl Certifier {
    /// Validate and build.
    ///
    /// # Errors
    /// [`CertifyError::InvalidConfig`] or [`CertifyError::Regression`].
    ///
    /// ```
    /// use streamcert_certificate::{Certifier, CertifierConfig, CertifyError};
    /// use streamcert_regression::RegressionConfig;
    /// // K must be m × p = 1 × 1.
    /// let cfg = CertifierConfig::new(RegressionConfig::new(1, 1, 100, 5, 1e-4), vec![1.0, 2.0], 0.2, 0.05, 10);
    /// assert!(matches!(Certifier::new(cfg), Err(CertifyError::InvalidConfig { field: "gain", .. })));
    /// ```
    pub fn new(cfg: CertifierConfig) -> Result<Self, CertifyError> {
        cfg.validate()?;
        let (p, m) = (cfg.regression.outputs, cfg.regression.inputs);
        Ok(Self {
            regression: SlidingRegression::new(cfg.regression)?,
            gain_norm: linalg::spectral_norm(&cfg.gain, m, p),
            gauss: Gate::new(cfg.margin, cfg.consecutive),
            wass: Gate::new(cfg.margin, cfg.consecutive),
            calibrated: Gate::new(cfg.margin, cfg.consecutive),
            looks: 0,
            // T = [I_p; K] (d × p, row-major).
            tmat: (0..(p + m) * p)
                .map(|idx| {
                    let (r, c) = (idx / p, idx % p);
                    if r < p { f64::from(u8::from(r == c)) } else { cfg.gain[(r - p) * p + c] }
                })
                .collect(),
            form: vec![0.0; p * p],
            form_scratch: vec![0.0; (p + m) * p + linalg::eig_work_len(p)],
            ambiguity: match &cfg.ambiguity {
                Some(a) => (0..p).map(|_| AmbiguityRadius::new(*a)).collect::<Result<_, _>>()?,
                None => Vec::new(),
            },
            resid: vec![0.0; p],
            samples: 0,
            skipped: 0,
            jcl: vec![0.0; p * p],
            work: vec![0.0; p * p],
            eig_work: vec![0.0; linalg::eig_work_len(p)],
            cfg,
        })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &CertifierConfig {
        &self.cfg
    }

    /// `‖K‖₂`.
    #[must_use]
    pub fn gain_norm(&self) -> f64 {
        self.gain_norm
    }

    /// Samples absorbed so far.
    #[must_use]
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// Bad samples skipped so far (policy [`BadSamplePolicy::Skip`]).
    #[must_use]
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// The underlying regression.
    #[must_use]
    pub fn regression(&self) -> &SlidingRegression {
        &self.regression
    }

    /// Absorb one sample and return the evidence. No allocation.
    ///
    /// # Errors
    /// Under [`BadSamplePolicy::Reject`], the regression's sample error (the state is
    /// untouched, except after [`RegressionError::Overflow`], which clears the window).
    pub fn push(&mut self, t: f64, y: &[f64], u: &[f64]) -> Result<Evidence, CertifyError> {
        if let Err(e) = self.regression.push(t, y, u) {
            return match self.cfg.bad_samples {
                BadSamplePolicy::Reject => Err(e.into()),
                BadSamplePolicy::Skip => {
                    self.skipped += 1;
                    let amb = self.ambiguity_snapshot();
                    Ok(Evidence {
                        t,
                        beta_hat: None,
                        rho: None,
                        cert_gauss: None,
                        gauss_gate: self.gauss.update(t, None),
                        reason: Some(NotCertified::SkippedSample),
                        eps: amb.map(|a| a.0),
                        kurtosis: amb.and_then(|a| a.1),
                        spike_fraction: amb.map(|a| a.2),
                        cert_wass: None,
                        wass_gate: self.wass.update(t, None),
                        wass_reason: Some(NotCertified::SkippedSample),
                        rho_calibrated: None,
                        cert_calibrated: None,
                        calibrated_gate: self.calibrated.update(t, None),
                        rms_residual: None,
                        gram_lambda_min: None,
                        columns: self.regression.columns(),
                    })
                }
            };
        }
        self.samples += 1;
        let (ready, columns, blocked) = self.evaluate();
        let amb = self.ambiguity_snapshot();
        let cert_gauss = ready.map(|r| certificate_value(r.beta_hat, r.rho, 0.0));
        let cert_wass = match (ready, amb) {
            (Some(r), Some((eps, ..))) => Some(certificate_value(r.beta_hat, r.rho, eps)),
            _ => None,
        };
        let gauss_gate = self.gauss.update(t, cert_gauss);
        let wass_gate = self.wass.update(t, cert_wass);
        let rho_calibrated = ready.and_then(|r| r.rho_cal);
        let cert_calibrated = ready.and_then(|r| r.rho_cal.map(|rc| r.beta_hat - rc));
        // Without a calibration the calibrated gate never sees a certificate: it stays closed.
        let calibrated_gate = if self.cfg.calibration.is_some() {
            self.calibrated.update(t, cert_calibrated)
        } else {
            self.calibrated.state()
        };
        let reason = closed_reason(blocked, cert_gauss, &gauss_gate, &self.gauss);
        let wass_reason = if amb.is_none() {
            Some(NotCertified::NoAmbiguityModel)
        } else {
            closed_reason(blocked, cert_wass, &wass_gate, &self.wass)
        };
        Ok(Evidence {
            t,
            beta_hat: ready.map(|r| r.beta_hat),
            rho: ready.map(|r| r.rho),
            cert_gauss,
            gauss_gate,
            reason,
            eps: amb.map(|a| a.0),
            kurtosis: amb.and_then(|a| a.1),
            spike_fraction: amb.map(|a| a.2),
            cert_wass,
            wass_gate,
            wass_reason,
            rho_calibrated,
            cert_calibrated,
            calibrated_gate,
            rms_residual: ready.map(|r| r.rms),
            gram_lambda_min: ready.map(|r| r.lambda_min),
            columns,
        })
    }

    /// `(ε, κ_e, ŝ)`, each the largest over outputs; `None` without an ambiguity model.
    #[inline]
    fn ambiguity_snapshot(&self) -> Option<(f64, Option<f64>, f64)> {
        let (first, rest) = self.ambiguity.split_first()?;
        let s = first.snapshot();
        let (mut eps, mut kurtosis, mut spikes) = (s.eps, s.kurtosis, s.spike_fraction);
        for a in rest {
            let s = a.snapshot();
            eps = eps.max(s.eps);
            kurtosis = match (kurtosis, s.kurtosis) {
                (Some(x), Some(y)) => Some(x.max(y)),
                (x, y) => x.or(y),
            };
            spikes = spikes.max(s.spike_fraction);
        }
        Some((eps, kurtosis, spikes))
    }

    /// Solve the regression, form `β̂` and `ρ`, and feed the residuals to the ambiguity
    /// estimators; when not ready, say why.
    fn evaluate(&mut self) -> (Option<Ready>, usize, Option<NotCertified>) {
        // Literal dimensions for the paper's p = m = 1 let the compiler unroll the kernels.
        if self.cfg.regression.outputs == 1 && self.cfg.regression.inputs == 1 {
            self.evaluate_dims(1, 1)
        } else {
            self.evaluate_dims(self.cfg.regression.outputs, self.cfg.regression.inputs)
        }
    }

    /// [`evaluate`](Self::evaluate) with the configured dimensions passed in.
    #[inline(always)]
    fn evaluate_dims(
        &mut self,
        p: usize,
        m: usize,
    ) -> (Option<Ready>, usize, Option<NotCertified>) {
        let d = p + m;
        let residual_source = self.cfg.residuals;
        let est = self.regression.estimate();
        let columns = est.columns;
        let blocked = match est.status {
            EstimateStatus::Ready => None,
            EstimateStatus::WarmingUp { columns, needed } => {
                Some(NotCertified::WarmingUp { columns, needed })
            }
            EstimateStatus::InsufficientExcitation { .. } => {
                Some(NotCertified::InsufficientExcitation)
            }
            EstimateStatus::WeakInstruments { .. } => Some(NotCertified::WeakInstruments),
        };
        if blocked.is_some() {
            return (None, columns, blocked);
        }
        let (rms, lambda_min) = (est.rms_residual, est.gram_lambda_min);
        // J_cl = J_obs + B_obs K (views of exactly p × d and m × p, so literal dimensions
        // leave no bounds checks), then its symmetric part.
        let (theta, k) = (&est.theta[..p * d], &self.cfg.gain[..m * p]);
        let jcl = &mut self.jcl[..p * p];
        for i in 0..p {
            for j in 0..p {
                let mut v = theta[i * d + j];
                for l in 0..m {
                    v += theta[i * d + p + l] * k[l * p + j];
                }
                jcl[i * p + j] = v;
            }
        }
        // Residuals for ε: ΔY − Θ̂ Z of the newest interval or column.
        let scalar_theta = (d == 2).then(|| [est.theta[0], est.theta[1]]);
        if let ([amb], ResidualSource::OneStep, Some(th), Some((z1, dy1))) = (
            &mut self.ambiguity[..],
            residual_source,
            scalar_theta,
            self.regression.newest_interval(),
        ) {
            // p = m = 1 with the default residual, written out: going through `residual` and
            // the `resid` buffer costs about 10 % of the whole step (measured A/B with
            // criterion), and this is the paper's case.
            let _ = amb.push(dy1[0] - (th[0] * z1[0] + th[1] * z1[1]));
        } else if !self.ambiguity.is_empty()
            && self.regression.residual(residual_source, &mut self.resid)
        {
            for (amb, &r) in self.ambiguity.iter_mut().zip(&self.resid[..p]) {
                // A non-finite residual is not absorbed (AmbiguityError::NonFinite).
                let _ = amb.push(r);
            }
        }
        for i in 0..p {
            for j in i..p {
                self.work[i * p + j] = 0.5 * (self.jcl[i * p + j] + self.jcl[j * p + i]);
            }
        }
        let lambda_max = linalg::sym_eig_extremes(&self.work, p, &mut self.eig_work).1;
        let beta_hat = -lambda_max;
        let rho = self.cfg.conservatism * (1.0 + self.gain_norm) * rms
            / (lambda_min + self.cfg.regression.ridge).sqrt();
        if !(beta_hat.is_finite() && rho.is_finite()) {
            return (None, columns, Some(NotCertified::InsufficientExcitation));
        }
        let rho_cal = match self.cfg.calibration {
            Some(c) => self.calibrated_radius_now(c.delta, rms),
            None => None,
        };
        (Some(Ready { beta_hat, rho, rms, lambda_min, rho_cal }), columns, None)
    }

    /// The calibrated radius for this look ([`calibrated_radius`]), from the latest estimate;
    /// counts the look. `None` when the estimate has no Gram factor.
    fn calibrated_radius_now(&mut self, delta: f64, rms: f64) -> Option<f64> {
        let (p, m) = (self.cfg.regression.outputs, self.cfg.regression.inputs);
        let d = p + m;
        let (scratch, eig) = self.form_scratch.split_at_mut(d * p);
        if !self.regression.gram_inverse_form(&self.tmat, p, scratch, &mut self.form) {
            return None;
        }
        self.looks += 1;
        let form_max = linalg::sym_eig_extremes(&self.form, p, eig).1;
        let risk = look_risk(delta, self.looks);
        Some(calibrated_radius(self.cfg.regression.horizon, rms, form_max, p, risk))
    }

    /// Serialise the full streaming state as JSON (floats round-trip exactly).
    ///
    /// # Errors
    /// [`CertifyError::Checkpoint`] if serialisation fails.
    pub fn checkpoint(&self) -> Result<String, CertifyError> {
        serde_json::to_string(self).map_err(|e| CertifyError::Checkpoint(e.to_string()))
    }

    /// Restore a state written by [`checkpoint`](Self::checkpoint), checking its consistency.
    ///
    /// # Errors
    /// [`CertifyError::Checkpoint`] for malformed JSON or an inconsistent state.
    pub fn restore(json: &str) -> Result<Self, CertifyError> {
        let c: Self =
            serde_json::from_str(json).map_err(|e| CertifyError::Checkpoint(e.to_string()))?;
        c.cfg.validate()?;
        c.regression.check_state().map_err(|e| CertifyError::Checkpoint(e.to_string()))?;
        let p = c.cfg.regression.outputs;
        if c.ambiguity.len() != if c.cfg.ambiguity.is_some() { p } else { 0 }
            || c.ambiguity
                .iter()
                .any(|a| Some(*a.config()) != c.cfg.ambiguity || !a.is_consistent())
        {
            return Err(CertifyError::Checkpoint(
                "ambiguity state does not match its configuration".into(),
            ));
        }
        if c.regression.config() != &c.cfg.regression
            || c.jcl.len() != p * p
            || c.work.len() != p * p
            || c.resid.len() != p
            || c.tmat.len() != (p + c.cfg.regression.inputs) * p
            || c.form.len() != p * p
        {
            return Err(CertifyError::Checkpoint("state does not match its configuration".into()));
        }
        Ok(c)
    }
}

/// Why a gate is closed after this sample (`None` when it is open).
fn closed_reason(
    blocked: Option<NotCertified>,
    cert: Option<f64>,
    state: &GateState,
    gate: &Gate,
) -> Option<NotCertified> {
    if state.open {
        return None;
    }
    if blocked.is_some() {
        return blocked;
    }
    match cert {
        Some(c) if c >= gate.margin() => {
            Some(NotCertified::Accumulating { streak: state.streak, needed: gate.needed() })
        }
        Some(c) => Some(NotCertified::BelowMargin { certificate: c, margin: gate.margin() }),
        None => Some(NotCertified::InsufficientExcitation),
    }
}
