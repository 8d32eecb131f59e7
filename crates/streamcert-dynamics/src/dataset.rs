//! The G5 data sets of the paper's two experiments (Section V-A), as used by the reproduction
//! (`cargo xtask reproduce`) and by `streamcert simulate g5`.

use serde::{Deserialize, Serialize};

use crate::{
    Coupling, Disturbance, DisturbanceConfig, Dither, DitherConfig, DynamicsError, G5, G5Config,
    Integrator, NoiseScaling, Process, SimConfig, Trajectory, simulate,
};

/// Which experiment's data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Experiment {
    /// Experiment 1: `γ = 0.15`, `K = diag(−3.5, −4.0)`, 30 s, the three-regime schedule
    /// with the periodic layer on `η` (into `x4`), nothing into `x1`.
    One,
    /// Experiment 2: disconnected (`γ = 0`), `K = diag(−2.5, −3.0)`, 16 s, Gaussian
    /// `σ = 0.10` into `x4` (and into `x1` when `noise_on_a`).
    Two,
}

/// A G5 data run under the candidate gains plus PRBS dither on both inputs
/// (`u = K y + d(t)`): in open loop G5's node 2 (`ẋ2 = x2³ − x2 + 0.3 x1`) escapes in finite
/// time once `x1` exceeds about 1.28, so data are collected in closed loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct G5Dataset {
    /// Which experiment.
    pub experiment: Experiment,
    /// Coupling structure (irrelevant for Experiment 2, where `γ = 0`).
    pub coupling: Coupling,
    /// Step (paper: 0.02 s).
    pub dt: f64,
    /// PRBS amplitude on each input.
    pub dither: f64,
    /// PRBS hold time in seconds.
    pub dither_hold: f64,
    /// Noise scaling with `dt`.
    pub noise_scaling: NoiseScaling,
    /// Experiment 2: also put the noise into `x1`.
    pub noise_on_a: bool,
    /// Number of steps instead of the experiment's (Experiment 1: 1500, Experiment 2: 800);
    /// after 30 s Experiment 1's schedule has no random part left.
    #[serde(default)]
    pub steps: Option<usize>,
}

impl G5Dataset {
    /// The reproduction's defaults for `experiment`: cascade coupling, `dt = 0.02`, PRBS ±0.5
    /// held 0.1 s, SDE noise scaling, Experiment-2 noise on both subsystems.
    #[must_use]
    pub fn defaults(experiment: Experiment) -> Self {
        Self {
            experiment,
            coupling: Coupling::Cascade,
            dt: 0.02,
            dither: 0.5,
            dither_hold: 0.1,
            noise_scaling: NoiseScaling::Sde,
            noise_on_a: true,
            steps: None,
        }
    }

    /// `(γ, k1, k4, steps)` of the experiment (Table I).
    #[must_use]
    pub fn settings(&self) -> (f64, f64, f64, usize) {
        match self.experiment {
            Experiment::One => (0.15, -3.5, -4.0, 1500),
            Experiment::Two => (0.0, -2.5, -3.0, 800),
        }
    }

    /// The system.
    ///
    /// # Errors
    /// None for the built-in parameters; kept fallible for the validated constructor.
    pub fn system(&self) -> Result<G5, DynamicsError> {
        let (gamma, k1, k4, _) = self.settings();
        G5::new(G5Config { gamma, k1, k4, ..G5Config::paper(self.coupling) })
    }

    /// Simulate from the origin. `seeds` drive, in order: the noise into `x1`, the noise into
    /// `x4`, the dither on `u1`, the dither on `u4`.
    ///
    /// # Errors
    /// Invalid `dt`, dither or noise parameters.
    pub fn run(&self, seeds: [u64; 4]) -> Result<Trajectory, DynamicsError> {
        self.run_inner(seeds)
    }

    /// The four seeds of run `run` (0-based) of this experiment, the one rule the
    /// reproduction (`cargo xtask reproduce`, run `run`) and `streamcert simulate g5 --seed
    /// run` share: `(run + 1) · 1 000 003 + stream`, streams 1 to 4 for Experiment 1 and 11 to
    /// 14 for Experiment 2.
    #[must_use]
    pub fn seeds(&self, run: u64) -> [u64; 4] {
        let first = match self.experiment {
            Experiment::One => 1,
            Experiment::Two => 11,
        };
        let base = (run + 1).wrapping_mul(1_000_003);
        [base + first, base + first + 1, base + first + 2, base + first + 3]
    }

    /// [`run`](Self::run) with the seeds of run `run` ([`seeds`](Self::seeds)).
    ///
    /// # Errors
    /// As [`run`](Self::run).
    pub fn run_seeded(&self, run: u64) -> Result<Trajectory, DynamicsError> {
        self.run_inner(self.seeds(run))
    }

    fn run_inner(&self, seeds: [u64; 4]) -> Result<Trajectory, DynamicsError> {
        let sys = self.system()?;
        let (_, k1, k4, default_steps) = self.settings();
        let steps = self.steps.unwrap_or(default_steps);
        let cfg = SimConfig {
            dt: self.dt,
            steps,
            t0: 0.0,
            x0: vec![0.0; 5],
            integrator: Integrator::EulerMaruyama,
            noise_scaling: self.noise_scaling,
        };
        let gauss = DisturbanceConfig::stationary(Process::Gaussian { sigma: 0.10 });
        let (into_a, into_b) = match self.experiment {
            Experiment::One => (DisturbanceConfig::none(), DisturbanceConfig::experiment1()),
            Experiment::Two => {
                (if self.noise_on_a { gauss.clone() } else { DisturbanceConfig::none() }, gauss)
            }
        };
        let mut dist = [Disturbance::new(into_a, seeds[0])?, Disturbance::new(into_b, seeds[1])?];
        let prbs = DitherConfig::Prbs { amplitude: self.dither, hold: self.dither_hold };
        let (mut da, mut db) = (Dither::new(prbs, seeds[2])?, Dither::new(prbs, seeds[3])?);
        simulate(&sys, &cfg, &mut dist, |t, y, u| {
            u[0] = k1 * y[0] + da.value(t);
            u[1] = k4 * y[1] + db.value(t);
        })
    }
}
