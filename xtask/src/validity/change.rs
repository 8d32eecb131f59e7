//! The plant-change table of `cargo xtask validity`: a contracting loop (`β* = 3`) whose plant
//! changes at 20 s, or drifts slowly from 10 s, with the default configuration (every guard
//! on).

use std::fmt::Write as _;

use anyhow::Result;
use streamcert_certificate::{Certifier, NotCertified};
use streamcert_dynamics::{LinearScenario, PlantSwitch, Process};

use super::MARGIN;
use super::cells::{plain, scenario};
use super::quantile;
use crate::common::{markdown, median};

/// The candidate gain and the exploring one: with `ẏ = a y + u + w`, `β* = −(a + K)`.
const K: f64 = -1.5;
const SWITCH: f64 = 20.0;
const M: usize = 150;
/// Cells of the table: four steps at each of two sampling steps, two drifts.
pub(super) const CELLS: usize = 10;
/// Where a slow drift starts.
const DRIFT_START: f64 = 10.0;

/// What one run shows after the change.
struct Run {
    /// The gate was open just before the change.
    open_at_switch: bool,
    /// Time from the change to the first closed sample (`∞`: never closed).
    delay: f64,
    /// The gate's last opening after the change, relative to it (`None`: never open after).
    last_open: Option<f64>,
    /// Post-change samples, and those the change guard held closed.
    after: usize,
    changed: usize,
}

/// One run, its events measured from `reference` (the change, or the time a drift's true
/// rate crosses the margin).
fn one(s: &LinearScenario, seed: u64, reference: f64) -> Result<Run> {
    let traj = s.run(seed)?;
    let cell = plain("change".into(), s.clone(), vec![K], M, 10);
    let mut cert = Certifier::new(cell.config(None))?;
    let mut run =
        Run { open_at_switch: false, delay: f64::INFINITY, last_open: None, after: 0, changed: 0 };
    for i in 0..traj.len() {
        let t = traj.t[i];
        let ev = cert.push(t, traj.output(i), traj.input(i))?;
        let open = ev.calibrated.open;
        if t < reference {
            run.open_at_switch = open;
            continue;
        }
        run.after += 1;
        run.changed +=
            usize::from(matches!(ev.calibrated.reason, Some(NotCertified::PlantChanged { .. })));
        if !open && run.delay.is_infinite() {
            run.delay = t - reference;
        }
        if open {
            run.last_open = Some(t - reference);
        }
    }
    Ok(run)
}

/// `runs` runs of scenario `s` (seeds from `base`) on two threads, events measured from
/// `reference`.
fn runs_of(
    s: &LinearScenario,
    (base, runs): (u64, usize),
    reference: f64,
    bar: &indicatif::ProgressBar,
) -> Result<Vec<Run>> {
    let half = runs / 2;
    std::thread::scope(|scope| -> Result<Vec<Run>> {
        let a = scope.spawn(|| {
            (0..half).map(|r| one(s, base + r as u64, reference)).collect::<Result<Vec<_>>>()
        });
        let b = (half..runs)
            .map(|r| {
                bar.inc(2);
                one(s, base + r as u64, reference)
            })
            .collect::<Result<Vec<_>>>();
        let mut a = a.join().expect("worker thread")?;
        a.extend(b?);
        Ok(a)
    })
}

/// A cell's row: its sampling step, the change (`what`), the shortest window's span, whether
/// the new plant is below the margin, and the runs.
fn row(dt: f64, what: &str, span: f64, unsafe_change: bool, results: &[Run]) -> Vec<String> {
    let runs = results.len();
    let open: Vec<&Run> = results.iter().filter(|r| r.open_at_switch).collect();
    let late = results.iter().filter(|r| r.last_open.is_some_and(|l| l > 1.5 * span));
    let late = late.count();
    let mut delays: Vec<f64> = open.iter().map(|r| r.delay).collect();
    let (after_samples, changed): (usize, usize) =
        results.iter().fold((0, 0), |(a, c), r| (a + r.after, c + r.changed));
    vec![
        format!("{dt}"),
        what.to_string(),
        format!("{:.2}", span),
        format!("{} / {runs}", open.len()),
        if unsafe_change {
            format!("{late} ({:.1} %)", 100.0 * late as f64 / runs as f64)
        } else {
            "–".into()
        },
        if delays.is_empty() { "–".into() } else { format!("{:.2}", median(&delays)) },
        if delays.is_empty() { "–".into() } else { format!("{:.2}", quantile(&mut delays, 0.9)) },
        format!("{:.1} %", 100.0 * changed as f64 / after_samples.max(1) as f64),
        format!(
            "{:.1} %",
            100.0 * results.iter().filter(|r| r.last_open.is_some()).count() as f64 / runs as f64
        ),
    ]
}

/// The table: `runs` runs per cell at `dt = 0.01` and `0.02`, changes from `β* = 3` to
/// `−0.2`, `0`, `0.04` (below the margin) and `1` (still contracting).
pub(super) fn table(runs: usize, bar: &indicatif::ProgressBar) -> Result<String> {
    let mut rows = Vec::new();
    // Steps at 20 s at both sampling steps, then slow drifts from 10 s at dt = 0.02: `(dt,
    // rate after, ramp seconds)`.
    let steps = [0.01, 0.02]
        .into_iter()
        .flat_map(|dt| [-0.2, 0.0, 0.04, 1.0].into_iter().map(move |after| (dt, after, 0.0)));
    let drifts = [(0.02, -0.2, 10.0), (0.02, -0.2, 20.0)];
    for (cell, (dt, after, ramp)) in steps.chain(drifts).enumerate() {
        {
            // The shortest window's span: its M columns of h intervals cover M + h − 1 steps.
            let span = (M + super::H - 1) as f64 * dt;
            let at = if ramp > 0.0 { DRIFT_START } else { SWITCH };
            // Events are measured from the time the true rate crosses the margin (the change
            // itself for a step).
            let reference = at + ramp * ((3.0 - MARGIN) / (3.0 - after)).min(1.0);
            let s = LinearScenario {
                dt,
                steps: (40.0 / dt).round() as usize,
                switch: Some(PlantSwitch { at, a: vec![-(after + K)], ramp }),
                ..scenario(1, vec![-(3.0 + K)], -2.0, Process::Gaussian { sigma: 0.1 })
            };
            let base = 95_000_000 + 1_000_000 * cell as u64;
            let results = runs_of(&s, (base, runs), reference, bar)?;
            let what = if ramp > 0.0 {
                format!(
                    "3 → {after}, drift over {ramp} s from {at} s (crosses at {reference:.1} s)"
                )
            } else {
                format!("3 → {after}")
            };
            rows.push(row(dt, &what, span, after < 0.05, &results));
        }
    }
    let mut s = String::new();
    let _ = writeln!(
        s,
        "## Plant change (the default configuration: every guard on)\n\n`ẏ = a y + u + w`, K = {K}, σ = 0.1, exploration K_e = −2, M = {M}, h = 5, n_s = 10, 40 s: `a` gives β* = 3 until {SWITCH} s, then the rate after the change; in the drift rows `a` moves linearly from β* = 3 to the rate after over the ramp, and every time below is measured from the moment the true rate crosses the margin {MARGIN} (for a step, the change); {runs} runs per cell. `span`: the shortest window's span (M + h − 1 steps). `open late`: the runs whose gate was open later than 1.5 spans after the change (for the changes below the margin: a deployment on the new plant, target at most 5 %). `closing delay`: from the change to the first closed sample (∞ when never closed). `closed by the change guard`: the share of post-change samples whose reason is the change guard's. `open after`: runs whose gate was open at some time after the change (for 3 → 1 the new plant still contracts, and reopening is power).\n"
    );
    let _ = writeln!(
        s,
        "{}",
        markdown(
            &[
                "dt",
                "β* change",
                "span [s]",
                "open at the change",
                "open late (> 1.5 spans)",
                "median closing delay [s]",
                "90th pct [s]",
                "closed by the change guard",
                "open after"
            ],
            &rows
        )
    );
    Ok(s)
}
