//! The crate's error type.

use streamcert_ambiguity::AmbiguityError;
use streamcert_regression::RegressionError;

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CertifyError {
    /// A configuration field is out of range.
    #[error("invalid certifier configuration: `{field}` {reason}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// What is wrong and what is accepted.
        reason: String,
    },
    /// The regression rejected a sample or its configuration.
    #[error(transparent)]
    Regression(#[from] RegressionError),
    /// The ambiguity configuration is invalid.
    #[error(transparent)]
    Ambiguity(#[from] AmbiguityError),
    /// A checkpoint could not be written or read.
    #[error("checkpoint: {0}")]
    Checkpoint(String),
}

impl CertifyError {
    /// `Err(InvalidConfig)` for `field`, with what is wrong and what would be valid.
    pub(crate) fn refuse<T>(field: &'static str, reason: String) -> Result<T, Self> {
        Err(Self::InvalidConfig { field, reason })
    }
}
