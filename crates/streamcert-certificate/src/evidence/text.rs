//! [`NotCertified`] in words: the text of the evidence's `reason_*` columns and of the
//! verdict lines.

use super::NotCertified;
use crate::fixed::{Fixed, Sig};

/// [`NotCertified::FirstOrderOnly`]'s text.
const FIRST_ORDER_ONLY: &str = "not computed at this order: the paper's certificates are of the \
     first-order model (order = 1); the calibrated column carries the certificate of the order \
     configured";

impl std::fmt::Display for NotCertified {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::WarmingUp { columns, needed } => {
                write!(f, "warming up ({columns}/{needed} columns)")
            }
            Self::InsufficientExcitation => f.write_str("insufficient excitation"),
            Self::WeakInstruments => f.write_str("weak instruments"),
            Self::BelowMargin { certificate, margin } => {
                write!(f, "certificate {} below margin {margin}", Fixed::<4>(*certificate))
            }
            Self::Accumulating { streak, needed } => {
                write!(f, "above margin for {streak}/{needed} samples")
            }
            Self::SkippedSample => f.write_str("bad sample skipped"),
            Self::NoAmbiguityModel => f.write_str("no ambiguity model configured"),
            Self::NoCalibration => f.write_str("no calibration configured"),
            Self::Gap { dt, reference } => {
                write!(
                    f,
                    "gap of {} s (reference step {} s): window reset",
                    Sig(*dt),
                    Sig(*reference)
                )
            }
            Self::RateBelowMargin { window, upper } => write!(
                f,
                "window {window}: the rate is at most {}, below the margin (the candidate does \
                 not contract enough on the newest data)",
                Fixed::<4>(*upper)
            ),
            Self::VaryingDynamics { window, statistic, threshold } => write!(
                f,
                "dynamics vary over the explored region (window {window}: Wald {} > {})",
                Fixed::<3>(*statistic),
                Fixed::<3>(*threshold)
            ),
            Self::HiddenDynamics { window, statistic, threshold } => write!(
                f,
                "the output has dynamics the model does not hold (window {window}: past \
                 increment, Wald {} > {})",
                Fixed::<3>(*statistic),
                Fixed::<3>(*threshold)
            ),
            Self::OrderUntested { window } => {
                write!(f, "window {window}: model order not yet tested (no larger fit)")
            }
            Self::LinearityUntested { window } => {
                write!(f, "window {window}: linearity not yet tested (no feature fit)")
            }
            Self::PlantChanged { window, beta_hat, newest_upper } => write!(
                f,
                "the plant changed (window {window}'s rate {} is above what the newest data \
                 allow, at most {})",
                Sig(*beta_hat),
                Sig(*newest_upper)
            ),
            Self::NoNonlinearModel
            | Self::LibraryMisfit { .. }
            | Self::LibraryUntested { .. }
            | Self::OutsideRegion { .. } => self.fmt_nonlinear(f),
            Self::InputFollowsOutputs { window } => write!(
                f,
                "the data cannot separate the plant from the controller: the input is a fixed \
                 linear function of the outputs in window {window} (u = K y with nothing added); \
                 add a dither, a small signal on the input that the outputs do not explain \
                 (VALIDITY.md's cells add a PRBS of ±1 held 0.2 s)"
            ),
            Self::FirstOrderOnly => f.write_str(FIRST_ORDER_ONLY),
            Self::WeaklyIdentified { window, moves } if *moves <= 0.0 => write!(
                f,
                "the data do not identify the rate: an input or output has not moved beyond \
                 its level in window {window} (hold it less long, or move it more often)"
            ),
            Self::WeaklyIdentified { window, moves } => write!(
                f,
                "the input has barely moved in window {window}: {} effective moves carry the \
                 rate, too few for a bound (move it more often)",
                Fixed::<1>(*moves)
            ),
        }
    }
}

impl NotCertified {
    /// The nonlinear certificate's reasons in words ([`Display`](std::fmt::Display)'s).
    fn fmt_nonlinear(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NoNonlinearModel => f.write_str("no nonlinear model configured"),
            Self::LibraryMisfit { window, statistic, threshold } => write!(
                f,
                "the feature library misses the drift (window {window}: lack of fit, Wald {} > {})",
                Fixed::<3>(*statistic),
                Fixed::<3>(*threshold)
            ),
            Self::LibraryUntested { window } => {
                write!(
                    f,
                    "window {window}: feature library not yet checked (no lack-of-fit estimate)"
                )
            }
            Self::OutsideRegion { y, lo, hi } => write!(
                f,
                "the output {} lies outside the certified region [{}, {}]",
                Sig(*y),
                Sig(*lo),
                Sig(*hi)
            ),
            // Display sends only the nonlinear reasons here; any other is named by its kind.
            other => f.write_str(other.kind()),
        }
    }
}
