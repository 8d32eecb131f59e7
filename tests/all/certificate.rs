//! streamcert-certificate: `β̂` against a dense eigensolver, validity of the certificate on
//! known linear systems, the gate, bad input, and checkpoint/restore.

use proptest::prelude::*;
use streamcert::ambiguity::AmbiguityConfig;
use streamcert::certificate::{
    BadSamplePolicy, CertificateKind, Certifier, CertifierConfig, CertifyError, Evidence,
    NotCertified, ResidualSource, certificate_surface, certificate_value,
};
use streamcert::regression::{Estimator, InputIntegral, RegressionConfig, RegressionError};

use crate::support::{run as run_scenario, scalar, true_rate};
use streamcert::dynamics::{LinearScenario, Process};

fn config(p: usize, m: usize, gain: Vec<f64>, c: f64) -> CertifierConfig {
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(p, m, 150, 5, 1e-4)
    };
    CertifierConfig::new(reg, gain, c, 0.05, 10)
}

fn run(cert: &mut Certifier, stream: &LinearScenario, seed: u64) -> Vec<Evidence> {
    let traj = run_scenario(stream, seed);
    (0..traj.len())
        .map(|k| cert.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid sample"))
        .collect()
}

fn two_state() -> LinearScenario {
    LinearScenario {
        a: vec![-1.0, 0.5, -0.3, -2.0],
        b: vec![1.0, 0.2, 0.0, 1.0],
        n: 2,
        m: 2,
        noise: Process::Gaussian { sigma: 0.02 },
        k_explore: vec![0.0; 4],
        dither: 0.5,
        dither_hold: 0.1,
        dt: 0.01,
        steps: 2000,
        noise_gain: None,
        sensor_noise: 0.0,
        switch: None,
    }
}

#[test]
fn beta_hat_is_minus_the_largest_eigenvalue_of_sym_j_cl() {
    let k = vec![-0.5, 0.1, 0.0, -0.8];
    let mut cert = Certifier::new(config(2, 2, k.clone(), 0.5)).expect("valid");
    let stream = two_state();
    let traj = run_scenario(&stream, 1);
    for i in 0..traj.len() {
        let ev = cert.push(traj.t[i], traj.output(i), traj.input(i)).expect("valid");
        let Some(beta_hat) = ev.beta_hat() else { continue };
        // Rebuild J_cl from the regression's Θ and solve with nalgebra.
        let mut reg = cert.regression().clone();
        let est = reg.estimate();
        let theta: Vec<f64> = est.theta.to_vec();
        let j_obs = vec![theta[0], theta[1], theta[4], theta[5]];
        let b_obs = vec![theta[2], theta[3], theta[6], theta[7]];
        let oracle = true_rate(&j_obs, &b_obs, &k, 2, 2);
        assert!((beta_hat - oracle).abs() < 1e-10 * (1.0 + oracle.abs()), "{beta_hat} vs {oracle}");
        let rho = ev.rho().expect("ready");
        assert!(rho >= 0.0);
        assert_eq!(ev.gaussian.value, Some(beta_hat - rho));
        let expected_rho =
            0.5 * (1.0 + cert.gain_norm()) * est.rms_residual / (est.gram_lambda_min + 1e-4).sqrt();
        assert!((rho - expected_rho).abs() <= 1e-12 * expected_rho);
    }
}

#[test]
fn certificate_stays_below_the_true_rate_on_known_systems() {
    // Scalar ẏ = a y + u + noise under strong dither; candidate K with known closed-loop rate.
    let mut below = 0usize;
    let mut total = 0usize;
    for (a, k) in [(0.5, -1.5), (-1.0, -1.0), (0.2, -0.7)] {
        let stream =
            LinearScenario { steps: 1500, ..scalar(a, k, Process::Gaussian { sigma: 0.05 }, 1.0) };
        let truth = true_rate(&[a], &[1.0], &[k], 1, 1);
        for seed in 0..10 {
            let mut cert = Certifier::new(config(1, 1, vec![k], 1.0)).expect("valid");
            for ev in run(&mut cert, &stream, seed) {
                if let Some(c) = ev.gaussian.value {
                    total += 1;
                    below += usize::from(c <= truth);
                }
            }
        }
    }
    let fraction = below as f64 / total as f64;
    assert!(total > 30_000);
    assert!(fraction > 0.95, "certificate below the true rate on {fraction} of steps");
}

#[test]
fn gate_opens_for_a_contracting_candidate_and_reports_why_it_is_closed() {
    let stream = scalar(-1.0, -1.0, Process::Gaussian { sigma: 0.05 }, 1.0);
    let mut cert = Certifier::new(config(1, 1, vec![-1.0], 0.2)).expect("valid");
    let evs = run(&mut cert, &stream, 3);
    // Warm-up: no certificate until the window holds M columns (h + M samples).
    assert!(matches!(evs[0].gaussian.reason, Some(NotCertified::WarmingUp { .. })));
    assert!(evs[..154].iter().all(|e| e.gaussian.value.is_none() && !e.gaussian.open));
    assert!(evs[155].gaussian.value.is_some());
    let opened = evs.iter().position(|e| e.gaussian.open).expect("gate opens");
    // n_s = 10 consecutive samples at or above the margin before it.
    assert!(evs[opened + 1 - 10..=opened].iter().all(|e| e.gaussian.value.expect("ready") >= 0.05));
    assert!(matches!(evs[opened - 1].gaussian.reason, Some(NotCertified::Accumulating { .. })));
    assert_eq!(cert.gate(CertificateKind::Gaussian).first_opened_at, Some(evs[opened].t));
}

#[test]
fn no_excitation_is_not_certified() {
    // Pure feedback, no dither: Z has rank one.
    let stream =
        LinearScenario { steps: 600, ..scalar(-1.0, -1.0, Process::Gaussian { sigma: 0.05 }, 0.0) };
    // With trapezoidal integrals of both y and u = K y, ∫u = K ∫y exactly. (With the
    // zero-order-hold rule the two integrals use different quadratures and are not collinear.)
    let mut cfg = config(1, 1, vec![-1.0], 0.2);
    cfg.regression.input_integral = InputIntegral::Trapezoidal;
    let mut cert = Certifier::new(cfg).expect("valid");
    let evs = run(&mut cert, &stream, 3);
    assert!(evs.iter().all(|e| !e.gaussian.open));
    assert!(matches!(
        evs.last().expect("non-empty").gaussian.reason,
        Some(NotCertified::InsufficientExcitation)
    ));
}

#[test]
fn bad_samples_are_rejected_or_skipped_and_never_certified() {
    let stream =
        LinearScenario { steps: 600, ..scalar(-1.0, -1.0, Process::Gaussian { sigma: 0.05 }, 1.0) };
    let traj = run_scenario(&stream, 5);
    let mut reject = Certifier::new(config(1, 1, vec![-1.0], 0.2)).expect("valid");
    let mut skip = Certifier::new(CertifierConfig {
        bad_samples: BadSamplePolicy::Skip,
        ..config(1, 1, vec![-1.0], 0.2)
    })
    .expect("valid");
    for k in 0..traj.len() {
        let (t, y, u) = (traj.t[k], traj.output(k), traj.input(k));
        if k % 97 == 50 {
            let err = reject.push(t, &[f64::NAN], u).unwrap_err();
            assert!(matches!(err, CertifyError::Regression(RegressionError::NonFinite { .. })));
            let ev = skip.push(t, &[f64::NAN], u).expect("skip policy");
            assert_eq!(ev.gaussian.reason, Some(NotCertified::SkippedSample));
            assert!(!ev.gaussian.open && ev.gaussian.value.is_none());
            // A repeated time is bad too.
            assert!(reject.push(traj.t[k - 1], y, u).is_err());
        } else {
            let a = reject.push(t, y, u).expect("valid");
            let b = skip.push(t, y, u).expect("valid");
            // Same estimate; only the gates differ (a skip closes the skip policy's gate).
            assert_eq!(
                (a.beta_hat(), a.rho(), a.gaussian.value),
                (b.beta_hat(), b.rho(), b.gaussian.value)
            );
        }
    }
    assert_eq!(skip.skipped(), (0..traj.len()).filter(|k| k % 97 == 50).count() as u64);
    assert!(matches!(
        reject.push(100.0, &[1.0, 2.0], &[0.0]),
        Err(CertifyError::Regression(RegressionError::DimensionMismatch { .. }))
    ));
}

#[test]
fn checkpoint_and_restore_continue_bit_identically() {
    let stream = two_state();
    let traj = run_scenario(&stream, 11);
    let cfg = CertifierConfig {
        regression: RegressionConfig {
            estimator: Estimator::Instrumented,
            ..config(2, 2, vec![0.0; 4], 0.5).regression
        },
        ambiguity: Some(AmbiguityConfig::paper(150)),
        ..config(2, 2, vec![-0.5, 0.1, 0.0, -0.8], 0.5)
    };
    let mut whole = Certifier::new(cfg.clone()).expect("valid");
    let all: Vec<Evidence> = (0..traj.len())
        .map(|k| whole.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid"))
        .collect();
    let mut first = Certifier::new(cfg).expect("valid");
    let split = 777;
    for k in 0..split {
        first.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid");
    }
    let sealed = first.checkpoint().expect("serialises");
    let json = first.checkpoint_json().expect("serialises");
    let mut second = Certifier::restore(&sealed).expect("restores");
    for k in split..traj.len() {
        let ev = second.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid");
        let want = &all[k];
        assert_eq!(ev.beta_hat().map(f64::to_bits), want.beta_hat().map(f64::to_bits));
        assert_eq!(ev.rho().map(f64::to_bits), want.rho().map(f64::to_bits));
        assert_eq!(ev, *want);
    }
    assert_eq!(second, whole);
    // A corrupted checkpoint is refused, not trusted: every flipped bit of the header and
    // of a sample of the payload is caught (by the checksum, or before it by the header), in
    // both encodings.
    for bytes in [&sealed[..], json.as_bytes()] {
        let positions = (0..bytes.len()).filter(|&i| i < 400 || i % 61 == 0);
        for i in positions {
            let mut damaged = bytes.to_vec();
            damaged[i] ^= 1 << (i % 8);
            assert!(Certifier::restore(&damaged).is_err(), "flipped bit at byte {i} was accepted");
        }
        assert!(Certifier::restore(&bytes[..bytes.len() / 2]).is_err());
    }
    assert!(Certifier::restore("{").is_err());
    assert!(Certifier::restore("").is_err());
    // The binary encoding is the smaller.
    assert!(sealed.len() * 2 < json.len(), "{} against {}", sealed.len(), json.len());
    // Past the checksum (re-sealed after an edit), the state is checked against itself.
    let payload = crate::support::json_payload(&json);
    let config = second.config().clone();
    let reseal = |edited: String| crate::support::reseal_json(&edited, &config);
    assert!(
        Certifier::restore(reseal(payload.replace("\"window\":150", "\"window\":151"))).is_err()
    );
    // A spike count that disagrees with the values in the window.
    let at = payload.find("\"spikes\":").expect("spike count serialised") + "\"spikes\":".len();
    let digits = payload[at..].chars().take_while(char::is_ascii_digit).count();
    let count: usize = payload[at..at + digits].parse().expect("a count");
    let tampered = format!("{}{}{}", &payload[..at], count + 1, &payload[at + digits..]);
    assert!(Certifier::restore(reseal(tampered)).is_err());
    // A Gram entry that no longer matches the window it summarises.
    let at = payload.find("\"g\":[").expect("Gram sums serialised") + "\"g\":[".len();
    let end = at + payload[at..].find(',').expect("an entry");
    let tampered = format!("{}-5.0{}", &payload[..at], &payload[end..]);
    let err = Certifier::restore(reseal(tampered)).expect_err("refused");
    assert!(err.to_string().contains("running sum G[0][0]"), "{err}");
}

#[test]
fn invalid_configurations_are_refused() {
    let ok = config(1, 1, vec![-1.0], 0.2);
    for (cfg, field) in [
        (CertifierConfig { conservatism: 0.0, ..ok.clone() }, "conservatism"),
        (CertifierConfig { conservatism: f64::NAN, ..ok.clone() }, "conservatism"),
        (CertifierConfig { margin: f64::INFINITY, ..ok.clone() }, "margin"),
        (CertifierConfig { consecutive: 0, ..ok.clone() }, "consecutive"),
        (CertifierConfig { gain: vec![f64::NAN], ..ok.clone() }, "gain"),
    ] {
        assert!(
            matches!(Certifier::new(cfg), Err(CertifyError::InvalidConfig { field: f, .. }) if f == field)
        );
    }
}

proptest! {
    #[test]
    fn wasserstein_never_exceeds_gaussian(beta in -10.0f64..10.0, rho in 0.0f64..10.0, eps in 0.0f64..1.0) {
        let gauss = certificate_value(beta, rho, 0.0);
        prop_assert_eq!(gauss, beta - rho);
        prop_assert!(certificate_value(beta, rho, eps) <= gauss);
        let grid = [0.0, eps / 2.0, eps];
        let mut out = [0.0; 3];
        certificate_surface(beta, rho, &grid, &mut out);
        prop_assert_eq!(out[0], gauss);
        prop_assert!(out[2] <= out[1] && out[1] <= out[0]);
    }
}

fn laplace_scalar() -> LinearScenario {
    LinearScenario { steps: 6000, ..scalar(-1.0, -1.0, Process::Laplace { scale: 0.1 }, 1.0) }
}

fn with_ambiguity(residuals: ResidualSource) -> CertifierConfig {
    CertifierConfig {
        ambiguity: Some(AmbiguityConfig::paper(150)),
        residuals,
        ..config(1, 1, vec![-1.0], 0.3)
    }
}

#[test]
fn both_certificates_come_from_one_certifier_and_keep_their_order() {
    let mut cert = Certifier::new(with_ambiguity(ResidualSource::OneStep)).expect("valid");
    let evs = run(&mut cert, &laplace_scalar(), 4);
    let mut both = 0;
    for ev in &evs {
        if let (Some(g), Some(w), Some(eps)) = (ev.gaussian.value, ev.wasserstein.value, ev.eps()) {
            both += 1;
            assert!(w <= g);
            assert!((0.015..=0.32).contains(&eps));
            assert_eq!(
                w,
                certificate_value(ev.beta_hat().expect("ready"), ev.rho().expect("ready"), eps)
            );
        }
        // The Wasserstein gate can only be open when the Gaussian one is.
        assert!(!ev.wasserstein.open || ev.gaussian.open);
        // Each verdict: a reason exactly when closed; value = estimate − radius.
        for kind in CertificateKind::ALL {
            let v = ev.verdict(kind);
            assert_eq!(v.open, v.reason.is_none(), "{kind:?} at t = {}", ev.t);
            assert_eq!(v.value.is_some(), v.radius.is_some(), "{kind:?} at t = {}", ev.t);
        }
        if let (Some(b), Some(r), Some(a)) = (ev.beta_hat(), ev.rho(), ev.ambiguity) {
            assert_eq!(ev.gaussian.value, Some(b - r));
            assert_eq!(ev.wasserstein.radius, Some(r * (1.0 + 2.0 * a.eps)));
        }
    }
    assert!(both > 5000);
    // Without an ambiguity model there is no Wasserstein certificate, and it says so.
    let mut plain = Certifier::new(config(1, 1, vec![-1.0], 0.3)).expect("valid");
    let ev = run(&mut plain, &laplace_scalar(), 4).pop().expect("non-empty");
    assert_eq!((ev.wasserstein.value, ev.eps()), (None, None));
    assert_eq!(ev.wasserstein.reason, Some(NotCertified::NoAmbiguityModel));
}

#[test]
fn one_step_residuals_keep_the_laplace_tails_that_horizon_residuals_average_away() {
    let mean_kurtosis = |source| {
        let mut cert = Certifier::new(with_ambiguity(source)).expect("valid");
        let ks: Vec<f64> = run(&mut cert, &laplace_scalar(), 9)
            .iter()
            .skip(600)
            .filter_map(|e| e.ambiguity.and_then(|a| a.kurtosis))
            .collect();
        ks.iter().sum::<f64>() / ks.len() as f64
    };
    let one_step = mean_kurtosis(ResidualSource::OneStep);
    let horizon = mean_kurtosis(ResidualSource::Horizon);
    // Laplace increments: excess kurtosis 3 per step, 3/h = 0.6 for a sum of h = 5 steps
    // (overlapping columns are not independent, so only the ordering and rough size are tested).
    assert!(one_step > 2.0, "one-step kurtosis {one_step}");
    assert!(horizon < 1.2 && horizon < one_step - 1.0, "horizon kurtosis {horizon}");
}

/// With several outputs, `ε` and its statistics are the largest over one ambiguity radius per
/// output, each fed the one-step residual of its output whenever the regression is ready: an
/// independent regression and radii, fed the same way, give the same numbers bit for bit at
/// every sample (through warm-up, the σ0 calibration and spikes).
#[test]
fn the_ambiguity_level_of_several_outputs_is_the_largest_of_their_radii() {
    use streamcert::ambiguity::AmbiguityRadius;
    use streamcert::regression::{EstimateStatus, SlidingRegression};
    let (p, m) = (2usize, 1usize);
    let reg_cfg = RegressionConfig::new(p, m, 40, 3, 1e-4);
    let amb_cfg = AmbiguityConfig::paper(30);
    let mut cfg = CertifierConfig::new(reg_cfg, vec![-1.0, 0.5], 0.2, 0.05, 10);
    cfg.ambiguity = Some(amb_cfg);
    let mut cert = Certifier::new(cfg).expect("valid");
    let mut reg = SlidingRegression::new(reg_cfg).expect("valid");
    let mut radii: Vec<_> = (0..p).map(|_| AmbiguityRadius::new(amb_cfg).expect("valid")).collect();
    let (mut x, mut state, mut resid) = (0.3f64, [0.0f64; 3], [0.0; 2]);
    for k in 0..400 {
        x = 3.9 * x * (1.0 - x);
        let spike = if k % 53 == 0 { 8.0 } else { 1.0 };
        state = [
            0.9 * state[0] + 0.1 * state[2] + spike * (x - 0.5),
            0.8 * state[1] - 0.2 * state[0] + 0.3 * (x * x - 0.3),
            0.95 * state[2] + (x - 0.5),
        ];
        let t = 0.5 * k as f64;
        let ev = cert.push(t, &state[..p], &state[p..]).expect("valid");
        reg.push(t, &state[..p], &state[p..]).expect("valid");
        if reg.estimate().status == EstimateStatus::Ready
            && reg.residual(ResidualSource::OneStep, &mut resid)
        {
            for (a, &r) in radii.iter_mut().zip(&resid) {
                let _ = a.push(r);
            }
        }
        let snaps: Vec<_> = radii.iter().map(AmbiguityRadius::snapshot).collect();
        let eps = snaps.iter().map(|s| s.eps).fold(f64::NEG_INFINITY, f64::max);
        let spikes = snaps.iter().map(|s| s.spike_fraction).fold(f64::NEG_INFINITY, f64::max);
        let kurtosis = snaps.iter().filter_map(|s| s.kurtosis).reduce(f64::max);
        let level = ev.ambiguity.expect("an ambiguity model is configured");
        assert_eq!(level.eps.to_bits(), eps.to_bits(), "sample {k}");
        assert_eq!(level.spike_fraction.to_bits(), spikes.to_bits(), "sample {k}");
        assert_eq!(level.kurtosis.map(f64::to_bits), kurtosis.map(f64::to_bits), "sample {k}");
    }
    assert!(radii.iter().all(|a| a.snapshot().kurtosis.is_some()), "the tails were reached");
}

/// A declared gap ([`Certifier::gap`]) is a gap in the time column: the evidence after it is
/// that of the same samples with every time after the gap shifted far enough for the gap
/// detector to see it (times on a binary grid, so the shift is exact), but for the step the
/// gap's reason quotes; and a checkpoint taken with the gap pending continues bit for bit.
#[test]
fn a_declared_gap_is_a_gap_in_the_time_column() {
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(1, 1, 60, 3, 1e-4)
    };
    let cfg = CertifierConfig::guarded(reg, vec![-1.0], 0.05, 5);
    let dt = 1.0 / 64.0;
    // A stable scalar loop with a seeded input.
    let mut state = 0x853c_49e6_748f_ea9bu64;
    let mut rnd = || {
        state =
            state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    };
    let (mut y, mut samples) = (0.3f64, Vec::new());
    for k in 0..3000u32 {
        let u =
            if k % 16 == 0 { rnd() } else { samples.last().map_or(0.0, |s: &(f64, f64, f64)| s.2) };
        samples.push((f64::from(k) * dt, y, u));
        y += dt * (-2.0 * y + u) + 0.01 * rnd();
    }
    let (cut, mut compared) = (1800, 0);
    let mut declared = Certifier::new(cfg.clone()).unwrap();
    let mut shifted = Certifier::new(cfg).unwrap();
    for (k, &(t, y, u)) in samples.iter().enumerate() {
        if k == cut {
            declared.gap();
            // A checkpoint with the gap pending restores to it: the run goes on from the
            // restored certifier, and the comparison below holds through it.
            let bytes = declared.checkpoint().unwrap();
            let restored = Certifier::restore(&bytes).unwrap();
            assert!(restored.checkpoint().unwrap() == bytes, "the restored state re-seals alike");
            declared = restored;
        }
        let a = declared.push(t, &[y], &[u]).unwrap();
        let b = shifted.push(if k >= cut { t + 64.0 } else { t }, &[y], &[u]).unwrap();
        if k == cut {
            assert!(matches!(a.calibrated.reason, Some(NotCertified::Gap { .. })), "{a:?}");
            assert!(matches!(b.calibrated.reason, Some(NotCertified::Gap { .. })), "{b:?}");
            assert_eq!(a.columns, 0);
            continue;
        }
        for (x, z) in [(&a.gaussian, &b.gaussian), (&a.calibrated, &b.calibrated)] {
            assert_eq!(x.value.map(f64::to_bits), z.value.map(f64::to_bits), "sample {k}");
            assert_eq!(x.open, z.open, "sample {k}");
        }
        assert_eq!(a.columns, b.columns);
        compared += usize::from(k > cut && a.calibrated.value.is_some());
    }
    assert_eq!((declared.gaps(), shifted.gaps()), (1, 1));
    assert!(compared > 500, "{compared} calibrated values compared after the gap");
}
