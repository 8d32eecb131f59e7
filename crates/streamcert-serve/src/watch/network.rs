//! The watcher of a `network` run: each epoch into the metrics, the network gate's changes
//! into verdict messages, the subsystems onto the status page.

use std::sync::Arc;
use std::time::Instant;

use streamcert_network::{EpochReport, NetworkConfig};
use streamcert_pipeline::network::{NetSummary, epoch_reasons, reason_words, verdict_line};
use streamcert_pipeline::source::SourceReport;
use streamcert_pipeline::watch::Watch;

use super::{Shown, lag};
use crate::Shared;
use crate::metrics::{self, NetworkSeries, RunSeries};
use crate::status::Subsystem;
use crate::verdict::{Candidate, Counters, Reason, Risk, VerdictMessage, VerdictSink};

/// Every reason kind a network gate reports (the network's own and the local gates').
fn reason_kinds() -> Vec<&'static str> {
    let mut kinds = vec![
        "no_sample",
        "stale",
        "coupling_unbounded",
        "network_below_margin",
        "accumulating_epochs",
    ];
    kinds.extend(streamcert_certificate::NotCertified::KINDS);
    kinds
}

/// Watches a `network` run ([`crate::Monitor::network`]).
pub struct NetworkWatch {
    shared: Arc<Shared>,
    cfg: NetworkConfig,
    series: NetworkSeries,
    run: RunSeries,
    last_reason: &'static str,
    subsystems: Vec<Subsystem>,
    shown: Shown,
}

impl NetworkWatch {
    pub(crate) fn new(
        shared: Arc<Shared>,
        cfg: &NetworkConfig,
        sinks: Vec<Box<dyn VerdictSink>>,
    ) -> Self {
        let name = shared.name.clone();
        let names: Vec<String> = cfg.subsystems.iter().map(|s| s.name.clone()).collect();
        let message = VerdictMessage {
            schema: crate::verdict::VERDICT_SCHEMA,
            sequence: 0,
            name: name.clone(),
            kind: "network",
            certificate: "network",
            candidate: Candidate {
                gain: Vec::new(),
                margin: cfg.margin,
                order: None,
                orders: Vec::new(),
            },
            open: false,
            since: None,
            t: None,
            since_text: None,
            t_text: None,
            value: None,
            look_order: None,
            reason: Some(Reason::new("starting", "no epoch yet")),
            risk: cfg.total_risk().map(|delta| Risk { delta }),
            ended: false,
            counters: Counters::default(),
        };
        let subsystems = names
            .iter()
            .map(|n| Subsystem { name: n.clone(), certificate: None, open: false, reason: None })
            .collect();
        Self {
            series: shared.metrics.network(&name, &names, &reason_kinds()),
            run: shared.metrics.run(&name, cfg.margin),
            shown: Shown::new(&shared, message, sinks),
            shared,
            cfg: cfg.clone(),
            last_reason: "none",
            subsystems,
        }
    }

    /// The status page's document brought up to date ([`Shown::write`]), the subsystems with
    /// the verdict line.
    fn refresh(
        &mut self,
        now: Instant,
        rebuilt: bool,
        summary: Option<&NetSummary>,
        ended: Option<String>,
    ) {
        let verdict = summary.map(|s| verdict_line(&self.cfg, s));
        let mut st = self.shared.status();
        if verdict.is_some() {
            st.subsystems.clone_from(&self.subsystems);
        }
        self.shown.write(&mut st, now, verdict, rebuilt, ended);
    }

    /// The metrics and subsystems of epoch `r`.
    fn measure(&mut self, r: &EpochReport, summary: &NetSummary) {
        self.series.rate.set(r.rate.unwrap_or(f64::NAN));
        self.series.gate.set(if r.open { 1.0 } else { 0.0 });
        for (i, sub) in self.subsystems.iter_mut().enumerate() {
            let why = r.not_certified.iter().find(|(j, _)| *j == i).map(|(_, w)| w);
            sub.certificate = r.local.get(i).copied().flatten();
            sub.open = why.is_none();
            sub.reason = why.map(ToString::to_string);
            self.series.sub_certificate[i].set(sub.certificate.unwrap_or(f64::NAN));
            self.series.sub_gate[i].set(if sub.open { 1.0 } else { 0.0 });
        }
        let c = self.shown.counters();
        (c.samples, c.epochs, c.skipped) = (summary.rows, summary.epochs, summary.skipped);
        metrics::advance(&self.run.samples, summary.rows);
        metrics::advance(&self.run.epochs, summary.epochs);
        metrics::advance(&self.run.skipped, summary.skipped);
        self.run.last_time.set(r.t);
        self.run.lag.set(lag(r.t));
    }
}

impl Watch for NetworkWatch {
    fn epoch(&mut self, r: &EpochReport, _names: &[String], summary: &NetSummary) {
        let now = Instant::now();
        self.shown.arrived = Some(now);
        self.measure(r, summary);
        let kinds = epoch_reasons(r);
        let kind = kinds.first().copied().unwrap_or("none");
        if kind != self.last_reason {
            metrics::set_state(&self.series.reasons, kind);
            self.last_reason = kind;
        }
        let due = self.shown.due(now);
        let detail = || summary.last_reason.clone().unwrap_or_default();
        let why = kinds.first().map(|k| (*k, detail));
        let (changed, rebuilt) = self.shown.gate.set(r.t, r.open, r.rate, why, reason_words, due);
        if self.shown.chart.due(r.t, r.open) {
            self.shown.pending.push((r.t, r.rate, r.open));
        }
        self.refresh(now, rebuilt, (changed || due).then_some(summary), None);
    }

    fn net_summary(&mut self, summary: &NetSummary) {
        self.refresh(Instant::now(), false, Some(summary), None);
    }

    fn net_skipped(&mut self, summary: &NetSummary) {
        self.shown.counters().skipped = summary.skipped;
        metrics::advance(&self.run.skipped, summary.skipped);
    }

    fn gap(&mut self, why: &str) {
        self.shown.counters().gaps += 1;
        metrics::advance(&self.run.gaps, self.shown.counters().gaps);
        let closed = self.shown.gate.close("gap", why);
        self.refresh(Instant::now(), closed, None, None);
    }

    fn wants_source(&mut self) -> bool {
        self.shown.source_due()
    }

    fn source(&mut self, report: Option<&SourceReport>) {
        self.shown.source(Some(&self.run), report);
    }

    fn end(&mut self, error: Option<&str>) {
        let how = self.shown.end(error);
        self.refresh(Instant::now(), true, None, Some(how));
    }
}
