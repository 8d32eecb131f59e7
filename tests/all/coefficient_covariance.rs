//! The coefficient covariance of a window (what the nonlinear certificate's bound over a
//! region and the guards' Wald tests use) against a batch recompute with nalgebra, unbatched
//! and over batches of blocks.

use nalgebra::{DMatrix, DVector};
use streamcert::regression::{InstrumentedWindows, RateMap, Solve, WindowEstimate};

/// 200 columns with p = 1, d = 3 (two features and one input) from a logistic map:
/// `(z, Δy)` with `Δy = 0.8 z₀ − 0.3 z₁ + 0.5 z₂ + noise`.
fn logistic_columns() -> Vec<([f64; 3], f64)> {
    let mut x = 0.37f64;
    let mut step = || {
        x = (3.91 * x * (1.0 - x)).clamp(1e-6, 1.0 - 1e-6);
        x - 0.5
    };
    (0..200)
        .map(|_| {
            let z = [step(), step(), step()];
            (z, 0.8 * z[0] - 0.3 * z[1] + 0.5 * z[2] + 0.1 * step())
        })
        .collect()
}

#[test]
fn the_coefficient_covariance_equals_a_batch_recompute() {
    // Random columns with p = 1, d = 3 (two features and one input), J = 2.
    let mut w = InstrumentedWindows::with_regressors(1, 3, 2, 1, 2, &[20, 40]).expect("valid");
    let cols = logistic_columns();
    for (z, dy) in &cols {
        w.push_column(z, &[*dy]);
    }
    let mut est = WindowEstimate::with_regressors(1, 3, 2);
    let t = [1.0, 0.4, -1.2];
    w.estimate(
        1,
        Solve { ridge: 1e-9, rate: RateMap::SymmetricPart(&t), min_pivot_ratio: 1e-12 },
        &mut est,
    );
    assert!(est.ready);
    let mut cov = vec![0.0; 9];
    assert!(w.coefficient_covariance(1, &mut est, &mut cov));
    // tᵀ Ω_θ t is the score variance of `estimate` for the same direction.
    let quad: f64 = (0..3).map(|a| (0..3).map(|b| t[a] * cov[a * 3 + b] * t[b]).sum::<f64>()).sum();
    assert!((quad / est.score_cov[0] - 1.0).abs() < 1e-9, "{quad} vs {}", est.score_cov[0]);
    // Batch: the window's 40 instrumented columns (the newest), blocks of h = 2.
    // Usable from column 5 (the instrument ring holds J h + L + 1 = 6 columns); 97 complete
    // blocks of 2 end at column 198, so the window is columns 159..=198.
    let usable: Vec<_> = cols.iter().enumerate().skip(159).take(40).collect();
    let inst = |q: usize| DVector::from_iterator(6, (1..=2).flat_map(|j| cols[q - j * 2 - 1].0));
    let (mut nm, mut cw, mut hm) =
        (DMatrix::zeros(3, 6), DMatrix::zeros(1, 6), DMatrix::zeros(6, 6));
    for &(q, (z, dy)) in &usable {
        let wq = inst(q);
        nm += DVector::from_row_slice(z) * wq.transpose();
        cw += DMatrix::from_element(1, 1, *dy) * wq.transpose();
        hm += &wq * wq.transpose();
    }
    // The ridge `λ = 10⁻⁹` relative to each diagonal entry.
    let ridged = |mut m: DMatrix<f64>| {
        for i in 0..m.nrows() {
            m[(i, i)] *= 1.0 + 1e-9;
        }
        m
    };
    let hinv = ridged(hm).try_inverse().expect("invertible");
    let a = ridged(&nm * &hinv * nm.transpose());
    let ainv = a.clone().try_inverse().expect("invertible");
    let theta = &cw * &hinv * nm.transpose() * &ainv;
    for i in 0..3 {
        assert!((theta[i] - est.theta[i]).abs() < 1e-8 * (1.0 + theta[i].abs()));
    }
    let mut omega = DMatrix::zeros(3, 3);
    for block in usable.chunks(2) {
        let (mut bn, mut bcw) = (DMatrix::zeros(3, 6), DMatrix::zeros(1, 6));
        for &(q, (z, dy)) in block {
            let wq = inst(q);
            bn += DVector::from_row_slice(z) * wq.transpose();
            bcw += DMatrix::from_element(1, 1, *dy) * wq.transpose();
        }
        // The block's delete-one-block change (the second stage without it, the first
        // stage held): Θ̂ − (Cw − Cw_b) Q (A − N_b Q)⁻¹, Q = (H + λ diag H)⁻¹ Nᵀ.
        let q = &hinv * nm.transpose();
        let rest = (&a - &bn * &q).try_inverse().expect("invertible");
        let g = (&theta - (&cw - bcw) * &q * rest).transpose();
        omega += &g * g.transpose();
    }
    let hf = 2.0f64;
    omega *= 3.0 * hf * hf / (2.0 * hf * hf + 1.0);
    for i in 0..9 {
        assert!(
            (omega[i] - cov[i]).abs() < 1e-8 * (1.0 + omega[i].abs()),
            "{i}: {} vs {}",
            omega[i],
            cov[i]
        );
    }
}

#[test]
fn the_coefficient_covariance_follows_the_batches_of_the_score_covariance() {
    // As above, with batches of three blocks (window 1: 20 blocks of h = 2, so batches of
    // 2, 3, …, 3): the image of Ω_θ under t is still the score variance of `estimate`, and
    // both differ from the unbatched ones.
    let build = |batch: usize| {
        let w = InstrumentedWindows::with_regressors(1, 3, 2, 1, 2, &[20, 40]).expect("valid");
        w.with_batch(batch).expect("valid batch")
    };
    let (mut w1, mut w3) = (build(1), build(3));
    for (z, dy) in logistic_columns() {
        w1.push_column(&z, &[dy]);
        w3.push_column(&z, &[dy]);
    }
    let t = [1.0, 0.4, -1.2];
    let mut scores = Vec::new();
    for w in [&w1, &w3] {
        let mut est = WindowEstimate::with_regressors(1, 3, 2);
        w.estimate(
            1,
            Solve { ridge: 1e-9, rate: RateMap::SymmetricPart(&t), min_pivot_ratio: 1e-12 },
            &mut est,
        );
        assert!(est.ready);
        assert_eq!(est.batches, 20usize.div_ceil(w.batch()));
        let mut cov = vec![0.0; 9];
        assert!(w.coefficient_covariance(1, &mut est, &mut cov));
        let quad: f64 =
            (0..3).map(|a| (0..3).map(|b| t[a] * cov[a * 3 + b] * t[b]).sum::<f64>()).sum();
        assert!((quad / est.score_cov[0] - 1.0).abs() < 1e-9, "{quad} vs {}", est.score_cov[0]);
        scores.push(est.score_cov[0]);
    }
    assert!((scores[0] / scores[1] - 1.0).abs() > 1e-3, "{scores:?}");
    // A batch that leaves the shortest window (10 blocks) p + m = 3 batches or fewer.
    let w = InstrumentedWindows::with_regressors(1, 3, 2, 1, 2, &[20, 40]).expect("valid");
    assert!(w.with_batch(4).is_err());
}
