//! # streamcert
//!
//! Facade crate: re-exports the streamcert micro-crates under short names. Depend on this
//! crate for everything, or on one micro-crate alone (for example `streamcert-dynamics`).
//!
//! * [`dynamics`]: the `Dynamics` trait, the G5 benchmark, disturbances, dither, integrators.

pub use streamcert_dynamics as dynamics;
