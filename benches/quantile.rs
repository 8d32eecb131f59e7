//! Cost of the Student-t quantile a calibrated look takes (`t_quantile`, two per look when
//! `β̂` is below the margin), beside statrs' `StudentsT::inverse_cdf` (the naive baseline) in
//! the same group.
//!
//! The inputs are what the calibrated certificate asks for: fractional degrees of freedom
//! `ν ∈ [6, 26]` (effective blocks minus `d`) and the risks `δ / (k (k + 1))` of looks
//! `k = 1, 2, …` at `δ = 0.01`, 64 pairs cycled.
//!
//! Run: `cargo bench --bench quantile`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use statrs::distribution::{ContinuousCDF, StudentsT};
use streamcert::certificate::{look_risk, t_quantile};

fn inputs() -> Vec<(f64, f64)> {
    (0..64u64)
        .map(|i| {
            let nu = 6.0 + 20.0 * ((i * 37 % 64) as f64 / 64.0) + 0.297;
            (nu, look_risk(0.01, 1.0, i % 16 + 1))
        })
        .collect()
}

fn quantile(c: &mut Criterion) {
    let mut group = c.benchmark_group("t_quantile");
    let pairs = inputs();
    let mut k = 0usize;
    group.bench_function("halley", |b| {
        b.iter(|| {
            k = (k + 1) % pairs.len();
            let (nu, risk) = pairs[k];
            black_box(t_quantile(black_box(nu), black_box(risk)))
        });
    });
    group.bench_function("naive_statrs_inverse_cdf", |b| {
        b.iter(|| {
            k = (k + 1) % pairs.len();
            let (nu, risk) = pairs[k];
            let dist = StudentsT::new(0.0, 1.0, black_box(nu)).expect("valid");
            black_box(-dist.inverse_cdf(black_box(risk)))
        });
    });
    group.finish();
}

criterion_group!(benches, quantile);
criterion_main!(benches);
