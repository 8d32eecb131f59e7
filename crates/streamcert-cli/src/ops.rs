//! `--serve`, `--metrics` and `[verdict]`: the verdict where operators look (the
//! `streamcert-serve` crate's page and metrics, `streamcert-live`'s verdict topic).

use std::net::{SocketAddr, ToSocketAddrs};
use std::path::Path;
use std::time::Duration;

use streamcert_live::verdict::{VerdictPublisher, parse_verdict};
use streamcert_pipeline::CliError;
use streamcert_serve::{Monitor, MonitorOptions, Routes, Server, VerdictMessage, VerdictSink};

/// Where a run's verdict is shown while it runs.
#[derive(clap::Args, Clone)]
pub(crate) struct Ops {
    /// Serve the live status page (and its JSON, and the metrics) on ADDR: HOST:PORT, or a
    /// bare PORT on localhost (default 127.0.0.1:8080). Read only.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:8080")]
    serve: Option<String>,
    /// Serve the Prometheus metrics on ADDR at /metrics (default 127.0.0.1:9464).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:9464")]
    metrics: Option<String>,
    /// The run's name on the page, in the metrics' `loop` label and the verdict messages
    /// (default: the configuration file's name without its extension).
    #[arg(long)]
    name: Option<String>,
    /// The page says data stopped after this many seconds without a sample.
    #[arg(long, value_name = "SECONDS", default_value_t = 5.0)]
    stale_after: f64,
}

/// A run's monitor, its servers and its verdict topic (nothing when none is asked for).
pub(crate) struct Operator {
    pub(crate) monitor: Option<Monitor>,
    pub(crate) sinks: Vec<Box<dyn VerdictSink>>,
    _servers: Vec<Server>,
}

impl Ops {
    /// Whether anything is asked for besides the name.
    pub(crate) fn is_set(&self) -> bool {
        self.serve.is_some() || self.metrics.is_some()
    }

    /// Start what is asked for: the servers, and the publisher of `verdict` (the
    /// configuration's `[verdict]` table).
    pub(crate) fn start(
        &self,
        config: &str,
        verdict: Option<&toml::Table>,
    ) -> Result<Operator, CliError> {
        let name = self.name.clone().unwrap_or_else(|| {
            Path::new(config)
                .file_stem()
                .map_or("streamcert".into(), |s| s.to_string_lossy().into())
        });
        let bad = |message: String| CliError::Config { path: config.into(), message };
        let mut sinks: Vec<Box<dyn VerdictSink>> = Vec::new();
        if let Some(table) = verdict {
            let cfg = parse_verdict(table, &name).map_err(bad)?;
            let mut publisher = VerdictPublisher::new(cfg)?;
            sinks.push(Box::new(move |m: &VerdictMessage| {
                publisher.publish(&m.to_json(), &m.offline().to_json());
            }));
        }
        if !self.is_set() && sinks.is_empty() {
            return Ok(Operator { monitor: None, sinks, _servers: Vec::new() });
        }
        let stale = Duration::try_from_secs_f64(self.stale_after)
            .ok()
            .filter(|d| !d.is_zero())
            .ok_or_else(|| bad(format!("--stale-after {}: give seconds > 0", self.stale_after)))?;
        let monitor =
            Monitor::new(MonitorOptions { stale_after: stale, ..MonitorOptions::named(&name) });
        let mut servers = Vec::new();
        for (addr, routes, what) in
            [(&self.serve, Routes::All, "status page"), (&self.metrics, Routes::Metrics, "metrics")]
        {
            if let Some(addr) = addr {
                let server = monitor.serve(address(addr).map_err(bad)?, routes).map_err(|e| {
                    CliError::io(
                        format!("serving the {what}"),
                        std::io::Error::other(e.to_string()),
                    )
                })?;
                let path = if routes == Routes::Metrics { "metrics" } else { "" };
                eprintln!("{what}: http://{}/{path}", server.addr());
                servers.push(server);
            }
        }
        Ok(Operator { monitor: Some(monitor), sinks, _servers: servers })
    }
}

/// `HOST:PORT`, or a bare `PORT` on 127.0.0.1 (never every interface unless written).
fn address(text: &str) -> Result<SocketAddr, String> {
    if let Ok(port) = text.parse::<u16>() {
        return Ok(SocketAddr::from(([127, 0, 0, 1], port)));
    }
    text.to_socket_addrs()
        .map_err(|e| format!("`{text}`: not an address (HOST:PORT or PORT): {e}"))?
        .next()
        .ok_or_else(|| format!("`{text}`: the host has no address"))
}
