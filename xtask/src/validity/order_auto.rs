//! ORDER.md's `order = "auto"` sections: the same loops through the order ladder (orders 1, 2
//! and 3 side by side, each at risk `δ / 3`, the gate open when any is), with first-order loops
//! beside them: the boundary (every opening false), beyond the model, and power, with the
//! order whose look stood.

use std::fmt::Write as _;

use anyhow::Result;

use super::order::{
    Cell, Run, beyond_cells, boundary_row, near_cells, power_cells, power_row, runs_of, share,
};
use crate::common::markdown;

/// `cell` under `order = "auto"`.
fn auto(mut cell: Cell) -> Cell {
    cell.auto = true;
    cell
}

/// A first-order loop `ẏ = −y + u + 0.1` under `gain`, sensor noise.
fn first_order(name: &str, gain: f64) -> Cell {
    Cell::new(name, 1, &[1.0], gain, false)
}

/// The boundary cells: ORDER.md's loops just below the margin and a first-order loop there.
pub(super) fn near() -> Vec<Cell> {
    let mut cells: Vec<Cell> = near_cells().into_iter().map(auto).collect();
    // ẏ = −y + u + 0.1 under K = 0.955: rate 0.045.
    cells.push(auto(first_order("order 1, a lag", 0.955)));
    cells
}

/// Plants beyond every order certified, and beyond linearity: ORDER.md's, each plant once
/// (its table runs some at two orders).
pub(super) fn beyond() -> Vec<Cell> {
    let mut cells: Vec<Cell> = Vec::new();
    for cell in beyond_cells() {
        if cells.iter().all(|c| c.name != cell.name) {
            cells.push(auto(cell));
        }
    }
    cells
}

/// Loops the ladder should certify: hidden-state plants read by one output, ORDER.md's
/// order-2 power loops, and first-order loops at 2× and 5× the margin.
pub(super) fn power() -> Vec<Cell> {
    let mut cells = vec![
        // ÿ + ẏ + y = u + 0.1 under K = −2: s² + s + 3, rate 0.5.
        Cell::new("a damped mass read by its position, K = −2", 2, &[1.0, 1.0], -2.0, false),
        // Two equal tanks (s + 1)², the lower one read, K = −1: s² + 2 s + 2, rate 1.
        Cell::new("a tank behind a tank, K = −1", 2, &[2.0, 1.0], -1.0, false),
        // ẏ = −y + u read through a 0.3 s sensor lag: (s + 1)(s + 10/3), K = −10/3 (−1 in
        // the plant's units): rate 2.17.
        Cell::new(
            "a lag read through a 0.3 s sensor lag, K = −1",
            2,
            &[13.0 / 3.0, 10.0 / 3.0],
            -10.0 / 3.0,
            false,
        ),
    ];
    cells.extend(power_cells());
    cells.push(first_order("order 1, 2× the margin", 0.9));
    cells.push(first_order("order 1, 5× the margin", 0.75));
    cells.into_iter().map(auto).collect()
}

/// The power cells at the command line's own window and horizon (`M = 150`, `h = 5`): what
/// `order = "auto"` certifies with only the columns, gain and margin set.
pub(super) fn power_at_defaults() -> Vec<Cell> {
    power()
        .into_iter()
        .map(|mut c| {
            c.regression = (150, 5);
            c
        })
        .collect()
}

/// The rows open at each order over all runs, as shares of the open rows: `1 / 2 / 3`.
fn orders_share(results: &[Run]) -> String {
    let by: [usize; 3] =
        std::array::from_fn(|k| results.iter().map(|r| r.open_at_order[k]).sum::<usize>());
    let all: usize = by.iter().sum();
    if all == 0 {
        return "–".into();
    }
    format!("{} / {} / {}", share(by[0], all), share(by[1], all), share(by[2], all))
}

/// The three tables, `runs` runs per boundary cell, `beyond_runs` and `power_runs` for the
/// others.
pub(super) fn tables(
    (runs, beyond_runs, power_runs): (usize, usize, usize),
    bar: &indicatif::ProgressBar,
) -> Result<String> {
    let mut s = String::from(
        "## `order = \"auto\"`: orders 1, 2 and 3 side by side\n\nThe same loops through the certifier a user gets with `[regression] order = \"auto\"` and the window, horizon and risk above: the calibrated certificate at orders 1, 2 and 3, each at risk δ/3, each order's window raised to the smallest its guards hold (order 3: 1963 rows), the gate open when any order's is (one sample). `open at order 1 / 2 / 3`: of the rows the gate was open, the share whose standing look was each order's.\n\n",
    );
    let mut rows = Vec::new();
    for (ci, cell) in near().iter().enumerate() {
        let results = runs_of(cell, 340_000_000 + 1_000_000 * ci as u64, runs, bar)?;
        rows.push(boundary_row(cell, &results));
    }
    let _ = writeln!(s, "### Loops just below the margin: every opening is false\n");
    let _ = writeln!(s, "{}", markdown(&["cell", "β*", "opened", "95 % CP upper", "≤ 2δ"], &rows));
    let mut rows = Vec::new();
    for (ci, cell) in beyond().iter().enumerate() {
        let results = runs_of(cell, 350_000_000 + 1_000_000 * ci as u64, beyond_runs, bar)?;
        let opened = results.iter().filter(|r| r.first_open.is_some()).count();
        rows.push(vec![
            cell.name.clone(),
            format!("{:.4}", cell.truth().0),
            format!("{opened} / {beyond_runs}"),
            orders_share(&results),
        ]);
    }
    let _ = writeln!(s, "### Beyond the model\n");
    let header = ["cell", "β*", "opened", "open at order 1 / 2 / 3"];
    let _ = writeln!(s, "{}", markdown(&header, &rows));
    for (title, cells, base) in [
        (format!("Power ({power_runs} runs each)"), power(), 360_000_000),
        (
            format!(
                "Power at the command line's window and horizon, `M = 150`, `h = 5` ({power_runs} runs each)"
            ),
            power_at_defaults(),
            370_000_000,
        ),
    ] {
        s.push_str(&power_table(&title, &cells, base, power_runs, bar)?);
    }
    Ok(s)
}

/// One power table: `cells`, `power_runs` runs each from seed `base`.
fn power_table(
    title: &str,
    cells: &[Cell],
    base: u64,
    power_runs: usize,
    bar: &indicatif::ProgressBar,
) -> Result<String> {
    let mut s = String::new();
    let mut rows = Vec::new();
    for (ci, cell) in cells.iter().enumerate() {
        let results = runs_of(cell, base + 1_000_000 * ci as u64, power_runs, bar)?;
        let mut row = power_row(cell, &results);
        row.push(orders_share(&results));
        rows.push(row);
    }
    let _ = writeln!(s, "### {title}\n");
    let header = ["cell", "β*", "certified", "median first opening [s]", "open at order 1 / 2 / 3"];
    let _ = writeln!(s, "{}", markdown(&header, &rows));
    Ok(s)
}

/// The cells `tables` runs, for the progress bar: boundary, beyond, power (both tables).
pub(super) fn counts() -> (usize, usize, usize) {
    (near().len(), beyond().len(), power().len() + power_at_defaults().len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validity::MARGIN;
    use streamcert_certificate::Certifier;
    use streamcert_dynamics::ObservableLoop;

    /// Every boundary and beyond-the-model loop is below the margin, every power loop at
    /// least twice above it, and every cell runs `order = "auto"`.
    #[test]
    fn the_auto_cells_sit_where_their_tables_say() {
        for cell in near().iter().chain(&beyond()) {
            assert!(cell.truth().0 < MARGIN, "{}", cell.name);
        }
        for cell in &power() {
            assert!(cell.truth().0 >= 2.0 * MARGIN * 0.95, "{}: {}", cell.name, cell.truth().0);
        }
        let lagged = ObservableLoop::new(&[13.0 / 3.0, 10.0 / 3.0], -10.0 / 3.0).rate();
        assert!((lagged - 2.1667).abs() < 0.01, "{lagged}");
        for cell in near().iter().chain(&beyond()).chain(&power()) {
            assert!(cell.auto, "{}", cell.name);
            let cfg = cell.config().unwrap();
            assert!(cfg.orders.is_some() && Certifier::new(cfg).is_ok(), "{}", cell.name);
        }
    }
}
