//! Per-value cost of the sliding kurtosis and spike update (the ambiguity radius inputs),
//! beside a naive two-pass recompute of the window in the same group.
//!
//! Run: `cargo bench --bench ambiguity`.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use streamcert::ambiguity::{AmbiguityConfig, AmbiguityRadius, SlidingKurtosis, SpikeScale};
use streamcert::dynamics::{Disturbance, DisturbanceConfig, Process};
use streamcert::experiments::regime_schedule;

fn stream(process: Process, n: usize) -> Vec<f64> {
    let mut d = Disturbance::new(DisturbanceConfig::stationary(process), 5).expect("valid");
    (0..n).map(|k| d.random(k as f64)).collect()
}

/// Naive baseline: keep the window in a ring and recompute mean, m2, m4 and the spike count
/// by two passes after every value.
struct Naive {
    buf: Vec<f64>,
    head: usize,
    len: usize,
}

impl Naive {
    fn push(&mut self, x: f64, threshold: f64) -> (f64, f64) {
        let n = self.buf.len();
        self.buf[self.head] = x;
        self.head = (self.head + 1) % n;
        self.len = (self.len + 1).min(n);
        let w = &self.buf[..self.len];
        let mean = w.iter().sum::<f64>() / self.len as f64;
        let (mut m2, mut m4, mut spikes) = (0.0, 0.0, 0usize);
        for &v in w {
            let d = (v - mean) * (v - mean);
            m2 += d;
            m4 += d * d;
            spikes += usize::from(v.abs() > threshold);
        }
        let n = self.len as f64;
        ((m4 / n) / (m2 / n).powi(2) - 3.0, spikes as f64 / n)
    }
}

fn kurtosis_and_spikes(c: &mut Criterion) {
    let mut group = c.benchmark_group("kurtosis_spike_update");
    let window = 150;
    // Experiment 1's Regime 3: Laplace 0.3 plus 4.5 to 7.5 σ0 spikes at 5.5 % per step.
    let spikes = regime_schedule().segments[2].process;
    for (name, process) in
        [("gaussian", Process::Gaussian { sigma: 0.08 }), ("laplace_spikes", spikes)]
    {
        let data = stream(process, 1 << 14);
        let mask = data.len() - 1;
        let id = format!("{name}_N{window}");
        let cfg = AmbiguityConfig {
            spike_scale: SpikeScale::Fixed { sigma0: 0.08 },
            ..AmbiguityConfig::paper(window)
        };
        let mut amb = AmbiguityRadius::new(cfg).expect("valid");
        let mut k = 0usize;
        // The update alone: moments and spike count absorb one value (ε is formed on read).
        group.bench_function(BenchmarkId::new("update", &id), |b| {
            b.iter(|| {
                k = (k + 1) & mask;
                amb.push(black_box(data[k])).expect("finite");
            });
        });
        black_box(amb.snapshot());
        let mut amb = AmbiguityRadius::new(cfg).expect("valid");
        // The update and reading `ε` (kurtosis, spike fraction, eq. eps_est) after every value.
        group.bench_function(BenchmarkId::new("incremental", &id), |b| {
            b.iter(|| {
                k = (k + 1) & mask;
                amb.push(black_box(data[k])).expect("finite");
                black_box(amb.snapshot().eps);
            });
        });
        let mut moments = SlidingKurtosis::new(window).expect("valid");
        group.bench_function(BenchmarkId::new("moments_only", &id), |b| {
            b.iter(|| {
                k = (k + 1) & mask;
                moments.push(black_box(data[k])).expect("finite");
                black_box(moments.excess_kurtosis());
            });
        });
        let mut naive = Naive { buf: vec![0.0; window], head: 0, len: 0 };
        group.bench_function(BenchmarkId::new("naive_two_pass", &id), |b| {
            b.iter(|| {
                k = (k + 1) & mask;
                black_box(naive.push(black_box(data[k]), 0.24));
            });
        });
    }
    group.finish();
}

criterion_group!(benches, kurtosis_and_spikes);
criterion_main!(benches);
