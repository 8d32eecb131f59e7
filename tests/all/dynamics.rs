//! streamcert-dynamics: Jacobians against finite differences, integrator order, disturbance
//! moments, determinism, G5 coupling structures, configuration errors.

use proptest::prelude::*;
use statrs::statistics::Statistics;
use streamcert::dynamics::{
    Coupling, Disturbance, DisturbanceConfig, Dither, DitherConfig, Dynamics, DynamicsError, G5,
    G5Config, Impulse, Integrator, LinearSystem, NoiseScaling, Process, Segment, SimConfig,
    simulate,
};
use streamcert::experiments::regime_schedule;

fn g5(coupling: Coupling, gamma: f64) -> G5 {
    G5::new(G5Config { gamma, ..G5Config::paper(coupling) }).expect("valid config")
}

/// Central finite-difference Jacobian of the drift, row-major.
fn fd_jacobian(sys: &G5, x: &[f64; 5], u: &[f64; 2]) -> [f64; 25] {
    let h = 1e-6;
    let mut jac = [0.0; 25];
    let (mut fp, mut fm) = ([0.0; 5], [0.0; 5]);
    for j in 0..5 {
        let (mut xp, mut xm) = (*x, *x);
        xp[j] += h;
        xm[j] -= h;
        sys.drift(0.0, &xp, u, &mut fp);
        sys.drift(0.0, &xm, u, &mut fm);
        for i in 0..5 {
            jac[i * 5 + j] = (fp[i] - fm[i]) / (2.0 * h);
        }
    }
    jac
}

fn state() -> impl Strategy<Value = [f64; 5]> {
    prop::array::uniform5(-2.0f64..2.0)
}

proptest! {
    #[test]
    fn g5_jacobian_matches_central_differences(
        x in state(),
        u in prop::array::uniform2(-3.0f64..3.0),
        gamma in 0.0f64..4.2,
        bidirectional in any::<bool>(),
    ) {
        let c = if bidirectional { Coupling::Bidirectional } else { Coupling::Cascade };
        let sys = g5(c, gamma);
        let mut jac = [0.0; 25];
        prop_assert!(sys.jacobian(0.0, &x, &u, &mut jac));
        let fd = fd_jacobian(&sys, &x, &u);
        for i in 0..25 {
            let scale = 1.0 + fd[i].abs();
            prop_assert!((jac[i] - fd[i]).abs() < 1e-6 * scale, "entry {i}: {} vs {}", jac[i], fd[i]);
        }
    }

    #[test]
    fn closed_loop_jacobian_and_observed_rates_match_differences(
        x in state(),
        gamma in 0.0f64..2.0,
        k1 in -5.0f64..0.0,
        k4 in -5.0f64..0.0,
    ) {
        let sys = G5::new(G5Config { gamma, k1, k4, ..G5Config::paper(Coupling::Bidirectional) })
            .expect("valid");
        // Closed loop under u = (k1 x1, k4 x4): differentiate the closed-loop drift.
        let cl = |x: &[f64; 5], dx: &mut [f64; 5]| sys.drift(0.0, x, &[k1 * x[0], k4 * x[3]], dx);
        let h = 1e-6;
        let mut jac = [0.0; 25];
        sys.closed_loop_jacobian(&x, &mut jac);
        let (mut fp, mut fm) = ([0.0; 5], [0.0; 5]);
        for j in 0..5 {
            let (mut xp, mut xm) = (x, x);
            xp[j] += h;
            xm[j] -= h;
            cl(&xp, &mut fp);
            cl(&xm, &mut fm);
            for i in 0..5 {
                let fd = (fp[i] - fm[i]) / (2.0 * h);
                prop_assert!((jac[i * 5 + j] - fd).abs() < 1e-6 * (1.0 + fd.abs()));
            }
        }
        // The observed closed-loop rates are the negated measured-channel diagonal entries.
        let rates = sys.observed_closed_loop_rates(&x);
        prop_assert!((rates.a + jac[0]).abs() < 1e-12);
        prop_assert!((rates.b + jac[3 * 5 + 3]).abs() < 1e-12);
    }
}

/// `ẋ = A x` with `A = [[−½, 2], [−2, −½]]`: `x(t) = e^{−t/2} R(−2t) x0`.
fn rotation_decay() -> LinearSystem {
    LinearSystem::new(
        2,
        1,
        2,
        1,
        vec![-0.5, 2.0, -2.0, -0.5],
        vec![0.0; 2],
        vec![1.0, 0.0, 0.0, 1.0],
        vec![0.0; 2],
    )
    .expect("valid")
}

fn final_error(integrator: Integrator, dt: f64) -> f64 {
    let sys = rotation_decay();
    let t_end = 2.0;
    let steps = (t_end / dt).round() as usize;
    let cfg = SimConfig {
        dt,
        steps,
        t0: 0.0,
        x0: vec![1.0, 0.0],
        integrator,
        noise_scaling: NoiseScaling::Sde,
    };
    let mut d = [Disturbance::new(DisturbanceConfig::none(), 0).expect("valid")];
    let traj = simulate(&sys, &cfg, &mut d, |_, _, u| u[0] = 0.0).expect("valid");
    let decay = (-0.5 * t_end).exp();
    let exact = [decay * (2.0 * t_end).cos(), -decay * (2.0 * t_end).sin()];
    let x = traj.state(steps);
    ((x[0] - exact[0]).powi(2) + (x[1] - exact[1]).powi(2)).sqrt()
}

#[test]
fn rk4_converges_at_fourth_order_and_euler_at_first() {
    for (integrator, order) in [(Integrator::Rk4, 4.0), (Integrator::EulerMaruyama, 1.0)] {
        let errs: Vec<f64> =
            [0.04, 0.02, 0.01].iter().map(|&dt| final_error(integrator, dt)).collect();
        for w in errs.windows(2) {
            let observed = (w[0] / w[1]).log2();
            assert!(
                (observed - order).abs() < 0.15,
                "{integrator:?}: observed order {observed}, expected {order} (errors {errs:?})"
            );
        }
    }
}

fn draws(process: Process, n: usize, seed: u64) -> Vec<f64> {
    let mut d = Disturbance::new(DisturbanceConfig::stationary(process), seed).expect("valid");
    (0..n).map(|k| d.random(k as f64 * 0.02)).collect()
}

/// Excess kurtosis by the two-pass formula.
fn excess_kurtosis(x: &[f64]) -> f64 {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let m2 = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    let m4 = x.iter().map(|v| (v - mean).powi(4)).sum::<f64>() / n;
    m4 / (m2 * m2) - 3.0
}

#[test]
fn disturbance_moments_match_theory() {
    let n = 400_000;
    // Experiment 1's Regime 3: Laplace 0.3 plus 4.5 to 7.5 σ0 spikes at 5.5 % per step.
    let spikes = regime_schedule().segments[2].process;
    // (process, theoretical excess kurtosis, tolerance on it)
    let cases = [
        (Process::Gaussian { sigma: 0.08 }, Some(0.0), 0.05),
        (Process::Laplace { scale: 0.5 }, Some(3.0), 0.4),
        (Process::StudentT { dof: 10.0, scale: 1.0 }, Some(1.0), 0.3),
        (spikes, None, 0.0),
    ];
    for (i, (process, kurt, tol)) in cases.into_iter().enumerate() {
        let x = draws(process, n, 100 + i as u64);
        let var = process.variance();
        let mean = x.as_slice().mean();
        let sample_var = x.as_slice().variance();
        // Mean within 5 standard errors of 0.
        assert!(mean.abs() < 5.0 * (var / n as f64).sqrt(), "{process:?}: mean {mean}");
        // Variance within 3 %: the standard error of a sample variance is below 1 % here.
        assert!((sample_var / var - 1.0).abs() < 0.03, "{process:?}: var {sample_var} vs {var}");
        if let Some(k) = kurt {
            let observed = excess_kurtosis(&x);
            assert!((observed - k).abs() < tol, "{process:?}: excess kurtosis {observed} vs {k}");
        }
    }
}

#[test]
fn spike_rate_matches_probability() {
    // With a zero Laplace base every non-zero draw is a spike.
    let p = Process::LaplaceSpikes {
        scale: 0.0,
        spike_prob: 0.055,
        spike_min: 4.5,
        spike_max: 7.5,
        sigma0: 0.08,
    };
    let n = 200_000;
    let x = draws(p, n, 9);
    let hits = x.iter().filter(|v| **v != 0.0).count() as f64 / n as f64;
    let se = (0.055 * 0.945 / n as f64).sqrt();
    assert!((hits - 0.055).abs() < 5.0 * se, "spike rate {hits}");
    assert!(x.iter().all(|v| *v == 0.0 || (0.36 - 1e-12..=0.6 + 1e-12).contains(&v.abs())));
    let positive = x.iter().filter(|v| **v > 0.0).count() as f64
        / x.iter().filter(|v| **v != 0.0).count() as f64;
    assert!((positive - 0.5).abs() < 0.03, "sign balance {positive}");
}

fn exp1_run(seed: u64, coupling: Coupling) -> Vec<f64> {
    let sys = G5::new(G5Config { gamma: 0.15, k1: -3.5, k4: -4.0, ..G5Config::paper(coupling) })
        .expect("valid");
    let cfg = SimConfig {
        dt: 0.02,
        steps: 1500,
        t0: 0.0,
        x0: vec![0.0; 5],
        integrator: Integrator::EulerMaruyama,
        noise_scaling: NoiseScaling::Sde,
    };
    let mut d = [
        Disturbance::new(DisturbanceConfig::none(), seed).expect("valid"),
        Disturbance::new(regime_schedule(), seed + 1).expect("valid"),
    ];
    let mut dither =
        Dither::new(DitherConfig::Prbs { amplitude: 0.3, hold: 0.1 }, seed + 2).expect("valid");
    let traj = simulate(&sys, &cfg, &mut d, |t, y, u| {
        u[0] = -3.5 * y[0] + dither.value(t);
        u[1] = -4.0 * y[1];
    })
    .expect("valid");
    traj.x
}

#[test]
fn identical_seeds_give_identical_trajectories() {
    let a = exp1_run(5, Coupling::Cascade);
    let b = exp1_run(5, Coupling::Cascade);
    let c = exp1_run(6, Coupling::Cascade);
    assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
    assert!(a.iter().zip(&c).any(|(x, y)| x != y));
    assert!(a.iter().all(|v| v.is_finite()));
}

/// Peak of `‖x‖` after an impulse of 2.5 into `x4` at 3 s, 14 s, no noise.
fn impulse_peak_and_end(coupling: Coupling, gamma: f64) -> (f64, f64) {
    let sys = g5(coupling, gamma);
    let cfg = SimConfig {
        dt: 0.02,
        steps: 700,
        t0: 0.0,
        x0: vec![0.0; 5],
        integrator: Integrator::Rk4,
        noise_scaling: NoiseScaling::Sde,
    };
    let impulse = DisturbanceConfig {
        impulses: vec![Impulse { time: 3.0, magnitude: 2.5 }],
        ..DisturbanceConfig::none()
    };
    let mut d = [
        Disturbance::new(DisturbanceConfig::none(), 0).expect("valid"),
        Disturbance::new(impulse, 1).expect("valid"),
    ];
    let traj = simulate(&sys, &cfg, &mut d, |_, y, u| {
        u[0] = -2.5 * y[0];
        u[1] = -3.0 * y[1];
    })
    .expect("valid");
    let norm = |k: usize| traj.state(k).iter().map(|v| v * v).sum::<f64>().sqrt();
    let peak = (0..traj.len())
        .map(norm)
        .fold(0.0, |a: f64, b| if b.is_nan() { f64::INFINITY } else { a.max(b) });
    (peak, norm(traj.len() - 1))
}

#[test]
fn cascade_recovers_from_impulse_where_strong_bidirectional_coupling_does_not() {
    // Cascade at the top of the sweep range: both blocks contract, so the network does.
    let (peak, end) = impulse_peak_and_end(Coupling::Cascade, 4.2);
    assert!(peak.is_finite() && peak < 5.0, "cascade peak {peak}");
    assert!(end < 1e-3, "cascade end {end}");
    // Bidirectional at γ = 4.2 > √(2.5·4): the linearised (x1, x4) block is unstable.
    let (peak, end) = impulse_peak_and_end(Coupling::Bidirectional, 4.2);
    assert!(peak > 1e3, "bidirectional peak {peak}, end {end}");
    // Bidirectional below the threshold recovers.
    let (_, end) = impulse_peak_and_end(Coupling::Bidirectional, 1.0);
    assert!(end < 1e-3, "weakly coupled bidirectional end {end}");
}

#[test]
fn bad_configurations_are_typed_errors() {
    let neg = DisturbanceConfig::stationary(Process::Gaussian { sigma: -0.1 });
    assert!(matches!(Disturbance::new(neg, 0), Err(DynamicsError::Negative { name: "sigma", .. })));
    let nan = G5Config { a12: f64::NAN, ..G5Config::paper(Coupling::Cascade) };
    assert!(matches!(G5::new(nan), Err(DynamicsError::NonFinite { name: "a12", .. })));
    let empty = DisturbanceConfig { segments: vec![], ..DisturbanceConfig::none() };
    assert_eq!(Disturbance::new(empty, 0).err(), Some(DynamicsError::EmptySchedule));
    let overlap = DisturbanceConfig {
        segments: vec![
            Segment { start: 0.0, end: 10.0, process: Process::Zero },
            Segment { start: 9.0, end: 20.0, process: Process::Zero },
        ],
        ..DisturbanceConfig::none()
    };
    assert!(matches!(
        Disturbance::new(overlap, 0),
        Err(DynamicsError::OverlappingSegments { index: 1, .. })
    ));
    let sys = g5(Coupling::Cascade, 0.0);
    let mut d = [
        Disturbance::new(DisturbanceConfig::none(), 0).expect("valid"),
        Disturbance::new(DisturbanceConfig::none(), 1).expect("valid"),
    ];
    for dt in [0.0, -0.02] {
        let cfg = SimConfig {
            dt,
            steps: 10,
            t0: 0.0,
            x0: vec![0.0; 5],
            integrator: Integrator::Rk4,
            noise_scaling: NoiseScaling::Sde,
        };
        let err = simulate(&sys, &cfg, &mut d, |_, _, _| {}).err();
        assert!(matches!(err, Some(DynamicsError::NotPositive { name: "dt", .. })), "{err:?}");
    }
    let cfg = SimConfig {
        dt: 0.02,
        steps: 10,
        t0: 0.0,
        x0: vec![0.0; 4],
        integrator: Integrator::Rk4,
        noise_scaling: NoiseScaling::Sde,
    };
    assert!(matches!(
        simulate(&sys, &cfg, &mut d, |_, _, _| {}),
        Err(DynamicsError::DimensionMismatch { name: "x0", .. })
    ));
    assert!(matches!(
        simulate(&sys, &SimConfig { x0: vec![0.0; 5], ..cfg }, &mut d[..1], |_, _, _| {}),
        Err(DynamicsError::DimensionMismatch { name: "disturbances", .. })
    ));
}

#[test]
fn noise_scalings_give_their_stationary_variances() {
    // ẋ = −a x + η, η Gaussian σ: stationary variance σ²/(2a) · s(dt)²/dt.
    let (a, sigma, dt) = (2.0, 0.5, 0.01);
    let sys =
        LinearSystem::new(1, 1, 1, 1, vec![-a], vec![0.0], vec![1.0], vec![1.0]).expect("valid");
    for scaling in [NoiseScaling::Sde, NoiseScaling::HeldInput, NoiseScaling::StateIncrement] {
        let cfg = SimConfig {
            dt,
            steps: 400_000,
            t0: 0.0,
            x0: vec![0.0],
            integrator: Integrator::EulerMaruyama,
            noise_scaling: scaling,
        };
        let mut d =
            [Disturbance::new(DisturbanceConfig::stationary(Process::Gaussian { sigma }), 3)
                .expect("valid")];
        let traj = simulate(&sys, &cfg, &mut d, |_, _, u| u[0] = 0.0).expect("valid");
        let s = scaling.factor(dt);
        // Exact stationary variance of the Euler recursion x' = (1 − a dt) x + s σ ξ.
        let phi: f64 = 1.0 - a * dt;
        let expected = (s * sigma).powi(2) / (1.0 - phi * phi);
        let observed = traj.x[1000..].variance();
        assert!((observed / expected - 1.0).abs() < 0.05, "{scaling:?}: {observed} vs {expected}");
    }
}
