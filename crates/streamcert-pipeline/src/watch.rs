//! Watching a run as it goes: what a dashboard, an interlock or a status page needs from
//! `certify` and `network`, handed over as each row is certified, without the run knowing who
//! watches (the `streamcert-serve` crate's metrics, status page and verdict messages).
//!
//! A [`Watch`] is called on the certifying thread, after the row's evidence is computed and
//! counted into the summary, before the row is written (a live run writes it at once; a
//! file's run writes it with its batch). The calls are in input order. [`NoWatch`] does
//! nothing, at no cost: the runs without a watcher call it.

use streamcert_certificate::{Certifier, Evidence};
use streamcert_network::EpochReport;

use crate::source::SourceReport;
use crate::summary::{NetSummary, Summary};

/// Receives a run's events in input order (module docs). Every method has an empty default,
/// so a watcher implements what it uses.
pub trait Watch: Send {
    /// A `certify` row certified: its evidence, the certifier after it, and the summary
    /// counting it.
    fn sample(&mut self, cert: &Certifier, summary: &Summary, ev: &Evidence) {
        let _ = (cert, summary, ev);
    }

    /// A `certify` row passed over as bad (a malformed row under `--on-bad-row skip`, a
    /// sample the certifier refused, a live source's bad payload): every gate closes.
    fn skipped(&mut self, summary: &Summary) {
        let _ = summary;
    }

    /// A `network` epoch composed: its report, the subsystems' names, the summary counting
    /// it.
    fn epoch(&mut self, report: &EpochReport, names: &[String], summary: &NetSummary) {
        let _ = (report, names, summary);
    }

    /// A bad payload of a `network` run's live source, skipped.
    fn net_skipped(&mut self, summary: &NetSummary) {
        let _ = summary;
    }

    /// The source declared a gap (why, in words): new windows start at the next row.
    fn gap(&mut self, why: &str) {
        let _ = why;
    }

    /// Whether the watcher wants the source's counts now ([`Watch::source`] is then called
    /// with them). Asked after every item of a live source; the default never.
    fn wants_source(&mut self) -> bool {
        false
    }

    /// The source's counts so far (`None` for a file or a pipe).
    fn source(&mut self, report: Option<&SourceReport>) {
        let _ = report;
    }

    /// A `certify` run's summary at its end (before [`Watch::end`]).
    fn summary(&mut self, summary: &Summary) {
        let _ = summary;
    }

    /// A `network` run's summary at its end (before [`Watch::end`]).
    fn net_summary(&mut self, summary: &NetSummary) {
        let _ = summary;
    }

    /// The run ended: its stream is over, or an error stopped it (`error`, in words).
    fn end(&mut self, error: Option<&str>) {
        let _ = error;
    }
}

/// A watcher that does nothing: the runs without one.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoWatch;

impl Watch for NoWatch {}
