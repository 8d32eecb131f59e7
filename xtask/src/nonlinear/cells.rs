//! The study's cells: the loops, their candidate gains and truths, and how long they run.

use anyhow::Result;
use streamcert_dynamics::{G5, Process, ScalarDrift, ScalarScenario};
use streamcert_experiments::{Experiment, G5Dataset};

use super::WINDOW;

/// One cell: a loop, the candidate gain, and whether its smallest visited rate is meant to be
/// below the margin (a validity cell) or at least 3× above it (a power cell).
pub(super) struct Cell {
    pub(super) name: &'static str,
    pub(super) scenario: ScalarScenario,
    pub(super) k: f64,
    pub(super) validity: bool,
    /// Instead of the scalar scenario: G5's subsystem A (`Some(0)`: output `x1`, input `u1`,
    /// candidate `k1`) or B (`Some(1)`: output `x4`, input `u4`, candidate `k4`) on
    /// Experiment 2's data (`γ = 0`), run `g5_steps` samples of 0.02 s.
    pub(super) g5: Option<usize>,
    /// Samples of a G5 cell (2000: the experiment's 40 s).
    pub(super) g5_steps: usize,
    /// Base window `M` (columns); the smallest the cubic library with its two lack-of-fit
    /// terms accepts is `h (D + e + m + 2) = 45` with the affine model's intercept (`m`
    /// counts `τ` as an input).
    pub(super) window: usize,
    /// Number of calibrated windows `M, 2M, …` (`None`: the default, doubling until the
    /// longest holds 200 blocks of `h` columns, at least five). The long-run power cells raise it so that the
    /// longest window grows with the run.
    pub(super) windows: Option<usize>,
}

impl Cell {
    /// The true local rate at output `y` under the candidate gain.
    pub(super) fn rate(&self, y: f64) -> f64 {
        match self.g5 {
            // The dynamics crate's truth: A's rate depends on x1 = y only, B's on nothing.
            Some(which) => {
                let x = if which == 0 { [y, 0.0, 0.0, 0.0, 0.0] } else { [0.0, 0.0, 0.0, y, 0.0] };
                let rates = self.g5_system().map(|g| g.observed_closed_loop_rates(&x));
                rates.map_or(f64::NAN, |r| if which == 0 { r.a } else { r.b })
            }
            None => self.scenario.local_rate(y, self.k),
        }
    }

    /// Experiment 2's G5 (for its true local rates).
    fn g5_system(&self) -> Option<G5> {
        G5Dataset::defaults(Experiment::Two).system().ok()
    }

    /// Times, outputs and inputs of run `seed`.
    pub(super) fn data(&self, seed: u64) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>)> {
        if let Some(which) = self.g5 {
            let data =
                G5Dataset { steps: Some(self.g5_steps), ..G5Dataset::defaults(Experiment::Two) };
            let traj = data.run_seeded(seed)?;
            let pick = |v: &[f64], w: usize| v.chunks_exact(w).map(|r| r[which]).collect();
            Ok((traj.t.clone(), pick(&traj.y, traj.p), pick(&traj.u, traj.m)))
        } else {
            let traj = self.scenario.run(seed)?;
            Ok((traj.t, traj.y, traj.u))
        }
    }
}

fn base() -> ScalarScenario {
    ScalarScenario::new(ScalarDrift::NegXTanhX, -1.1)
}

/// The cubic `f = 0.5 x − 0.6 x³` explored by `u = −1.5 y + PRBS(±1, held 0.5 s)` with
/// process noise `sigma`: under `K` its rate is `−0.5 − K + 1.8 x²`, smallest at `x = 0`.
fn cubic(sigma: f64) -> ScalarScenario {
    ScalarScenario {
        drift: ScalarDrift::Polynomial(vec![0.0, 0.5, 0.0, -0.6]),
        k_explore: -1.5,
        dither: 1.0,
        dither_hold: 0.5,
        noise: Process::Gaussian { sigma },
        ..base()
    }
}

impl Cell {
    /// A cell on a scalar loop with the study's base window and default windows.
    fn new(name: &'static str, scenario: ScalarScenario, k: f64, validity: bool) -> Self {
        Self {
            name,
            scenario,
            k,
            validity,
            g5: None,
            g5_steps: 2000,
            window: WINDOW,
            windows: None,
        }
    }

    /// A validity cell: the smallest visited rate is below the margin.
    fn validity(name: &'static str, scenario: ScalarScenario, k: f64) -> Self {
        Self::new(name, scenario, k, true)
    }

    /// A power cell: the smallest visited rate is at least 3× the margin.
    fn power(name: &'static str, scenario: ScalarScenario, k: f64) -> Self {
        Self::new(name, scenario, k, false)
    }

    /// Run `steps` samples (of the scalar loop, or of G5) with `windows` calibrated windows.
    fn long(self, steps: usize, windows: usize) -> Self {
        Self {
            scenario: ScalarScenario { steps, ..self.scenario },
            g5_steps: steps,
            windows: Some(windows),
            ..self
        }
    }
}

/// G5's subsystem `which` (0: A, 1: B) on Experiment 2's data, with candidate gain `k`.
fn g5_cell(name: &'static str, which: usize, k: f64) -> Cell {
    Cell { g5: Some(which), ..Cell::power(name, base(), k) }
}

/// The study's cells, in the order their seeds are drawn from.
pub(super) fn cells() -> Vec<Cell> {
    let mut cells = forty_seconds();
    cells.extend(longer());
    // Last, so that every cell above keeps its seeds: a linear loop, whose rate is the same
    // at every state, at 5× the margin as in VALIDITY.md's power table (there `0.5` against a
    // margin of 0.1; here `0.25` against 0.05), explored as the loops above: what the
    // region-valid certificate costs where the linear one's assumption holds.
    cells.push(Cell::power(
        "linear, rate 0.25 (5× the margin at every state), f = 0.5 x, K = −0.75, 40 s",
        ScalarScenario {
            drift: ScalarDrift::Polynomial(vec![0.0, 0.5]),
            k_explore: -1.0,
            ..base()
        },
        -0.75,
    ));
    // A drift the default library holds exactly, `0.5 x + 0.15 x²`, whose local rate
    // `−(0.5 + 0.3 x + K)` is smallest at the region's upper end: the pointwise bound's case,
    // where the point of the smallest rate is an end of the region the data chose. Under
    // `K = −0.85` the rate crosses the margin at x = 1, where the regions' upper quantile
    // falls in about a third of the runs; under `K = −0.9` at x = 1.17, above most of them.
    for (name, k) in [
        (
            "quadratic drift 0.5 x + 0.15 x², σ = 0.02, K = −0.85: rate 0.35 − 0.3 x, below the margin for x > 1, K_e = −1.5",
            -0.85,
        ),
        (
            "quadratic drift 0.5 x + 0.15 x², σ = 0.02, K = −0.9: rate 0.4 − 0.3 x, below the margin for x > 1.17, K_e = −1.5",
            -0.9,
        ),
    ] {
        cells.push(Cell::validity(
            name,
            ScalarScenario { drift: ScalarDrift::Polynomial(vec![0.0, 0.5, 0.15]), ..cubic(0.02) },
            k,
        ));
    }
    // G5's subsystem B on its 40 s with windows that end at the run's length (62 to 1984
    // columns): the longest looks once, at 39.8 s, on every column of the run, so its "one
    // look at the end, whole δ" is what any bound on this estimator can open in 40 s.
    let setting = Experiment::Two.setting();
    cells.push(Cell {
        window: 62,
        windows: Some(6),
        ..g5_cell(
            "G5 subsystem B, Experiment 2 data, 40 s, windows 62 to 1984 columns (the longest looks once, at the end, on every column)",
            1,
            setting.k4,
        )
    });
    cells
}

/// The 40 s cells, and the near-margin cell at the smallest window.
fn forty_seconds() -> Vec<Cell> {
    let poly = |c: Vec<f64>| ScalarDrift::Polynomial(c);
    let setting = Experiment::Two.setting();
    vec![
        Cell::validity(
            "−x tanh x, K = −1.1 (a band that does not contract; rate < 0 near x = −1.2)",
            base(),
            -1.1,
        ),
        Cell::validity(
            "cubic, rate 0.03 + 1.8 x² (just below the margin at x = 0), K_e = −1.5",
            cubic(0.1),
            -0.53,
        ),
        Cell::validity(
            "band, rate −0.1 + 1.5 (x − 0.8)² (non-contracting near x = 0.8), K = −1",
            ScalarScenario { drift: poly(vec![0.0, 0.14, 1.2, -0.5]), k_explore: -1.0, ..base() },
            -1.0,
        ),
        Cell::power(
            "cubic, rate 2 + 0.9 x² (40× the margin), dither ±3",
            ScalarScenario {
                drift: poly(vec![0.0, -1.0, 0.0, -0.3]),
                k_explore: -1.0,
                dither: 3.0,
                ..base()
            },
            -1.0,
        ),
        Cell::power(
            "cubic, rate 0.15 + 1.8 x² (3× the margin at x = 0), K_e = −1.5",
            cubic(0.1),
            -0.65,
        ),
        Cell::power("same, process noise σ = 0.02", cubic(0.02), -0.65),
        Cell::power("same, rate 0.5 + 1.8 x² (10× the margin)", cubic(0.1), -1.0),
        Cell::power(
            "−x tanh x, K = −2, process noise σ = 0.02",
            ScalarScenario { k_explore: -2.0, noise: Process::Gaussian { sigma: 0.02 }, ..base() },
            -2.0,
        ),
        Cell::power(
            "−x tanh x, K = −2 (rate ≥ 0.8, 16× the margin)",
            ScalarScenario { k_explore: -2.0, ..base() },
            -2.0,
        ),
        g5_cell(
            "G5 subsystem A, Experiment 2 data (rate tanh x1 + x1 sech² x1 + 2.5), 40 s",
            0,
            setting.k1,
        ),
        g5_cell("G5 subsystem B, Experiment 2 data (linear: rate 1 − k4 = 4), 40 s", 1, setting.k4),
        // Last, so that the seeds of the cells above (drawn from the cell's index) stay as they
        // were.
        Cell {
            window: 45,
            ..Cell::validity(
                "the cubic 0.03 + 1.8 x² (just below the margin) at the smallest window the cubic library with its lack-of-fit check accepts (M = 45, with the intercept)",
                cubic(0.1),
                -0.53,
            )
        },
    ]
}

/// Power with more data: the same loops run longer, with windows that double up to about the
/// run's length (after the cells above, so that their seeds stay as they were).
fn longer() -> Vec<Cell> {
    let setting = Experiment::Two.setting();
    vec![
        Cell::power(
            "cubic, rate 0.15 + 1.8 x² (3× the margin), σ = 0.1, 2000 s, windows up to 102 400 columns",
            cubic(0.1),
            -0.65,
        )
        .long(200_000, 12),
        Cell::power(
            "cubic, rate 0.15 + 1.8 x² (3× the margin), σ = 0.02, 200 s, windows up to 25 600 columns",
            cubic(0.02),
            -0.65,
        )
        .long(20_000, 10),
        Cell::power(
            "cubic, rate 0.5 + 1.8 x² (10× the margin), σ = 0.1, 400 s, windows up to 51 200 columns",
            cubic(0.1),
            -1.0,
        )
        .long(40_000, 11),
        Cell::validity(
            "cubic, rate 0.03 + 1.8 x² (just below the margin), 400 s, windows up to 51 200 columns",
            cubic(0.1),
            -0.53,
        )
        .long(40_000, 11),
        Cell::power(
            "−x tanh x, K = −2 (16× the margin), σ = 0.1, 400 s, windows up to 51 200 columns",
            ScalarScenario { k_explore: -2.0, ..base() },
            -2.0,
        )
        .long(40_000, 11),
        // G5's subsystems on five times Experiment 2's length (the 40 s cells above are
        // short of data: see the oracle column).
        g5_cell(
            "G5 subsystem A, Experiment 2 data, 200 s, windows up to 6400 columns",
            0,
            setting.k1,
        )
        .long(10_000, 8),
        g5_cell("G5 subsystem B, Experiment 2 data, 200 s, windows up to 6400 columns", 1, setting.k4)
            .long(10_000, 8),
    ]
}
