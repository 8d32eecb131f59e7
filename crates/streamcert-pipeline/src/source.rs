//! Where samples come from: one abstraction beneath `certify` for a CSV file, stdin and live
//! plant sources (the `streamcert-live` crate's MQTT subscriptions), so that adding a source
//! touches neither the certifier nor the run loop.
//!
//! A [`Source`] yields, one at a time, what happened next in the stream:
//! - [`Next::Row`]: a sample, written into the caller's [`Sample`] (no allocation per row);
//! - [`Next::Gap`]: samples are missing here (an outage, a stale signal): the next sample
//!   starts new windows ([`Certifier::gap`](streamcert_certificate::Certifier::gap)), exactly
//!   as a gap in a file's time column does, never integrated across;
//! - [`Next::Bad`]: a payload that could not be a sample (not a number, a missing field, NaN,
//!   time going backwards, too large): counted and reported, closing every gate as a skipped
//!   row does, never a number the certifier sees;
//! - [`Next::Idle`]: nothing to certify yet (a live source waited, or its connection changed):
//!   the run looks at the source's counts ([`Source::report`]) and asks again, so that what a
//!   watcher shows (reconnections, messages passed over) is current while no row comes.
//!
//! A source with at-least-once delivery (an MQTT persistent session) holds its
//! acknowledgements until the rows they carried are in a written checkpoint
//! ([`Source::committed`]); it may ask for a checkpoint sooner ([`Source::commit_due`]) when
//! its window of unacknowledged messages fills.

use serde::{Deserialize, Serialize};

use crate::input::{Sample, SampleReader};
use crate::{CliError, RowError};

/// What a [`Source`] yielded next.
#[derive(Debug, Clone, PartialEq)]
pub enum Next {
    /// A sample, written into the caller's [`Sample`].
    Row,
    /// Samples are missing before the next row (why, in words): new windows start there.
    Gap(String),
    /// A payload that is not a sample: where and why (its topic or node, an excerpt).
    Bad(RowError),
    /// Nothing to certify yet: a live source waited its poll interval or its connection
    /// changed. The caller may look at [`Source::report`] and asks again; the certifier sees
    /// nothing of it.
    Idle,
}

/// A stream of samples: a CSV file or pipe ([`SampleReader`]) or a live plant source.
pub trait Source {
    /// The next item into `s` (`s` is written only for [`Next::Row`]); `None` at the end of
    /// the stream (a live source ends only when told to stop).
    ///
    /// # Errors
    /// A malformed row of a file ([`CliError::Row`], which the run's bad-row policy decides
    /// on) or an error that ends the stream (I/O, a refused connection at the start).
    fn next_into(&mut self, s: &mut Sample) -> Option<Result<Next, CliError>>;

    /// The rows yielded so far are in a durable checkpoint: a source with at-least-once
    /// delivery acknowledges the messages they came from, so that after a crash the broker
    /// redelivers exactly what the checkpoint does not hold. A file does nothing.
    ///
    /// # Errors
    /// An acknowledgement that could not be sent.
    fn committed(&mut self) -> Result<(), CliError> {
        Ok(())
    }

    /// Whether the source wants a checkpoint now (its window of unacknowledged messages is
    /// full), whatever the row count since the last one.
    fn commit_due(&self) -> bool {
        false
    }

    /// Continue from the state a checkpoint holds (the report the source gave when it was
    /// written): a source whose rows depend on messages already acknowledged (the alignment of
    /// per-signal topics) takes its state back, so that the resumed run forms the rows an
    /// uninterrupted one would. A file does nothing.
    ///
    /// # Errors
    /// A state written by another kind of source or settings.
    fn restore(&mut self, report: &SourceReport) -> Result<(), CliError> {
        let _ = report;
        Ok(())
    }

    /// What the source counted so far (messages, bad payloads by kind, late messages,
    /// reconnections, gaps), for the summary; `None` for a file.
    fn report(&self) -> Option<SourceReport> {
        None
    }
}

impl<R: std::io::Read> Source for SampleReader<R> {
    fn next_into(&mut self, s: &mut Sample) -> Option<Result<Next, CliError>> {
        SampleReader::next_into(self, s).map(|r| r.map(|()| Next::Row))
    }
}

/// FNV-1a, 64 bits, of `bytes` (a retained payload's fingerprint).
fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes
        .iter()
        .fold(0xcbf2_9ce4_8422_2325, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
}

/// A live source's counts, in the summary (text and JSON) and the checkpoint.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SourceReport {
    /// What the source is, in words (`mqtt tcp://127.0.0.1:1883, 3 topics`), without
    /// credentials.
    pub name: String,
    /// Messages received.
    pub messages: u64,
    /// Rows yielded to the certifier.
    pub rows: u64,
    /// Bad payloads by kind (`not_a_number`, `missing_field`, `not_finite`,
    /// `time_backwards`, `oversized`, ...), in the order first seen.
    pub bad: Vec<(String, u64)>,
    /// Messages older than the reorder window allows (their rows were already out): dropped.
    pub late: u64,
    /// Messages the broker delivered again (after a reconnection) that were already taken:
    /// passed over.
    #[serde(default)]
    pub redelivered: u64,
    /// Grid rows not formed because a signal's latest value was older than `max_age` or
    /// missing.
    pub stale_rows: u64,
    /// Gaps yielded (outages and stale stretches; each starts new windows).
    pub gaps: u64,
    /// Reconnections: connections made again after one was lost.
    pub reconnects: u64,
    /// Reconnection attempts: every connection lost or refused, each followed by another
    /// attempt (at least `reconnects`; more while the broker or server is away).
    #[serde(default)]
    pub reconnect_attempts: u64,
    /// Topics or nodes that delivered nothing within the stated time, by name.
    pub silent: Vec<String>,
    /// The retained message last taken on each topic, as `(topic, FNV-1a 64 of its
    /// payload)`: a broker sends it again at every subscription, and it is taken once.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub retained: Vec<(String, u64)>,
    /// The source's own state at a checkpoint ([`Source::restore`]), when its rows depend on
    /// messages already acknowledged; `None` otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state: Option<serde_json::Value>,
}

impl SourceReport {
    /// Count one bad payload of `kind`.
    pub fn count_bad(&mut self, kind: &str) {
        match self.bad.iter_mut().find(|(k, _)| k == kind) {
            Some((_, n)) => *n += 1,
            None => self.bad.push((kind.to_string(), 1)),
        }
    }

    /// Whether a retained message (`payload` on `topic`) is the one already taken there; if
    /// not, it is remembered as the topic's.
    pub fn retained_again(&mut self, topic: &str, payload: &[u8]) -> bool {
        let hash = fnv1a64(payload);
        match self.retained.iter_mut().find(|(t, _)| t == topic) {
            Some((_, h)) if *h == hash => true,
            Some((_, h)) => {
                *h = hash;
                false
            }
            None => {
                self.retained.push((topic.to_string(), hash));
                false
            }
        }
    }

    /// Continue the counts of `saved` (a checkpoint's report): a resumed run's counts are the
    /// run's, not the process's. The name, the silent topics and the source's state stay
    /// this process's own.
    pub fn continue_from(&mut self, saved: &SourceReport) {
        self.messages = saved.messages;
        self.rows = saved.rows;
        self.bad.clone_from(&saved.bad);
        self.late = saved.late;
        self.redelivered = saved.redelivered;
        self.stale_rows = saved.stale_rows;
        self.gaps = saved.gaps;
        self.reconnects = saved.reconnects;
        self.reconnect_attempts = saved.reconnect_attempts;
        self.retained.clone_from(&saved.retained);
    }

    /// Bad payloads of every kind.
    #[must_use]
    pub fn bad_total(&self) -> u64 {
        self.bad.iter().map(|(_, n)| n).sum()
    }

    /// One line for the summary: `source: mqtt ... : 1200 messages, 400 rows, 3 bad
    /// (not_a_number 2, oversized 1), 1 late, 0 redelivered, 0 stale rows, 1 gaps, 1
    /// reconnects (4 attempts)`.
    #[must_use]
    pub fn line(&self) -> String {
        let bad = if self.bad.is_empty() {
            String::new()
        } else {
            let kinds: Vec<String> = self.bad.iter().map(|(k, n)| format!("{k} {n}")).collect();
            format!(" ({})", kinds.join(", "))
        };
        let mut line = format!(
            "source: {}: {} messages, {} rows, {} bad{bad}, {} late, {} redelivered, {} stale \
             rows, {} gaps, {} reconnects ({} attempts)",
            self.name,
            self.messages,
            self.rows,
            self.bad_total(),
            self.late,
            self.redelivered,
            self.stale_rows,
            self.gaps,
            self.reconnects,
            self.reconnect_attempts
        );
        if !self.silent.is_empty() {
            line.push_str(&format!("; silent: {}", self.silent.join(", ")));
        }
        line
    }
}
