//! What watching a run costs it: a whole `certify` of 20 000 G5 rows with the default
//! configuration, row by row (the live path, every row flushed) to a sink, without a
//! watcher (baseline), with the `streamcert-serve` watcher (metrics, status document,
//! verdict messages to no sink), and with the watcher while its server answers 100 clients
//! that each poll every 500 ms (what 100 open status pages do), half of them the page's
//! document, half the metrics. The file path (three threads in batches) with and without
//! the watcher too.
//!
//! Run: `cargo bench --bench serve`. Throughput is in rows (elements) per second.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use streamcert_pipeline::certify::{self, Options};
use streamcert_pipeline::config::{self, Config};
use streamcert_pipeline::input::SampleReader;
use streamcert_serve::{Monitor, MonitorOptions, Routes};

#[path = "support/g5.rs"]
mod support;

const ROWS: usize = 20_000;

/// One row-by-row run of `csv`, watched by `watch`.
fn live_run(cfg: &Config, csv: &str, watch: &mut dyn streamcert_pipeline::watch::Watch) {
    let mut reader = SampleReader::new(csv.as_bytes(), "g5.csv", &cfg.columns).expect("header");
    let mut sink = std::io::sink();
    certify::run_source_watched(cfg, &mut reader, "g5.csv", &mut sink, &Options::default(), watch)
        .expect("run");
}

/// `GET path` on `addr`, the whole response read; whether it was a 200.
fn get(addr: SocketAddr, path: &str) -> bool {
    let Ok(mut s) = TcpStream::connect(addr) else { return false };
    let req = format!("GET {path} HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n");
    let mut text = String::new();
    s.write_all(req.as_bytes()).is_ok()
        && s.read_to_string(&mut text).is_ok()
        && text.starts_with("HTTP/1.1 200")
}

fn serve(c: &mut Criterion) {
    let csv = support::g5_csv(ROWS);
    let cfg = config::parse(&config::g5_node_b(), "g5 node b").expect("configuration");
    let mut group = c.benchmark_group("serve_rows");
    group.throughput(Throughput::Elements(ROWS as u64));
    group.sample_size(20);
    group.measurement_time(Duration::from_secs(20));
    group.bench_function("live_unwatched", |b| {
        b.iter(|| live_run(&cfg, &csv, &mut streamcert_pipeline::watch::NoWatch));
    });
    group.bench_function("live_watched", |b| {
        b.iter(|| {
            let monitor = Monitor::new(MonitorOptions::named("bench"));
            let mut watch = monitor.certify(&cfg.certifier, &cfg.columns.outputs, Vec::new());
            live_run(&cfg, &csv, &mut watch);
        });
    });
    let monitor = Monitor::new(MonitorOptions::named("bench"));
    let server =
        monitor.serve("127.0.0.1:0".parse().expect("address"), Routes::All).expect("serve");
    let (addr, stop, answered) =
        (server.addr(), Arc::new(AtomicBool::new(false)), Arc::new(AtomicU64::new(0)));
    let clients: Vec<_> = (0..100)
        .map(|i| {
            let (stop, answered) = (Arc::clone(&stop), Arc::clone(&answered));
            std::thread::spawn(move || {
                // Spread over the 500 ms, as independent pages are.
                std::thread::sleep(Duration::from_millis(5 * i));
                while !stop.load(Ordering::Relaxed) {
                    let path = if i % 2 == 0 { "/api/status" } else { "/metrics" };
                    if get(addr, path) {
                        answered.fetch_add(1, Ordering::Relaxed);
                    }
                    std::thread::sleep(Duration::from_millis(500));
                }
            })
        })
        .collect();
    group.bench_function("live_watched_100_clients", |b| {
        b.iter(|| {
            let mut watch = monitor.certify(&cfg.certifier, &cfg.columns.outputs, Vec::new());
            live_run(&cfg, &csv, &mut watch);
        });
    });
    stop.store(true, Ordering::Relaxed);
    clients.into_iter().for_each(|c| c.join().expect("client"));
    assert!(answered.load(Ordering::Relaxed) > 100, "the clients were answered");
    drop(server);
    group.bench_function("file_unwatched", |b| {
        b.iter(|| {
            let mut sink = std::io::sink();
            certify::run(&cfg, csv.as_bytes(), "g5.csv", &mut sink, &Options::default())
                .expect("run")
        });
    });
    group.bench_function("file_watched", |b| {
        b.iter(|| {
            let monitor = Monitor::new(MonitorOptions::named("bench"));
            let mut watch = monitor.certify(&cfg.certifier, &cfg.columns.outputs, Vec::new());
            let mut sink = std::io::sink();
            let opts = Options::default();
            certify::run_watched(&cfg, csv.as_bytes(), "g5.csv", &mut sink, &opts, &mut watch)
                .expect("run")
        });
    });
    group.finish();
}

criterion_group!(benches, serve);
criterion_main!(benches);
