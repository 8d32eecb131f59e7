//! The affine model (an intercept in every regression): verdicts invariant to the operating
//! point, the digits kept at `y₀ = 10⁶`, and the operating-point loop below the margin that the
//! model through the origin certifies.

use proptest::prelude::*;
use streamcert::certificate::{
    Calibration, Certifier, CertifierConfig, Evidence, NonlinearConfig, Verdict,
};
use streamcert::dynamics::{LinearScenario, Process, Trajectory};
use streamcert::regression::{InputIntegral, Model, RegressionConfig};

use crate::support::{coupled_pair, run as run_scenario, scalar};

const H: usize = 5;

/// The calibrated certificate (and, with `nonlinear`, the cubic nonlinear one) on one output,
/// `M = 150`, `h = 5`, zero-order hold, margin 0.05, a one-sample gate.
fn config(k: f64, model: Model, nonlinear: bool) -> CertifierConfig {
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        model,
        ..RegressionConfig::new(1, 1, 150, H, 1e-4)
    };
    CertifierConfig {
        calibration: Some(Calibration::new(0.01)),
        nonlinear: nonlinear.then(|| NonlinearConfig::with_degree(3)),
        ..CertifierConfig::new(reg, vec![k], 0.1, 0.05, 1)
    }
}

/// Every row of `traj` with `y + a`, `u + b`, certified.
fn certify(cfg: &CertifierConfig, traj: &Trajectory, a: f64, b: f64) -> Vec<Evidence> {
    let mut cert = Certifier::new(cfg.clone()).expect("valid");
    (0..traj.len())
        .map(|i| {
            let y = [traj.output(i)[0] + a];
            let u = [traj.input(i)[0] + b];
            cert.push(traj.t[i], &y, &u).expect("finite")
        })
        .collect()
}

/// `ẏ = 0.5 y + u + w`, `u = −y + PRBS(±1, held 0.2 s)`, σ = 0.1, 20 s at dt = 0.01.
fn loop_about_zero() -> LinearScenario {
    LinearScenario {
        dither_hold: 0.2,
        steps: 2000,
        ..scalar(0.5, -1.0, Process::Gaussian { sigma: 0.1 }, 1.0)
    }
}

/// Two values equal within `tol` relative to `scale` (both absent counts as equal).
fn close(a: Option<f64>, b: Option<f64>, tol: f64) -> bool {
    match (a, b) {
        (Some(x), Some(y)) => (x - y).abs() <= tol * (1.0 + x.abs().max(y.abs())),
        (None, None) => true,
        _ => false,
    }
}

/// The same verdict: the value and radius within `tol`, and the same gate state unless the
/// value sits within `tol` of the margin (where rounding may decide).
fn same_verdict(a: &Verdict, b: &Verdict, tol: f64, margin: f64) -> bool {
    let near = a.value.is_some_and(|v| (v - margin).abs() <= tol * (1.0 + v.abs()));
    close(a.value, b.value, tol) && close(a.radius, b.radius, tol) && (near || a.open == b.open)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(6))]

    /// `certify` on `(y + a, u + b)` equals `certify` on `(y, u)` for offsets up to `10⁶`,
    /// with the calibrated certificate and with the nonlinear one. Tolerance `10⁻⁶` relative:
    /// the working origin is the first sample, so both runs integrate `y − y₁`; they differ by
    /// the rounding of forming it from `10⁶`-sized values (`ulp(10⁶) ≈ 1.2·10⁻¹⁰` against
    /// excursions of order 0.1 to 1, `≈ 10⁻⁹` relative), amplified by the solves' condition.
    #[test]
    fn verdicts_are_invariant_to_the_operating_point(
        a in -1e6f64..1e6, b in -1e6f64..1e6, seed in 0u64..1000, nonlinear in any::<bool>(),
    ) {
        let traj = run_scenario(&loop_about_zero(), seed);
        let cfg = config(-1.5, Model::Affine, nonlinear);
        let (plain, shifted) = (certify(&cfg, &traj, 0.0, 0.0), certify(&cfg, &traj, a, b));
        let tol = 1e-6;
        let mut compared = 0;
        for (p, s) in plain.iter().zip(&shifted) {
            prop_assert!(close(p.beta_hat(), s.beta_hat(), tol), "t {}: {:?} vs {:?}", p.t, p.beta_hat(), s.beta_hat());
            prop_assert!(close(p.rho(), s.rho(), tol));
            prop_assert!(same_verdict(&p.gaussian, &s.gaussian, tol, 0.05));
            prop_assert!(same_verdict(&p.calibrated, &s.calibrated, tol, 0.05), "t {}: {:?} vs {:?}", p.t, p.calibrated, s.calibrated);
            prop_assert!(same_verdict(&p.nonlinear, &s.nonlinear, tol, 0.05), "t {}: {:?} vs {:?}", p.t, p.nonlinear, s.nonlinear);
            // The nonlinear region is reported in the record's coordinates.
            if let (Some(rp), Some(rs)) = (p.nonlinear_region, s.nonlinear_region) {
                prop_assert!((rp.lo + a - rs.lo).abs() <= 1e-6 * (1.0 + a.abs()));
                prop_assert!((rp.hi + a - rs.hi).abs() <= 1e-6 * (1.0 + a.abs()));
            }
            compared += usize::from(p.calibrated.value.is_some());
        }
        prop_assert!(compared > 500, "{compared} calibrated values compared");
    }
}

/// At `y₀ = 10⁶` with `σ = 0.1` the certificate equals the one of the centred record (the
/// digits test), here at every step of a run whose gate opens.
#[test]
fn the_certificate_at_a_million_equals_the_centred_one() {
    let traj = run_scenario(&loop_about_zero(), 3);
    let cfg = config(-1.5, Model::Affine, false);
    let (plain, far) = (certify(&cfg, &traj, 0.0, 0.0), certify(&cfg, &traj, 1e6, 0.0));
    let mut worst = 0.0f64;
    for (p, f) in plain.iter().zip(&far) {
        if let (Some(x), Some(y)) = (p.calibrated.value, f.calibrated.value) {
            worst = worst.max((x - y).abs() / (1.0 + x.abs()));
        }
        assert_eq!(p.calibrated.open, f.calibrated.open, "t {}", p.t);
    }
    assert!(plain.iter().any(|e| e.calibrated.open), "the calibrated gate opens");
    eprintln!("largest relative difference at 1e6: {worst:e}");
    assert!(worst < 1e-7, "largest relative difference {worst:e}");
}

/// An operating-point loop: `ẏ = −0.02 (y − 50) + (u − 10) + w`, `σ = 0.1`,
/// `u = 10 + PRBS(±1, held 0.2 s)`, 40 s at `dt = 0.01`, candidate `K = 0`: true rate 0.02,
/// below the margin 0.05, so every opening is a false deployment. Through the origin the
/// operating point enters `Θ̂` as dynamics and the gate opens in most runs; the affine model
/// opens in at most what the risk δ = 0.01 allows (the test fails when the lower end of the
/// 95 % Clopper–Pearson interval of 200 runs is above δ).
#[test]
fn an_operating_point_below_the_margin_is_not_certified() {
    let scenario = LinearScenario {
        dither_hold: 0.2,
        steps: 4000,
        ..scalar(-0.02, 0.0, Process::Gaussian { sigma: 0.1 }, 1.0)
    };
    let opens = |model: Model, runs: u64| {
        let cfg = config(0.0, model, false);
        (0..runs)
            .filter(|&s| {
                let traj = run_scenario(&scenario, 9100 + s);
                certify(&cfg, &traj, 50.0, 10.0).iter().any(|e| e.calibrated.open)
            })
            .count()
    };
    let origin = opens(Model::ThroughOrigin, 20);
    assert!(origin >= 10, "through the origin {origin} of 20 opened");
    let runs = 200;
    let affine = opens(Model::Affine, runs);
    eprintln!("operating point: through the origin {origin} of 20, affine {affine} of {runs}");
    let (lower, _) = crate::calibrated::clopper_pearson(affine, runs as usize);
    assert!(lower <= 0.01, "affine: {affine} of {runs} opened");
}

/// Units and the metric (`p = 2`): the same plant logged with its second output in other
/// units (`y_B = D y`, `D = diag(1, 1000)`, the controller `K_B = K D⁻¹`) is certified as in
/// the first units when the metric `w = (1, 1/1000)` is stated, and differently when not: the
/// identity metric of the new units is another metric of the plant.
#[test]
fn a_stated_metric_undoes_a_change_of_units() {
    let scenario = coupled_pair(loop_about_zero(), 3000);
    let traj = run_scenario(&scenario, 12);
    let gain = vec![-2.0, 0.0, 0.0, -2.0];
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(2, 2, 150, H, 1e-4)
    };
    let cfg = |gain: Vec<f64>, metric: Option<Vec<f64>>| CertifierConfig {
        calibration: Some(Calibration::new(0.01)),
        metric,
        ..CertifierConfig::new(reg, gain, 0.1, 0.05, 1)
    };
    let d = [1.0, 1000.0];
    let run = |cfg: CertifierConfig, scale: [f64; 2]| {
        let mut cert = Certifier::new(cfg).expect("valid");
        (0..traj.len())
            .map(|i| {
                let y = traj.output(i);
                cert.push(traj.t[i], &[scale[0] * y[0], scale[1] * y[1]], traj.input(i))
                    .expect("finite")
            })
            .collect::<Vec<_>>()
    };
    let gain_b = vec![gain[0] / d[0], gain[1] / d[1], gain[2] / d[0], gain[3] / d[1]];
    let first = run(cfg(gain.clone(), None), [1.0, 1.0]);
    let stated = run(cfg(gain_b.clone(), Some(vec![1.0 / d[0], 1.0 / d[1]])), d);
    let unstated = run(cfg(gain_b, None), d);
    let mut differ = 0;
    for ((a, b), c) in first.iter().zip(&stated).zip(&unstated) {
        assert!(close(a.beta_hat(), b.beta_hat(), 1e-6), "t {}", a.t);
        assert!(same_verdict(&a.calibrated, &b.calibrated, 1e-6, 0.05), "t {}", a.t);
        differ += usize::from(!close(a.beta_hat(), c.beta_hat(), 1e-3));
    }
    assert!(differ > first.len() / 2, "the unstated metric changed β̂ at {differ} samples");
    // The regions are reported in the logged units.
    let mut cert =
        Certifier::new(cfg(vec![-2.0, 0.0, 0.0, -2.0], Some(vec![1.0, 1000.0]))).expect("valid");
    for i in 0..200 {
        cert.push(traj.t[i], traj.output(i), traj.input(i)).expect("finite");
    }
    // The paper window's region: the last M + h = 155 samples.
    let hi = (45..200).map(|i| traj.output(i)[1]).fold(f64::MIN, f64::max);
    let region: Vec<_> = cert.region().collect();
    assert!((region[1].hi - hi).abs() <= 1e-12 * hi.abs().max(1.0), "{region:?} vs {hi}");
    // One output's rate does not depend on its unit: a metric there is refused.
    let one = CertifierConfig { metric: Some(vec![2.0]), ..config(-1.5, Model::Affine, false) };
    assert!(Certifier::new(one).is_err());
}
