//! The order-`n` cells of `cargo xtask validity --only-order RUNS`: the certificate of order
//! `n` (`[regression] order = 2 | 3`) through the certifier and its calibrated gate, on loops
//! measured through one output whose other states are hidden (`ObservableLoop`), at the
//! boundary (closed loops just below the margin), beyond the order, for power and after a
//! plant change (ORDER.md).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;
use streamcert_certificate::{Calibration, Certifier, CertifierConfig, NotCertified, OrderLadder};
use streamcert_dynamics::ObservableLoop;
use streamcert_regression::{LoopModel, RegressionConfig};

use super::{DELTA, MARGIN, clopper_pearson};
use crate::common::{markdown, median, progress, write};

/// The certificate's window in rows and its horizon in samples (20 s and 0.5 s at 100 Hz).
const WINDOW: usize = 2000;
const HORIZON: usize = 50;
/// Where the plant-change cell's plant changes (samples), and its length.
const CHANGE_AT: usize = 3000;
const CHANGE_SAMPLES: usize = 7000;

/// One cell: a loop, the order certified (or with `auto`, `order = "auto"`: orders 1 to 3),
/// and the units `y` and `u` are read in (`y · scale.0`, `u · scale.1`; the gain is given to
/// the certifier in those units).
#[derive(Clone)]
pub(super) struct Cell {
    pub(super) name: String,
    pub(super) order: usize,
    pub(super) plant: ObservableLoop,
    pub(super) scale: (f64, f64),
    pub(super) auto: bool,
    /// The window (rows) and horizon certified at: `(WINDOW, HORIZON)` unless set.
    pub(super) regression: (usize, usize),
}

impl Cell {
    /// The plant `a` under `gain` at `order`, with sensor noise `σ = 0.01` or, with
    /// `process`, process noise `σ_p = 0.05` on the unmeasured last state and no sensor noise.
    pub(super) fn new(name: &str, order: usize, a: &[f64], gain: f64, process: bool) -> Self {
        let mut plant = ObservableLoop::new(a, gain);
        if process {
            (plant.sensor, plant.process) = (0.0, 0.05);
        }
        let noise = if process { "process noise" } else { "sensor noise" };
        let (scale, auto, regression) = ((1.0, 1.0), false, (WINDOW, HORIZON));
        Self { name: format!("{name}, {noise}"), order, plant, scale, auto, regression }
    }

    /// The certifier a user gets with `[regression] order = n`, `window = 2000`, `horizon =
    /// 50`, `[calibration] delta = 0.01` (every default of the certificate of order `n`: its
    /// look period, the hidden-dynamics guard), margin 0.05, a one-sample gate; with `auto`,
    /// `order = "auto"` instead.
    pub(super) fn config(&self) -> Result<CertifierConfig> {
        let order = if self.auto { 1 } else { self.order };
        let regression = RegressionConfig {
            order: LoopModel::of_order(order)
                .ok_or_else(|| anyhow::anyhow!("order {order} is not 1, 2 or 3"))?,
            ..RegressionConfig::new(1, 1, self.regression.0, self.regression.1, 0.0)
        };
        let gain = self.plant.gain * self.scale.1 / self.scale.0;
        let mut cfg = CertifierConfig::new(regression, vec![gain], 1.0, MARGIN, 1);
        cfg.calibration = Some(Calibration::new(DELTA));
        cfg.orders = self.auto.then(OrderLadder::automatic);
        Ok(cfg)
    }

    /// The true rate before and after the cell's plant change (the same without one).
    pub(super) fn truth(&self) -> (f64, f64) {
        let before = self.plant.rate();
        let after = self.plant.change.as_ref().map_or(before, |(_, a)| {
            ObservableLoop { a: a.clone(), change: None, ..self.plant.clone() }.rate()
        });
        (before, after)
    }
}

/// What one run shows.
#[derive(Default)]
pub(super) struct Run {
    /// The first and the last sample the gate was open at.
    pub(super) first_open: Option<f64>,
    last_open: Option<f64>,
    /// Samples the gate was open at, by the standing look's order (1 to 3).
    pub(super) open_at_order: [usize; 3],
    /// Open at some sample before the plant change (the whole run without one).
    open_before_change: bool,
    /// Some look stated a margin above the true rate (an overstated rate, whether or not the
    /// gate opened on it).
    overstated: bool,
    /// Looks, and looks the hidden-dynamics and the nonlinearity guards refused.
    looks: usize,
    hidden: usize,
    varying: usize,
}

fn one(cell: &Cell, seed: u64) -> Result<Run> {
    let mut cert = Certifier::new(cell.config()?)?;
    let (before, after) = cell.truth();
    let change_time =
        cell.plant.change.as_ref().map_or(f64::INFINITY, |c| c.0 as f64 * cell.plant.dt);
    let mut run = Run::default();
    let (mut seen, mut failed) = (0u64, None);
    cell.plant.run(seed, |t, y, u| {
        let ev = match cert.push(t, &[y * cell.scale.0], &[u * cell.scale.1]) {
            Ok(ev) => ev,
            Err(e) => {
                failed = Some(e);
                return false;
            }
        };
        if ev.calibrated.open {
            if let Some(n) = ev.calibrated_order.filter(|n| (1..=3).contains(n)) {
                run.open_at_order[n - 1] += 1;
            }
            run.first_open.get_or_insert(t);
            run.last_open = Some(t);
            run.open_before_change |= t < change_time;
        }
        if let Some(look) = cert.order_n_look().filter(|l| l.index != seen) {
            seen = look.index;
            run.looks += 1;
            // The truth the look is judged against: the worse of the two where its window
            // holds rows from both plants.
            let truth = if t < change_time { before } else { before.min(after) };
            match &look.outcome {
                Ok(region) => run.overstated |= region.margin.is_some_and(|m| m > truth),
                Err(NotCertified::HiddenDynamics { .. }) => run.hidden += 1,
                Err(NotCertified::VaryingDynamics { .. }) => run.varying += 1,
                Err(_) => {}
            }
        }
        true
    });
    match failed {
        Some(e) => Err(e.into()),
        None => Ok(run),
    }
}

/// `runs` seeds of a cell from `base`, on two threads.
pub(super) fn runs_of(
    cell: &Cell,
    base: u64,
    runs: usize,
    bar: &indicatif::ProgressBar,
) -> Result<Vec<Run>> {
    let half = runs / 2;
    std::thread::scope(|s| {
        let a =
            s.spawn(|| (0..half).map(|r| one(cell, base + r as u64)).collect::<Result<Vec<_>>>());
        let b = (half..runs)
            .map(|r| {
                bar.inc(2);
                one(cell, base + r as u64)
            })
            .collect::<Result<Vec<_>>>();
        let mut a = a.join().expect("worker thread")?;
        a.extend(b?);
        Ok(a)
    })
}

/// The loops just below the margin: each order-2 and order-3 plant with sensor noise and with
/// process noise, the input held 10 s and 30 s, and the units of `y` and `u`.
pub(super) fn near_cells() -> Vec<Cell> {
    let real = |name: &str| Cell::new(name, 2, &[1.2, 1.0], 0.948_025, false);
    let mut cells = Vec::new();
    for process in [false, true] {
        // s² + 0.09 s + 2: −0.045 ± 1.41 j.
        cells.push(Cell::new("order 2, a complex pair", 2, &[0.09, 1.0], -1.0, process));
        // Open loop (s + 0.1)(s + 2); closed (s + 0.045)(s + 2.055).
        let slow = "order 2, a slow tank feeding a fast one";
        cells.push(Cell::new(slow, 2, &[2.1, 0.2], 0.107_525, process));
        // An unstable plant (s − 0.5) read through a sensor lag (s + 5); closed
        // (s + 0.045)(s + 4.455).
        let lag = "order 2, an unstable plant behind a sensor lag";
        cells.push(Cell::new(lag, 2, &[4.5, -2.5], -2.700_475, process));
        // (s + 1)³ − 0.955³: rightmost root −0.045.
        cells.push(Cell::new(
            "order 3, three lags",
            3,
            &[3.0, 3.0, 1.0],
            0.955f64.powi(3),
            process,
        ));
    }
    for hold in [10, 30] {
        let mut cell = real(&format!("order 2, a real pair, the input held {hold} s"));
        cell.plant.hold = hold * 100;
        cells.push(cell);
    }
    for (what, scale) in [
        ("y × 0.01", (0.01, 1.0)),
        ("y × 100", (100.0, 1.0)),
        ("u × 0.01", (1.0, 0.01)),
        ("u × 100", (1.0, 100.0)),
    ] {
        cells.push(Cell { scale, ..real(&format!("order 2, a real pair in units {what}")) });
    }
    cells
}

/// Plants beyond the order, just below the margin: four lags and a transport delay at
/// order 3, and at order 2 the same with three lags, and four lags under a dither ten times
/// larger (a higher signal-to-noise ratio, where a misfit is seen best and a biased fit is
/// most confident); and beyond linearity, a loop whose static term stiffens at order 2.
pub(super) fn beyond_cells() -> Vec<Cell> {
    // (s + 1)ᴺ − 0.955ᴺ: rightmost root −0.045.
    let lags = |count: i32, order: usize| {
        let a: Vec<f64> = (1..=count as u64)
            .map(|k| (1..=k).fold(1.0, |c, j| c * (count as u64 - j + 1) as f64 / j as f64))
            .collect();
        let name = if count == 3 { "three lags" } else { "four lags in series" };
        Cell::new(name, order, &a, 0.955f64.powi(count), false)
    };
    // ẏ = −y + K y(t − τ), τ = 10 samples: rightmost root −0.045 for K = 0.955 e^{−0.045 τ}.
    let delay = |order: usize| {
        let name = "a lag behind a transport delay of 10 samples";
        let mut cell = Cell::new(name, order, &[1.0], 0.955 * (-0.0045f64).exp(), false);
        cell.plant.delay = 10;
        cell
    };
    // ÿ + 1.2 ẏ + y + 2 y³ = u + 0.1 under K = 0.97: the slope 0.03 + 6 y², the rate about
    // 0.025 at y = 0 (visited), about 0.6 at the far end of the excursion.
    let stiff = Cell {
        name: "a stiffening spring, rate 0.025 at y = 0, sensor noise".into(),
        plant: ObservableLoop { cubic: 2.0, ..ObservableLoop::new(&[1.2, 1.0], 0.97) },
        ..Cell::new("", 2, &[1.2, 1.0], 0.97, false)
    };
    let mut loud = lags(4, 2);
    loud.plant.amplitude = 1.0;
    loud.name = "four lags in series, dither ±1, sensor noise".into();
    vec![lags(4, 3), delay(3), lags(3, 2), lags(4, 2), loud, delay(2), stiff]
}

/// Loops of order 2 at 2×, 5× and 20× the margin.
pub(super) fn power_cells() -> Vec<Cell> {
    vec![
        // (s + 0.1)(s + 1.1), (s + 0.25)(s + 0.95), (s + 1)(s + 2).
        Cell::new("order 2, 2× the margin", 2, &[1.2, 1.0], 0.89, false),
        Cell::new("order 2, 5× the margin", 2, &[1.2, 1.0], 0.7625, false),
        Cell::new("order 2, 20× the margin", 2, &[3.0, 3.0], 1.0, false),
    ]
}

/// 5× the margin for 30 s, then the closed loop (s + 0.045)(s + 1.155), for 70 s.
fn change_cell() -> Cell {
    let mut cell =
        Cell::new("order 2, 5× the margin → just below it", 2, &[1.2, 1.0], 0.7625, false);
    (cell.plant.change, cell.plant.samples) =
        (Some((CHANGE_AT, vec![1.2, 0.814_475])), CHANGE_SAMPLES);
    cell
}

pub(super) fn share(k: usize, n: usize) -> String {
    format!("{:.1} %", 100.0 * k as f64 / n.max(1) as f64)
}

/// Looks the hidden-dynamics guard refused, and looks the nonlinearity guard refused, over
/// all looks.
fn hidden_share(results: &[Run]) -> String {
    let looks = results.iter().map(|r| r.looks).sum();
    let hidden = results.iter().map(|r| r.hidden).sum();
    let varying = results.iter().map(|r| r.varying).sum();
    format!("{} / {}", share(hidden, looks), share(varying, looks))
}

/// A boundary cell's row: its name, `β*`, the runs opened, the 95 % Clopper–Pearson upper
/// bound on the false-opening rate and whether it is at most 2δ.
pub(super) fn boundary_row(cell: &Cell, results: &[Run]) -> Vec<String> {
    let runs = results.len();
    let opened = results.iter().filter(|r| r.first_open.is_some()).count();
    let (_, hi) = clopper_pearson(opened, runs);
    vec![
        cell.name.clone(),
        format!("{:.4}", cell.truth().0),
        format!("{opened} / {runs}"),
        format!("{hi:.4}"),
        if hi <= 2.0 * DELTA { "yes".into() } else { "**no**".into() },
    ]
}

/// The loops just below the margin, `runs` each.
fn near_table(runs: usize, bar: &indicatif::ProgressBar) -> Result<String> {
    let mut s = String::new();
    let mut rows = Vec::new();
    for (ci, cell) in near_cells().iter().enumerate() {
        let results = runs_of(cell, 300_000_000 + 1_000_000 * ci as u64, runs, bar)?;
        let mut row = boundary_row(cell, &results);
        row.push(format!("{} / {runs}", results.iter().filter(|r| r.overstated).count()));
        row.push(hidden_share(&results));
        rows.push(row);
    }
    let _ = writeln!(s, "## Loops just below the margin (n_s = 1): every opening is false\n");
    let header = [
        "cell",
        "β*",
        "opened",
        "95 % CP upper",
        "≤ 2δ",
        "runs with a look above β*",
        "looks refused: hidden dynamics / nonlinearity",
    ];
    let _ = writeln!(s, "{}", markdown(&header, &rows));
    Ok(s)
}

/// The plants beyond order 3, `beyond_runs` each.
fn beyond_table(beyond_runs: usize, bar: &indicatif::ProgressBar) -> Result<String> {
    let mut s = String::new();
    let mut rows = Vec::new();
    for (ci, cell) in beyond_cells().iter().enumerate() {
        let results = runs_of(cell, 310_000_000 + 1_000_000 * ci as u64, beyond_runs, bar)?;
        let opened = results.iter().filter(|r| r.first_open.is_some()).count();
        rows.push(vec![
            cell.name.clone(),
            cell.order.to_string(),
            format!("{:.4}", cell.truth().0),
            format!("{opened} / {beyond_runs}"),
            hidden_share(&results),
        ]);
    }
    let _ = writeln!(
        s,
        "## Beyond the model: plants of a higher order than the one certified, and a nonlinear one\n"
    );
    let header = ["cell", "order", "β*", "opened", "looks refused: hidden dynamics / nonlinearity"];
    let _ = writeln!(s, "{}", markdown(&header, &rows));
    Ok(s)
}

/// A power cell's row: its name, `β*`, the share of runs certified and the median first
/// opening.
pub(super) fn power_row(cell: &Cell, results: &[Run]) -> Vec<String> {
    let times: Vec<f64> = results.iter().filter_map(|r| r.first_open).collect();
    vec![
        cell.name.clone(),
        format!("{:.4}", cell.truth().0),
        share(times.len(), results.len()),
        if times.is_empty() { "never".into() } else { format!("{:.2}", median(&times)) },
    ]
}

/// The loops of order 2 at 2×, 5× and 20× the margin, `power_runs` each.
fn power_table(power_runs: usize, bar: &indicatif::ProgressBar) -> Result<String> {
    let mut s = String::new();
    let mut rows = Vec::new();
    for (ci, cell) in power_cells().iter().enumerate() {
        let results = runs_of(cell, 320_000_000 + 1_000_000 * ci as u64, power_runs, bar)?;
        let mut row = power_row(cell, &results);
        row.push(hidden_share(&results));
        rows.push(row);
    }
    let _ = writeln!(s, "## Power ({power_runs} runs each)\n");
    let header = [
        "cell",
        "β*",
        "certified",
        "median first opening [s]",
        "looks refused: hidden dynamics / nonlinearity",
    ];
    let _ = writeln!(s, "{}", markdown(&header, &rows));
    Ok(s)
}

/// The plant change, `change_runs` runs.
fn change_table(change_runs: usize, bar: &indicatif::ProgressBar) -> Result<String> {
    let mut s = String::new();
    let cell = change_cell();
    let results = runs_of(&cell, 330_000_000, change_runs, bar)?;
    let change = CHANGE_AT as f64 * cell.plant.dt;
    let span = WINDOW as f64 * cell.plant.dt;
    let late = results.iter().filter(|r| r.last_open.is_some_and(|t| t >= change + 1.5 * span));
    let late = late.count();
    let (before, after) = cell.truth();
    let _ = writeln!(s, "## A plant change ({change_runs} runs)\n");
    let header = [
        "cell",
        "β* before / after",
        "change at [s]",
        "open before it",
        "open past 1.5 windows after it",
        "≤ 5 %",
    ];
    let row = vec![
        cell.name.clone(),
        format!("{before:.4} / {after:.4}"),
        format!("{change}"),
        share(results.iter().filter(|r| r.open_before_change).count(), change_runs),
        share(late, change_runs),
        if late * 20 <= change_runs { "yes".into() } else { "**no**".into() },
    ];
    let _ = writeln!(s, "{}", markdown(&header, &[row]));
    Ok(s)
}

/// The order cells, `runs` per near-margin cell, into `ORDER.md` under `out`.
pub(crate) fn order_only(runs: usize, out: &Path) -> Result<()> {
    let beyond_runs = runs.min(200);
    let power_runs = (runs / 5).clamp(20, 400);
    let change_runs = (runs / 10).clamp(20, 200);
    // The order ladder runs three orders a sample: a quarter of the runs at the boundary
    // (at least 200, whose 0 openings bound the rate below 2δ).
    let auto_runs = (runs / 4).max(20);
    let (auto_near, auto_beyond, auto_power) = super::order_auto::counts();
    let bar = progress(
        near_cells().len() * runs
            + beyond_cells().len() * beyond_runs
            + power_cells().len() * power_runs
            + change_runs
            + auto_near * auto_runs
            + auto_beyond * beyond_runs
            + auto_power * power_runs,
        "order n",
    );
    let mut s = format!(
        "# The certificate of order n\n\nProduced by `cargo xtask validity --only-order {runs}`. Each run: a loop `u = K y_m + d` around the plant `y⁽ᴺ⁾ + a_1 y⁽ᴺ⁻¹⁾ + … + a_N y = u + 0.1` in observable form (only `y` measured; the input and the constant enter the last state), from rest, simulated exactly (zero-order hold) at 100 Hz for 40 s; `d` a dither of ±0.1 whose sign is redrawn every second (unless held longer); sensor noise `σ = 0.01` on `y`, or process noise `σ_p = 0.05` (`σ_p √dt w` per sample) on the last, unmeasured state. The certifier a user gets with `[regression] order = n`, `window = {WINDOW}`, `horizon = {HORIZON}` and `[calibration] delta = {DELTA}`: the certificate of order n with its defaults (the first look when the window is full, looks every {} samples, the hidden-dynamics guard at risk δ per look), margin {MARGIN}, a one-sample gate. `β*` is the rate of the loop as simulated (`−ln ϱ(Φ_cl)/dt`, the sampled closed loop's spectral radius, `ObservableLoop::rate`).\n\n",
        WINDOW / 10
    );
    s.push_str(&near_table(runs, &bar)?);
    s.push_str(&beyond_table(beyond_runs, &bar)?);
    s.push_str(&power_table(power_runs, &bar)?);
    s.push_str(&change_table(change_runs, &bar)?);
    s.push_str(&super::order_auto::tables((auto_runs, beyond_runs, power_runs), &bar)?);
    bar.finish_and_clear();
    let _ = writeln!(
        s,
        "## Reading the tables\n\n- `95 % CP upper`: the upper end of the two-sided 95 % Clopper–Pearson interval on the false-opening rate; the cell passes when it is at most 2δ = {}.\n- `runs with a look above β*`: the runs in which some look stated a margin above the loop's true rate, whether or not the gate opened on it (a look below the margin states one too).\n- `looks refused: hidden dynamics / nonlinearity`: the looks whose verdict was the hidden-dynamics guard's (the past row's coefficients tested at every look), and the nonlinearity guard's (the square and the cube of the output where the static term enters); beyond the model it is the guards' power, on a loop the model holds their false refusals.
- `β*` of the stiffening spring is the rate of its linearisation at `y = 0`, the slowest point of the region it visits.\n- A plant change: the window is {} s; past 1.5 windows after the change every row the window holds comes from the new plant. The certificate of order n has no change guard of its own: it forgets the old plant as its window slides.",
        2.0 * DELTA,
        WINDOW as f64 * 0.01
    );
    write(&out.join("ORDER.md"), &s)?;
    println!("wrote {}", out.join("ORDER.md").display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every boundary and beyond-the-order loop is just below the margin (within 0.01 of it;
    /// the stiffening spring below it),
    /// every power loop above it, and the plant change crosses it.
    #[test]
    fn the_cells_sit_where_their_tables_say() {
        for cell in near_cells().iter().chain(&beyond_cells()) {
            let rate = cell.truth().0;
            // The stiffening spring is below the margin at y = 0, not just below it.
            let floor = if cell.plant.cubic == 0.0 { MARGIN - 0.01 } else { 0.0 };
            assert!(rate < MARGIN && rate > floor, "{}: {rate}", cell.name);
        }
        for (cell, times) in power_cells().iter().zip([2.0, 5.0, 20.0]) {
            let rate = cell.truth().0;
            assert!((rate / MARGIN - times).abs() < 0.05 * times, "{}: {rate}", cell.name);
        }
        let (before, after) = change_cell().truth();
        assert!(before > 4.0 * MARGIN && after < MARGIN, "{before} → {after}");
        // Each cell's configuration is one the certifier accepts.
        for cell in near_cells().iter().chain(&beyond_cells()).chain(&power_cells()) {
            assert!(Certifier::new(cell.config().unwrap()).is_ok(), "{}", cell.name);
        }
    }
}
