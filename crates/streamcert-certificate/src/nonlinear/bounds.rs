//! The numbers behind a nonlinear look: rigorous bounds of a polynomial over an interval, the
//! upper quantile of Fisher's F, and the simultaneous (Scheffé–Hotelling) multiplier.

use statrs::distribution::{ContinuousCDF, Normal};
use statrs::function::beta::inv_beta_reg;
use statrs::function::gamma::ln_gamma;

use crate::look::quantile::beta_continued_fraction;
use crate::look::quantile::t_quantile;

/// The Taylor coefficients of the polynomial `Σ_i c_i y^i` at `centre`, in place: afterwards
/// `c_i` is the coefficient of `(y − centre)^i`. Repeated synthetic division, `O(n²)`.
pub(crate) fn shift_in_place(c: &mut [f64], centre: f64) {
    let n = c.len();
    for i in 0..n {
        for j in (i..n.saturating_sub(1)).rev() {
            c[j] += centre * c[j + 1];
        }
    }
}

/// Lower and upper bounds of `Σ_i c_i y^i` over `[lo, hi]`: with the Taylor coefficients `q_i`
/// at the midpoint `m` and the half-width `r`, every value lies in
/// `q_0 ± Σ_{i>=1} |q_i| r^i` (the triangle inequality on `(y − m)^i ∈ [−r^i, r^i]`). Exact
/// when `lo = hi`; the overestimate is `O(r²)` where the polynomial is smooth. `work` holds
/// at least `c.len()` values.
pub fn polynomial_bounds(c: &[f64], lo: f64, hi: f64, work: &mut [f64]) -> (f64, f64) {
    let (m, r) = (0.5 * (lo + hi), 0.5 * (hi - lo));
    let q = &mut work[..c.len()];
    q.copy_from_slice(c);
    shift_in_place(q, m);
    let (mut spread, mut power) = (0.0, 1.0);
    for &qi in &q[1..] {
        power *= r;
        spread += qi.abs() * power;
    }
    (q[0] - spread, q[0] + spread)
}

/// The upper `1 − risk` quantile of Fisher's F with `(d1, d2)` degrees of freedom. The upper
/// tail is `Q(F) = I_w(d2/2, d1/2)` with `w = d2/(d2 + d1 F)`, solved for `w` on the lower
/// tail of the beta function (no digits lost to `1 − risk`):
///
/// * for `risk < 0.25`: Newton steps on `ln I_w = ln risk` in `u = ln w` (nearly linear in the
///   tail, where `I_w ≈ w^a / (a B)`), from the chi-square start of Wilson and Hilferty,
///   with `I_w` by its continued fraction (modified Lentz) and the log-beta constant computed
///   once, until the step is below `1e-12`; about half a microsecond;
/// * otherwise, or without convergence in 30 steps, statrs' `inv_beta_reg`.
///
/// `+∞` outside `d1, d2 > 0`, `risk ∈ (0, 1)`. Checked against statrs in the tests.
#[must_use]
pub fn f_quantile(d1: f64, d2: f64, risk: f64) -> f64 {
    if !(d1 > 0.0 && d2 > 0.0 && risk > 0.0 && risk < 1.0) {
        return f64::INFINITY;
    }
    let w = if risk < 0.25 { tail_beta_quantile(0.5 * d2, 0.5 * d1, d1, risk) } else { None }
        .unwrap_or_else(|| inv_beta_reg(0.5 * d2, 0.5 * d1, risk));
    if !(w > 0.0) {
        return f64::INFINITY;
    }
    (d2 / d1) * (1.0 - w) / w
}

/// `w` with `I_w(a, b) = risk` in the lower tail (see [`f_quantile`]); `None` when the
/// iteration leaves the continued fraction's range or does not converge.
fn tail_beta_quantile(a: f64, b: f64, d1: f64, risk: f64) -> Option<f64> {
    // Start: F ≈ χ²_{d1}(1 − risk)/d1 (Wilson–Hilferty), w = d2/(d2 + d1 F) with d2 = 2a.
    let z = -Normal::new(0.0, 1.0).ok()?.inverse_cdf(risk);
    let g = 2.0 / (9.0 * d1);
    let chi = d1 * (1.0 - g + z * g.sqrt()).max(1e-3).powi(3);
    let d2 = 2.0 * a;
    let mut u = (d2 / (d2 + chi)).ln();
    let ln_beta = ln_gamma(a) + ln_gamma(b) - ln_gamma(a + b);
    let target = risk.ln();
    for _ in 0..30 {
        let w = u.exp();
        if !(w > 0.0 && w < (a + 1.0) / (a + b + 2.0)) {
            return None;
        }
        let ln_front = a * w.ln() + b * (1.0 - w).ln() - ln_beta;
        let ln_i = ln_front + beta_continued_fraction(a, b, w)?.ln() - a.ln();
        // d/du ln I = w · pdf(w) / I, pdf(w) = w^{a−1} (1 − w)^{b−1} / B.
        let ln_slope = a * w.ln() + (b - 1.0) * (1.0 - w).ln() - ln_beta - ln_i;
        let step = (ln_i - target) / ln_slope.exp();
        u -= step.clamp(-2.0, 2.0);
        if step.abs() <= 1e-12 {
            return Some(u.exp());
        }
    }
    None
}

/// The multiplier `c` of a bound `a(y)ᵀ(θ − θ̂) <= c · √(a(y)ᵀ Ω̂ a(y))` that holds for every
/// `y` at once with probability `1 − risk`, when `a(y)` ranges over a space of dimension
/// `rank` and `Ω̂` has `nu` degrees of freedom:
///
/// ```text
/// rank = 1:  c = t_ν(1 − risk)                              (one direction, one-sided)
/// rank > 1:  c² = ν r / (ν − r + 1) · F_{r, ν − r + 1}(1 − risk)   (Hotelling's T², Scheffé)
/// ```
///
/// By Cauchy–Schwarz, `sup_a (aᵀe)² / (aᵀΩ̂a) = eᵀ Ω̂⁻¹ e` over the space, which is
/// Hotelling's `T²` with `r` and `ν` degrees of freedom; so the bound holds for every point of
/// every region, including a region the data chose. `+∞` when `ν − r + 1 <= 0`.
#[must_use]
pub fn simultaneous_multiplier(rank: usize, nu: f64, risk: f64) -> f64 {
    if rank <= 1 {
        return t_quantile(nu, risk);
    }
    let r = rank as f64;
    let d2 = nu - r + 1.0;
    if !(d2 > 0.0) {
        return f64::INFINITY;
    }
    (nu * r / d2 * f_quantile(r, d2, risk)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use statrs::distribution::{ContinuousCDF, FisherSnedecor};

    #[test]
    fn shifted_coefficients_evaluate_the_same_polynomial() {
        let c = [0.3, -1.2, 0.7, 2.0, -0.4];
        let mut q = c;
        shift_in_place(&mut q, 0.8);
        for y in [-2.0, -0.5, 0.0, 0.8, 1.7] {
            let direct: f64 = c.iter().rev().fold(0.0, |a, &ci| a * y + ci);
            let shifted: f64 = q.iter().rev().fold(0.0, |a, &qi| a * (y - 0.8) + qi);
            assert!((direct - shifted).abs() < 1e-12 * (1.0 + direct.abs()), "{y}");
        }
    }

    #[test]
    fn polynomial_bounds_contain_a_dense_scan_and_tighten_with_width() {
        let c = [0.1, -1.0, 0.0, 1.0];
        let mut work = [0.0; 4];
        for (lo, hi) in [(-2.0, 2.0), (-0.2, 0.1), (0.5, 0.5), (1.0, 1.3)] {
            let (l, u) = polynomial_bounds(&c, lo, hi, &mut work);
            let (mut smin, mut smax) = (f64::INFINITY, f64::NEG_INFINITY);
            for i in 0..=2000 {
                let y = lo + (hi - lo) * f64::from(i) / 2000.0;
                let v: f64 = c.iter().rev().fold(0.0, |a, &ci| a * y + ci);
                smin = smin.min(v);
                smax = smax.max(v);
            }
            assert!(
                l <= smin + 1e-12 && u >= smax - 1e-12,
                "[{lo}, {hi}]: {l} {u} vs {smin} {smax}"
            );
            // The overestimate is second order in the width: here |q_i| <= 4, so at most
            // 2 · 4 Σ_{i>=2} r^i (the true extreme may sit where those terms change sign).
            let r: f64 = 0.5 * (hi - lo);
            let excess = 8.0 * (r * r + r * r * r) + 1e-12;
            assert!(smin - l <= excess && u - smax <= excess, "[{lo}, {hi}]: {l} {u}");
        }
    }

    #[test]
    fn f_quantile_inverts_statrs_survival_function() {
        for (d1, d2) in [(1.0, 10.0), (2.0, 40.0), (3.0, 150.5), (5.0, 7.0)] {
            let dist = FisherSnedecor::new(d1, d2).unwrap();
            for risk in [0.1, 0.01, 1e-4, 1e-7] {
                let f = f_quantile(d1, d2, risk);
                let sf = dist.sf(f);
                assert!((sf / risk - 1.0).abs() < 1e-6, "F({d1},{d2}) at {risk}: sf {sf}");
            }
        }
    }

    #[test]
    fn f_quantile_agrees_with_statrs_inverse_on_a_grid() {
        for d1 in [1.0, 2.0, 3.0, 7.0] {
            for d2 in [3.0, 12.5, 60.0, 400.0, 5000.0] {
                for risk in [0.2, 0.05, 1e-3, 1e-5, 1e-8] {
                    let fast = f_quantile(d1, d2, risk);
                    // In the tail the fast path answers (no fallback to statrs).
                    if risk <= 0.05 {
                        let w = tail_beta_quantile(0.5 * d2, 0.5 * d1, d1, risk);
                        assert!(w.is_some(), "{d1} {d2} {risk}");
                    }
                    let dist = FisherSnedecor::new(d1, d2).unwrap();
                    let sf = dist.sf(fast);
                    assert!((sf / risk - 1.0).abs() < 1e-7, "F({d1},{d2}) {risk}: sf {sf}");
                }
            }
        }
    }

    #[test]
    fn rank_one_is_the_one_sided_t_and_more_directions_cost_more() {
        assert_eq!(simultaneous_multiplier(1, 40.0, 1e-3), t_quantile(40.0, 1e-3));
        let (c1, c2, c3) = (
            simultaneous_multiplier(1, 100.0, 1e-3),
            simultaneous_multiplier(2, 100.0, 1e-3),
            simultaneous_multiplier(3, 100.0, 1e-3),
        );
        assert!(c1 < c2 && c2 < c3, "{c1} {c2} {c3}");
        // Two directions: T² = 2ν/(ν − 1) F_{2, ν−1}; at ν = ∞ it is χ²_2 = −2 ln risk.
        let big = simultaneous_multiplier(2, 1e7, 1e-3);
        assert!((big * big - (-2.0 * 1e-3f64.ln())).abs() < 1e-3, "{big}");
        assert!(simultaneous_multiplier(4, 3.0, 0.01).is_infinite());
    }
}
