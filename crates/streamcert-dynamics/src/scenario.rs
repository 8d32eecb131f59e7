//! Known-answer data sets: a linear system under exploratory output feedback.

use serde::{Deserialize, Serialize};

use crate::{
    Disturbance, DisturbanceConfig, Dither, DitherConfig, DynamicsError, Integrator, LinearSystem,
    NoiseScaling, Process, SimConfig, Trajectory, simulate,
};

/// `dx = (A x + B u) dt + dη` (independent noise on every state, SDE scaling), fully
/// measured (`y = x`), under the exploration policy `u = K_explore y + d(t)` where `d` is an
/// independent PRBS per input, held over each step. The ground truth of every estimator test:
/// the closed-loop Jacobian under a candidate `K` is `A + B K` exactly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinearScenario {
    /// State dimension `n` (= outputs).
    pub n: usize,
    /// Input dimension `m`.
    pub m: usize,
    /// `A`, `n × n` row-major.
    pub a: Vec<f64>,
    /// `B`, `n × m` row-major.
    pub b: Vec<f64>,
    /// Noise process on every state (scaled by `√dt`, [`NoiseScaling::Sde`]).
    pub noise: Process,
    /// Exploration gain `K_explore`, `m × n` row-major.
    pub k_explore: Vec<f64>,
    /// PRBS amplitude.
    pub dither: f64,
    /// PRBS hold time in seconds.
    pub dither_hold: f64,
    /// Step.
    pub dt: f64,
    /// Number of steps.
    pub steps: usize,
}

impl LinearScenario {
    /// Simulate with Euler–Maruyama from `x = 0`. Every draw derives from `seed`.
    ///
    /// # Errors
    /// Any configuration error of the system, the noise, the dither or the simulation, and
    /// [`DynamicsError::DimensionMismatch`] for a wrong `K_explore` length.
    pub fn run(&self, seed: u64) -> Result<Trajectory, DynamicsError> {
        let (n, m) = (self.n, self.m);
        if self.k_explore.len() != m * n {
            return Err(DynamicsError::DimensionMismatch {
                name: "k_explore",
                expected: m * n,
                got: self.k_explore.len(),
            });
        }
        let eye: Vec<f64> = (0..n * n).map(|k| if k / n == k % n { 1.0 } else { 0.0 }).collect();
        let sys = LinearSystem::new(n, m, n, n, self.a.clone(), self.b.clone(), eye.clone(), eye)?;
        let cfg = SimConfig {
            dt: self.dt,
            steps: self.steps,
            t0: 0.0,
            x0: vec![0.0; n],
            integrator: Integrator::EulerMaruyama,
            noise_scaling: NoiseScaling::Sde,
        };
        let noise = DisturbanceConfig::stationary(self.noise);
        let mut dist = (0..n)
            .map(|j| {
                Disturbance::new(noise.clone(), seed.wrapping_mul(1000).wrapping_add(j as u64))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let prbs = DitherConfig::Prbs { amplitude: self.dither, hold: self.dither_hold };
        let mut dithers = (0..m)
            .map(|j| Dither::new(prbs, seed.wrapping_mul(1000).wrapping_add(500 + j as u64)))
            .collect::<Result<Vec<_>, _>>()?;
        let k = &self.k_explore;
        simulate(&sys, &cfg, &mut dist, |t, y, u| {
            for i in 0..m {
                u[i] = (0..n).map(|j| k[i * n + j] * y[j]).sum::<f64>() + dithers[i].value(t);
            }
        })
    }
}
