//! The live path's rows per second beside the CSV path's, in the same run: a whole `certify`
//! of the same 20 000 G5-like rows with the default configuration, read from CSV bytes in
//! memory, and published one JSON row per message to the embedded broker on loopback and
//! read back through an MQTT subscription (publishing on another thread as it goes). Both go
//! through `certify::run_source`, row by row, every row flushed, to a sink.
//!
//! Run: `cargo bench --bench live`. Throughput is in rows (elements) per second. The
//! latency from publish to evidence row: `cargo run --release --example live_latency`.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use streamcert_live::MqttSource;
use streamcert_live::publish::{self, Layout, PublishOptions};
use streamcert_pipeline::CliError;
use streamcert_pipeline::certify::{self, Options};
use streamcert_pipeline::config;
use streamcert_pipeline::input::{Sample, SampleReader};
use streamcert_pipeline::source::{Next, Source, SourceReport};

#[path = "support/g5.rs"]
mod support;

const ROWS: usize = 20_000;

/// G5's node b through experiment 1's schedule, `ROWS` steps: the CSV text, its header and
/// rows.
fn g5() -> (String, Vec<String>, Vec<Vec<f64>>) {
    let text = support::g5_csv(ROWS);
    let mut lines = text.lines();
    let header = lines.next().expect("header").split(',').map(String::from).collect();
    let rows = lines.map(|l| l.split(',').map(|v| v.parse().expect("number")).collect()).collect();
    (text, header, rows)
}

/// A source that ends after `left` rows (the benchmark's end of stream).
struct Take<S> {
    inner: S,
    left: usize,
}

impl<S: Source> Source for Take<S> {
    fn next_into(&mut self, s: &mut Sample) -> Option<Result<Next, CliError>> {
        if self.left == 0 {
            return None;
        }
        let next = self.inner.next_into(s);
        if matches!(next, Some(Ok(Next::Row))) {
            self.left -= 1;
        }
        next
    }

    fn report(&self) -> Option<SourceReport> {
        self.inner.report()
    }
}

fn live(c: &mut Criterion) {
    let (csv, header, rows) = g5();
    let port = {
        let addr = streamcert_live::broker::free_loopback().expect("port");
        streamcert_live::broker::serve(addr).expect("broker");
        addr.port()
    };
    let base = config::g5_node_b();
    let file_cfg = config::parse(&base, "g5 node b").expect("configuration");
    let mut group = c.benchmark_group("live_rows");
    group.throughput(Throughput::Elements(ROWS as u64));
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(30));
    group.bench_function("csv", |b| {
        b.iter(|| {
            let mut reader =
                SampleReader::new(csv.as_bytes(), "g5.csv", &file_cfg.columns).expect("header");
            let mut sink = std::io::sink();
            certify::run_source(&file_cfg, &mut reader, "g5.csv", &mut sink, &Options::default())
                .expect("run")
        });
    });
    let run = AtomicU64::new(0);
    group.bench_function("mqtt_json_rows", |b| {
        b.iter(|| {
            // A topic and a session of its own per iteration.
            let n = run.fetch_add(1, Ordering::Relaxed);
            let topic = format!("bench/{n}");
            let text = format!(
                "{base}\n[source]\nkind = \"mqtt\"\nservers = [\"tcp://127.0.0.1:{port}\"]\n\
                 client_id = \"bench-{n}\"\ntopics = [\"{topic}\"]\npersistent_session = false\n"
            );
            let cfg = config::parse(&text, "live").expect("configuration");
            let parsed = streamcert_live::parse(cfg.source.as_ref().expect("source"), &cfg.columns);
            let Ok(streamcert_live::SourceConfig::Mqtt(live)) = parsed else { panic!("mqtt") };
            let mut source = MqttSource::new(live, 1, false).expect("client");
            assert!(source.wait_subscribed(Duration::from_secs(10)));
            let server =
                streamcert_live::config::Server { host: "127.0.0.1".into(), port, tls: false };
            let opts = PublishOptions {
                server,
                topic,
                client_id: format!("bench-pub-{n}"),
                layout: Layout::Rows,
                pace: 0.0,
            };
            let (h, r) = (header.clone(), rows.clone());
            let sender = std::thread::spawn(move || publish::publish(&opts, &h, 0, r));
            let mut take = Take { inner: source, left: ROWS };
            let mut sink = std::io::sink();
            let s = certify::run_source(&cfg, &mut take, "mqtt", &mut sink, &Options::default())
                .expect("run");
            sender.join().expect("publisher").expect("published");
            s
        });
    });
    group.finish();
}

criterion_group!(benches, live);
criterion_main!(benches);
