//! A run restarted from the checkpoints it had written at any moment composes, from the
//! composer's checkpointed epoch on, the reports of the uninterrupted run.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert_certificate::CertifierConfig;
use streamcert_network::{EpochReport, NetworkConfig, SubsystemSpec};
use streamcert_regression::RegressionConfig;
use streamcert_timely::{ComposerState, Output, Placement, Resume, Row, SiteState, run};

#[derive(Debug, thiserror::Error)]
#[error("bad row")]
struct BadRow;

fn network(n: usize) -> NetworkConfig {
    let specs = (0..n)
        .map(|i| {
            let reg = RegressionConfig::new(1, 1, 60, 5, 1e-4);
            let c = CertifierConfig::new(reg, vec![-1.0 - 0.2 * i as f64], 0.3, 0.1, 3);
            SubsystemSpec::new(&format!("s{i}"), c)
        })
        .collect();
    let edges = (0..n).map(|i| ((i + 1) % n, i, 0.05)).collect();
    NetworkConfig::new(specs, edges, 0.25).split_risk(0.05)
}

/// One sample per row, subsystem `i` at its own times.
fn rows(n: usize, steps: usize, seed: u64) -> Vec<Row> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut y = vec![0.0; n];
    let mut out = Vec::new();
    for k in 0..steps {
        for i in 0..n {
            let u = -1.5 * y[i] + if rng.random::<bool>() { 1.0 } else { -1.0 };
            out.push(Row {
                line: out.len() as u64 + 2,
                t: k as f64 * 0.01 + 0.001 * i as f64,
                samples: vec![(i, vec![y[i], u])],
                gap: false,
            });
            y[i] += 0.01 * (-0.2 * y[i] + u) + 0.01 * rng.random_range(-1.0..1.0);
        }
    }
    out
}

/// What a run handed out, in order.
#[derive(Clone)]
enum Seen {
    Epoch(Box<EpochReport>),
    Site(Box<SiteState>),
    Composer(Box<ComposerState>),
}

fn go(cfg: &NetworkConfig, data: Vec<Row>, resume: Option<Resume>, every: u64) -> Vec<Seen> {
    let mut seen = Vec::new();
    let place = Placement::local(cfg.subsystems.len(), 1);
    run(
        cfg.clone(),
        &place,
        resume,
        Some(every),
        move || data.into_iter().map(Ok::<Row, BadRow>),
        |o| {
            seen.push(match o {
                Output::Epoch(r) => Seen::Epoch(Box::new(r.clone())),
                Output::Site(s) => Seen::Site(Box::new(s.clone())),
                Output::Composer(c) => Seen::Composer(Box::new(c.clone())),
                Output::Started { .. } => return Ok(()),
            });
            Ok(())
        },
    )
    .expect("run");
    seen
}

fn epochs(seen: &[Seen]) -> Vec<EpochReport> {
    seen.iter()
        .filter_map(|s| if let Seen::Epoch(r) = s { Some((**r).clone()) } else { None })
        .collect()
}

#[test]
fn a_restart_from_the_checkpoints_of_any_moment_continues_the_run() {
    let cfg = network(3);
    let data = rows(3, 900, 21);
    let mut want: Option<Vec<EpochReport>> = None;
    for every in [1, 3] {
        let whole = go(&cfg, data.clone(), None, every);
        let reports = epochs(&whole);
        assert!(reports.len() >= 30, "{} epochs", reports.len());
        // The period changes what is written, never the reports.
        assert_eq!(want.get_or_insert_with(|| reports.clone()), &reports);
        let mut resumed = 0;
        // A crash after any event: the checkpoints written by then.
        for cut in (5..whole.len()).step_by(4) {
            let newest = |before: usize| {
                let site = whole[..before].iter().rev().find_map(|s| match s {
                    Seen::Site(s) => Some((**s).clone()),
                    _ => None,
                });
                let composer = whole[..before].iter().rev().find_map(|s| match s {
                    Seen::Composer(c) => Some((**c).clone()),
                    _ => None,
                });
                (site, composer)
            };
            let (site, composer) = newest(cut);
            let (older_site, older) = newest(cut / 2);
            // The newest of both; an older composer's beside the newest site's; an older
            // site's beside the newest composer's (the site replays from its checkpoint and
            // its sends up to the composer's epoch land at that epoch).
            for (site, composer) in
                [(site.clone(), composer.clone()), (site, older), (older_site, composer)]
            {
                let Some(composer) = composer else { continue };
                let from = composer.next_epoch().expect("started");
                let site = site.map(|s| s.verify(&cfg, 0, &[0, 0, 0]).expect("valid"));
                let resume = Resume { site, composer: Some(composer), rejoin: false };
                let again = epochs(&go(&cfg, data.clone(), Some(resume), every));
                let tail: Vec<EpochReport> =
                    reports.iter().filter(|r| r.epoch >= from).cloned().collect();
                assert_eq!(again, tail, "period {every}: crash after event {cut}, epoch {from}");
                resumed += 1;
            }
        }
        assert!(resumed >= 25, "{resumed} restarts");
    }
}

/// A resumed state that does not fit the run (another network's site) is refused before any
/// worker starts, as a checkpoint error.
#[test]
fn a_site_state_of_another_network_is_refused() {
    let small = network(2);
    let whole = go(&small, rows(2, 300, 5), None, 1);
    let site = whole.iter().rev().find_map(|s| match s {
        Seen::Site(s) => Some((**s).clone()),
        _ => None,
    });
    let composer = whole.iter().rev().find_map(|s| match s {
        Seen::Composer(c) => Some((**c).clone()),
        _ => None,
    });
    let cfg = network(3);
    let place = Placement::local(3, 1);
    let resume = Resume { site, composer, rejoin: false };
    let data = rows(3, 100, 5);
    let result = run(
        cfg,
        &place,
        Some(resume),
        Some(1),
        move || data.into_iter().map(Ok::<Row, BadRow>),
        |_| Ok(()),
    );
    match result {
        Err(streamcert_timely::TimelyError::Checkpoint(m)) => {
            assert!(m.contains("subsystems") || m.contains("network"), "{m}")
        }
        other => panic!("expected a checkpoint refusal, got {:?}", other.map(|_| ())),
    }
}
