//! The live network certifier against its oracles: two separate certifiers for the local
//! certificates, Lemma 1 and the dense composition for the network rate, staleness, and the
//! network gate against the true network rate of a synthetic network over seeded runs.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::certificate::{CertificateKind, Certifier, CertifierConfig};
use streamcert::compose::{Network, lemma1_rate, network_rate, warning_gain};
use streamcert::dynamics::{Coupling, LinearScenario, Process};
use streamcert::experiments::{Experiment, G5Dataset};
use streamcert::network::{
    EpochReport, NetworkCertifier, NetworkConfig, NotCertifiedLocal, SubsystemSpec,
};
use streamcert::regression::{InputIntegral, RegressionConfig};

use crate::support::{run, scalar};

fn local(k: f64) -> CertifierConfig {
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(1, 1, 150, 5, 1e-4)
    };
    CertifierConfig::new(reg, vec![k], 0.3, 0.1, 10)
}

#[test]
fn g5_bidirectional_equals_two_certifiers_and_lemma_1() {
    let setting = Experiment::Two.setting();
    let data =
        G5Dataset { coupling: Coupling::Bidirectional, ..G5Dataset::defaults(Experiment::Two) }
            .run_seeded(1)
            .expect("data");
    let gamma = 0.4;
    let cfg = NetworkConfig::new(
        vec![
            SubsystemSpec::new("A", local(setting.k1)),
            SubsystemSpec::new("B", local(setting.k4)),
        ],
        vec![(0, 1, gamma), (1, 0, gamma)],
        0.5,
    );
    let mut net = NetworkCertifier::new(cfg).expect("valid");
    let mut separate =
        [local(setting.k1), local(setting.k4)].map(|c| Certifier::new(c).expect("valid"));
    // values[i][j]: subsystem i's Gaussian certificate after sample j, from its own certifier.
    let mut values: [Vec<Option<f64>>; 2] = [Vec::new(), Vec::new()];
    let mut reports: Vec<EpochReport> = Vec::new();
    for j in 0..data.len() {
        for i in 0..2 {
            let (y, u) = (&data.output(j)[i..=i], &data.input(j)[i..=i]);
            let ev = net.push(i, data.t[j], y, u, |r| reports.push(r.clone())).expect("sample");
            let own = separate[i].push(data.t[j], y, u).expect("sample");
            assert_eq!(ev, own, "subsystem {i} at step {j}");
            values[i].push(own.gaussian.value);
        }
    }
    assert!(reports.len() >= 30, "{} epochs", reports.len());
    let mut composed = 0;
    for r in &reports {
        // The epoch at T is composed from the samples before T.
        let last = data.t.iter().rposition(|&t| t < r.t).expect("a sample before the epoch");
        for i in 0..2 {
            assert_eq!(r.local[i].map(f64::to_bits), values[i][last].map(f64::to_bits));
        }
        if let (Some(a), Some(b), Some(rate)) = (r.local[0], r.local[1], r.rate) {
            composed += 1;
            // Lemma 1 (eq. beta_net) as a closed form, for rates of any sign.
            let lemma = if a > 0.0 && b > 0.0 {
                lemma1_rate(a, b, gamma).expect("positive rates")
            } else {
                0.5 * (a + b) - (0.25 * (a - b).powi(2) + gamma * gamma).sqrt()
            };
            assert!((rate - lemma).abs() <= 1e-10 * (1.0 + lemma.abs()), "{rate} vs {lemma}");
            // The Perron weights of the symmetric 2 × 2 gain matrix in closed form: the top
            // eigenvector of [[−a, γ], [γ, −b]] at λ = −rate is (γ, λ + a).
            let (l, total) = (-rate, r.participation.iter().sum::<f64>());
            let p0 = gamma * gamma / (gamma * gamma + (l + a) * (l + a));
            assert!((total - 1.0).abs() <= 1e-9, "participation sums to {total}");
            assert!(r.sensitivity_converged);
            assert!((r.participation[0] - p0).abs() <= 1e-6, "{:?} vs {p0}", r.participation);
            if a > 0.0 && b > 0.0 {
                let scale = r.critical_scale.expect("scale");
                let warn = warning_gain(a, b).expect("positive");
                assert!((scale * gamma - warn).abs() <= 1e-9 * warn, "{scale} γ vs {warn}");
            }
            assert_eq!(r.certified, r.not_certified.is_empty() && rate >= 0.0);
        } else {
            assert!(r.rate.is_none() && !r.certified && !r.open);
        }
    }
    assert!(composed >= 20, "{composed} epochs with a network rate");
    assert!(reports.iter().any(|r| r.open), "the network gate opens on this data");
}

#[test]
fn a_silent_subsystem_turns_stale_and_closes_the_network_gate() {
    let stream = |k: f64, seed: u64| {
        run(
            &LinearScenario {
                steps: 3000,
                ..scalar(0.5, k, Process::Gaussian { sigma: 0.05 }, 1.0)
            },
            seed,
        )
    };
    let (a, b) = (stream(-2.5, 1), stream(-3.0, 2));
    let mut cfg = NetworkConfig::new(
        vec![SubsystemSpec::new("a", local(-2.5)), SubsystemSpec::new("b", local(-3.0))],
        vec![(0, 1, 0.2)],
        0.25,
    );
    cfg.stale_after = 1.0;
    let mut net = NetworkCertifier::new(cfg).expect("valid");
    let mut reports = Vec::new();
    for j in 0..a.len() {
        net.push(0, a.t[j], a.output(j), a.input(j), |r| reports.push(r.clone())).expect("a");
        // Subsystem b goes silent after 15 s.
        if b.t[j] < 15.0 {
            net.push(1, b.t[j], b.output(j), b.input(j), |r| reports.push(r.clone())).expect("b");
        }
    }
    net.advance(40.0, |r| reports.push(r.clone())).expect("advance");
    let open_before = reports.iter().filter(|r| r.t < 15.0).any(|r| r.open);
    assert!(open_before, "the network gate opens while both report");
    for r in reports.iter().filter(|r| r.t > 16.0 + 1e-9) {
        assert!(!r.open && !r.certified && r.rate.is_none(), "t = {}", r.t);
        assert!(
            r.not_certified
                .iter()
                .any(|(i, why)| *i == 1 && matches!(why, NotCertifiedLocal::Stale { .. })),
            "t = {}: {:?}",
            r.t,
            r.not_certified
        );
    }
    // advance() composed the epochs after the last sample, up to 40 s.
    assert_eq!(reports.last().map(|r| r.t), Some(40.0));
}

/// A synthetic network of scalar linear subsystems `ẏ_i = a_i y_i + u_i + w_i` with candidate
/// gains `K_i` (true local rates `−(a_i + K_i)`), disconnected data, and coupling bounds on a
/// random graph scaled by `s`. The network certificate (calibrated locals, risk split over the
/// subsystems) must never open when the true network rate is below the margin.
#[test]
fn the_network_gate_opens_only_when_the_true_network_rate_is_above_the_margin() {
    let n = 12;
    let margin = 0.1;
    let mut opened_above = 0;
    let mut cases_above = 0;
    for seed in 0..6u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
        let a: Vec<f64> = (0..n).map(|_| rng.random_range(-0.5..0.5)).collect();
        let rates: Vec<f64> = (0..n).map(|_| rng.random_range(0.6..2.0)).collect();
        let k: Vec<f64> = (0..n).map(|i| -rates[i] - a[i]).collect();
        let mut edges = Vec::new();
        for i in 0..n {
            for _ in 0..2 {
                let j = rng.random_range(0..n);
                if j != i {
                    edges.push((i, j, rng.random_range(0.1..0.5)));
                }
            }
        }
        // Scale the gains so that the true network rate is 5 margins, or just below one margin (
        // bisection on the scale).
        let true_rate = |s: f64| {
            let e: Vec<_> = edges.iter().map(|&(i, j, g)| (i, j, s * g)).collect();
            network_rate(&Network::new(rates.clone(), &e).expect("net")).expect("rate").rate
        };
        let scale_for = |target: f64| {
            let (mut lo, mut hi) = (0.0, 50.0);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if true_rate(mid) > target { lo = mid } else { hi = mid }
            }
            lo
        };
        for target in [5.0 * margin, 0.8 * margin] {
            let s = scale_for(target);
            let truth = true_rate(s);
            let couplings: Vec<_> = edges.iter().map(|&(i, j, g)| (i, j, s * g)).collect();
            let subsystems = (0..n)
                .map(|i| {
                    SubsystemSpec::new(
                        &format!("s{i}"),
                        CertifierConfig { margin: 0.05, consecutive: 1, ..local(k[i]) },
                    )
                })
                .collect();
            let mut cfg = NetworkConfig::new(subsystems, couplings, 1.0).split_risk(0.05);
            cfg.margin = margin;
            assert_eq!(cfg.certificate, CertificateKind::Calibrated);
            let mut net = NetworkCertifier::new(cfg).expect("valid");
            let data: Vec<_> = (0..n)
                .map(|i| {
                    let plant = scalar(a[i], k[i], Process::Gaussian { sigma: 0.05 }, 1.0);
                    run(&LinearScenario { steps: 4000, ..plant }, 1000 * seed + i as u64)
                })
                .collect();
            let mut opened = false;
            for j in 0..data[0].len() {
                for (i, d) in data.iter().enumerate() {
                    net.push(i, d.t[j], d.output(j), d.input(j), |r| opened |= r.open)
                        .expect("sample");
                }
            }
            if truth >= margin {
                cases_above += 1;
                opened_above += usize::from(opened);
            } else {
                assert!(!opened, "seed {seed}: opened with true network rate {truth} < {margin}");
            }
        }
    }
    // Power: the gate opens in most runs whose true network rate is five margins up.
    assert!(opened_above * 2 > cases_above, "opened in {opened_above} of {cases_above}");
}

#[test]
fn a_time_far_ahead_is_refused_and_changes_nothing() {
    let data = run(
        &LinearScenario { steps: 600, ..scalar(0.5, -2.0, Process::Gaussian { sigma: 0.05 }, 1.0) },
        5,
    );
    let cfg = NetworkConfig::new(vec![SubsystemSpec::new("a", local(-2.0))], Vec::new(), 0.1);
    let (mut clean, mut hit) = (
        NetworkCertifier::new(cfg.clone()).expect("valid"),
        NetworkCertifier::new(cfg).expect("valid"),
    );
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for j in 0..data.len() {
        if j == 300 {
            // A corrupted time: 10¹² s is 10¹³ epochs ahead.
            let err = hit.push(0, 1e12, data.output(j), data.input(j), |r| b.push(r.clone()));
            assert!(
                matches!(err, Err(streamcert::network::NetworkError::TimeJump { .. })),
                "{err:?}"
            );
        }
        clean.push(0, data.t[j], data.output(j), data.input(j), |r| a.push(r.clone())).expect("a");
        hit.push(0, data.t[j], data.output(j), data.input(j), |r| b.push(r.clone())).expect("b");
    }
    assert_eq!(a, b);
    assert_eq!(clean, hit);
}

/// A subsystem of order `n > 1`, or with `order = "auto"`, is refused by name: its
/// certificate bounds a spectral abscissa, not a contraction rate in a shared metric, which
/// Lemma 1 needs. The same subsystem at the first order composes.
#[test]
fn a_subsystem_of_higher_order_is_refused_naming_why() {
    use streamcert::certificate::{Calibration, OrderLadder};
    use streamcert::regression::LoopModel;
    let first = || {
        let mut c = local(-2.0);
        c.regression.window = 2000;
        c.regression.horizon = 50;
        c.calibration = Some(Calibration::new(0.01));
        c
    };
    let build = |c: CertifierConfig| {
        let subsystems = vec![SubsystemSpec::new("a", c), SubsystemSpec::new("b", local(-2.0))];
        NetworkCertifier::new(NetworkConfig::new(subsystems, vec![(0, 1, 0.1)], 0.1))
    };
    assert!(build(first()).is_ok());
    let mut two = first();
    two.regression.order = LoopModel::of_order(2).unwrap();
    let mut auto = first();
    auto.orders = Some(OrderLadder::automatic());
    for (c, says) in [(two, "order 2"), (auto, "order \"auto\"")] {
        match build(c) {
            Err(streamcert::network::NetworkError::InvalidConfig { field, reason }) => {
                assert_eq!(field, "subsystems");
                assert!(reason.contains(says) && reason.contains("Lemma 1"), "{reason}");
                assert!(reason.contains("order = 1"), "{reason}");
            }
            other => panic!("not refused: {other:?}"),
        }
    }
}
