//! `InstrumentedWindows::estimate_coefficients` (one block pass) against `estimate` followed
//! by `coefficient_covariance` (two passes): bit for bit, for one and two outputs, with and
//! without batches, on every window, through the ring's wrap.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::regression::{InstrumentedWindows, WindowEstimate};

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
                win.estimate(w, 1e-9, &t, 1e-12, &mut two);
                let two_ready = two.ready && win.coefficient_covariance(w, &mut two, &mut cov_two);
                let ready =
                    win.estimate_coefficients(w, 1e-9, &t, 1e-12, &mut fused, &mut cov_fused);
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
