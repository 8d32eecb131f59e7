//! [`NotCertified`] in words: the text of the evidence's `reason_*` columns and of the
//! verdict lines.

use super::NotCertified;
use crate::fixed::{Fixed, Sig};
use streamcert_regression::MAX_ORDER;

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
            Self::HiddenDynamics { .. } => self.fmt_hidden(f),
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
    /// [`NotCertified::HiddenDynamics`]'s words: the order tried and what would be valid.
    fn fmt_hidden(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Self::HiddenDynamics { window, statistic, threshold, order } = self else {
            return Ok(());
        };
        let (statistic, threshold) = (Fixed::<3>(*statistic), Fixed::<3>(*threshold));
        match *order {
            0 | 1 => write!(
                f,
                "the output has dynamics beyond its model's order (order 1, window {window}: \
                 past increment, Wald {statistic} > {threshold}); a model of order 2 or 3 on \
                 one output may hold them: [regression] order = \"auto\" runs orders 1 to 3 \
                 within one risk δ (a second run on the same data spends the risk δ again)"
            ),
            n if n < MAX_ORDER => write!(
                f,
                "the output has dynamics beyond its model's order (order {n}, window {window}: \
                 past row, Wald {statistic} > {threshold}); a model of order {} ([regression] \
                 order = {}) may hold them",
                n + 1,
                n + 1
            ),
            n => write!(
                f,
                "the output has dynamics beyond its model's order (order {n}, the largest \
                 certified; window {window}: past row, Wald {statistic} > {threshold}); no \
                 certificate of order {n} or below is valid for this loop: one is with the \
                 unmeasured states logged as outputs (order 1 takes several)"
            ),
        }
    }

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

#[cfg(test)]
mod tests {
    use super::NotCertified;

    fn hidden(order: usize) -> NotCertified {
        NotCertified::HiddenDynamics { window: 150, statistic: 31.4, threshold: 9.2, order }
    }

    /// The words name the order tried and what would be valid at each order: the first
    /// order names the models of order 2 and 3, `order = "auto"` that tries them within the
    /// run's risk, and the risk a second run spends; order 2
    /// names order 3; order 3, the largest, names none above it but the states as outputs.
    #[test]
    fn the_hidden_dynamics_words_name_the_order_and_what_would_be_valid() {
        let one = hidden(1).to_string();
        assert!(one.starts_with("the output has dynamics beyond its model's order (order 1,"));
        assert!(one.contains("past increment"), "{one}");
        assert!(one.contains("order 2 or 3 on one output") && one.contains("risk δ again"));
        assert!(one.contains("order = \"auto\" runs orders 1 to 3 within one risk δ"), "{one}");
        let two = hidden(2).to_string();
        assert!(two.contains("(order 2, window 150") && two.contains("[regression] order = 3"));
        assert!(two.contains("past row, Wald 31.400 > 9.200"), "{two}");
        let three = hidden(3).to_string();
        assert!(three.contains("(order 3, the largest certified;") && !three.contains("order = 4"));
        assert!(three.contains("unmeasured states logged as outputs"), "{three}");
    }

    /// A reason serialised before the order was recorded reads as the first order's.
    #[test]
    fn a_reason_without_its_order_is_the_first_orders() {
        let old = r#"{"reason":"hidden_dynamics","window":150,"statistic":31.4,"threshold":9.2}"#;
        let read: NotCertified = serde_json::from_str(old).unwrap();
        assert_eq!(read, hidden(1));
        let round: NotCertified =
            serde_json::from_str(&serde_json::to_string(&hidden(3)).unwrap()).unwrap();
        assert_eq!(round, hidden(3));
    }
}
