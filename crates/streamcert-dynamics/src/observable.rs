//! A loop of any order measured through one output: the plant
//! `y⁽ᴺ⁾ + a_1 y⁽ᴺ⁻¹⁾ + … + a_N y = u(t − τ) + 0.1` in observable form, under
//! `u = K y_m + d`, simulated exactly (zero-order hold) at a fixed step.
//!
//! It is the plant family of the certificate of order `n` (the tests of
//! `streamcert-certificate` and `cargo xtask validity --only-order`): a tank behind a tank, a
//! mass read by its position, a plant behind a sensor lag, a transport delay of whole samples.

use std::collections::VecDeque;

use nalgebra::{DMatrix, DVector};

/// SplitMix64 uniforms in `[0, 1)` and Box–Muller normals: seeded and portable (integer
/// arithmetic and `ln`, `sqrt`, `cos` of IEEE-754 `f64`).
#[derive(Debug, Clone)]
pub struct SplitMix(pub u64);

impl SplitMix {
    /// A uniform in `[0, 1)` (the top 53 bits of the next SplitMix64 output).
    pub fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A standard normal (Box–Muller, `√(−2 ln u₁) cos(2π u₂)`).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// A loop `u = gain · y_m + d` around the plant `sᴺ + a_1 sᴺ⁻¹ + … + a_N` in observable form:
/// `ẋ_i = −a_i x_1 + x_{i+1}` for `i < N`, `ẋ_N = −a_N x_1 + u(t − τ) + 0.1`, `y = x_1`,
/// from rest. Only `y` is measured, so every other state is hidden from the certificate.
///
/// Each step of `dt` is exact for the input held over it (the matrix exponential of the
/// state augmented by the input and the constant). The closed loop's characteristic
/// polynomial is `sᴺ + a_1 sᴺ⁻¹ + … + (a_N − K)` without delay: its rightmost root's real
/// part is the loop's rate, the truth a certificate is judged against.
#[derive(Debug, Clone)]
pub struct ObservableLoop {
    /// `a_1..a_N` (`N ≥ 1`).
    pub a: Vec<f64>,
    /// The candidate gain `K`.
    pub gain: f64,
    /// Sensor noise: `y_m = y + sensor · e`, `e` standard normal per sample.
    pub sensor: f64,
    /// Process noise on the last (unmeasured) state: `process · √dt · w` per sample.
    pub process: f64,
    /// Input delay in samples (a transport delay `τ = delay · dt`).
    pub delay: usize,
    /// Samples between the dither's draws of `±amplitude` (its sign redrawn with probability
    /// one half).
    pub hold: usize,
    /// The dither's amplitude.
    pub amplitude: f64,
    /// From this sample on the plant's `a` is this one (a plant change).
    pub change: Option<(usize, Vec<f64>)>,
    /// A cubic static term: `ẋ_N` also receives `−cubic · y³` (a spring that stiffens for
    /// `cubic > 0`). 0 (the default) is the linear loop; otherwise each sample is integrated
    /// by the classical Runge–Kutta method in ten steps, the input held.
    pub cubic: f64,
    /// Samples in a run.
    pub samples: usize,
    /// The sampling step in seconds.
    pub dt: f64,
}

impl ObservableLoop {
    /// The plant `a` under `gain` at 100 Hz: sensor noise `σ = 0.01`, no process noise, no
    /// delay, a dither of `±0.1` redrawn every second, 40 s.
    #[must_use]
    pub fn new(a: &[f64], gain: f64) -> Self {
        Self {
            a: a.to_vec(),
            gain,
            sensor: 0.01,
            process: 0.0,
            delay: 0,
            hold: 100,
            amplitude: 0.1,
            change: None,
            cubic: 0.0,
            samples: 4000,
            dt: 0.01,
        }
    }

    /// One exact step of `dt` of the plant `a`, its state augmented by the input and the
    /// constant: `exp([[A, b, 0.1 b], [0, 0, 0], [0, 0, 0]] dt)`.
    fn step(&self, a: &[f64]) -> DMatrix<f64> {
        (Self::generator(a) * self.dt).exp()
    }

    /// The augmented system's matrix `[[A, b, 0.1 b], [0, 0, 0], [0, 0, 0]]`.
    fn generator(a: &[f64]) -> DMatrix<f64> {
        let n = a.len();
        let mut big = DMatrix::<f64>::zeros(n + 2, n + 2);
        for (i, ai) in a.iter().enumerate() {
            big[(i, 0)] = -ai;
            if i + 1 < n {
                big[(i, i + 1)] = 1.0;
            }
        }
        big[(n - 1, n)] = 1.0;
        big[(n - 1, n + 1)] = 0.1;
        big
    }

    /// One step of `dt` with the cubic term: ten classical Runge–Kutta steps of
    /// `ẋ = G x − cubic x_1³ e_N`, the input and the constant held.
    fn nonlinear_step(&self, generator: &DMatrix<f64>, x: &DVector<f64>) -> DVector<f64> {
        let n = self.a.len();
        let f = |x: &DVector<f64>| {
            let mut dx = generator * x;
            dx[n - 1] -= self.cubic * x[0].powi(3);
            dx
        };
        let h = self.dt / 10.0;
        let mut x = x.clone();
        for _ in 0..10 {
            let k1 = f(&x);
            let k2 = f(&(&x + &k1 * (h / 2.0)));
            let k3 = f(&(&x + &k2 * (h / 2.0)));
            let k4 = f(&(&x + &k3 * h));
            x += (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0);
        }
        x
    }

    /// The noiseless loop's rate: `−ln ϱ(Φ_cl) / dt`, `ϱ` the spectral radius of the sampled
    /// closed loop `x_{k+1} = Φ x_k + Γ u_{k−delay}`, `u_k = K x_{1,k}` (the plant's state and
    /// the `delay` inputs in flight). It is the truth of the loop as simulated, the input held
    /// over each sample; without delay it is the rightmost root of
    /// `sᴺ + a_1 sᴺ⁻¹ + … + (a_N − K)` to `O(K dt)`. With a cubic term it is the rate of the
    /// linearisation at `y = 0`. `NaN` for an empty `a`.
    #[must_use]
    pub fn rate(&self) -> f64 {
        let n = self.a.len();
        if n == 0 {
            return f64::NAN;
        }
        let step = self.step(&self.a);
        let size = n + self.delay;
        let mut cl = DMatrix::<f64>::zeros(size, size);
        cl.view_mut((0, 0), (n, n)).copy_from(&step.view((0, 0), (n, n)));
        let gamma = step.view((0, n), (n, 1)).into_owned();
        if self.delay == 0 {
            for i in 0..n {
                cl[(i, 0)] += gamma[i] * self.gain;
            }
        } else {
            // The oldest input in flight, `x_n`, acts now; the buffer shifts; the newest is
            // `K x_1`.
            for i in 0..n {
                cl[(i, n)] = gamma[i];
            }
            for j in 0..self.delay - 1 {
                cl[(n + j, n + j + 1)] = 1.0;
            }
            cl[(size - 1, 0)] = self.gain;
        }
        let radius = cl.complex_eigenvalues().iter().map(|l| l.norm()).fold(0.0, f64::max);
        -radius.ln() / self.dt
    }

    /// Run seed `seed`, calling `visit(t, y_m, u)` at every sample (`t = k · dt`) until it
    /// returns `false` or the run's samples are done. An empty `a` or a zero `hold` runs
    /// nothing.
    pub fn run(&self, seed: u64, mut visit: impl FnMut(f64, f64, f64) -> bool) {
        let n = self.a.len();
        if n == 0 || self.hold == 0 {
            return;
        }
        let mut step = self.step(&self.a);
        let mut generator = Self::generator(&self.a);
        let mut rng = SplitMix(seed);
        let mut x = DVector::<f64>::zeros(n + 2);
        let mut dither = self.amplitude;
        let mut queue: VecDeque<f64> = std::iter::repeat_n(0.0, self.delay).collect();
        for k in 0..self.samples {
            if let Some((at, a)) = &self.change
                && k == *at
                && a.len() == n
            {
                step = self.step(a);
                generator = Self::generator(a);
            }
            if k % self.hold == 0 {
                dither = if rng.uniform() < 0.5 { -self.amplitude } else { self.amplitude };
            }
            let measured = x[0] + self.sensor * rng.normal();
            let input = self.gain * measured + dither;
            if !visit(k as f64 * self.dt, measured, input) {
                return;
            }
            queue.push_back(input);
            x[n] = queue.pop_front().unwrap_or(input);
            x[n + 1] = 1.0;
            x = if self.cubic == 0.0 { &step * x } else { self.nonlinear_step(&generator, &x) };
            x[n - 1] += self.process * self.dt.sqrt() * rng.normal();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The noiseless first-order loop `ẏ = −a y + u + 0.1`, `u = K y + d`, against its closed
    /// form over one held dither value.
    #[test]
    fn the_first_order_loop_matches_its_closed_form() {
        let plant = ObservableLoop { sensor: 0.0, hold: 1000, ..ObservableLoop::new(&[2.0], -1.0) };
        let mut ys = Vec::new();
        plant.run(3, |_, y, u| {
            ys.push((y, u));
            ys.len() < 500
        });
        let d = ys[0].1;
        // y(t) = y∞ (1 − e^{−3t}) with y∞ = (d + 0.1) / 3 under the held input.
        let y_inf = (d + 0.1) / 3.0;
        for (k, (y, _)) in ys.iter().enumerate() {
            let exact = y_inf * (1.0 - (-3.0 * k as f64 * 0.01).exp());
            assert!((y - exact).abs() < 1e-12, "sample {k}: {y} against {exact}");
        }
    }

    /// A delay of `k` samples shifts the input's part of the response by exactly `k` samples
    /// (the constant is not delayed: its part, a run without dither, is taken out).
    #[test]
    fn a_delay_shifts_the_response_by_whole_samples() {
        let base =
            ObservableLoop { sensor: 0.0, gain: 0.0, ..ObservableLoop::new(&[1.0, 2.0], 0.0) };
        let collect = |plant: &ObservableLoop| {
            let mut v = Vec::new();
            plant.run(5, |_, y, _| {
                v.push(y);
                true
            });
            v
        };
        let constant = collect(&ObservableLoop { amplitude: 0.0, ..base.clone() });
        let plain = collect(&base);
        let delayed = collect(&ObservableLoop { delay: 7, ..base.clone() });
        let part = |v: &[f64], k: usize| v[k] - constant[k];
        for k in 0..7 {
            assert!(part(&delayed, k).abs() < 1e-15);
        }
        for k in 7..plain.len() {
            assert!((part(&delayed, k) - part(&plain, k - 7)).abs() < 1e-12, "sample {k}");
        }
        assert!(part(&plain, 100).abs() > 1e-3);
    }

    /// The sampled loop's rate against the first-order closed form
    /// `−ln(e^{−a dt} + K (1 − e^{−a dt}) / a) / dt`, and against the polynomial's rightmost
    /// root to `O(K dt)` at order 2 and 3.
    #[test]
    fn the_rate_is_the_sampled_loops() {
        let first = ObservableLoop::new(&[2.0], -1.0);
        let e = (-0.02f64).exp();
        let exact = -(e - (1.0 - e) / 2.0).ln() / 0.01;
        assert!((first.rate() - exact).abs() < 1e-9, "{} against {exact}", first.rate());
        // (s + 0.045)(s + 1.155), and (s + 1)³ − 0.955³ (rightmost root −0.045).
        for (a, gain) in [(vec![1.2, 1.0], 0.948_025), (vec![3.0, 3.0, 1.0], 0.955f64.powi(3))] {
            let rate = ObservableLoop::new(&a, gain).rate();
            assert!((rate - 0.045).abs() < 5e-4, "{a:?}: {rate}");
        }
        // A delay slows a loop under positive feedback: ẏ = −y + K y(t − τ) has its rightmost
        // root at −0.045 for K = 0.955 e^{−0.045 τ}, τ = 0.1 s (10 samples), to O(dt).
        let delayed =
            ObservableLoop { delay: 10, ..ObservableLoop::new(&[1.0], 0.955 * (-0.0045f64).exp()) };
        assert!((delayed.rate() - 0.045).abs() < 1e-3, "{}", delayed.rate());
    }

    /// The Runge–Kutta path of the cubic term agrees with the exact step where the cubic is
    /// negligible, and a stiffening spring holds a smaller excursion than the linear one.
    #[test]
    fn the_cubic_term_stiffens_the_loop() {
        let collect = |plant: &ObservableLoop| {
            let mut v = Vec::new();
            plant.run(8, |_, y, _| {
                v.push(y);
                true
            });
            v
        };
        let linear = ObservableLoop { sensor: 0.0, ..ObservableLoop::new(&[1.2, 1.0], 0.5) };
        let tiny = collect(&ObservableLoop { cubic: 1e-12, ..linear.clone() });
        let exact = collect(&linear);
        for (a, b) in tiny.iter().zip(&exact) {
            assert!((a - b).abs() < 1e-9, "{a} against {b}");
        }
        let stiff = collect(&ObservableLoop { cubic: 5.0, amplitude: 1.0, ..linear.clone() });
        let soft = collect(&ObservableLoop { amplitude: 1.0, ..linear });
        let peak = |v: &[f64]| v.iter().fold(0.0f64, |m, y| m.max(y.abs()));
        assert!(peak(&stiff) < 0.8 * peak(&soft), "{} against {}", peak(&stiff), peak(&soft));
    }

    #[test]
    fn the_same_seed_gives_the_same_run() {
        let plant = ObservableLoop { process: 0.05, ..ObservableLoop::new(&[0.09, 1.0], -1.0) };
        let collect = |seed| {
            let mut v = Vec::new();
            plant.run(seed, |t, y, u| {
                v.push((t, y, u));
                true
            });
            v
        };
        assert_eq!(collect(11), collect(11));
        assert_ne!(collect(11), collect(12));
    }
}
