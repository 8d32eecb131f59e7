//! The nonlinear certificate and the region of every certificate: against the true
//! state-dependent rate of scalar systems (`−x tanh x`, a cubic, a polynomial with a
//! non-contracting band; the coefficient covariance is in `coefficient_covariance.rs`), degree 1
//! against the linear calibrated certificate (property), the nonlinearity test closing the
//! linear calibrated gate, and the lack-of-fit check of the feature library.

use proptest::prelude::*;
use streamcert::certificate::{
    Calibration, CertificateKind, Certifier, CertifierConfig, CertifyError, FeatureSet, Interval,
    NonlinearConfig, NotCertified, RiskSplit,
};
use streamcert::dynamics::{ScalarDrift, ScalarScenario, Trajectory};
use streamcert::experiments::{Experiment, G5Dataset};
use streamcert::regression::{InputIntegral, RegressionConfig};

const H: usize = 5;

/// Calibrated (`δ = 0.01`, base window `window`) and nonlinear (degree `degree`) certifier
/// for one output and one input.
pub(crate) fn config(k: f64, margin: f64, window: usize, degree: usize) -> CertifierConfig {
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(1, 1, window, H, 1e-4)
    };
    CertifierConfig {
        calibration: Some(Calibration::new(0.01)),
        nonlinear: Some(NonlinearConfig::with_degree(degree)),
        ..CertifierConfig::new(reg, vec![k], 0.1, margin, 1)
    }
}

/// The band loop: `ẋ = −x tanh x + u + w`, `u = −1.1 x + PRBS(±1.5, held 1 s)`, σ = 0.1,
/// 40 s at dt = 0.01.
fn tanh_loop() -> ScalarScenario {
    ScalarScenario::new(ScalarDrift::NegXTanhX, -1.1)
}

/// `f = −x − 0.3 x³` explored by `u = −x + PRBS(±3, held 1 s)`: under `k = −1` the rate
/// `2 + 0.9 x²` is at least 2 (40× the margin 0.05) everywhere.
pub(crate) fn cubic_40x() -> ScalarScenario {
    ScalarScenario {
        drift: ScalarDrift::Polynomial(vec![0.0, -1.0, 0.0, -0.3]),
        k_explore: -1.0,
        dither: 3.0,
        dither_hold: 1.0,
        ..tanh_loop()
    }
}

/// The smallest true rate over `[lo, hi]` by a dense scan (the rates here are smooth).
fn min_rate(s: &ScalarScenario, k: f64, r: Interval) -> f64 {
    (0..=400)
        .map(|i| s.local_rate(r.lo + (r.hi - r.lo) * f64::from(i) / 400.0, k))
        .fold(f64::INFINITY, f64::min)
}

/// Run `s` (seed) through `cfg`; for every sample with a nonlinear certificate, the
/// certificate and the smallest true rate over its region.
fn trace(
    s: &ScalarScenario,
    cfg: &CertifierConfig,
    seed: u64,
) -> (Trajectory, Vec<(f64, f64)>, Certifier) {
    let traj = s.run(seed).expect("valid scenario");
    let k = cfg.gain[0];
    let mut cert = Certifier::new(cfg.clone()).expect("valid");
    let mut out = Vec::new();
    for i in 0..traj.t.len() {
        let ev = cert.push(traj.t[i], &traj.y[i..=i], &traj.u[i..=i]).expect("finite data");
        if let (Some(v), Some(r)) = (ev.nonlinear.value, ev.nonlinear_region) {
            out.push((v, min_rate(s, k, r)));
        }
    }
    (traj, out, cert)
}

#[test]
fn the_nonlinear_certificate_stays_below_the_true_rate_over_its_region() {
    let cubic = ScalarScenario {
        drift: ScalarDrift::Polynomial(vec![0.0, 0.5, 0.0, -0.6]),
        k_explore: -1.5,
        dither: 1.0,
        dither_hold: 0.5,
        ..tanh_loop()
    };
    // A band of non-contraction between two contracting regions: f' = 0.3 − 1.2 x² + … .
    let band = ScalarScenario {
        drift: ScalarDrift::Polynomial(vec![0.0, -0.2, 0.9, -0.5]),
        k_explore: -1.2,
        dither: 1.2,
        dither_hold: 0.5,
        ..tanh_loop()
    };
    for (name, s, k) in [("tanh", tanh_loop(), -1.1), ("cubic", cubic, -1.5), ("band", band, -1.2)]
    {
        let mut steps = 0;
        for seed in 0..6 {
            let (_, out, _) = trace(&s, &config(k, 0.05, 50, 3), seed);
            steps += out.len();
            for (v, truth) in out {
                assert!(v <= truth, "{name} seed {seed}: certificate {v} above min rate {truth}");
            }
        }
        assert!(steps > 1000, "{name}: only {steps} certified samples");
    }
}

#[test]
fn on_g5_subsystem_a_the_certificate_stays_below_the_true_rate_over_its_region() {
    // Experiment 2's data (γ = 0), 40 s; subsystem A is output x1, input u1, candidate k1,
    // and the dynamics crate gives its true rate at every x1.
    let data = G5Dataset { steps: Some(2000), ..G5Dataset::defaults(Experiment::Two) };
    let g5 = data.system().expect("valid");
    let k1 = Experiment::Two.setting().k1;
    let truth = |x1: f64| g5.observed_closed_loop_rates(&[x1, 0.0, 0.0, 0.0, 0.0]).a;
    let mut valued = 0;
    for seed in 0..4 {
        let traj = data.run_seeded(seed).expect("valid");
        let (n, p, m) = (traj.t.len(), traj.p, traj.m);
        let mut cert = Certifier::new(config(k1, 0.05, 50, 3)).expect("valid");
        for i in 0..n {
            let ev = cert
                .push(traj.t[i], &traj.y[i * p..=i * p], &traj.u[i * m..=i * m])
                .expect("finite");
            if let (Some(v), Some(r)) = (ev.nonlinear.value, ev.nonlinear_region) {
                let lowest = (0..=400)
                    .map(|j| truth(r.lo + (r.hi - r.lo) * f64::from(j) / 400.0))
                    .fold(f64::INFINITY, f64::min);
                assert!(v <= lowest, "seed {seed} t = {}: {v} above {lowest}", traj.t[i]);
                valued += 1;
            }
        }
    }
    assert!(valued > 1000, "only {valued} samples with a certificate");
}

#[test]
fn a_named_library_that_holds_the_drift_certifies_the_tanh_loop_and_stays_below_truth() {
    let library = FeatureSet::from_names(&["y", "y*tanh(y)"]).expect("valid");
    let named = |k: f64| CertifierConfig {
        nonlinear: Some(NonlinearConfig::with_features(library)),
        ..config(k, 0.05, 50, 3)
    };
    // The non-contracting band loop and a contracting one (K = −2, rate >= 0.8).
    // The promise is per run: a value above the smallest true rate over its region in at most
    // δ = 0.01 of runs, so two such runs of these twelve would happen with probability below
    // 0.7 % if it holds (with the default split one seed of the band loop has one, 0.009
    // above; with equal shares none of these seeds does).
    let (mut opened, mut above) = (0, 0);
    for (k, seeds) in [(-1.1, 0..6), (-2.0, 0..6)] {
        let s = ScalarScenario::new(ScalarDrift::NegXTanhX, k);
        for seed in seeds {
            let (_, out, cert) = trace(&s, &named(k), seed);
            above += usize::from(out.iter().any(|(v, truth)| v > truth));
            if k == -2.0 {
                opened +=
                    usize::from(cert.gate(CertificateKind::Nonlinear).first_opened_at.is_some());
            }
        }
    }
    assert!(above <= 1, "{above} of 12 runs had a value above the truth");
    assert!(opened >= 5, "the contracting tanh loop opened in {opened} of 6 runs");
}

#[test]
fn the_tanh_loop_is_refused_by_the_nonlinear_gate_and_the_linear_gate_is_told() {
    let s = tanh_loop();
    let cfg = config(-1.1, 0.05, 50, 3);
    let mut varying = 0;
    for seed in 0..10 {
        let traj = s.run(seed).expect("valid");
        let mut cert = Certifier::new(cfg.clone()).expect("valid");
        for i in 0..traj.t.len() {
            let ev = cert.push(traj.t[i], &traj.y[i..=i], &traj.u[i..=i]).expect("finite");
            let visits_band = traj.x[..=i].iter().any(|&x| s.local_rate(x, -1.1) < 0.05);
            if ev.nonlinear.open && visits_band {
                // The region of the open certificate must then exclude every band state.
                let r = ev.nonlinear_region.expect("an open gate has a region");
                assert!(min_rate(&s, -1.1, r) >= 0.05, "seed {seed}: open over {r:?}");
            }
            if matches!(ev.calibrated.reason, Some(NotCertified::VaryingDynamics { .. })) {
                varying += 1;
            }
        }
    }
    // The nonlinearity test fires on this loop (the linear model is refused at some looks).
    assert!(varying > 0, "the nonlinearity test never fired");
}

#[test]
fn a_contracting_nonlinear_loop_is_certified_with_its_region() {
    let s = cubic_40x();
    let mut opened = 0;
    for seed in 0..10 {
        let (traj, out, cert) = trace(&s, &config(-1.0, 0.05, 50, 3), seed);
        opened += usize::from(
            cert.gate(streamcert::certificate::CertificateKind::Nonlinear)
                .first_opened_at
                .is_some(),
        );
        assert!(out.iter().all(|(v, truth)| v <= truth));
        // The paper window's region is the range of the last M + h samples.
        let n = traj.t.len();
        let region: Vec<Interval> = cert.region().collect();
        let from = n - (50 + H);
        let lo = traj.y[from..].iter().copied().fold(f64::INFINITY, f64::min);
        let hi = traj.y[from..].iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert_eq!(region[0], Interval { lo, hi });
    }
    assert!(opened >= 9, "opened in {opened} of 10 runs");
}

#[test]
fn the_configuration_says_what_is_valid() {
    let mut cfg = config(-1.0, 0.05, 50, 3);
    cfg.calibration = None;
    let err = Certifier::new(cfg).unwrap_err();
    assert!(matches!(err, CertifyError::InvalidConfig { field: "nonlinear", .. }), "{err}");
    // Cubic library, lack-of-fit y⁴ y⁵ (the past increment in a fit of its own), u,
    // intercept: h (3 + 2 + 1 + 1 + 2) = 45.
    let err = Certifier::new(config(-1.0, 0.05, 40, 3)).unwrap_err();
    let says = ["is 45", "check_terms = 0", "hidden_dynamics = false"];
    assert!(says.iter().all(|s| err.to_string().contains(s)), "{err}");
    let mut unchecked = config(-1.0, 0.05, 40, 3);
    unchecked.nonlinear =
        Some(NonlinearConfig { check_terms: 0, ..NonlinearConfig::with_degree(3) });
    assert!(Certifier::new(unchecked.clone()).is_ok());
    let mut short = config(-1.0, 0.05, 30, 3);
    short.nonlinear = unchecked.nonlinear;
    short.calibration = short.calibration.map(Calibration::unguarded); // (else 40 first)
    let err = Certifier::new(short).unwrap_err();
    assert!(err.to_string().contains("smallest valid window is 35"), "{err}");
    // Through the origin, one unknown fewer: 40.
    let mut origin = config(-1.0, 0.05, 35, 3);
    origin.regression.model = streamcert::regression::Model::ThroughOrigin;
    let err = Certifier::new(origin).unwrap_err();
    assert!(err.to_string().contains("smallest valid window is 40"), "{err}");
    let mut many = config(-1.0, 0.05, 200, 3);
    many.nonlinear = Some(NonlinearConfig { check_terms: 8, ..NonlinearConfig::with_degree(3) });
    let err = Certifier::new(many).unwrap_err();
    assert!(matches!(err, CertifyError::InvalidConfig { field: "nonlinear.check_terms", .. }));
    let mut cfg = config(-1.0, 0.05, 50, 3);
    cfg.regression = RegressionConfig::new(2, 2, 80, H, 1e-4);
    cfg.gain = vec![0.0; 4];
    let err = Certifier::new(cfg).unwrap_err();
    assert!(err.to_string().contains("one output"), "{err}");
    // Batches of blocks apply to the linear calibrated certificate (smallest window
    // h (4 (p + m + 2) + 1) = 85 at b = 4 with the intercept); the nonlinear certificate keeps
    // blocks of h.
    let batched = |window| {
        let mut cfg = config(-1.0, 0.05, window, 3);
        cfg.calibration = cfg.calibration.map(|c| Calibration { batch_blocks: 4, ..c });
        Certifier::new(cfg)
    };
    assert!(batched(85).is_ok());
    let err = batched(80).unwrap_err();
    assert!(err.to_string().contains("smallest valid window is 85"), "{err}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// On linear data the nonlinear certificate of degree 1 is the linear calibrated one, when
    /// both split `δ` across the windows by the same rule.
    #[test]
    fn degree_one_equals_the_linear_calibrated_certificate(
        a in -1.0f64..0.8, k in -2.5f64..-0.5, seed in 0u64..1000, window in 25usize..80,
        split in prop_oneof![
            Just(RiskSplit::Equal), Just(RiskSplit::ByLength), Just(RiskSplit::ByLengthSquared)
        ],
    ) {
        let s = ScalarScenario {
            drift: ScalarDrift::Polynomial(vec![0.0, a]),
            k_explore: k,
            dither: 1.0,
            dither_hold: 0.2,
            steps: 1500,
            ..tanh_loop()
        };
        let traj = s.run(seed).expect("valid");
        // The certificate's arithmetic, without the lack-of-fit check (which only closes gates).
        let mut cfg = config(k, 0.05, window, 1);
        cfg.nonlinear = Some(NonlinearConfig {
            check_terms: 0,
            risk_split: split,
            ..NonlinearConfig::with_degree(1)
        });
        // Guards, the batched second covariance (`auto_batches`) and the anchored window (whose
        // share the sliding windows' looks give up) are the linear one's only.
        cfg.calibration = cfg.calibration.map(|c| Calibration {
            auto_batches: 0,
            anchored_share: 0.0,
            risk_split: split,
            ..Calibration::unguarded(c)
        });
        let mut cert = Certifier::new(cfg).expect("valid");
        let mut compared = 0;
        for i in 0..traj.t.len() {
            let ev = cert.push(traj.t[i], &traj.y[i..=i], &traj.u[i..=i]).expect("finite");
            let lin = cert.calibrated_looks().to_vec();
            let nl = cert.nonlinear_looks().to_vec();
            for (l, n) in lin.iter().zip(&nl) {
                match (l, n) {
                    (Some(l), Some(n)) => {
                        let tol = 1e-9 * (1.0 + l.certificate().abs());
                        prop_assert!((l.certificate() - n.certificate).abs() < tol,
                            "{} vs {}", l.certificate(), n.certificate);
                        compared += 1;
                    }
                    (None, None) => {}
                    _ => prop_assert!(false, "one certificate without the other"),
                }
            }
            prop_assert_eq!(ev.calibrated.value.is_some(), ev.nonlinear.value.is_some());
        }
        prop_assert!(compared > 0);
    }
}

/// Runs of `s` through `cfg` (seeds `0..runs`): how many opened the nonlinear gate while its
/// region held a state whose true rate is below the margin, and how many samples gave the
/// lack-of-fit reason.
fn false_openings(s: &ScalarScenario, cfg: &CertifierConfig, runs: u64) -> (usize, usize) {
    let k = cfg.gain[0];
    let (mut falsely, mut misfit) = (0, 0);
    for seed in 0..runs {
        let traj = s.run(seed).expect("valid scenario");
        let mut cert = Certifier::new(cfg.clone()).expect("valid");
        let mut opened_falsely = false;
        for i in 0..traj.t.len() {
            let ev = cert.push(traj.t[i], &traj.y[i..=i], &traj.u[i..=i]).expect("finite");
            if let (true, Some(r)) = (ev.nonlinear.open, ev.nonlinear_region) {
                opened_falsely |= min_rate(s, k, r) < cfg.margin;
            }
            misfit += usize::from(matches!(
                ev.nonlinear.reason,
                Some(NotCertified::LibraryMisfit { .. })
            ));
        }
        falsely += usize::from(opened_falsely);
    }
    (falsely, misfit)
}

#[test]
fn the_lack_of_fit_check_closes_the_gate_of_a_library_that_misses_the_drift() {
    // The band (rate −0.1 + 1.5 (x − 0.8)², non-contracting near x = 0.8) under the library
    // `y, y·tanh y`, which cannot hold its x² and x³ terms: unchecked, the certificate of the
    // library's best fit opens while the region holds non-contracting states.
    let band = ScalarScenario {
        drift: ScalarDrift::Polynomial(vec![0.0, 0.14, 1.2, -0.5]),
        k_explore: -1.0,
        ..tanh_loop()
    };
    let library = FeatureSet::from_names(&["y", "y*tanh(y)"]).expect("valid");
    let mut cfg = config(-1.0, 0.05, 50, 1);
    cfg.nonlinear =
        Some(NonlinearConfig { check_terms: 0, ..NonlinearConfig::with_features(library) });
    let (unchecked, none) = false_openings(&band, &cfg, 10);
    cfg.nonlinear = Some(NonlinearConfig::with_features(library));
    let (checked, misfit) = false_openings(&band, &cfg, 10);
    assert_eq!(none, 0);
    assert!(unchecked >= 6, "unchecked: {unchecked} of 10 runs opened falsely");
    assert!(checked * 3 <= unchecked, "checked {checked} against unchecked {unchecked}");
    assert!(misfit > 0, "no sample gave the lack-of-fit reason");
}

#[test]
fn the_lack_of_fit_check_passes_a_library_that_holds_the_drift() {
    // The cubic 2 + 0.9 x² (40× the margin) under the cubic library: the extra terms y⁴, y⁵
    // are zero, the gate opens in every run, and the check rejects at few looks (its risk is
    // δ = 0.01 per look).
    let cubic = cubic_40x();
    let cfg = config(-1.0, 0.05, 50, 3);
    let (mut looks, mut rejected, mut untested) = (0, 0, 0);
    for seed in 0..6 {
        let traj = cubic.run(seed).expect("valid scenario");
        let mut cert = Certifier::new(cfg.clone()).expect("valid");
        let mut seen = vec![0u64; cert.nonlinear_looks().len()];
        let mut opened = false;
        for i in 0..traj.t.len() {
            opened |=
                cert.push(traj.t[i], &traj.y[i..=i], &traj.u[i..=i]).expect("ok").nonlinear.open;
            for (w, look) in cert.nonlinear_looks().iter().enumerate() {
                if let Some(l) = look.filter(|l| l.look != seen[w]) {
                    seen[w] = l.look;
                    looks += 1;
                    match l.misfit {
                        Some(test) => rejected += usize::from(test.significant()),
                        None => untested += 1,
                    }
                }
            }
        }
        assert!(opened, "seed {seed}: the gate never opened");
    }
    // Untested looks (the larger fit has fewer degrees of freedom: on the shortest window
    // its ν − e + 1 can be ≤ 0 where the certificate's is not) do not stand either.
    let tested = looks - untested;
    assert!(tested > 100 && untested < looks / 2, "{looks} looks, {untested} untested");
    assert!(rejected * 20 <= tested, "{rejected} of {tested} tested looks rejected the library");
}
