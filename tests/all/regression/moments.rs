//! The windows' segment sums (`InstrumentedWindows::with_moments`) against a pass over the
//! blocks, the first-order fresh estimate against the coefficient pass, a restored state's
//! segment sums bit for bit, and the look's fused batched covariance against `set_batch` and a
//! second estimate, bit for bit.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::regression::{InstrumentedWindows, RateMap, Solve, WindowEstimate};

/// A loop-like column stream for `p` outputs and `m` inputs, the inputs AR(1) so that the
/// lagged regressors are relevant instruments.
struct Stream {
    rng: ChaCha8Rng,
    state: Vec<f64>,
    input: Vec<f64>,
    p: usize,
    m: usize,
    offset: f64,
}

impl Stream {
    fn new(p: usize, m: usize, offset: f64, seed: u64) -> Self {
        let rng = ChaCha8Rng::seed_from_u64(seed);
        Self { rng, state: vec![0.0; p], input: vec![0.0; m], p, m, offset }
    }

    fn next(&mut self) -> (Vec<f64>, Vec<f64>) {
        for v in &mut self.input {
            *v = 0.9 * *v + self.rng.random::<f64>() - 0.5;
        }
        let u = self.input.clone();
        let mut z: Vec<f64> = self.state.iter().map(|s| s + self.offset).collect();
        z.extend(&u);
        let dy: Vec<f64> = (0..self.p)
            .map(|i| {
                -0.3 * self.state[i] + 0.4 * u[i % self.m] + 0.1 * (self.rng.random::<f64>() - 0.5)
            })
            .collect();
        for (s, v) in self.state.iter_mut().zip(&dy) {
            *s += v;
        }
        (z, dy)
    }
}

fn direction(p: usize, d: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let mut t = vec![0.0; d * p];
    for j in 0..p {
        t[j * p + j] = 1.0;
    }
    for v in &mut t[p * p..] {
        *v = rng.random::<f64>() - 0.5;
    }
    t
}

/// At every block of a stream that wraps the ring many times (and after a reset), every
/// window's sums and every older part's (`skip` from 0 to the whole window) from the epoch
/// sums equal a pass over the blocks to `10⁻¹²` of the sums' magnitude, at an operating
/// point far from zero too.
#[test]
fn epoch_sums_equal_a_pass_over_the_blocks_through_wraps_and_resets() {
    for (p, m, offset) in [(1, 2, 0.0), (1, 2, 1e3), (2, 1, 5.0)] {
        let windows = [24usize, 48, 96];
        let mut win =
            InstrumentedWindows::new(p, m, 3, 1, 1, &windows).expect("valid").with_moments();
        assert!(win.has_moments());
        let mut stream = Stream::new(p, m, offset, 3);
        let stride = (p + m) * (p + m) * 2 + p * (p + m);
        let (mut direct, mut epoch) = (vec![0.0; stride], vec![0.0; stride]);
        let mut compared = 0;
        for step in 0..2000 {
            if step == 1100 {
                win.reset();
            }
            let (z, dy) = stream.next();
            if !win.push_column(&z, &dy) {
                continue;
            }
            for w in 0..windows.len() {
                win.window_sums(w, &mut direct);
                assert!(win.span_sums_from_moments(w, 0, &mut epoch));
                let scale = direct.iter().fold(0.0f64, |a, v| a.max(v.abs())).max(1e-300);
                for (a, b) in direct.iter().zip(&epoch) {
                    assert!((a - b).abs() <= 1e-12 * scale, "{p} {m} {offset} w {w}: {a} {b}");
                }
                compared += 1;
            }
        }
        assert!(compared > 1000, "{compared}");
    }
}

/// The fresh estimate (first-order, from the segment sums) against the coefficient pass over
/// the blocks (`estimate_coefficients_first_order`): for `p = 1` the score variance in the
/// direction `T` is `Tᵀ Ω_θ T` and the effective number of blocks is the same sum, both to
/// `10⁻⁶` relative (quadratic forms whose terms cancel), and `Θ̂` agrees to `10⁻⁹`.
#[test]
fn the_fresh_estimate_equals_the_first_order_pass() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let (p, m) = (1, 2);
    let d = p + m;
    let windows = [90usize, 180, 360];
    let mut win = InstrumentedWindows::new(p, m, 3, 1, 1, &windows).expect("valid").with_moments();
    let t = direction(p, d, &mut rng);
    let mut stream = Stream::new(p, m, 0.0, 9);
    let (mut fresh, mut pass) = (WindowEstimate::new(p, m, 1), WindowEstimate::new(p, m, 1));
    let mut cov = vec![0.0; d * d];
    let mut compared = 0;
    for _ in 0..3000 {
        let (z, dy) = stream.next();
        if !win.push_column(&z, &dy) {
            continue;
        }
        for w in 0..windows.len() {
            win.fresh_estimate(
                w,
                0,
                Solve { ridge: 1e-12, rate: RateMap::SymmetricPart(&t), min_pivot_ratio: 1e-12 },
                &mut fresh,
            );
            let ready = win.estimate_coefficients_first_order(
                w,
                Solve { ridge: 1e-12, rate: RateMap::SymmetricPart(&t), min_pivot_ratio: 1e-12 },
                &mut pass,
                &mut cov,
            );
            assert_eq!(fresh.ready, ready, "window {w}");
            if !ready {
                continue;
            }
            let quad: f64 =
                (0..d).map(|a| (0..d).map(|b| t[a] * cov[a * d + b] * t[b]).sum::<f64>()).sum();
            let rel = |a: f64, b: f64| (a - b).abs() / a.abs().max(b.abs());
            // A quadratic form of moments differenced over a quarter of the ring: its
            // rounding is relative to its terms' magnitude, which on a window that barely
            // identifies the rate is many times its value (the estimate refuses below 10⁻⁹).
            assert!(rel(fresh.score_cov[0], quad) < 1e-6, "{} {quad}", fresh.score_cov[0]);
            assert!(rel(fresh.effective_blocks, pass.effective_blocks) < 1e-6);
            for (a, b) in fresh.theta.iter().zip(&pass.theta) {
                assert!(rel(*a, *b) < 1e-9, "{a} {b}");
            }
            assert_eq!(fresh.batches, pass.batches);
            compared += 1;
        }
    }
    assert!(compared > 600, "{compared}");
}

/// A state serialised and read back, its segment sums rebuilt from the block ring
/// (`keep_moments`), gives every fresh estimate bit for bit as the state that kept them all
/// along, at every block after the restore (the restore falls in the middle of an epoch).
#[test]
fn rebuilt_epoch_sums_are_the_same_bits() {
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let (p, m) = (1, 2);
    let windows = [24usize, 48, 96];
    let mut kept = InstrumentedWindows::new(p, m, 3, 1, 1, &windows).expect("valid").with_moments();
    let t = direction(p, p + m, &mut rng);
    let mut stream = Stream::new(p, m, 0.5, 4);
    for _ in 0..1234 {
        let (z, dy) = stream.next();
        kept.push_column(&z, &dy);
    }
    let json = serde_json::to_string(&kept).expect("serialise");
    let mut restored: InstrumentedWindows = serde_json::from_str(&json).expect("read back");
    assert!(!restored.has_moments(), "the segment sums are not serialised");
    restored.keep_moments();
    assert_eq!(restored, kept);
    let (mut a, mut b) = (WindowEstimate::new(p, m, 1), WindowEstimate::new(p, m, 1));
    for _ in 0..800 {
        let (z, dy) = stream.next();
        assert_eq!(kept.push_column(&z, &dy), restored.push_column(&z, &dy));
        for w in 0..windows.len() {
            for skip in [0, 4] {
                kept.fresh_estimate(
                    w,
                    skip,
                    Solve {
                        ridge: 1e-12,
                        rate: RateMap::SymmetricPart(&t),
                        min_pivot_ratio: 1e-12,
                    },
                    &mut a,
                );
                restored.fresh_estimate(
                    w,
                    skip,
                    Solve {
                        ridge: 1e-12,
                        rate: RateMap::SymmetricPart(&t),
                        min_pivot_ratio: 1e-12,
                    },
                    &mut b,
                );
                assert_eq!(a, b);
            }
        }
    }
}

/// The look's fused pass (`estimate_batched`) gives the estimate of `estimate` and, in
/// `batched`, the covariance, effective number and count of batches of `set_batch(b)` then
/// `estimate`, bit for bit.
#[test]
fn the_batched_covariance_of_the_fused_pass_equals_a_second_estimate() {
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    for (p, m) in [(1, 2), (2, 1)] {
        let windows = [30usize, 60, 120];
        let mut win = InstrumentedWindows::new(p, m, 2, 1, 1, &windows).expect("valid");
        let t = direction(p, p + m, &mut rng);
        let mut stream = Stream::new(p, m, 1.0, 6);
        let (mut fused, mut one, mut two) = (
            WindowEstimate::new(p, m, 1),
            WindowEstimate::new(p, m, 1),
            WindowEstimate::new(p, m, 1),
        );
        let mut compared = 0;
        for _ in 0..900 {
            let (z, dy) = stream.next();
            if !win.push_column(&z, &dy) {
                continue;
            }
            for w in 0..windows.len() {
                for b in [2, 3] {
                    win.estimate_batched(
                        w,
                        b,
                        Solve {
                            ridge: 1e-12,
                            rate: RateMap::SymmetricPart(&t),
                            min_pivot_ratio: 1e-12,
                        },
                        &mut fused,
                    );
                    win.estimate(
                        w,
                        Solve {
                            ridge: 1e-12,
                            rate: RateMap::SymmetricPart(&t),
                            min_pivot_ratio: 1e-12,
                        },
                        &mut one,
                    );
                    win.set_batch(b);
                    win.estimate(
                        w,
                        Solve {
                            ridge: 1e-12,
                            rate: RateMap::SymmetricPart(&t),
                            min_pivot_ratio: 1e-12,
                        },
                        &mut two,
                    );
                    win.set_batch(1);
                    assert_eq!(fused.ready, one.ready);
                    assert_eq!(fused.theta, one.theta);
                    assert_eq!(fused.score_cov, one.score_cov);
                    assert_eq!(fused.effective_blocks.to_bits(), one.effective_blocks.to_bits());
                    assert_eq!(fused.batched.ready, two.ready, "{p} {m} w {w} b {b}");
                    if two.ready {
                        assert_eq!(fused.batched.score_cov, two.score_cov);
                        assert_eq!(
                            fused.batched.effective_blocks.to_bits(),
                            two.effective_blocks.to_bits()
                        );
                        assert_eq!(fused.batched.batches, two.batches);
                        compared += 1;
                    }
                }
            }
        }
        assert!(compared > 300, "{compared}");
    }
}
