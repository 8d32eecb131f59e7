//! The calibrated certificate's configuration: its default windows, the risk its looks spend,
//! and the configurations it refuses, each with what would be valid.

use streamcert::certificate::{
    Calibration, Certifier, CertifierConfig, CertifyError, calibrated_radius, look_risk,
};
use streamcert::regression::Model;

use crate::calibrated::calibrated;

#[test]
fn default_windows_double_until_the_longest_holds_200_blocks() {
    let cal = Calibration::new(0.01);
    // At least five windows; more while the longest holds fewer than 200 blocks.
    assert_eq!(cal.window_lengths(150, 5), vec![150, 300, 600, 1200, 2400]);
    assert_eq!(cal.window_lengths(20, 5), vec![20, 40, 80, 160, 320, 640, 1280]);
    assert_eq!(cal.window_lengths(50, 5), vec![50, 100, 200, 400, 800, 1600]);
    assert_eq!(cal.window_lengths(2000, 5), vec![2000, 4000, 8000, 16000, 32000]);
    let capped = Calibration { max_window: Some(600), ..cal };
    assert_eq!(capped.window_lengths(20, 5), vec![20, 40, 80, 160, 320]);
    let fixed = Calibration { windows: Some(2), ..cal };
    assert_eq!(fixed.window_lengths(20, 5), vec![20, 40]);
}

/// Oracle: the shares sum to one, equal by default, proportional to the length when asked;
/// and a certifier's looks spend them (the first look of window `w` at `δ share_w / 2`).
#[test]
fn the_risk_split_across_windows() {
    use streamcert::certificate::RiskSplit;
    let lengths = [150, 300, 600, 1200, 2400];
    let equal = RiskSplit::Equal.shares(&lengths);
    assert_eq!(equal, vec![0.2; 5]);
    let by_length = RiskSplit::ByLength.shares(&lengths);
    for (s, m) in by_length.iter().zip(lengths) {
        assert!((s - m as f64 / 4650.0).abs() < 1e-15, "{s}");
    }
    assert!((by_length.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    assert_eq!(Calibration::new(0.01).risk_split, RiskSplit::Equal);
    // Through a certifier: the shortest window's first look, under either split, has the
    // radius of its share's risk.
    use streamcert::dynamics::Process;
    let scenario = crate::support::scalar(-0.5, -1.0, Process::Gaussian { sigma: 0.1 }, 1.0);
    let traj = crate::support::run(&scenario, 77);
    for (split, share) in [(RiskSplit::Equal, 0.2), (RiskSplit::ByLength, 150.0 / 4650.0)] {
        let mut cfg = calibrated(1, vec![-1.0], 150, 10);
        cfg.calibration =
            cfg.calibration.map(|c| Calibration { risk_split: split, auto_batches: 0, ..c });
        let mut c = Certifier::new(cfg).unwrap();
        let mut checked = false;
        for i in 0..traj.len() {
            c.push(traj.t[i], traj.output(i), traj.input(i)).unwrap();
            if let Some(l) = c.calibrated_looks()[0].filter(|l| l.look == 1) {
                // The sliding windows split `1 − anchored_share` of δ.
                let sliding = 1.0 - Calibration::new(0.01).anchored_share;
                let want =
                    calibrated_radius(l.sd * l.sd, l.nu, look_risk(0.01, sliding * share, 1));
                assert!((l.radius - want).abs() <= 1e-12 * want, "{split:?}: {} {want}", l.radius);
                checked = true;
                break;
            }
        }
        assert!(checked, "{split:?}: no first look");
    }
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
}

#[test]
fn settings_out_of_range_are_refused_naming_the_field() {
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
    // The change guard's risk per comparison and the model guards' risk per test lie in
    // (0, 1).
    type WithRisk = fn(f64) -> Calibration;
    let risks: [(&str, WithRisk); 2] = [
        ("calibration.change_risk", |r| Calibration {
            change_risk: Some(r),
            ..Calibration::new(0.01)
        }),
        ("calibration.guard_risk", |r| Calibration {
            guard_risk: Some(r),
            ..Calibration::new(0.01)
        }),
    ];
    for (name, with) in risks {
        for (risk, valid) in
            [(0.0, false), (1.0, false), (f64::NAN, false), (1e-9, true), (0.5, true)]
        {
            let cfg = CertifierConfig {
                calibration: Some(with(risk)),
                ..calibrated(1, vec![-0.54], 150, 1)
            };
            match Certifier::new(cfg) {
                Ok(_) => assert!(valid, "{name} {risk} accepted"),
                Err(CertifyError::InvalidConfig { field, reason }) => {
                    assert!(!valid && field == name, "{risk}: {field} {reason}");
                    assert!(reason.contains("(0, 1)"), "{reason}");
                }
                Err(e) => panic!("{risk}: {e}"),
            }
        }
    }
}

/// The automatic batches (`auto_batches`, default 30): window `w` of `B_w` blocks takes
/// batches of `⌊B_w / max(30, 2d + 1)⌋` blocks (1, 2, 4, 8, 16 for the default windows from
/// `M = 150`), and where that is at least 2 the look's radius is the smaller of the radius in
/// batches of one block at `1 − auto_batch_risk` of the look's risk and the batched one at
/// `auto_batch_risk` (the union bound; default 0.2, and 0.5 here too); the window too short
/// for it keeps the radius at the whole risk, bit for bit. Under sensor noise (which batches
/// of one block overstate) the batched radius is the one that stands at some looks.
#[test]
fn automatic_batches_take_the_smaller_radius_at_their_shares_of_the_risk() {
    use streamcert::dynamics::{LinearScenario, Process};
    let scenario = LinearScenario {
        sensor_noise: 0.05,
        dither_hold: 0.2,
        steps: 4000,
        ..crate::support::scalar(-0.46, -2.0, Process::Gaussian { sigma: 0.1 }, 1.0)
    };
    let auto = calibrated(1, vec![-0.54], 150, 10);
    assert_eq!(auto.calibration.map(|c| c.auto_batch_risk), Some(0.2));
    let mut off = auto.clone();
    off.calibration = off.calibration.map(|c| Calibration { auto_batches: 0, ..c });
    // The default five windows (150 to 2400 columns), an equal share of δ each.
    let windows = 5.0;
    for share in [0.2, 0.5] {
        let mut cfg = auto.clone();
        cfg.calibration = cfg.calibration.map(|c| Calibration { auto_batch_risk: share, ..c });
        let (mut batched_won, mut compared) = (0, 0);
        for seed in 0..4 {
            let traj = crate::support::run(&scenario, 31_000 + seed);
            let (mut a, mut b) =
                (Certifier::new(cfg.clone()).unwrap(), Certifier::new(off.clone()).unwrap());
            for i in 0..traj.len() {
                a.push(traj.t[i], traj.output(i), traj.input(i)).unwrap();
                b.push(traj.t[i], traj.output(i), traj.input(i)).unwrap();
            }
            for (w, (la, lb)) in a.calibrated_looks().iter().zip(b.calibrated_looks()).enumerate() {
                let (Some(la), Some(lb)) = (la, lb) else { continue };
                assert_eq!((la.look, la.beta_hat.to_bits()), (lb.look, lb.beta_hat.to_bits()));
                if w == 0 {
                    // 30 blocks: batches of ⌊30 / 30⌋ = 1 block: no second radius.
                    assert_eq!(la.radius.to_bits(), lb.radius.to_bits());
                    continue;
                }
                let sliding = 1.0 - Calibration::new(0.01).anchored_share;
                let risk = look_risk(0.01, sliding / windows, la.look) * (1.0 - share);
                let first = calibrated_radius(lb.sd * lb.sd, lb.nu, risk);
                assert!(la.radius <= first * (1.0 + 1e-12), "window {w}: {} > {first}", la.radius);
                if la.radius < first * (1.0 - 1e-9) {
                    // The batched radius stood: at its share of the risk, from 30 batches
                    // (ν at most 30 − d = 27; 57 and more in batches of one block).
                    batched_won += 1;
                    let batched = look_risk(0.01, sliding / windows, la.look) * share;
                    let expected = calibrated_radius(la.sd * la.sd, la.nu, batched);
                    assert!((la.radius - expected).abs() <= 1e-12 * expected, "window {w}");
                    assert!(la.nu <= 27.0 && la.nu < lb.nu, "window {w}: ν {} / {}", la.nu, lb.nu);
                }
                compared += 1;
            }
        }
        assert_eq!(compared, 16, "four runs, the four longer windows");
        // Measured: 6 (share 0.2) and 8 (0.5) of these 16 looks (3 and 4 with
        // batches of a fixed 8 blocks, whose t quantile on the shorter long windows' few
        // batches outweighed the tighter spread).
        assert!(batched_won >= 4, "{share}: the batched radius stood at {batched_won} of 16");
    }
    for bad in [0.0, 1.0, f64::NAN] {
        let mut cfg = auto.clone();
        cfg.calibration = cfg.calibration.map(|c| Calibration { auto_batch_risk: bad, ..c });
        let err = Certifier::new(cfg).unwrap_err().to_string();
        assert!(err.contains("auto_batch_risk") && err.contains("(0, 1)"), "{err}");
    }
    // The blocks per batch, by the rule: about 30 batches, at least 2d + 1.
    let cal = Calibration::new(0.01);
    let rule: Vec<usize> = [30, 59, 60, 480, 481].map(|b| cal.auto_batch_blocks(b, 3)).into();
    assert_eq!(rule, [1, 1, 2, 16, 16]);
    // d = 21 (p = m = 10 with the intercept): 43 batches.
    assert_eq!((cal.auto_batch_blocks(85, 21), cal.auto_batch_blocks(86, 21)), (1, 2));
    let off = Calibration { auto_batches: 0, ..cal };
    assert_eq!(off.auto_batch_blocks(480, 3), 0);
    // Refused values, with what is valid.
    for bad in [1, 7] {
        let mut cfg = auto.clone();
        cfg.calibration = cfg.calibration.map(|c| Calibration { auto_batches: bad, ..c });
        let err = Certifier::new(cfg).unwrap_err().to_string();
        assert!(err.contains("auto_batches") && err.contains("at least 8"), "{err}");
    }
}
