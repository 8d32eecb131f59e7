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
    /// Experiment 2's data (`γ = 0`), run 40 s.
    pub(super) g5: Option<usize>,
    /// Base window `M` (columns); the smallest the cubic library accepts is
    /// `h (D + m + 2) = 30`.
    pub(super) window: usize,
    /// Number of calibrated windows `M, 2M, …` (`None`: the default, doubling until the
    /// longest holds 200 blocks of `h` columns). The long-run power cells raise it so that the
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
            let data = G5Dataset { steps: Some(2000), ..G5Dataset::defaults(Experiment::Two) };
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

pub(super) fn cells() -> Vec<Cell> {
    let poly = |c: Vec<f64>| ScalarDrift::Polynomial(c);
    vec![
        Cell {
            name: "−x tanh x, K = −1.1 (the issue's loop; rate < 0 near x = −1.2)",
            scenario: base(),
            k: -1.1,
            validity: true,
            g5: None,
            window: WINDOW,
            windows: None,
        },
        Cell {
            name: "cubic, rate 0.03 + 1.8 x² (just below the margin at x = 0), K_e = −1.5",
            scenario: cubic(0.1),
            k: -0.53,
            validity: true,
            g5: None,
            window: WINDOW,
            windows: None,
        },
        Cell {
            name: "band, rate −0.1 + 1.5 (x − 0.8)² (non-contracting near x = 0.8), K = −1",
            scenario: ScalarScenario {
                drift: poly(vec![0.0, 0.14, 1.2, -0.5]),
                k_explore: -1.0,
                ..base()
            },
            k: -1.0,
            validity: true,
            g5: None,
            window: WINDOW,
            windows: None,
        },
        Cell {
            name: "cubic, rate 2 + 0.9 x² (40× the margin), dither ±3",
            scenario: ScalarScenario {
                drift: poly(vec![0.0, -1.0, 0.0, -0.3]),
                k_explore: -1.0,
                dither: 3.0,
                ..base()
            },
            k: -1.0,
            validity: false,
            g5: None,
            window: WINDOW,
            windows: None,
        },
        Cell {
            name: "cubic, rate 0.15 + 1.8 x² (3× the margin at x = 0), K_e = −1.5",
            scenario: cubic(0.1),
            k: -0.65,
            validity: false,
            g5: None,
            window: WINDOW,
            windows: None,
        },
        Cell {
            name: "same, process noise σ = 0.02",
            scenario: cubic(0.02),
            k: -0.65,
            validity: false,
            g5: None,
            window: WINDOW,
            windows: None,
        },
        Cell {
            name: "same, rate 0.5 + 1.8 x² (10× the margin)",
            scenario: cubic(0.1),
            k: -1.0,
            validity: false,
            g5: None,
            window: WINDOW,
            windows: None,
        },
        Cell {
            name: "−x tanh x, K = −2, process noise σ = 0.02",
            scenario: ScalarScenario {
                k_explore: -2.0,
                noise: Process::Gaussian { sigma: 0.02 },
                ..base()
            },
            k: -2.0,
            validity: false,
            g5: None,
            window: WINDOW,
            windows: None,
        },
        Cell {
            name: "−x tanh x, K = −2 (rate ≥ 0.8, 16× the margin)",
            scenario: ScalarScenario { k_explore: -2.0, ..base() },
            k: -2.0,
            validity: false,
            g5: None,
            window: WINDOW,
            windows: None,
        },
        Cell {
            name: "G5 subsystem A, Experiment 2 data (rate tanh x1 + x1 sech² x1 + 2.5), 40 s",
            scenario: base(),
            k: Experiment::Two.setting().k1,
            validity: false,
            g5: Some(0),
            window: WINDOW,
            windows: None,
        },
        Cell {
            name: "G5 subsystem B, Experiment 2 data (linear: rate 1 − k4 = 4), 40 s",
            scenario: base(),
            k: Experiment::Two.setting().k4,
            validity: false,
            g5: Some(1),
            window: WINDOW,
            windows: None,
        },
        // Last, so that the seeds of the cells above (drawn from the cell's index) stay as they
        // were.
        Cell {
            name: "the cubic 0.03 + 1.8 x² (just below the margin) at the smallest window the cubic library accepts (M = 30)",
            scenario: cubic(0.1),
            k: -0.53,
            validity: true,
            g5: None,
            window: 30,
            windows: None,
        },
        // Power with more data: the same loops run longer, with windows that double up to
        // about the run's length (last, so the seeds above stay as they were).
        Cell {
            name: "cubic, rate 0.15 + 1.8 x² (3× the margin), σ = 0.1, 2000 s, windows up to 102 400 columns",
            scenario: ScalarScenario { steps: 200_000, ..cubic(0.1) },
            k: -0.65,
            validity: false,
            g5: None,
            window: WINDOW,
            windows: Some(12),
        },
        Cell {
            name: "cubic, rate 0.15 + 1.8 x² (3× the margin), σ = 0.02, 200 s, windows up to 25 600 columns",
            scenario: ScalarScenario { steps: 20_000, ..cubic(0.02) },
            k: -0.65,
            validity: false,
            g5: None,
            window: WINDOW,
            windows: Some(10),
        },
        Cell {
            name: "cubic, rate 0.5 + 1.8 x² (10× the margin), σ = 0.1, 400 s, windows up to 51 200 columns",
            scenario: ScalarScenario { steps: 40_000, ..cubic(0.1) },
            k: -1.0,
            validity: false,
            g5: None,
            window: WINDOW,
            windows: Some(11),
        },
        Cell {
            name: "cubic, rate 0.03 + 1.8 x² (just below the margin), 400 s, windows up to 51 200 columns",
            scenario: ScalarScenario { steps: 40_000, ..cubic(0.1) },
            k: -0.53,
            validity: true,
            g5: None,
            window: WINDOW,
            windows: Some(11),
        },
        Cell {
            name: "−x tanh x, K = −2 (16× the margin), σ = 0.1, 400 s, windows up to 51 200 columns",
            scenario: ScalarScenario { k_explore: -2.0, steps: 40_000, ..base() },
            k: -2.0,
            validity: false,
            g5: None,
            window: WINDOW,
            windows: Some(11),
        },
    ]
}
