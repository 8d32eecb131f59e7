//! The watchers a run is given ([`streamcert_pipeline::watch::Watch`]): each sample's
//! evidence into the metrics (atomic stores), the gate's changes into verdict messages at
//! once, and the status page's document refreshed at most every [`REFRESH`] of wall time
//! (and at every change), so that serving never slows the certifier down.

use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use streamcert_certificate::{
    CertificateKind, Certifier, CertifierConfig, Evidence, NotCertified, SampleTime,
};
use streamcert_pipeline::certify::{Summary, reason_words};
use streamcert_pipeline::source::SourceReport;
use streamcert_pipeline::watch::Watch;

use crate::Shared;
use crate::metrics::{self, Certificate, RunSeries};

/// A certify run's series, set from its last evidence when scraped.
pub(crate) struct LoopSeries {
    certificates: Vec<(CertificateKind, Certificate)>,
    run: RunSeries,
}

impl LoopSeries {
    /// Every series from the last sample's evidence `ev`, the run's counts, the age of the
    /// last sample (wall seconds) and the wall clock now (Unix seconds).
    pub(crate) fn publish(&self, ev: Option<&Evidence>, counters: &Counters, age: f64, unix: f64) {
        let r = &self.run;
        metrics::advance(&r.samples, counters.samples);
        metrics::advance(&r.gaps, counters.gaps);
        metrics::advance(&r.skipped, counters.skipped);
        metrics::advance(&r.bad, counters.bad);
        metrics::advance(&r.reconnects, counters.reconnects);
        metrics::advance(&r.reconnect_attempts, counters.reconnect_attempts);
        r.age.set(age);
        let Some(ev) = ev else { return };
        r.last_time.set(ev.t);
        // The evidence was computed when the sample arrived, `age` ago.
        r.lag.set(if UNIX_SECONDS.contains(&ev.t) { unix - age - ev.t } else { f64::NAN });
        for (kind, series) in &self.certificates {
            let v = ev.verdict(*kind);
            series.value.set(v.value.unwrap_or(f64::NAN));
            series.radius.set(v.radius.unwrap_or(f64::NAN));
            series.estimate.set(match (v.value, v.radius) {
                (Some(c), Some(r)) => c + r,
                _ => f64::NAN,
            });
            series.gate.set(if v.open { 1.0 } else { 0.0 });
            metrics::set_state(&series.reasons, v.reason.map_or("none", |r| r.kind()));
        }
    }
}
use crate::verdict::{Candidate, Counters, Reason, Risk, VerdictMessage, VerdictSink};

pub(crate) mod network;
mod shown;

use shown::Shown;

/// The status page's document is refreshed at most this often (and at every change).
pub const REFRESH: Duration = Duration::from_millis(100);

/// How often a live source's counts are asked for.
const SOURCE_EVERY: Duration = Duration::from_secs(1);

/// Sample times that read as Unix seconds (2001 to 2100) have an evidence lag and are written
/// in UTC; others are a clock of their own.
use streamcert_certificate::UNIX_SECONDS;

/// The deciding gate's state and the verdict messages it sends (shared by both watchers).
pub(crate) struct Gate {
    pub(crate) message: VerdictMessage,
    sinks: Vec<Box<dyn VerdictSink>>,
    /// The last positive step between two samples' times: the decimals the times are
    /// written with.
    pub(crate) step: Option<f64>,
}

impl Gate {
    /// A closed gate before any sample; the first message (sequence 0) sent to every sink.
    pub(crate) fn new(message: VerdictMessage, mut sinks: Vec<Box<dyn VerdictSink>>) -> Self {
        sinks.iter_mut().for_each(|s| s.publish(&message));
        Self { message, sinks, step: None }
    }

    /// The gate at sample time `t`, closed for `why` (its kind, and its detail made only when
    /// needed): `(changed, rebuilt)`, whether the gate changed (a message was sent) and
    /// whether the reason was written anew (the gate changed, `rebuild` asked, or the kind
    /// changed). A sample that changes neither allocates nothing.
    pub(crate) fn set<D: FnOnce() -> String>(
        &mut self,
        t: f64,
        open: bool,
        value: Option<f64>,
        why: Option<(&'static str, D)>,
        words: fn(&str) -> String,
        rebuild: bool,
    ) -> (bool, bool) {
        let m = &mut self.message;
        let changed = open != m.open;
        if let Some(d) = m.t.map(|last| t - last).filter(|d| *d > 0.0) {
            self.step = Some(d);
        }
        m.t = Some(t);
        m.value = value;
        if changed || m.since.is_none() {
            m.since = Some(t);
        }
        let kind = why.as_ref().map(|(k, _)| *k);
        let rebuilt = changed || rebuild || kind != m.reason.as_ref().map(|r| r.kind.as_str());
        if rebuilt {
            m.reason =
                why.map(|(k, detail)| Reason { kind: k.into(), words: words(k), detail: detail() });
        }
        if changed {
            m.open = open;
            self.send();
        }
        (changed, rebuilt)
    }

    /// The gate closed at once by `kind` (a skipped row, a gap) until the next sample says
    /// more; `true` when it was open.
    pub(crate) fn close(&mut self, kind: &str, detail: &str) -> bool {
        let was_open = self.message.open;
        self.message.reason = Some(Reason::new(kind, detail));
        if was_open {
            self.message.open = false;
            self.message.since = self.message.t;
            self.send();
        }
        was_open
    }

    /// The run ended: the last message, the gate closed.
    pub(crate) fn end(&mut self, detail: String) {
        let m = &mut self.message;
        if m.open {
            m.since = m.t;
        }
        m.open = false;
        m.ended = true;
        m.reason = Some(Reason {
            kind: "stopped".into(),
            words: "the certifier stopped: it vouches for nothing after its last sample \
                    [stopped]"
                .into(),
            detail,
        });
        self.send();
    }

    fn send(&mut self) {
        let step = self.step;
        let m = &mut self.message;
        m.sequence += 1;
        let text = |t: Option<f64>| t.map(|t| SampleTime::new(t, step).to_string());
        (m.since_text, m.t_text) = (text(m.since), text(m.t));
        let m = &self.message;
        self.sinks.iter_mut().for_each(|s| s.publish(m));
    }
}

/// The wall clock in Unix seconds.
pub(crate) fn unix_now() -> f64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64())
}

/// The lag of a sample at time `t`, when `t` reads as Unix seconds.
pub(crate) fn lag(t: f64) -> f64 {
    if UNIX_SECONDS.contains(&t) { unix_now() - t } else { f64::NAN }
}

/// Watches a `certify` run ([`crate::Monitor::certify`]).
pub struct CertifyWatch {
    shared: Arc<Shared>,
    cfg: CertifierConfig,
    outputs: Vec<String>,
    deciding: CertificateKind,
    /// The last sample's evidence.
    last: Option<Evidence>,
    shown: Shown,
}

impl CertifyWatch {
    pub(crate) fn new(
        shared: Arc<Shared>,
        cfg: &CertifierConfig,
        outputs: &[String],
        sinks: Vec<Box<dyn VerdictSink>>,
    ) -> Self {
        let name = shared.name.clone();
        let deciding = if cfg.calibration.is_some() {
            CertificateKind::Calibrated
        } else {
            CertificateKind::Gaussian
        };
        let mut kinds = vec![CertificateKind::Gaussian, CertificateKind::Wasserstein];
        kinds.extend(cfg.calibration.is_some().then_some(CertificateKind::Calibrated));
        kinds.extend(cfg.nonlinear.is_some().then_some(CertificateKind::Nonlinear));
        let reasons = streamcert_certificate::NotCertified::KINDS;
        let certificates = kinds
            .into_iter()
            .map(|k| (k, shared.metrics.certificate(&name, kind_name(k), &reasons)))
            .collect();
        let series = LoopSeries { certificates, run: shared.metrics.run(&name, cfg.margin) };
        // With `order = "auto"` the gauge follows the standing look (0 before one).
        let auto = cfg.orders.as_ref().map(|l| l.orders.clone());
        shared
            .metrics
            .model_order(&name, if auto.is_some() { 0 } else { cfg.regression.order.order() });
        *shared.loop_series.lock().unwrap_or_else(std::sync::PoisonError::into_inner) =
            Some(series);
        let message = VerdictMessage {
            schema: crate::verdict::VERDICT_SCHEMA,
            sequence: 0,
            name,
            kind: "loop",
            certificate: kind_name(deciding),
            candidate: Candidate {
                gain: cfg.gain.chunks(cfg.regression.outputs.max(1)).map(<[f64]>::to_vec).collect(),
                margin: cfg.margin,
                order: auto.is_none().then(|| cfg.regression.order.order()),
                orders: auto.unwrap_or_default(),
            },
            open: false,
            since: None,
            t: None,
            since_text: None,
            t_text: None,
            value: None,
            look_order: None,
            reason: Some(Reason::new("starting", "no sample yet")),
            risk: cfg.calibration.as_ref().map(|c| Risk { delta: c.delta }),
            ended: false,
            counters: Counters::default(),
        };
        Self {
            shown: Shown::new(&shared, message, sinks),
            shared,
            cfg: cfg.clone(),
            outputs: outputs.to_vec(),
            deciding,
            last: None,
        }
    }

    /// The status page's document brought up to date ([`Shown::write`]) with the last
    /// evidence and the sample's reason (copies; put in words when served); `sample_reason`
    /// `None` puts the gate's own reason instead (a skipped row, a gap, the end).
    fn refresh(
        &mut self,
        now: Instant,
        sample_reason: Option<Option<NotCertified>>,
        summary: Option<&Summary>,
        ended: Option<String>,
    ) {
        let verdict = summary.map(|s| s.verdict_line(&self.cfg, &self.outputs));
        let mut st = self.shared.status();
        st.evidence = self.last;
        st.sample_reason = sample_reason;
        self.shown.write(&mut st, now, verdict, sample_reason.is_none(), ended);
    }
}

/// A certificate's name in the metrics and messages.
fn kind_name(kind: CertificateKind) -> &'static str {
    match kind {
        CertificateKind::Gaussian => "gaussian",
        CertificateKind::Wasserstein => "wasserstein",
        CertificateKind::Calibrated => "calibrated",
        CertificateKind::Nonlinear => "nonlinear",
    }
}

impl Watch for CertifyWatch {
    fn sample(&mut self, _cert: &Certifier, summary: &Summary, ev: &Evidence) {
        let now = Instant::now();
        let shown = &mut self.shown;
        shown.arrived = Some(now);
        let c = shown.counters();
        (c.samples, c.gaps, c.skipped) = (summary.rows, summary.gaps, summary.skipped);
        let d = ev.verdict(self.deciding);
        let due = shown.due(now);
        let why = d.reason.map(|r| (r.kind(), move || r.to_string()));
        // The order of the look the value is from (the paper's Gaussian certificate is of the
        // first order), in the message before it may be sent.
        let look_order = match self.deciding {
            CertificateKind::Calibrated => ev.calibrated_order,
            _ => d.value.map(|_| 1),
        };
        if look_order != shown.gate.message.look_order
            && !shown.gate.message.candidate.orders.is_empty()
        {
            self.shared.metrics.model_order(&self.shared.name, look_order.unwrap_or(0));
        }
        shown.gate.message.look_order = look_order;
        let (changed, _) = shown.gate.set(ev.t, d.open, d.value, why, reason_words, false);
        if shown.chart.due(ev.t, d.open) {
            shown.pending.push((ev.t, d.value, d.open));
        }
        self.last = Some(*ev);
        self.refresh(now, Some(d.reason), (changed || due).then_some(summary), None);
    }

    fn summary(&mut self, summary: &Summary) {
        let reason = self.shared.status().sample_reason;
        self.refresh(Instant::now(), reason, Some(summary), None);
    }

    fn skipped(&mut self, summary: &Summary) {
        self.shown.counters().skipped = summary.skipped;
        let why = "a bad row was passed over: every gate closes";
        let closed = self.shown.gate.close("skipped_sample", why);
        self.refresh(Instant::now(), None, closed.then_some(summary), None);
    }

    fn gap(&mut self, why: &str) {
        self.shown.gate.close("gap", why);
        self.refresh(Instant::now(), None, None, None);
    }

    fn wants_source(&mut self) -> bool {
        self.shown.source_due()
    }

    fn source(&mut self, report: Option<&SourceReport>) {
        self.shown.source(None, report);
    }

    fn end(&mut self, error: Option<&str>) {
        let how = self.shown.end(error);
        self.refresh(Instant::now(), None, None, Some(how));
    }
}
