//! # streamcert-ambiguity
//!
//! Sliding-window shape statistics of a scalar stream and the ambiguity radius of the paper
//! (Section III-A, eq. eps_est):
//!
//! ```text
//! ε(t) = clip(ε_floor + α_κ max(0, κ_e(t)) + α_s ŝ(t), ε_floor, ε_cap)
//! ```
//!
//! where `κ_e` is the excess kurtosis and `ŝ` the share of values beyond `3 σ0` over the last
//! `N_tail` values. This crate depends on nothing else of streamcert: anyone who needs exact
//! sliding-window moments can use [`SlidingKurtosis`] alone.
//!
//! Key design decision: [`SlidingKurtosis`] keeps power sums of `x − c` about a shift `c`
//! (the window mean at the last exact recompute) and tracks how much magnitude has passed
//! through each sum since then. Subtracting an evicted spike's fourth power from a sum it
//! dominates cancels catastrophically; the magnitude tracker detects exactly that (and a
//! drifting mean) and triggers an exact two-pass recompute of the window, as does a fixed
//! period of `N_tail` samples. The result equals a two-pass recompute to about `1e-12`
//! relative, including streams with spikes `10⁶` times the base scale and large offsets.
//!
//! ```
//! use streamcert_ambiguity::{AmbiguityConfig, AmbiguityRadius, SpikeScale};
//! let config = AmbiguityConfig {
//!     spike_scale: SpikeScale::Fixed { sigma0: 1.0 },
//!     ..AmbiguityConfig::paper(150)
//! };
//! // A light-tailed, bounded stream (uniform on [-1, 1]): negative excess kurtosis, no
//! // value beyond 3 sigma0, so the radius sits at its floor.
//! let mut calm = AmbiguityRadius::new(config.clone())?;
//! for k in 0..300 {
//!     calm.push(((k * 7919) % 1000) as f64 / 500.0 - 1.0)?;
//! }
//! let s = calm.snapshot();
//! assert!(s.kurtosis.is_some_and(|k| k < 0.0) && s.spike_fraction == 0.0);
//! assert_eq!(s.eps, 0.015);
//! // The same stream with a spike of 3.5 every 50 values: heavier tails widen the radius,
//! // below its cap.
//! let mut spiky = AmbiguityRadius::new(config)?;
//! for k in 0..300 {
//!     let x = ((k * 7919) % 1000) as f64 / 500.0 - 1.0;
//!     spiky.push(if k % 50 == 0 { 3.5 } else { x })?;
//! }
//! let w = spiky.snapshot();
//! assert!(w.eps > 0.1 && w.eps < 0.32, "{}", w.eps);
//! # Ok::<(), streamcert_ambiguity::AmbiguityError>(())
//! ```

mod moments;
mod radius;
mod spike;

pub use moments::SlidingKurtosis;
pub use radius::{Ambiguity, AmbiguityConfig, AmbiguityRadius};
pub use spike::{MAD_TO_SIGMA, RobustScale, SpikeCounter, SpikeScale};

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum AmbiguityError {
    /// The tail window is too short for a fourth moment.
    #[error("tail window of {window} values is too short: at least {min} are needed")]
    TailWindowTooShort {
        /// Given window.
        window: usize,
        /// Minimum accepted.
        min: usize,
    },
    /// `ε_floor > ε_cap`, or either outside `[0, ∞)`.
    #[error("radius bounds must satisfy 0 <= eps_floor <= eps_cap, got floor {floor}, cap {cap}")]
    InvalidBounds {
        /// `ε_floor`.
        floor: f64,
        /// `ε_cap`.
        cap: f64,
    },
    /// A parameter is negative, NaN or infinite.
    #[error("parameter `{name}` must be finite and >= 0 (> 0 for scales), got {value}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// Offending value.
        value: f64,
    },
    /// A calibration period of zero values.
    #[error("the robust-scale calibration needs at least {min} values, got {got}")]
    CalibrationTooShort {
        /// Given.
        got: usize,
        /// Minimum.
        min: usize,
    },
    /// A pushed value is NaN or infinite; it was not absorbed.
    #[error("value {0} is not finite; it was rejected")]
    NonFinite(f64),
}

/// `(i + 1) mod cap` without a division.
#[inline]
pub(crate) fn next(i: usize, cap: usize) -> usize {
    if i + 1 == cap { 0 } else { i + 1 }
}
