//! What the certifier reports after each sample: [`Evidence`], and [`NotCertified`], why a gate
//! is closed.

use serde::{Deserialize, Serialize};

use crate::GateState;

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
    /// No calibration is configured, so there is no calibrated certificate.
    NoCalibration,
    /// The step before this sample is a gap (larger than `gap_factor` times the reference
    /// step): the window was reset, so it is warming up again.
    Gap {
        /// The step.
        dt: f64,
        /// The reference step (median of the last 32).
        reference: f64,
    },
    /// Calibrated certificate: a window whose latest look is at least as recent as every
    /// standing certificate bounds the rate from above below the margin (the loop stopped
    /// contracting enough, for example after a plant change).
    RateDropped {
        /// The window length that gives the bound.
        window: usize,
        /// Its upper bound `β̂_w + ρ_w`.
        upper: f64,
    },
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
            Self::NoCalibration => f.write_str("no calibration configured"),
            Self::Gap { dt, reference } => {
                write!(f, "gap of {dt} s (reference step {reference} s): window reset")
            }
            Self::RateDropped { window, upper } => write!(
                f,
                "window {window}: the rate is at most {upper:.4}, below the margin (dynamics changed?)"
            ),
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
    /// Calibrated radius `ρ_w` of the window that gives the calibrated certificate
    /// ([`calibrated_radius`]), when configured and a look stands.
    pub rho_calibrated: Option<f64>,
    /// Calibrated certificate `β̂_w − ρ_w` (the largest standing window look; its `β̂_w` is the
    /// instrumented estimate of that window, not `beta_hat`).
    pub cert_calibrated: Option<f64>,
    /// Window length `M_w` (columns) of that look.
    pub calibrated_window: Option<usize>,
    /// The calibrated certificate's gate (false-deployment probability at most `δ`).
    pub calibrated_gate: GateState,
    /// Why the calibrated gate is closed (`None` when open).
    pub calibrated_reason: Option<NotCertified>,
    /// `RMS(R)`.
    pub rms_residual: Option<f64>,
    /// `λ_min(Z Zᵀ / M)`.
    pub gram_lambda_min: Option<f64>,
    /// Columns in the window.
    pub columns: usize,
}
