//! The rate of order `n` at a look: the exact test at one margin (`robustly_stable`, what a
//! certificate's decision needs; `robustly_stable_rational`, the same test without its
//! floating-point filter) and the margin itself by bisection (`robust_margin`, what its
//! evidence reports), for the closed loops of the order-2 and order-3 studies.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use streamcert::certificate::{
    Ellipsoid, robust_margin, robustly_stable, robustly_stable_rational,
};

/// `(name, β̂, Σ, r²)`: the order-2 study's loop `(s + 0.25)(s + 0.95)` with a look's
/// covariance, and three lags `(s + 0.5)(s + 1)(s + 2)`.
fn cases() -> Vec<(&'static str, Vec<f64>, Vec<f64>, f64)> {
    vec![
        ("order_2", vec![1.2, 0.2375], vec![1.1e-3, -2.0e-4, -2.0e-4, 3.0e-4], 14.88),
        (
            "order_3",
            vec![3.5, 3.5, 1.0],
            vec![4e-3, 1e-3, 2e-4, 1e-3, 3e-3, 5e-4, 2e-4, 5e-4, 1e-3],
            17.0,
        ),
    ]
}

/// The margin by bisection on the rational test alone over `[−R − 1, R]`.
fn exact_bisection(e: &Ellipsoid<'_>, tolerance: f64) -> Option<f64> {
    let n = e.centre.len();
    let r = e.radius2.sqrt();
    let bound = 1.0
        + (0..n)
            .map(|i| e.centre[i].abs() + r * e.covariance[i * n + i].sqrt())
            .fold(0.0, f64::max);
    let (mut lo, mut hi) = (-bound - 1.0, bound);
    if !robustly_stable_rational(e, lo) {
        return None;
    }
    while hi - lo > tolerance {
        let mid = 0.5 * (lo + hi);
        if robustly_stable_rational(e, mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(lo)
}

fn order_n(c: &mut Criterion) {
    let mut group = c.benchmark_group("order_n");
    for (name, centre, cov, r2) in cases() {
        let e = Ellipsoid { centre: &centre, covariance: &cov, radius2: r2 };
        group.bench_function(format!("robustly_stable/{name}"), |b| {
            b.iter(|| robustly_stable(black_box(&e), black_box(0.05)));
        });
        group.bench_function(format!("robustly_stable_rational/{name}"), |b| {
            b.iter(|| robustly_stable_rational(black_box(&e), black_box(0.05)));
        });
        group.bench_function(format!("robust_margin/{name}"), |b| {
            b.iter(|| robust_margin(black_box(&e), 1e-12));
        });
        // Baseline: the same margin by bisection on the rational test alone, from Cauchy's
        // bracket (what `robust_margin` does without its floating-point guide and filter).
        group.bench_function(format!("exact_bisection/{name}"), |b| {
            b.iter(|| exact_bisection(black_box(&e), 1e-12));
        });
    }
    group.finish();
}

criterion_group!(benches, order_n);
criterion_main!(benches);
