//! An OPC UA subscription as a [`Source`]: async-opcua's client, driven on a thread of its
//! own (a single-threaded runtime), the values taken on the calling thread.
//!
//! - **Values**: one monitored item per node, at the configured sampling interval, queued by
//!   the server (`queue_size`) between publications, reported on every change of status,
//!   value or timestamp (a constant signal keeps arriving, so it never looks stale). Each
//!   value's time is its source timestamp (or, by explicit choice, the server's), and every
//!   node is a signal of the [`align`](crate::align) rule: rows on the grid `k·T` of source
//!   time, sample and hold, never interpolated.
//! - **Timestamps** are 100 ns ticks: a value within 50 ns of a grid point is taken at the
//!   grid point (`k·T` in floating point need not equal the decimal tick), so that a server
//!   that samples on the grid forms the same rows as the samples written to a file.
//! - **Outages**: a lost connection is a gap (counted; the windows restart), whatever the
//!   server kept: an OPC UA server queues at most `queue_size` values per node for a
//!   subscription and may drop a session, so nothing across an outage is trusted. The client
//!   reconnects with a doubling wait (`reconnect_min` to `reconnect_max`) and creates the
//!   subscription again on a new session; the process keeps running.
//! - **Bad values**: a status that is not Good, a value that is not a number, not finite, or
//!   without the chosen timestamp is counted by kind, named with its node and an excerpt, and
//!   yielded as [`Next::Bad`]; the certifier never sees it.
//! - **Restarts**: OPC UA keeps nothing for a client that is gone, so a process killed and
//!   resumed from its checkpoint continues with a gap where it was away (the MQTT source's
//!   persistent session is the live path without loss across a restart).

use std::collections::HashMap;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use opcua::types::{DataValue, Variant};
use streamcert_pipeline::input::Sample;
use streamcert_pipeline::source::{Next, Source, SourceReport};
use streamcert_pipeline::{CliError, RowError};

use crate::config::{OpcUaConfig, Timestamp};
use crate::payload::PayloadError;
use crate::rows::{SignalRows, Silence};

mod client;
pub use client::APPLICATION_URI;
#[cfg(feature = "opcua-server")]
pub mod server;

/// How long one wait for the client's thread lasts before the source checks its clocks.
const POLL: Duration = Duration::from_millis(50);

/// Ticks (100 ns) from OPC UA's epoch, 1601-01-01, to the Unix epoch.
pub const UNIX_EPOCH_TICKS: i64 = 116_444_736_000_000_000;

/// What the client's thread hands over.
enum Event {
    /// A value of the signal at this index.
    Value(usize, DataValue),
    /// A session is up (the first, or after an outage).
    Connected,
    /// Every node's monitored item is created.
    Subscribed,
    /// The connection was lost, or could not be made: the client retries.
    Lost(String),
    /// The subscription cannot be made (a node the server does not have, a refused
    /// certificate): the source ends with this error.
    Failed(String),
}

/// A live OPC UA source (see the module docs).
pub struct OpcUaSource {
    events: Receiver<Event>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    driver: Option<JoinHandle<()>>,
    cfg: OpcUaConfig,
    report: SourceReport,
    rows: SignalRows,
    /// Nodes (their ids) and whether each has delivered.
    nodes: Vec<(String, bool)>,
    silence: Silence,
    last_value: Instant,
    connected: bool,
    /// A session was up at least once (a later one is a reconnection).
    ever_connected: bool,
    subscribed: bool,
}

impl OpcUaSource {
    /// Start the client's thread (it connects, retrying, and subscribes). `outputs` is the
    /// number of outputs (the nodes' first columns).
    ///
    /// # Errors
    /// A node id that does not parse; the alignment rule.
    pub fn new(cfg: OpcUaConfig, outputs: usize) -> Result<Self, CliError> {
        let rows = SignalRows::new(cfg.nodes.len(), outputs, cfg.rule)?;
        let ids = client::node_ids(&cfg)?;
        let (tx, events) = std::sync::mpsc::channel();
        let (stop, stopped) = tokio::sync::oneshot::channel();
        let thread_cfg = cfg.clone();
        let driver = std::thread::Builder::new()
            .name("opcua-client".into())
            .spawn(move || client::drive(&thread_cfg, ids, &tx, stopped))
            .map_err(|e| CliError::io("starting the OPC UA client", e))?;
        let report = SourceReport {
            name: format!("opcua {} ({} nodes)", cfg.endpoint, cfg.nodes.len()),
            ..SourceReport::default()
        };
        let nodes = cfg.nodes.iter().map(|n| (n.id.clone(), false)).collect();
        Ok(Self {
            events,
            stop: Some(stop),
            driver: Some(driver),
            silence: Silence::new(cfg.silent_after),
            cfg,
            report,
            rows,
            nodes,
            last_value: Instant::now(),
            connected: false,
            ever_connected: false,
            subscribed: false,
        })
    }

    /// Wait until every node's monitored item is created, for at most `timeout`: `true` once
    /// subscribed. Values that arrive meanwhile are kept. A caller that must not miss values
    /// written from now on (a test, a script that starts its plant next) calls it first.
    ///
    /// # Errors
    /// The subscription cannot be made.
    pub fn wait_subscribed(&mut self, timeout: Duration) -> Result<bool, CliError> {
        let deadline = Instant::now() + timeout;
        while !self.subscribed && Instant::now() < deadline {
            match self.events.recv_timeout(POLL) {
                // What a value yields before the subscription is made (a bad value, a gap)
                // is counted in the report and passed over.
                Ok(event) => {
                    self.event(event)?;
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return Ok(false),
            }
        }
        Ok(self.subscribed)
    }

    /// One event from the client's thread: `Some` to yield.
    fn event(&mut self, event: Event) -> Result<Option<Next>, CliError> {
        match event {
            Event::Value(i, dv) => Ok(self.value(i, &dv)),
            Event::Connected => {
                if self.ever_connected {
                    self.report.reconnects += 1;
                }
                self.ever_connected = true;
                self.connected = true;
                Ok(None)
            }
            Event::Subscribed => {
                self.subscribed = true;
                // The idle and silence clocks start once the source can receive.
                self.last_value = Instant::now();
                self.silence.restart();
                eprintln!(
                    "source: {}: subscribed to {} nodes",
                    self.cfg.endpoint,
                    self.nodes.len()
                );
                Ok(None)
            }
            Event::Lost(why) => {
                eprintln!("source: {}: {why}; reconnecting", self.cfg.endpoint);
                self.report.reconnect_attempts += 1;
                if self.connected {
                    self.connected = false;
                    self.report.gaps += 1;
                    return Ok(Some(Next::Gap(format!(
                        "the connection to {} was lost: values sampled during the outage may \
                         be missing",
                        self.cfg.endpoint
                    ))));
                }
                Ok(None)
            }
            Event::Failed(why) => Err(CliError::io(
                format!("OPC UA {}", self.cfg.endpoint),
                std::io::Error::other(why),
            )),
        }
    }

    /// One node's value into the aligner, or a bad value to yield.
    fn value(&mut self, i: usize, dv: &DataValue) -> Option<Next> {
        self.report.messages += 1;
        // A node that has no value yet (never written: no value, no timestamp; or its status
        // says it waits for one): nothing to align, nothing wrong.
        let waiting = dv.status == Some(opcua::types::StatusCode::BadWaitingForInitialData);
        let never = dv.value.is_none()
            && dv.source_timestamp.is_none()
            && dv.status.is_none_or(|s| s.is_good());
        if waiting || never {
            return None;
        }
        self.last_value = Instant::now();
        self.nodes[i].1 = true;
        match sample(dv, self.cfg.timestamp, self.rows.rule().period) {
            Ok((t, v)) => {
                if self.rows.push(i, t, v).is_err() {
                    self.report.late += 1;
                }
                None
            }
            Err(e) => {
                self.report.count_bad(e.kind);
                Some(Next::Bad(RowError {
                    file: format!("opcua node {}", self.nodes[i].0),
                    line: self.report.messages,
                    column: None,
                    message: e.to_string(),
                }))
            }
        }
    }
}

/// A value's time (seconds since the Unix epoch, snapped to the grid of `period` within
/// 50 ns) and its number, or what is wrong with it.
///
/// # Errors
/// A [`PayloadError`] of kind `bad_status`, `missing_field` (no timestamp, no value),
/// `not_a_number` or `not_finite`.
pub fn sample(dv: &DataValue, which: Timestamp, period: f64) -> Result<(f64, f64), PayloadError> {
    let excerpt = |dv: &DataValue| format!("{dv:?}").into_bytes();
    if let Some(status) = dv.status.filter(|s| !s.is_good()) {
        return Err(PayloadError::new("bad_status", &format!("status {status}"), &excerpt(dv)));
    }
    let stamp = match which {
        Timestamp::Source => dv.source_timestamp,
        Timestamp::Server => dv.server_timestamp,
    };
    let Some(stamp) = stamp else {
        let what = format!(
            "no {} timestamp",
            if which == Timestamp::Source { "source" } else { "server" }
        );
        return Err(PayloadError::new("missing_field", &what, &excerpt(dv)));
    };
    let value = match &dv.value {
        None | Some(Variant::Empty) => {
            return Err(PayloadError::new("missing_field", "no value", &excerpt(dv)));
        }
        Some(v) if !v.is_numeric() => {
            return Err(PayloadError::new(
                "not_a_number",
                "the value is not a number",
                &excerpt(dv),
            ));
        }
        Some(v) => v.as_f64().unwrap_or(f64::NAN),
    };
    if !value.is_finite() {
        return Err(PayloadError::new("not_finite", &format!("value {value}"), &excerpt(dv)));
    }
    Ok((seconds(stamp.ticks(), period), value))
}

/// Ticks as seconds since the Unix epoch; within 50 ns of a point `k·period` of the grid,
/// that point (as the aligner computes it).
#[must_use]
pub fn seconds(ticks: i64, period: f64) -> f64 {
    let t = (ticks - UNIX_EPOCH_TICKS) as f64 / 1e7;
    let k = (t / period).round();
    let g = (k as i64) as f64 * period;
    if (t - g).abs() <= 5e-8 { g } else { t }
}

/// Seconds since the Unix epoch as ticks (the nearest 100 ns), for a server's timestamps.
#[must_use]
pub fn ticks(seconds: f64) -> i64 {
    (seconds * 1e7).round() as i64 + UNIX_EPOCH_TICKS
}

impl Source for OpcUaSource {
    fn next_into(&mut self, s: &mut Sample) -> Option<Result<Next, CliError>> {
        loop {
            if let Some(next) = self.rows.next(s, &mut self.report) {
                return Some(Ok(next));
            }
            self.silence.check(&self.nodes, &mut self.report);
            // Idle only once subscribed: a site's source waits for its peers first.
            let idle = self.cfg.idle_timeout.is_some_and(|d| self.last_value.elapsed() >= d);
            if self.subscribed && idle {
                return None;
            }
            match self.events.recv_timeout(POLL) {
                Ok(event) => match self.event(event) {
                    Ok(Some(next)) => return Some(Ok(next)),
                    Ok(None) => {}
                    Err(e) => return Some(Err(e)),
                },
                // Nothing within the poll: the run looks at the counts.
                Err(RecvTimeoutError::Timeout) => return Some(Ok(Next::Idle)),
                Err(RecvTimeoutError::Disconnected) => return None,
            }
        }
    }

    fn report(&self) -> Option<SourceReport> {
        let mut report = self.report.clone();
        report.state = self.rows.state();
        Some(report)
    }

    fn restore(&mut self, report: &SourceReport) -> Result<(), CliError> {
        if let Some(state) = &report.state {
            self.rows.restore(state)?;
        }
        // The run's counts go on from the checkpoint's.
        self.report.continue_from(report);
        Ok(())
    }
}

/// A source that ends closes its session (the server frees it at once) and stops its thread
/// (waited for at most 2 s).
impl Drop for OpcUaSource {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        let deadline = Instant::now() + Duration::from_secs(2);
        while self.driver.as_ref().is_some_and(|d| !d.is_finished()) && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

/// Index of each node id's signal.
pub(crate) type Signals = HashMap<opcua::types::NodeId, usize>;

/// Create a self-signed client certificate (DER) and private key (PEM) for
/// [`APPLICATION_URI`], the identity the client presents under a signing policy. A plant's
/// PKI usually issues its own; this is for trying a secure endpoint and for the tests.
///
/// # Errors
/// The files cannot be written.
pub fn create_client_certificate(
    cert: &std::path::Path,
    key: &std::path::Path,
) -> Result<(), CliError> {
    let desc = opcua::types::ApplicationDescription {
        application_uri: APPLICATION_URI.into(),
        application_name: "streamcert".into(),
        product_uri: APPLICATION_URI.into(),
        ..Default::default()
    };
    let x509: opcua::crypto::X509Data = desc.into();
    opcua::crypto::CertificateStore::create_certificate_and_key(&x509, true, cert, key)
        .map(|_| ())
        .map_err(|e| CliError::io(format!("writing {}", cert.display()), std::io::Error::other(e)))
}

/// Trust a server's certificate (DER or PEM at `cert`): written to `pki_dir/trusted/` under
/// the name the client looks it up by, and taken out of `pki_dir/rejected/` (where a refused
/// first contact put it; a certificate there is refused even when trusted).
///
/// # Errors
/// The certificate cannot be read or written.
pub fn trust_server_certificate(
    pki_dir: &std::path::Path,
    cert: &std::path::Path,
) -> Result<(), CliError> {
    let err =
        |e: String| CliError::io(format!("trusting {}", cert.display()), std::io::Error::other(e));
    let x509 = opcua::crypto::CertificateStore::read_cert(cert).map_err(err)?;
    let dir = pki_dir.join("trusted");
    std::fs::create_dir_all(&dir)
        .map_err(|e| CliError::io(format!("creating {}", dir.display()), e))?;
    let name = opcua::crypto::CertificateStore::cert_file_name(&x509);
    let _ = std::fs::remove_file(pki_dir.join("rejected").join(&name));
    let der = x509.to_der().map_err(|e| err(e.to_string()))?;
    std::fs::write(dir.join(name), der)
        .map_err(|e| CliError::io(format!("writing into {}", dir.display()), e))
}
