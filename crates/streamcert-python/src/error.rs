//! [`Error`]: every way a call from Python can fail, one variant per exception class.

/// An error of the Python package; the bindings raise one exception class per variant
/// (`ConfigError`, `InputDataError`, `CheckpointError`, `ComposeError`), all subclasses of
/// `streamcert.StreamcertError`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The configuration is invalid (the command line's message, word for word).
    #[error("{0}")]
    Config(String),
    /// A sample is not valid data: where, and what is wrong.
    #[error("{}", data_message(*row, column.as_deref(), message))]
    Data {
        /// 0-based row of the array passed in.
        row: usize,
        /// The column's name (a `[columns]` name), when one column is at fault.
        column: Option<String>,
        /// What was found and what was expected.
        message: String,
    },
    /// Arrays of the wrong shape, length or type.
    #[error("{0}")]
    Shape(String),
    /// A checkpoint is damaged, foreign, or was written with another configuration.
    #[error("{0}")]
    Checkpoint(String),
    /// A network cannot be composed (negative or non-finite gain, wrong dimensions).
    #[error("{0}")]
    Compose(String),
}

fn data_message(row: usize, column: Option<&str>, message: &str) -> String {
    match column {
        Some(c) => format!("row {row}: column `{c}`: {message}"),
        None => format!("row {row}: {message}"),
    }
}

impl From<streamcert_pipeline::CliError> for Error {
    fn from(e: streamcert_pipeline::CliError) -> Self {
        use streamcert_pipeline::CliError as C;
        match e {
            C::Config { .. } => Self::Config(e.to_string()),
            C::Checkpoint { .. } => Self::Checkpoint(e.to_string()),
            C::Row(r) => Self::Data { row: 0, column: r.column, message: r.message },
            other => Self::Shape(other.to_string()),
        }
    }
}
