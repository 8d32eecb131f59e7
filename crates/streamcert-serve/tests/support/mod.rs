//! Helpers of the server's tests: a G5 run whose source calls back before chosen rows (so a
//! request sees the run between two rows, deterministically), and a plain HTTP/1.1 client.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::time::Duration;

use streamcert_dynamics::Coupling;
use streamcert_experiments::Experiment;
use streamcert_pipeline::config::{self, Config};
use streamcert_pipeline::input::{Sample, SampleReader};
use streamcert_pipeline::source::{Next, Source};
use streamcert_pipeline::{CliError, certify};

/// The repository's `examples/data` file `name`.
pub(crate) fn example(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples/data").join(name)
}

/// G5 node b's configuration (calibrated certificate, the default guards).
pub(crate) fn node_b() -> Config {
    config::parse(&config::g5_node_b(), "g5_node_b").unwrap()
}

/// The 16 s of G5 Experiment 2, seed 1 (`streamcert simulate g5 --experiment 2 --seed 1`),
/// with the rows of `[gap_from, gap_to)` left out: a gap there.
pub(crate) fn g5_rows(gap: Option<(f64, f64)>) -> String {
    let mut bytes = Vec::new();
    let (exp, coupling) = (Experiment::Two, Coupling::Cascade);
    streamcert_pipeline::simulate::run(exp, coupling, 1, None, None, &mut bytes).unwrap();
    let text = String::from_utf8(bytes).unwrap();
    let mut out = String::new();
    for (i, line) in text.lines().enumerate() {
        let t: f64 = line.split(',').next().unwrap().parse().unwrap_or(f64::NAN);
        if i > 0 && gap.is_some_and(|(a, b)| t >= a && t < b) {
            continue;
        }
        out.push_str(line);
        out.push('\n');
    }
    out
}

/// A CSV source that calls `before(k)` before it yields row `k` (from 0).
pub(crate) struct Paused<'a, F: FnMut(u64)> {
    pub(crate) reader: SampleReader<&'a [u8]>,
    pub(crate) before: F,
    pub(crate) row: u64,
}

impl<F: FnMut(u64)> Source for Paused<'_, F> {
    fn next_into(&mut self, s: &mut Sample) -> Option<Result<Next, CliError>> {
        (self.before)(self.row);
        self.row += 1;
        self.reader.next_into(s).map(|r| r.map(|()| Next::Row))
    }
}

/// Certify `rows` with `cfg` row by row, `watch` watching and `before(k)` called before row
/// `k`; the evidence CSV.
pub(crate) fn run_paused(
    cfg: &Config,
    rows: &str,
    watch: &mut dyn streamcert_pipeline::watch::Watch,
    before: impl FnMut(u64),
) -> String {
    let reader = SampleReader::new(rows.as_bytes(), "g5", &cfg.columns).unwrap();
    let mut source = Paused { reader, before, row: 0 };
    let mut out = Vec::new();
    let opts = certify::Options::default();
    certify::run_source_watched(cfg, &mut source, "g5", &mut out, &opts, watch).unwrap();
    String::from_utf8(out).unwrap()
}

/// The evidence rows as maps from column to field.
pub(crate) fn evidence(csv: &str) -> Vec<std::collections::HashMap<String, String>> {
    let mut lines = csv.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let mut r = csv::ReaderBuilder::new().has_headers(false).from_reader(csv.as_bytes());
    r.records()
        .skip(1)
        .map(|rec| header.iter().cloned().zip(rec.unwrap().iter().map(String::from)).collect())
        .collect()
}

/// A response: its status code, its headers (lower-cased names) and its body.
pub(crate) struct Response {
    pub(crate) status: u16,
    pub(crate) headers: String,
    pub(crate) body: String,
}

/// Send `request` (raw bytes) to `addr` and read the whole response (the connection closes).
pub(crate) fn raw(addr: SocketAddr, request: &[u8]) -> Response {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    // A server may answer and close before a large request is written whole.
    let _ = s.write_all(request);
    let mut bytes = Vec::new();
    let _ = s.read_to_end(&mut bytes);
    let text = String::from_utf8_lossy(&bytes).to_string();
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let status = head.split(' ').nth(1).and_then(|c| c.parse().ok()).unwrap_or(0);
    Response { status, headers: head.to_lowercase(), body: body.to_string() }
}

/// `METHOD path` on `addr`.
pub(crate) fn request(addr: SocketAddr, method: &str, path: &str) -> Response {
    let req = format!("{method} {path} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n");
    raw(addr, req.as_bytes())
}

/// `GET path` on `addr`.
pub(crate) fn get(addr: SocketAddr, path: &str) -> Response {
    request(addr, "GET", path)
}

/// A scrape's values by metric name and sorted labels.
pub(crate) type Scraped = std::collections::HashMap<(String, Vec<(String, String)>), f64>;

/// A monitor named `name` serving every route on a free loopback port.
pub(crate) fn started(name: &str) -> (streamcert_serve::Monitor, streamcert_serve::Server) {
    let monitor = streamcert_serve::Monitor::new(streamcert_serve::MonitorOptions::named(name));
    let addr: SocketAddr = "127.0.0.1:0".parse().unwrap();
    let server = monitor.serve(addr, streamcert_serve::Routes::All).unwrap();
    (monitor, server)
}

/// A scrape, parsed by `prometheus-parse`: value by (name, sorted labels).
pub(crate) fn parse(text: &str) -> Scraped {
    let lines = text.lines().map(|l| Ok(l.to_string()));
    let scrape = prometheus_parse::Scrape::parse(lines).unwrap();
    scrape
        .samples
        .into_iter()
        .map(|s| {
            let v = match s.value {
                prometheus_parse::Value::Counter(v)
                | prometheus_parse::Value::Gauge(v)
                | prometheus_parse::Value::Untyped(v) => v,
                other => panic!("{} is not a number: {other:?}", s.metric),
            };
            let mut labels: Vec<(String, String)> =
                s.labels.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
            labels.sort();
            ((s.metric, labels), v)
        })
        .collect()
}

/// The value of series `name` with `labels` in a scrape (a missing one fails the test).
pub(crate) fn value(m: &Scraped, name: &str, labels: &[(&str, &str)]) -> f64 {
    let mut l: Vec<(String, String)> =
        labels.iter().map(|(k, v)| ((*k).to_string(), (*v).to_string())).collect();
    l.sort();
    *m.get(&(name.to_string(), l.clone())).unwrap_or_else(|| panic!("no {name} {l:?}"))
}
