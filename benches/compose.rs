//! Network composition: dense `N = 1000`, sparse grid-like `N = 10⁵` and `10⁶`, and a sparse
//! network with random long-range edges. Naive baselines in the same groups: the dense
//! spectral abscissa by nalgebra's unblocked Schur eigenvalues (what one would write first),
//! and, for the sparse certificate, the dense path on a grid small enough for it.
//!
//! Run: `cargo bench --bench compose`.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::compose::{
    DenseMethod, DenseOptions, Network, SparseOptions, certify_sparse, network_rate,
    network_rate_with, symmetric_rate_at_least,
};

/// `side × side` grid, 4-neighbour coupling, rates in [2, 3], gains in [0, 0.4], plus
/// `long_range` random edges with gains in [0, 0.2].
fn grid(side: usize, long_range: usize, seed: u64) -> Network {
    let n = side * side;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let beta: Vec<f64> = (0..n).map(|_| 2.0 + rng.random::<f64>()).collect();
    let mut edges = Vec::with_capacity(4 * n + long_range);
    for r in 0..side {
        for c in 0..side {
            let i = r * side + c;
            let mut link =
                |j: usize, rng: &mut ChaCha8Rng| edges.push((i, j, 0.4 * rng.random::<f64>()));
            if r > 0 {
                link(i - side, &mut rng);
            }
            if r + 1 < side {
                link(i + side, &mut rng);
            }
            if c > 0 {
                link(i - 1, &mut rng);
            }
            if c + 1 < side {
                link(i + 1, &mut rng);
            }
        }
    }
    for _ in 0..long_range {
        let i = rng.random_range(0..n);
        let j = rng.random_range(0..n);
        if i != j {
            edges.push((i, j, 0.2 * rng.random::<f64>()));
        }
    }
    Network::new(beta, &edges).expect("valid")
}

fn dense(c: &mut Criterion) {
    let mut group = c.benchmark_group("compose_dense");
    group.sample_size(10);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let n = 1000;
    let beta: Vec<f64> = (0..n).map(|_| 5.0 + rng.random::<f64>()).collect();
    let mut edges = Vec::new();
    for i in 0..n {
        for j in 0..n {
            if i != j && rng.random::<f64>() < 0.05 {
                edges.push((i, j, 0.1 * rng.random::<f64>()));
            }
        }
    }
    let net = Network::new(beta, &edges).expect("valid");
    // The default path (Perron brackets) against the eigendecomposition it replaces, in the
    // same run; the Perron path must have closed its brackets for the comparison to hold.
    let fast = network_rate(&net).expect("solves");
    assert!(fast.converged && fast.method == DenseMethod::Perron, "{:?}", fast.method);
    group.bench_function(BenchmarkId::new("network_rate_perron", "N1000"), |b| {
        b.iter(|| black_box(network_rate(&net).expect("solves").rate));
    });
    let exact = DenseOptions { exact: true, ..DenseOptions::default() };
    group.bench_function(BenchmarkId::new("naive_network_rate_eigendecomposition", "N1000"), |b| {
        b.iter(|| black_box(network_rate_with(&net, &exact).expect("solves").rate));
    });
    group.bench_function(BenchmarkId::new("sparse_certificate", "N1000"), |b| {
        b.iter(|| black_box(certify_sparse(&net, &SparseOptions::default()).expect("valid").rate));
    });
    let g = nalgebra::DMatrix::from_row_slice(n, n, &net.dense_gain_matrix());
    group.bench_function(BenchmarkId::new("naive_nalgebra_abscissa_only", "N1000"), |b| {
        b.iter(|| black_box(g.complex_eigenvalues().iter().fold(f64::MIN, |a, z| a.max(z.re))));
    });
    group.finish();
}

fn sparse(c: &mut Criterion) {
    let mut group = c.benchmark_group("compose_sparse");
    group.sample_size(10);
    let small = grid(30, 0, 1);
    group.bench_function(BenchmarkId::new("certify_sparse", "grid_N900"), |b| {
        b.iter(|| {
            black_box(certify_sparse(&small, &SparseOptions::default()).expect("valid").rate)
        });
    });
    let exact = DenseOptions { exact: true, ..DenseOptions::default() };
    group.bench_function(BenchmarkId::new("naive_dense_network_rate", "grid_N900"), |b| {
        b.iter(|| black_box(network_rate_with(&small, &exact).expect("solves").rate));
    });
    for (name, side, long) in
        [("grid_N1e5", 317usize, 0usize), ("grid_N1e6", 1000, 0), ("long_range_N1e5", 317, 10_000)]
    {
        let net = grid(side, long, 2);
        group.bench_function(BenchmarkId::new("certify_sparse", name), |b| {
            b.iter(|| {
                black_box(certify_sparse(&net, &SparseOptions::default()).expect("valid").rate)
            });
        });
    }
    let net = grid(317, 0, 2);
    group.bench_function(BenchmarkId::new("one_sparse_cholesky", "grid_N1e5"), |b| {
        b.iter(|| black_box(symmetric_rate_at_least(&net, 0.5).expect("valid")));
    });
    group.finish();
}

criterion_group!(benches, dense, sparse);
criterion_main!(benches);
