//! The curvature test of order `n`: least squares on the widened rows (a dense solve as the
//! oracle), and what it sees: a stiffening spring against the same loop without it.

use nalgebra::DMatrix;
use rand::{Rng as _, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::super::*;
use super::{noisy_record, prbs, times};

/// The curvature test's coefficients are least squares on the rows widened by the square and
/// the cube of the output's excursion, weighted as the output regressor `k = n` (a dense solve
/// as the oracle); its covariance is the larger fit's block.
#[test]
fn the_curvature_test_is_the_widened_least_squares() {
    for n in [2, 3] {
        let (t, y, u) = noisy_record(n, 3000, 21 + n as u64);
        let cfg = OrderNConfig::new(LoopModel::of_order(n).unwrap(), 1, 3000, 20);
        let record = OrderNRecord::new(&cfg, &t, &y, &u).unwrap();
        let (span, d) = (cfg.span(), cfg.width());
        let rows = 100..record.rows();
        let test = record.curvature_test(rows.clone()).unwrap();
        assert_eq!(test.rows, rows.len());
        // The output regressor k = n is `Σ_i wy_n,i y_i` with `y` relative to the first sample:
        // its weights, recovered from the rows of y and y², are applied to the powers.
        let excursion: Vec<f64> = y.iter().map(|v| v - y[0]).collect();
        let x = DMatrix::from_fn(test.rows, d + 2, |i, j| {
            let r = rows.start + i;
            if j < d {
                return record.phi[r * d + j];
            }
            let w = record.wy(r, n - 1);
            let power = if j == d { 2 } else { 3 };
            w.iter().zip(&excursion[r..=r + span]).map(|(wi, e)| wi * e.powi(power)).sum()
        });
        // The regressor k = n itself is that weighting of the excursion.
        for i in [0, test.rows / 2, test.rows - 1] {
            let r = rows.start + i;
            let w = record.wy(r, n - 1);
            let direct: f64 = w.iter().zip(&excursion[r..=r + span]).map(|(a, b)| a * b).sum();
            let stored = record.phi[r * d + n - 1];
            assert!((direct - stored).abs() <= 1e-9 * stored.abs().max(1e-6), "row {r}");
        }
        let z = DMatrix::from_fn(test.rows, 1, |i, _| record.z[rows.start + i]);
        let xt = x.transpose();
        let theta = (&xt * &x).lu().solve(&(&xt * z)).unwrap();
        for (k, g) in test.coefficients.iter().enumerate() {
            let want = theta[d + k];
            assert!(
                (g - want).abs() <= 1e-6 * want.abs().max(1e-6),
                "n {n}: g_{k} {g} against {want}"
            );
        }
        assert_eq!(test.covariance.len(), 4);
        assert!(test.covariance[0] > 0.0 && test.covariance[3] > 0.0);
        assert!(test.statistic().is_finite() && test.statistic() >= 0.0);
        assert!(matches!(
            record.curvature_test(0..d + 2),
            Err(RegressionError::InsufficientData { .. })
        ));
    }
}

/// `ÿ + 1.2 ẏ + y + s y³ = u + 0.1` from rest under the input `u` on the times `t` (RK4,
/// ten steps per sample interval, the input held), with sensor noise `σ = 0.01`.
fn spring(s: f64, t: &[f64], u: &[f64], rng: &mut ChaCha8Rng) -> Vec<f64> {
    let f = |x: [f64; 2], uk: f64| [x[1], -1.2 * x[1] - x[0] - s * x[0].powi(3) + uk + 0.1];
    let mut x = [0.0f64; 2];
    let mut y = Vec::with_capacity(t.len());
    for k in 0..t.len() {
        y.push(x[0] + 0.01 * (2.0 * rng.random::<f64>() - 1.0) * 3f64.sqrt());
        if k + 1 < t.len() {
            let dt = (t[k + 1] - t[k]) / 10.0;
            for _ in 0..10 {
                let add = |a: [f64; 2], b: [f64; 2], c: f64| [a[0] + c * b[0], a[1] + c * b[1]];
                let k1 = f(x, u[k]);
                let k2 = f(add(x, k1, dt / 2.0), u[k]);
                let k3 = f(add(x, k2, dt / 2.0), u[k]);
                let k4 = f(add(x, k3, dt), u[k]);
                for i in 0..2 {
                    x[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
                }
            }
        }
    }
    y
}

/// A spring that stiffens (`s = 0.5`, the slope `1 + 3 s y²` from 1 to about 2.5 over the
/// excursions a ±2 input drives) gives a statistic far above every one of the linear loop's
/// on the same inputs and noise (`s = 0`), which stays of the order of its two degrees of
/// freedom.
#[test]
fn the_curvature_test_sees_a_stiffening_spring() {
    let cfg = OrderNConfig::new(LoopModel::of_order(2).unwrap(), 1, 4000, 50);
    let mut linear = Vec::new();
    let mut bent = Vec::new();
    for seed in 0..12 {
        let mut rng = ChaCha8Rng::seed_from_u64(300 + seed);
        let t = times(4000, 0.01, 0.0, &mut rng);
        let u: Vec<f64> = prbs(&t, 1.0, &mut rng).iter().map(|v| 2.0 * v).collect();
        for (s, out) in [(0.0, &mut linear), (0.5, &mut bent)] {
            let mut noise = ChaCha8Rng::seed_from_u64(900 + seed);
            let y = spring(s, &t, &u, &mut noise);
            let record = OrderNRecord::new(&cfg, &t, &y, &u).unwrap();
            out.push(record.curvature_test(0..record.rows()).unwrap().statistic());
        }
    }
    linear.sort_by(f64::total_cmp);
    let (median, max) = (linear[linear.len() / 2], linear[linear.len() - 1]);
    let weakest = bent.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(median < 6.0, "the linear loop's median statistic {median} ({linear:?})");
    assert!(weakest > 10.0 * max.max(1.0), "stiffening {bent:?} against linear {linear:?}");
}
