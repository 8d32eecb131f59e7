//! The plant-change table of `cargo xtask validity`: a contracting loop (`β* = 3`) whose plant
//! changes at 20 s, with the default configuration (every guard on).

use std::fmt::Write as _;

use anyhow::Result;
use streamcert_certificate::{Certifier, NotCertified};
use streamcert_dynamics::{LinearScenario, PlantSwitch, Process};

use super::cells::{plain, scenario};
use super::quantile;
use crate::common::{markdown, median};

/// The candidate gain and the exploring one: with `ẏ = a y + u + w`, `β* = −(a + K)`.
const K: f64 = -1.5;
const SWITCH: f64 = 20.0;
const M: usize = 150;

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

fn one(s: &LinearScenario, seed: u64) -> Result<Run> {
    let traj = s.run(seed)?;
    let cell = plain("change".into(), s.clone(), vec![K], M, 10);
    let mut cert = Certifier::new(cell.config(None))?;
    let mut run =
        Run { open_at_switch: false, delay: f64::INFINITY, last_open: None, after: 0, changed: 0 };
    for i in 0..traj.len() {
        let t = traj.t[i];
        let ev = cert.push(t, traj.output(i), traj.input(i))?;
        let open = ev.calibrated.open;
        if t < SWITCH {
            run.open_at_switch = open;
            continue;
        }
        run.after += 1;
        run.changed +=
            usize::from(matches!(ev.calibrated.reason, Some(NotCertified::PlantChanged { .. })));
        if !open && run.delay.is_infinite() {
            run.delay = t - SWITCH;
        }
        if open {
            run.last_open = Some(t - SWITCH);
        }
    }
    Ok(run)
}

/// The table: `runs` runs per cell at `dt = 0.01` and `0.02`, changes from `β* = 3` to
/// `−0.2`, `0`, `0.04` (below the margin) and `1` (still contracting).
pub(super) fn table(runs: usize, bar: &indicatif::ProgressBar) -> Result<String> {
    let mut rows = Vec::new();
    for (ci, dt) in [0.01, 0.02].into_iter().enumerate() {
        // The shortest window's span: its M columns of h intervals cover M + h − 1 steps.
        let span = (M + super::H - 1) as f64 * dt;
        for (cj, after) in [-0.2, 0.0, 0.04, 1.0].into_iter().enumerate() {
            let s = LinearScenario {
                dt,
                steps: (40.0 / dt).round() as usize,
                switch: Some(PlantSwitch { at: SWITCH, a: vec![-(after + K)] }),
                ..scenario(1, vec![-(3.0 + K)], -2.0, Process::Gaussian { sigma: 0.1 })
            };
            let base = 95_000_000 + 1_000_000 * (4 * ci + cj) as u64;
            let half = runs / 2;
            let results = std::thread::scope(|scope| -> Result<Vec<Run>> {
                let a = scope.spawn(|| {
                    (0..half).map(|r| one(&s, base + r as u64)).collect::<Result<Vec<_>>>()
                });
                let b = (half..runs)
                    .map(|r| {
                        bar.inc(2);
                        one(&s, base + r as u64)
                    })
                    .collect::<Result<Vec<_>>>();
                let mut a = a.join().expect("worker thread")?;
                a.extend(b?);
                Ok(a)
            })?;
            let open: Vec<&Run> = results.iter().filter(|r| r.open_at_switch).collect();
            let late = results.iter().filter(|r| r.last_open.is_some_and(|l| l > 1.5 * span));
            let late = late.count();
            let mut delays: Vec<f64> = open.iter().map(|r| r.delay).collect();
            let (after_samples, changed): (usize, usize) =
                results.iter().fold((0, 0), |(a, c), r| (a + r.after, c + r.changed));
            let unsafe_change = after < 0.05;
            rows.push(vec![
                format!("{dt}"),
                format!("3 → {after}"),
                format!("{:.2}", span),
                format!("{} / {runs}", open.len()),
                if unsafe_change {
                    format!("{late} ({:.1} %)", 100.0 * late as f64 / runs as f64)
                } else {
                    "–".into()
                },
                if delays.is_empty() { "–".into() } else { format!("{:.2}", median(&delays)) },
                if delays.is_empty() {
                    "–".into()
                } else {
                    format!("{:.2}", quantile(&mut delays, 0.9))
                },
                format!("{:.1} %", 100.0 * changed as f64 / after_samples.max(1) as f64),
                format!(
                    "{:.1} %",
                    100.0 * results.iter().filter(|r| r.last_open.is_some()).count() as f64
                        / runs as f64
                ),
            ]);
        }
    }
    let mut s = String::new();
    let _ = writeln!(
        s,
        "## Plant change (the default configuration: every guard on)\n\n`ẏ = a y + u + w`, K = {K}, σ = 0.1, exploration K_e = −2, M = {M}, h = 5, n_s = 10, 40 s: `a` gives β* = 3 until {SWITCH} s, then the rate after the change; {runs} runs per cell. `span`: the shortest window's span (M + h − 1 steps). `open late`: the runs whose gate was open later than 1.5 spans after the change (for the changes below the margin: a deployment on the new plant, target at most 5 %). `closing delay`: from the change to the first closed sample (∞ when never closed). `closed by the change guard`: the share of post-change samples whose reason is the change guard's. `open after`: runs whose gate was open at some time after the change (for 3 → 1 the new plant still contracts, and reopening is power).\n"
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
