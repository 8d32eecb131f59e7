//! The G5 data sets of the paper's two experiments (Section V-A), as used by the reproduction
//! (`cargo xtask reproduce`) and by `streamcert simulate g5`.

use serde::{Deserialize, Serialize};

use streamcert_dynamics::{
    Coupling, Disturbance, DisturbanceConfig, Dither, DitherConfig, DynamicsError, G5, G5Config,
    Integrator, NoiseScaling, Periodic, Process, Segment, SimConfig, Trajectory, simulate,
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

/// Experiment 1's three-regime schedule on `η` (into `x4`) with the paper's periodic layer
/// (Section II-D, Section V-A): Gaussian `σ0 = 0.08` on `[0, 10)`, Laplace scale 0.5 on
/// `[10, 20)`, Laplace scale 0.3 plus spikes of 4.5 to 7.5 `σ0` at 5.5 % per step on
/// `[20, 30)`, all on top of `0.10 sin(2πt/10) + 0.05 sin(2πt/5 + 0.7)`.
#[must_use]
pub fn regime_schedule() -> DisturbanceConfig {
    let sigma0 = 0.08;
    DisturbanceConfig {
        segments: vec![
            Segment { start: 0.0, end: 10.0, process: Process::Gaussian { sigma: sigma0 } },
            Segment { start: 10.0, end: 20.0, process: Process::Laplace { scale: 0.5 } },
            Segment {
                start: 20.0,
                end: 30.0,
                process: Process::LaplaceSpikes {
                    scale: 0.3,
                    spike_prob: 0.055,
                    spike_min: 4.5,
                    spike_max: 7.5,
                    sigma0,
                },
            },
        ],
        periodic: Periodic::paper(),
        impulses: Vec::new(),
    }
}

/// The constants of one experiment (Table I and Section V), the one place they are written.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Setting {
    /// Coupling gain `γ` of the data run.
    pub gamma: f64,
    /// Candidate gain of subsystem A (`u1 = k1 x1`).
    pub k1: f64,
    /// Candidate gain of subsystem B (`u4 = k4 x4`).
    pub k4: f64,
    /// Steps of the data run at the paper's `dt = 0.02` s.
    pub steps: usize,
    /// Deployment margin `β_margin`.
    pub margin: f64,
    /// Standard deviation `σ` of Experiment 2's stationary Gaussian noise; `None` for
    /// Experiment 1, whose noise is the three-regime schedule
    /// ([`regime_schedule`]).
    pub sigma: Option<f64>,
    /// Impulse amplitude of the post-deployment response (Figs. 5 and 8).
    pub impulse: f64,
}

impl Experiment {
    /// The experiment's constants.
    #[must_use]
    pub const fn setting(self) -> Setting {
        match self {
            Self::One => Setting {
                gamma: 0.15,
                k1: -3.5,
                k4: -4.0,
                steps: 1500,
                margin: 0.05,
                sigma: None,
                impulse: 2.5,
            },
            Self::Two => Setting {
                gamma: 0.0,
                k1: -2.5,
                k4: -3.0,
                steps: 800,
                margin: 0.10,
                sigma: Some(0.10),
                impulse: 2.5,
            },
        }
    }
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
    /// Coupling gain `γ` instead of the experiment's (Experiment 1: 0.15, Experiment 2: 0),
    /// for example to estimate the couplings of a bidirectional network.
    #[serde(default)]
    pub gamma: Option<f64>,
}

impl G5Dataset {
    /// The reproduction's defaults for `experiment`: cascade coupling, `dt = 0.02`, PRBS ±1
    /// held 0.1 s, SDE noise scaling, Experiment-2 noise on both subsystems.
    #[must_use]
    pub fn defaults(experiment: Experiment) -> Self {
        Self {
            experiment,
            coupling: Coupling::Cascade,
            dt: 0.02,
            dither: 1.0,
            dither_hold: 0.1,
            noise_scaling: NoiseScaling::Sde,
            noise_on_a: true,
            steps: None,
            gamma: None,
        }
    }

    /// The system.
    ///
    /// # Errors
    /// None for the built-in parameters; kept fallible for the validated constructor.
    pub fn system(&self) -> Result<G5, DynamicsError> {
        let Setting { gamma, k1, k4, .. } = self.experiment.setting();
        let gamma = self.gamma.unwrap_or(gamma);
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
        let Setting { k1, k4, steps: default_steps, sigma, .. } = self.experiment.setting();
        let steps = self.steps.unwrap_or(default_steps);
        let cfg = SimConfig {
            dt: self.dt,
            steps,
            t0: 0.0,
            x0: vec![0.0; 5],
            integrator: Integrator::EulerMaruyama,
            noise_scaling: self.noise_scaling,
        };
        let (into_a, into_b) = match sigma {
            None => (DisturbanceConfig::none(), regime_schedule()),
            Some(sigma) => {
                let gauss = DisturbanceConfig::stationary(Process::Gaussian { sigma });
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
