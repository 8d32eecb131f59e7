//! # streamcert-dynamics
//!
//! Simulation substrate for streamcert: the [`Dynamics`] trait, the paper's five-node
//! benchmark network G5 (the paper's eqs. SA1 to SB5; docs/paper.md), seeded disturbance
//! processes for the three regimes of Experiment 1, probing inputs (dither), the two
//! integrators (Euler–Maruyama and RK4), and [`ObservableLoop`]: a loop of any order measured
//! through one output, simulated exactly, the plant family of the certificate of order `n`.
//!
//! Key design decisions:
//!
//! * Every random draw comes from a [`rand_chacha::ChaCha8Rng`] seeded by the caller, so a seed
//!   gives the same numbers on every run and every platform with IEEE-754 `f64`.
//! * The paper does not say how a noise sample scales with the step `dt`. [`NoiseScaling`]
//!   makes that an explicit choice: the SDE reading (`dx = f dt + E σ dW`, increment
//!   `√dt · w`), the held-input reading (`η` held over the step inside `ẋ`, increment `dt · w`)
//!   and the per-step state-increment reading (increment `w`). The experiments use the SDE
//!   reading because it is the only one whose stationary statistics do not depend on `dt`
//!   (see [`NoiseScaling`]).
//! * Ground truth is analytic: [`G5::jacobian`] and [`G5::observed_closed_loop_rates`] give the
//!   true local contraction rates that every certificate is judged against.
//!
//! ```
//! use streamcert_dynamics::{G5, G5Config, Coupling};
//! let cfg = G5Config { gamma: 0.15, k1: -3.5, k4: -4.0, ..G5Config::paper(Coupling::Cascade) };
//! let g5 = G5::new(cfg)?;
//! // True rates of the observed closed loops (y_A = x1, u1 = k1 x1; y_B = x4, u4 = k4 x4).
//! let rates = g5.observed_closed_loop_rates(&[0.0; 5]);
//! assert!((rates.a - 3.5).abs() < 1e-12);
//! assert!((rates.b - 5.0).abs() < 1e-12);
//! # Ok::<(), streamcert_dynamics::DynamicsError>(())
//! ```

mod disturbance;
mod dither;
mod error;
mod g5;
mod linear;
mod observable;
mod scalar;
mod scenario;
mod simulate;
mod system;

pub use disturbance::{Disturbance, DisturbanceConfig, Impulse, Periodic, Process, Segment};
pub use dither::{Dither, DitherConfig};
pub use error::DynamicsError;
pub use g5::{Coupling, G5, G5Config, LocalRates};
pub use linear::LinearSystem;
pub use observable::{ObservableLoop, SplitMix};
pub use scalar::{ScalarDrift, ScalarScenario};
pub use scenario::{LinearScenario, PlantSwitch};
pub use simulate::{Integrator, NoiseScaling, SimConfig, Trajectory, simulate};
pub use system::Dynamics;

/// The seeded, portable generator used for every random draw in this crate.
pub type SeededRng = rand_chacha::ChaCha8Rng;

/// Build the crate's seeded generator from a `u64` seed.
///
/// Two generators built from the same seed produce identical streams.
///
/// ```
/// use rand::RngCore;
/// let mut a = streamcert_dynamics::seeded_rng(7);
/// let mut b = streamcert_dynamics::seeded_rng(7);
/// assert_eq!(a.next_u64(), b.next_u64());
/// ```
#[must_use]
pub fn seeded_rng(seed: u64) -> SeededRng {
    use rand::SeedableRng;
    SeededRng::seed_from_u64(seed)
}

/// Check that a named parameter is finite.
pub(crate) fn finite(name: &'static str, value: f64) -> Result<f64, DynamicsError> {
    if value.is_finite() { Ok(value) } else { Err(DynamicsError::NonFinite { name, value }) }
}

/// Check that a named parameter is finite and `>= 0`.
pub(crate) fn non_negative(name: &'static str, value: f64) -> Result<f64, DynamicsError> {
    finite(name, value)?;
    if value >= 0.0 { Ok(value) } else { Err(DynamicsError::Negative { name, value }) }
}

/// Check that a named parameter is finite and `> 0`.
pub(crate) fn positive(name: &'static str, value: f64) -> Result<f64, DynamicsError> {
    finite(name, value)?;
    if value > 0.0 { Ok(value) } else { Err(DynamicsError::NotPositive { name, value }) }
}
