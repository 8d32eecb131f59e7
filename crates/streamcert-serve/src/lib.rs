//! # streamcert-serve
//!
//! The verdict where operators look, for a running `streamcert certify` or `network`:
//! - **Prometheus metrics** (`/metrics`, OpenMetrics text through `prometheus-client`): the
//!   certificates, the rate estimates, the radii, the margin, the gates, the reason a gate is
//!   closed (a state set), a network's rate and subsystems, the counters, the age of the last
//!   sample and the lag to its evidence (docs/operations.md lists every series with its unit);
//! - **verdict messages** ([`VerdictMessage`], schema `streamcert.verdict/1`): one per change
//!   of the deciding gate, handed to [`VerdictSink`]s (the command line publishes them,
//!   retained, on an MQTT topic through `streamcert-live`);
//! - **a live status page** (`/`, its document at `/api/status`): the gate in words and
//!   colour, the certificate against the margin over the last minutes, the reason, the
//!   verdict line, the counters, and that data stopped when the source stalls. Its script
//!   and style are embedded; it loads nothing from elsewhere.
//!
//! A [`Monitor`] holds one run's metrics and status. [`Monitor::certify`] and
//! [`Monitor::network`] give the watcher the run is handed
//! (`streamcert_pipeline::certify::run_watched`); [`Monitor::serve`] starts a read-only
//! server on an address (the command line binds localhost unless told otherwise). A sample
//! costs the run a copy of its evidence and counts under a lock no reader holds for long;
//! the metrics are set from them when scraped, the page's verdict line is refreshed at most
//! every [`REFRESH`] and at every change of the gate.
//!
//! The pipeline does not depend on this crate: the Python package and a downstream user of
//! the pipeline link no web server.
//!
//! ```
//! use streamcert_serve::{Monitor, MonitorOptions, Routes};
//! use streamcert_pipeline::{certify, config};
//!
//! let cfg = config::parse(&config::g5_node_b(), "g5_node_b")?;
//! let monitor = Monitor::new(MonitorOptions::named("loop7"));
//! let server = monitor.serve("127.0.0.1:0".parse()?, Routes::All)?;
//! let mut watch = monitor.certify(&cfg.certifier, &cfg.columns.outputs, Vec::new());
//! let csv = "t,y_b,u_b\n0,1,0\n0.01,0.9,0.1\n0.02,0.8,0\n";
//! let opts = certify::Options::default();
//! let mut out = Vec::new();
//! certify::run_watched(&cfg, csv.as_bytes(), "rows", &mut out, &opts, &mut watch)?;
//! let text = monitor.metrics_text();
//! assert!(text.contains("streamcert_samples_total{loop=\"loop7\"} 3"));
//! assert_eq!(monitor.status().counters.samples, 3);
//! assert!(monitor.status().ended.is_some());
//! drop(server);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod http;
mod metrics;
mod status;
mod verdict;
mod watch;

use std::net::SocketAddr;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use streamcert_certificate::CertifierConfig;
use streamcert_network::NetworkConfig;

pub use http::{Routes, Server};
pub use metrics::to_text_format;
pub use status::{STATUS_SCHEMA, Status, Subsystem};
pub use verdict::{Candidate, Counters, Reason, Risk, VERDICT_SCHEMA, VerdictMessage, VerdictSink};
pub use watch::network::NetworkWatch;
pub use watch::{CertifyWatch, REFRESH};

/// What a server could not do.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ServeError {
    /// The address could not be bound (taken, or not this host's).
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        /// The address asked for.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// The server's thread or runtime could not start.
    #[error("cannot start the server: {0}")]
    Runtime(std::io::Error),
}

/// How a [`Monitor`] presents its run.
#[derive(Debug, Clone)]
pub struct MonitorOptions {
    /// The run's name: the metrics' `loop` label, the page's title, the messages' `name`.
    pub name: String,
    /// The page says data stopped after this long without a sample. Default 5 s.
    pub stale_after: Duration,
    /// The chart's span in sample time (seconds). Default 300.
    pub chart_seconds: f64,
}

impl MonitorOptions {
    /// The defaults, with the run's name.
    #[must_use]
    pub fn named(name: &str) -> Self {
        Self { name: name.into(), stale_after: Duration::from_secs(5), chart_seconds: 300.0 }
    }
}

/// What the watcher writes and the server reads.
pub(crate) struct Shared {
    name: String,
    chart_seconds: f64,
    metrics: metrics::Metrics,
    status: Mutex<Status>,
    /// A certify run's series (`None` for a network, whose watcher sets its own).
    loop_series: Mutex<Option<watch::LoopSeries>>,
}

impl Shared {
    /// The status document, locked (a poisoned lock still holds the last document written).
    fn status(&self) -> MutexGuard<'_, Status> {
        self.status.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The metrics at `now`: a certify run's series set from its last evidence, the age of
    /// the last sample brought up to date.
    fn metrics_text(&self, now: Instant) -> String {
        let (evidence, counters, age) = {
            let st = self.status();
            let age = st.arrived.map(|a| now.saturating_duration_since(a).as_secs_f64());
            (st.evidence, st.counters, age.unwrap_or(f64::NAN))
        };
        let series = self.loop_series.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        match series.as_ref() {
            Some(s) => s.publish(evidence.as_ref(), &counters, age, watch::unix_now()),
            None => self.metrics.run_age(&self.name, age),
        }
        drop(series);
        self.metrics.text()
    }
}

/// One run's metrics and status, served by [`Monitor::serve`] and fed by the watcher of
/// [`Monitor::certify`] or [`Monitor::network`] (crate docs).
#[derive(Clone)]
pub struct Monitor {
    shared: Arc<Shared>,
}

impl Monitor {
    /// An empty monitor.
    #[must_use]
    pub fn new(opts: MonitorOptions) -> Self {
        let mut status = Status::new(&opts.name, "loop", "calibrated");
        status.stale_after_seconds = opts.stale_after.as_secs_f64();
        status.chart_seconds = opts.chart_seconds;
        Self {
            shared: Arc::new(Shared {
                name: opts.name,
                chart_seconds: opts.chart_seconds,
                metrics: metrics::Metrics::new(),
                status: Mutex::new(status),
                loop_series: Mutex::new(None),
            }),
        }
    }

    /// The watcher of a `certify` run with this configuration (its gain, margin, risk and
    /// deciding certificate) and output names; `sinks` receive the verdict messages, the
    /// first (sequence 0, the gate closed) at once.
    #[must_use]
    pub fn certify(
        &self,
        cfg: &CertifierConfig,
        outputs: &[String],
        sinks: Vec<Box<dyn VerdictSink>>,
    ) -> CertifyWatch {
        CertifyWatch::new(Arc::clone(&self.shared), cfg, outputs, sinks)
    }

    /// The watcher of a `network` run with this configuration; `sinks` as for
    /// [`Monitor::certify`].
    #[must_use]
    pub fn network(&self, cfg: &NetworkConfig, sinks: Vec<Box<dyn VerdictSink>>) -> NetworkWatch {
        NetworkWatch::new(Arc::clone(&self.shared), cfg, sinks)
    }

    /// Serve `routes` on `addr` (port 0: any free port, [`Server::addr`] says which) until the
    /// [`Server`] is dropped.
    ///
    /// # Errors
    /// The address cannot be bound, or the server's thread cannot start.
    pub fn serve(&self, addr: SocketAddr, routes: Routes) -> Result<Server, ServeError> {
        Server::start(Arc::clone(&self.shared), addr, routes)
    }

    /// The status document now (what `/api/status` serves).
    #[must_use]
    pub fn status(&self) -> Status {
        self.shared.status().at(Instant::now())
    }

    /// The metrics now, in OpenMetrics text (what `/metrics` serves a scraper that asks for
    /// OpenMetrics; [`to_text_format`] gives the text format 0.0.4 served otherwise).
    #[must_use]
    pub fn metrics_text(&self) -> String {
        self.shared.metrics_text(Instant::now())
    }
}
