//! The study's cells: the linear loops, their candidate gains and truths, and the
//! certifier settings each runs.

use streamcert_certificate::{Calibration, CertifierConfig, HorizonLadder, RiskSplit};
use streamcert_dynamics::{LinearScenario, Process};
use streamcert_regression::{InputIntegral, Model, RegressionConfig};

use super::{DELTA, H, MARGIN};

/// `--horizon auto`: the default cells run the horizon ladder (set once, before any cell).
static HORIZON_AUTO: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Run the default cells with the horizon ladder (`true`) or at `h = 5` (`false`).
pub(crate) fn set_horizon_auto(auto: bool) {
    HORIZON_AUTO.store(auto, std::sync::atomic::Ordering::Relaxed);
}

/// Whether the default cells run the horizon ladder.
pub(super) fn horizon_auto() -> bool {
    HORIZON_AUTO.load(std::sync::atomic::Ordering::Relaxed)
}

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
    /// Constant offsets `(y₀, u₀)` added to every output and input (an operating point).
    pub(super) offset: (f64, f64),
    /// Positive factors `(s_y, s_u)` multiplying every logged output and input (the units of
    /// the log); the candidate gain is scaled by `s_u / s_y` so that the loop is the same.
    pub(super) scale: (f64, f64),
    /// Outputs the sensor sees: the first `observed` states (fewer than `n` hides states).
    pub(super) observed: usize,
    /// The true rate where it is not `−λ_max(sym(A + B K))` of the observed loop: a hidden
    /// state's plant, `−max Re λ(A + B K)` (the rate in its best metric).
    pub(super) truth: Option<f64>,
    /// The regression's model (the default: affine, an intercept in every regression).
    pub(super) model: Model,
    /// The calibrated certificate as it was before the defaults of the safe-by-default and
    /// plant-data work: the model through the origin, no guards, no automatic batches, at
    /// least four windows with the risk split by length (the power table's "before" columns,
    /// on the same runs).
    pub(super) before: bool,
    /// The earlier default windows (at least four, the risk split
    /// by length), every other default kept: what the fifth window and the equal split
    /// change.
    pub(super) filed_windows: bool,
}

/// A cell with the defaults for the fields most cells leave alone.
pub(super) fn plain(
    family: String,
    scenario: LinearScenario,
    gain: Vec<f64>,
    window: usize,
    consecutive: usize,
) -> Cell {
    let observed = scenario.n;
    Cell {
        family,
        scenario,
        gain,
        window,
        consecutive,
        batch: 1,
        offset: (0.0, 0.0),
        scale: (1.0, 1.0),
        observed,
        truth: None,
        model: Model::Affine,
        before: false,
        filed_windows: false,
    }
}

impl Cell {
    pub(super) fn truth(&self) -> f64 {
        self.truth.unwrap_or_else(|| {
            true_rate(&self.scenario.a, &self.scenario.b, &self.gain, self.scenario.n)
        })
    }
    pub(super) fn config(&self, c: Option<f64>) -> CertifierConfig {
        let (p, m) = (self.observed, self.scenario.m);
        let reg = RegressionConfig {
            input_integral: InputIntegral::ZeroOrderHold,
            model: if self.before { Model::ThroughOrigin } else { self.model },
            ..RegressionConfig::new(p, m, self.window, H, 1e-4)
        };
        let (sy, su) = self.scale;
        let mut cfg = CertifierConfig::new(
            reg,
            self.gain.iter().map(|k| k * su / sy).collect(),
            c.unwrap_or(1.0),
            MARGIN,
            self.consecutive,
        );
        if c.is_none() {
            let cal = Calibration { batch_blocks: self.batch, ..Calibration::new(DELTA) };
            // The earlier default windows: at least four, the risk split by length.
            let mut windows = 4;
            while windows < 16 && self.window << (windows - 1) < 200 * H {
                windows += 1;
            }
            let filed =
                Calibration { windows: Some(windows), risk_split: RiskSplit::ByLength, ..cal };
            cfg.calibration = Some(if self.before {
                Calibration { auto_batches: 0, anchored_share: 0.0, ..filed.unguarded() }
            } else if self.filed_windows {
                filed
            } else {
                // `--horizon auto`: the horizon ladder (`horizon = "auto"`), the base
                // window `window / h` blocks of h columns at every horizon.
                cfg.ladder = (horizon_auto() && self.window.is_multiple_of(H)).then(|| {
                    HorizonLadder { blocks: Some(self.window / H), ..HorizonLadder::automatic() }
                });
                cal
            });
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
    let cell = |family: String, scenario: LinearScenario, gain: Vec<f64>, window| {
        plain(family, scenario, gain, window, 1)
    };
    // Window sweep, M/h = 2 … 30, the short-window case (β* = 0.04); 25 is the
    // smallest window with the intercept (h (p + m + 3)).
    for window in [10, 15, 20, 25, 30, 50, 75, 150] {
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
    // An operating point (as real plant data are): `ẏ = −0.02 (y − y₀) + (u − 10) + w`,
    // explored by `u = 10 + PRBS`, candidate K = 0 (β* = 0.02, below the margin).
    for y0 in [50.0, 1e6] {
        let s = scenario(1, vec![-0.02], 0.0, Process::Gaussian { sigma: 0.1 });
        cells.push(Cell {
            offset: (y0, 10.0),
            ..cell(format!("operating point y₀ = {y0:e}, u₀ = 10"), s, vec![0.0], 150)
        });
    }
    cells.extend(hidden_and_batched_cells());
    cells
}

/// The near-margin cells of hidden dynamics and of batches of blocks (after the others, in
/// the order their seeds are drawn).
fn hidden_and_batched_cells() -> Vec<Cell> {
    let mut cells = Vec::new();
    let scalar = |noise| scenario(1, vec![0.5], -1.0, noise);
    let cell = |family: String, scenario: LinearScenario, gain: Vec<f64>, window| {
        plain(family, scenario, gain, window, 1)
    };
    // Hidden dynamics: a two-state plant measured by its first state, `u = PRBS(±1, held
    // 0.5 s)`, noise into the second state, K = 0: a damped mass (`ẍ = −2 ẋ + u + w`, the
    // position does not contract: β* = 0) and a lightly damped oscillator
    // (`ẍ = −x − 0.05 ẋ + u + w`, its state decays at 0.025).
    for (name, a, truth) in [
        ("hidden state: damped mass by position", vec![0.0, 1.0, 0.0, -2.0], 0.0),
        ("hidden state: oscillator by position", vec![0.0, 1.0, -1.0, -0.05], 0.025),
    ] {
        let s = LinearScenario {
            n: 2,
            m: 1,
            a,
            b: vec![0.0, 1.0],
            k_explore: vec![0.0, 0.0],
            noise_gain: Some(vec![0.0, 1.0]),
            dither_hold: 0.5,
            ..scenario(1, vec![0.0], 0.0, Process::Gaussian { sigma: 0.1 })
        };
        cells.push(Cell {
            observed: 1,
            truth: Some(truth),
            ..cell(name.into(), s, vec![0.0], 150)
        });
    }
    // Batches of 4 and 8 blocks (`batch_blocks`): the sensor-noise cell, and the smallest
    // window each setting accepts (h (b (u + 1) + 1), u = p + m + 1 unknowns with the
    // intercept: 85 and 165) and one below it.
    let sensor = LinearScenario {
        sensor_noise: 0.05,
        ..scenario(1, vec![0.5], -1.5, Process::Gaussian { sigma: 0.1 })
    };
    let batched = |family: &str, scenario, window, batch| Cell {
        batch,
        ..cell(format!("{family}, batches of {batch} blocks"), scenario, vec![-0.54], window)
    };
    for (batch, smallest) in [(4, 85), (8, 165)] {
        // M = 150, or the smallest window the setting accepts when that is longer.
        let window = smallest.max(150);
        cells.push(batched("scalar, sensor noise σ_v = 0.05", sensor.clone(), window, batch));
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
        cells.push(plain(
            format!("scalar, β* = {multiple}× margin"),
            s.clone(),
            gain.clone(),
            150,
            10,
        ));
        if multiple == 5.0 {
            // What the intercept costs on a loop that does run about zero: the same runs
            // through the origin (the paper's model, an explicit choice).
            let name = format!("scalar, β* = {multiple}× margin, model through the origin");
            cells.push(Cell { model: Model::ThroughOrigin, ..plain(name, s, gain, 150, 10) });
        }
    }
    let p2 = scenario(2, vec![0.5, 0.3, -0.2, 0.2], -1.0, Process::Gaussian { sigma: 0.1 });
    cells.push(plain("p = 2, K = −2I (β* = 1.49)".into(), p2, eye(2, -2.0), 150, 10));
    let sensor = LinearScenario {
        sensor_noise: 0.05,
        ..scenario(1, vec![-1.0], -2.0, Process::Gaussian { sigma: 0.02 })
    };
    let sensor_cell =
        plain("scalar, sensor noise σ_v = 0.05, β* = 3".into(), sensor, vec![-2.0], 150, 10);
    cells.push(sensor_cell.clone());
    cells.push(Cell {
        family: format!("{}, model through the origin", sensor_cell.family),
        model: Model::ThroughOrigin,
        ..sensor_cell.clone()
    });
    // M = 150, or the smallest window the setting accepts with the intercept (165 at b = 8).
    for (batch, window) in [(4, 150), (8, 165)] {
        cells.push(Cell {
            family: format!("{}, batches of {batch} blocks, M = {window}", sensor_cell.family),
            batch,
            window,
            ..sensor_cell.clone()
        });
    }
    // What the default windows (five, an equal share of δ each) change: cells above on the
    // four windows split by length of the filing, every other default kept. Last, so that
    // the cells above keep their seeds (a cell's seeds follow its index).
    let filed = |cell: &Cell| Cell {
        family: format!("{}, four windows split by length", cell.family),
        filed_windows: true,
        ..cell.clone()
    };
    let compared = ["scalar, β* = 5× margin", "scalar, β* = 20× margin", &sensor_cell.family];
    let more: Vec<Cell> =
        cells.iter().filter(|c| compared.contains(&c.family.as_str())).map(filed).collect();
    cells.extend(more);
    cells
}

/// The hold times of the held-input family, in seconds: a PRBS of ±1 that switches at most
/// every `hold` seconds (a step test at the longer holds).
pub(super) const HOLDS: [f64; 4] = [0.2, 2.0, 10.0, 30.0];

/// `ẏ = −y + u + w` explored in open loop (`K_e = 0`) by a PRBS of ±1 held `hold` seconds,
/// process noise `σ`, 60 s at `dt = 0.02`: the loop of the identification-and-units study.
pub(super) fn held_scenario(hold: f64, sigma: f64) -> LinearScenario {
    LinearScenario {
        dither_hold: hold,
        dt: 0.02,
        steps: 3000,
        ..scenario(1, vec![-1.0], 0.0, Process::Gaussian { sigma })
    }
}

/// The candidate of true rate `rate` on [`held_scenario`]: `β* = 1 − K`.
fn held_gain(rate: f64) -> Vec<f64> {
    vec![1.0 - rate]
}

/// The held-input family's unsafe cells (`n_s = 1`, every opening false): each hold, process
/// noise 0.1 and 1.5, candidates far from the exploring gain with true rates −0.5 and 0.04.
pub(super) fn held_cells() -> Vec<Cell> {
    let mut cells = Vec::new();
    for hold in HOLDS {
        for sigma in [0.1, 1.5] {
            for rate in [-0.5, 0.04] {
                cells.push(plain(
                    format!("held {hold} s, σ = {sigma}"),
                    held_scenario(hold, sigma),
                    held_gain(rate),
                    150,
                    1,
                ));
            }
        }
    }
    cells
}

/// The held-input family's contracting candidates (5× and 20× the margin, `n_s = 10`).
pub(super) fn held_power_cells() -> Vec<Cell> {
    let mut cells = Vec::new();
    for hold in HOLDS {
        for sigma in [0.1, 1.5] {
            for multiple in [5.0, 20.0] {
                cells.push(plain(
                    format!("held {hold} s, σ = {sigma}, β* = {multiple}× margin"),
                    held_scenario(hold, sigma),
                    held_gain(multiple * MARGIN),
                    150,
                    10,
                ));
            }
        }
    }
    cells
}

/// The scales of the units family: each of `y` and `u` multiplied by these, the other kept.
pub(super) const SCALES: [f64; 5] = [1e-3, 1e-2, 1.0, 1e2, 1e3];

/// `cell` logged in other units: `y` times each scale, then `u` times each (the unit scale
/// once).
pub(super) fn scaled(cell: &Cell) -> Vec<Cell> {
    let mut out = Vec::new();
    for (sy, su) in SCALES
        .iter()
        .map(|&s| (s, 1.0))
        .chain(SCALES.iter().filter(|&&s| s != 1.0).map(|&s| (1.0, s)))
    {
        out.push(Cell {
            family: format!("{}, y ×{sy:e}, u ×{su:e}", cell.family),
            scale: (sy, su),
            ..cell.clone()
        });
    }
    out
}

/// The units family's two bases: the 5× power cell and the held-input unsafe cell (10 s,
/// σ = 1.5, β* = −0.5).
pub(super) fn units_bases() -> (Cell, Cell) {
    let s = scenario(1, vec![0.5], -1.0, Process::Gaussian { sigma: 0.1 });
    let gain = diagonal_candidate(&s, 5.0 * MARGIN);
    let power = plain("scalar, β* = 5× margin".into(), s, gain, 150, 10);
    let unsafe_cell =
        plain("held 10 s, σ = 1.5".into(), held_scenario(10.0, 1.5), held_gain(-0.5), 150, 1);
    (power, unsafe_cell)
}
