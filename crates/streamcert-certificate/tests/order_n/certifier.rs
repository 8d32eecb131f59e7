//! The certifier at `[regression] order = 2`: what it refuses, the calibrated verdict that
//! carries the certificate of order `n` through the gate, the gap, and a checkpoint that
//! continues the run bit for bit.

use streamcert_certificate::{
    Calibration, Certifier, CertifierConfig, CertifyError, Evidence, NonlinearConfig, NotCertified,
    OrderNCertificate,
};
use streamcert_regression::{LoopModel, RegressionConfig};

use crate::support::Loop;

/// `ÿ + 1.2 ẏ + y = u + 0.1` under `u = 0.7625 y_m + d` (closed loop `(s + 0.25)(s + 0.95)`,
/// five times a margin of 0.05), sensor noise `σ = 0.01`: `(t, y_m, u)`.
fn record(seed: u64, samples: usize) -> Vec<(f64, f64, f64)> {
    let mut out = Vec::with_capacity(samples);
    Loop { samples, ..Loop::new(&[1.2, 1.0], 0.7625) }.run(seed, |t, y, u| {
        out.push((t, y, u));
        true
    });
    out
}

fn config(consecutive: usize) -> CertifierConfig {
    let regression = RegressionConfig {
        order: LoopModel::of_order(2).unwrap(),
        ..RegressionConfig::new(1, 1, 2000, 50, 0.0)
    };
    let mut cfg = CertifierConfig::new(regression, vec![0.7625], 1.0, 0.05, consecutive);
    cfg.calibration = Some(Calibration::new(0.01));
    cfg
}

fn refused(cfg: CertifierConfig) -> &'static str {
    match Certifier::new(cfg) {
        Err(CertifyError::InvalidConfig { field, .. }) => field,
        other => panic!("not refused: {other:?}"),
    }
}

#[test]
fn what_order_n_does_not_support_is_refused_by_name() {
    let mut two = config(1);
    two.regression.outputs = 2;
    two.gain = vec![0.7625, 0.0];
    assert_eq!(refused(two), "regression.outputs");
    let mut bare = config(1);
    bare.calibration = None;
    assert_eq!(refused(bare), "calibration");
    let mut nonlinear = config(1);
    nonlinear.nonlinear = Some(NonlinearConfig::default());
    assert_eq!(refused(nonlinear), "nonlinear");
    let mut small = config(1);
    small.regression.window = 100;
    assert_eq!(refused(small), "min_rows");
    assert!(Certifier::new(config(1)).is_ok());
}

#[test]
fn the_calibrated_verdict_is_the_certificate_of_order_n_through_the_gate() {
    let samples = record(1, 4000);
    let cfg = config(1);
    let mut cert = Certifier::new(cfg.clone()).unwrap();
    let mut direct = OrderNCertificate::new(cfg.order_n().unwrap()).unwrap();
    let mut gated = Certifier::new(config(50)).unwrap();
    let (mut first_open, mut first_gated) = (None, None);
    for (k, &(t, y, u)) in samples.iter().enumerate() {
        let ev = cert.push(t, &[y], &[u]).unwrap();
        direct.push(t, y, &[u]).unwrap();
        assert_eq!(ev.calibrated.open, direct.open(), "sample {k}");
        assert_eq!(ev.gaussian.reason, Some(NotCertified::FirstOrderOnly));
        assert_eq!(ev.wasserstein.reason, Some(NotCertified::FirstOrderOnly));
        assert_eq!(ev.columns, direct.rows());
        if ev.calibrated.open {
            assert!(ev.calibrated.value.unwrap() >= 0.05);
            assert_eq!(ev.calibrated_horizon, Some(50));
            first_open.get_or_insert(k);
        } else if direct.latest().is_none() {
            assert!(matches!(ev.calibrated.reason, Some(NotCertified::WarmingUp { .. })));
        }
        if gated.push(t, &[y], &[u]).unwrap().calibrated.open {
            first_gated.get_or_insert(k);
        }
    }
    // n_s = 50 consecutive samples: open 49 samples after the one-sample gate.
    let first = first_open.expect("certified");
    assert_eq!(first_gated, Some(first + 49));
}

#[test]
fn a_gap_restarts_the_window_and_a_checkpoint_continues_bit_for_bit() {
    let samples = record(2, 4000);
    let mut cert = Certifier::new(config(1)).unwrap();
    let mut evidence: Vec<Evidence> = Vec::new();
    for &(t, y, u) in &samples[..2500] {
        evidence.push(cert.push(t, &[y], &[u]).unwrap());
    }
    assert!(evidence.last().unwrap().calibrated.open);
    for bytes in [cert.checkpoint().unwrap(), cert.checkpoint_json().unwrap().into_bytes()] {
        let mut restored = Certifier::restore(&bytes).unwrap();
        let mut original = cert.clone();
        for &(t, y, u) in &samples[2500..] {
            let (a, b) =
                (original.push(t, &[y], &[u]).unwrap(), restored.push(t, &[y], &[u]).unwrap());
            assert_eq!(format!("{a:?}"), format!("{b:?}"));
        }
    }
    // A damaged state is refused, not run.
    let json = cert.checkpoint_json().unwrap();
    assert!(
        Certifier::restore(json.replace("\"head\":", "\"head\":9999999,\"was\":").as_bytes())
            .is_err()
    );
    cert.gap();
    let (t, y, u) = samples[2500];
    let ev = cert.push(t, &[y], &[u]).unwrap();
    assert!(matches!(ev.calibrated.reason, Some(NotCertified::Gap { .. })));
    assert!(!ev.calibrated.open);
    assert_eq!(ev.columns, 0);
}
