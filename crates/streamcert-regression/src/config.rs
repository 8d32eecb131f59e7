//! Configuration of the sliding regression: the integral and estimator choices and
//! [`RegressionConfig`] with its validation.

use serde::{Deserialize, Serialize};

use crate::{LoopModel, RegressionError};

/// How `∫ u dτ` is computed over each sample interval `[t_j, t_{j+1}]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InputIntegral {
    /// `(t_{j+1} − t_j)(u_j + u_{j+1}) / 2`, as in the paper (exact for a piecewise-linear
    /// input).
    Trapezoidal,
    /// `(t_{j+1} − t_j) u_j`: exact when the input is held from `t_j` until `t_{j+1}` (a
    /// digital controller with a zero-order hold, and the simulator of `streamcert-dynamics`).
    ZeroOrderHold,
}

/// Which estimator solves the window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Estimator {
    /// Ridge least squares `Θ̂ = ΔY Zᵀ (Z Zᵀ + λ I)⁻¹` (paper).
    Ordinary,
    /// Instrumental variables with the previous interval's regressor as instrument (see the
    /// crate docs for the assumption it needs).
    Instrumented,
}

/// The model the window is fitted to.
///
/// A plant runs about an operating point `(y₀, u₀)`: `ẏ = J (y − y₀) + B (u − u₀)` is
/// `ẏ = J y + B u + c` with `c = −J y₀ − B u₀`. Through the origin (`c = 0`, the paper's eq.
/// regressor) the operating point enters `Θ̂` as if it were dynamics, so the verdict changes
/// with the units of the sensor (°C or K) and with the set point. The affine model fits `c`
/// beside `Θ` and its verdicts are invariant to constant offsets of `y` and `u`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Model {
    /// `ΔY_q ≈ Θ Z_q + c τ_q`, with `τ_q` the time the column spans (the integral of `1`, so a
    /// constant drift `c` is exact under irregular sampling too) and `c` not penalised by the
    /// ridge. Solved by partialling `τ` out of every sum (Frisch–Waugh–Lovell): with
    /// `a_z = Σ Z τ`, `a_y = Σ ΔY τ`, `T = Σ τ²`, the estimator sees `ZZᵀ − a_z a_zᵀ/T`,
    /// `ΔY Zᵀ − a_y a_zᵀ/T`, `ΔYΔYᵀ − a_y a_yᵀ/T` (and `Z Wᵀ − a_z a_wᵀ/T`,
    /// `ΔY Wᵀ − a_y a_wᵀ/T` with `a_w = Σ W τ` for the instrumented estimator), which gives
    /// the same `Θ̂` as the fit with `τ` as an extra regressor. `ĉ = (a_y − Θ̂ a_z)/T`. The
    /// samples are integrated relative to the first sample's `(y, u)` (kept across resets), so
    /// the sums hold the plant's excursions, not its operating point: at `y₀ = 10⁶` the
    /// digits are those of a centred record. Default.
    #[default]
    Affine,
    /// `ΔY ≈ Θ Z` (the paper's eq. regressor): valid only when the operating point is the
    /// origin of `y` and `u`. Kept for reproducing the paper and for loops known to run about
    /// zero; an explicit choice.
    ThroughOrigin,
}

/// The interval over which [`SlidingRegression::residual`](crate::SlidingRegression::residual) evaluates `ΔY − Θ̂ Z`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ResidualSource {
    /// The newest sample interval `[t_{k−1}, t_k]` (one-step residual; keeps the tails of the
    /// per-step noise). Default.
    #[default]
    OneStep,
    /// The newest `h`-step column (nearly Gaussian by averaging `h` increments).
    Horizon,
}

/// Configuration of a [`SlidingRegression`](crate::SlidingRegression). Build with [`RegressionConfig::new`] for the
/// documented defaults, then adjust public fields.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegressionConfig {
    /// Number of outputs `p >= 1`.
    pub outputs: usize,
    /// Number of inputs `m >= 1`.
    pub inputs: usize,
    /// The model: [`Model::Affine`] (default) or [`Model::ThroughOrigin`] (the paper).
    #[serde(default)]
    pub model: Model,
    /// The loop model the columns are built for ([`LoopModel`]): the width of a column, the
    /// samples it spans, the hidden-dynamics guard's regressors and the fast paths. Default
    /// [`LoopModel::FirstOrder`], the paper's (left out of the serialised form, so that states
    /// and fingerprints read and compare as before).
    #[serde(default, skip_serializing_if = "LoopModel::is_first_order")]
    pub order: LoopModel,
    /// Window length `M` in columns (`M >= p + m`, one more for the affine model).
    pub window: usize,
    /// Horizon `h >= 1` in samples: each column spans `h` sample intervals.
    pub horizon: usize,
    /// Ridge `λ >= 0` (paper Table I: `1e-4`).
    pub ridge: f64,
    /// Warm-up: no estimate until the window holds this many columns (`p + m <= min_columns
    /// <= M`). Default `M`.
    pub min_columns: usize,
    /// Input integral rule. Default [`InputIntegral::Trapezoidal`] (the paper).
    pub input_integral: InputIntegral,
    /// Estimator. Default [`Estimator::Ordinary`] (the paper).
    pub estimator: Estimator,
    /// Exact recompute of the statistics every this many columns (`1 <= refresh <= M`).
    /// Default `M`.
    pub refresh_period: usize,
    /// Excitation test: the estimate is refused when `λ_min(ZZᵀ) <= ratio · λ_max(ZZᵀ)`
    /// (and, for the instrumented estimator, when the LU pivot ratio of `Z Wᵀ` is below
    /// it). Default `1e-9`; must lie in `[0, 1)`.
    pub min_excitation_ratio: f64,
}

impl RegressionConfig {
    /// Required quantities; every other field gets its documented default.
    #[must_use]
    pub fn new(outputs: usize, inputs: usize, window: usize, horizon: usize, ridge: f64) -> Self {
        Self {
            outputs,
            inputs,
            model: Model::Affine,
            order: LoopModel::FirstOrder,
            window,
            horizon,
            ridge,
            min_columns: window,
            input_integral: InputIntegral::Trapezoidal,
            estimator: Estimator::Ordinary,
            refresh_period: window,
            min_excitation_ratio: 1e-9,
        }
    }

    /// Check every field.
    ///
    /// # Errors
    /// [`RegressionError::InvalidConfig`] naming the field and what is accepted.
    pub fn validate(&self) -> Result<(), RegressionError> {
        let bad = |field: &'static str, reason: String| {
            Err(RegressionError::InvalidConfig { field, reason })
        };
        // The affine model spends one more column on its intercept.
        let d = self.outputs + self.inputs + usize::from(self.model == Model::Affine);
        if self.outputs == 0 {
            return bad("outputs", "must be at least 1".into());
        }
        if !self.order.is_first_order() {
            return bad(
                "order",
                format!(
                    "is {}: the sliding regression fits the first-order model (order = 1); a \
                     model of order 2 or 3 is fitted by OrderNRegression or OrderNFit",
                    self.order.order()
                ),
            );
        }
        if self.inputs == 0 {
            return bad("inputs", "must be at least 1".into());
        }
        if self.horizon == 0 {
            return bad("horizon", "must be at least 1 sample".into());
        }
        if self.window < d {
            return bad(
                "window",
                format!(
                    "must be at least p + m (+ 1 for the affine model) = {d}, got {}",
                    self.window
                ),
            );
        }
        if !(self.ridge >= 0.0 && self.ridge.is_finite()) {
            return bad("ridge", format!("must be finite and >= 0, got {}", self.ridge));
        }
        if self.min_columns < d || self.min_columns > self.window {
            return bad(
                "min_columns",
                format!(
                    "must lie in [p + m (+ 1 affine), window] = [{d}, {}], got {}",
                    self.window, self.min_columns
                ),
            );
        }
        check_refresh_and_ratio(self.refresh_period, self.window, self.min_excitation_ratio)
    }
}

/// The checks every windowed regression's configuration shares: an exact recompute every
/// `1 <= refresh_period <= window` columns, and an excitation ratio in `[0, 1)`.
pub(crate) fn check_refresh_and_ratio(
    refresh_period: usize,
    window: usize,
    min_excitation_ratio: f64,
) -> Result<(), RegressionError> {
    let bad =
        |field: &'static str, reason: String| Err(RegressionError::InvalidConfig { field, reason });
    if refresh_period == 0 || refresh_period > window {
        return bad(
            "refresh_period",
            format!("must lie in [1, window] = [1, {window}], got {refresh_period}"),
        );
    }
    if !(0.0..1.0).contains(&min_excitation_ratio) {
        return bad(
            "min_excitation_ratio",
            format!("must lie in [0, 1), got {min_excitation_ratio}"),
        );
    }
    Ok(())
}
