//! The study's cells: the linear loops, their candidate gains and truths, and the
//! certifier settings each runs.

use streamcert_certificate::{Calibration, CertifierConfig};
use streamcert_dynamics::{LinearScenario, Process};
use streamcert_regression::{InputIntegral, RegressionConfig};

use super::{DELTA, H, MARGIN};

/// One cell: a data-generating scenario, a candidate gain and a certifier setting.
#[derive(Clone)]
pub(super) struct Cell {
    pub(super) family: String,
    pub(super) scenario: LinearScenario,
    pub(super) gain: Vec<f64>,
    pub(super) window: usize,
    pub(super) consecutive: usize,
    /// Blocks per batch of the calibrated certificate's variance (`batch_blocks`).
    pub(super) batch: usize,
}

impl Cell {
    pub(super) fn truth(&self) -> f64 {
        true_rate(&self.scenario.a, &self.scenario.b, &self.gain, self.scenario.n)
    }
    pub(super) fn config(&self, c: Option<f64>) -> CertifierConfig {
        let n = self.scenario.n;
        let reg = RegressionConfig {
            input_integral: InputIntegral::ZeroOrderHold,
            ..RegressionConfig::new(n, n, self.window, H, 1e-4)
        };
        let mut cfg = CertifierConfig::new(
            reg,
            self.gain.clone(),
            c.unwrap_or(1.0),
            MARGIN,
            self.consecutive,
        );
        if c.is_none() {
            cfg.calibration =
                Some(Calibration { batch_blocks: self.batch, ..Calibration::new(DELTA) });
        }
        cfg
    }
}

/// `−λ_max(sym(A + B K))` (Jacobi sweeps on the small symmetric matrix).
fn true_rate(a: &[f64], b: &[f64], k: &[f64], n: usize) -> f64 {
    let mut s = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            let mut v = a[i * n + j];
            for l in 0..n {
                v += b[i * n + l] * k[l * n + j];
            }
            s[i * n + j] += 0.5 * v;
            s[j * n + i] += 0.5 * v;
        }
    }
    let mut work = vec![0.0; streamcert_regression::linalg::eig_work_len(n)];
    -streamcert_regression::linalg::sym_eig_extremes(&s, n, &mut work).1
}

fn eye(n: usize, c: f64) -> Vec<f64> {
    (0..n * n).map(|i| if i / n == i % n { c } else { 0.0 }).collect()
}

pub(super) fn scenario(n: usize, a: Vec<f64>, k_explore: f64, noise: Process) -> LinearScenario {
    LinearScenario {
        n,
        m: n,
        a,
        b: eye(n, 1.0),
        noise,
        k_explore: eye(n, k_explore),
        dither: 1.0,
        dither_hold: 0.2,
        dt: 0.01,
        steps: 4000,
        noise_gain: None,
        sensor_noise: 0.0,
        switch: None,
    }
}

/// `K = −c I` with `c` chosen so that the true rate is `rate`.
fn diagonal_candidate(s: &LinearScenario, rate: f64) -> Vec<f64> {
    let base = true_rate(&s.a, &s.b, &vec![0.0; s.n * s.n], s.n);
    eye(s.n, -(rate - base))
}

fn noises(sigma: f64) -> [(&'static str, Process); 3] {
    [
        ("Gaussian", Process::Gaussian { sigma }),
        ("Laplace", Process::Laplace { scale: sigma / 2f64.sqrt() }),
        ("Student-t(3)", Process::StudentT { dof: 3.0, scale: sigma / 3f64.sqrt() }),
    ]
}

/// The near-margin cells: every opening is a false deployment.
pub(super) fn near_margin_cells() -> Vec<Cell> {
    let mut cells = Vec::new();
    let scalar = |noise| scenario(1, vec![0.5], -1.0, noise);
    let cell = |family: String, scenario: LinearScenario, gain: Vec<f64>, window| Cell {
        family,
        scenario,
        gain,
        window,
        consecutive: 1,
        batch: 1,
    };
    // Window sweep, M/h = 2 … 30, the short-window case (β* = 0.04).
    for window in [10, 15, 20, 30, 50, 75, 150] {
        let s = scalar(Process::Gaussian { sigma: 0.1 });
        cells.push(cell("scalar, Gaussian".into(), s, vec![-0.54], window));
    }
    cells.push(cell(
        "scalar, Gaussian, β* = 0".into(),
        scalar(Process::Gaussian { sigma: 0.1 }),
        vec![-0.5],
        150,
    ));
    for (name, noise) in noises(0.1).into_iter().skip(1) {
        for window in [20, 150] {
            cells.push(cell(format!("scalar, {name}"), scalar(noise), vec![-0.54], window));
        }
    }
    // Sensor noise on y (errors in variables).
    let sensor = LinearScenario {
        sensor_noise: 0.05,
        ..scenario(1, vec![0.5], -1.5, Process::Gaussian { sigma: 0.1 })
    };
    cells.push(cell("scalar, sensor noise σ_v = 0.05".into(), sensor, vec![-0.54], 150));
    // Candidate far from the exploring gain (K_e = −3, K = 0.46), heavy process noise.
    let far = scenario(1, vec![-0.5], -3.0, Process::Gaussian { sigma: 0.5 });
    cells.push(cell("scalar, far from K_e, σ = 0.5".into(), far, vec![0.46], 150));
    // p = 2 with common-mode noise, and with unequal noise across outputs.
    let a2 = vec![0.5, 0.3, -0.2, 0.2];
    let common = LinearScenario {
        noise_gain: Some(vec![0.6, 0.0, 0.8, 0.0, 0.6, 0.8]),
        ..scenario(2, a2.clone(), -1.0, Process::Gaussian { sigma: 0.1 })
    };
    let k = diagonal_candidate(&common, 0.04);
    cells.push(cell("p = 2, common-mode noise".into(), common, k, 150));
    let unequal = LinearScenario {
        noise_gain: Some(vec![1.0, 0.0, 0.0, 0.2]),
        ..scenario(2, a2, -1.0, Process::Gaussian { sigma: 0.1 })
    };
    let k = diagonal_candidate(&unequal, 0.04);
    cells.push(cell("p = 2, unequal noise".into(), unequal, k, 150));
    // p = 3.
    let a3 = vec![0.5, 0.3, 0.0, -0.2, 0.2, 0.1, 0.0, 0.1, -0.1];
    let three = scenario(3, a3, -1.0, Process::Gaussian { sigma: 0.1 });
    let k = diagonal_candidate(&three, 0.04);
    cells.push(cell("p = 3".into(), three, k, 150));
    // Batches of 4 and 8 blocks (`batch_blocks`): the sensor-noise cell, and the smallest
    // window each setting accepts (h (b (p + m + 1) + 1): 65 and 125) and one below it.
    let sensor = LinearScenario {
        sensor_noise: 0.05,
        ..scenario(1, vec![0.5], -1.5, Process::Gaussian { sigma: 0.1 })
    };
    let batched = |family: &str, scenario, window, batch| Cell {
        batch,
        ..cell(format!("{family}, batches of {batch} blocks"), scenario, vec![-0.54], window)
    };
    for (batch, smallest) in [(4, 65), (8, 125)] {
        cells.push(batched("scalar, sensor noise σ_v = 0.05", sensor.clone(), 150, batch));
        for window in [smallest - H, smallest] {
            let s = scalar(Process::Gaussian { sigma: 0.1 });
            cells.push(batched("scalar, Gaussian", s, window, batch));
        }
    }
    cells
}

/// Contracting candidates at 2×, 5× and 20× the margin, plus the two power targets.
pub(super) fn power_cells() -> Vec<Cell> {
    let mut cells = Vec::new();
    for multiple in [2.0, 5.0, 20.0] {
        let s = scenario(1, vec![0.5], -1.0, Process::Gaussian { sigma: 0.1 });
        let gain = diagonal_candidate(&s, multiple * MARGIN);
        cells.push(Cell {
            family: format!("scalar, β* = {multiple}× margin"),
            scenario: s,
            gain,
            window: 150,
            consecutive: 10,
            batch: 1,
        });
    }
    let p2 = scenario(2, vec![0.5, 0.3, -0.2, 0.2], -1.0, Process::Gaussian { sigma: 0.1 });
    cells.push(Cell {
        family: "p = 2, K = −2I (β* = 1.49)".into(),
        gain: eye(2, -2.0),
        scenario: p2,
        window: 150,
        consecutive: 10,
        batch: 1,
    });
    let sensor = LinearScenario {
        sensor_noise: 0.05,
        ..scenario(1, vec![-1.0], -2.0, Process::Gaussian { sigma: 0.02 })
    };
    let sensor_cell = Cell {
        family: "scalar, sensor noise σ_v = 0.05, β* = 3".into(),
        scenario: sensor,
        gain: vec![-2.0],
        window: 150,
        consecutive: 10,
        batch: 1,
    };
    cells.push(sensor_cell.clone());
    for batch in [4, 8] {
        cells.push(Cell {
            family: format!("{}, batches of {batch} blocks", sensor_cell.family),
            batch,
            ..sensor_cell.clone()
        });
    }
    cells
}
