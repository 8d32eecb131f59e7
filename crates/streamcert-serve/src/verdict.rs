//! The verdict as a message: one JSON object per change of the gate, for an interlock (a PLC,
//! a SCADA tag) to subscribe to. Schema `streamcert.verdict/1` (docs/operations.md):
//!
//! ```json
//! {"schema": "streamcert.verdict/1", "sequence": 3, "name": "loop7", "kind": "loop",
//!  "certificate": "calibrated", "candidate": {"gain": [[0.5]], "margin": 0.001, "order": 1},
//!  "open": true, "since": 12.5, "t": 12.5, "since_text": "12.5", "t_text": "12.5",
//!  "value": 0.0021, "look_order": 1, "reason": null, "risk": {"delta": 0.05}, "ended": false,
//!  "counters": {"samples": 626, "epochs": 0, "gaps": 0, "skipped": 0, "bad": 0,
//!               "reconnects": 0, "reconnect_attempts": 0, "late": 0}}
//! ```
//!
//! `open` is the gate that decides deployment: the calibrated certificate's when it is
//! configured (the default), else the paper's Gaussian one, whose `risk` is `null` (no stated
//! risk); a network's gate for `network`. `since` is the sample time from which the gate has
//! been in this state, `t` the sample time of the message, both in seconds; `since_text` and
//! `t_text` are the same times as a person reads them: ISO 8601 UTC to the millisecond where
//! the times read as Unix seconds (a live source's timestamps), else seconds with the decimals
//! the sampling step resolves. `counters` are the run's counts when the message was sent
//! (a live source's bad payloads, reconnection attempts and reconnections among them). `reason` is `null` exactly when
//! the gate is open; otherwise its `kind` (one of the evidence rows' reason kinds), the kind
//! in `words` and the row's own `detail`. `sequence` counts the messages of one run from 0,
//! so a subscriber drops a repeat (a message published again after a reconnection). The last
//! message of a run has `ended: true` and the gate closed: a certifier that stopped vouches
//! for nothing after its last sample.

use serde::Serialize;
use streamcert_pipeline::certify::reason_words;

/// The schema's name and version, the first field of every message.
pub const VERDICT_SCHEMA: &str = "streamcert.verdict/1";

/// One verdict message (module docs).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VerdictMessage {
    /// [`VERDICT_SCHEMA`].
    pub schema: &'static str,
    /// The message's place in the run, from 0.
    pub sequence: u64,
    /// The loop's or network's name.
    pub name: String,
    /// `"loop"` (certify) or `"network"`.
    pub kind: &'static str,
    /// The certificate whose gate this is: `"calibrated"`, `"gaussian"` or `"network"`.
    pub certificate: &'static str,
    /// The candidate judged.
    pub candidate: Candidate,
    /// Whether the gate is open: the candidate may be deployed.
    pub open: bool,
    /// The sample time from which the gate has been in this state (`None` before a sample).
    pub since: Option<f64>,
    /// The sample time of the message (`None` before a sample).
    pub t: Option<f64>,
    /// `since` as a person reads it ([`streamcert_certificate::SampleTime`]): ISO 8601 UTC
    /// where it reads as Unix seconds, else seconds.
    pub since_text: Option<String>,
    /// `t` as a person reads it (as `since_text`).
    pub t_text: Option<String>,
    /// The certificate at `t` (1/s; the network rate for a network).
    pub value: Option<f64>,
    /// The loop model's order of the look `value` is from: the configured order, or with
    /// `order = "auto"` the order whose look stands (`None` before a look and for a
    /// network).
    pub look_order: Option<usize>,
    /// Why the gate is closed (`None` exactly when it is open).
    pub reason: Option<Reason>,
    /// The risk stated for the run (`None`: the paper's certificates, no stated risk).
    pub risk: Option<Risk>,
    /// The run ended: the last message, the gate closed.
    pub ended: bool,
    /// The run's counts when the message was sent.
    pub counters: Counters,
}

/// A candidate: its gain (rows of `K`, one per input; empty for a network), the margin the
/// certificate must clear (1/s) and the order of the loop model it is judged with.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Candidate {
    /// `K`, one row per input.
    pub gain: Vec<Vec<f64>>,
    /// The margin (1/s).
    pub margin: f64,
    /// The loop model's order, `[regression] order`: 1 the paper's first-order model (the
    /// output's rate a function of the output and the input), 2 or 3 a closed loop
    /// `sⁿ + β_1 sⁿ⁻¹ + … + β_n` read through one output; `None` for a network and with
    /// `order = "auto"` (then `orders`).
    pub order: Option<usize>,
    /// With `order = "auto"`, the orders run side by side (`[1, 2, 3]`, each at risk `δ/3`);
    /// left out otherwise.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub orders: Vec<usize>,
}

/// Counts of a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Counters {
    /// Rows certified.
    pub samples: u64,
    /// Network epochs composed.
    pub epochs: u64,
    /// Gaps.
    pub gaps: u64,
    /// Rows passed over as bad.
    pub skipped: u64,
    /// A live source's bad payloads.
    pub bad: u64,
    /// A live source's reconnections: connections made again after one was lost.
    pub reconnects: u64,
    /// A live source's reconnection attempts: every connection lost or refused, each followed
    /// by another attempt (at least `reconnects`, more while the broker or server is away).
    pub reconnect_attempts: u64,
    /// A live source's late messages.
    pub late: u64,
}

/// Why a gate is closed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Reason {
    /// The reason's kind (`below_margin`, `warming_up`, `plant_changed`, ..., `stopped`).
    pub kind: String,
    /// The kind in words, with the kind: `"<phrase> [<kind>]"`.
    pub words: String,
    /// The row's own words (the window, the bound, the numbers).
    pub detail: String,
}

impl Reason {
    /// A reason of `kind` (its words from the shared reason table) with the row's `detail`.
    #[must_use]
    pub fn new(kind: &str, detail: &str) -> Self {
        Self { kind: kind.into(), words: reason_words(kind), detail: detail.into() }
    }
}

/// The risk a verdict is stated at.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Risk {
    /// The chance of a false deployment over the run, at most.
    pub delta: f64,
}

impl VerdictMessage {
    /// The message's offline form: the gate closed, `ended`, the reason `offline`: what a
    /// publisher leaves with the broker as its last will, published if the certifier's
    /// connection is lost without a word.
    #[must_use]
    pub fn offline(&self) -> Self {
        Self {
            open: false,
            ended: true,
            reason: Some(Reason {
                kind: "offline".into(),
                words: "the certifier is offline: it vouches for nothing [offline]".into(),
                detail: "its connection to the broker was lost".into(),
            }),
            ..self.clone()
        }
    }

    /// The message as one line of JSON.
    #[must_use]
    pub fn to_json(&self) -> Vec<u8> {
        // Every field is a plain number, string, bool or a vector of them: it serialises.
        serde_json::to_vec(self).unwrap_or_default()
    }
}

/// Where verdict messages go: an MQTT topic (`streamcert-live`'s publisher), a test's
/// channel. Called on the certifying thread; it must not block for long.
pub trait VerdictSink: Send {
    /// Publish `message`.
    fn publish(&mut self, message: &VerdictMessage);
}

impl<F: FnMut(&VerdictMessage) + Send> VerdictSink for F {
    fn publish(&mut self, message: &VerdictMessage) {
        self(message);
    }
}
