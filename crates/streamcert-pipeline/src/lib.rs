//! # streamcert-pipeline
//!
//! The certify pipeline from a user's data to a verdict, beneath the `streamcert` command line
//! (`streamcert-cli`, a thin caller), the Python package and `xtask`: configuration files and
//! their defaults, streaming CSV input with precise error locations, per-sample evidence
//! records, the summary and its verdict line, sealed checkpoints, the `certify`, `network`,
//! `compose` and `simulate` commands, and the pictures' data. No crate depends on the command
//! line's crate (tested).
//!
//! Exit codes: 0 success, 2 invalid command line or configuration (nothing was read),
//! 3 malformed input data (stopping policy), 4 I/O failure, 5 checkpoint failure.

pub mod certify;
pub mod compose;
pub mod config;
pub mod input;
pub mod network;
pub mod output;
pub mod picture;
mod reasons;
mod resume;
pub mod simulate;
pub mod source;
mod summary;
pub mod watch;

use std::fmt;

/// Errors of the command line, each with what a user needs to fix it.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CliError {
    /// The configuration is invalid; nothing was read.
    #[error("{path}: invalid configuration: {message}")]
    Config {
        /// Configuration file.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// A row of the input is malformed.
    #[error("{0}")]
    Row(RowError),
    /// The input has no header or no data.
    #[error("{file}: {message}")]
    Input {
        /// Input name.
        file: String,
        /// What is wrong.
        message: String,
    },
    /// Reading or writing failed.
    #[error("{context}: {source}")]
    Io {
        /// What was being done.
        context: String,
        /// The error.
        source: std::io::Error,
    },
    /// A checkpoint could not be written, read or used.
    #[error("checkpoint {path}: {message}")]
    Checkpoint {
        /// Checkpoint file.
        path: String,
        /// What is wrong.
        message: String,
    },
}

impl CliError {
    /// The process exit code for this error.
    #[must_use]
    pub fn exit_code(&self) -> i32 {
        match self {
            Self::Config { .. } => 2,
            Self::Row(_) | Self::Input { .. } => 3,
            Self::Io { .. } => 4,
            Self::Checkpoint { .. } => 5,
        }
    }

    /// An I/O error with what was being done.
    pub fn io(context: impl Into<String>, source: std::io::Error) -> Self {
        Self::Io { context: context.into(), source }
    }
}

/// A malformed row: where, and what was expected.
#[derive(Debug, Clone, PartialEq)]
pub struct RowError {
    /// Input name (`-` for stdin).
    pub file: String,
    /// 1-based line number.
    pub line: u64,
    /// Column name, when one column is at fault.
    pub column: Option<String>,
    /// What was found and what was expected.
    pub message: String,
}

impl fmt::Display for RowError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.column {
            Some(c) => write!(f, "{}:{}: column `{c}`: {}", self.file, self.line, self.message),
            None => write!(f, "{}:{}: {}", self.file, self.line, self.message),
        }
    }
}
