//! Where the command line's time goes, per row, beside baselines in the same groups: reading
//! (`SampleReader` against the csv crate's `ByteRecord` reader it replaced, and against
//! splitting lines and parsing every field with `str::parse`), writing (`EvidenceWriter`
//! against the csv crate's serde writer it replaced, and one `format!` per field, as the
//! command line did first), and a whole `certify` run from bytes in memory to a sink.
//!
//! Run: `cargo bench --bench cli`. Throughput is in rows (elements) per second.

use std::fmt::Write as _;
use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::certificate::{Certifier, Evidence};
use streamcert_pipeline::certify::{self, Options};
use streamcert_pipeline::config;
use streamcert_pipeline::input::{Sample, SampleReader};
use streamcert_pipeline::output::{EvidenceWriter, Flush, Format, Header};

const ROWS: usize = 20_000;

/// A file shaped like `streamcert simulate g5` output: 12 columns, the default configuration's
/// `t`, `y_b`, `u_b` among them.
fn g5_like_csv() -> String {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut s = String::from("t,y_a,u_a,y_b,u_b,x1,x2,x3,x4,x5,beta_true_a,beta_true_b\n");
    let mut x = [0.0f64; 5];
    for k in 0..ROWS {
        for v in &mut x {
            *v = 0.97 * *v + 0.1 * (rng.random::<f64>() - 0.5);
        }
        let (ua, ub) =
            (-3.5 * x[0] + rng.random::<f64>() - 0.5, -4.0 * x[3] + rng.random::<f64>() - 0.5);
        let _ = writeln!(
            s,
            "{},{},{ua},{},{ub},{},{},{},{},{},3.5,5",
            k as f64 * 0.02,
            x[0],
            x[3],
            x[0],
            x[1],
            x[2],
            x[3],
            x[4]
        );
    }
    s
}

fn options() -> Options {
    Options::default()
}

fn read(c: &mut Criterion) {
    let cfg = config::parse(&config::g5_node_b(), "g5 node b").expect("default configuration");
    let text = g5_like_csv();
    let mut group = c.benchmark_group("cli_read");
    group.throughput(Throughput::Elements(ROWS as u64));
    group.bench_function("sample_reader", |b| {
        b.iter(|| {
            let mut reader =
                SampleReader::new(text.as_bytes(), "bench", &cfg.columns).expect("header");
            let mut s = Sample::default();
            let mut sum = 0.0;
            while let Some(r) = reader.next_into(&mut s) {
                r.expect("row");
                sum += s.t + s.y[0] + s.u[0];
            }
            black_box(sum)
        });
    });
    group.bench_function("csv_crate_byte_record", |b| {
        b.iter(|| {
            let mut reader = csv::ReaderBuilder::new().flexible(true).from_reader(text.as_bytes());
            let mut record = csv::ByteRecord::new();
            let mut sum = 0.0;
            while reader.read_byte_record(&mut record).expect("row") {
                for i in [0, 3, 4] {
                    let raw = record.get(i).expect("field").trim_ascii();
                    sum += fast_float2::parse::<f64, _>(raw).expect("number");
                }
            }
            black_box(sum)
        });
    });
    group.bench_function("naive_split_and_parse_all", |b| {
        b.iter(|| {
            let mut sum = 0.0;
            for line in text.lines().skip(1) {
                let v: Vec<f64> =
                    line.split(',').map(|f| f.trim().parse().expect("number")).collect();
                sum += v[0] + v[3] + v[4];
            }
            black_box(sum)
        });
    });
    group.finish();
}

fn write(c: &mut Criterion) {
    let cfg = config::parse(&config::g5_node_b(), "g5 node b").expect("default configuration");
    let mut cert = Certifier::new(cfg.certifier.clone()).expect("valid");
    let text = g5_like_csv();
    let mut reader = SampleReader::new(text.as_bytes(), "bench", &cfg.columns).expect("header");
    let (mut s, mut evidence) = (Sample::default(), Vec::<Evidence>::with_capacity(ROWS));
    while let Some(r) = reader.next_into(&mut s) {
        r.expect("row");
        evidence.push(cert.push(s.t, &s.y, &s.u).expect("sample"));
    }
    let mut group = c.benchmark_group("cli_write");
    group.throughput(Throughput::Elements(ROWS as u64));
    group.bench_function("evidence_writer_csv", |b| {
        b.iter(|| {
            let mut w = EvidenceWriter::new(
                std::io::sink(),
                Format::Csv,
                Header::Write,
                Flush::Buffered,
                Vec::new(),
            )
            .expect("header");
            for e in &evidence {
                w.write(e).expect("write");
            }
            w.flush().expect("flush");
        });
    });
    group.bench_function("csv_crate_serde", |b| {
        b.iter(|| {
            let mut w = csv::Writer::from_writer(std::io::sink());
            for e in &evidence {
                w.serialize(streamcert::certificate::EvidenceRow::from(e)).expect("write");
            }
            w.flush().expect("flush");
        });
    });
    group.bench_function("naive_format_per_field", |b| {
        let num = |v: Option<f64>| v.map_or(String::new(), |x| format!("{x}"));
        let reason = |r: Option<streamcert::certificate::NotCertified>| {
            r.map_or(String::new(), |r| r.to_string().replace(',', ";"))
        };
        b.iter(|| {
            let mut out = std::io::sink();
            for e in &evidence {
                let amb = e.ambiguity;
                let line = format!(
                    "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
                    e.t,
                    num(e.beta_hat()),
                    num(e.rho()),
                    num(amb.map(|a| a.eps)),
                    num(amb.and_then(|a| a.kurtosis)),
                    num(amb.map(|a| a.spike_fraction)),
                    num(e.gaussian.value),
                    num(e.wasserstein.value),
                    u8::from(e.gaussian.open),
                    u8::from(e.wasserstein.open),
                    reason(e.gaussian.reason),
                    reason(e.wasserstein.reason),
                    num(e.calibrated.radius),
                    num(e.calibrated.value),
                    e.calibrated_window.map_or(String::new(), |w| w.to_string()),
                    u8::from(e.calibrated.open),
                    reason(e.calibrated.reason)
                );
                std::io::Write::write_all(&mut out, line.as_bytes()).expect("write");
            }
        });
    });
    group.finish();
}

fn whole_run(c: &mut Criterion) {
    let cfg = config::parse(&config::g5_node_b(), "g5 node b").expect("default configuration");
    let text = g5_like_csv();
    let mut group = c.benchmark_group("cli_certify");
    group.throughput(Throughput::Elements(ROWS as u64));
    for (name, flush) in
        [("file_two_threads", Flush::Buffered), ("live_row_by_row", Flush::EachRow)]
    {
        let opts = Options { flush, ..options() };
        group.bench_function(name, |b| {
            b.iter(|| {
                let mut out = std::io::sink();
                certify::run(&cfg, text.as_bytes(), "bench", &mut out, &opts).expect("run")
            });
        });
    }
    group.finish();
}

criterion_group!(benches, read, write, whole_run);
criterion_main!(benches);
