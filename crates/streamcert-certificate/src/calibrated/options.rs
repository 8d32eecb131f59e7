//! The calibrated certificate's two option enums, both defined beneath the certificates: the
//! model guards' covariance ([`GuardVariance`], in `look/guard_variance.rs`, since the guards
//! and the nonlinear certificate's check read it) and the split of `δ` across windows
//! ([`RiskSplit`], in `look/split.rs`, since the nonlinear certificate splits its own `δ` by
//! the same rules).

pub use crate::look::guard_variance::GuardVariance;
pub use crate::look::split::RiskSplit;
