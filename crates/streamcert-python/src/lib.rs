//! # streamcert-python
//!
//! The Python package `streamcert`: the library's certificates from numpy arrays. The
//! array-level core is plain Rust, tested by the workspace's `cargo test` without Python:
//!
//! - [`Run`]: the command line's `certify` over arrays (the same certifier, summary and
//!   checkpoints, so the same numbers bit for bit), one sample or one block at a time;
//! - [`EvidenceColumns`]: a block of evidence in columns (the CSV's columns as numbers, the
//!   gates, the reasons as codes and texts, the regions);
//! - [`config`]: configurations from TOML (the command line's parser) or from a JSON object
//!   laid over the command line's defaults;
//! - [`compose()`](compose::compose): the network rate, weights, critical scale and the
//!   limiting subsystem and coupling;
//! - [`NetworkRun`]: the command line's `network` fed by subsystem;
//! - [`simulate_g5`](simulate::simulate_g5): the paper's benchmark as arrays.
//!
//! With the `python` feature (which maturin turns on, `python/pyproject.toml`), the
//! `bindings` module wraps these in the extension module `streamcert._native`; the Python
//! package in `python/streamcert` adds the conversions of numpy and pandas inputs and the
//! result objects.

mod columns;
pub mod compose;
pub mod config;
mod error;
mod network;
mod run;
pub mod simulate;

#[cfg(feature = "python")]
mod bindings;

pub use columns::{
    EvidenceColumns, FLOAT_COLUMNS, GATES, ReasonColumn, WINDOW_COLUMNS, float_values,
};
pub use error::Error;
pub use network::NetworkRun;
pub use run::Run;
