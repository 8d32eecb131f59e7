//! Estimated couplings and the threaded fleet path of the live network certifier: on
//! bidirectional G5 the coupling bounds contain the true `γ`, the local certificates equal
//! separate certifiers of the same configuration, the network rate equals the dense
//! composition of the same local rates and bounds; batches over threads equal sample-by-sample
//! pushes.

use streamcert::certificate::{
    Calibration, CertificateKind, Certifier, CertifierConfig, CouplingBlock, CouplingConfig,
};
use streamcert::compose::{Network, network_rate};
use streamcert::dynamics::{Coupling, Process, Trajectory};
use streamcert::experiments::{Experiment, G5Dataset};
use streamcert::network::{
    EpochReport, EstimatedCoupling, NetworkCertifier, NetworkConfig, SampleBatch, SubsystemSpec,
};
use streamcert::regression::{InputIntegral, RegressionConfig};

use crate::support::{run, scalar};

/// Subsystem `i` of G5 (0: A, 1: B) with the other's output as a coupling input.
fn coupled(k: f64) -> CertifierConfig {
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(1, 2, 150, 5, 1e-4)
    };
    CertifierConfig {
        calibration: Some(Calibration::new(0.01)),
        couplings: Some(CouplingConfig {
            blocks: vec![CouplingBlock { first: 1, len: 1 }],
            delta: 0.01,
        }),
        ..CertifierConfig::new(reg, vec![k, 0.0], 0.3, 0.1, 10)
    }
}

fn g5(gamma: f64, seed: u64) -> Trajectory {
    G5Dataset {
        coupling: Coupling::Bidirectional,
        steps: Some(4000),
        gamma: Some(gamma),
        ..G5Dataset::defaults(Experiment::Two)
    }
    .run_seeded(seed)
    .expect("data")
}

fn network(delta: f64) -> NetworkConfig {
    let s = Experiment::Two.setting();
    let mut cfg = NetworkConfig::new(
        vec![SubsystemSpec::new("A", coupled(s.k1)), SubsystemSpec::new("B", coupled(s.k4))],
        Vec::new(),
        0.5,
    );
    cfg.estimated = vec![
        EstimatedCoupling { to: 0, from: 1, block: 0 },
        EstimatedCoupling { to: 1, from: 0, block: 0 },
    ];
    cfg.split_risk(delta)
}

/// Subsystem `i`'s sample `j`: its output, and its input then the other's output.
fn sample(data: &Trajectory, i: usize, j: usize) -> ([f64; 1], [f64; 2]) {
    let (y, u) = (data.output(j), data.input(j));
    ([y[i]], [u[i], y[1 - i]])
}

/// Every sample of a G5 run in arrival order, `(subsystem, t, y, u)`.
fn g5_samples(gamma: f64, seed: u64) -> Vec<(usize, f64, Vec<f64>, Vec<f64>)> {
    let data = g5(gamma, seed);
    (0..data.len())
        .flat_map(|j| {
            let data = &data;
            (0..2).map(move |i| {
                let (y, u) = sample(data, i, j);
                (i, data.t[j], y.to_vec(), u.to_vec())
            })
        })
        .collect()
}

#[test]
fn g5_coupling_bounds_contain_the_true_gamma() {
    for (seed, gamma) in [(0, 0.3), (1, 0.3), (2, 0.6), (3, 0.0)] {
        let data = g5(gamma, seed);
        let cfg = network(0.05);
        let mut net = NetworkCertifier::new(cfg.clone()).expect("valid");
        let mut separate = cfg
            .subsystems
            .iter()
            .map(|s| Certifier::new(s.certifier.clone()).expect("valid"))
            .collect::<Vec<_>>();
        let mut reports: Vec<EpochReport> = Vec::new();
        for j in 0..data.len() {
            for i in 0..2 {
                let (y, u) = sample(&data, i, j);
                let ev = net.push(i, data.t[j], &y, &u, |r| reports.push(r.clone())).expect("ok");
                assert_eq!(ev, separate[i].push(data.t[j], &y, &u).expect("ok"));
            }
        }
        let mut bounded = 0;
        for r in &reports {
            for (e, g) in cfg.estimated.iter().zip(&r.estimated) {
                let Some(g) = *g else { continue };
                bounded += 1;
                assert!(g >= gamma, "seed {seed}: γ̄ {e:?} = {g} below the true γ = {gamma}");
            }
            if let (Some(rate), [Some(g0), Some(g1)]) = (r.rate, r.estimated.as_slice()) {
                let beta: Vec<f64> = r.local.iter().map(|v| v.expect("value")).collect();
                let net = Network::new(beta, &[(0, 1, *g0), (1, 0, *g1)]).expect("net");
                assert_eq!(rate.to_bits(), network_rate(&net).expect("rate").rate.to_bits());
            }
        }
        assert!(bounded > 100, "seed {seed}: {bounded} bounds");
    }
}

/// Every epoch report of `net` fed `samples` one by one, and then in batches of `batch`
/// samples over `threads` threads, on fresh copies.
fn one_by_one_and_batched(
    cfg: &NetworkConfig,
    samples: &[(usize, f64, Vec<f64>, Vec<f64>)],
    batch: usize,
    threads: usize,
) -> (Vec<EpochReport>, Vec<EpochReport>, NetworkCertifier, NetworkCertifier) {
    let mut serial = NetworkCertifier::new(cfg.clone()).expect("valid");
    let mut one = Vec::new();
    for (i, t, y, u) in samples {
        serial.push(*i, *t, y, u, |r| one.push(r.clone())).expect("sample");
    }
    let mut fleet = NetworkCertifier::new(cfg.clone()).expect("valid");
    let mut many = Vec::new();
    let mut b = SampleBatch::new();
    for chunk in samples.chunks(batch) {
        b.clear();
        for (i, t, y, u) in chunk {
            b.push(*i, *t, y, u);
        }
        fleet.push_batch(&b, threads, |r| many.push(r.clone())).expect("batch");
    }
    (one, many, serial, fleet)
}

#[test]
fn batches_over_threads_equal_pushes_one_by_one() {
    // Eight scalar subsystems at 100 Hz, epochs of 5 s: segments of 4000 samples run on threads.
    let n = 8;
    let mut samples = Vec::new();
    let data: Vec<_> = (0..n)
        .map(|i| {
            let a = 0.1 * i as f64 - 0.3;
            let plant = scalar(a, -1.5, Process::Gaussian { sigma: 0.05 }, 1.0);
            run(&streamcert::dynamics::LinearScenario { steps: 3000, ..plant }, 7 + i as u64)
        })
        .collect();
    for j in 0..data[0].len() {
        for (i, d) in data.iter().enumerate() {
            samples.push((i, d.t[j], d.output(j).to_vec(), d.input(j).to_vec()));
        }
    }
    let locals = (0..n)
        .map(|i| {
            let reg = RegressionConfig::new(1, 1, 150, 5, 1e-4);
            let c = CertifierConfig::new(reg, vec![-1.0 - 0.1 * i as f64], 0.3, 0.1, 10);
            SubsystemSpec::new(&format!("s{i}"), c)
        })
        .collect();
    let edges = (0..n).map(|i| ((i + 1) % n, i, 0.05)).collect();
    let mut cfg = NetworkConfig::new(locals, edges, 5.0).split_risk(0.05);
    cfg.dense_limit = 4; // the sparse composition
    for (batch, threads) in [(10_000, 2), (7_001, 3), (24_000, 8), (333, 2), (10, 2)] {
        let (one, many, serial, fleet) = one_by_one_and_batched(&cfg, &samples, batch, threads);
        assert!(one.len() >= 5 && one.iter().any(|r| r.rate.is_some()), "{} epochs", one.len());
        assert_eq!(one, many, "batch {batch}, {threads} threads");
        assert_eq!(serial, fleet, "the whole state, batch {batch}, {threads} threads");
    }
    // The G5 network with estimated couplings, in batches of one second over two threads.
    let g5_samples = g5_samples(0.3, 4);
    let (one, many, _, _) = one_by_one_and_batched(&network(0.05), &g5_samples, 100, 2);
    assert!(one.iter().any(|r| r.estimated.iter().all(Option::is_some)));
    assert_eq!(one, many);
}

#[test]
fn a_batch_with_an_unknown_subsystem_is_refused_whole() {
    let mut net = NetworkCertifier::new(network(0.05)).expect("valid");
    let mut b = SampleBatch::new();
    b.push(0, 0.0, &[0.0], &[0.0, 0.0]);
    b.push(5, 0.0, &[0.0], &[0.0, 0.0]);
    let before = serde_json::to_string(&net).expect("json");
    assert!(net.push_batch(&b, 2, |_| {}).is_err());
    assert_eq!(serde_json::to_string(&net).expect("json"), before);
}

#[test]
fn estimated_couplings_are_checked() {
    let s = Experiment::Two.setting();
    // The coupling channel must not be actuated.
    let mut bad = coupled(s.k1);
    bad.gain = vec![s.k1, 0.5];
    let err = Certifier::new(bad).expect_err("actuated coupling channel");
    assert!(err.to_string().contains("row of K must be zero"), "{err}");
    // A block past the inputs (even one whose end overflows), and an empty one.
    for (first, len) in [(2, 1), (1, usize::MAX), (1, 0)] {
        let mut bad = coupled(s.k1);
        bad.couplings =
            Some(CouplingConfig { blocks: vec![CouplingBlock { first, len }], delta: 0.01 });
        let err = Certifier::new(bad).expect_err("bad block");
        assert!(err.to_string().contains("within the 2 inputs"), "{err}");
    }
    // A block the subsystem does not have, and a coupling both given and estimated.
    let mut cfg = network(0.05);
    cfg.estimated[0].block = 1;
    assert!(NetworkCertifier::new(cfg).is_err());
    let mut cfg = network(0.05);
    cfg.couplings.push((0, 1, 0.3));
    assert!(NetworkCertifier::new(cfg).is_err());
    // Risk split over two subsystems and two estimated couplings: δ/4 each.
    let cfg = network(0.08);
    for spec in &cfg.subsystems {
        assert_eq!(spec.certifier.calibration.map(|c| c.delta), Some(0.02));
        assert_eq!(spec.certifier.couplings.as_ref().map(|c| c.delta), Some(0.02));
    }
}

#[test]
fn a_rejected_sample_in_a_batch_reports_the_epochs_before_it() {
    let mut samples = g5_samples(0.3, 6);
    let bad = 2 * 2500 + 1; // subsystem B's sample at step 2500
    samples[bad].2[0] = f64::NAN;
    let cfg = network(0.05);
    let mut serial = NetworkCertifier::new(cfg.clone()).expect("valid");
    let mut want = Vec::new();
    let mut serial_err = None;
    for (i, t, y, u) in &samples {
        if let Err(e) = serial.push(*i, *t, y, u, |r| want.push(r.clone())) {
            serial_err = Some(e.to_string());
            break;
        }
    }
    for threads in [1, 2] {
        let mut fleet = NetworkCertifier::new(cfg.clone()).expect("valid");
        let mut b = SampleBatch::new();
        for (i, t, y, u) in &samples {
            b.push(*i, *t, y, u);
        }
        let mut got = Vec::new();
        let err = fleet.push_batch(&b, threads, |r| got.push(r.clone())).expect_err("NaN");
        assert_eq!(Some(err.to_string()), serial_err, "{threads} threads");
        assert_eq!(got, want, "{threads} threads: the epochs before the bad sample");
    }
}

/// Oracle: the union bound's sum. Split over two subsystems and two estimated couplings, the
/// risks the calibrations and coupling bounds carry add up to the run-level `δ`; the paper's
/// certificates carry none.
#[test]
fn the_split_risks_add_up_to_the_run_level_risk() {
    for delta in [0.01, 0.05, 0.2] {
        let cfg = network(delta);
        let total = cfg.total_risk().expect("calibrated");
        assert!((total - delta).abs() <= 1e-15, "{total} {delta}");
        let shares: Vec<f64> = cfg
            .subsystems
            .iter()
            .map(|s| s.certifier.calibration.as_ref().expect("calibrated").delta)
            .collect();
        assert_eq!(shares, vec![delta / 4.0; 2]);
        let paper = NetworkConfig { certificate: CertificateKind::Gaussian, ..cfg };
        assert_eq!(paper.total_risk(), None);
    }
}
