//! The timely network certifier in one process with several worker threads against the
//! one-process `NetworkCertifier`: the same epoch reports, bit for bit, and the same first
//! failure.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert_certificate::CertifierConfig;
use streamcert_network::{EpochReport, NetworkCertifier, NetworkConfig, SubsystemSpec};
use streamcert_regression::RegressionConfig;
use streamcert_timely::{Output, Placement, Row, TimelyError, run};

/// `n` scalar subsystems `ẏ = a y + u + w` under `u = k y + PRBS`, Euler steps of 10 ms, all
/// in one row per step.
fn rows(n: usize, steps: usize, seed: u64) -> Vec<Row> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let a: Vec<f64> = (0..n).map(|_| rng.random_range(-0.5..0.5)).collect();
    let mut y = vec![0.0; n];
    let mut d = vec![1.0; n];
    (0..steps)
        .map(|k| {
            let t = k as f64 * 0.01;
            let samples = (0..n)
                .map(|i| {
                    if k % 20 == 0 && rng.random::<bool>() {
                        d[i] = -d[i];
                    }
                    let u = -1.5 * y[i] + d[i];
                    let s = (i, vec![y[i], u]);
                    y[i] += 0.01 * (a[i] * y[i] + u) + 0.01 * rng.random_range(-1.0..1.0);
                    s
                })
                .collect();
            Row { line: k as u64 + 2, t, samples, gap: false }
        })
        .collect()
}

fn network(n: usize) -> NetworkConfig {
    let specs = (0..n)
        .map(|i| {
            let reg = RegressionConfig::new(1, 1, 100, 5, 1e-4);
            let c = CertifierConfig::new(reg, vec![-1.0 - 0.1 * i as f64], 0.3, 0.1, 5);
            SubsystemSpec::new(&format!("s{i}"), c)
        })
        .collect();
    let edges = (0..n).map(|i| ((i + 1) % n, i, 0.05)).collect();
    NetworkConfig::new(specs, edges, 0.5).split_risk(0.05)
}

fn serial(cfg: &NetworkConfig, rows: &[Row]) -> (Vec<EpochReport>, Option<String>) {
    let mut net = NetworkCertifier::new(cfg.clone()).expect("valid");
    let mut out = Vec::new();
    for r in rows {
        for (i, v) in &r.samples {
            if r.gap {
                net.gap(*i);
            }
            if let Err(e) = net.push(*i, r.t, &v[..1], &v[1..], |e| out.push(e.clone())) {
                return (out, Some(e.to_string()));
            }
        }
    }
    (out, None)
}

/// A handler that keeps the epoch reports.
fn collect(out: &mut Vec<EpochReport>) -> impl FnMut(Output<'_>) -> Result<(), String> + '_ {
    |o| {
        if let Output::Epoch(r) = o {
            out.push(r.clone());
        }
        Ok(())
    }
}

#[derive(Debug, thiserror::Error)]
#[error("bad row")]
struct BadRow;

fn timely(
    cfg: &NetworkConfig,
    rows: Vec<Row>,
    workers: usize,
) -> (Vec<EpochReport>, Option<String>) {
    let mut out = Vec::new();
    let result = run(
        cfg.clone(),
        &Placement::local(cfg.subsystems.len(), workers),
        None,
        None,
        move || rows.into_iter().map(Ok::<Row, BadRow>),
        collect(&mut out),
    );
    (out, result.err().map(|e| e.to_string()))
}

#[test]
fn worker_threads_give_the_one_process_reports() {
    let cfg = network(5);
    let data = rows(5, 2000, 3);
    let (want, none) = serial(&cfg, &data);
    assert!(none.is_none());
    assert!(want.len() >= 30 && want.iter().any(|r| r.rate.is_some()), "{} epochs", want.len());
    for workers in [1, 2, 3] {
        let (got, err) = timely(&cfg, data.clone(), workers);
        assert!(err.is_none(), "{err:?}");
        assert_eq!(got, want, "{workers} workers");
    }
}

#[test]
fn a_declared_gap_restarts_the_rows_subsystems_windows_as_in_one_process() {
    let cfg = network(3);
    let mut data = rows(3, 1500, 7);
    let (plain, _) = serial(&cfg, &data);
    // A live source's outage before row 700: every subsystem in it restarts its windows.
    data[700].gap = true;
    let (want, none) = serial(&cfg, &data);
    assert!(none.is_none());
    assert_ne!(want, plain, "the gap changes the reports");
    for workers in [1, 2] {
        let (got, err) = timely(&cfg, data.clone(), workers);
        assert!(err.is_none(), "{err:?}");
        assert_eq!(got, want, "{workers} workers");
    }
}

#[test]
fn a_rejected_sample_stops_where_one_process_stops() {
    let cfg = network(4);
    let mut data = rows(4, 1500, 5);
    // Subsystem 2's output is not a number at row 900 (line 902).
    data[900].samples[2].1[0] = f64::NAN;
    let (want, err) = serial(&cfg, &data);
    assert!(err.is_some());
    let (got, got_err) = timely(&cfg, data, 2);
    assert_eq!(got, want);
    let got_err = got_err.expect("an error");
    assert!(got_err.starts_with("line 902: subsystem 2 (`s2`)"), "{got_err}");
}

#[test]
fn a_bad_row_and_a_time_jump_stop_the_run() {
    let cfg = network(3);
    let data = rows(3, 600, 9);
    let want = serial(&cfg, &data[..400]).0;
    let mut out = Vec::new();
    let head = data[..400].to_vec();
    let result = run(
        cfg.clone(),
        &Placement::local(3, 2),
        None,
        None,
        move || head.into_iter().map(Ok).chain(std::iter::once(Err(BadRow))),
        collect(&mut out),
    );
    assert!(matches!(result, Err(TimelyError::Source { row: 401, .. })));
    assert_eq!(out, want);
    let mut jump = data[..400].to_vec();
    jump.push(Row { line: 999, t: 1e9, samples: vec![(0, vec![0.0, 0.0])], gap: false });
    let mut out = Vec::new();
    let result = run(
        cfg,
        &Placement::local(3, 1),
        None,
        None,
        move || jump.into_iter().map(Ok::<Row, BadRow>),
        collect(&mut out),
    );
    assert!(matches!(result, Err(TimelyError::Network { line: 999, .. })), "{result:?}");
    assert_eq!(out, want);
}

#[test]
fn unaligned_subsystem_rows_give_the_one_process_reports() {
    // One sample per row, each subsystem at its own times (offset by 1 ms per subsystem), and
    // a silent stretch for subsystem 1 (it turns stale, then resumes).
    let cfg = network(4);
    let data: Vec<Row> = rows(4, 1500, 11)
        .into_iter()
        .flat_map(|r| {
            let (t, line) = (r.t, r.line);
            r.samples.into_iter().filter_map(move |(i, v)| {
                let silent = i == 1 && (6.0..9.0).contains(&t);
                (!silent).then(|| Row {
                    line,
                    t: t + 0.001 * i as f64,
                    samples: vec![(i, v)],
                    gap: false,
                })
            })
        })
        .collect();
    let (want, none) = serial(&cfg, &data);
    assert!(none.is_none());
    assert!(want.iter().any(|r| r.not_certified.iter().any(|(i, _)| *i == 1)));
    for workers in [2, 3] {
        let (got, err) = timely(&cfg, data.clone(), workers);
        assert!(err.is_none(), "{err:?}");
        assert_eq!(got, want, "{workers} workers");
    }
}

#[test]
fn an_unknown_subsystem_and_a_bad_certifier_are_refused() {
    // A row naming subsystem 7 of a 3-subsystem network stops the run where one process stops.
    let cfg = network(3);
    let mut data = rows(3, 600, 13);
    data[450].samples[1].0 = 7;
    let (want, err) = serial(&cfg, &data);
    assert!(err.is_some_and(|e| e.contains("no subsystem 7")));
    let mut out = Vec::new();
    let result = run(
        cfg,
        &Placement::local(3, 2),
        None,
        None,
        move || data.into_iter().map(Ok::<Row, BadRow>),
        collect(&mut out),
    );
    match result {
        Err(TimelyError::Network { line, source }) => {
            assert_eq!(line, 452);
            assert!(source.to_string().contains("no subsystem 7"), "{source}");
        }
        other => panic!("expected the unknown subsystem, got {other:?}"),
    }
    assert_eq!(out, want);
    // A subsystem whose certifier cannot be built is a configuration error before any worker
    // starts (no panic in a worker).
    let mut bad = network(2);
    bad.subsystems[1].certifier.gain = vec![1.0, 2.0];
    let result = run(
        bad,
        &Placement::local(2, 1),
        None,
        None,
        std::iter::empty::<Result<Row, BadRow>>,
        |_| Ok(()),
    );
    assert!(matches!(result, Err(TimelyError::Config(ref m)) if m.contains("gain")), "{result:?}");
}
