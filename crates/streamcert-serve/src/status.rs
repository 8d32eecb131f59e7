//! What the status page shows, as JSON (`GET /api/status`, schema `streamcert.status/1`):
//! the gate in words, the certificate against the margin over the last minutes of sample time,
//! the reason, the verdict line, the counters, whether data stopped, and a network's
//! subsystems.

use std::collections::VecDeque;
use std::time::Instant;

use serde::Serialize;

use streamcert_certificate::{NotCertified, SampleTime};

use crate::verdict::{Counters, Reason};

/// The status document's schema and version.
pub const STATUS_SCHEMA: &str = "streamcert.status/1";

/// Points the chart keeps at most.
const CHART_POINTS: usize = 600;

/// The status of one run (module docs).
#[derive(Debug, Clone, Serialize)]
pub struct Status {
    /// [`STATUS_SCHEMA`].
    pub schema: &'static str,
    /// The run's name.
    pub name: String,
    /// `"loop"` or `"network"`.
    pub kind: &'static str,
    /// The deciding certificate: `"calibrated"`, `"gaussian"` or `"network"`.
    pub certificate: &'static str,
    /// The run's stated risk (`None`: no stated risk).
    pub risk: Option<f64>,
    /// The margin (1/s).
    pub margin: f64,
    /// The loop model's order (`[regression] order`; `None` for a network and with
    /// `order = "auto"`): the verdict is the certificate of that order.
    pub order: Option<usize>,
    /// With `order = "auto"`, the orders run side by side (`[1, 2, 3]`); empty otherwise.
    pub orders: Vec<usize>,
    /// The order of the look `value` is from (with `order = "auto"` the standing one;
    /// `None` before a look and for a network).
    pub look_order: Option<usize>,
    /// Whether the deciding gate is open.
    pub open: bool,
    /// The sample time from which it has been in this state (seconds).
    pub since: Option<f64>,
    /// `since` as a person reads it: ISO 8601 UTC where it reads as Unix seconds, else
    /// seconds with the decimals the sampling step resolves
    /// ([`streamcert_certificate::SampleTime`]).
    pub since_text: Option<String>,
    /// Why it is closed.
    pub reason: Option<Reason>,
    /// The verdict line, as the summary would give it if the input ended here.
    pub verdict: String,
    /// The last sample's time (seconds).
    pub t: Option<f64>,
    /// `t` as a person reads it (as `since_text`).
    pub t_text: Option<String>,
    /// The deciding certificate at `t` (the network rate for a network).
    pub value: Option<f64>,
    /// Counts so far.
    pub counters: Counters,
    /// Wall seconds since the last sample arrived (`None` before one).
    pub age_seconds: Option<f64>,
    /// Whether data stopped: no sample for longer than `stale_after_seconds`.
    pub stalled: bool,
    /// The silence after which the page says data stopped.
    pub stale_after_seconds: f64,
    /// The run ended (why, in words), or `None` while it runs.
    pub ended: Option<String>,
    /// The live source, in words (`None` for a file or a pipe).
    pub source: Option<String>,
    /// The chart: `[t, certificate, open]` over the last `chart_seconds` of sample time.
    pub chart: VecDeque<(f64, Option<f64>, bool)>,
    /// The chart's span in sample time.
    pub chart_seconds: f64,
    /// A network's subsystems.
    pub subsystems: Vec<Subsystem>,
    /// The sampling step the times are written with (`None`: not known).
    #[serde(skip)]
    pub(crate) step: Option<f64>,
    /// When the last sample arrived (for `age_seconds`).
    #[serde(skip)]
    pub(crate) arrived: Option<Instant>,
    /// The last sample's reason as the certifier gave it, put in words when served (`None`:
    /// `reason` stands as written).
    #[serde(skip)]
    pub(crate) sample_reason: Option<Option<NotCertified>>,
    /// A certify run's last evidence (its metrics are set from it when scraped).
    #[serde(skip)]
    pub(crate) evidence: Option<streamcert_certificate::Evidence>,
}

/// One subsystem of a network.
#[derive(Debug, Clone, Serialize)]
pub struct Subsystem {
    /// Its name.
    pub name: String,
    /// Its composing certificate.
    pub certificate: Option<f64>,
    /// Whether it is certified.
    pub open: bool,
    /// Why not, in words.
    pub reason: Option<String>,
}

impl Status {
    /// A run that has seen no sample yet.
    pub(crate) fn new(name: &str, kind: &'static str, certificate: &'static str) -> Self {
        Self {
            schema: STATUS_SCHEMA,
            name: name.into(),
            kind,
            certificate,
            risk: None,
            margin: 0.0,
            order: None,
            orders: Vec::new(),
            look_order: None,
            open: false,
            since: None,
            since_text: None,
            reason: None,
            verdict: "no sample yet".into(),
            t: None,
            t_text: None,
            value: None,
            counters: Counters::default(),
            age_seconds: None,
            stalled: false,
            stale_after_seconds: 5.0,
            ended: None,
            source: None,
            chart: VecDeque::with_capacity(CHART_POINTS + 1),
            chart_seconds: 300.0,
            subsystems: Vec::new(),
            step: None,
            arrived: None,
            sample_reason: None,
            evidence: None,
        }
    }

    /// The document as served at `now`: the age of the last sample and whether data stopped.
    pub(crate) fn at(&self, now: Instant) -> Self {
        let mut s = self.clone();
        if let Some(r) = self.sample_reason {
            s.reason = r.map(|r| Reason::new(r.kind(), &r.to_string()));
        }
        let text = |t: Option<f64>| t.map(|t| SampleTime::new(t, self.step).to_string());
        (s.since_text, s.t_text) = (text(self.since), text(self.t));
        s.age_seconds = self.arrived.map(|a| now.saturating_duration_since(a).as_secs_f64());
        s.stalled =
            self.ended.is_none() && s.age_seconds.is_some_and(|age| age > self.stale_after_seconds);
        s
    }
}

/// Which points the chart takes: at most one per `span / CHART_POINTS` of sample time, and
/// every change of the gate.
#[derive(Debug, Clone)]
pub(crate) struct Chart {
    span: f64,
    last: Option<(f64, bool)>,
}

impl Chart {
    pub(crate) fn new(span: f64) -> Self {
        Self { span, last: None }
    }

    /// Whether the point at `t` with the gate `open` is taken.
    pub(crate) fn due(&mut self, t: f64, open: bool) -> bool {
        let step = self.span / CHART_POINTS as f64;
        let due = match self.last {
            None => true,
            Some((last, was_open)) => t >= last + step || t < last || open != was_open,
        };
        if due {
            self.last = Some((t, open));
        }
        due
    }

    /// Append `pending` to `points`, dropping points older than the span before the newest.
    pub(crate) fn append(
        &self,
        points: &mut VecDeque<(f64, Option<f64>, bool)>,
        pending: &mut Vec<(f64, Option<f64>, bool)>,
    ) {
        points.extend(pending.drain(..));
        let newest = points.back().map_or(f64::NEG_INFINITY, |p| p.0);
        while points.front().is_some_and(|p| p.0 < newest - self.span)
            || points.len() > CHART_POINTS
        {
            points.pop_front();
        }
    }
}
