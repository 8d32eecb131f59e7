//! What both watchers keep for the status page and the verdict messages, and how they write
//! it into the status document.

use std::time::Instant;

use streamcert_pipeline::source::SourceReport;

use super::{Gate, REFRESH, SOURCE_EVERY};
use crate::Shared;
use crate::metrics::{self, RunSeries};
use crate::status::{Chart, Status};
use crate::verdict::Counters;
use crate::verdict::{VerdictMessage, VerdictSink};

/// The deciding gate and its messages, the chart's points not yet in the document, the
/// counts, the verdict line, when it was last refreshed, when the last sample arrived, and
/// the live source's counts.
pub(crate) struct Shown {
    pub(crate) gate: Gate,
    pub(crate) chart: Chart,
    pub(crate) pending: Vec<(f64, Option<f64>, bool)>,
    verdict: String,
    refreshed: Option<Instant>,
    pub(crate) arrived: Option<Instant>,
    source_asked: Instant,
    source_line: Option<String>,
    /// The source's line changed since it was last written into the document.
    source_changed: bool,
}

impl Shown {
    /// The gate before any sample (its first message sent to `sinks`), written into the
    /// document with the run's kind, margin and risk.
    pub(crate) fn new(
        shared: &Shared,
        message: VerdictMessage,
        sinks: Vec<Box<dyn VerdictSink>>,
    ) -> Self {
        {
            let mut st = shared.status();
            st.kind = message.kind;
            st.certificate = message.certificate;
            st.margin = message.candidate.margin;
            st.order = message.candidate.order;
            st.orders.clone_from(&message.candidate.orders);
            st.risk = message.risk.map(|r| r.delta);
            st.reason.clone_from(&message.reason);
        }
        Self {
            gate: Gate::new(message, sinks),
            chart: Chart::new(shared.chart_seconds),
            pending: Vec::with_capacity(64),
            verdict: String::new(),
            refreshed: None,
            arrived: None,
            source_asked: Instant::now(),
            source_line: None,
            source_changed: false,
        }
    }

    /// Whether the verdict line is due again ([`REFRESH`] since the last).
    pub(crate) fn due(&self, now: Instant) -> bool {
        self.refreshed.is_none_or(|r| now.duration_since(r) >= REFRESH)
    }

    /// Write into `st` the gate's scalars and the counts (copies, no allocation), the gate's
    /// own reason when `gate_reason`, the `verdict` line (and the source's counts) when
    /// given, how the run `ended`, and the chart's pending points.
    pub(crate) fn write(
        &mut self,
        st: &mut Status,
        now: Instant,
        verdict: Option<String>,
        gate_reason: bool,
        ended: Option<String>,
    ) {
        let m = &self.gate.message;
        (st.open, st.since, st.t, st.value) = (m.open, m.since, m.t, m.value);
        st.look_order = m.look_order;
        (st.counters, st.step) = (m.counters, self.gate.step);
        st.arrived = self.arrived;
        if gate_reason {
            st.reason.clone_from(&m.reason);
        }
        if let Some(v) = verdict {
            self.verdict = v;
            self.refreshed = Some(now);
            st.verdict.clone_from(&self.verdict);
        }
        if self.source_changed {
            self.source_changed = false;
            st.source.clone_from(&self.source_line);
        }
        if ended.is_some() {
            st.ended = ended;
        }
        if !self.pending.is_empty() {
            self.chart.append(&mut st.chart, &mut self.pending);
        }
    }

    /// Whether a source's counts are due (every [`SOURCE_EVERY`]).
    pub(crate) fn source_due(&mut self) -> bool {
        let now = Instant::now();
        let due = now.duration_since(self.source_asked) >= SOURCE_EVERY;
        if due {
            self.source_asked = now;
        }
        due
    }

    /// A live source's counts into the counts, the metrics (`run`, when the watcher sets
    /// them itself) and the source's line.
    pub(crate) fn source(&mut self, run: Option<&RunSeries>, report: Option<&SourceReport>) {
        let Some(r) = report else { return };
        let c = self.counters();
        (c.bad, c.reconnects, c.reconnect_attempts, c.late) =
            (r.bad_total(), r.reconnects, r.reconnect_attempts, r.late);
        if let Some(run) = run {
            metrics::advance(&run.bad, r.bad_total());
            metrics::advance(&run.reconnects, r.reconnects);
            metrics::advance(&run.reconnect_attempts, r.reconnect_attempts);
        }
        let line = r.line();
        if self.source_line.as_ref() != Some(&line) {
            self.source_line = Some(line);
            self.source_changed = true;
        }
    }

    /// The run's counts (those of the gate's message: every message carries them).
    pub(crate) fn counters(&mut self) -> &mut Counters {
        &mut self.gate.message.counters
    }

    /// The run ended (`error`: what stopped it): the last message sent; how, in words.
    pub(crate) fn end(&mut self, error: Option<&str>) -> String {
        let how = error.map_or_else(|| "the input ended".to_string(), |e| format!("stopped: {e}"));
        self.gate.end(how.clone());
        how
    }
}
