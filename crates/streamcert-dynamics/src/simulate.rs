//! Fixed-step integration of a [`Dynamics`] under a feedback policy and seeded disturbances.
//!
//! One step from `t_k` to `t_{k+1} = t_k + dt`, with the input `u_k = π(t_k, y_k)` held over
//! the step (zero-order hold):
//!
//! ```text
//! x_{k+1} = Φ_dt(x_k, u_k)                  drift, Euler or RK4, with the periodic layer p(t)
//!           + E (s(dt) r_k + i_k)           random part r_k scaled by NoiseScaling, impulses i_k
//! ```
//!
//! The periodic layer is deterministic and enters the drift (`ẋ = f + E p(t)`), evaluated at
//! each RK4 stage time. Under [`NoiseScaling::HeldInput`] the random part also enters the
//! drift, held over the step.

use serde::{Deserialize, Serialize};

use crate::{Disturbance, Dynamics, DynamicsError, finite, positive};

/// Integration scheme for the drift.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Integrator {
    /// Euler–Maruyama: `x + dt f(t, x, u)` plus the noise increment. Strong order 1/2 for
    /// SDEs; the standard scheme for the stochastic experiments.
    EulerMaruyama,
    /// Classical fourth-order Runge–Kutta on the drift (input and held noise constant over the
    /// step), plus the noise increment afterwards. Fourth order for deterministic runs; with
    /// noise it is no more accurate than Euler–Maruyama in the strong sense.
    Rk4,
}

/// How one disturbance sample `r_k` becomes a state increment over a step of length `dt`.
///
/// The paper writes `ẋ4 = −x4 + u4 + η(t)` with `η` "Gaussian with standard deviation
/// `σ0`" but never says how a sample relates to `dt`. Three readings:
///
/// | variant | increment | stationary std of `ẋ = −a x + η` |
/// |---|---|---|
/// | [`Sde`](Self::Sde) | `√dt · r_k` (`r` is the intensity of white noise, `dx = … + σ dW`) | `σ / √(2a)`, independent of `dt` |
/// | [`HeldInput`](Self::HeldInput) | `dt · r_k` (`η` is a piecewise-constant signal) | `≈ σ √(dt / 2a)`, vanishes as `dt → 0` |
/// | [`StateIncrement`](Self::StateIncrement) | `r_k` (added to the state each step) | `≈ σ / √(2a dt)`, grows as `dt → 0` |
///
/// The experiments use [`Sde`](Self::Sde): it is the only reading whose statistics do not
/// change with the step, so results at the paper's `dt = 0.02` mean something for another `dt`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseScaling {
    /// SDE reading: increment `√dt · r_k`.
    Sde,
    /// Held-input reading: `η` constant over the step inside the drift, increment `dt · r_k`.
    HeldInput,
    /// Per-step additive reading: increment `r_k`.
    StateIncrement,
}

impl NoiseScaling {
    /// The factor `s(dt)` multiplying a random sample.
    #[must_use]
    pub fn factor(self, dt: f64) -> f64 {
        match self {
            Self::Sde => dt.sqrt(),
            Self::HeldInput => dt,
            Self::StateIncrement => 1.0,
        }
    }
}

/// Simulation settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    /// Step `dt > 0` in seconds.
    pub dt: f64,
    /// Number of steps; the trajectory has `steps + 1` samples.
    pub steps: usize,
    /// Initial time.
    pub t0: f64,
    /// Initial state (length `n`).
    pub x0: Vec<f64>,
    /// Drift integrator.
    pub integrator: Integrator,
    /// Noise scaling with `dt`.
    pub noise_scaling: NoiseScaling,
}

impl SimConfig {
    /// Validate against a system of state dimension `n`.
    ///
    /// # Errors
    /// [`DynamicsError::NotPositive`] for `dt <= 0`, [`DynamicsError::NonFinite`] for a NaN
    /// `dt`, `t0` or initial state entry, [`DynamicsError::DimensionMismatch`] for a wrong
    /// initial state length.
    pub fn validate(&self, n: usize) -> Result<(), DynamicsError> {
        positive("dt", self.dt)?;
        finite("t0", self.t0)?;
        if self.x0.len() != n {
            return Err(DynamicsError::DimensionMismatch {
                name: "x0",
                expected: n,
                got: self.x0.len(),
            });
        }
        for &v in &self.x0 {
            finite("x0", v)?;
        }
        Ok(())
    }
}

/// A simulated trajectory; all series are flat, row-major by sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Trajectory {
    /// State dimension `n`.
    pub n: usize,
    /// Input dimension `m`.
    pub m: usize,
    /// Output dimension `p`.
    pub p: usize,
    /// Disturbance channels `q`.
    pub q: usize,
    /// Sample times `t_0 … t_K` (`K + 1` values).
    pub t: Vec<f64>,
    /// States, `(K + 1) × n`.
    pub x: Vec<f64>,
    /// Measured outputs `y_k = C x_k`, `(K + 1) × p`.
    pub y: Vec<f64>,
    /// Inputs `u_k = π(t_k, y_k)`, `(K + 1) × m` (the last one is computed but not applied).
    pub u: Vec<f64>,
    /// Disturbance values `η_k = r_k + p(t_k)` per channel before scaling, `K × q`.
    pub eta: Vec<f64>,
}

impl Trajectory {
    /// An empty trajectory of the dimensions `(n, m, p, q)` with room for `steps` steps.
    fn with_capacity((n, m, p, q): (usize, usize, usize, usize), steps: usize) -> Self {
        Self {
            n,
            m,
            p,
            q,
            t: Vec::with_capacity(steps + 1),
            x: Vec::with_capacity((steps + 1) * n),
            y: Vec::with_capacity((steps + 1) * p),
            u: Vec::with_capacity((steps + 1) * m),
            eta: Vec::with_capacity(steps * q),
        }
    }

    /// Number of samples `K + 1`.
    #[must_use]
    pub fn len(&self) -> usize {
        self.t.len()
    }
    /// `true` when there is no sample.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
    /// State at sample `k`.
    #[must_use]
    pub fn state(&self, k: usize) -> &[f64] {
        &self.x[k * self.n..(k + 1) * self.n]
    }
    /// Output at sample `k`.
    #[must_use]
    pub fn output(&self, k: usize) -> &[f64] {
        &self.y[k * self.p..(k + 1) * self.p]
    }
    /// Input at sample `k`.
    #[must_use]
    pub fn input(&self, k: usize) -> &[f64] {
        &self.u[k * self.m..(k + 1) * self.m]
    }
    /// Disturbance values of step `k` (`k < K`).
    #[must_use]
    pub fn disturbance(&self, k: usize) -> &[f64] {
        &self.eta[k * self.q..(k + 1) * self.q]
    }
}

/// Simulate `sys` from `cfg.x0` for `cfg.steps` steps under the policy `u = policy(t, y)`.
///
/// `disturbances[j]` drives channel `j` (one per column of `E`). All output storage is
/// allocated once before the loop; the loop itself does not allocate.
///
/// # Errors
/// Any [`SimConfig::validate`] error, or [`DynamicsError::DimensionMismatch`] when the number
/// of disturbances differs from `q`.
///
/// ```
/// use streamcert_dynamics::*;
/// let sys = LinearSystem::new(1, 1, 1, 1, vec![-1.0], vec![1.0], vec![1.0], vec![1.0])?;
/// let cfg = SimConfig { dt: 0.01, steps: 100, t0: 0.0, x0: vec![1.0],
///     integrator: Integrator::Rk4, noise_scaling: NoiseScaling::Sde };
/// let mut d = [Disturbance::new(DisturbanceConfig::none(), 0)?];
/// let traj = simulate(&sys, &cfg, &mut d, |_t, _y, u| u[0] = 0.0)?;
/// assert!((traj.state(100)[0] - (-1.0f64).exp()).abs() < 1e-9);
/// # Ok::<(), DynamicsError>(())
/// ```
pub fn simulate<D, P>(
    sys: &D,
    cfg: &SimConfig,
    disturbances: &mut [Disturbance],
    mut policy: P,
) -> Result<Trajectory, DynamicsError>
where
    D: Dynamics + ?Sized,
    P: FnMut(f64, &[f64], &mut [f64]),
{
    let (n, m, p, q) = (sys.state_dim(), sys.input_dim(), sys.output_dim(), sys.disturbance_dim());
    cfg.validate(n)?;
    if disturbances.len() != q {
        return Err(DynamicsError::DimensionMismatch {
            name: "disturbances",
            expected: q,
            got: disturbances.len(),
        });
    }
    let e = sys.disturbance_gain();
    let k_max = cfg.steps;
    let dt = cfg.dt;
    let scale = cfg.noise_scaling.factor(dt);
    let held = cfg.noise_scaling == NoiseScaling::HeldInput;

    let mut traj = Trajectory::with_capacity((n, m, p, q), k_max);
    // Scratch, allocated once: x, y, u, random parts, impulse parts, 4 RK stages, stage state.
    let mut x = cfg.x0.clone();
    let mut y = vec![0.0; p];
    let mut u = vec![0.0; m];
    let mut r = vec![0.0; q];
    let mut imp = vec![0.0; q];
    let mut held_r = vec![0.0; q];
    let mut k = vec![vec![0.0; n]; 4];
    let mut xs = vec![0.0; n];

    // Drift including the deterministic layer (and the held random part when `held`).
    let full_drift =
        |t: f64, x: &[f64], u: &[f64], held_r: &[f64], dist: &[Disturbance], dx: &mut [f64]| {
            sys.drift(t, x, u, dx);
            for (j, d) in dist.iter().enumerate() {
                let w = d.periodic(t) + held_r[j];
                if w != 0.0 {
                    for i in 0..n {
                        dx[i] += e[i * q + j] * w;
                    }
                }
            }
        };

    let mut t = cfg.t0;
    for step in 0..=k_max {
        sys.output(&x, &mut y);
        policy(t, &y, &mut u);
        traj.t.push(t);
        traj.x.extend_from_slice(&x);
        traj.y.extend_from_slice(&y);
        traj.u.extend_from_slice(&u);
        if step == k_max {
            break;
        }
        for (j, d) in disturbances.iter_mut().enumerate() {
            r[j] = d.random(t);
            imp[j] = d.impulses_in(t, t + dt);
            traj.eta.push(r[j] + d.periodic(t));
            held_r[j] = if held { r[j] } else { 0.0 };
        }
        let drift =
            |t: f64, x: &[f64], dx: &mut [f64]| full_drift(t, x, &u, &held_r, disturbances, dx);
        integrate(cfg.integrator, drift, (t, dt), &mut x, (&mut k, &mut xs));
        for j in 0..q {
            let w = if held { 0.0 } else { scale * r[j] } + imp[j];
            if w != 0.0 {
                for i in 0..n {
                    x[i] += e[i * q + j] * w;
                }
            }
        }
        // Time from the index, not by accumulation, so long runs do not drift.
        t = cfg.t0 + (step + 1) as f64 * dt;
    }
    Ok(traj)
}

/// One step of `dt` from `t` of `ẋ = drift(t, x)` by `integrator`, in place, with the stages
/// `k` (four of `n`) and the stage state `xs` as scratch.
fn integrate(
    integrator: Integrator,
    drift: impl Fn(f64, &[f64], &mut [f64]),
    (t, dt): (f64, f64),
    x: &mut [f64],
    (k, xs): (&mut [Vec<f64>], &mut [f64]),
) {
    let n = x.len();
    match integrator {
        Integrator::EulerMaruyama => {
            drift(t, x, &mut k[0]);
            for i in 0..n {
                x[i] += dt * k[0][i];
            }
        }
        Integrator::Rk4 => {
            let [k1, k2, k3, k4] = k else { unreachable!("four stages") };
            drift(t, x, k1);
            for i in 0..n {
                xs[i] = x[i] + 0.5 * dt * k1[i];
            }
            drift(t + 0.5 * dt, xs, k2);
            for i in 0..n {
                xs[i] = x[i] + 0.5 * dt * k2[i];
            }
            drift(t + 0.5 * dt, xs, k3);
            for i in 0..n {
                xs[i] = x[i] + dt * k3[i];
            }
            drift(t + dt, xs, k4);
            for i in 0..n {
                x[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
    }
}
