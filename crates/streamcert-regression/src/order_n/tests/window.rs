//! The window's looks from kept rows and units against the batch fits of the window's samples,
//! and the same bits whatever was kept.

use rand::{Rng as _, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::super::*;
use super::{prbs, simulate};

/// An equally spaced closed-loop record at 100 Hz with sensor noise and an offset.
fn record(n: usize, len: usize, seed: u64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    record_with(n, len, seed, 0.2)
}

/// The same with the output drifting by `drift · sin(t / 10 s)`.
fn record_with(n: usize, len: usize, seed: u64, drift: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let a: &[f64] = if n == 2 { &[1.2, 1.0] } else { &[3.5, 3.5, 1.0] };
    let b: &[f64] = if n == 2 { &[0.0, 1.0] } else { &[0.0, 0.5, 2.0] };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let t: Vec<f64> = (0..len).map(|k| k as f64 * 0.01).collect();
    let u = prbs(&t, 0.7, &mut rng);
    let mut y = simulate(a, b, 0.1, &t, &u);
    for (k, v) in y.iter_mut().enumerate() {
        // A drift of the output, so that the window's origin moves between looks.
        *v += 0.02 * (rng.random::<f64>() - 0.5) + 5.0 + drift * (k as f64 * 1e-3).sin();
    }
    (t, y, u)
}

fn close(a: f64, b: f64, tol: f64, scale: f64) -> bool {
    (a - b).abs() <= tol * scale
}

/// The looks a certifier makes: every `period` samples once `min_rows` rows are in, on the
/// window's last `min(M, rows)` rows.
fn looks(
    len: usize,
    span: usize,
    min_rows: usize,
    window: usize,
    period: usize,
) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut k = min_rows + span - 1;
    while k < len {
        let rows = (k + 1 - span).min(window);
        out.push((k + 1 - (rows + span), k + 1));
        k += period;
    }
    out
}

/// At every look of a sliding window (growing, then full; the origin drifting), the fit, the
/// past-row test and the curvature test from kept rows and units are the batch ones over the
/// window's samples: the same `θ̂` to `10⁻⁸`, covariances to `10⁻⁶` of their scale.
#[test]
fn the_window_looks_are_the_batch_fits_of_the_window() {
    for n in [2, 3] {
        let (t, y, u) = record(n, 4200, 40 + n as u64);
        let cfg = OrderNConfig::new(LoopModel::of_order(n).unwrap(), 1, 1500, 12);
        let span = cfg.span();
        let mut window = OrderNWindow::new(&cfg).unwrap();
        let mut checked = 0;
        for (s, e) in looks(t.len(), span, 700, 1500, 170) {
            let mut look = window.prepare(s as u64, &t[s..e], &y[s..e], &u[s..e]).unwrap();
            let record = OrderNRecord::new(&cfg, &t[s..e], &y[s..e], &u[s..e]).unwrap();
            let all = 0..record.rows();
            let (fast, slow) = (look.fit().unwrap(), record.fit(all.clone()).unwrap());
            assert_eq!(fast.rows(), slow.rows());
            let d = slow.theta().len();
            for i in 0..d {
                let (a, b) = (fast.theta()[i], slow.theta()[i]);
                assert!(close(a, b, 1e-8, 1.0 + b.abs()), "n {n} look {s}: θ_{i} {a} {b}");
                for j in 0..d {
                    let scale =
                        (slow.covariance()[i * d + i] * slow.covariance()[j * d + j]).sqrt();
                    let (a, b) = (fast.covariance()[i * d + j], slow.covariance()[i * d + j]);
                    assert!(close(a, b, 1e-6, scale), "n {n} look {s}: V_{i}{j} {a} {b}");
                }
            }
            let noise = slow.sensor_variance() + slow.equation_variance();
            assert!(close(fast.sensor_variance(), slow.sensor_variance(), 1e-6, noise));
            assert!(close(fast.equation_variance(), slow.equation_variance(), 1e-6, noise));
            let pairs = [
                (look.past_row_test().unwrap(), record.past_row_test(all.clone()).unwrap()),
                (look.curvature_test().unwrap(), record.curvature_test(all).unwrap()),
            ];
            for (fast, slow) in pairs {
                assert_eq!(fast.rows, slow.rows);
                let q = slow.coefficients.len();
                for i in 0..q {
                    let sd = slow.covariance[i * q + i].sqrt();
                    let (a, b) = (fast.coefficients[i], slow.coefficients[i]);
                    assert!(close(a, b, 1e-6, sd), "n {n} look {s}: γ_{i} {a} {b}");
                }
                let (a, b) = (fast.statistic(), slow.statistic());
                assert!(close(a, b, 1e-6, 1.0 + b), "n {n} look {s}: W {a} {b}");
            }
            checked += 1;
        }
        assert!(checked >= 15, "{checked}");
    }
}

/// A look gives the same bits from a window that kept its rows and units over every earlier
/// look and from a new one that sees this look's samples only (as after a restore).
#[test]
fn a_look_does_not_depend_on_what_was_kept() {
    let n = 2;
    let (t, y, u) = record(n, 3600, 7);
    let cfg = OrderNConfig::new(LoopModel::of_order(n).unwrap(), 1, 1200, 15);
    let span = cfg.span();
    let mut kept = OrderNWindow::new(&cfg).unwrap();
    for (s, e) in looks(t.len(), span, 650, 1200, 150) {
        let mut fresh = OrderNWindow::new(&cfg).unwrap();
        let mut a = kept.prepare(s as u64, &t[s..e], &y[s..e], &u[s..e]).unwrap();
        let mut b = fresh.prepare(s as u64, &t[s..e], &y[s..e], &u[s..e]).unwrap();
        // The tests first on one side, the fit first on the other.
        let (pa, ca, fa) =
            (a.past_row_test().unwrap(), a.curvature_test().unwrap(), a.fit().unwrap());
        let (fb, cb, pb) =
            (b.fit().unwrap(), b.curvature_test().unwrap(), b.past_row_test().unwrap());
        assert_eq!(fa, fb, "look {s}");
        assert_eq!(pa, pb, "look {s}");
        assert_eq!(ca, cb, "look {s}");
    }
}

/// A window whose rows are not all equally spaced alike is not taken: the caller fits the
/// samples.
#[test]
fn an_unequally_spaced_window_is_left_to_the_batch_fit() {
    let (mut t, y, u) = record(2, 1500, 3);
    let cfg = OrderNConfig::new(LoopModel::of_order(2).unwrap(), 1, 1000, 10);
    let mut window = OrderNWindow::new(&cfg).unwrap();
    assert!(window.prepare(0, &t, &y, &u).is_some());
    // One late sample.
    for v in &mut t[900..] {
        *v += 0.003;
    }
    let mut window = OrderNWindow::new(&cfg).unwrap();
    assert!(window.prepare(0, &t, &y, &u).is_none());
    // A window past it is taken again.
    assert!(window.prepare(901, &t[901..], &y[901..], &u[901..]).is_some());
    // Too few samples for a row.
    assert!(window.prepare(0, &t[..20], &y[..20], &u[..20]).is_none());
}

/// The looks agree with the batch fits with two inputs (each input's `φ^u_n` moved with its
/// own origin, the second input offset by 3) and an output drifting by `50 sin(t / 10 s)`, so
/// that each unit's square and cube are moved across a wide range to the window's origin.
#[test]
fn the_window_looks_agree_with_two_inputs_and_a_far_drift() {
    let n = 2;
    let (t, y, u1) = record_with(n, 3600, 9, 50.0);
    let mut rng = ChaCha8Rng::seed_from_u64(10);
    let u2 = prbs(&t, 0.4, &mut rng);
    let u: Vec<f64> = u1.iter().zip(&u2).flat_map(|(a, b)| [*a, 3.0 + *b]).collect();
    let cfg = OrderNConfig::new(LoopModel::of_order(n).unwrap(), 2, 1500, 12);
    let span = cfg.span();
    let mut window = OrderNWindow::new(&cfg).unwrap();
    let mut checked = 0;
    for (s, e) in looks(t.len(), span, 900, 1500, 170) {
        let mut look = window.prepare(s as u64, &t[s..e], &y[s..e], &u[2 * s..2 * e]).unwrap();
        let record = OrderNRecord::new(&cfg, &t[s..e], &y[s..e], &u[2 * s..2 * e]).unwrap();
        let all = 0..record.rows();
        let (fast, slow) = (look.fit().unwrap(), record.fit(all.clone()).unwrap());
        let d = slow.theta().len();
        for i in 0..d {
            let (a, b) = (fast.theta()[i], slow.theta()[i]);
            assert!(close(a, b, 1e-7, 1.0 + b.abs()), "look {s}: θ_{i} {a} {b}");
            let scale = slow.covariance()[i * d + i];
            let (a, b) = (fast.covariance()[i * d + i], scale);
            assert!(close(a, b, 1e-5, scale), "look {s}: V_{i}{i} {a} {b}");
        }
        let (fast, slow) = (look.curvature_test().unwrap(), record.curvature_test(all).unwrap());
        let (a, b) = (fast.statistic(), slow.statistic());
        assert!(close(a, b, 1e-5, 1.0 + b), "look {s}: W {a} {b}");
        checked += 1;
    }
    assert!(checked >= 10, "{checked}");
}
