//! What the order-`n` integration tests share: a seeded, portable random stream and loops of
//! any order simulated exactly.

use std::collections::VecDeque;

use nalgebra::{DMatrix, DVector};

/// The sampling step of every simulated loop (100 Hz).
pub(crate) const DT: f64 = 0.01;

/// SplitMix64 uniforms in `[0, 1)` and Box–Muller normals: seeded and portable.
pub(crate) struct Rng(pub(crate) u64);

impl Rng {
    /// A uniform in `[0, 1)`.
    pub(crate) fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A standard normal.
    pub(crate) fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// A loop `u = gain · y_m + d` around the plant `sᴺ + a_1 sᴺ⁻¹ + … + a_N` in observable form
/// (`y = x_1`; the input, delayed by `delay` samples, and the constant 0.1 enter the last
/// state), from rest, simulated exactly (zero-order hold) at [`DT`].
#[derive(Debug, Clone)]
pub(crate) struct Loop {
    /// `a_1..a_N`.
    pub(crate) a: Vec<f64>,
    /// The candidate gain `K`.
    pub(crate) gain: f64,
    /// Sensor noise: `y_m = y + sensor · e`.
    pub(crate) sensor: f64,
    /// Process noise on the last (unmeasured) state: `process · √DT · w` per sample.
    pub(crate) process: f64,
    /// Input delay in samples.
    pub(crate) delay: usize,
    /// Samples between the dither's draws of `±amplitude`.
    pub(crate) hold: usize,
    /// The dither's amplitude.
    pub(crate) amplitude: f64,
    /// From this sample on the plant's `a` is this one.
    pub(crate) change: Option<(usize, Vec<f64>)>,
    /// Samples in a run.
    pub(crate) samples: usize,
}

impl Loop {
    /// The plant `a` under `gain`, sensor noise `σ = 0.01`, a dither of `±0.1` redrawn every
    /// second, 40 s.
    pub(crate) fn new(a: &[f64], gain: f64) -> Self {
        Self {
            a: a.to_vec(),
            gain,
            sensor: 0.01,
            process: 0.0,
            delay: 0,
            hold: 100,
            amplitude: 0.1,
            change: None,
            samples: 4000,
        }
    }

    /// One exact step of [`DT`] of the plant `a`, its state augmented by the input and the
    /// constant.
    fn step(a: &[f64]) -> DMatrix<f64> {
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
        (big * DT).exp()
    }

    /// Run seed `seed`, calling `visit(t, y_m, u)` at every sample until it returns `false`.
    pub(crate) fn run(&self, seed: u64, mut visit: impl FnMut(f64, f64, f64) -> bool) {
        let n = self.a.len();
        let mut step = Self::step(&self.a);
        let mut rng = Rng(seed);
        let mut x = DVector::<f64>::zeros(n + 2);
        let mut dither = self.amplitude;
        let mut queue: VecDeque<f64> = std::iter::repeat_n(0.0, self.delay).collect();
        for k in 0..self.samples {
            if let Some((at, a)) = &self.change
                && k == *at
            {
                step = Self::step(a);
            }
            if k % self.hold == 0 {
                dither = if rng.uniform() < 0.5 { -self.amplitude } else { self.amplitude };
            }
            let measured = x[0] + self.sensor * rng.normal();
            let input = self.gain * measured + dither;
            if !visit(k as f64 * DT, measured, input) {
                return;
            }
            queue.push_back(input);
            x[n] = queue.pop_front().unwrap_or(input);
            x[n + 1] = 1.0;
            x = &step * x;
            x[n - 1] += self.process * DT.sqrt() * rng.normal();
        }
    }
}

/// `f` over `seeds` on two threads, in seed order.
pub(crate) fn par_map<T: Send>(seeds: std::ops::Range<u64>, f: impl Fn(u64) -> T + Sync) -> Vec<T> {
    let seeds: Vec<u64> = seeds.collect();
    let (left, right) = seeds.split_at(seeds.len() / 2);
    std::thread::scope(|s| {
        let a = s.spawn(|| left.iter().map(|&k| f(k)).collect::<Vec<_>>());
        let b = right.iter().map(|&k| f(k)).collect::<Vec<_>>();
        let mut all = a.join().unwrap();
        all.extend(b);
        all
    })
}
