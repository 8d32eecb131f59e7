//! # streamcert
//!
//! Facade crate: re-exports the streamcert micro-crates under short names. Depend on this
//! crate for everything, or on one micro-crate alone.
//!
//! * [`dynamics`]: the `Dynamics` trait, the G5 benchmark, disturbances, dither, integrators.
//! * [`regression`]: streaming sliding-window integral regression (ridge and instrumented).
//! * [`ambiguity`]: exact sliding-window kurtosis, spike fraction and the radius `ε(t)`.
//! * [`certificate`]: the streaming certifier (`β̂`, `ρ`, certificate, deployment gate).
//! * [`compose`]: network composition (Lemma 1, asymmetric blocks, N subsystems, sparse).

pub use streamcert_ambiguity as ambiguity;
pub use streamcert_certificate as certificate;
pub use streamcert_compose as compose;
pub use streamcert_dynamics as dynamics;
pub use streamcert_experiments as experiments;
pub use streamcert_network as network;
pub use streamcert_regression as regression;
