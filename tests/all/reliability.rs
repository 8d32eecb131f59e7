//! Gaps, irregular sampling and skipped samples: the certifier restarts its window at a gap,
//! keeps `ε` at its floor on Gaussian data sampled irregularly, and closes every gate on a
//! skipped sample.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::ambiguity::AmbiguityConfig;
use streamcert::certificate::{
    BadSamplePolicy, Certifier, CertifierConfig, Evidence, NotCertified,
};
use streamcert::dynamics::{LinearScenario, Process};
use streamcert::regression::{InputIntegral, RegressionConfig};

use crate::support::{run as run_scenario, scalar};

fn config() -> CertifierConfig {
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(1, 1, 150, 5, 1e-4)
    };
    CertifierConfig {
        ambiguity: Some(AmbiguityConfig::paper(150)),
        ..CertifierConfig::new(reg, vec![-1.5], 0.1, 0.05, 10)
    }
}

/// Gaussian data on a 0.01 s grid: `ẏ = 0.5 y + u + w`, 60 s.
fn plant() -> LinearScenario {
    LinearScenario {
        dither_hold: 0.2,
        steps: 6000,
        ..scalar(0.5, -1.0, Process::Gaussian { sigma: 0.1 }, 1.0)
    }
}

/// Push the rows `keep` selects; return the evidence.
fn certify(cfg: &CertifierConfig, keep: impl Fn(usize, f64) -> bool) -> Vec<Evidence> {
    let traj = run_scenario(&plant(), 3);
    let mut cert = Certifier::new(cfg.clone()).expect("valid");
    (0..traj.len())
        .filter(|&i| keep(i, traj.t[i]))
        .map(|i| cert.push(traj.t[i], traj.output(i), traj.input(i)).expect("valid"))
        .collect()
}

#[test]
fn a_gap_restarts_the_window_and_closes_the_gates() {
    // 2 s of rows missing after t = 30 s.
    let hole = |_: usize, t: f64| !(30.0..32.0).contains(&t);
    let evidence = certify(&config(), hole);
    let at = evidence.iter().position(|e| e.t >= 32.0).expect("rows after the gap");
    assert!(evidence[at - 1].gaussian.open, "the gate was open before the gap");
    let gap = &evidence[at];
    assert!(
        matches!(gap.gaussian.reason, Some(NotCertified::Gap { dt, reference }) if dt > 2.0 && (reference - 0.01).abs() < 1e-9)
    );
    assert!(matches!(gap.wasserstein.reason, Some(NotCertified::Gap { .. })));
    assert!(!gap.gaussian.open && !gap.wasserstein.open);
    // The window restarts: warming up for the next M + h samples, no estimate across the gap.
    assert!(evidence[at..at + 150].iter().all(|e| e.beta_hat().is_none() && !e.gaussian.open));
    assert!(evidence[at + 200..].iter().any(|e| e.gaussian.open));
    // The residual across the gap never reaches ε: the kurtosis stays that of Gaussian noise.
    let worst = evidence[at..]
        .iter()
        .filter_map(|e| e.ambiguity.and_then(|a| a.kurtosis))
        .fold(f64::MIN, f64::max);
    assert!(worst < 2.0, "kurtosis after the gap {worst}");
    // With the detector effectively off, the window integrates across the gap and keeps
    // estimating as if nothing had happened (no restart, no gap reason; the column across
    // the gap is one long interval in the window).
    let off = CertifierConfig { gap_factor: 1e9, ..config() };
    let evidence = certify(&off, hole);
    assert!(evidence[at].beta_hat().is_some(), "{:?}", evidence[at].gaussian.reason);
    assert!(!matches!(evidence[at].gaussian.reason, Some(NotCertified::Gap { .. })));
}

#[test]
fn irregular_sampling_keeps_eps_where_regular_sampling_has_it() {
    // A random 70 % of the rows (steps of 0.01 to a few hundredths, no gap above 5×).
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let kept: Vec<bool> = (0..=6000).map(|_| rng.random::<f64>() < 0.7).collect();
    let evidence = certify(&config(), |i, _| kept[i] || i % 4 == 0);
    let eps: Vec<f64> = evidence.iter().filter_map(|e| e.eps()).collect();
    let mean = eps.iter().sum::<f64>() / eps.len() as f64;
    // Regular sampling of the same data is the reference: ε stays where it has it (its spike
    // fraction depends on the MAD-calibrated σ0 of eq. eps_est), and the residuals stay
    // Gaussian (excess kurtosis near 0).
    let regular = certify(&config(), |_, _| true);
    let reference: Vec<f64> = regular.iter().filter_map(|e| e.eps()).collect();
    let reference = reference.iter().sum::<f64>() / reference.len() as f64;
    let kurtosis: Vec<f64> =
        evidence.iter().filter_map(|e| e.ambiguity.and_then(|a| a.kurtosis)).collect();
    let kurtosis = kurtosis.iter().sum::<f64>() / kurtosis.len() as f64;
    assert!(kurtosis.abs() < 0.5, "mean excess kurtosis {kurtosis} under irregular sampling");
    let at_cap = eps.iter().filter(|&&e| e >= 0.32).count() as f64 / eps.len() as f64;
    assert!(
        (mean - reference).abs() < 0.03 && at_cap < 0.01,
        "mean ε {mean} (regular {reference}), share at the cap {at_cap}"
    );
    assert!(evidence.iter().all(|e| !matches!(e.gaussian.reason, Some(NotCertified::Gap { .. }))));
}

#[test]
fn a_skipped_sample_closes_every_gate_and_is_not_absorbed() {
    let cfg = CertifierConfig { bad_samples: BadSamplePolicy::Skip, ..config() };
    let traj = run_scenario(&plant(), 3);
    let mut cert = Certifier::new(cfg).expect("valid");
    let mut last = None;
    for i in 0..3000 {
        last = Some(cert.push(traj.t[i], traj.output(i), traj.input(i)).expect("valid"));
    }
    assert!(last.expect("evidence").gaussian.open);
    let before = cert.regression().clone();
    let ev = cert.push(traj.t[3000], &[f64::NAN], traj.input(3000)).expect("skipped");
    assert_eq!(ev.gaussian.reason, Some(NotCertified::SkippedSample));
    assert!(!ev.gaussian.open && !ev.wasserstein.open && !ev.calibrated.open);
    assert_eq!(cert.regression(), &before, "a skipped sample is not absorbed");
    assert_eq!(cert.skipped(), 1);
    // The same through the explicit call a caller (the CLI) makes for an unreadable row.
    let ev = cert.skip(f64::NAN);
    assert!(!ev.gaussian.open);
    assert_eq!(cert.skipped(), 2);
    // The gate needs n_s fresh samples again.
    let next = cert.push(traj.t[3000], traj.output(3000), traj.input(3000)).expect("valid");
    assert!(!next.gaussian.open);
}

/// Long runs: the running sums of the regression and the sliding moments of the ambiguity
/// radius against an exact recompute from their windows at checkpoints, on a stream with spikes
/// and a dynamic range of 10⁶ (values of order 10⁻³ with bursts of order 10³). `cargo test`
/// runs 10⁶ samples; `STREAMCERT_LONG_RUN=10000000 cargo test --release --test all long_run`
/// runs 10⁷. The largest relative drift is printed.
#[test]
fn long_run_drift_stays_below_1e_8() {
    let samples: usize =
        std::env::var("STREAMCERT_LONG_RUN").ok().and_then(|s| s.parse().ok()).unwrap_or(1_000_000);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut reg =
        streamcert::regression::SlidingRegression::new(RegressionConfig::new(1, 1, 150, 5, 1e-4))
            .expect("valid");
    let mut moments = streamcert::ambiguity::SlidingKurtosis::new(150).expect("valid");
    let (mut y, mut worst_moments, mut worst_sums) = (0.0f64, 0.0f64, 0.0f64);
    let checkpoints = 20;
    for k in 0..samples {
        let spike = if rng.random::<f64>() < 0.001 { 1e3 } else { 1e-3 };
        let u = spike * (rng.random::<f64>() - 0.5);
        y = 0.99 * y + u;
        reg.push(k as f64 * 0.01, &[y], &[u]).expect("valid sample");
        moments.push(u).expect("finite");
        if (k + 1) % (samples / checkpoints) == 0 {
            // check_statistics: every running sum within 1e-8 of its Cauchy–Schwarz scale; the
            // smallest decade that passes is the drift reported.
            reg.check_statistics(1e-8).expect("regression sums within 1e-8 of the recompute");
            let decade = (8..=16)
                .rev()
                .map(|e| 10f64.powi(-e))
                .find(|&tol| reg.check_statistics(tol).is_ok());
            worst_sums = worst_sums.max(decade.unwrap_or(1e-8));
            let values: Vec<f64> = moments.values().collect();
            let n = values.len() as f64;
            let mean = values.iter().sum::<f64>() / n;
            let m2 = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
            let m4 = values.iter().map(|v| (v - mean).powi(4)).sum::<f64>() / n;
            let (var, kurt) = (moments.variance().expect("full"), moments.excess_kurtosis());
            worst_moments = worst_moments.max(((var - m2) / m2).abs());
            if let Some(kurt) = kurt {
                let exact = m4 / (m2 * m2) - 3.0;
                worst_moments = worst_moments.max(((kurt - exact) / (exact.abs() + 3.0)).abs());
            }
        }
    }
    eprintln!(
        "{samples} samples: largest relative drift of the regression sums below {worst_sums:e}, \
         of the sliding moments {worst_moments:e}"
    );
    assert!(worst_moments <= 1e-8, "sliding moments drift {worst_moments:e}");
}
