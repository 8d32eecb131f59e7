//! The regression of order `n`: one output, `m` inputs, the plant
//!
//! ```text
//! y⁽ⁿ⁾ + a_1 y⁽ⁿ⁻¹⁾ + … + a_n y = Σ_inputs (b_1 u⁽ⁿ⁻¹⁾ + … + b_n u) + c,
//! θ = (a_1..a_n, b_{1,1}..b_{1,n}, …, b_{m,1}..b_{m,n}, c),   d = n (1 + m) + 1,
//! ```
//!
//! for a plant whose output is not its whole state (a tank behind a tank, a mass read by its
//! position, a sensor lag). It extends the paper's integral regression (Section II-B, eq.
//! regressor), which is its `n = 1` case, [`LoopModel::FirstOrder`].
//!
//! ## The row
//!
//! Apply the `n`-fold sliding integral to the plant: with `J f(t) = ∫_{t−L}^t f` and
//! `Δ f(t) = f(t) − f(t−L)`, `J f' = Δ f`, the two commute and `Jⁿ 1 = Lⁿ`, so
//!
//! ```text
//! Δⁿ y(t) = Σ_k a_k (−J^k Δ^{n−k} y)(t) + Σ_k b_k (J^k Δ^{n−k} u)(t) + c Lⁿ,    k = 1..n.
//! ```
//!
//! A row uses the data of `[t − nL, t]` only: no initial conditions, no derivatives, and it holds
//! for a held input (the Dirac terms of `y⁽ⁿ⁾` where `u` steps are integrated away). For `n = 1`
//! it is the first-order column `Δy = J ∫y + B ∫u + c L` with `a_1 = −J`, `b_1 = B`.
//!
//! Under irregular sampling a fixed lag `L` would need `y` between samples, and the
//! interpolation error would be amplified by `Δⁿ`. The row therefore puts its knots on samples,
//! `τ_j = t_{k−(n−j)h}` (`h` the horizon in samples), and uses the B-spline `M` of degree `n − 1`
//! on those knots with `∫ M = 1`: by Peano's theorem `∫ M f⁽ⁿ⁾ = n! f[τ_0..τ_n]`, and by parts
//! `∫ M f⁽ⁿ⁻ᵏ⁾ = (−1)^{n−k} ∫ M⁽ⁿ⁻ᵏ⁾ f`. Scaled by `L̄ⁿ`, `L̄ = (τ_n − τ_0)/n`:
//!
//! ```text
//! z = L̄ⁿ n! y[τ_0..τ_n],   φ^y_k = −L̄ⁿ (−1)^{n−k} ⟨M⁽ⁿ⁻ᵏ⁾, y⟩,   φ^u_k = L̄ⁿ (−1)^{n−k} ⟨M⁽ⁿ⁻ᵏ⁾, u⟩,
//! intercept L̄ⁿ;      z ≈ φ θ.
//! ```
//!
//! On equal spacing this is the `J`-row exactly. `y` is the linear interpolant of its samples
//! and `u` is held (zero-order hold), so every integral is exact; the row's only error is `y`
//! between samples, `O(dt²)`. One row ends at every sample once `n h + 1` samples are in.
//!
//! ## The estimators
//!
//! - [`OrderNRegression`] is the streaming one: each sample costs `O(n² (1 + m))` for its row
//!   (sliding moments, below) and `O(d²)` for the window's sums; nothing is allocated per
//!   sample.
//! - [`OrderNFit`] is the batch one, over every row of a record or any run of its rows
//!   ([`OrderNRecord`], built once for many looks): least squares and the coefficients'
//!   covariance from the residual's known structure ([`OrderNFit`] explains it).
//! - [`OrderNWindow`] gives a sliding window's looks (the batch fit and its two model tests
//!   over the window's rows) from what earlier looks computed: each row once and the filtered
//!   rows' products in units, so that a look pays for what is new since the last, not for the
//!   whole window.
//!
//! They work on the samples relative to the record's (the window's) first sample, the origin,
//! which only the intercept sees; it is reported in the plant's own coordinates.

mod curvature;
mod fit;
mod past;
mod rows;
mod spline;
mod streaming;
mod sums;
mod variance;

pub use curvature::CurvatureTest;
pub use fit::{ClosedLoop, OrderNFit, OrderNRecord};
pub use past::{PastRowTest, RegressorTest};
pub use streaming::OrderNRegression;
pub use sums::{OrderNWindow, WindowLook};

use crate::{LoopModel, RegressionError};

/// The largest order the regression fits.
pub const MAX_ORDER: usize = 3;

/// Configuration of an order-`n` regression ([`OrderNRegression`], [`OrderNFit`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OrderNConfig {
    /// The plant's order: [`LoopModel::FirstOrder`] or [`LoopModel::Order`] `(2 | 3)`.
    pub model: LoopModel,
    /// Number of inputs `m >= 1` (one output).
    pub inputs: usize,
    /// Horizon `h >= 1` in samples: the knots are `h` samples apart, a row spans `n h` sample
    /// intervals.
    pub horizon: usize,
    /// Window `M` in rows of the streaming estimator (`M >= d`); the batch fit uses every row
    /// of its record.
    pub window: usize,
    /// The streaming estimator's warm-up: no estimate until this many rows are in
    /// (`d <= min_rows <= M`). Default `M`.
    pub min_rows: usize,
    /// Exact recompute of the streaming sums every this many rows (`1 <= refresh <= M`).
    /// Default `M`.
    pub refresh_period: usize,
    /// Identification: no estimate when the column-scaled Gram matrix has
    /// `λ_min <= ratio · λ_max`. Default `1e-10`; in `[0, 1)`.
    pub min_excitation_ratio: f64,
}

impl OrderNConfig {
    /// The documented defaults for a model, `m` inputs, window `M` and horizon `h`.
    #[must_use]
    pub fn new(model: LoopModel, inputs: usize, window: usize, horizon: usize) -> Self {
        Self {
            model,
            inputs,
            horizon,
            window,
            min_rows: window,
            refresh_period: window,
            min_excitation_ratio: 1e-10,
        }
    }

    /// The number of coefficients `d = n (1 + m) + 1`.
    #[must_use]
    pub fn width(&self) -> usize {
        self.shape().width()
    }

    /// The sample intervals a row spans, `n h`.
    #[must_use]
    pub fn span(&self) -> usize {
        self.model.span(self.horizon)
    }

    /// Check one sample `(t, y, u)` taken after a sample at `previous`: finite values, the
    /// configured number of inputs, a time after `previous`.
    ///
    /// # Errors
    /// [`RegressionError::DimensionMismatch`], [`RegressionError::NonFinite`] or
    /// [`RegressionError::NonIncreasingTime`], naming the value.
    pub fn check_sample(
        &self,
        previous: Option<f64>,
        t: f64,
        y: f64,
        u: &[f64],
    ) -> Result<(), RegressionError> {
        check_sample(previous, t, y, u, self.inputs)
    }

    pub(crate) fn shape(&self) -> Shape {
        Shape { n: self.model.order(), m: self.inputs, h: self.horizon }
    }

    /// Check every field.
    ///
    /// # Errors
    /// [`RegressionError::InvalidConfig`] naming the field and what is accepted.
    pub fn validate(&self) -> Result<(), RegressionError> {
        let bad = |field: &'static str, reason: String| {
            Err(RegressionError::InvalidConfig { field, reason })
        };
        if self.inputs == 0 {
            return bad("inputs", "must be at least 1".into());
        }
        if self.horizon == 0 {
            return bad("horizon", "must be at least 1 sample".into());
        }
        let d = self.width();
        if self.window < d {
            return bad(
                "window",
                format!("must be at least d = n (1 + m) + 1 = {d}, got {}", self.window),
            );
        }
        if self.min_rows < d || self.min_rows > self.window {
            return bad(
                "min_rows",
                format!("must lie in [d, window] = [{d}, {}], got {}", self.window, self.min_rows),
            );
        }
        crate::config::check_refresh_and_ratio(
            self.refresh_period,
            self.window,
            self.min_excitation_ratio,
        )
    }
}

/// The dimensions a row depends on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Shape {
    pub(crate) n: usize,
    pub(crate) m: usize,
    pub(crate) h: usize,
}

impl Shape {
    pub(crate) fn width(self) -> usize {
        self.n * (1 + self.m) + 1
    }

    pub(crate) fn span(self) -> usize {
        self.n * self.h
    }
}

/// Check one sample: finite values, the right number of inputs, time after `previous`.
pub(crate) fn check_sample(
    previous: Option<f64>,
    t: f64,
    y: f64,
    u: &[f64],
    inputs: usize,
) -> Result<(), RegressionError> {
    if u.len() != inputs {
        return Err(RegressionError::DimensionMismatch {
            field: "u",
            expected: inputs,
            got: u.len(),
        });
    }
    if !t.is_finite() {
        return Err(RegressionError::NonFinite { field: "t", index: 0, value: t });
    }
    if !y.is_finite() {
        return Err(RegressionError::NonFinite { field: "y", index: 0, value: y });
    }
    if let Some((index, &value)) = u.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(RegressionError::NonFinite { field: "u", index, value });
    }
    match previous {
        Some(previous) if t <= previous => {
            Err(RegressionError::NonIncreasingTime { previous, got: t })
        }
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests;
