//! Shared helpers: seeded linear-system streams with known answers.

use streamcert::dynamics::{
    Disturbance, DisturbanceConfig, Dither, DitherConfig, Integrator, LinearSystem, NoiseScaling,
    Process, SimConfig, Trajectory, simulate,
};

/// A stream from `ẋ = A x + B u + σ dW` (SDE noise on every state), `y = x`, under
/// `u = K_explore y + PRBS dither` held over each step.
pub(crate) struct LinearStream {
    pub(crate) a: Vec<f64>,
    pub(crate) b: Vec<f64>,
    pub(crate) n: usize,
    pub(crate) m: usize,
    pub(crate) sigma: f64,
    pub(crate) k_explore: Vec<f64>,
    pub(crate) dither: f64,
    pub(crate) dither_hold: f64,
    pub(crate) dt: f64,
    pub(crate) steps: usize,
}

impl LinearStream {
    pub(crate) fn run(&self, seed: u64) -> Trajectory {
        let (n, m) = (self.n, self.m);
        let c: Vec<f64> = (0..n * n).map(|k| if k / n == k % n { 1.0 } else { 0.0 }).collect();
        let sys = LinearSystem::new(n, m, n, n, self.a.clone(), self.b.clone(), c.clone(), c)
            .expect("valid system");
        let cfg = SimConfig {
            dt: self.dt,
            steps: self.steps,
            t0: 0.0,
            x0: vec![0.0; n],
            integrator: Integrator::EulerMaruyama,
            noise_scaling: NoiseScaling::Sde,
        };
        let mut dist: Vec<Disturbance> = (0..n)
            .map(|j| {
                let cfg = DisturbanceConfig::stationary(Process::Gaussian { sigma: self.sigma });
                Disturbance::new(cfg, seed * 1000 + j as u64).expect("valid")
            })
            .collect();
        let mut dithers: Vec<Dither> = (0..m)
            .map(|j| {
                let cfg = DitherConfig::Prbs { amplitude: self.dither, hold: self.dither_hold };
                Dither::new(cfg, seed * 1000 + 500 + j as u64).expect("valid")
            })
            .collect();
        let k = self.k_explore.clone();
        simulate(&sys, &cfg, &mut dist, |t, y, u| {
            for i in 0..m {
                u[i] = (0..n).map(|j| k[i * n + j] * y[j]).sum::<f64>() + dithers[i].value(t);
            }
        })
        .expect("valid simulation")
    }
}

/// True closed-loop rate `−λ_max(sym(A + B K))` with nalgebra's dense eigensolver (the oracle).
pub(crate) fn true_rate(a: &[f64], b: &[f64], k: &[f64], n: usize, m: usize) -> f64 {
    let a = nalgebra::DMatrix::from_row_slice(n, n, a);
    let b = nalgebra::DMatrix::from_row_slice(n, m, b);
    let k = nalgebra::DMatrix::from_row_slice(m, n, k);
    let j = a + b * k;
    let s = (&j + j.transpose()) * 0.5;
    -s.symmetric_eigen().eigenvalues.max()
}
