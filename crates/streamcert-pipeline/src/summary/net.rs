//! [`NetSummary`]: the counts over a `network` run (its text and JSON are the network
//! verdict's, `network/verdict.rs`).

use serde::{Deserialize, Serialize};

use crate::picture::Trace;
use crate::source::SourceReport;

/// Counts over a run (continued across checkpoint and resume).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct NetSummary {
    /// Input rows.
    pub rows: u64,
    /// Rows passed over at the start of a resumed input (the checkpoint holds them).
    pub replayed: u64,
    /// Time of the last input row.
    pub last_time: Option<f64>,
    /// Epochs composed.
    pub epochs: u64,
    /// Epochs certified.
    pub certified: u64,
    /// Epochs with the network gate open.
    pub open: u64,
    /// First time the network gate opened.
    pub first_open: Option<f64>,
    /// Whether the network gate was open at the last epoch (for `--require-certified`).
    #[serde(default)]
    pub open_at_end: bool,
    /// Since when the network gate has been open without a break (`None`: closed).
    #[serde(default)]
    pub open_since: Option<f64>,
    /// The network rate at the last epoch.
    #[serde(default)]
    pub last_rate: Option<f64>,
    /// Epochs with the gate closed, by kind of reason (a kind counted once per epoch).
    #[serde(default)]
    pub reasons: Vec<(String, u64)>,
    /// Why the gate was closed at the last epoch, in words (`None`: open).
    #[serde(default)]
    pub last_reason: Option<String>,
    /// Bad payloads of a live source, skipped.
    #[serde(default)]
    pub skipped: u64,
    /// A live source's counts ([`SourceReport`]); `None` for a file or a pipe.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<SourceReport>,
    /// The epochs of the picture (`--plot`), not checkpointed.
    #[serde(skip)]
    pub trace: Option<Trace>,
}
