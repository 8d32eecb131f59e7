//! The calibrated certificate's configuration: its default windows, the risk its looks spend,
//! and the configurations it refuses, each with what would be valid.

use streamcert::certificate::{Calibration, Certifier, CertifierConfig, CertifyError, look_risk};
use streamcert::regression::Model;

use crate::calibrated::calibrated;

#[test]
fn default_windows_double_until_the_longest_holds_200_blocks() {
    let cal = Calibration::new(0.01);
    assert_eq!(cal.window_lengths(150, 5), vec![150, 300, 600, 1200]);
    assert_eq!(cal.window_lengths(20, 5), vec![20, 40, 80, 160, 320, 640, 1280]);
    assert_eq!(cal.window_lengths(2000, 5), vec![2000, 4000, 8000, 16000]);
    let capped = Calibration { max_window: Some(600), ..cal };
    assert_eq!(capped.window_lengths(20, 5), vec![20, 40, 80, 160, 320]);
    let fixed = Calibration { windows: Some(2), ..cal };
    assert_eq!(fixed.window_lengths(20, 5), vec![20, 40]);
}

#[test]
fn look_risks_sum_to_the_share_of_delta() {
    let total: f64 = (1..200_000u64).map(|k| look_risk(0.01, 0.25, k)).sum();
    assert!((total - 0.0025).abs() < 1e-7, "{total}");
    assert!(look_risk(0.01, 1.0, 1) == 0.005);
}

#[test]
fn configurations_without_a_valid_bound_are_refused_with_what_is_valid() {
    // With the guards (the default): the nonlinearity guard's larger fit has
    // u = p + m + 1 + 2p unknowns under the affine model, so h (u + 2) = 35 for p = m = 1,
    // h = 5 (30 through the origin); without them h (p + m + 3) = 25 (the intercept is one
    // more unknown) and h (p + m + 2) = 20 through the origin.
    let err = Certifier::new(calibrated(1, vec![-0.54], 34, 1)).unwrap_err();
    let CertifyError::InvalidConfig { field: "window", reason } = err else { panic!("{err}") };
    assert!(reason.contains("smallest valid window is 35"), "{reason}");
    assert!(reason.contains("without the guards it would be 25"), "{reason}");
    assert!(Certifier::new(calibrated(1, vec![-0.54], 35, 1)).is_ok());
    let model = |p: usize, window: usize, origin: bool, guards: bool| {
        let mut cfg = calibrated(p, vec![if p == 1 { -0.54 } else { 0.0 }; p * p], window, 1);
        if origin {
            cfg.regression.model = Model::ThroughOrigin;
        }
        if !guards {
            cfg.calibration = cfg.calibration.map(Calibration::unguarded);
        }
        Certifier::new(cfg)
    };
    // (p, origin, guards, smallest): p = m = 2 has 2 + 2 + 1 (+ 4) unknowns.
    for (p, origin, guards, smallest) in [
        (1, true, true, 30),
        (1, false, false, 25),
        (1, true, false, 20),
        (2, false, true, 55),
        (2, true, true, 50),
        (2, false, false, 35),
        (2, true, false, 30),
    ] {
        let err = model(p, smallest - 1, origin, guards).unwrap_err();
        let text = format!("smallest valid window is {smallest}");
        assert!(err.to_string().contains(&text), "{p} {origin} {guards}: {err}");
        assert!(model(p, smallest, origin, guards).is_ok());
    }
    for margin in [0.0, -0.1] {
        let cfg = CertifierConfig { margin, ..calibrated(1, vec![-0.54], 150, 1) };
        let err = Certifier::new(cfg).unwrap_err();
        assert!(matches!(err, CertifyError::InvalidConfig { field: "margin", .. }), "{err}");
    }
    let cfg = CertifierConfig {
        calibration: Some(Calibration { look_spacing: 0.0, ..Calibration::new(0.01) }),
        ..calibrated(1, vec![-0.54], 150, 1)
    };
    assert!(Certifier::new(cfg).is_err());
    // Batches of b blocks: h (b (p + m + 2) + 1) = 85 for b = 4, 165 for b = 8 under the
    // affine model (h (b (p + m + 1) + 1) = 65, 125 through the origin); b in 1..=8.
    let batched = |window, batch_blocks| CertifierConfig {
        calibration: Some(Calibration { batch_blocks, ..Calibration::new(0.01) }),
        ..calibrated(1, vec![-0.54], window, 1)
    };
    for (batch, smallest) in [(4, 85), (8, 165)] {
        let err = Certifier::new(batched(smallest - 1, batch)).unwrap_err();
        let CertifyError::InvalidConfig { field: "window", reason } = err else { panic!("{err}") };
        assert!(reason.contains(&format!("smallest valid window is {smallest}")), "{reason}");
        assert!(reason.contains("fewer blocks per batch"), "{reason}");
        assert!(Certifier::new(batched(smallest, batch)).is_ok());
    }
    for batch in [0, 9] {
        let err = Certifier::new(batched(1000, batch)).unwrap_err();
        let CertifyError::InvalidConfig { field, .. } = err else { panic!("{err}") };
        assert_eq!(field, "calibration.batch_blocks");
    }
}
