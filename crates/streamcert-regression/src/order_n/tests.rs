//! Oracles for the order-`n` rows and estimators: the sliding-integral kernels written out, the
//! first-order sliding regression, exact simulation, and the batch fit for the streaming one.

use nalgebra::DMatrix;
use rand::{Rng as _, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::rows::RowWeights;
use super::*;
use crate::{InputIntegral, Model, RegressionConfig, SlidingRegression};

mod curvature;
mod window;

/// Sample times from `0` with mean step `dt`, each step jittered by up to `±jitter · dt`.
fn times(len: usize, dt: f64, jitter: f64, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let mut t = vec![0.0; len];
    for k in 1..len {
        t[k] = t[k - 1] + dt * (1.0 + jitter * (2.0 * rng.random::<f64>() - 1.0));
    }
    t
}

/// A held ±1 input redrawn every `hold` seconds on average (random durations).
fn prbs(t: &[f64], hold: f64, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let (mut next, mut level) = (0.0, 1.0);
    t.iter()
        .map(|&tk| {
            if tk >= next {
                level = if rng.random::<f64>() < 0.5 { -1.0 } else { 1.0 };
                next = tk + hold * (0.5 + rng.random::<f64>());
            }
            level
        })
        .collect()
}

/// Exact zero-order-hold simulation of `y⁽ⁿ⁾ + Σ a_k y⁽ⁿ⁻ᵏ⁾ = Σ b_k u⁽ⁿ⁻ᵏ⁾ + c` from rest in the
/// observable canonical form (`ẋ_k = −a_k x_1 + x_{k+1} + b_k u`, `ẋ_n` also `+ c`, `y = x_1`),
/// stepping with the matrix exponential of the system augmented by `u` and `1`.
fn simulate(a: &[f64], b: &[f64], c: f64, t: &[f64], u: &[f64]) -> Vec<f64> {
    let n = a.len();
    let mut big = DMatrix::<f64>::zeros(n + 2, n + 2);
    for k in 0..n {
        big[(k, 0)] = -a[k];
        if k + 1 < n {
            big[(k, k + 1)] = 1.0;
        }
        big[(k, n)] = b[k];
    }
    big[(n - 1, n + 1)] = c;
    let mut x = nalgebra::DVector::<f64>::zeros(n + 2);
    let mut y = Vec::with_capacity(t.len());
    for k in 0..t.len() {
        y.push(x[0]);
        if k + 1 < t.len() {
            x[n] = u[k];
            x[n + 1] = 1.0;
            x = (&big * (t[k + 1] - t[k])).exp() * x;
        }
    }
    y
}

/// `J^k Δ^{n−k}`'s kernel `K_k(v) = Σ_j (−1)^j C(n, j) (v − jL)_+^{k−1} / (k − 1)!`.
fn kernel(n: usize, k: usize, l: f64, v: f64) -> f64 {
    let binom =
        |n: usize, j: usize| (0..j).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64);
    let fact = (1..k).product::<usize>() as f64;
    (0..=n)
        .map(|j| {
            let x = v - j as f64 * l;
            let p = if x > 0.0 { x.powi(k as i32 - 1) } else { 0.0 };
            (if j % 2 == 0 { 1.0 } else { -1.0 }) * binom(n, j) * p / fact
        })
        .sum()
}

/// On equal spacing every weight is the sliding-integral kernel of the design's table: the row
/// of samples `t_0..t_{nh}` is `Δⁿ y`, `−∫ K_k(v) y(t − v) dv` and `∫ K_k(v) u(t − v) dv`,
/// with `y` the interpolant and `u` held, integrated here by two-point Gauss–Legendre on each
/// sample interval (exact for the cubic integrands, and never evaluated at a knot).
#[test]
fn rows_on_equal_spacing_are_the_sliding_integrals() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for n in 1..=3 {
        for h in [1usize, 3, 5] {
            let shape = Shape { n, m: 2, h };
            let (span, d, dt) = (shape.span(), shape.width(), 0.05);
            let l = h as f64 * dt;
            let t: Vec<f64> = (0..=span).map(|i| 3.0 + i as f64 * dt).collect();
            let y: Vec<f64> = (0..=span).map(|_| rng.random::<f64>() - 0.5).collect();
            let u: Vec<f64> =
                (0..(span + 1) * 2).map(|_| 2.0 * rng.random::<f64>() - 1.0).collect();
            let mut w = RowWeights::new(shape);
            w.fill(shape, &t);
            let mut row = vec![0.0; d];
            let z = w.apply(shape, &y, &u, &mut row);
            let binom = |j: usize| (0..j).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64);
            let dn: f64 = (0..=n)
                .map(|j| (if j % 2 == 0 { 1.0 } else { -1.0 }) * binom(j) * y[span - j * h])
                .sum();
            assert!((z - dn).abs() < 1e-12, "n {n} h {h}: {z} {dn}");
            let g = [0.5 - 0.5 / 3f64.sqrt(), 0.5 + 0.5 / 3f64.sqrt()];
            for k in 1..=n {
                let (mut iy, mut iu) = (0.0, [0.0; 2]);
                // v = t_end − x runs over the sample intervals, newest first.
                for i in 0..span {
                    let (lo, hi) = (t[i], t[i + 1]);
                    for x in g.map(|g| lo + g * (hi - lo)) {
                        let kv = kernel(n, k, l, t[span] - x) * 0.5 * dt;
                        let yx = y[i] + (y[i + 1] - y[i]) * (x - lo) / dt;
                        iy += kv * yx;
                        iu[0] += kv * u[i * 2];
                        iu[1] += kv * u[i * 2 + 1];
                    }
                }
                assert!((row[k - 1] + iy).abs() < 1e-12, "n {n} h {h} k {k}: {} {iy}", row[k - 1]);
                assert!((row[n + k - 1] - iu[0]).abs() < 1e-12, "n {n} h {h} k {k}");
                assert!((row[2 * n + k - 1] - iu[1]).abs() < 1e-12, "n {n} h {h} k {k}");
            }
            assert!((row[d - 1] - l.powi(n as i32)).abs() < 1e-15);
        }
    }
}

/// For `n = 1` the row is the first-order sliding regression's column on irregular times:
/// `z = ΔY`, `φ^y = −∫y`, `φ^u = ∫u` (zero-order hold), the intercept `τ`.
#[test]
fn the_first_order_row_is_the_sliding_regressions_column() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let h = 4;
    let mut cfg = RegressionConfig::new(1, 1, 30, h, 0.0);
    (cfg.model, cfg.input_integral) = (Model::Affine, InputIntegral::ZeroOrderHold);
    let mut first = SlidingRegression::new(cfg).unwrap();
    let mut order1 =
        OrderNRegression::new(OrderNConfig::new(LoopModel::FirstOrder, 1, 30, h)).unwrap();
    let t = times(300, 0.02, 0.5, &mut rng);
    for (k, &tk) in t.iter().enumerate() {
        let (y, u) = (40.0 + rng.random::<f64>(), [3.0 * rng.random::<f64>() - 7.0]);
        first.push(tk, &[y], &u).unwrap();
        order1.push(tk, y, &u).unwrap();
        assert_eq!(first.newest_column().is_some(), order1.newest_row().is_some(), "{k}");
        if let (Some((zc, dy)), Some((row, z))) = (first.newest_column(), order1.newest_row()) {
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * (1.0 + a.abs());
            assert!(close(z, dy[0]), "{k}: {z} {}", dy[0]);
            assert!(close(-row[0], zc[0]), "{k}: {} {}", row[0], zc[0]);
            assert!(close(row[1], zc[1]), "{k}: {} {}", row[1], zc[1]);
            assert!(close(row[2], first.newest_column_span().unwrap()), "{k}");
        }
    }
}

/// A plant of order `n` (`a`, `b`, `c`) simulated exactly with the given jitter and step, and
/// the batch fit's largest relative coefficient error.
fn recovery_error(a: &[f64], b: &[f64], dt: f64, jitter: f64, hold: f64, seed: u64) -> f64 {
    let (n, c, duration, l) = (a.len(), 0.1, 60.0, 0.2);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let t = times((duration / dt) as usize, dt, jitter, &mut rng);
    let u = prbs(&t, hold, &mut rng);
    let y = simulate(a, b, c, &t, &u);
    let h = (l / dt).round() as usize;
    let cfg = OrderNConfig::new(LoopModel::of_order(n).unwrap(), 1, 10, h);
    let fit = OrderNFit::fit(&cfg, &t, &y, &u).unwrap();
    let truth: Vec<f64> = a.iter().chain(b).copied().chain([c]).collect();
    let scale = truth.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    fit.theta().iter().zip(&truth).map(|(e, t)| (e - t).abs() / scale).fold(0.0, f64::max)
}

/// Noise-free, the batch fit recovers `(a, b, c)` of plants of order 2 and 3 on regular and
/// on jittered (±50 %) times, and its error is the interpolant's `O(dt²)`: halving the step
/// divides it by about four. (The plants have no zero on a pole: `(s + 1)(s + 0.5)(s + 2)`
/// over `0.5 s + 2`; a cancelling zero would make the plant one of lower order, which the
/// regression of order 3 cannot identify.)
#[test]
fn noise_free_fits_recover_the_plant_at_second_order_in_the_step() {
    let plants: [(&[f64], &[f64]); 2] =
        [(&[1.2, 1.0], &[0.5, 1.0]), (&[3.5, 3.5, 1.0], &[0.0, 0.5, 2.0])];
    for (a, b) in plants {
        for jitter in [0.0, 0.5] {
            let coarse = recovery_error(a, b, 0.01, jitter, 0.3, 3);
            let fine = recovery_error(a, b, 0.005, jitter, 0.3, 3);
            assert!(coarse < 1e-3, "order {} jitter {jitter}: {coarse:.2e}", a.len());
            let ratio = coarse / fine;
            assert!(
                (2.5..6.0).contains(&ratio),
                "order {} jitter {jitter}: {coarse:.2e} / {fine:.2e}",
                a.len()
            );
        }
    }
}

/// A noisy closed-loop record for the streaming and gap tests.
fn noisy_record(n: usize, len: usize, seed: u64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let a: &[f64] = if n == 2 { &[1.2, 1.0] } else { &[3.5, 3.5, 1.0] };
    let b: &[f64] = if n == 2 { &[0.0, 1.0] } else { &[0.0, 0.5, 2.0] };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let t = times(len, 0.01, 0.3, &mut rng);
    let u = prbs(&t, 0.7, &mut rng);
    let mut y = simulate(a, b, 0.1, &t, &u);
    for v in &mut y {
        *v += 0.01 * (rng.random::<f64>() - 0.5) + 5.0;
    }
    (t, y, u)
}

/// The streaming estimator's rows are the direct rows and its window's estimate is the batch
/// fit over the same rows, over a long run with jittered times, noise and an offset.
#[test]
fn the_streaming_estimate_is_the_batch_fit_over_a_long_run() {
    for n in 2..=3 {
        let (t, y, u) = noisy_record(n, 40_000, 5 + n as u64);
        let mut cfg = OrderNConfig::new(LoopModel::of_order(n).unwrap(), 1, 900, 15);
        cfg.refresh_period = 700;
        let shape = cfg.shape();
        let (span, d) = (shape.span(), shape.width());
        let mut reg = OrderNRegression::new(cfg).unwrap();
        let mut weights = RowWeights::new(shape);
        let mut row = vec![0.0; d];
        let (y0, u0) = (y[0], u[0]);
        for k in 0..t.len() {
            reg.push(t[k], y[k], &u[k..=k]).unwrap();
            if k >= span && k % 97 == 0 {
                let s = k - span..k + 1;
                weights.fill(shape, &t[s.clone()]);
                let ys: Vec<f64> = y[s.clone()].iter().map(|v| v - y0).collect();
                let us: Vec<f64> = u[s].iter().map(|v| v - u0).collect();
                let z = weights.apply(shape, &ys, &us, &mut row);
                let (srow, sz) = reg.newest_row().unwrap();
                let size = row.iter().fold(z.abs(), |m, v| m.max(v.abs()));
                for (a, b) in srow.iter().zip(&row).chain([(&sz, &z)]) {
                    assert!((a - b).abs() <= 1e-10 * size, "n {n} k {k}: {a} {b}");
                }
            }
            if k > 5000 && k % 4999 == 0 {
                let first = k + 1 - (cfg.window + span);
                let fit =
                    OrderNFit::fit(&cfg, &t[first..=k], &y[first..=k], &u[first..=k]).unwrap();
                assert_eq!(fit.rows(), cfg.window);
                let streaming = reg.estimate().unwrap().to_vec();
                for (a, b) in streaming.iter().zip(fit.theta()).take(d - 1) {
                    assert!((a - b).abs() <= 1e-7 * (1.0 + b.abs()), "n {n} k {k}: {a} {b}");
                }
                // The intercepts are taken about different origins (the stream's first sample,
                // the slice's); in the plant's coordinates they agree.
                assert!((streaming[d - 1] - fit.theta()[d - 1]).abs() < 1e-5, "n {n} k {k}");
            }
        }
    }
}

/// A gap (`reset`) restarts the rows: nothing until `n h + 1` new samples and `min_rows` rows,
/// then the batch fit of the samples after the gap alone.
#[test]
fn a_gap_restarts_the_rows() {
    let n = 2;
    let (t, y, u) = noisy_record(n, 6000, 21);
    let mut cfg = OrderNConfig::new(LoopModel::of_order(n).unwrap(), 1, 1000, 20);
    cfg.min_rows = 500;
    let span = cfg.span();
    let mut reg = OrderNRegression::new(cfg).unwrap();
    for k in 0..3000 {
        reg.push(t[k], y[k], &u[k..=k]).unwrap();
    }
    assert!(reg.estimate().is_ok());
    reg.reset();
    assert_eq!(reg.rows(), 0);
    for k in 3000..3000 + span + cfg.min_rows - 1 {
        reg.push(t[k], y[k], &u[k..=k]).unwrap();
        assert!(matches!(reg.estimate(), Err(RegressionError::InsufficientData { .. })), "{k}");
    }
    let last = 3000 + span + cfg.min_rows - 1;
    reg.push(t[last], y[last], &u[last..=last]).unwrap();
    assert_eq!(reg.rows(), cfg.min_rows);
    let fit = OrderNFit::fit(&cfg, &t[3000..=last], &y[3000..=last], &u[3000..=last]).unwrap();
    let streaming = reg.estimate().unwrap().to_vec();
    for (a, b) in streaming.iter().zip(fit.theta()) {
        assert!((a - b).abs() <= 1e-6 * (1.0 + b.abs()), "{a} {b}");
    }
}

/// Bad samples are refused with the reason and leave the state as it was; records too short or
/// without excitation are refused by the batch fit.
#[test]
fn bad_data_is_refused_not_absorbed() {
    let cfg = OrderNConfig::new(LoopModel::of_order(2).unwrap(), 1, 50, 3);
    let mut reg = OrderNRegression::new(cfg).unwrap();
    for k in 0..40 {
        reg.push(k as f64 * 0.1, (k as f64).sin(), &[(k % 3) as f64]).unwrap();
    }
    let before = reg.clone();
    assert!(matches!(
        reg.push(f64::NAN, 0.0, &[0.0]),
        Err(RegressionError::NonFinite { field: "t", .. })
    ));
    assert!(matches!(
        reg.push(5.0, f64::INFINITY, &[0.0]),
        Err(RegressionError::NonFinite { field: "y", .. })
    ));
    assert!(matches!(
        reg.push(5.0, 0.0, &[f64::NAN]),
        Err(RegressionError::NonFinite { field: "u", .. })
    ));
    assert!(matches!(reg.push(3.9, 0.0, &[0.0]), Err(RegressionError::NonIncreasingTime { .. })));
    assert!(matches!(
        reg.push(5.0, 0.0, &[0.0, 1.0]),
        Err(RegressionError::DimensionMismatch { .. })
    ));
    assert_eq!(reg, before);

    let t: Vec<f64> = (0..200).map(|k| k as f64 * 0.01).collect();
    let short = &t[..cfg.span() + cfg.width()];
    let zeros = vec![0.0; short.len()];
    assert!(matches!(
        OrderNFit::fit(&cfg, short, &zeros, &zeros),
        Err(RegressionError::InsufficientData { .. })
    ));
    let y: Vec<f64> = t.iter().map(|x| x.sin()).collect();
    let held = vec![1.0; t.len()];
    assert!(matches!(OrderNFit::fit(&cfg, &t, &y, &held), Err(RegressionError::NotIdentified(_))));
    let mut back = t.clone();
    back[100] = back[99];
    assert!(matches!(
        OrderNFit::fit(&cfg, &back, &y, &y),
        Err(RegressionError::NonIncreasingTime { .. })
    ));
    let mut bad = OrderNConfig::new(LoopModel::of_order(3).unwrap(), 1, 5, 3);
    assert!(matches!(
        OrderNRegression::new(bad),
        Err(RegressionError::InvalidConfig { field: "window", .. })
    ));
    bad.window = 20;
    bad.min_rows = 20;
    bad.refresh_period = 20;
    bad.horizon = 0;
    assert!(matches!(bad.validate(), Err(RegressionError::InvalidConfig { field: "horizon", .. })));
}

proptest::proptest! {
    /// For every loop model: the streaming row (sliding moments) is the direct row (weights on
    /// the span's samples) after every sample, on random irregular samples, through a reset.
    #[test]
    fn every_models_streaming_row_is_its_direct_row(
        steps in proptest::collection::vec((0.001f64..0.05, -5.0f64..5.0, -5.0f64..5.0), 30..150),
        h in 1usize..5,
        reset_at in 0usize..150,
    ) {
        for model in LoopModel::ALL {
            let cfg = OrderNConfig::new(model, 1, 12, h);
            let shape = cfg.shape();
            let (span, d) = (shape.span(), shape.width());
            let mut reg = OrderNRegression::new(cfg).unwrap();
            let mut weights = RowWeights::new(shape);
            let mut row = vec![0.0; d];
            let (mut t, mut hist) = (0.0, Vec::new());
            for (k, &(dt, y, u)) in steps.iter().enumerate() {
                if k == reset_at {
                    reg.reset();
                    hist.clear();
                }
                t += dt;
                reg.push(t, y, &[u]).unwrap();
                hist.push((t, y - reg.origin()[0], u - reg.origin()[1]));
                let ready = hist.len() > span;
                proptest::prop_assert_eq!(reg.newest_row().is_some(), ready);
                if ready {
                    let s = &hist[hist.len() - span - 1..];
                    let ts: Vec<f64> = s.iter().map(|x| x.0).collect();
                    let ys: Vec<f64> = s.iter().map(|x| x.1).collect();
                    let us: Vec<f64> = s.iter().map(|x| x.2).collect();
                    weights.fill(shape, &ts);
                    let z = weights.apply(shape, &ys, &us, &mut row);
                    let (srow, sz) = reg.newest_row().unwrap();
                    let size = ys.iter().chain(&us).fold(1.0f64, |m, v| m.max(v.abs()));
                    for (a, b) in srow.iter().zip(&row).chain([(&sz, &z)]) {
                        proptest::prop_assert!((a - b).abs() <= 1e-9 * size, "{:?} k {}: {} {}", model, k, a, b);
                    }
                }
            }
        }
    }
}

/// The past-row test's coefficients are least squares on the rows widened by the past row's
/// regressand and output regressors (a dense solve as the oracle), its covariance is the
/// larger fit's block, and its rows are those with a past row.
#[test]
fn the_past_row_test_is_the_widened_least_squares() {
    for n in [2, 3] {
        let (t, y, u) = noisy_record(n, 3000, 11 + n as u64);
        let cfg = OrderNConfig::new(LoopModel::of_order(n).unwrap(), 1, 3000, 20);
        let record = OrderNRecord::new(&cfg, &t, &y, &u).unwrap();
        let (span, d) = (cfg.span(), cfg.width());
        let rows = 100..record.rows();
        let test = record.past_row_test(rows.clone()).unwrap();
        let first = rows.start.max(span + 1);
        assert_eq!(test.rows, rows.end - first);
        let wide = d + 1 + n;
        let x = DMatrix::from_fn(test.rows, wide, |i, j| {
            let r = first + i;
            match j {
                j if j < d => record.phi[r * d + j],
                j if j == d => record.z[r - span - 1],
                j => record.phi[(r - span - 1) * d + j - d - 1],
            }
        });
        let z = DMatrix::from_fn(test.rows, 1, |i, _| record.z[first + i]);
        let xt = x.transpose();
        let theta = (&xt * &x).lu().solve(&(&xt * z)).unwrap();
        for (k, g) in test.coefficients.iter().enumerate() {
            let want = theta[d + k];
            assert!(
                (g - want).abs() <= 1e-6 * want.abs().max(1e-3),
                "n {n}: γ_{k} {g} against {want}"
            );
        }
        assert_eq!(test.covariance.len(), (n + 1) * (n + 1));
        assert!((0..=n).all(|k| test.covariance[k * (n + 2)] > 0.0));
        assert!(test.statistic().is_finite() && test.statistic() >= 0.0);
        // Too few rows for the larger fit: refused, typed.
        assert!(matches!(
            record.past_row_test(0..span + 1 + d + 1),
            Err(RegressionError::InsufficientData { .. })
        ));
    }
}
