//! The outcome of [`SlidingRegression::estimate`](crate::SlidingRegression::estimate): its
//! status and a borrowed view of `Θ̂` with the window's summary statistics.

use serde::{Deserialize, Serialize};

/// Outcome of [`SlidingRegression::estimate`](crate::SlidingRegression::estimate).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum EstimateStatus {
    /// `theta` holds a valid estimate.
    Ready,
    /// Fewer columns than `min_columns`.
    WarmingUp {
        /// Columns in the window.
        columns: usize,
        /// Columns needed.
        needed: usize,
    },
    /// `λ_min(ZZᵀ) <= ratio · λ_max(ZZᵀ)`: the data do not excite every direction of `Z`
    /// (for example `u = K y` without dither).
    InsufficientExcitation {
        /// `λ_min(ZZᵀ)`.
        lambda_min: f64,
        /// `λ_max(ZZᵀ)`.
        lambda_max: f64,
    },
    /// The instrumented system `Z Wᵀ + λ I` is numerically singular.
    WeakInstruments {
        /// Pivot ratio of its LU factorisation.
        pivot_ratio: f64,
    },
}

/// A view of the current estimate. Fields other than `status` and `columns` are only
/// meaningful when `status == Ready`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate<'a> {
    /// Whether the estimate is usable, and why not.
    pub status: EstimateStatus,
    /// `Θ̂ = [J_obs B_obs]`, `p × (p + m)`, row-major.
    pub theta: &'a [f64],
    /// `p`.
    pub outputs: usize,
    /// `m`.
    pub inputs: usize,
    /// The affine model's intercept `ĉ` per output (`ΔY_q ≈ Θ̂ Z_q + ĉ τ_q`, a rate: units of
    /// `y` per unit of time, in the working coordinates of
    /// [`SlidingRegression::origin`](crate::SlidingRegression::origin)); empty through the
    /// origin.
    pub intercept: &'a [f64],
    /// `RMS(R) = √(‖ΔY − Θ̂ Z‖²_F / (p M))` (`R = ΔY − Θ̂ Z − ĉ τ` under the affine model),
    /// computed from the (centred) sufficient statistics as
    /// `tr S − 2 tr(Θ̂ Cᵀ) + tr(Θ̂ G Θ̂ᵀ)`, clamped at 0.
    pub rms_residual: f64,
    /// `λ_min(Z Zᵀ / M)` (of the centred `Z Zᵀ − a_z a_zᵀ/T` under the affine model).
    pub gram_lambda_min: f64,
    /// `λ_max(Z Zᵀ / M)` (centred likewise).
    pub gram_lambda_max: f64,
    /// Number of columns `M` currently in the window.
    pub columns: usize,
}

impl Estimate<'_> {
    /// `J_obs[i][j]` (`p × p`).
    #[must_use]
    pub fn j_obs(&self, i: usize, j: usize) -> f64 {
        self.theta[i * (self.outputs + self.inputs) + j]
    }
    /// `B_obs[i][j]` (`p × m`).
    #[must_use]
    pub fn b_obs(&self, i: usize, j: usize) -> f64 {
        self.theta[i * (self.outputs + self.inputs) + self.outputs + j]
    }
}
