//! Hotelling's machinery, shared by the nonlinear certificate, its checks, the model guards
//! and the coupling bounds: the upper quantile of Fisher's F, the simultaneous
//! (Scheffé–Hotelling) multiplier of a bound over a space of directions, and the Wald test of
//! a group of coefficients against Hotelling's quantile.

use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, Normal};
use statrs::function::beta::inv_beta_reg;
use statrs::function::gamma::ln_gamma;
use streamcert_regression::linalg;

use super::quantile::{beta_continued_fraction, t_quantile};

/// The Wald test of the terms of degree `>= 2` at one look.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NonlinearityTest {
    /// `W = θ̂_Hᵀ Ω̂_HH⁻¹ θ̂_H`.
    pub statistic: f64,
    /// Hotelling's quantile `ν q/(ν − q + 1) · F_{q, ν−q+1}(1 − α)`, `q = D − 1`.
    pub threshold: f64,
}

impl NonlinearityTest {
    /// `true` when the dynamics vary over the region at the test's risk.
    #[must_use]
    pub fn significant(&self) -> bool {
        self.statistic > self.threshold
    }
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

/// The Wald statistic `θ̂_Sᵀ Ω̂_SS⁻¹ θ̂_S` of `q` coefficients whose covariance `Ω̂_SS` is in
/// `sub` (`q × q`, overwritten by its factor) and values in `rhs` (overwritten), against
/// Hotelling's quantile `ν q/(ν − q + 1) · F_{q, ν−q+1}(1 − α)`; `None` when `Ω̂_SS` is not
/// positive definite, `ν − q + 1 <= 0`, or a value is not finite. `work`: `q` values.
pub(crate) fn hotelling_wald(
    q: usize,
    nu: f64,
    alpha: f64,
    (sub, rhs, work): (&mut [f64], &mut [f64], &mut [f64]),
) -> Option<NonlinearityTest> {
    if !linalg::cholesky_in_place(&mut sub[..q * q], q) {
        return None;
    }
    work[..q].copy_from_slice(&rhs[..q]);
    linalg::cholesky_solve_in_place(&sub[..q * q], q, &mut rhs[..q]);
    let quad: f64 = work[..q].iter().zip(&rhs[..q]).map(|(a, b)| a * b).sum();
    let (qf, d2) = (q as f64, nu - q as f64 + 1.0);
    if !(quad.is_finite() && d2 > 0.0) {
        return None;
    }
    let threshold = nu * qf / d2 * f_quantile(qf, d2, alpha);
    threshold.is_finite().then_some(NonlinearityTest { statistic: quad, threshold })
}

/// The Wald test of the `q` entries `S = {index(0), …, index(q − 1)}` of `vec(Θ̂)` (`theta`,
/// its covariance `cov`, `n × n` row-major with `n = theta.len()`): [`hotelling_wald`] on
/// `Ω̂_SS` and `θ̂_S` gathered into the scratch (`sub`: `q²`, `rhs` and `work`: `q` each).
/// `None` when `q = 0`, or as [`hotelling_wald`].
pub(crate) fn wald_entries(
    (theta, cov): (&[f64], &[f64]),
    (q, index): (usize, impl Fn(usize) -> usize),
    (nu, alpha): (f64, f64),
    (sub, rhs, work): (&mut [f64], &mut [f64], &mut [f64]),
) -> Option<NonlinearityTest> {
    if q == 0 {
        return None;
    }
    let n = theta.len();
    for a in 0..q {
        for b in 0..q {
            sub[a * q + b] = cov[index(a) * n + index(b)];
        }
        rhs[a] = theta[index(a)];
    }
    hotelling_wald(q, nu, alpha, (sub, rhs, work))
}

#[cfg(test)]
mod tests {
    use super::*;
    use statrs::distribution::{ContinuousCDF, FisherSnedecor};

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
