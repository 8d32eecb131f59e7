//! Known-answer data sets: a linear system under exploratory output feedback.

use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::{
    Disturbance, DisturbanceConfig, Dither, DitherConfig, Dynamics, DynamicsError, Integrator,
    LinearSystem, NoiseScaling, Process, SimConfig, Trajectory, seeded_rng, simulate,
};

/// A change of the plant during a run: from time `at` the state matrix moves from the
/// scenario's `A` to `a`, at once (`ramp = 0`, a step) or linearly over `ramp` seconds (a slow
/// drift): `A(t) = A + s(t) (a − A)`, `s(t) = clamp((t − at) / ramp, 0, 1)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlantSwitch {
    /// Switching time (the drift's start) in seconds.
    pub at: f64,
    /// The new `A`, `n × n` row-major.
    pub a: Vec<f64>,
    /// Seconds over which `A` drifts to `a` (0: a step at `at`).
    #[serde(default)]
    pub ramp: f64,
}

impl PlantSwitch {
    /// The share `s(t) ∈ [0, 1]` of the change in force at time `t`.
    #[must_use]
    pub fn share(&self, t: f64) -> f64 {
        if t < self.at {
            0.0
        } else if self.ramp > 0.0 {
            ((t - self.at) / self.ramp).min(1.0)
        } else {
            1.0
        }
    }
}

/// `dx = (A x + B u) dt + E dη` (SDE scaling), measured as `y = x + v` with white Gaussian
/// sensor noise `v` of standard deviation `sensor_noise`, under the exploration policy
/// `u = K_explore y + d(t)` where `d` is an independent PRBS per input, held over each step.
/// The controller sees the same noisy `y` that is recorded. The ground truth of every
/// estimator test: the closed-loop Jacobian under a candidate `K` is `A + B K` exactly (before
/// and after a [`PlantSwitch`]).
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
    /// Noise process of every channel (scaled by `√dt`, [`NoiseScaling::Sde`]).
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
    /// Disturbance gain `E`, `n × q` row-major, one independent channel per column (default
    /// `None`: the identity, independent noise on every state). A column of ones is
    /// common-mode noise; unequal diagonal entries give unequal noise across outputs.
    #[serde(default)]
    pub noise_gain: Option<Vec<f64>>,
    /// Standard deviation of the white Gaussian sensor noise on every output (default 0).
    #[serde(default)]
    pub sensor_noise: f64,
    /// A change of `A` during the run (default none).
    #[serde(default)]
    pub switch: Option<PlantSwitch>,
}

/// `LinearSystem` with `y = x`, whose `A` may switch once.
struct Plant {
    sys: LinearSystem,
    switch: Option<PlantSwitch>,
}

impl Dynamics for Plant {
    fn state_dim(&self) -> usize {
        self.sys.state_dim()
    }
    fn input_dim(&self) -> usize {
        self.sys.input_dim()
    }
    fn output_dim(&self) -> usize {
        self.sys.output_dim()
    }
    fn disturbance_dim(&self) -> usize {
        self.sys.disturbance_dim()
    }
    fn drift(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        self.sys.drift(t, x, u, dx);
        if let Some(sw) = &self.switch {
            let share = sw.share(t);
            if share > 0.0 {
                // Replace A x by A(t) x = (A + s (A₂ − A)) x.
                let (n, a, a2) = (x.len(), self.sys.a(), &sw.a);
                for i in 0..n {
                    for j in 0..n {
                        dx[i] += share * (a2[i * n + j] - a[i * n + j]) * x[j];
                    }
                }
            }
        }
    }
    fn output(&self, x: &[f64], y: &mut [f64]) {
        self.sys.output(x, y);
    }
    fn disturbance_gain(&self) -> &[f64] {
        self.sys.disturbance_gain()
    }
}

impl LinearScenario {
    /// The state matrix in force at time `t`: `A`, the switched one, or between the two
    /// during a drift ([`PlantSwitch`]).
    #[must_use]
    pub fn a_at(&self, t: f64) -> Vec<f64> {
        match &self.switch {
            Some(s) => {
                let share = s.share(t);
                self.a.iter().zip(&s.a).map(|(a, a2)| a + share * (a2 - a)).collect()
            }
            None => self.a.clone(),
        }
    }

    /// Simulate with Euler–Maruyama from `x = 0`. Every draw derives from `seed`.
    ///
    /// # Errors
    /// Any configuration error of the system, the noise, the dither or the simulation, and
    /// [`DynamicsError::DimensionMismatch`] for a wrong `K_explore`, noise gain or switched
    /// `A` length; [`DynamicsError::Negative`] for a negative sensor noise.
    pub fn run(&self, seed: u64) -> Result<Trajectory, DynamicsError> {
        let (n, m) = (self.n, self.m);
        let mismatch =
            |name, expected, got| DynamicsError::DimensionMismatch { name, expected, got };
        if self.k_explore.len() != m * n {
            return Err(mismatch("k_explore", m * n, self.k_explore.len()));
        }
        crate::non_negative("sensor_noise", self.sensor_noise)?;
        let eye: Vec<f64> = (0..n * n).map(|k| if k / n == k % n { 1.0 } else { 0.0 }).collect();
        let e = self.noise_gain.clone().unwrap_or_else(|| eye.clone());
        if e.is_empty() || !e.len().is_multiple_of(n) {
            return Err(mismatch("noise_gain", n, e.len()));
        }
        let q = e.len() / n;
        let switch = match &self.switch {
            Some(s) if s.a.len() != n * n => return Err(mismatch("switch.a", n * n, s.a.len())),
            Some(s) => {
                for &v in &s.a {
                    crate::finite("switch.a", v)?;
                }
                crate::finite("switch.at", s.at)?;
                crate::finite("switch.ramp", s.ramp)?;
                if s.ramp < 0.0 {
                    return Err(DynamicsError::Negative { name: "switch.ramp", value: s.ramp });
                }
                Some(s.clone())
            }
            None => None,
        };
        let sys = LinearSystem::new(n, m, n, q, self.a.clone(), self.b.clone(), eye, e)?;
        let plant = Plant { sys, switch };
        let cfg = SimConfig {
            dt: self.dt,
            steps: self.steps,
            t0: 0.0,
            x0: vec![0.0; n],
            integrator: Integrator::EulerMaruyama,
            noise_scaling: NoiseScaling::Sde,
        };
        let noise = DisturbanceConfig::stationary(self.noise);
        let mut dist = (0..q)
            .map(|j| {
                Disturbance::new(noise.clone(), seed.wrapping_mul(1000).wrapping_add(j as u64))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let prbs = DitherConfig::Prbs { amplitude: self.dither, hold: self.dither_hold };
        let mut dithers = (0..m)
            .map(|j| Dither::new(prbs, seed.wrapping_mul(1000).wrapping_add(500 + j as u64)))
            .collect::<Result<Vec<_>, _>>()?;
        let k = &self.k_explore;
        let sigma_v = self.sensor_noise;
        let mut sensor_rng = seeded_rng(seed.wrapping_mul(1000).wrapping_add(900));
        let mut v = Vec::with_capacity(if sigma_v > 0.0 { (self.steps + 1) * n } else { 0 });
        let mut y_meas = vec![0.0; n];
        let mut traj = simulate(&plant, &cfg, &mut dist, |t, y, u| {
            for (i, ym) in y_meas.iter_mut().enumerate() {
                *ym = y[i];
                if sigma_v > 0.0 {
                    let z: f64 = StandardNormal.sample(&mut sensor_rng);
                    v.push(sigma_v * z);
                    *ym += sigma_v * z;
                }
            }
            for i in 0..m {
                u[i] = (0..n).map(|j| k[i * n + j] * y_meas[j]).sum::<f64>() + dithers[i].value(t);
            }
        })?;
        for (y, dv) in traj.y.iter_mut().zip(&v) {
            *y += dv;
        }
        Ok(traj)
    }
}
