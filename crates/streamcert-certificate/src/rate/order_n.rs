//! The rate of a closed loop of order `n` over its coefficients' confidence ellipsoid: the
//! largest margin `α` such that every coefficient vector in the ellipsoid gives a
//! characteristic polynomial whose roots all have real part below `−α`.
//!
//! Under `u = K y` a plant of order `n` has the closed-loop polynomial
//! `p(s; β) = sⁿ + β_1 sⁿ⁻¹ + … + β_n`, `β = a − K b`, affine in the coefficients. Given the
//! ellipsoid `E = {β : (β − β̂)ᵀ Σ⁻¹ (β − β̂) <= r²}`, the shifted polynomial
//! `q(s; β) = p(s − α; β)` is affine in `β`, monic, continuous in `β`, and `E` is connected,
//! so by the zero exclusion principle (Barmish 1994, ch. 7) every member is Hurwitz iff one
//! is and `0 ∉ q(jω; E)` for every `ω >= 0`. The test at `α` ([`robustly_stable`]):
//!
//! 1. the centre `q(s; β̂)` is Hurwitz (Routh: `c_1 > 0`; `c_1, c_2 > 0`; or
//!    `c_1, c_2, c_3 > 0, c_1 c_2 > c_3`);
//! 2. at `ω = 0` the value set is the interval `m_0 ± r √(a_0ᵀ Σ a_0)` with
//!    `a_0 = ((−α)ⁿ⁻¹, …, 1)`: require `m_0 > r √(a_0ᵀ Σ a_0)`;
//! 3. for `ω > 0` the value set is the ellipse `m(ω) + A(ω)(β − β̂)`, `A` the real and
//!    imaginary parts of `((jω − α)ⁿ⁻¹, …, 1)`; `0` lies outside it iff
//!    `F(ω) = mᵀ adj(G) m − r² det G > 0` with `G = A Σ Aᵀ`. `F` is even with `F(0) = 0`, so
//!    `F(ω) = ω² F̃(ω²)`, `deg F̃ = 2n − 2`; the test is that `F̃` has no root in `(0, ∞)`,
//!    decided by Sturm's theorem.
//!
//! Every step is exact: the inputs (floats, so dyadic rationals) are carried in rational
//! arithmetic, so a tangency (a double root of `F̃`) counts as a root and a boundary touch is
//! rejected. The test is first carried in floating-point balls whose radii bound every
//! rounding error; where every sign it asks for is decided by its ball, that answer is the
//! rational arithmetic's, and only a run with an undecided sign (a tangency, a sign too close
//! to zero for the floats) is carried in rational arithmetic. A frequency grid would not be a test: nothing bounds what happens between its
//! points. For `n = 1`, `F̃ = Σ_11 > 0` and the test is `β̂_1 − α > r √Σ_11`: the first-order
//! rate minus its radius.
//!
//! The margin ([`robust_margin`]) is found by bisection, since the test is monotone in `α`
//! (robust at `α` implies robust at every smaller `α`): from `−R − 1` (robust: by Cauchy's
//! bound, every member's roots lie in `|s| < R = 1 + max_i (|β̂_i| + r √Σ_ii)`) to `R`, the
//! result the last `α` that passed, so never above the true margin.

use num_rational::BigRational;
use num_traits::{Num, Signed, Zero};

mod ball;
use ball::Ball;

/// A confidence ellipsoid of a closed loop's characteristic coefficients:
/// `{β : (β − β̂)ᵀ Σ⁻¹ (β − β̂) <= r²}`.
#[derive(Debug, Clone, Copy)]
pub struct Ellipsoid<'a> {
    /// `β̂ = (β̂_1..β̂_n)`, the coefficients of `sⁿ⁻¹ … s⁰`, `1 <= n <= 3`.
    pub centre: &'a [f64],
    /// `Σ`, `n × n` row-major, symmetric positive semi-definite.
    pub covariance: &'a [f64],
    /// `r² >= 0`.
    pub radius2: f64,
}

/// The numbers the test is carried in: rationals for the test itself, floats for the
/// bisection's guide.
trait Field: Clone + PartialOrd + Num + Signed {
    /// `x` (exactly, for the rationals: a finite float is a dyadic rational).
    fn of(x: f64) -> Self;
}

impl Field for f64 {
    fn of(x: f64) -> Self {
        x
    }
}

impl Field for Ball {
    fn of(x: f64) -> Self {
        Ball::exact(x)
    }
}

impl Field for BigRational {
    fn of(x: f64) -> Self {
        BigRational::from_float(x).unwrap_or_else(BigRational::zero)
    }
}

/// A polynomial, lowest power first.
type Poly<T> = Vec<T>;

fn add<T: Field>(a: &[T], b: &[T]) -> Poly<T> {
    let mut out = vec![T::zero(); a.len().max(b.len())];
    for (o, x) in out.iter_mut().zip(a) {
        *o = o.clone() + x.clone();
    }
    for (o, x) in out.iter_mut().zip(b) {
        *o = o.clone() + x.clone();
    }
    out
}

fn scale<T: Field>(a: &[T], k: &T) -> Poly<T> {
    a.iter().map(|x| x.clone() * k.clone()).collect()
}

fn mul<T: Field>(a: &[T], b: &[T]) -> Poly<T> {
    if a.is_empty() || b.is_empty() {
        return Vec::new();
    }
    let mut out = vec![T::zero(); a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        if x.is_zero() {
            continue;
        }
        for (j, y) in b.iter().enumerate() {
            out[i + j] = out[i + j].clone() + x.clone() * y.clone();
        }
    }
    out
}

/// Drop the zero leading coefficients.
fn trim<T: Field>(mut a: Poly<T>) -> Poly<T> {
    while a.last().is_some_and(Zero::is_zero) {
        a.pop();
    }
    a
}

/// `x^k`.
fn power<T: Field>(x: &T, k: usize) -> T {
    (0..k).fold(T::one(), |acc, _| acc * x.clone())
}

/// `(jω − α)^k` as its real and imaginary parts, polynomials in `ω`.
fn shifted_power<T: Field>(alpha: &T, k: usize) -> (Poly<T>, Poly<T>) {
    let (mut re, mut im) = (vec![T::zero(); k + 1], vec![T::zero(); k + 1]);
    let mut binom = 1u64;
    for l in 0..=k {
        // C(k, l) (jω)^l (−α)^{k−l}.
        let c = T::of(binom as f64) * power(&-alpha.clone(), k - l);
        match l % 4 {
            0 => re[l] = c,
            1 => im[l] = c,
            2 => re[l] = -c,
            _ => im[l] = -c,
        }
        binom = binom * (k - l) as u64 / (l + 1) as u64;
    }
    (re, im)
}

/// The coefficients `c_1..c_n` of the monic `q(s) = p(s − α; β)`, `p(s) = sⁿ + Σ β_i sⁿ⁻ⁱ`
/// (highest power first, without the leading one).
fn shifted_coefficients<T: Field>(beta: &[T], alpha: &T) -> Vec<T> {
    let n = beta.len();
    // (s − α)^k in s, lowest power first.
    let shifted = |k: usize| {
        let mut p: Poly<T> = vec![T::one()];
        for _ in 0..k {
            p = mul(&p, &[-alpha.clone(), T::one()]);
        }
        p
    };
    let mut q = shifted(n);
    for (i, b) in beta.iter().enumerate() {
        q = add(&q, &scale(&shifted(n - 1 - i), b));
    }
    (1..=n).map(|i| q[n - i].clone()).collect()
}

/// Routh–Hurwitz for a monic polynomial of degree `1..=3` with coefficients `c`.
fn hurwitz<T: Field>(c: &[T]) -> bool {
    match c {
        [c1] => c1.is_positive(),
        [c1, c2] => c1.is_positive() && c2.is_positive(),
        [c1, c2, c3] => {
            c1.is_positive()
                && c2.is_positive()
                && c3.is_positive()
                && c1.clone() * c2.clone() > c3.clone()
        }
        _ => false,
    }
}

/// Sign variations of a sequence, zeros skipped.
fn variations(signs: impl Iterator<Item = i8>) -> usize {
    let mut last = 0;
    let mut count = 0;
    for s in signs.filter(|s| *s != 0) {
        if last != 0 && s != last {
            count += 1;
        }
        last = s;
    }
    count
}

fn sign<T: Field>(x: &T) -> i8 {
    if x.is_positive() {
        1
    } else if x.is_negative() {
        -1
    } else {
        0
    }
}

/// The remainder of `a` divided by `b` (`b` trimmed; empty for an empty `b`).
fn remainder<T: Field>(a: &[T], b: &[T]) -> Poly<T> {
    let Some(lead) = b.last() else {
        return Vec::new();
    };
    let mut r = trim(a.to_vec());
    while r.len() >= b.len() && !r.is_empty() {
        let k = r.len() - b.len();
        let f = r[r.len() - 1].clone() / lead.clone();
        for (i, y) in b.iter().enumerate() {
            r[i + k] = r[i + k].clone() - f.clone() * y.clone();
        }
        r.pop();
        r = trim(r);
    }
    r
}

/// Whether `f` (trimmed, `f(0) != 0`) has a real root in `(0, ∞)`: by Sturm's theorem the
/// number of distinct roots in `(0, ∞)` is `V(0) − V(∞)`.
fn has_positive_root<T: Field>(f: &[T]) -> bool {
    let derivative: Poly<T> =
        f.iter().enumerate().skip(1).map(|(i, c)| c.clone() * T::of(i as f64)).collect();
    let mut chain = vec![f.to_vec(), trim(derivative)];
    while chain.last().is_some_and(|p| !p.is_empty()) {
        let n = chain.len();
        let r = remainder(&chain[n - 2], &chain[n - 1]);
        chain.push(r.into_iter().map(|c| -c).collect());
    }
    chain.pop();
    let at_zero = variations(chain.iter().map(|p| p.first().map_or(0, sign)));
    let at_infinity = variations(chain.iter().map(|p| p.last().map_or(0, sign)));
    at_zero > at_infinity
}

/// `xᵀ Σ y` for `n`-vectors.
fn quadratic<T: Field>(sigma: &[T], x: &[T], y: &[T], n: usize) -> T {
    let mut total = T::zero();
    for i in 0..n {
        for j in 0..n {
            total = total + x[i].clone() * sigma[i * n + j].clone() * y[j].clone();
        }
    }
    total
}

/// Whether the ellipsoid is one the test is defined for: order `1..=3`, an `n × n`
/// covariance, finite values, `r² >= 0`.
fn well_formed(e: &Ellipsoid<'_>) -> bool {
    let n = e.centre.len();
    (1..=3).contains(&n)
        && e.covariance.len() == n * n
        && e.radius2 >= 0.0
        && e.radius2.is_finite()
        && e.centre.iter().chain(e.covariance).all(|x| x.is_finite())
}

/// The test of the module docs at `alpha`, carried in `T`.
fn stable_at<T: Field>(e: &Ellipsoid<'_>, alpha: f64) -> bool {
    let n = e.centre.len();
    let beta: Vec<T> = e.centre.iter().map(|&x| T::of(x)).collect();
    let sigma: Vec<T> = e.covariance.iter().map(|&x| T::of(x)).collect();
    let (r2, a) = (T::of(e.radius2), T::of(alpha));
    // 1. The centre.
    if !hurwitz(&shifted_coefficients(&beta, &a)) {
        return false;
    }
    // 2. ω = 0: m_0 = q(0; β̂), a_0 = ((−α)ⁿ⁻¹, …, 1).
    let minus_a = -a.clone();
    let a0: Vec<T> = (0..n).map(|i| power(&minus_a, n - 1 - i)).collect();
    let m0 = (0..n).fold(power(&minus_a, n), |acc, i| acc + beta[i].clone() * a0[i].clone());
    let spread = quadratic(&sigma, &a0, &a0, n);
    if !(m0.is_positive() && m0.clone() * m0 > r2.clone() * spread) {
        return false;
    }
    // 3. ω > 0: F(ω) = m_re² G22 − 2 m_re m_im G12 + m_im² G11 − r² (G11 G22 − G12²).
    let powers: Vec<(Poly<T>, Poly<T>)> = (0..=n).map(|k| shifted_power(&a, k)).collect();
    let (mut m_re, mut m_im) = powers[n].clone();
    // Column i of A is (jω − α)^{n−1−i}.
    let cols: Vec<&(Poly<T>, Poly<T>)> = (0..n).map(|i| &powers[n - 1 - i]).collect();
    for (b, col) in beta.iter().zip(&cols) {
        m_re = add(&m_re, &scale(&col.0, b));
        m_im = add(&m_im, &scale(&col.1, b));
    }
    let mut g: [Poly<T>; 3] = [Vec::new(), Vec::new(), Vec::new()];
    for (i, ci) in cols.iter().enumerate() {
        for (j, cj) in cols.iter().enumerate() {
            let s = &sigma[i * n + j];
            if s.is_zero() {
                continue;
            }
            g[0] = add(&g[0], &scale(&mul(&ci.0, &cj.0), s));
            g[1] = add(&g[1], &scale(&mul(&ci.0, &cj.1), s));
            g[2] = add(&g[2], &scale(&mul(&ci.1, &cj.1), s));
        }
    }
    let minus_two = T::of(-2.0);
    let quad = add(
        &add(&mul(&mul(&m_re, &m_re), &g[2]), &scale(&mul(&mul(&m_re, &m_im), &g[1]), &minus_two)),
        &mul(&mul(&m_im, &m_im), &g[0]),
    );
    let det = add(&mul(&g[0], &g[2]), &scale(&mul(&g[1], &g[1]), &-T::one()));
    let f = trim(add(&quad, &scale(&det, &-r2)));
    // F = ω² F̃(ω²): the even coefficients from ω² on.
    let ftilde: Poly<T> = trim(f.iter().skip(2).step_by(2).cloned().collect());
    match ftilde.first() {
        // F̃ ≡ 0 (a singular Σ): zero is not excluded.
        None => false,
        Some(c0) if !c0.is_positive() => false,
        Some(_) => !has_positive_root(&ftilde),
    }
}

/// Whether every member of `e` has all its roots with real part below `−α` (module docs:
/// exact, `false` at a boundary touch). `false` for an ellipsoid that is not well formed
/// (order outside `1..=3`, a non-finite value, a negative radius) or a non-finite `alpha`.
#[must_use]
pub fn robustly_stable(e: &Ellipsoid<'_>, alpha: f64) -> bool {
    well_formed(e)
        && alpha.is_finite()
        && ball::decided(|| stable_at::<Ball>(e, alpha))
            .unwrap_or_else(|| stable_at::<BigRational>(e, alpha))
}

/// [`robustly_stable`] carried in rational arithmetic only, without the floating-point filter
/// that decides most `α` first: the reference the filter's answers equal (every answer of
/// [`robustly_stable`] is this function's), and the benchmarks' baseline.
#[must_use]
pub fn robustly_stable_rational(e: &Ellipsoid<'_>, alpha: f64) -> bool {
    well_formed(e) && alpha.is_finite() && stable_at::<BigRational>(e, alpha)
}

/// The largest `α` (to `tolerance`, never above it) at which [`robustly_stable`] holds: the
/// certified margin, in 1/s. `None` when the ellipsoid is not well formed or the test fails
/// even at the bracket's lower end (then no margin can be stated).
///
/// The bisection is guided by the same test carried in floating point, which costs a small
/// fraction of the exact one; the exact test then confirms a passing `α` at or below the
/// guide and a failing one above it, and bisects between them. The result always passes the
/// exact test, whatever the guide said.
#[must_use]
pub fn robust_margin(e: &Ellipsoid<'_>, tolerance: f64) -> Option<f64> {
    let n = e.centre.len();
    if !well_formed(e) || !(tolerance > 0.0) {
        return None;
    }
    let r = e.radius2.sqrt();
    let bound = 1.0
        + (0..n)
            .map(|i| e.centre[i].abs() + r * e.covariance[i * n + i].max(0.0).sqrt())
            .fold(0.0, f64::max);
    if !bound.is_finite() {
        return None;
    }
    // At −R − 1 every member is robust (Cauchy's bound); at R the centre is not.
    let (lo, hi) = (-bound - 1.0, bound);
    if !robustly_stable(e, lo) {
        return None;
    }
    let bisect = |mut pass: f64, mut fail: f64, test: &dyn Fn(f64) -> bool| {
        while fail - pass > tolerance {
            let mid = 0.5 * (pass + fail);
            if mid <= pass || mid >= fail {
                break;
            }
            if test(mid) {
                pass = mid;
            } else {
                fail = mid;
            }
        }
        (pass, fail)
    };
    let (guide, _) = bisect(lo, hi, &|a| stable_at::<f64>(e, a));
    // Confirm exactly around the guide, widening the step until the exact test brackets it.
    let (mut pass, mut fail) = (lo, hi);
    let mut step = tolerance;
    while guide - step > lo {
        if robustly_stable(e, guide - step) {
            pass = guide - step;
            break;
        }
        step *= 16.0;
    }
    let mut step = tolerance;
    while pass + step < hi {
        if robustly_stable(e, pass + step) {
            pass += step;
            step *= 16.0;
        } else {
            fail = pass + step;
            break;
        }
    }
    let (pass, _) = bisect(pass, fail, &|a| robustly_stable(e, a));
    Some(pass)
}

#[cfg(test)]
mod tests;
