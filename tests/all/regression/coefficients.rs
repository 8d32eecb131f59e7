//! `InstrumentedWindows::estimate_coefficients` (one block pass) against `estimate` followed
//! by `coefficient_covariance` (two passes): bit for bit, for one and two outputs, with and
//! without batches, on every window, through the ring's wrap.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::regression::{InstrumentedWindows, RateMap, Solve, WindowEstimate};

/// Every window's fused estimate equals the two calls' `Θ̂`, `Ω_θ`, effective number of
/// blocks and batch count exactly, at every block boundary of a stream that wraps the block
/// ring several times; its score covariance is zero; a window not yet full is not ready in
/// either.
#[test]
fn the_fused_pass_equals_the_estimate_and_the_coefficient_covariance_bit_for_bit() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for (p, m, intervals, batch) in [(1, 2, 1, 1), (1, 2, 1, 3), (2, 1, 2, 1), (2, 1, 2, 2)] {
        let d = p + m;
        let windows = [24usize, 48, 96];
        let mut win = InstrumentedWindows::new(p, m, 2, 1, intervals, &windows)
            .expect("valid")
            .with_batch(batch)
            .expect("valid batch");
        let (mut two, mut fused) =
            (WindowEstimate::new(p, m, intervals), WindowEstimate::new(p, m, intervals));
        let (mut cov_two, mut cov_fused) = (vec![0.0; (p * d).pow(2)], vec![0.0; (p * d).pow(2)]);
        // A direction `T = [I_p; K]` with a random gain.
        let mut t = vec![0.0; d * p];
        for j in 0..p {
            t[j * p + j] = 1.0;
        }
        for v in &mut t[p * p..] {
            *v = rng.random::<f64>() - 0.5;
        }
        let mut state = vec![0.0; p];
        let mut compared = 0;
        for _ in 0..600 {
            let u: Vec<f64> = (0..m).map(|_| rng.random::<f64>() * 2.0 - 1.0).collect();
            let mut z = state.clone();
            z.extend(&u);
            let dy: Vec<f64> = (0..p)
                .map(|i| -0.4 * state[i] + 0.3 * u[i % m] + 0.05 * (rng.random::<f64>() - 0.5))
                .collect();
            for (s, v) in state.iter_mut().zip(&dy) {
                *s += v;
            }
            if !win.push_column(&z, &dy) {
                continue;
            }
            for w in 0..windows.len() {
                win.estimate(
                    w,
                    Solve { ridge: 1e-9, rate: RateMap::SymmetricPart(&t), min_pivot_ratio: 1e-12 },
                    &mut two,
                );
                let two_ready = two.ready && win.coefficient_covariance(w, &mut two, &mut cov_two);
                let ready = win.estimate_coefficients(
                    w,
                    Solve { ridge: 1e-9, rate: RateMap::SymmetricPart(&t), min_pivot_ratio: 1e-12 },
                    &mut fused,
                    &mut cov_fused,
                );
                assert_eq!(ready, two_ready, "{p} {m} {batch} window {w}");
                assert_eq!(ready, fused.ready);
                assert_eq!(fused.batches, two.batches);
                assert_eq!(fused.columns, two.columns);
                if !ready {
                    assert!(!win.is_full(w), "a full window is ready");
                    continue;
                }
                compared += 1;
                assert_eq!(fused.theta, two.theta, "{p} {m} {batch} window {w}");
                assert_eq!(fused.effective_blocks.to_bits(), two.effective_blocks.to_bits());
                assert_eq!(cov_fused, cov_two, "{p} {m} {batch} window {w}");
                assert!(fused.score_cov.iter().all(|&v| v == 0.0));
                assert!(two.score_cov.iter().any(|&v| v != 0.0));
            }
        }
        assert!(compared > 300, "{compared} comparisons");
    }
}

/// Oracle: the delete-one-block jackknife recomputed with nalgebra. For `J = 1` the estimate
/// is `Θ̂ = Cw N⁻¹`; deleting block `j` gives `Θ̂_(j) = (Cw − Cw_j)(N − N_j)⁻¹`, and the score
/// covariance of `estimate` is `c_h Σ_j ((Θ̂ − Θ̂_(j)) T)²` (batches of one block, no ridge),
/// the coefficient covariance `c_h Σ_j vec(Θ̂ − Θ̂_(j)) vec(Θ̂ − Θ̂_(j))ᵀ`: both to `10⁻⁹`
/// relative, on a stream whose input rarely moves (a few blocks carry the information, the
/// case the leverage factor is for).
#[test]
fn the_score_variance_is_the_delete_one_block_jackknife() {
    use nalgebra::{DMatrix, RowDVector};
    let (h, lag, blocks) = (3usize, 1usize, 20usize);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut win = InstrumentedWindows::new(1, 2, h, lag, 1, &[h * blocks]).expect("valid");
    let mut est = WindowEstimate::new(1, 2, 1);
    let t = [1.0, 0.7, 0.0];
    let (mut zs, mut dys) = (Vec::new(), Vec::new());
    let (mut state, mut u) = (0.3, 1.0);
    let mut checked = 0;
    for q in 0..400usize {
        // The input flips rarely (a step test), the second regressor is the intercept's span.
        if rng.random::<f64>() < 0.02 {
            u = -u;
        }
        let z = [state, u, 1.0];
        let dy = -0.5 * state + 0.8 * u + 0.2 + 0.3 * (rng.random::<f64>() - 0.5);
        state += 0.1 * dy;
        zs.push(z);
        dys.push(dy);
        let done = win.push_column(&z, &[dy]);
        // The first instrumented column is `h + lag`; a window of whole blocks ends at `q`.
        let usable = (q + 1).saturating_sub(h + lag);
        if !done || usable < h * blocks {
            continue;
        }
        assert_eq!(usable % h, 0);
        win.estimate(
            0,
            Solve { ridge: 0.0, rate: RateMap::SymmetricPart(&t), min_pivot_ratio: 1e-12 },
            &mut est,
        );
        if !est.ready {
            continue;
        }
        let mut cov = vec![0.0; 9];
        assert!(win.coefficient_covariance(0, &mut est, &mut cov));
        let first = q + 1 - h * blocks;
        let sums = |skip: Option<usize>| {
            let (mut n, mut cw) = (DMatrix::<f64>::zeros(3, 3), RowDVector::<f64>::zeros(3));
            for c in first..=q {
                if skip.is_some_and(|j| (c - first) / h == j) {
                    continue;
                }
                let w = zs[c - h - lag];
                for a in 0..3 {
                    for b in 0..3 {
                        n[(a, b)] += zs[c][a] * w[b];
                    }
                    cw[a] += dys[c] * w[a];
                }
            }
            (n, cw)
        };
        let theta = |skip| {
            let (n, cw) = sums(skip);
            cw * n.try_inverse().expect("regular")
        };
        let full = theta(None);
        let ch = 3.0 * (h * h) as f64 / (2.0 * (h * h) as f64 + 1.0);
        let (mut var, mut cov_oracle) = (0.0, DMatrix::<f64>::zeros(3, 3));
        for j in 0..blocks {
            let change = &full - theta(Some(j));
            let s: f64 = (0..3).map(|a| change[a] * t[a]).sum();
            var += ch * s * s;
            cov_oracle += ch * change.transpose() * &change;
        }
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1e-12);
        assert!(close(est.score_cov[0], var), "q {q}: {} against {var}", est.score_cov[0]);
        for a in 0..3 {
            for b in 0..3 {
                assert!(close(cov[a * 3 + b], cov_oracle[(a, b)]), "q {q} ({a}, {b})");
            }
        }
        checked += 1;
    }
    assert!(checked > 30, "{checked} windows checked");
}
