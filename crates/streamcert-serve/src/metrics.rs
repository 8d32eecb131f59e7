//! The Prometheus metrics (docs/operations.md lists them; the `prometheus-client` crate's registry and its OpenMetrics text
//! encoding). Each series' handle is taken once, when the run starts, so that a sample's
//! update is a handful of atomic stores, never a lookup.
//!
//! | name | type | labels | what |
//! |---|---|---|---|
//! | `streamcert_certificate_per_second` | gauge | loop, certificate | the certificate (1/s; NaN while there is none) |
//! | `streamcert_rate_estimate_per_second` | gauge | loop, certificate | the rate estimate it bounds: `β̂` (paper's), `β̂_w` (calibrated) |
//! | `streamcert_radius_per_second` | gauge | loop, certificate | the radius subtracted |
//! | `streamcert_margin_per_second` | gauge | loop | the margin the certificate must clear |
//! | `streamcert_model_order` | gauge | loop | the loop model's order (`[regression] order`: 1, 2 or 3; with `"auto"` the standing look's, 0 before one) |
//! | `streamcert_gate_open` | gauge | loop, certificate | 1 while the gate is open |
//! | `streamcert_gate_reason` | gauge (state set) | loop, certificate, reason | 1 for the reason the gate is closed (`none` when open), 0 for the others |
//! | `streamcert_network_rate_per_second` | gauge | loop | the network rate (NaN while there is none) |
//! | `streamcert_network_gate_open` | gauge | loop | 1 while the network gate is open |
//! | `streamcert_subsystem_certificate_per_second` | gauge | loop, subsystem | a subsystem's composing certificate |
//! | `streamcert_subsystem_gate_open` | gauge | loop, subsystem | 1 while a subsystem is certified |
//! | `streamcert_samples_total` | counter | loop | rows certified |
//! | `streamcert_epochs_total` | counter | loop | network epochs composed |
//! | `streamcert_gaps_total` | counter | loop | gaps (a file's time column, a source's outage) |
//! | `streamcert_skipped_rows_total` | counter | loop | rows passed over as bad |
//! | `streamcert_bad_payloads_total` | counter | loop | a live source's bad payloads |
//! | `streamcert_reconnects_total` | counter | loop | a live source's reconnections (connections made again) |
//! | `streamcert_reconnect_attempts_total` | counter | loop | a live source's reconnection attempts (every connection lost or refused) |
//! | `streamcert_last_sample_time_seconds` | gauge | loop | the last sample's time |
//! | `streamcert_last_sample_age_seconds` | gauge | loop | wall time since the last sample arrived |
//! | `streamcert_evidence_lag_seconds` | gauge | loop | wall clock less the sample's time when its evidence was computed (sample times in Unix seconds only; NaN otherwise) |
//!
//! `loop` is the run's name (`--name`; a network run's too).
//!
//! `/metrics` serves the Prometheus text format 0.0.4 (`text/plain; version=0.0.4`), whose
//! counter families are declared with their `_total` names, as `promtool check metrics`
//! wants; a scraper that asks for OpenMetrics (`Accept: application/openmetrics-text`) is
//! served that format, as the registry encodes it ([`to_text_format`] turns one into the
//! other).

use std::sync::atomic::AtomicU64;

use prometheus_client::encoding::text::encode;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;

/// A gauge of `f64`.
pub(crate) type FGauge = Gauge<f64, AtomicU64>;

type Labels = Vec<(&'static str, String)>;

/// Every family of the table above, in one registry.
pub(crate) struct Metrics {
    registry: Registry,
    certificate: Family<Labels, FGauge>,
    estimate: Family<Labels, FGauge>,
    radius: Family<Labels, FGauge>,
    margin: Family<Labels, FGauge>,
    order: Family<Labels, FGauge>,
    gate: Family<Labels, FGauge>,
    reason: Family<Labels, FGauge>,
    network_rate: Family<Labels, FGauge>,
    network_gate: Family<Labels, FGauge>,
    sub_certificate: Family<Labels, FGauge>,
    sub_gate: Family<Labels, FGauge>,
    samples: Family<Labels, Counter>,
    epochs: Family<Labels, Counter>,
    gaps: Family<Labels, Counter>,
    skipped: Family<Labels, Counter>,
    bad: Family<Labels, Counter>,
    reconnects: Family<Labels, Counter>,
    reconnect_attempts: Family<Labels, Counter>,
    last_time: Family<Labels, FGauge>,
    age: Family<Labels, FGauge>,
    lag: Family<Labels, FGauge>,
}

/// One certificate's series.
#[derive(Clone)]
pub(crate) struct Certificate {
    pub(crate) value: FGauge,
    pub(crate) estimate: FGauge,
    pub(crate) radius: FGauge,
    pub(crate) gate: FGauge,
    /// One per reason kind, `none` first.
    pub(crate) reasons: Vec<(&'static str, FGauge)>,
}

/// A run's counters and clocks.
#[derive(Clone)]
pub(crate) struct RunSeries {
    pub(crate) samples: Counter,
    pub(crate) epochs: Counter,
    pub(crate) gaps: Counter,
    pub(crate) skipped: Counter,
    pub(crate) bad: Counter,
    pub(crate) reconnects: Counter,
    pub(crate) reconnect_attempts: Counter,
    pub(crate) last_time: FGauge,
    pub(crate) age: FGauge,
    pub(crate) lag: FGauge,
    pub(crate) margin: FGauge,
}

/// A network's series.
#[derive(Clone)]
pub(crate) struct NetworkSeries {
    pub(crate) rate: FGauge,
    pub(crate) gate: FGauge,
    pub(crate) sub_certificate: Vec<FGauge>,
    pub(crate) sub_gate: Vec<FGauge>,
    pub(crate) reasons: Vec<(&'static str, FGauge)>,
}

fn labels(pairs: &[(&'static str, &str)]) -> Labels {
    pairs.iter().map(|(k, v)| (*k, (*v).to_string())).collect()
}

impl Metrics {
    pub(crate) fn new() -> Self {
        let mut registry = Registry::default();
        let mut gauge = |name: &str, help: &str| {
            let f = Family::<Labels, FGauge>::default();
            registry.register(name, help, f.clone());
            f
        };
        let certificate = gauge("streamcert_certificate_per_second", "The certificate (1/s)");
        let estimate = gauge(
            "streamcert_rate_estimate_per_second",
            "The rate estimate the certificate bounds",
        );
        let radius = gauge("streamcert_radius_per_second", "The radius the certificate subtracts");
        let margin = gauge("streamcert_margin_per_second", "The margin the certificate must clear");
        let order = gauge("streamcert_model_order", "The loop model's order ([regression] order)");
        let gate = gauge("streamcert_gate_open", "1 while the gate is open");
        let reason = gauge("streamcert_gate_reason", "1 for the reason the gate is closed");
        let network_rate = gauge("streamcert_network_rate_per_second", "The network rate");
        let network_gate =
            gauge("streamcert_network_gate_open", "1 while the network gate is open");
        let sub_certificate =
            gauge("streamcert_subsystem_certificate_per_second", "A subsystem's certificate");
        let sub_gate = gauge("streamcert_subsystem_gate_open", "1 while a subsystem is certified");
        let last_time =
            gauge("streamcert_last_sample_time_seconds", "The last sample's time (its own clock)");
        let age = gauge("streamcert_last_sample_age_seconds", "Wall time since the last sample");
        let lag = gauge(
            "streamcert_evidence_lag_seconds",
            "Wall clock less the sample's time when its evidence was computed",
        );
        let mut counter = |name: &str, help: &str| {
            let f = Family::<Labels, Counter>::default();
            registry.register(name, help, f.clone());
            f
        };
        Self {
            samples: counter("streamcert_samples", "Rows certified"),
            epochs: counter("streamcert_epochs", "Network epochs composed"),
            gaps: counter("streamcert_gaps", "Gaps: new windows start"),
            skipped: counter("streamcert_skipped_rows", "Rows passed over as bad"),
            bad: counter("streamcert_bad_payloads", "A live source's bad payloads"),
            reconnects: counter("streamcert_reconnects", "A live source's reconnections"),
            reconnect_attempts: counter(
                "streamcert_reconnect_attempts",
                "A live source's reconnection attempts",
            ),
            registry,
            certificate,
            estimate,
            radius,
            margin,
            order,
            gate,
            reason,
            network_rate,
            network_gate,
            sub_certificate,
            sub_gate,
            last_time,
            age,
            lag,
        }
    }

    /// The series of certificate `kind` of run `name`, with a state per reason of `reasons`.
    pub(crate) fn certificate(
        &self,
        name: &str,
        kind: &str,
        reasons: &[&'static str],
    ) -> Certificate {
        let l = labels(&[("loop", name), ("certificate", kind)]);
        let nan = |g: FGauge| {
            g.set(f64::NAN);
            g
        };
        Certificate {
            value: nan(self.certificate.get_or_create(&l).clone()),
            estimate: nan(self.estimate.get_or_create(&l).clone()),
            radius: nan(self.radius.get_or_create(&l).clone()),
            gate: self.gate.get_or_create(&l).clone(),
            reasons: self.reason_states(&self.reason, &l, reasons),
        }
    }

    fn reason_states(
        &self,
        family: &Family<Labels, FGauge>,
        l: &Labels,
        reasons: &[&'static str],
    ) -> Vec<(&'static str, FGauge)> {
        let _ = self;
        std::iter::once("none")
            .chain(reasons.iter().copied())
            .map(|r| {
                let mut l = l.clone();
                l.push(("reason", r.to_string()));
                (r, family.get_or_create(&l).clone())
            })
            .collect()
    }

    /// The counters and clocks of run `name`, its margin set.
    pub(crate) fn run(&self, name: &str, margin: f64) -> RunSeries {
        let l = labels(&[("loop", name)]);
        let s = RunSeries {
            samples: self.samples.get_or_create(&l).clone(),
            epochs: self.epochs.get_or_create(&l).clone(),
            gaps: self.gaps.get_or_create(&l).clone(),
            skipped: self.skipped.get_or_create(&l).clone(),
            bad: self.bad.get_or_create(&l).clone(),
            reconnects: self.reconnects.get_or_create(&l).clone(),
            reconnect_attempts: self.reconnect_attempts.get_or_create(&l).clone(),
            last_time: self.last_time.get_or_create(&l).clone(),
            age: self.age.get_or_create(&l).clone(),
            lag: self.lag.get_or_create(&l).clone(),
            margin: self.margin.get_or_create(&l).clone(),
        };
        s.margin.set(margin);
        s.last_time.set(f64::NAN);
        s.age.set(f64::NAN);
        s.lag.set(f64::NAN);
        s
    }

    /// Run `name`'s loop model order: `[regression] order`, set once; with `order = "auto"`
    /// the standing look's order, set as it changes (0 before a look).
    pub(crate) fn model_order(&self, name: &str, order: usize) {
        self.order.get_or_create(&labels(&[("loop", name)])).set(order as f64);
    }

    /// The series of network `name` with `subsystems`, a state per reason of `reasons`.
    pub(crate) fn network(
        &self,
        name: &str,
        subsystems: &[String],
        reasons: &[&'static str],
    ) -> NetworkSeries {
        let l = labels(&[("loop", name)]);
        let sub = |family: &Family<Labels, FGauge>| -> Vec<FGauge> {
            subsystems
                .iter()
                .map(|s| family.get_or_create(&labels(&[("loop", name), ("subsystem", s)])).clone())
                .collect()
        };
        let s = NetworkSeries {
            rate: self.network_rate.get_or_create(&l).clone(),
            gate: self.network_gate.get_or_create(&l).clone(),
            sub_certificate: sub(&self.sub_certificate),
            sub_gate: sub(&self.sub_gate),
            reasons: self.reason_states(
                &self.reason,
                &labels(&[("loop", name), ("certificate", "network")]),
                reasons,
            ),
        };
        s.rate.set(f64::NAN);
        s.sub_certificate.iter().for_each(|g| {
            g.set(f64::NAN);
        });
        s
    }

    /// Set run `name`'s age of the last sample (at a scrape).
    pub(crate) fn run_age(&self, name: &str, age: f64) {
        self.age.get_or_create(&labels(&[("loop", name)])).set(age);
    }

    /// The registry in the OpenMetrics text format.
    pub(crate) fn text(&self) -> String {
        let mut out = String::with_capacity(8 * 1024);
        // Writing into a String does not fail.
        let _ = encode(&mut out, &self.registry);
        out
    }
}

/// The OpenMetrics text `open` in the Prometheus text format 0.0.4: a counter family's
/// `# HELP` and `# TYPE` lines name it with `_total`, as its samples do (OpenMetrics names
/// the family without it); `# UNIT` and `# EOF` lines, which 0.0.4 does not have, are left
/// out. Samples and the other families are the same in both formats.
#[must_use]
pub fn to_text_format(open: &str) -> String {
    let counters: std::collections::HashSet<&str> =
        open.lines().filter_map(|l| l.strip_prefix("# TYPE ")?.strip_suffix(" counter")).collect();
    let mut out = String::with_capacity(open.len() + 16 * counters.len());
    for line in open.lines() {
        if line == "# EOF" || line.starts_with("# UNIT ") {
            continue;
        }
        let meta = ["# HELP ", "# TYPE "].into_iter().find_map(|p| {
            let rest = line.strip_prefix(p)?;
            let (name, tail) = rest.split_once(' ')?;
            counters.contains(name).then(|| format!("{p}{name}_total {tail}"))
        });
        match meta {
            Some(l) => out.push_str(&l),
            None => out.push_str(line),
        }
        out.push('\n');
    }
    out
}

/// Set the state set `states` to `current` (1 for it, 0 for the others).
pub(crate) fn set_state(states: &[(&'static str, FGauge)], current: &str) {
    for (kind, g) in states {
        g.set(if *kind == current { 1.0 } else { 0.0 });
    }
}

/// Advance counter `c` to `total` (the summary's count; a counter only goes up).
pub(crate) fn advance(c: &Counter, total: u64) {
    let now = c.get();
    if total > now {
        c.inc_by(total - now);
    }
}
