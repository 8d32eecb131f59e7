//! The guards of the linear calibrated certificate: tests that close its gate where the
//! certificate's model is contradicted by the data, on by default
//! ([`Calibration`](crate::Calibration)):
//!
//! * [`model`]: one larger fit on the same windows and looks, testing a hidden state (the
//!   output's past increment, [`Calibration::hidden_dynamics`](crate::Calibration::hidden_dynamics))
//!   and a slope that varies over the explored region (squares and cubes of the outputs,
//!   [`Calibration::nonlinearity`](crate::Calibration::nonlinearity));
//! * [`change`]: a fresh estimate of the shortest window against every window's latest look
//!   ([`Calibration::plant_change`](crate::Calibration::plant_change)).
//!
//! A guard only closes: its risk is not part of `δ`, and what a false closing costs is power,
//! measured by `cargo xtask validity` (VALIDITY.md).

pub(crate) mod change;
mod curvature;
pub(crate) mod model;

pub(crate) use change::{ChangeGuard, Fresh};
pub(crate) use model::{Groups, ModelGuard};
