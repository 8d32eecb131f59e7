//! Known-answer nonlinear data sets: a scalar system `ẋ = f(x) + b u` under exploratory
//! output feedback, with the true state-dependent contraction rate.

use serde::{Deserialize, Serialize};

use crate::{
    Disturbance, DisturbanceConfig, Dither, DitherConfig, Dynamics, DynamicsError, Integrator,
    NoiseScaling, Process, SimConfig, Trajectory, simulate,
};

/// The drift `f` of a [`ScalarScenario`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ScalarDrift {
    /// `f(x) = −x tanh x` (G5's node 1 without coupling): `f'(x) = −tanh x − x sech² x`.
    NegXTanhX,
    /// `f(x) = Σ_i c_i x^i`, coefficients lowest degree first.
    Polynomial(Vec<f64>),
}

impl ScalarDrift {
    /// `f(x)`.
    #[must_use]
    pub fn value(&self, x: f64) -> f64 {
        match self {
            Self::NegXTanhX => -x * x.tanh(),
            Self::Polynomial(c) => c.iter().rev().fold(0.0, |a, &ci| a * x + ci),
        }
    }

    /// `f'(x)`.
    #[must_use]
    pub fn slope(&self, x: f64) -> f64 {
        match self {
            Self::NegXTanhX => {
                let th = x.tanh();
                -th - x * (1.0 - th * th)
            }
            Self::Polynomial(c) => {
                c.iter().enumerate().skip(1).rev().fold(0.0, |a, (i, &ci)| a * x + i as f64 * ci)
            }
        }
    }
}

/// `dx = (f(x) + b u) dt + dη` (SDE scaling), `y = x`, under `u = k_explore y + d(t)` with a
/// PRBS `d` held over each step. The ground truth of the nonlinear certificate: under a
/// candidate gain `k` the local contraction rate at `x` is
/// [`local_rate`](Self::local_rate)` = −(f'(x) + b k)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScalarScenario {
    /// The drift.
    pub drift: ScalarDrift,
    /// Input gain `b`.
    pub b: f64,
    /// Noise process (scaled by `√dt`).
    pub noise: Process,
    /// Exploration gain.
    pub k_explore: f64,
    /// PRBS amplitude.
    pub dither: f64,
    /// PRBS hold time in seconds.
    pub dither_hold: f64,
    /// Step.
    pub dt: f64,
    /// Number of steps.
    pub steps: usize,
    /// Initial state (default 0).
    #[serde(default)]
    pub x0: f64,
}

struct Plant<'a> {
    drift: &'a ScalarDrift,
    b: [f64; 1],
    e: [f64; 1],
}

impl Dynamics for Plant<'_> {
    fn state_dim(&self) -> usize {
        1
    }
    fn input_dim(&self) -> usize {
        1
    }
    fn output_dim(&self) -> usize {
        1
    }
    fn disturbance_dim(&self) -> usize {
        1
    }
    fn drift(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        dx[0] = self.drift.value(x[0]) + self.b[0] * u[0];
    }
    fn output(&self, x: &[f64], y: &mut [f64]) {
        y[0] = x[0];
    }
    fn disturbance_gain(&self) -> &[f64] {
        &self.e
    }
}

impl ScalarScenario {
    /// `drift` explored by `u = k_explore y + PRBS(±1.5, held 1 s)` with Gaussian process noise
    /// `σ = 0.1`, `b = 1`, 40 s at `dt = 0.01` from `x = 0`: the nonlinear study's loop (with
    /// `f = −x tanh x` and `k_explore = −1.1`, the nonlinear study's example).
    #[must_use]
    pub fn new(drift: ScalarDrift, k_explore: f64) -> Self {
        Self {
            drift,
            b: 1.0,
            noise: Process::Gaussian { sigma: 0.1 },
            k_explore,
            dither: 1.5,
            dither_hold: 1.0,
            dt: 0.01,
            steps: 4000,
            x0: 0.0,
        }
    }

    /// The true local contraction rate at `x` under the candidate gain `k`: `−(f'(x) + b k)`.
    #[must_use]
    pub fn local_rate(&self, x: f64, k: f64) -> f64 {
        -(self.drift.slope(x) + self.b * k)
    }

    /// Simulate with Euler–Maruyama from `x0`. Every draw derives from `seed` (the same
    /// stream rule as [`LinearScenario`](crate::LinearScenario)).
    ///
    /// # Errors
    /// Any configuration error of the noise, the dither or the simulation.
    pub fn run(&self, seed: u64) -> Result<Trajectory, DynamicsError> {
        crate::finite("b", self.b)?;
        crate::finite("k_explore", self.k_explore)?;
        crate::finite("x0", self.x0)?;
        let plant = Plant { drift: &self.drift, b: [self.b], e: [1.0] };
        let cfg = SimConfig {
            dt: self.dt,
            steps: self.steps,
            t0: 0.0,
            x0: vec![self.x0],
            integrator: Integrator::EulerMaruyama,
            noise_scaling: NoiseScaling::Sde,
        };
        let mut dist = vec![Disturbance::new(
            DisturbanceConfig::stationary(self.noise),
            seed.wrapping_mul(1000),
        )?];
        let prbs = DitherConfig::Prbs { amplitude: self.dither, hold: self.dither_hold };
        let mut dither = Dither::new(prbs, seed.wrapping_mul(1000).wrapping_add(500))?;
        let k = self.k_explore;
        simulate(&plant, &cfg, &mut dist, |t, y, u| u[0] = k * y[0] + dither.value(t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slopes_match_finite_differences() {
        for drift in [ScalarDrift::NegXTanhX, ScalarDrift::Polynomial(vec![0.1, -1.0, 0.5, -0.3])] {
            for x in [-2.0, -1.2, 0.0, 0.4, 1.7] {
                let h = 1e-6;
                let fd = (drift.value(x + h) - drift.value(x - h)) / (2.0 * h);
                assert!((fd - drift.slope(x)).abs() < 1e-7, "{drift:?} at {x}");
            }
        }
    }

    #[test]
    fn the_tanh_loop_has_a_non_contracting_band() {
        let s = ScalarScenario::new(ScalarDrift::NegXTanhX, -1.1);
        assert!(s.local_rate(-1.2, -1.1) < 0.0);
        assert!(s.local_rate(0.0, -1.1) > 1.0);
        let traj = s.run(3).unwrap();
        let visited_min =
            traj.x.iter().map(|&x| s.local_rate(x, -1.1)).fold(f64::INFINITY, f64::min);
        assert!(visited_min < 0.0, "the data visit the band: {visited_min}");
        assert_eq!(traj.x, s.run(3).unwrap().x, "seeded");
    }
}
