//! Oracles for the exact test: the first order's closed form, the second order's closed form,
//! and brute force (members of the ellipsoid, their roots by a dense eigensolver).

use nalgebra::DMatrix;
use rand::{Rng as _, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::*;

/// A random stable centre (the polynomial of random stable roots) and a random positive
/// definite covariance of scale `size`, `n × n`.
fn random_ellipsoid(n: usize, size: f64, rng: &mut ChaCha8Rng) -> (Vec<f64>, Vec<f64>) {
    // Roots: a real one and, for n >= 2, a complex pair or two reals.
    let mut poly = vec![1.0];
    let push_real = |poly: &mut Vec<f64>, r: f64| {
        let mut next = vec![0.0; poly.len() + 1];
        for (i, c) in poly.iter().enumerate() {
            next[i] += c;
            next[i + 1] += c * r;
        }
        *poly = next;
    };
    let mut k = 0;
    while k < n {
        if n - k >= 2 && rng.random::<f64>() < 0.5 {
            let (re, im) = (0.2 + 2.0 * rng.random::<f64>(), 0.1 + 2.0 * rng.random::<f64>());
            // s² + 2 re s + re² + im².
            let quad = [1.0, 2.0 * re, re * re + im * im];
            let mut next = vec![0.0; poly.len() + 2];
            for (i, c) in poly.iter().enumerate() {
                for (j, q) in quad.iter().enumerate() {
                    next[i + j] += c * q;
                }
            }
            poly = next;
            k += 2;
        } else {
            push_real(&mut poly, 0.1 + 2.0 * rng.random::<f64>());
            k += 1;
        }
    }
    let centre = poly[1..].to_vec();
    let l: Vec<f64> = (0..n * n)
        .map(|_| size * Distribution::<f64>::sample(&StandardNormal, &mut *rng))
        .collect();
    let mut cov = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            cov[i * n + j] = (0..n).map(|k| l[i * n + k] * l[j * n + k]).sum::<f64>();
        }
        cov[i * n + i] += size * size * 0.05;
    }
    (centre, cov)
}

/// `−max Re` of the roots of `sⁿ + Σ β_i sⁿ⁻ⁱ` (the companion matrix's eigenvalues).
fn margin_of(beta: &[f64]) -> f64 {
    let n = beta.len();
    let mut c = DMatrix::<f64>::zeros(n, n);
    for i in 0..n {
        c[(0, i)] = -beta[i];
        if i + 1 < n {
            c[(i + 1, i)] = 1.0;
        }
    }
    -c.complex_eigenvalues().iter().map(|z| z.re).fold(f64::NEG_INFINITY, f64::max)
}

/// The smallest margin over sampled members: the boundary (and inside) of the ellipsoid.
fn sampled_margin(
    centre: &[f64],
    cov: &[f64],
    r2: f64,
    samples: usize,
    rng: &mut ChaCha8Rng,
) -> f64 {
    let n = centre.len();
    let l = DMatrix::from_row_slice(n, n, cov).cholesky().expect("positive definite").l();
    let mut worst = margin_of(centre);
    for k in 0..samples {
        let u: Vec<f64> =
            (0..n).map(|_| Distribution::<f64>::sample(&StandardNormal, &mut *rng)).collect();
        let norm = u.iter().map(|x| x * x).sum::<f64>().sqrt();
        let depth = if k % 5 == 0 { rng.random::<f64>() } else { 1.0 };
        let beta: Vec<f64> = (0..n)
            .map(|i| {
                centre[i] + r2.sqrt() * depth * (0..n).map(|j| l[(i, j)] * u[j] / norm).sum::<f64>()
            })
            .collect();
        worst = worst.min(margin_of(&beta));
    }
    worst
}

/// For n = 1 the certificate is the first-order rate minus its radius: `β̂ − r √Σ`.
#[test]
fn at_first_order_the_margin_is_the_rate_minus_the_radius() {
    for (beta, var, r2) in [(1.5, 0.04, 9.0), (0.3, 1e-4, 14.9), (-0.2, 0.01, 4.0)] {
        let e = Ellipsoid { centre: &[beta], covariance: &[var], radius2: r2 };
        let want = beta - (r2 * var).sqrt();
        let got = robust_margin(&e, 1e-12).expect("a margin");
        assert!((got - want).abs() < 1e-11, "{got} {want}");
        assert!(got <= want);
        assert!(robustly_stable(&e, want - 1e-9) && !robustly_stable(&e, want + 1e-9));
    }
}

/// The second order's closed form: `s² + c_1 s + c_2` is Hurwitz iff `c_1, c_2 > 0`, and
/// both are affine in `β`, so the family is robust at `α` iff
/// `β̂_1 − 2α > r √Σ_11` and `β̂_2 − α β̂_1 + α² > r √(vᵀ Σ v)`, `v = (−α, 1)`.
fn closed_form_2(beta: &[f64], cov: &[f64], r2: f64, alpha: f64) -> (bool, f64) {
    let r = r2.sqrt();
    let s1 = beta[0] - 2.0 * alpha - r * cov[0].sqrt();
    let v = [-alpha, 1.0];
    let vsv = v[0] * v[0] * cov[0] + 2.0 * v[0] * v[1] * cov[1] + v[1] * v[1] * cov[3];
    let s2 = beta[1] - alpha * beta[0] + alpha * alpha - r * vsv.sqrt();
    (s1 > 0.0 && s2 > 0.0, s1.min(s2))
}

/// The exact test agrees with the second order's closed form at random `α` away from its
/// boundary, and the two margins agree to the bisection's tolerance, over 150 random
/// ellipsoids.
#[test]
fn at_second_order_the_test_is_the_closed_form() {
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let mut compared = 0;
    for _ in 0..150 {
        let (centre, cov) = random_ellipsoid(2, 0.05 + 0.3 * rng.random::<f64>(), &mut rng);
        let r2 = 1.0 + 14.0 * rng.random::<f64>();
        let e = Ellipsoid { centre: &centre, covariance: &cov, radius2: r2 };
        for _ in 0..5 {
            let alpha = -1.0 + 3.0 * rng.random::<f64>();
            let (want, slack) = closed_form_2(&centre, &cov, r2, alpha);
            if slack.abs() > 1e-9 {
                assert_eq!(robustly_stable(&e, alpha), want, "{centre:?} {cov:?} {r2} {alpha}");
                compared += 1;
            }
        }
        // The closed form's margin by its own bisection.
        let (mut lo, mut hi) = (-50.0, 50.0);
        if !closed_form_2(&centre, &cov, r2, lo).0 {
            assert_eq!(robust_margin(&e, 1e-12), None);
            continue;
        }
        while hi - lo > 1e-13 {
            let mid = 0.5 * (lo + hi);
            if closed_form_2(&centre, &cov, r2, mid).0 { lo = mid } else { hi = mid }
        }
        let got = robust_margin(&e, 1e-12).expect("a margin");
        assert!((got - lo).abs() < 1e-9, "{got} {lo}");
        // The margin passes the exact test and a step above it does not, whatever the
        // floating-point guide of the bisection said.
        assert!(robustly_stable(&e, got) && !robustly_stable(&e, got + 2e-12), "{got}");
    }
    assert!(compared > 500, "{compared}");
}

/// Brute force at orders 2 and 3: no sampled member of the ellipsoid has a margin below the
/// certified one (validity), and the smallest sampled margin is close above it (tightness).
#[test]
fn no_member_of_the_ellipsoid_is_slower_than_the_certified_margin() {
    let mut rng = ChaCha8Rng::seed_from_u64(29);
    for n in [2usize, 3] {
        for case in 0..12 {
            let (centre, cov) = random_ellipsoid(n, 0.02 + 0.1 * rng.random::<f64>(), &mut rng);
            let r2 = 2.0 + 10.0 * rng.random::<f64>();
            let e = Ellipsoid { centre: &centre, covariance: &cov, radius2: r2 };
            let Some(certified) = robust_margin(&e, 1e-12) else {
                continue;
            };
            let sampled = sampled_margin(&centre, &cov, r2, 20_000, &mut rng);
            assert!(certified <= sampled + 1e-9, "n {n} case {case}: {certified} > {sampled}");
            assert!(sampled - certified < 5e-3, "n {n} case {case}: {certified} vs {sampled}");
        }
    }
}

/// The test is monotone in `α` (what the bisection needs), and the centre's own margin bounds
/// every certified one.
#[test]
fn the_test_is_monotone_and_below_the_centres_margin() {
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    for n in 1..=3 {
        for _ in 0..15 {
            let (centre, cov) = random_ellipsoid(n, 0.1 * rng.random::<f64>() + 1e-3, &mut rng);
            let e = Ellipsoid { centre: &centre, covariance: &cov, radius2: 9.0 };
            let passes: Vec<bool> =
                (0..60).map(|i| robustly_stable(&e, -2.0 + 0.08 * f64::from(i))).collect();
            let first_fail = passes.iter().position(|p| !p).unwrap_or(passes.len());
            assert!(passes[first_fail..].iter().all(|p| !p), "n {n}: {passes:?}");
            if let Some(m) = robust_margin(&e, 1e-12) {
                assert!(m <= margin_of(&centre) + 1e-9, "n {n}");
            }
        }
    }
}

/// Ill-formed ellipsoids are refused: an order outside 1..=3, a non-finite value, a negative
/// radius; a point ellipsoid (Σ = 0) has a value set that is a curve, which the test reads as
/// not excluded (conservative), so no margin is stated.
#[test]
fn ill_formed_ellipsoids_are_refused() {
    let cov4 = vec![0.0; 16];
    let e = Ellipsoid { centre: &[1.0, 2.0, 3.0, 4.0], covariance: &cov4, radius2: 1.0 };
    assert_eq!(robust_margin(&e, 1e-9), None);
    assert!(!robustly_stable(&e, 0.0));
    let e = Ellipsoid { centre: &[], covariance: &[], radius2: 1.0 };
    assert_eq!(robust_margin(&e, 1e-9), None);
    let e = Ellipsoid { centre: &[1.0, f64::NAN], covariance: &[1.0, 0.0, 0.0, 1.0], radius2: 1.0 };
    assert!(!robustly_stable(&e, 0.0));
    let e = Ellipsoid { centre: &[3.0, 2.0], covariance: &[0.01, 0.0, 0.0, 0.01], radius2: -1.0 };
    assert!(!robustly_stable(&e, 0.0));
    let e = Ellipsoid { centre: &[3.0, 2.0], covariance: &[0.01, 0.0, 0.0], radius2: 1.0 };
    assert_eq!(robust_margin(&e, 1e-9), None);
    let e = Ellipsoid { centre: &[3.0, 2.0], covariance: &[0.0; 4], radius2: 1.0 };
    assert_eq!(robust_margin(&e, 1e-9), None);
    // An unstable centre: no margin above the lower bracket fails, but the margin is negative.
    let e = Ellipsoid { centre: &[-1.0, 2.0], covariance: &[1e-4, 0.0, 0.0, 1e-4], radius2: 1.0 };
    let m = robust_margin(&e, 1e-12).expect("a (negative) margin");
    assert!(m < 0.0 && m <= margin_of(&[-1.0, 2.0]));
}

/// The floating-point filter answers only as the rational arithmetic does: over random
/// ellipsoids of orders 1 to 3 and `α` spread over the bracket, within `1e-9` of the margin and
/// at the certified margin's neighbouring floats (where the sign of some value is at the
/// floats' resolution), every run the balls decide gives the rational test's answer. The
/// filter decides almost every `α` away from the margin (what makes it worth having) and leaves
/// to the rationals some at it.
#[test]
fn the_filter_answers_as_the_rational_test_or_defers() {
    let mut rng = ChaCha8Rng::seed_from_u64(43);
    let (mut far, mut far_decided, mut near, mut near_decided) = (0, 0, 0, 0);
    for n in 1..=3 {
        for _ in 0..40 {
            let (centre, cov) = random_ellipsoid(n, 0.01 + 0.3 * rng.random::<f64>(), &mut rng);
            let r2 = 1.0 + 20.0 * rng.random::<f64>();
            let e = Ellipsoid { centre: &centre, covariance: &cov, radius2: r2 };
            let margin = robust_margin(&e, 1e-12);
            let mut alphas: Vec<(f64, bool)> =
                (0..8).map(|_| (-2.0 + 5.0 * rng.random::<f64>(), false)).collect();
            if let Some(m) = margin {
                let mut up = m;
                let mut down = m;
                alphas.push((m, true));
                for _ in 0..4 {
                    (up, down) = (up.next_up(), down.next_down());
                    alphas.extend([(up, true), (down, true)]);
                }
                alphas.extend([(m + 1e-9, true), (m - 1e-9, true)]);
            }
            for (alpha, at_margin) in alphas {
                let exact = stable_at::<BigRational>(&e, alpha);
                let filtered = ball::decided(|| stable_at::<Ball>(&e, alpha));
                if let Some(answer) = filtered {
                    assert_eq!(answer, exact, "n {n} {centre:?} {cov:?} {r2} at {alpha}");
                }
                if at_margin {
                    (near, near_decided) =
                        (near + 1, near_decided + usize::from(filtered.is_some()));
                } else {
                    (far, far_decided) = (far + 1, far_decided + usize::from(filtered.is_some()));
                }
            }
        }
    }
    assert!(far_decided * 100 >= far * 99, "{far_decided} of {far}");
    assert!(near_decided < near, "{near_decided} of {near}");
}

/// At the boundary itself: `β̂ = 1.5`, `Σ = 0.25`, `r² = 4` at first order is robust exactly
/// below `α = 0.5` (`β̂ − α > r √Σ = 1`), and not at it; the float just below `0.5` passes
/// although its margin over the boundary (`2⁻⁵⁴`) is below the floats' resolution of the
/// squared comparison, so the filter defers it to the rationals.
#[test]
fn the_boundary_float_is_decided_exactly() {
    let e = Ellipsoid { centre: &[1.5], covariance: &[0.25], radius2: 4.0 };
    assert!(!robustly_stable(&e, 0.5));
    assert!(robustly_stable(&e, 0.5f64.next_down()));
    assert!(!robustly_stable(&e, 0.5f64.next_up()));
    assert_eq!(ball::decided(|| stable_at::<Ball>(&e, 0.5f64.next_down())), None);
}
