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
//! rejected. A frequency grid would not be a test: nothing bounds what happens between its
//! points. For `n = 1`, `F̃ = Σ_11 > 0` and the test is `β̂_1 − α > r √Σ_11`: the first-order
//! rate minus its radius.
//!
//! The margin ([`robust_margin`]) is found by bisection, since the test is monotone in `α`
//! (robust at `α` implies robust at every smaller `α`): from `−R − 1` (robust: by Cauchy's
//! bound, every member's roots lie in `|s| < R = 1 + max_i (|β̂_i| + r √Σ_ii)`) to `R`, the
//! result the last `α` that passed, so never above the true margin.

use num_bigint::BigInt;
use num_rational::BigRational;
use num_traits::{One, Signed, Zero};

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

/// A polynomial with rational coefficients, lowest power first.
type Poly = Vec<BigRational>;

/// `x` exactly (a finite float is a dyadic rational).
fn exact(x: f64) -> BigRational {
    BigRational::from_float(x).unwrap_or_else(BigRational::zero)
}

fn add(a: &Poly, b: &Poly) -> Poly {
    let mut out = vec![BigRational::zero(); a.len().max(b.len())];
    for (o, x) in out.iter_mut().zip(a) {
        *o += x;
    }
    for (o, x) in out.iter_mut().zip(b) {
        *o += x;
    }
    out
}

fn scale(a: &Poly, k: &BigRational) -> Poly {
    a.iter().map(|x| x * k).collect()
}

fn mul(a: &Poly, b: &Poly) -> Poly {
    if a.is_empty() || b.is_empty() {
        return Vec::new();
    }
    let mut out = vec![BigRational::zero(); a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        if x.is_zero() {
            continue;
        }
        for (j, y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

/// Drop the zero leading coefficients.
fn trim(mut a: Poly) -> Poly {
    while a.last().is_some_and(Zero::is_zero) {
        a.pop();
    }
    a
}

/// `(jω − α)^k` as its real and imaginary parts, polynomials in `ω`.
fn shifted_power(alpha: &BigRational, k: usize) -> (Poly, Poly) {
    let (mut re, mut im) = (vec![BigRational::zero(); k + 1], vec![BigRational::zero(); k + 1]);
    let mut binom = BigInt::one();
    for l in 0..=k {
        // C(k, l) (jω)^l (−α)^{k−l}.
        let mut c = BigRational::from_integer(binom.clone());
        for _ in 0..k - l {
            c *= -alpha;
        }
        match l % 4 {
            0 => re[l] = c,
            1 => im[l] = c,
            2 => re[l] = -c,
            _ => im[l] = -c,
        }
        binom = binom * BigInt::from(k - l) / BigInt::from(l + 1);
    }
    (re, im)
}

/// The coefficients `c_1..c_n` of the monic `q(s) = p(s − α; β)`, `p(s) = sⁿ + Σ β_i sⁿ⁻ⁱ`
/// (highest power first, without the leading one).
fn shifted_coefficients(beta: &[BigRational], alpha: &BigRational) -> Vec<BigRational> {
    let n = beta.len();
    // (s − α)^k in s, lowest power first.
    let power = |k: usize| {
        let mut p: Poly = vec![BigRational::one()];
        for _ in 0..k {
            p = mul(&p, &vec![-alpha.clone(), BigRational::one()]);
        }
        p
    };
    let mut q = power(n);
    for (i, b) in beta.iter().enumerate() {
        q = add(&q, &scale(&power(n - 1 - i), b));
    }
    (1..=n).map(|i| q[n - i].clone()).collect()
}

/// Routh–Hurwitz for a monic polynomial of degree `1..=3` with coefficients `c`.
fn hurwitz(c: &[BigRational]) -> bool {
    let pos = |x: &BigRational| x.is_positive();
    match c {
        [c1] => pos(c1),
        [c1, c2] => pos(c1) && pos(c2),
        [c1, c2, c3] => pos(c1) && pos(c2) && pos(c3) && c1 * c2 > *c3,
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

fn sign(x: &BigRational) -> i8 {
    if x.is_positive() {
        1
    } else if x.is_negative() {
        -1
    } else {
        0
    }
}

/// The remainder of `a` divided by `b` (`b` non-zero, trimmed).
fn remainder(a: &Poly, b: &Poly) -> Poly {
    let mut r = trim(a.clone());
    let lead = b.last().expect("a non-zero divisor").clone();
    while r.len() >= b.len() && !r.is_empty() {
        let k = r.len() - b.len();
        let f = r.last().expect("non-empty") / &lead;
        for (i, y) in b.iter().enumerate() {
            r[i + k] -= &f * y;
        }
        r.pop();
        r = trim(r);
    }
    r
}

/// Whether `f` (trimmed, `f(0) != 0`) has a real root in `(0, ∞)`: Sturm's theorem, the
/// number of distinct roots in `(0, ∞)` is `V(0) − V(∞)`.
fn has_positive_root(f: &Poly) -> bool {
    let derivative: Poly = f
        .iter()
        .enumerate()
        .skip(1)
        .map(|(i, c)| c * BigRational::from_integer(BigInt::from(i)))
        .collect();
    let mut chain = vec![f.clone(), trim(derivative)];
    while chain.last().is_some_and(|p| !p.is_empty()) {
        let n = chain.len();
        let r = remainder(&chain[n - 2], &chain[n - 1]);
        chain.push(r.iter().map(|c| -c).collect());
    }
    chain.pop();
    let at_zero = variations(chain.iter().map(|p| p.first().map_or(0, sign)));
    let at_infinity = variations(chain.iter().map(|p| p.last().map_or(0, sign)));
    at_zero > at_infinity
}

/// Whether every member of `e` has all its roots with real part below `−α` (module docs:
/// exact, `false` at a boundary touch). `false` for an ellipsoid that is not well formed
/// (order outside `1..=3`, a non-finite value, a negative radius).
#[must_use]
pub fn robustly_stable(e: &Ellipsoid<'_>, alpha: f64) -> bool {
    let n = e.centre.len();
    if !(1..=3).contains(&n)
        || e.covariance.len() != n * n
        || !(e.radius2 >= 0.0)
        || !alpha.is_finite()
        || !e.centre.iter().chain(e.covariance).all(|x| x.is_finite())
        || !e.radius2.is_finite()
    {
        return false;
    }
    let beta: Vec<BigRational> = e.centre.iter().map(|&x| exact(x)).collect();
    let sigma: Vec<BigRational> = e.covariance.iter().map(|&x| exact(x)).collect();
    let (r2, a) = (exact(e.radius2), exact(alpha));
    // 1. The centre.
    if !hurwitz(&shifted_coefficients(&beta, &a)) {
        return false;
    }
    // 2. ω = 0: m_0 = q(0; β̂), a_0 = ((−α)ⁿ⁻¹, …, 1).
    let a0: Vec<BigRational> =
        (0..n).map(|i| (0..n - 1 - i).fold(BigRational::one(), |acc, _| acc * -&a)).collect();
    let m0 = (0..n).fold((0..n).fold(BigRational::one(), |acc, _| acc * -&a), |acc, i| {
        acc + &beta[i] * &a0[i]
    });
    let spread = quadratic(&sigma, &a0, &a0, n);
    if !(m0.is_positive() && &m0 * &m0 > &r2 * &spread) {
        return false;
    }
    // 3. ω > 0: F(ω) = m_re² G22 − 2 m_re m_im G12 + m_im² G11 − r² (G11 G22 − G12²).
    let powers: Vec<(Poly, Poly)> = (0..=n).map(|k| shifted_power(&a, k)).collect();
    let (mut m_re, mut m_im) = powers[n].clone();
    // Column i of A is (jω − α)^{n−1−i}.
    let cols: Vec<&(Poly, Poly)> = (0..n).map(|i| &powers[n - 1 - i]).collect();
    for (b, col) in beta.iter().zip(&cols) {
        m_re = add(&m_re, &scale(&col.0, b));
        m_im = add(&m_im, &scale(&col.1, b));
    }
    let mut g = [Vec::new(), Vec::new(), Vec::new()];
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
    let two = BigRational::from_integer(BigInt::from(2));
    let quad = add(
        &add(&mul(&mul(&m_re, &m_re), &g[2]), &scale(&mul(&mul(&m_re, &m_im), &g[1]), &-two)),
        &mul(&mul(&m_im, &m_im), &g[0]),
    );
    let det = add(&mul(&g[0], &g[2]), &scale(&mul(&g[1], &g[1]), &-BigRational::one()));
    let f = trim(add(&quad, &scale(&det, &-r2)));
    // F = ω² F̃(ω²): the even coefficients from ω² on.
    let ftilde: Poly = trim(f.iter().skip(2).step_by(2).cloned().collect());
    match ftilde.first() {
        // F̃ ≡ 0 (a singular Σ): zero is not excluded.
        None => false,
        Some(c0) if !c0.is_positive() => false,
        Some(_) => !has_positive_root(&ftilde),
    }
}

/// `xᵀ Σ y` for `n`-vectors.
fn quadratic(sigma: &[BigRational], x: &[BigRational], y: &[BigRational], n: usize) -> BigRational {
    let mut total = BigRational::zero();
    for i in 0..n {
        for j in 0..n {
            total += &x[i] * &sigma[i * n + j] * &y[j];
        }
    }
    total
}

/// The largest `α` (to `tolerance`, never above it) at which [`robustly_stable`] holds: the
/// certified margin, in 1/s. `None` when the ellipsoid is not well formed or the test fails
/// even at the bracket's lower end (then no margin can be stated).
#[must_use]
pub fn robust_margin(e: &Ellipsoid<'_>, tolerance: f64) -> Option<f64> {
    let n = e.centre.len();
    if !(1..=3).contains(&n) || e.covariance.len() != n * n || !(tolerance > 0.0) {
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
    let (mut lo, mut hi) = (-bound - 1.0, bound);
    if !robustly_stable(e, lo) {
        return None;
    }
    while hi - lo > tolerance {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if robustly_stable(e, mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(lo)
}

#[cfg(test)]
mod tests;
