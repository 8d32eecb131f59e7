//! The hidden-dynamics guard (`Calibration::hidden_dynamics`, on by default): outputs with a
//! hidden state are not certified on the first-order model, first-order loops keep their
//! certificates; and the model guards' risk (`Calibration::guard_risk`) only closes.

use streamcert::certificate::{Calibration, Certifier, CertifierConfig, NotCertified};
use streamcert::dynamics::{LinearScenario, Process, ScalarDrift, ScalarScenario, Trajectory};
use streamcert::regression::{InputIntegral, RegressionConfig};

use crate::calibrated::clopper_pearson;
use crate::support::{run as run_scenario, scalar};

/// The calibrated certificate on one output, `M = 150`, `h = 5`, zero-order hold, margin
/// 0.05, a one-sample gate, candidate `K = k`; the guard on or off.
fn config(k: f64, guard: bool) -> CertifierConfig {
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(1, 1, 150, 5, 1e-4)
    };
    CertifierConfig {
        // This guard alone (the others off), to see what it does.
        calibration: Some(Calibration {
            hidden_dynamics: guard,
            ..Calibration::new(0.01).unguarded()
        }),
        ..CertifierConfig::new(reg, vec![k], 0.1, 0.05, 1)
    }
}

/// A two-state plant `ẋ = A x + [0; 1] u + [0; 1] w` measured by its first state only
/// (`y = x₁`), `u = PRBS(±1, held 0.5 s)`, σ = 0.1, 40 s at dt = 0.01.
fn by_position(a: [f64; 4]) -> LinearScenario {
    LinearScenario {
        n: 2,
        m: 1,
        a: a.to_vec(),
        b: vec![0.0, 1.0],
        k_explore: vec![0.0, 0.0],
        noise_gain: Some(vec![0.0, 1.0]),
        dither_hold: 0.5,
        steps: 4000,
        ..scalar(0.0, 0.0, Process::Gaussian { sigma: 0.1 }, 1.0)
    }
}

/// Whether the calibrated gate opens on the first coordinate of `traj`, and the reasons seen.
fn opens(cfg: &CertifierConfig, traj: &Trajectory) -> (bool, Vec<NotCertified>) {
    let mut cert = Certifier::new(cfg.clone()).expect("valid");
    let mut reasons = Vec::new();
    let mut opened = false;
    for i in 0..traj.len() {
        let ev = cert.push(traj.t[i], &traj.output(i)[..1], traj.input(i)).expect("finite");
        opened |= ev.calibrated.open;
        if let Some(r) = ev.calibrated.reason {
            reasons.push(r);
        }
    }
    (opened, reasons)
}

/// A damped mass by its position (`ẍ = −2 ẋ + u + w`: the position does not contract) and a
/// lightly damped oscillator by its position (`ẍ = −x − 0.05 ẋ + u + w`: its state decays at
/// 0.025, below the margin, in any metric): without the guard the first-order model certifies
/// them (the mass in 2 of 100 runs, the oscillator in 99: the anchored window's growing data
/// see through the mass more often than the sliding windows alone did); with it the gate opens in at most what δ = 0.01 allows over 100 runs (the lower end
/// of the 95 % Clopper–Pearson interval at most δ), and the reason names the hidden dynamics.
#[test]
fn outputs_with_a_hidden_state_are_not_certified() {
    let runs = 100u64;
    for (name, a, unguarded_at_least) in
        [("damped mass", [0.0, 1.0, 0.0, -2.0], 1), ("oscillator", [0.0, 1.0, -1.0, -0.05], 50)]
    {
        let scenario = by_position(a);
        let count = |guard: bool, runs: u64| {
            let mut hidden = 0;
            let opened = (0..runs)
                .filter(|&s| {
                    let traj = run_scenario(&scenario, 4400 + s);
                    let (opened, reasons) = opens(&config(0.0, guard), &traj);
                    hidden += usize::from(
                        reasons.iter().any(|r| matches!(r, NotCertified::HiddenDynamics { .. })),
                    );
                    opened
                })
                .count();
            (opened, hidden)
        };
        let (unguarded, _) = count(false, 100);
        let (guarded, hidden) = count(true, runs);
        eprintln!(
            "{name}: unguarded {unguarded} of {runs}, guarded {guarded} of {runs}, reason in {hidden}"
        );
        assert!(
            unguarded >= unguarded_at_least,
            "{name}: the first-order model opened {unguarded} of {runs}"
        );
        let (lower, _) = clopper_pearson(guarded, runs as usize);
        assert!(lower <= 0.01, "{name}: {guarded} of {runs} opened with the guard");
        assert!(hidden as u64 >= runs / 2, "{name}: the reason named in {hidden} of {runs}");
    }
}

/// First-order loops keep their certificates: `ẏ = 0.5 y + u + w` under `K = −1.5` (true
/// rate 1.0) opens in every one of 40 runs with the guard, and the share of samples whose
/// reason is the guard's is small (its false closings: a test at risk δ per look).
#[test]
fn first_order_loops_keep_their_certificates() {
    let scenario = LinearScenario {
        dither_hold: 0.2,
        steps: 4000,
        ..scalar(0.5, -1.0, Process::Gaussian { sigma: 0.1 }, 1.0)
    };
    let (mut opened, mut closed_by_guard, mut samples) = (0, 0, 0);
    for s in 0..40 {
        let traj = run_scenario(&scenario, 5500 + s);
        let (o, reasons) = opens(&config(-1.5, true), &traj);
        opened += usize::from(o);
        closed_by_guard +=
            reasons.iter().filter(|r| matches!(r, NotCertified::HiddenDynamics { .. })).count();
        samples += traj.len();
    }
    let share = closed_by_guard as f64 / samples as f64;
    eprintln!("first order: opened {opened} of 40, guard closings {share:.4} of samples");
    assert_eq!(opened, 40);
    assert!(share < 0.01, "the guard closed {share} of the samples");
}

/// `Calibration::guard_risk` only closes: on the nonlinear study's `−x tanh x` loop (`K =
/// −1.1`, where the nonlinearity guard has work to do) and on a first-order linear loop, the
/// default configuration's gate at `guard_risk = 0.05` is open only at samples where the
/// default's (`δ/W = 0.0025`) is; it closes at more samples in some run, and the default's
/// gate opens in some run (so the comparison is not vacuous).
#[test]
fn a_larger_guard_risk_only_closes() {
    assert_eq!(Calibration::new(0.01).guard_risk(4), 0.0025);
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(1, 1, 150, 5, 1e-4)
    };
    let cfg = |k: f64, guard_risk| CertifierConfig {
        calibration: Some(Calibration { guard_risk, ..Calibration::new(0.01) }),
        ..CertifierConfig::new(reg, vec![k], 0.1, 0.05, 1)
    };
    let tanh = ScalarScenario::new(ScalarDrift::NegXTanhX, -1.1);
    let linear =
        LinearScenario { steps: 4000, ..scalar(0.5, -1.0, Process::Gaussian { sigma: 0.1 }, 1.0) };
    let (mut fewer, mut opened, mut compared) = (0, 0, 0);
    for seed in 0..8u64 {
        let (traj, k) = if seed % 2 == 0 {
            (tanh.run(seed).expect("valid"), -1.1)
        } else {
            (run_scenario(&linear, 70_000 + seed), -1.5)
        };
        let mut default = Certifier::new(cfg(k, None)).expect("valid");
        let mut larger = Certifier::new(cfg(k, Some(0.05))).expect("valid");
        let (mut open_default, mut open_larger) = (0, 0);
        for i in 0..traj.len() {
            let (t, y, u) = (traj.t[i], &traj.output(i)[..1], traj.input(i));
            let a = larger.push(t, y, u).expect("valid").calibrated.open;
            let b = default.push(t, y, u).expect("valid").calibrated.open;
            assert!(!a || b, "seed {seed}, t = {t}: open only at the larger risk");
            open_default += usize::from(b);
            open_larger += usize::from(a);
            compared += 1;
        }
        fewer += usize::from(open_larger < open_default);
        opened += usize::from(open_default > 0);
    }
    assert!(compared > 30_000 && fewer >= 1 && opened >= 2, "{compared} {fewer} {opened}");
}

/// The nonlinear certificate's own order test (its larger fit holds the past increment,
/// on with `Calibration::hidden_dynamics`): on the damped mass and the oscillator by position
/// its reason closes the nonlinear gate in most of 20 runs and never with the test off; on a
/// first-order nonlinear loop (the cubic `−x − 0.3 x³` under `K = −1`, rate at least 2, 40×
/// the margin) the nonlinear gate still opens in every one of 20 runs, and the test's
/// closings are a small share of the samples.
#[test]
fn the_nonlinear_certificate_tests_its_order_too() {
    use streamcert::certificate::NonlinearConfig;
    let nonlinear = |k: f64, order: bool| CertifierConfig {
        calibration: Some(Calibration { hidden_dynamics: order, ..Calibration::new(0.01) }),
        nonlinear: Some(NonlinearConfig::with_degree(3)),
        ..config(k, true)
    };
    // (opened, runs whose reasons name the hidden dynamics, samples so closed, samples)
    let run = |cfg: &CertifierConfig, traj: &Trajectory| {
        let mut cert = Certifier::new(cfg.clone()).expect("valid");
        let (mut opened, mut closed) = (false, 0);
        for i in 0..traj.len() {
            let ev = cert.push(traj.t[i], &traj.output(i)[..1], traj.input(i)).expect("finite");
            opened |= ev.nonlinear.open;
            closed += usize::from(matches!(
                ev.nonlinear.reason,
                Some(NotCertified::HiddenDynamics { .. })
            ));
        }
        (opened, closed)
    };
    for a in [[0.0, 1.0, 0.0, -2.0], [0.0, 1.0, -1.0, -0.05]] {
        let scenario = by_position(a);
        let (mut named, mut named_off) = (0, 0);
        for s in 0..20 {
            let traj = run_scenario(&scenario, 8800 + s);
            named += usize::from(run(&nonlinear(0.0, true), &traj).1 > 0);
            named_off += usize::from(run(&nonlinear(0.0, false), &traj).1 > 0);
        }
        eprintln!("{a:?}: the order test closed the nonlinear gate in {named} of 20 runs");
        assert!(named >= 15, "{a:?}: the reason named in {named} of 20 runs");
        assert_eq!(named_off, 0);
    }
    let cubic = ScalarScenario {
        drift: ScalarDrift::Polynomial(vec![0.0, -1.0, 0.0, -0.3]),
        k_explore: -1.0,
        dither: 3.0,
        dither_hold: 1.0,
        ..ScalarScenario::new(ScalarDrift::NegXTanhX, -1.1)
    };
    let (mut opened, mut closed, mut samples) = (0, 0, 0);
    for s in 0..20 {
        let traj = cubic.run(9900 + s).expect("valid scenario");
        let (o, c) = run(&nonlinear(-1.0, true), &traj);
        opened += usize::from(o);
        closed += c;
        samples += traj.len();
    }
    let share = closed as f64 / samples as f64;
    eprintln!("cubic: opened {opened} of 20, order closings {share:.4} of samples");
    assert_eq!(opened, 20);
    assert!(share < 0.02, "the order test closed {share} of the samples");
}
