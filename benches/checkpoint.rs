//! One calibrated certifier's sealed checkpoint: writing it (encode and seal) and restoring it
//! (check, decode, verify) in the binary encoding the command line writes (CBOR with the
//! sliding block rings rebuilt from the sample trail and the rest packed, version 7) against
//! the JSON export (version 4) of the same state in the same run, and the sizes (printed
//! once, before the timings), with the unpacked binary's (version 5: the JSON's payload
//! re-encoded in CBOR, every ring whole).
//!
//! The state: `examples/data/certify_b.toml` (G5's subsystem B, the default calibrated
//! certificate with every guard) after 20 000 steps of Experiment 1's data, seed 1 (the
//! data of `streamcert simulate g5 --experiment 1 --seed 1 --steps 20000`), so that every
//! window and the anchored window hold data.
//!
//! Also printed: the size of the same state under `horizon = "auto"` (the horizon ladder:
//! four calibrated certificates, `h = 1, 2, 5, 10`), an explicit choice.
//!
//! Run: `cargo bench --bench checkpoint`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use streamcert::certificate::{Certifier, Encoding, seal_value};
use streamcert::experiments::{Experiment, G5Dataset};

const ROWS: usize = 20_000;

/// `examples/data/certify_b.toml`, with `horizon` and `window` `"auto"` when `auto`.
fn certifier(auto: bool) -> Certifier {
    let mut toml = include_str!("../examples/data/certify_b.toml").to_string();
    if auto {
        toml = toml
            .replace("\nwindow = 150", "\nwindow = \"auto\"")
            .replace("horizon = 5", "horizon = \"auto\"");
    }
    let cfg = streamcert_pipeline::config::parse(&toml, "certify_b.toml").expect("valid");
    assert_eq!(cfg.certifier.ladder.is_some(), auto);
    let data = G5Dataset { steps: Some(ROWS), ..G5Dataset::defaults(Experiment::One) };
    let traj = data.run_seeded(1).expect("simulates");
    let mut cert = Certifier::new(cfg.certifier).expect("valid");
    // Subsystem B: the second output and input (`y_b`, `u_b` of `streamcert simulate g5`).
    for k in 0..traj.len() {
        let (y, u) = (traj.output(k)[1], traj.input(k)[1]);
        cert.push(traj.t[k], &[y], &[u]).expect("finite");
    }
    cert
}

fn checkpoint(c: &mut Criterion) {
    let auto = certifier(true).checkpoint().expect("encodes").len();
    let cert = certifier(false);
    let binary = cert.checkpoint().expect("encodes");
    let json = cert.checkpoint_json().expect("encodes");
    let state: serde_json::Value =
        serde_json::from_str(json.split_once('\n').expect("a header").1).expect("JSON");
    let unpacked = streamcert::certificate::encode(&state, Encoding::Binary).expect("encodes");
    eprintln!(
        "checkpoint of one certifier after {ROWS} rows: binary {} bytes, JSON {} bytes ({:.3}×), \
         unpacked binary payload {} bytes ({:.3}× the JSON)",
        binary.len(),
        json.len(),
        binary.len() as f64 / json.len() as f64,
        unpacked.len(),
        unpacked.len() as f64 / json.len() as f64
    );
    eprintln!(
        "the same state with horizon = \"auto\" (four horizons): binary {auto} bytes ({:.2}× the \
         single horizon's)",
        auto as f64 / binary.len() as f64
    );
    let mut group = c.benchmark_group("checkpoint");
    group.sample_size(20);
    for (name, encoding) in [("binary", Encoding::Binary), ("json", Encoding::Json)] {
        group.bench_function(format!("write_{name}"), |b| {
            b.iter(|| seal_value(black_box(&cert), encoding, cert.config()).expect("encodes"));
        });
    }
    group.bench_function("restore_binary", |b| {
        b.iter(|| Certifier::restore(black_box(&binary)).expect("restores"));
    });
    group.bench_function("restore_json", |b| {
        b.iter(|| Certifier::restore(black_box(&json)).expect("restores"));
    });
    group.finish();
}

criterion_group!(benches, checkpoint);
criterion_main!(benches);
