//! The hidden-dynamics guard of the certificate of order `n` (the past-row test): how often it
//! closes the gate of a loop the model holds, and how often it refuses a plant with a state
//! beyond the order.
//!
//! Protocol (fixed before the runs): plants in observable form (`y = x_1`, the input and the
//! constant 0.1 entering the last state), simulated exactly (zero-order hold) at 100 Hz for
//! 40 s from rest, optionally with the input delayed by a whole number of samples; the loop
//! `u = K y_m + d`, `d` a dither of `±0.1` redrawn every second; sensor noise `σ = 0.01`;
//! the certificate's defaults (`h = 50`, `M = 2000`, looks every 200 samples, `δ = 0.01`,
//! margin 0.05, the guard at risk `δ` per look).

use std::collections::VecDeque;

use nalgebra::{DMatrix, DVector};
use streamcert_certificate::{NotCertified, OrderNCertificate, OrderNCertificateConfig};
use streamcert_regression::{LoopModel, OrderNConfig};

/// SplitMix64 uniforms in `[0, 1)` and Box–Muller normals: seeded and portable.
struct Rng(u64);

impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

const DT: f64 = 0.01;

/// What one run's looks said: certified, refused by the guard, other.
#[derive(Debug, Default, Clone, Copy)]
struct Tally {
    looks: usize,
    certified: usize,
    hidden: usize,
}

/// The plant `sᴺ + a_1 sᴺ⁻¹ + … + a_N` (`a`), its input delayed by `delay` samples, under
/// `u = gain · y_m + d` with a dither of `±amplitude`.
#[derive(Clone, Copy)]
struct Plant {
    a: &'static [f64],
    gain: f64,
    delay: usize,
    amplitude: f64,
}

/// One seeded run of `plant`, certified at `order`.
fn run(plant: Plant, order: usize, seed: u64) -> Tally {
    let Plant { a, gain, delay, amplitude } = plant;
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
    let step = (big * DT).exp();
    let regression = OrderNConfig::new(LoopModel::of_order(order).unwrap(), 1, 2000, 50);
    let cfg = OrderNCertificateConfig::new(regression, vec![gain], 0.05, 0.01);
    let mut cert = OrderNCertificate::new(cfg).unwrap();
    let mut rng = Rng(seed);
    let mut x = DVector::<f64>::zeros(n + 2);
    let mut dither = 0.1;
    let mut queue: VecDeque<f64> = std::iter::repeat_n(0.0, delay).collect();
    let mut tally = Tally::default();
    for k in 0..4000 {
        if k % 100 == 0 {
            dither = if rng.uniform() < 0.5 { -amplitude } else { amplitude };
        }
        let measured = x[0] + 0.01 * rng.normal();
        let input = gain * measured + dither;
        if let Some(look) = cert.push(k as f64 * DT, measured, &[input]).unwrap() {
            tally.looks += 1;
            tally.certified += usize::from(look.certified());
            tally.hidden +=
                usize::from(matches!(look.outcome, Err(NotCertified::HiddenDynamics { .. })));
        }
        queue.push_back(input);
        x[n] = queue.pop_front().unwrap_or(input);
        x[n + 1] = 1.0;
        x = &step * x;
    }
    tally
}

/// The tallies of the seeded runs `seeds`, summed, on two threads.
fn cell(plant: Plant, order: usize, seeds: std::ops::Range<u64>) -> Tally {
    let seeds: Vec<u64> = seeds.collect();
    let (left, right) = seeds.split_at(seeds.len() / 2);
    let sum = |part: &[u64]| {
        part.iter().map(|&s| run(plant, order, s)).fold(Tally::default(), |t, r| Tally {
            looks: t.looks + r.looks,
            certified: t.certified + r.certified,
            hidden: t.hidden + r.hidden,
        })
    };
    let (l, r) = std::thread::scope(|s| {
        let l = s.spawn(|| sum(left));
        (l.join().unwrap(), sum(right))
    });
    Tally {
        looks: l.looks + r.looks,
        certified: l.certified + r.certified,
        hidden: l.hidden + r.hidden,
    }
}

/// `(s + 0.25)(s + 0.95)` closed (`K = 0.7625`): five times the margin, order 2 holds.
const HOLDS: Plant = Plant { a: &[1.2, 1.0], gain: 0.7625, delay: 0, amplitude: 0.1 };

#[test]
fn the_guard_rarely_closes_a_loop_the_model_holds() {
    let t = cell(HOLDS, 2, 1000..1040);
    eprintln!("order 2 holds, 5× the margin: {t:?}");
    assert!(t.hidden * 100 <= 2 * t.looks, "{t:?}");
    assert!(t.certified * 100 >= 95 * t.looks, "{t:?}");
}

#[test]
fn beyond_the_order_the_guard_refuses_most_looks() {
    // A slow state behind a fast one read through a sensor lag: (s + 0.045)(s + 2)(s + 5)
    // open loop, margin 0.045, below the margin; order 2 cannot hold it.
    let lagged = Plant { a: &[7.045, 10.315, 0.45], gain: 0.0, delay: 0, amplitude: 1.0 };
    // A complex pair −0.045 ± 1.41 j behind a transport delay of 10 samples.
    let delayed = Plant { a: &[0.09, 1.0], gain: -1.0, delay: 10, amplitude: 1.0 };
    for (name, plant, seeds) in [("lagged", lagged, 100..120), ("delayed", delayed, 300..320)] {
        let t = cell(plant, 2, seeds);
        eprintln!("{name}, order 2: {t:?}");
        assert_eq!(t.certified, 0, "{name}: {t:?}");
        assert!(t.hidden * 4 >= 3 * t.looks, "{name}: {t:?}");
    }
}
