//! # streamcert-regression
//!
//! Streaming integral regression on a sliding window (paper Section II-B, eq. regressor):
//! for each column `q` of a window of `M` columns with horizon `h` samples,
//!
//! ```text
//! ΔY_q = y(t_q + h) − y(t_q),      Z_q = [ ∫ y dτ ; ∫ u dτ ]  over [t_q, t_q + h],
//! ΔY ≈ Θ Z,   Θ = [J_obs  B_obs],   Θ̂ = ΔY Zᵀ (Z Zᵀ + λ I)⁻¹           (ridge)
//! R = ΔY − Θ̂ Z,   RMS(R) = √(‖R‖²_F / (p M)),   λ_min(Z Zᵀ / M).
//! ```
//!
//! A new column ends at every sample once `h + 1` samples are in, so consecutive columns
//! overlap (stride one sample). Integrals use the actual sample times, so non-uniform
//! sampling is handled: `∫y` is trapezoidal; `∫u` is trapezoidal (the paper) or exact for a
//! zero-order-held input ([`InputIntegral`]).
//!
//! Key design decision: the window keeps sufficient statistics `G = Z Zᵀ`, `C = ΔY Zᵀ`,
//! `S = ΔY ΔYᵀ` (and their instrumented counterparts). A sample adds the new column's outer
//! products and subtracts the evicted one's: `O(d²)` with `d = p + m`, no allocation,
//! independent of `M`. Every `refresh_period <= M` columns the statistics are recomputed
//! exactly from the ring buffer, so rounding drift stays bounded over arbitrarily long runs.
//! [`SlidingRegression::estimate`] then costs `O(d³)` (a Cholesky or LU solve and a small
//! symmetric eigenproblem), also independent of `M` and allocation-free.
//!
//! ## The instrumented variant
//!
//! With process noise `w`, `ΔY_q − Θ Z_q = ∫ w` over the column's interval, and `∫ y` over the
//! same interval responds to that noise, so the regressor is correlated with the error and the
//! ordinary estimate is biased (toward `J_obs = 0` for a scalar stable process driven only by
//! noise, where `ΔY` and `∫ y` are then nearly uncorrelated with the drift signal). The
//! instrumented estimator ([`Estimator::Instrumented`]) uses as instrument for column `q`
//! the regressor of the interval that ends where column `q` begins, `W_q = Z_{q−h}`, built
//! only from data up to `t_q`:
//!
//! ```text
//! Θ̂_IV (Z Wᵀ + λ I) = ΔY Wᵀ
//! ```
//!
//! Assumption: the noise over `[t_q, t_q + h]` is uncorrelated with everything observed up to
//! `t_q` (white process noise, no measurement noise, or measurement noise white across
//! samples further apart than `h`), and the instruments are relevant (`Z Wᵀ` well
//! conditioned: the signal must have memory over `h` samples, which a held dither provides).
//!
//! ```
//! use streamcert_regression::*;
//! let cfg = RegressionConfig {
//!     input_integral: InputIntegral::ZeroOrderHold,
//!     ..RegressionConfig::new(1, 1, 50, 5, 1e-6)
//! };
//! let mut reg = SlidingRegression::new(cfg)?;
//! // ẏ = −2 y + u with a square-wave input, sampled at dt = 0.01 (exact discretisation).
//! let (dt, mut y) = (0.01f64, 0.0f64);
//! for k in 0..400 {
//!     let u = if (k / 25) % 2 == 0 { 1.0 } else { -1.0 };
//!     reg.push(k as f64 * dt, &[y], &[u])?;
//!     let a = (-2.0 * dt).exp();
//!     y = a * y + (1.0 - a) / 2.0 * u;
//! }
//! let est = reg.estimate();
//! assert_eq!(est.status, EstimateStatus::Ready);
//! assert!((est.theta[0] + 2.0).abs() < 0.05 && (est.theta[1] - 1.0).abs() < 0.05);
//! # Ok::<(), streamcert_regression::RegressionError>(())
//! ```

pub mod linalg;
mod windows;

pub use windows::{InstrumentedWindows, WindowEstimate};

use serde::{Deserialize, Serialize};

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

/// The interval over which [`SlidingRegression::residual`] evaluates `ΔY − Θ̂ Z`.
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

/// Configuration of a [`SlidingRegression`]. Build with [`RegressionConfig::new`] for the
/// documented defaults, then adjust public fields.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegressionConfig {
    /// Number of outputs `p >= 1`.
    pub outputs: usize,
    /// Number of inputs `m >= 1`.
    pub inputs: usize,
    /// Window length `M` in columns (`M >= p + m`).
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
        let d = self.outputs + self.inputs;
        if self.outputs == 0 {
            return bad("outputs", "must be at least 1".into());
        }
        if self.inputs == 0 {
            return bad("inputs", "must be at least 1".into());
        }
        if self.horizon == 0 {
            return bad("horizon", "must be at least 1 sample".into());
        }
        if self.window < d {
            return bad("window", format!("must be at least p + m = {d}, got {}", self.window));
        }
        if !(self.ridge >= 0.0 && self.ridge.is_finite()) {
            return bad("ridge", format!("must be finite and >= 0, got {}", self.ridge));
        }
        if self.min_columns < d || self.min_columns > self.window {
            return bad(
                "min_columns",
                format!(
                    "must lie in [p + m, window] = [{d}, {}], got {}",
                    self.window, self.min_columns
                ),
            );
        }
        if self.refresh_period == 0 || self.refresh_period > self.window {
            return bad(
                "refresh_period",
                format!(
                    "must lie in [1, window] = [1, {}], got {}",
                    self.window, self.refresh_period
                ),
            );
        }
        if !(0.0..1.0).contains(&self.min_excitation_ratio) {
            return bad(
                "min_excitation_ratio",
                format!("must lie in [0, 1), got {}", self.min_excitation_ratio),
            );
        }
        Ok(())
    }
}

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RegressionError {
    /// A configuration field is out of range.
    #[error("invalid regression configuration: `{field}` {reason}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// What is wrong and what is accepted.
        reason: String,
    },
    /// A sample value is NaN or infinite. The sample was not absorbed.
    #[error("sample {field}[{index}] is not finite ({value}); the sample was rejected")]
    NonFinite {
        /// `"t"`, `"y"` or `"u"`.
        field: &'static str,
        /// Index within the field.
        index: usize,
        /// The value.
        value: f64,
    },
    /// Sample time not strictly after the previous one. The sample was not absorbed.
    #[error(
        "sample time {got} is not after the previous sample time {previous}; the sample was rejected"
    )]
    NonIncreasingTime {
        /// Previous accepted time.
        previous: f64,
        /// Offending time.
        got: f64,
    },
    /// A sample has the wrong number of outputs or inputs. The sample was not absorbed.
    #[error("sample {field} has {got} values, expected {expected}; the sample was rejected")]
    DimensionMismatch {
        /// `"y"` or `"u"`.
        field: &'static str,
        /// Expected length.
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// Finite samples produced a non-finite column (overflow). The window was cleared.
    #[error("column overflowed to a non-finite value; the window was cleared")]
    Overflow,
    /// A restored state is inconsistent with its configuration.
    #[error("corrupt regression state: {0}")]
    CorruptState(String),
}

/// Outcome of [`SlidingRegression::estimate`].
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
    /// `RMS(R) = √(‖ΔY − Θ̂ Z‖²_F / (p M))`, computed from the sufficient statistics as
    /// `tr S − 2 tr(Θ̂ Cᵀ) + tr(Θ̂ G Θ̂ᵀ)`, clamped at 0.
    pub rms_residual: f64,
    /// `λ_min(Z Zᵀ / M)`.
    pub gram_lambda_min: f64,
    /// `λ_max(Z Zᵀ / M)`.
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

/// Element-wise copy; for the short slices of the hot path a plain loop beats a `memcpy` call.
#[inline]
fn copy(dst: &mut [f64], src: &[f64]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d = *s;
    }
}

/// `true` when all three values are finite: `0 · x` is `±0` for a finite `x` and NaN for an
/// infinite or NaN one, so one comparison tests the three (the per-sample path's check).
#[inline(always)]
fn finite3(a: f64, b: f64, c: f64) -> bool {
    0.0 * a + 0.0 * b + 0.0 * c == 0.0
}

/// `(i + 1) mod cap` without a division.
#[inline]
fn next(i: usize, cap: usize) -> usize {
    if i + 1 == cap { 0 } else { i + 1 }
}

/// The streaming estimator. See the crate docs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlidingRegression {
    cfg: RegressionConfig,
    // Sample history, ring of h + 1 samples; `hist_head` is the newest.
    hist_t: Vec<f64>,
    hist_y: Vec<f64>,
    hist_u: Vec<f64>,
    hist_len: usize,
    hist_head: usize,
    // Regressor history for instruments, ring of h + 1 columns.
    zhist: Vec<f64>,
    zhist_len: usize,
    zhist_head: usize,
    // Column ring of M; `col_next` is where the next column goes.
    col_z: Vec<f64>,
    col_dy: Vec<f64>,
    col_w: Vec<f64>,
    col_len: usize,
    col_next: usize,
    // Sufficient statistics.
    g: Vec<f64>,
    c: Vec<f64>,
    s: Vec<f64>,
    gw: Vec<f64>,
    cw: Vec<f64>,
    since_refresh: usize,
    // Output and scratch.
    theta: Vec<f64>,
    work: Vec<f64>,
    work2: Vec<f64>,
    piv: Vec<usize>,
    z: Vec<f64>,
    dy: Vec<f64>,
    // Per-interval regressors `[∫y; ∫u]` over `[t_{j−1}, t_j]`, ring aligned with the sample
    // ring (slot `j` holds the interval that ends at sample slot `j`), stored twice (slots `j`
    // and `j + h + 1`) so the `h` intervals of a column are one contiguous run.
    hist_z1: Vec<f64>,
    // The newest single sample interval's output increment.
    dy1: Vec<f64>,
    // `1 / M`, so the per-sample estimate needs no division for it (checked on restore).
    inv_window: f64,
    // Columns built since construction or the last reset.
    #[serde(default)]
    built: u64,
}

impl SlidingRegression {
    /// Validate the configuration and reserve every buffer.
    ///
    /// # Errors
    /// [`RegressionError::InvalidConfig`].
    ///
    /// ```
    /// use streamcert_regression::{RegressionConfig, RegressionError, SlidingRegression};
    /// assert!(SlidingRegression::new(RegressionConfig::new(1, 1, 150, 5, 1e-4)).is_ok());
    /// let err = SlidingRegression::new(RegressionConfig::new(1, 1, 150, 0, 1e-4)).unwrap_err();
    /// assert!(matches!(err, RegressionError::InvalidConfig { field: "horizon", .. }));
    /// ```
    pub fn new(cfg: RegressionConfig) -> Result<Self, RegressionError> {
        cfg.validate()?;
        let (p, m, h, mm) = (cfg.outputs, cfg.inputs, cfg.horizon, cfg.window);
        let d = p + m;
        Ok(Self {
            cfg,
            hist_t: vec![0.0; h + 1],
            hist_y: vec![0.0; (h + 1) * p],
            hist_u: vec![0.0; (h + 1) * m],
            hist_len: 0,
            hist_head: 0,
            zhist: vec![0.0; (h + 1) * d],
            zhist_len: 0,
            zhist_head: 0,
            col_z: vec![0.0; mm * d],
            col_dy: vec![0.0; mm * p],
            col_w: vec![0.0; mm * d],
            col_len: 0,
            col_next: 0,
            g: vec![0.0; d * d],
            c: vec![0.0; p * d],
            s: vec![0.0; p * p],
            gw: vec![0.0; d * d],
            cw: vec![0.0; p * d],
            since_refresh: 0,
            theta: vec![0.0; p * d],
            work: vec![0.0; linalg::eig_work_len(d)],
            work2: vec![0.0; d * d],
            piv: vec![0; d],
            z: vec![0.0; d],
            dy: vec![0.0; p],
            hist_z1: vec![0.0; 2 * (h + 1) * d],
            dy1: vec![0.0; p],
            inv_window: 1.0 / mm as f64,
            built: 0,
        })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &RegressionConfig {
        &self.cfg
    }

    /// Number of columns in the window.
    #[must_use]
    pub fn columns(&self) -> usize {
        self.col_len
    }

    /// Time of the newest accepted sample, if any.
    #[must_use]
    pub fn last_time(&self) -> Option<f64> {
        (self.hist_len > 0).then(|| self.hist_t[self.hist_head])
    }

    /// The newest column `(Z_q, ΔY_q)`, if any.
    #[must_use]
    pub fn newest_column(&self) -> Option<(&[f64], &[f64])> {
        if self.col_len == 0 {
            return None;
        }
        let (d, p, mm) = (self.d(), self.cfg.outputs, self.cfg.window);
        let q = (self.col_next + mm - 1) % mm;
        Some((&self.col_z[q * d..(q + 1) * d], &self.col_dy[q * p..(q + 1) * p]))
    }

    /// Columns built since construction or the last [`reset`](Self::reset) (the window
    /// clears itself on [`RegressionError::Overflow`]): a consumer of
    /// [`newest_column`](Self::newest_column) compares it with the count it last saw.
    #[must_use]
    pub fn columns_built(&self) -> u64 {
        self.built
    }

    fn d(&self) -> usize {
        self.cfg.outputs + self.cfg.inputs
    }

    /// Forget every sample and column (the configuration is kept).
    pub fn reset(&mut self) {
        self.built = 0;
        self.hist_len = 0;
        self.zhist_len = 0;
        self.col_len = 0;
        self.col_next = 0;
        self.since_refresh = 0;
        for v in [&mut self.g, &mut self.c, &mut self.s, &mut self.gw, &mut self.cw] {
            v.fill(0.0);
        }
    }

    /// Check a sample without absorbing it.
    ///
    /// # Errors
    /// [`RegressionError::DimensionMismatch`], [`RegressionError::NonFinite`],
    /// [`RegressionError::NonIncreasingTime`].
    #[inline]
    pub fn check_sample(&self, t: f64, y: &[f64], u: &[f64]) -> Result<(), RegressionError> {
        let (p, m) = (self.cfg.outputs, self.cfg.inputs);
        if y.len() != p {
            return Err(RegressionError::DimensionMismatch {
                field: "y",
                expected: p,
                got: y.len(),
            });
        }
        if u.len() != m {
            return Err(RegressionError::DimensionMismatch {
                field: "u",
                expected: m,
                got: u.len(),
            });
        }
        if !t.is_finite() {
            return Err(RegressionError::NonFinite { field: "t", index: 0, value: t });
        }
        // One branch for the common all-finite case; the search for the culprit only runs on
        // a bad sample.
        let mut finite = true;
        for x in y.iter().chain(u) {
            finite &= x.is_finite();
        }
        if !finite {
            for (field, v) in [("y", y), ("u", u)] {
                if let Some((index, &value)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
                    return Err(RegressionError::NonFinite { field, index, value });
                }
            }
        }
        if let Some(previous) = self.last_time() {
            if t <= previous {
                return Err(RegressionError::NonIncreasingTime { previous, got: t });
            }
        }
        Ok(())
    }

    /// Absorb one sample `(t, y, u)`: `O(h d + d²)`, no allocation.
    ///
    /// # Errors
    /// A sample error from [`check_sample`](Self::check_sample) leaves the state untouched.
    /// [`RegressionError::Overflow`] means finite samples overflowed a column or the window's
    /// sums; the window was cleared so no estimate is built on it.
    pub fn push(&mut self, t: f64, y: &[f64], u: &[f64]) -> Result<(), RegressionError> {
        if let (&[y], &[u]) = (y, u) {
            if self.cfg.outputs == 1
                && self.cfg.inputs == 1
                && self.cfg.estimator == Estimator::Ordinary
            {
                return self.push_scalar(t, y, u);
            }
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
        let zoh = self.cfg.input_integral == InputIntegral::ZeroOrderHold;
        if self.hist_len == 0 {
            self.hist_head = 0;
        } else {
            let prev = self.hist_head;
            let t0 = self.hist_t[prev];
            if t <= t0 {
                return Err(RegressionError::NonIncreasingTime { previous: t0, got: t });
            }
            let (y0, u0) = (self.hist_y[prev], self.hist_u[prev]);
            let k = next(prev, cap);
            let dt = t - t0;
            let half = 0.5 * dt;
            let z1 = [half * (y0 + y), if zoh { dt * u0 } else { half * (u0 + u) }];
            self.hist_z1[2 * k..2 * k + 2].copy_from_slice(&z1);
            self.hist_z1[2 * (k + cap)..2 * (k + cap) + 2].copy_from_slice(&z1);
            self.dy1[0] = y - y0;
            self.hist_head = k;
        }
        let k = self.hist_head;
        self.hist_t[k] = t;
        self.hist_y[k] = y;
        self.hist_u[k] = u;
        self.hist_len = (self.hist_len + 1).min(cap);
        if self.hist_len < cap {
            return Ok(());
        }
        // The column: the `h` interval regressors after the oldest sample, oldest first.
        let oldest = next(k, cap);
        let (mut zy, mut zu) = (0.0, 0.0);
        for pair in self.hist_z1[2 * (oldest + 1)..2 * (oldest + cap)].chunks_exact(2) {
            zy += pair[0];
            zu += pair[1];
        }
        let dy = y - self.hist_y[oldest];
        if !finite3(zy, zu, dy) {
            self.reset();
            return Err(RegressionError::Overflow);
        }
        let q = self.col_next;
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
        if !finite3(g[0], g[3], s[0]) {
            self.reset();
            return Err(RegressionError::Overflow);
        }
        self.finish_column(q)
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
        let h = self.cfg.horizon;
        let d = p + m;
        let cap = h + 1;
        self.hist_head = if self.hist_len == 0 { 0 } else { next(self.hist_head, cap) };
        let k = self.hist_head;
        self.hist_t[k] = t;
        copy(&mut self.hist_y[k * p..(k + 1) * p], y);
        copy(&mut self.hist_u[k * m..(k + 1) * m], u);
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
        for i in 0..p {
            let (ya, yb) = (self.hist_y[a * p + i], self.hist_y[b * p + i]);
            z1[i] = half * (ya + yb);
            self.dy1[i] = yb - ya;
        }
        let zoh = self.cfg.input_integral == InputIntegral::ZeroOrderHold;
        for j in 0..m {
            let (ua, ub) = (self.hist_u[a * m + j], self.hist_u[b * m + j]);
            z1[p + j] = if zoh { dt * ua } else { half * (ua + ub) };
        }
        mirror[b * d..(b + 1) * d].copy_from_slice(z1);
    }

    /// The newest single sample interval `(Z, ΔY)` (one-step regressor and output increment),
    /// once two samples are in. Its residual `ΔY − Θ̂ Z` keeps the tails of the per-step
    /// noise that the `h`-step columns average away.
    #[must_use]
    #[inline]
    pub fn newest_interval(&self) -> Option<(&[f64], &[f64])> {
        let d = self.d();
        let b = self.hist_head;
        (self.hist_len >= 2).then_some((&self.hist_z1[b * d..(b + 1) * d], &self.dy1[..]))
    }

    /// Residual `out ← ΔY − Θ̂ Z` (length `p`) over the chosen interval, with the `Θ̂` of the
    /// latest [`estimate`](Self::estimate) call. Call it only after an estimate whose status
    /// was [`EstimateStatus::Ready`]; returns `false` (leaving `out` alone) when the interval
    /// does not exist yet.
    #[inline(always)]
    pub fn residual(&self, source: ResidualSource, out: &mut [f64]) -> bool {
        // Literal dimensions for the paper's p = m = 1 let the compiler unroll the products.
        if self.cfg.outputs == 1 && self.cfg.inputs == 1 {
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
        true
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
            && (self.cfg.estimator == Estimator::Ordinary
                || self.gw.iter().chain(self.cw.iter()).all(|v| v.is_finite()))
    }

    #[inline(always)]
    fn insert_column(&mut self, p: usize, d: usize) -> Result<(), RegressionError> {
        let mm = self.cfg.window;
        let q = self.col_next;
        let instrumented = self.cfg.estimator == Estimator::Instrumented;
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
            self.accumulate(q, 1.0);
        } else if self.col_len == mm {
            self.replace_column(q, p, d);
        } else {
            self.col_z[q * d..(q + 1) * d].copy_from_slice(&self.z);
            self.col_dy[q * p..(q + 1) * p].copy_from_slice(&self.dy);
            self.accumulate(q, 1.0);
        }
        if !self.statistics_finite(p, d) {
            self.reset();
            return Err(RegressionError::Overflow);
        }
        self.finish_column(q)
    }

    /// Advance the column ring past slot `q` and refresh the statistics when due.
    #[inline(always)]
    fn finish_column(&mut self, q: usize) -> Result<(), RegressionError> {
        let mm = self.cfg.window;
        self.built += 1;
        self.col_next = next(q, mm);
        self.col_len = (self.col_len + 1).min(mm);
        self.since_refresh += 1;
        if self.since_refresh >= self.cfg.refresh_period {
            self.refresh();
        }
        Ok(())
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
        let mm = self.cfg.window;
        // Oldest to newest, so the sums are formed in a fixed order: the ring holds the
        // window as [start, mm) followed by [0, start) when it has wrapped.
        let start = (self.col_next + mm - self.col_len) % mm;
        let first = (mm - start).min(self.col_len);
        if self.cfg.estimator == Estimator::Ordinary {
            let (p, d) = (self.cfg.outputs, self.d());
            if p == 1 && d == 2 {
                self.sum_columns(start, first, 1, 2);
                self.sum_columns(0, self.col_len - first, 1, 2);
            } else {
                self.sum_columns(start, first, p, d);
                self.sum_columns(0, self.col_len - first, p, d);
            }
        } else {
            for k in 0..self.col_len {
                self.accumulate((start + k) % mm, 1.0);
            }
        }
        self.since_refresh = 0;
    }

    /// Add the outer products of the contiguous slots `[from, from + count)` (ordinary
    /// statistics only).
    #[inline(always)]
    fn sum_columns(&mut self, from: usize, count: usize, p: usize, d: usize) {
        let zs = self.col_z[from * d..(from + count) * d].chunks_exact(d);
        let dys = self.col_dy[from * p..(from + count) * p].chunks_exact(p);
        for (z, dy) in zs.zip(dys) {
            for i in 0..d {
                let zi = z[i];
                for j in i..d {
                    self.g[i * d + j] += zi * z[j];
                }
            }
            for i in 0..p {
                let di = dy[i];
                for j in 0..d {
                    self.c[i * d + j] += di * z[j];
                }
                for j in i..p {
                    self.s[i * p + j] += di * dy[j];
                }
            }
        }
    }

    /// The sufficient statistics `(G = ZZᵀ, C = ΔY Zᵀ, S = ΔY ΔYᵀ)`, row-major; only the
    /// upper triangles of `G` and `S` are maintained.
    #[must_use]
    pub fn statistics(&self) -> (&[f64], &[f64], &[f64]) {
        (&self.g, &self.c, &self.s)
    }

    /// Solve the window: `O(d³ + p d²)`, no allocation.
    #[inline]
    pub fn estimate(&mut self) -> Estimate<'_> {
        if self.cfg.outputs == 1 && self.cfg.inputs == 1 {
            self.estimate_dims(1, 1)
        } else {
            self.estimate_dims(self.cfg.outputs, self.cfg.inputs)
        }
    }

    /// [`estimate`](Self::estimate) with the dimensions passed in (literals at the call site
    /// for the paper's `p = m = 1` unroll the small kernels).
    #[inline(always)]
    fn estimate_dims(&mut self, p: usize, m: usize) -> Estimate<'_> {
        let d = p + m;
        let n = self.col_len;
        let mut out = Estimate {
            status: EstimateStatus::Ready,
            theta: &[],
            outputs: p,
            inputs: m,
            rms_residual: f64::NAN,
            gram_lambda_min: f64::NAN,
            gram_lambda_max: f64::NAN,
            columns: n,
        };
        if n < self.cfg.min_columns {
            out.status = EstimateStatus::WarmingUp { columns: n, needed: self.cfg.min_columns };
            return out;
        }
        let (lo, hi) = linalg::sym_eig_extremes(&self.g, d, &mut self.work);
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
                for i in 0..d {
                    for j in 0..d {
                        let v = if j >= i { self.g[i * d + j] } else { self.g[j * d + i] };
                        self.work[i * d + j] = v + if i == j { ridge } else { 0.0 };
                    }
                }
                if !linalg::cholesky_in_place(&mut self.work, d) {
                    out.status =
                        EstimateStatus::InsufficientExcitation { lambda_min: lo, lambda_max: hi };
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
        // RSS = tr S − 2 tr(Θ Cᵀ) + tr(Θ G Θᵀ).
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
        out.rms_residual = (rss.max(0.0) * inv_n / p as f64).sqrt();
        out.theta = &self.theta;
        out
    }

    /// Check the internal consistency of a deserialised state (buffer sizes, counters).
    ///
    /// # Errors
    /// [`RegressionError::CorruptState`] describing the first inconsistency, or the
    /// configuration error.
    pub fn check_state(&self) -> Result<(), RegressionError> {
        self.cfg.validate()?;
        let fresh = Self::new(self.cfg)?;
        let sizes = [
            ("hist_t", self.hist_t.len(), fresh.hist_t.len()),
            ("hist_y", self.hist_y.len(), fresh.hist_y.len()),
            ("hist_u", self.hist_u.len(), fresh.hist_u.len()),
            ("zhist", self.zhist.len(), fresh.zhist.len()),
            ("col_z", self.col_z.len(), fresh.col_z.len()),
            ("col_dy", self.col_dy.len(), fresh.col_dy.len()),
            ("col_w", self.col_w.len(), fresh.col_w.len()),
            ("g", self.g.len(), fresh.g.len()),
            ("c", self.c.len(), fresh.c.len()),
            ("s", self.s.len(), fresh.s.len()),
            ("gw", self.gw.len(), fresh.gw.len()),
            ("cw", self.cw.len(), fresh.cw.len()),
            ("theta", self.theta.len(), fresh.theta.len()),
            ("work", self.work.len(), fresh.work.len()),
            ("work2", self.work2.len(), fresh.work2.len()),
            ("piv", self.piv.len(), fresh.piv.len()),
            ("z", self.z.len(), fresh.z.len()),
            ("dy", self.dy.len(), fresh.dy.len()),
            ("hist_z1", self.hist_z1.len(), fresh.hist_z1.len()),
            ("dy1", self.dy1.len(), fresh.dy1.len()),
        ];
        if let Some((name, got, want)) = sizes.iter().find(|(_, g, w)| g != w) {
            return Err(RegressionError::CorruptState(format!(
                "{name} has {got} entries, expected {want}"
            )));
        }
        let cap = self.cfg.horizon + 1;
        let ok = self.hist_len <= cap
            && self.hist_head < cap
            && self.zhist_len <= cap
            && self.zhist_head < cap
            && self.col_len <= self.cfg.window
            && self.col_next < self.cfg.window
            && self.since_refresh < self.cfg.refresh_period.max(1)
            && self.inv_window == fresh.inv_window;
        if !ok {
            return Err(RegressionError::CorruptState("ring counters out of range".into()));
        }
        let all_finite =
            [&self.hist_t, &self.hist_y, &self.hist_u, &self.col_z, &self.col_dy, &self.g]
                .iter()
                .all(|v| v.iter().all(|x| x.is_finite()));
        if !all_finite {
            return Err(RegressionError::CorruptState("non-finite value in the window".into()));
        }
        Ok(())
    }
}
