//! The held-input and units families of `cargo xtask validity`: inputs held for up to 30 s (a
//! step test, nearly collinear with the intercept over most windows) and logs in other
//! units, where the data barely identify the candidate's rate.

use std::fmt::Write as _;

use anyhow::Result;

use super::cells::{Cell, held_cells, held_power_cells, scaled, units_bases};
use super::{DELTA, RunResult, clopper_pearson, guard_share, run_many};
use crate::common::{markdown, median};

/// Seeds of the family's cells start here (apart from the other tables' seeds).
const SEED: u64 = 900_000_000;

/// The share of runs opened, their first openings and the row's unsafe-cell columns.
fn unsafe_row(cell: &Cell, results: &[RunResult], runs: usize) -> Vec<String> {
    let opened = results.iter().filter(|r| r.calibrated_open.is_some()).count();
    let (_, hi) = clopper_pearson(opened, runs);
    vec![
        cell.family.clone(),
        format!("{:.3}", cell.truth()),
        format!("{opened} / {runs}"),
        format!("{hi:.4}"),
        if hi <= 2.0 * DELTA { "yes".into() } else { "**no**".into() },
        guard_share(results),
        super::refusal_share(results),
    ]
}

fn power_row(cell: &Cell, results: &[RunResult], runs: usize) -> Vec<String> {
    let times: Vec<f64> = results.iter().filter_map(|r| r.calibrated_open).collect();
    vec![
        cell.family.clone(),
        format!("{:.3}", cell.truth()),
        format!("{:.1} %", 100.0 * times.len() as f64 / runs as f64),
        if times.is_empty() { "never".into() } else { format!("{:.2}", median(&times)) },
        guard_share(results),
        super::refusal_share(results),
    ]
}

const UNSAFE_HEADER: [&str; 7] = [
    "cell",
    "β*",
    "calibrated opened",
    "95 % CP upper",
    "≤ 2δ",
    "guard closed: all / hidden dynamics",
    "weakly identified",
];
const POWER_HEADER: [&str; 6] = [
    "cell",
    "β*",
    "calibrated certified",
    "median time [s]",
    "guard closed: all / hidden dynamics",
    "weakly identified",
];

/// The two families' tables: `runs` per unsafe cell, `power_runs` per contracting one.
pub(super) fn tables(
    runs: usize,
    power_runs: usize,
    bar: &indicatif::ProgressBar,
) -> Result<String> {
    let mut s = String::new();
    let mut seed = SEED;
    let mut next = || {
        seed += 1_000_000;
        seed
    };
    let rows = held_cells()
        .iter()
        .map(|c| Ok(unsafe_row(c, &run_many(c, runs, next(), bar)?, runs)))
        .collect::<Result<Vec<_>>>()?;
    let _ = writeln!(
        s,
        "## Held inputs: a step test (n_s = 1, {runs} runs each): every opening is false\n\n`ẏ = −y + u + w` explored in open loop by a PRBS of ±1 held for the named time (it switches sign at a hold's end with probability ½), 60 s at dt = 0.02, M = 150; the candidates `K = 1.5` (β* = −0.5) and `K = 0.96` (β* = 0.04) are far from the exploring gain 0.\n\n{}",
        markdown(&UNSAFE_HEADER, &rows)
    );
    let rows = held_power_cells()
        .iter()
        .map(|c| Ok(power_row(c, &run_many(c, power_runs, next(), bar)?, power_runs)))
        .collect::<Result<Vec<_>>>()?;
    let _ = writeln!(
        s,
        "## Held inputs: contracting candidates (n_s = 10, {power_runs} runs each)\n\n{}",
        markdown(&POWER_HEADER, &rows)
    );
    let (power, unsafe_cell) = units_bases();
    let base = next();
    let rows = scaled(&unsafe_cell)
        .iter()
        .map(|c| Ok(unsafe_row(c, &run_many(c, runs, base, bar)?, runs)))
        .collect::<Result<Vec<_>>>()?;
    let _ = writeln!(
        s,
        "## Units: the same loop logged in other units (n_s = 1, {runs} runs each)\n\nThe held-input cell at 10 s, σ = 1.5, β* = −0.5 with `y` or `u` multiplied by a constant and the candidate gain scaled with it (the same loop, the same seeds in every row).\n\n{}",
        markdown(&UNSAFE_HEADER, &rows)
    );
    // The same seeds in every scaled row: a difference between rows is the units' alone.
    let base = next();
    let rows = scaled(&power)
        .iter()
        .map(|c| Ok(power_row(c, &run_many(c, power_runs, base, bar)?, power_runs)))
        .collect::<Result<Vec<_>>>()?;
    let _ = writeln!(
        s,
        "## Units: the 5× power cell logged in other units (n_s = 10, {power_runs} runs each, the same seeds in every row)\n\n{}",
        markdown(&POWER_HEADER, &rows)
    );
    Ok(s)
}

/// Cells the family runs: unsafe ones at `runs`, contracting ones at `power_runs`.
pub(super) fn work(runs: usize, power_runs: usize) -> usize {
    let (power, unsafe_cell) = units_bases();
    (held_cells().len() + scaled(&unsafe_cell).len()) * runs
        + (held_power_cells().len() + scaled(&power).len()) * power_runs
}
