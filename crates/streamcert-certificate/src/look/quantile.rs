//! The numbers behind a calibrated look: the risk it spends, the Student-t quantile, the
//! radius, and for `p = 2` the rank-one variance bound.

use statrs::distribution::{ContinuousCDF, Normal, StudentsT};
use statrs::function::gamma::ln_gamma;

/// `δ_{w,k} = δ · share · 1 / (k (k + 1))`: the risk of the `k`-th look (`k >= 1`) of a window
/// with risk share `share`; summed over `k` it is `δ · share`.
#[must_use]
pub fn look_risk(delta: f64, share: f64, k: u64) -> f64 {
    let k = k.max(1) as f64;
    delta * share / (k * (k + 1.0))
}

/// The risk of the anchored window's `look`-th look (`>= 1`) of its `epoch`-th epoch (`>= 1`)
/// with risk share `share` and `design` looks sharing most of it
/// ([`Calibration::anchored_share`](crate::Calibration::anchored_share)):
///
/// ```text
/// δ_{e,j} = δ · share · ε_e · q_j
/// ε_1 = 0.9,   ε_e = 0.1 / ((e − 1) e)  (e >= 2)           (Σ_e ε_e = 1)
/// q_j = 0.9 / K  (j <= K),   q_j = 0.1 / ((j − K)(j − K + 1))  (j > K)   (Σ_j q_j = 1)
/// ```
///
/// so that summed over every look of every epoch it is `δ · share`, for a run of any length,
/// any number of epochs and any stopping rule. The first epoch (from the start) holds 90 %: a
/// commissioning run is one epoch, and a later epoch begins only after a gap or a change
/// point, where the sliding windows certify too (measured against 75 % with `share = 0.75`:
/// the loop at 5× the margin 91.0 % against 88.8 %, the 20× loop at 3.19 s against 4.44 s;
/// [`Calibration::anchored_share`](crate::Calibration::anchored_share)). Within an epoch the first `K` looks (sizes from the shortest window to
/// `g^(K−1)` times it) share 90 % equally: a loop is certified at the size its rate needs,
/// whichever that is; the tail keeps looking at a decreasing risk.
///
/// ```
/// use streamcert_certificate::anchored_look_risk;
/// let total: f64 = (1..=200u64)
///     .flat_map(|e| (1..=4000u64).map(move |j| anchored_look_risk(0.01, 0.9, e, j, 11)))
///     .sum();
/// assert!(total <= 0.009 && total > 0.0089);
/// ```
#[must_use]
pub fn anchored_look_risk(delta: f64, share: f64, epoch: u64, look: u64, design: u64) -> f64 {
    let e = epoch.max(1) as f64;
    let epoch_share = if epoch <= 1 { 0.9 } else { 0.1 / ((e - 1.0) * e) };
    let (j, k) = (look.max(1), design.max(1));
    let look_share = if j <= k {
        0.9 / k as f64
    } else {
        let i = (j - k) as f64;
        0.1 / (i * (i + 1.0))
    };
    delta * share * epoch_share * look_share
}

/// The upper `1 − risk` quantile of Student's t with `nu` degrees of freedom (`+∞` for
/// `nu < 1` or a risk outside `(0, 1)`).
///
/// For `nu >= 5` and `risk < 0.5`: the Cornish–Fisher expansion of `t` in the normal quantile
/// (four terms) as a start, then Halley steps on `ln S(t) = ln risk`, where the survival
/// function `S(t) = I_x(ν/2, 1/2) / 2`, `x = ν/(ν + t²)`, is the regularised incomplete beta
/// function by its continued fraction (modified Lentz) with the log-beta constant computed
/// once, until the relative step is below `1e-13`. Otherwise, and if that does not converge in
/// eight steps, statrs' `inverse_cdf`. Checked against statrs in the tests.
#[must_use]
pub fn t_quantile(nu: f64, risk: f64) -> f64 {
    if !(nu >= 1.0 && risk > 0.0 && risk < 1.0) {
        return f64::INFINITY;
    }
    if nu >= 5.0
        && risk < 0.5
        && let Some(t) = t_quantile_halley(nu, risk)
    {
        return t;
    }
    match StudentsT::new(0.0, 1.0, nu) {
        // The lower tail is computed without the cancellation of `1 − risk`.
        Ok(dist) => -dist.inverse_cdf(risk),
        Err(_) => f64::INFINITY,
    }
}

/// Halley iteration for [`t_quantile`]; `None` when it does not converge.
fn t_quantile_halley(nu: f64, risk: f64) -> Option<f64> {
    let z = -Normal::new(0.0, 1.0).ok()?.inverse_cdf(risk);
    let (z2, g) = (z * z, 1.0 / nu);
    let mut t = z
        + g * z * (z2 + 1.0) / 4.0
        + g * g * z * ((5.0 * z2 + 16.0) * z2 + 3.0) / 96.0
        + g * g * g * z * (((3.0 * z2 + 19.0) * z2 + 17.0) * z2 - 15.0) / 384.0;
    let a = 0.5 * nu;
    // ln B(ν/2, 1/2) and the log density constant ln Γ((ν+1)/2) − ln Γ(ν/2) − ½ ln(νπ).
    let (lg_a, lg_ab) = (ln_gamma(a), ln_gamma(a + 0.5));
    let ln_beta = lg_a + 0.5 * std::f64::consts::PI.ln() - lg_ab;
    let ln_norm = -ln_beta - 0.5 * nu.ln();
    let target = risk.ln();
    for _ in 0..8 {
        let q = nu + t * t;
        let x = nu / q;
        // I_x(a, 1/2) with the continued fraction, valid for x < (a + 1)/(a + 1.5).
        if !(t > 0.0 && x < (a + 1.0) / (a + 1.5)) {
            return None;
        }
        let ln_front = a * x.ln() + 0.5 * (t * t / q).ln() - ln_beta;
        let ln_sf = ln_front + beta_continued_fraction(a, 0.5, x)?.ln() - a.ln() - 2f64.ln();
        let ln_pdf = ln_norm - 0.5 * (nu + 1.0) * (q / nu).ln();
        // f(t) = ln S(t) − ln risk, f' = −pdf/S, f'' = −(pdf'/S) − (pdf/S)², pdf' = −pdf (ν+1) t/q.
        let r = (ln_pdf - ln_sf).exp();
        let f = ln_sf - target;
        let (f1, f2) = (-r, r * (nu + 1.0) * t / q - r * r);
        let step = 2.0 * f * f1 / (2.0 * f1 * f1 - f * f2);
        t -= step;
        if step.abs() <= 1e-13 * t.abs() {
            return Some(t);
        }
    }
    None
}

/// The continued fraction of the regularised incomplete beta function `I_x(a, b)` (modified
/// Lentz, as in Numerical Recipes' `betacf`); `None` if it does not converge.
///
/// Lentz's method replaces a denominator below `1e-300` in magnitude by `1e-300`. That guard
/// sits in the loop's chain of dependent operations but almost never fires, so the fraction is
/// first run without it, noting whether any denominator fell below `1e-300`; only then is it
/// run again with the guard. Both runs perform the same operations whenever the guard does not
/// fire, so the result is the guarded method's, bit for bit.
pub(crate) fn beta_continued_fraction(a: f64, b: f64, x: f64) -> Option<f64> {
    match lentz::<false>(a, b, x) {
        (h, false) => h,
        (_, true) => lentz::<true>(a, b, x).0,
    }
}

/// One run of the continued fraction: with `GUARD`, Lentz's replacement of tiny denominators;
/// without, the second value says whether a denominator was tiny (the run is then void).
#[inline(always)]
fn lentz<const GUARD: bool>(a: f64, b: f64, x: f64) -> (Option<f64>, bool) {
    const TINY: f64 = 1e-300;
    let mut tiny = false;
    let mut guard = |v: f64| {
        if GUARD {
            if v.abs() < TINY { TINY } else { v }
        } else {
            tiny |= v.abs() < TINY;
            v
        }
    };
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = guard(1.0 - qab * x / qap);
    d = 1.0 / d;
    let mut h = d;
    for m in 1..=300 {
        let (m, m2) = (f64::from(m), f64::from(2 * m));
        let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = guard(1.0 + aa * d);
        c = guard(1.0 + aa / c);
        d = 1.0 / d;
        h *= d * c;
        let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = guard(1.0 + aa * d);
        c = guard(1.0 + aa / c);
        d = 1.0 / d;
        let del = d * c;
        h *= del;
        if (del - 1.0).abs() < 1e-15 {
            return (Some(h), tiny);
        }
    }
    (None, tiny)
}

/// `ρ = t_ν(1 − risk) · √(λ_max(Ω̂))` (see the module docs): `variance` is `λ_max(Ω̂)`, the
/// largest estimated variance of `vᵀ(Ĵ_cl − J_cl)v` over unit `v`.
#[must_use]
pub fn calibrated_radius(variance: f64, nu: f64, risk: f64) -> f64 {
    t_quantile(nu, risk) * variance.max(0.0).sqrt()
}

/// For `p = 2`: an upper bound on `max_{‖v‖=1} vec(vvᵀ)ᵀ Ω vec(vvᵀ)`, the largest variance of
/// `vᵀ ΔJ v` over unit directions (`Ω` is `4 × 4`, positive semi-definite).
///
/// With `v = (cos θ, sin θ)`, `vec(vvᵀ) = ((1 + cos φ)/2, sin φ/2, sin φ/2, (1 − cos φ)/2)`
/// for `φ = 2θ`, so `f(φ)` is a trigonometric polynomial of degree 2 and, by Bernstein's
/// inequality, `|f'| <= 2 max f`. On a grid of `N = 256` points over `[0, 2π)` the maximum
/// is then at most `max_grid f / (1 − 2π/N)`. The certificate uses the smaller of this and
/// `λ_max(Ω)` (the bound over all unit symmetric matrices); it is the tighter one when `Ω` is
/// not isotropic, for example under common-mode noise.
#[must_use]
pub fn rank_one_variance_bound(omega: &[f64]) -> f64 {
    const N: usize = 256;
    let mut best = 0.0f64;
    for i in 0..N {
        let phi = 2.0 * std::f64::consts::PI * i as f64 / N as f64;
        let (s, c) = phi.sin_cos();
        let e = [0.5 * (1.0 + c), 0.5 * s, 0.5 * s, 0.5 * (1.0 - c)];
        let mut f = 0.0;
        for a in 0..4 {
            for b in 0..4 {
                f += e[a] * omega[a * 4 + b] * e[b];
            }
        }
        best = best.max(f);
    }
    best / (1.0 - 2.0 * std::f64::consts::PI / N as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unguarded first run returns the guarded method's value, bit for bit, over the
    /// arguments the t quantile and the nonlinear bounds use (and beyond).
    #[test]
    fn unguarded_fraction_is_the_guarded_one() {
        let mut compared = 0;
        for ia in 1..=60 {
            let a = 0.25 * f64::from(ia) + 0.013;
            for b in [0.5, 1.0, 1.5, 3.25, 10.0] {
                for ix in 1..100 {
                    let x = f64::from(ix) / 100.0;
                    if x >= (a + 1.0) / (a + b + 2.0) {
                        continue;
                    }
                    let guarded = lentz::<true>(a, b, x).0;
                    let fast = beta_continued_fraction(a, b, x);
                    assert_eq!(fast.map(f64::to_bits), guarded.map(f64::to_bits), "{a} {b} {x}");
                    compared += usize::from(guarded.is_some());
                }
            }
        }
        assert!(compared > 5000, "{compared}");
    }

    /// A denominator that vanishes: `1 − (a + b) x / (a + 1) = 0` at the start. The guard must
    /// fire (the unguarded run would divide by zero) and the guarded value is returned.
    #[test]
    fn a_vanishing_denominator_takes_the_guarded_run() {
        let (a, b) = (1.0, 1.0);
        let x = (a + 1.0) / (a + b);
        let (_, tiny) = lentz::<false>(a, b, x);
        assert!(tiny);
        assert_eq!(
            beta_continued_fraction(a, b, x).map(f64::to_bits),
            lentz::<true>(a, b, x).0.map(f64::to_bits)
        );
    }
}
