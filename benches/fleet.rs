//! The fleet path: `N` subsystems (`p = m = 1`, Gaussian certificate) at 1 kHz each, one second
//! of samples per iteration pushed with `NetworkCertifier::push_batch` in 10 ms batches over 1
//! and 2 threads, the network composed at the 1 s epoch (sparse: `N` above `dense_limit`).
//! The baseline in the same run is the same network fed sample by sample with
//! `NetworkCertifier::push` (round robin over the subsystems, one thread). At `N = 10⁴` the
//! same path also runs with the default local certificate (the calibrated certificate with its
//! guards, `Calibration::new(0.01)`) over 2 threads, after three seconds of data have filled
//! its windows (`fleet/push_batch_default_2t`).
//!
//! Run: `cargo bench --bench fleet` (throughput in samples per second).

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::certificate::{Calibration, CertifierConfig};
use streamcert::network::{NetworkCertifier, NetworkConfig, SampleBatch, SubsystemSpec};
use streamcert::regression::RegressionConfig;

const RATE: usize = 1000; // samples per second per subsystem
const CHUNK: usize = 10; // samples per subsystem per batch (10 ms)

fn network(n: usize, seed: u64, calibrated: bool) -> NetworkCertifier {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut local =
        CertifierConfig::new(RegressionConfig::new(1, 1, 150, 5, 1e-4), vec![-1.0], 0.2, 0.05, 10);
    if calibrated {
        local.calibration = Some(Calibration::new(0.01));
    }
    let specs = (0..n).map(|i| SubsystemSpec::new(&format!("s{i}"), local.clone())).collect();
    let mut edges = Vec::with_capacity(3 * n);
    for i in 0..n {
        for _ in 0..3 {
            let j = rng.random_range(0..n);
            if j != i {
                edges.push((i, j, rng.random_range(0.01..0.1)));
            }
        }
    }
    let mut cfg = NetworkConfig::new(specs, edges, 1.0);
    cfg.stale_after = 10.0;
    NetworkCertifier::new(cfg).expect("valid")
}

/// One second of samples from step `step` on, in batches of `CHUNK` steps.
fn one_second(
    net: &mut NetworkCertifier,
    batch: &mut SampleBatch,
    values: &[f64],
    step: &mut u64,
    threads: usize,
) -> usize {
    let n = net.len();
    let mut epochs = 0;
    for _ in 0..RATE / CHUNK {
        batch.clear();
        for _ in 0..CHUNK {
            *step += 1;
            let t = *step as f64 / RATE as f64;
            for i in 0..n {
                let k = (*step as usize * 7919 + i * 31) % (values.len() - 1);
                batch.push(i, t, &values[k..=k], &values[k + 1..k + 2]);
            }
        }
        net.push_batch(batch, threads, |r| {
            epochs += 1;
            black_box(r.rate);
        })
        .expect("batch");
    }
    epochs
}

fn fleet(c: &mut Criterion) {
    let mut group = c.benchmark_group("fleet");
    group.sample_size(10);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let values: Vec<f64> = (0..4099).map(|_| rng.random::<f64>() - 0.5).collect();
    for n in [1_000usize, 10_000, 100_000] {
        group.throughput(Throughput::Elements((n * RATE) as u64));
        for threads in [1usize, 2] {
            let mut net = network(n, n as u64, false);
            let mut batch = SampleBatch::new();
            let mut step = 0u64;
            one_second(&mut net, &mut batch, &values, &mut step, threads); // warm the windows
            group.bench_function(BenchmarkId::new(format!("push_batch_{threads}t"), n), |b| {
                b.iter(|| one_second(&mut net, &mut batch, &values, &mut step, threads));
            });
        }
        if n == 10_000 {
            let mut net = network(n, n as u64, true);
            let mut batch = SampleBatch::new();
            let mut step = 0u64;
            for _ in 0..3 {
                one_second(&mut net, &mut batch, &values, &mut step, 2);
            }
            group.bench_function(BenchmarkId::new("push_batch_default_2t", n), |b| {
                b.iter(|| one_second(&mut net, &mut batch, &values, &mut step, 2));
            });
        }
        if n <= 10_000 {
            let mut net = network(n, n as u64, false);
            let mut step = 0u64;
            let push_second = |net: &mut NetworkCertifier, step: &mut u64| {
                for _ in 0..RATE {
                    *step += 1;
                    let t = *step as f64 / RATE as f64;
                    for i in 0..n {
                        let k = (*step as usize * 7919 + i * 31) % (values.len() - 1);
                        net.push(i, t, &values[k..=k], &values[k + 1..k + 2], |r| {
                            black_box(r.rate);
                        })
                        .expect("sample");
                    }
                }
            };
            push_second(&mut net, &mut step);
            group.bench_function(BenchmarkId::new("push_one_by_one", n), |b| {
                b.iter(|| push_second(&mut net, &mut step));
            });
        }
    }
    group.finish();
}

criterion_group!(benches, fleet);
criterion_main!(benches);
