//! [`GuardVariance`]: the covariance behind the model guards' Wald tests, shared by the
//! guards, the nonlinear certificate's lack-of-fit check and the calibrated certificate's
//! options (which re-export it).

use serde::{Deserialize, Serialize};

/// The covariance behind the model guards' Wald tests
/// ([`Calibration::hidden_dynamics`](crate::Calibration::hidden_dynamics),
/// [`Calibration::nonlinearity`](crate::Calibration::nonlinearity)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GuardVariance {
    /// Each block's first-order influence `r_j Q A⁻¹` with the factor `B/(B − d)` for the
    /// fitted directions
    /// ([`estimate_coefficients_first_order`](streamcert_regression::InstrumentedWindows::estimate_coefficients_first_order)):
    /// one pass over the blocks without a factorisation per block, about a fifth of the
    /// jackknife's operations for the nonlinearity guard's five regressors (the default
    /// step's model guards about 0.3 µs against 0.8 µs, BENCHMARKS.md). It differs from the
    /// jackknife where a few blocks carry a direction (no leverage factor there, so the
    /// test rejects more often), and by `B/(B − d)` against about `1 + 2d/B` elsewhere.
    /// Closing never costs validity, so this moves the guards' false-closing rate and their
    /// protection, not the certificate's risk: VALIDITY.md, rerun with it, has every
    /// near-margin cell within 2δ, the hidden-state cells closed in 95 % of samples as
    /// before, and the `guard closed` column on linear loops up by 0.0 to 0.2 points.
    #[default]
    FirstOrder,
    /// Each block's delete-one-block change, as the certificate's own variance
    /// ([`estimate_coefficients`](streamcert_regression::InstrumentedWindows::estimate_coefficients)).
    Jackknife,
}

impl GuardVariance {
    /// Whether this is the default, [`GuardVariance::FirstOrder`].
    #[must_use]
    pub fn is_first_order(&self) -> bool {
        *self == Self::FirstOrder
    }
}
