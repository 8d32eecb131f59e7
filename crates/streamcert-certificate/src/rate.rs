//! The closed loop's rate from a fitted model: the one place where the certificates turn
//! coefficients into the number they certify.
//!
//! A loop model's rate provides three things, each for its own coefficients:
//! - the map `T` from the coefficients to the closed loop under `u = K y`
//!   ([`first_order::closed_loop_map`]);
//! - the rate of an estimate, `β̂` (in 1/s, larger is faster contraction);
//! - the variance of the estimate along the rate's direction, from the covariance the
//!   regression states for it (the calibrated certificate's `σ²_max`).
//!
//! [`first_order`] is the paper's model (Section II): `β̂ = −λ_max(sym Ĵ_cl)` with
//! `Ĵ_cl = Θ̂ T` (eq. beta), and the variance of `vᵀ(Θ̂ − Θ) T v` over unit `v` bounded by
//! `λ_max` of the score's covariance. A plant of order `n`
//! ([`streamcert_regression::LoopModel::Order`]) has no symmetric part to read: its rate is
//! the margin of its characteristic polynomial over the coefficients' confidence ellipsoid,
//! [`order_n`] (the exact test and its bisection).

pub(crate) mod first_order;
pub(crate) mod order_n;
