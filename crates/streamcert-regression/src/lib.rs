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
//! independent of `M`. Every `refresh_period <= M` columns, and at once when a diagonal sum
//! has fallen below `10⁻⁶` of its peak since the last recompute (a burst left the window), the
//! statistics are recomputed exactly from the ring buffer, so rounding drift stays below
//! `10⁻⁸` of each sum's scale over arbitrarily long runs with a `10⁶` dynamic range.
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

mod config;
mod error;
mod estimate;
pub mod linalg;
mod loop_model;
mod order_n;
mod range;
mod sliding;
mod windows;

pub use config::{Estimator, InputIntegral, Model, RegressionConfig, ResidualSource};
pub use error::RegressionError;
pub use estimate::{Estimate, EstimateStatus};
pub use loop_model::{FastPath, HiddenDynamicsTest, LoopModel};
pub use order_n::{
    ClosedLoop, CurvatureTest, MAX_ORDER, OrderNConfig, OrderNFit, OrderNRecord, OrderNRegression,
    OrderNWindow, PastRowTest, RegressorTest, WindowLook,
};
pub use range::{Interval, SlidingRange};
pub use sliding::SlidingRegression;
pub use windows::{
    AnchoredWindow, BatchedCovariance, InstrumentedWindows, MAX_MOMENT_ENTRIES, MAX_TAIL,
    MIN_LEVERAGE_PIVOT, MIN_RESIDUAL_SHARE, RateMap, Solve, WindowEstimate,
};
