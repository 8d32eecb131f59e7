//! streamcert-ambiguity: sliding kurtosis against a two-pass recompute at every step on hard
//! streams, the behaviour of `ε` on seeded residual streams, and configuration errors.

use proptest::prelude::*;
use streamcert::ambiguity::{
    AmbiguityConfig, AmbiguityError, AmbiguityRadius, SlidingKurtosis, SpikeScale,
};
use streamcert::dynamics::{Disturbance, DisturbanceConfig, Process};

fn stream(process: Process, n: usize, seed: u64) -> Vec<f64> {
    let mut d = Disturbance::new(DisturbanceConfig::stationary(process), seed).expect("valid");
    (0..n).map(|k| d.random(k as f64)).collect()
}

/// Two-pass `(mean, m2, m4)` of a slice.
fn two_pass(x: &[f64]) -> (f64, f64, f64) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let m2 = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    let m4 = x.iter().map(|v| (v - mean).powi(4)).sum::<f64>() / n;
    (mean, m2, m4)
}

fn check_against_two_pass(name: &str, xs: &[f64], window: usize) {
    let mut k = SlidingKurtosis::new(window).expect("valid");
    for (i, &x) in xs.iter().enumerate() {
        k.push(x).expect("finite");
        let w = &xs[(i + 1).saturating_sub(window)..=i];
        if w.len() < 4 {
            continue;
        }
        let (mean, m2, m4) = two_pass(w);
        let got_mean = k.mean().expect("non-empty");
        let got_var = k.variance().expect("non-empty");
        let scale = w.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        assert!(
            (got_mean - mean).abs() <= 1e-12 * scale,
            "{name} step {i}: mean {got_mean} vs {mean}"
        );
        assert!((got_var - m2).abs() <= 1e-10 * m2, "{name} step {i}: var {got_var} vs {m2}");
        // Kurtosis m4/m2² (>= 1) compared relatively; excess = that − 3.
        let want = m4 / (m2 * m2);
        let got = k.excess_kurtosis().expect("spread") + 3.0;
        assert!((got - want).abs() <= 1e-10 * want, "{name} step {i}: kurtosis {got} vs {want}");
    }
}

#[test]
fn sliding_kurtosis_equals_two_pass_at_every_step() {
    let n = 20_000;
    let gauss = stream(Process::Gaussian { sigma: 1.0 }, n, 1);
    let laplace = stream(Process::Laplace { scale: 0.5 }, n, 2);
    let spikes = stream(
        Process::LaplaceSpikes {
            scale: 1.0,
            spike_prob: 0.02,
            spike_min: 1e5,
            spike_max: 1e6,
            sigma0: 1.0,
        },
        n,
        3,
    );
    let offset: Vec<f64> =
        stream(Process::Gaussian { sigma: 1.0 }, n, 4).iter().map(|v| v + 1e5).collect();
    // Regime switches: the mean and the scale jump.
    let switching: Vec<f64> = gauss
        .iter()
        .enumerate()
        .map(|(i, v)| if (i / 500) % 2 == 0 { v * 1e-3 } else { 1e3 + v * 1e3 })
        .collect();
    for (name, xs) in
        [("gauss", &gauss), ("laplace", &laplace), ("spikes", &spikes), ("switching", &switching)]
    {
        for window in [4, 150] {
            check_against_two_pass(name, xs, window);
        }
    }
    // With an offset of 1e5 σ each deviation x − mean already carries a rounding error of
    // about 1e-11 σ in any algorithm, two-pass included; a window of 4 values amplifies that
    // beyond 1e-10 in the kurtosis (a conditioning limit, not an algorithmic one), so the
    // offset stream is checked at the paper's window.
    check_against_two_pass("offset", &offset, 150);
}

fn mean_snapshot(process: Process, seed: u64) -> (f64, f64, f64, f64) {
    let mut amb = AmbiguityRadius::new(AmbiguityConfig::paper(150)).expect("valid");
    let xs = stream(process, 20_000, seed);
    let (mut eps, mut kurt, mut at_cap, mut n) = (0.0, 0.0, 0.0, 0.0);
    for (i, &x) in xs.iter().enumerate() {
        amb.push(x).expect("finite");
        if i >= 300 {
            let s = amb.snapshot();
            eps += s.eps;
            kurt += s.kurtosis.expect("spread");
            at_cap += f64::from(u8::from(s.eps >= 0.32));
            n += 1.0;
        }
    }
    (eps / n, kurt / n, at_cap / n, amb.snapshot().sigma0.expect("calibrated"))
}

#[test]
fn eps_tracks_the_tail_shape() {
    let (eps_g, kurt_g, _, _) = mean_snapshot(Process::Gaussian { sigma: 0.08 }, 10);
    let (eps_l, kurt_l, _, _) = mean_snapshot(Process::Laplace { scale: 0.5 }, 11);
    let spikes = Process::LaplaceSpikes {
        scale: 0.3,
        spike_prob: 0.055,
        spike_min: 20.0,
        spike_max: 40.0,
        sigma0: 0.08,
    };
    let (eps_s, _, cap_s, _) = mean_snapshot(spikes, 12);
    // Gaussian: κ_e ≈ 0 (sample mean within ±0.2 at N = 150), ε within 0.03 of the floor.
    assert!(kurt_g.abs() < 0.2, "gaussian mean kurtosis {kurt_g}");
    assert!(eps_g < 0.015 + 0.03, "gaussian mean eps {eps_g}");
    // Laplace: κ_e near 3 (the windowed estimate is biased low), ε clearly above Gaussian.
    assert!((2.0..4.0).contains(&kurt_l), "laplace mean kurtosis {kurt_l}");
    assert!(eps_l > eps_g + 0.05, "laplace eps {eps_l} vs gaussian {eps_g}");
    // Strong spikes: ε at the cap most of the time.
    assert!(cap_s > 0.9 && eps_s > 0.3, "spike eps {eps_s}, share at cap {cap_s}");
}

/// The spike fraction and `ε` of the streaming radius against a batch count over the same
/// window at every step, with a fixed `σ0` and with the MAD calibration (whose frozen `σ0`
/// recounts the window already held).
#[test]
fn spike_fraction_and_eps_equal_a_batch_count_at_every_step() {
    let spikes = Process::LaplaceSpikes {
        scale: 0.3,
        spike_prob: 0.055,
        spike_min: 4.5,
        spike_max: 7.5,
        sigma0: 0.08,
    };
    let xs = stream(spikes, 5_000, 21);
    for (window, scale) in [
        (150, SpikeScale::Fixed { sigma0: 0.08 }),
        (150, SpikeScale::Calibrated { samples: 100 }),
        (7, SpikeScale::Calibrated { samples: 30 }),
    ] {
        let cfg = AmbiguityConfig { spike_scale: scale, ..AmbiguityConfig::paper(window) };
        let mut amb = AmbiguityRadius::new(cfg).expect("valid");
        for (i, &x) in xs.iter().enumerate() {
            amb.push(x).expect("finite");
            let snap = amb.snapshot();
            let w = &xs[(i + 1).saturating_sub(window)..=i];
            let want = snap.sigma0.map_or(0.0, |s0| {
                w.iter().filter(|v| v.abs() > 3.0 * s0).count() as f64 / w.len() as f64
            });
            assert!(
                (snap.spike_fraction - want).abs() <= 1e-15,
                "window {window} step {i}: fraction {} vs {want}",
                snap.spike_fraction
            );
            assert_eq!(snap.eps, cfg.radius(snap.kurtosis, snap.spike_fraction));
            assert!(amb.is_consistent());
        }
    }
}

#[test]
fn calibrated_scale_is_the_gaussian_sigma() {
    let (_, _, _, sigma0) = mean_snapshot(Process::Gaussian { sigma: 0.08 }, 13);
    // MAD over 150 values: standard error of the scale about 0.08 · 1.17/√150 ≈ 0.0077.
    assert!((sigma0 - 0.08).abs() < 0.03, "calibrated sigma0 {sigma0}");
}

#[test]
fn bad_configurations_are_typed_errors() {
    let ok = AmbiguityConfig::paper(150);
    let cases = [
        AmbiguityConfig { tail_window: 3, ..ok },
        AmbiguityConfig { eps_floor: 0.4, ..ok },
        AmbiguityConfig { eps_floor: -0.1, ..ok },
        AmbiguityConfig { eps_cap: f64::NAN, ..ok },
        AmbiguityConfig { alpha_kurtosis: -1.0, ..ok },
        AmbiguityConfig { alpha_spike: f64::INFINITY, ..ok },
        AmbiguityConfig { spike_scale: SpikeScale::Fixed { sigma0: 0.0 }, ..ok },
        AmbiguityConfig { spike_scale: SpikeScale::Calibrated { samples: 2 }, ..ok },
    ];
    for cfg in cases {
        let err = AmbiguityRadius::new(cfg).expect_err("invalid");
        assert!(matches!(
            err,
            AmbiguityError::TailWindowTooShort { .. }
                | AmbiguityError::InvalidBounds { .. }
                | AmbiguityError::InvalidParameter { .. }
                | AmbiguityError::CalibrationTooShort { .. }
        ));
    }
    let mut amb = AmbiguityRadius::new(ok).expect("valid");
    assert!(matches!(amb.push(f64::NAN), Err(AmbiguityError::NonFinite(_))));
}

proptest! {
    #[test]
    fn radius_stays_within_its_bounds(k in -10.0f64..1e6, s in 0.0f64..1.0, floor in 0.0f64..0.5, extra in 0.0f64..1.0) {
        let cfg = AmbiguityConfig { eps_floor: floor, eps_cap: floor + extra, ..AmbiguityConfig::paper(150) };
        let eps = cfg.radius(Some(k), s);
        prop_assert!(eps >= floor && eps <= floor + extra);
        prop_assert_eq!(cfg.radius(None, 0.0), floor);
    }
}

/// A restored sliding-moments state whose ring index is out of range (found by the
/// checkpoint fuzz target) is refused, not read.
#[test]
fn a_restored_window_with_indices_out_of_range_is_refused() {
    let mut k = streamcert::ambiguity::SlidingKurtosis::new(20).expect("valid");
    for i in 0..30 {
        k.push(f64::from(i).sin()).expect("finite");
    }
    assert!(k.is_consistent());
    let json = serde_json::to_string(&k).expect("serialises");
    for (from, to) in [("\"head\":10", "\"head\":37"), ("\"len\":20", "\"len\":21")] {
        assert!(json.contains(from), "{json}");
        let bad: streamcert::ambiguity::SlidingKurtosis =
            serde_json::from_str(&json.replace(from, to)).expect("parses");
        assert!(!bad.is_consistent());
    }
    // Running sums that disagree with the window are refused too.
    let v: serde_json::Value = serde_json::from_str(&json).expect("json");
    let mut edited = v.clone();
    edited["s"][1] = serde_json::json!(v["s"][1].as_f64().expect("sum") * 2.0);
    let bad: streamcert::ambiguity::SlidingKurtosis =
        serde_json::from_value(edited).expect("parses");
    assert!(!bad.is_consistent());
}

/// `push_and_snapshot` is `push` then `snapshot`, bit for bit, through calibration of `σ0`,
/// spikes entering and leaving, recomputes, and a non-finite value (an error, nothing
/// absorbed, in both).
#[test]
fn push_and_snapshot_is_push_then_snapshot() {
    let cfg = AmbiguityConfig::paper(20);
    let (mut fused, mut apart) =
        (AmbiguityRadius::new(cfg).expect("valid"), AmbiguityRadius::new(cfg).expect("valid"));
    let mut x = 0.3f64;
    for k in 0..600 {
        x = 3.9 * x * (1.0 - x);
        let v = match k {
            250 => f64::NAN,
            _ if k % 37 == 0 => 40.0 * (x - 0.5),
            _ => x - 0.5,
        };
        let got = fused.push_and_snapshot(v);
        let want = apart.push(v).map(|()| apart.snapshot());
        match (got, want) {
            (Ok(a), Ok(b)) => {
                let bits = |s: streamcert::ambiguity::Ambiguity| {
                    [s.eps, s.kurtosis.unwrap_or(-1.0), s.spike_fraction, s.sigma0.unwrap_or(-1.0)]
                        .map(f64::to_bits)
                };
                assert_eq!(bits(a), bits(b), "value {k}");
            }
            (Err(_), Err(_)) => assert!(v.is_nan(), "value {k}"),
            (a, b) => panic!("value {k}: {a:?} against {b:?}"),
        }
        assert_eq!(fused, apart, "value {k}");
    }
}
