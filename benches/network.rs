//! The live network certifier per sample, beside the same certifiers driven directly (the
//! floor the network layer adds to), and one epoch's composition, dense against sparse.
//!
//! Run: `cargo bench --bench network`.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::certificate::{Certifier, CertifierConfig};
use streamcert::compose::{Network, SparseOptions, certify_sparse, network_rate};
use streamcert::network::{NetworkCertifier, NetworkConfig, SubsystemSpec, perron_sensitivity};
use streamcert::regression::RegressionConfig;

fn local() -> CertifierConfig {
    CertifierConfig::new(RegressionConfig::new(1, 1, 150, 5, 1e-4), vec![-1.0], 0.2, 0.05, 10)
}

/// A random sparse coupling graph: about `degree` incoming couplings per subsystem.
fn graph(n: usize, degree: usize, rng: &mut ChaCha8Rng) -> Vec<(usize, usize, f64)> {
    let mut edges = Vec::with_capacity(n * degree);
    for i in 0..n {
        for _ in 0..degree {
            let j = rng.random_range(0..n);
            if j != i {
                edges.push((i, j, rng.random_range(0.01..0.1)));
            }
        }
    }
    edges
}

fn network_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("network_step");
    let dt = 1e-3;
    for n in [1_000usize, 10_000] {
        let mut rng = ChaCha8Rng::seed_from_u64(n as u64);
        let samples: Vec<f64> = (0..4096).map(|_| rng.random::<f64>() - 0.5).collect();
        let specs = (0..n).map(|i| SubsystemSpec::new(&format!("s{i}"), local())).collect();
        let mut cfg = NetworkConfig::new(specs, graph(n, 3, &mut rng), 1.0);
        cfg.stale_after = 10.0;
        let mut net = NetworkCertifier::new(cfg).expect("valid");
        let mut direct: Vec<Certifier> =
            (0..n).map(|_| Certifier::new(local()).expect("valid")).collect();
        // Warm every window up (M + h samples each).
        let (mut k, mut step) = (0usize, 0u64);
        for _ in 0..160 {
            step += 1;
            for i in 0..n {
                let (y, u) = (samples[k % 4096], samples[(k + 1) % 4096]);
                k += 1;
                net.push(i, step as f64 * dt, &[y], &[u], |r| {
                    black_box(r.rate);
                })
                .expect("sample");
                direct[i].push(step as f64 * dt, &[y], &[u]).expect("sample");
            }
        }
        let (mut i, mut t) = (n, step as f64 * dt);
        group.bench_function(BenchmarkId::new("network_push", n), |b| {
            b.iter(|| {
                if i == n {
                    (i, t) = (0, t + dt);
                }
                let (y, u) = (samples[k % 4096], samples[(k + 1) % 4096]);
                k += 1;
                let ev = net
                    .push(i, black_box(t), &[y], &[u], |r| {
                        black_box(r.rate);
                    })
                    .expect("sample");
                i += 1;
                black_box(ev.gaussian.value)
            });
        });
        let (mut i, mut t) = (n, step as f64 * dt);
        group.bench_function(BenchmarkId::new("certifiers_directly", n), |b| {
            b.iter(|| {
                if i == n {
                    (i, t) = (0, t + dt);
                }
                let (y, u) = (samples[k % 4096], samples[(k + 1) % 4096]);
                k += 1;
                let ev = direct[i].push(black_box(t), &[y], &[u]).expect("sample");
                i += 1;
                black_box(ev.gaussian.value)
            });
        });
    }
    group.finish();
}

fn compose_epoch(c: &mut Criterion) {
    let mut group = c.benchmark_group("compose_epoch");
    group.sample_size(10);
    for n in [100usize, 1_000] {
        let mut rng = ChaCha8Rng::seed_from_u64(7 + n as u64);
        let rates: Vec<f64> = (0..n).map(|_| rng.random_range(0.5..2.0)).collect();
        let net = Network::new(rates, &graph(n, 3, &mut rng)).expect("network");
        group.bench_function(BenchmarkId::new("dense_network_rate", n), |b| {
            b.iter(|| black_box(network_rate(&net).expect("rate").rate));
        });
        group.bench_function(BenchmarkId::new("sparse_and_sensitivity", n), |b| {
            b.iter(|| {
                let c = certify_sparse(&net, &SparseOptions::default()).expect("rate");
                let s = perron_sensitivity(&net, 1000, 1e-12);
                black_box((c.rate, s.limiting_subsystem))
            });
        });
    }
    // A dense coupling graph (every pair coupled): the certified sparse path on N² gains.
    let n = 1_000usize;
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let rates: Vec<f64> = (0..n).map(|_| rng.random_range(0.5..2.0)).collect();
    let dense: Vec<(usize, usize, f64)> = (0..n)
        .flat_map(|i| {
            (0..n)
                .filter(move |&j| j != i)
                .map(move |j| (i, j, 1e-4 * (1 + (i * 7 + j * 13) % 5) as f64))
        })
        .collect();
    let net = Network::new(rates, &dense).expect("network");
    group.bench_function(BenchmarkId::new("sparse_path_on_all_pairs", n), |b| {
        b.iter(|| black_box(certify_sparse(&net, &SparseOptions::default()).expect("rate").rate));
    });
    group.finish();
}

criterion_group!(benches, network_step, compose_epoch);
criterion_main!(benches);
