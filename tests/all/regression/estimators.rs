//! The estimators on known linear systems: the ordinary estimate converges with strong dither,
//! the instrumented estimator removes the noise bias, and a `p = 3, m = 2` system is recovered.

use streamcert::dynamics::{LinearScenario, Process};
use streamcert::regression::{
    EstimateStatus, Estimator, InputIntegral, RegressionConfig, SlidingRegression,
};

use crate::support::{run as run_scenario, scalar};

/// Push a simulated trajectory; return the final window's `(J_obs, B_obs)` for `p = m = 1`.
fn scalar_estimate(stream: &LinearScenario, estimator: Estimator, seed: u64) -> (f64, f64) {
    let traj = run_scenario(stream, seed);
    let cfg = RegressionConfig {
        estimator,
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(1, 1, traj.len() - 20, 5, 1e-8)
    };
    let mut reg = SlidingRegression::new(cfg).expect("valid");
    for k in 0..traj.len() {
        reg.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid sample");
    }
    let est = reg.estimate();
    assert_eq!(est.status, EstimateStatus::Ready);
    (est.j_obs(0, 0), est.b_obs(0, 0))
}

#[test]
fn scalar_estimate_converges_with_strong_dither() {
    // ẏ = −1 y + 2 u + 0.02 dW, PRBS dither of amplitude 1 held 0.2 s, no feedback.
    let stream = LinearScenario {
        a: vec![-1.0],
        b: vec![2.0],
        n: 1,
        m: 1,
        noise: Process::Gaussian { sigma: 0.02 },
        k_explore: vec![0.0],
        dither: 1.0,
        dither_hold: 0.2,
        dt: 0.01,
        steps: 4000,
        noise_gain: None,
        sensor_noise: 0.0,
        switch: None,
    };
    for seed in 0..5 {
        let (a, b) = scalar_estimate(&stream, Estimator::Ordinary, seed);
        // Euler discretisation with ZOH input: the integral relation holds to O(dt).
        assert!((a + 1.0).abs() < 0.05 && (b - 2.0).abs() < 0.1, "seed {seed}: a {a}, b {b}");
    }
}

#[test]
fn instrumented_estimator_removes_the_noise_bias() {
    const K_CANDIDATE: f64 = -1.0;
    // ẏ = −1 y + u + 0.5 dW, exploration u = −1 y + small PRBS: the noise dominates the output.
    let stream = LinearScenario {
        dither_hold: 0.5,
        steps: 30_000,
        ..scalar(-1.0, -1.0, Process::Gaussian { sigma: 0.5 }, 0.05)
    };
    let seeds = 40u64;
    let (mut ols, mut iv) = (Vec::new(), Vec::new());
    for seed in 0..seeds {
        let (a, b) = scalar_estimate(&stream, Estimator::Ordinary, seed);
        ols.push(-(a + b * K_CANDIDATE));
        let (a, b) = scalar_estimate(&stream, Estimator::Instrumented, seed);
        iv.push(-(a + b * K_CANDIDATE));
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let se = |v: &[f64]| {
        let mu = mean(v);
        (v.iter().map(|x| (x - mu).powi(2)).sum::<f64>() / (v.len() - 1) as f64 / v.len() as f64)
            .sqrt()
    };
    // True closed-loop rate under K = −1: 2. The ordinary estimate is biased toward 0 by far
    // more than its standard error; the instrumented mean is within 4 standard errors of 2.
    let (mo, mi, si) = (mean(&ols), mean(&iv), se(&iv));
    assert!(mo < 2.0 - 0.3 && mo < 2.0 - 10.0 * se(&ols), "ordinary mean rate {mo}");
    assert!((mi - 2.0).abs() < 4.0 * si + 0.05, "instrumented mean rate {mi} ± {si}");
}

#[test]
fn recovers_a_three_output_two_input_system() {
    let a = vec![-1.0, 0.3, 0.0, -0.2, -1.5, 0.4, 0.1, 0.0, -0.8];
    let b = vec![1.0, 0.0, 0.0, 1.0, 0.5, -0.5];
    let stream = LinearScenario {
        a: a.clone(),
        b: b.clone(),
        n: 3,
        m: 2,
        noise: Process::Gaussian { sigma: 0.01 },
        k_explore: vec![0.0; 6],
        dither: 1.0,
        dither_hold: 0.1,
        dt: 0.005,
        steps: 20_000,
        noise_gain: None,
        sensor_noise: 0.0,
        switch: None,
    };
    let traj = run_scenario(&stream, 8);
    let cfg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(3, 2, 5000, 4, 1e-9)
    };
    let mut reg = SlidingRegression::new(cfg).expect("valid");
    for k in 0..traj.len() {
        reg.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid sample");
    }
    let est = reg.estimate();
    assert_eq!(est.status, EstimateStatus::Ready);
    for i in 0..3 {
        for j in 0..3 {
            assert!(
                (est.j_obs(i, j) - a[i * 3 + j]).abs() < 0.05,
                "J[{i},{j}] = {}",
                est.j_obs(i, j)
            );
        }
        for j in 0..2 {
            assert!(
                (est.b_obs(i, j) - b[i * 2 + j]).abs() < 0.05,
                "B[{i},{j}] = {}",
                est.b_obs(i, j)
            );
        }
    }
}
