//! The crate's error type.

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RegressionError {
    /// A configuration field is out of range.
    #[error("invalid regression configuration: `{field}` {reason}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// What is wrong and what is accepted.
        reason: String,
    },
    /// A sample value is NaN or infinite. The sample was not absorbed.
    #[error("sample {field}[{index}] is not finite ({value}); the sample was rejected")]
    NonFinite {
        /// `"t"`, `"y"` or `"u"`.
        field: &'static str,
        /// Index within the field.
        index: usize,
        /// The value.
        value: f64,
    },
    /// Sample time not strictly after the previous one. The sample was not absorbed.
    #[error(
        "sample time {got} is not after the previous sample time {previous}; the sample was rejected"
    )]
    NonIncreasingTime {
        /// Previous accepted time.
        previous: f64,
        /// Offending time.
        got: f64,
    },
    /// A sample has the wrong number of outputs or inputs. The sample was not absorbed.
    #[error("sample {field} has {got} values, expected {expected}; the sample was rejected")]
    DimensionMismatch {
        /// `"y"` or `"u"`.
        field: &'static str,
        /// Expected length.
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// Finite samples produced a non-finite column (overflow). The window was cleared.
    #[error("column overflowed to a non-finite value; the window was cleared")]
    Overflow,
    /// A record too short for the fit: it needs more rows than coefficients.
    #[error("the record has {got} samples; the fit needs at least {needed}")]
    InsufficientData {
        /// Samples needed.
        needed: usize,
        /// Samples given.
        got: usize,
    },
    /// The data do not identify the coefficients (the regressors are collinear or zero).
    #[error("the coefficients are not identified: {0}")]
    NotIdentified(String),
    /// A restored state is inconsistent with its configuration.
    #[error("corrupt regression state: {0}")]
    CorruptState(String),
}
