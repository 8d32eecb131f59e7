//! The first-order rate (paper Section II, eq. beta): `β̂ = −λ_max(sym Ĵ_cl)`, `Ĵ_cl = Θ̂ T`.

use streamcert_regression::linalg;

use crate::rank_one_variance_bound;

/// The map `T` (`d × p`, row-major) with `J_cl = Θ T`: the identity on the outputs' rows, the
/// gain `K` on the inputs' rows, zero on the intercept's.
pub(crate) fn closed_loop_map(p: usize, m: usize, d: usize, gain: &[f64]) -> Vec<f64> {
    (0..d * p)
        .map(|idx| {
            let (r, c) = (idx / p, idx % p);
            if r < p {
                f64::from(u8::from(r == c))
            } else if r < p + m {
                gain[(r - p) * p + c]
            } else {
                0.0
            }
        })
        .collect()
}

/// `Ĵ_cl = Ĵ_obs + B̂_obs K` into `jcl` (`p × p`, [`linalg::closed_loop_jacobian`]) from
/// `Θ̂ = [Ĵ_obs B̂_obs]` and the gain `K`, then the upper triangle of
/// `sym Ĵ_cl = (Ĵ_cl + Ĵ_clᵀ)/2` into `sym`.
#[inline(always)]
pub(crate) fn form_sym_jcl(
    theta: &[f64],
    k: &[f64],
    jcl: &mut [f64],
    sym: &mut [f64],
    p: usize,
    m: usize,
) {
    let (jcl, sym) = (&mut jcl[..p * p], &mut sym[..p * p]);
    linalg::closed_loop_jacobian(theta, k, jcl, p, m);
    for i in 0..p {
        for j in i..p {
            sym[i * p + j] = 0.5 * (jcl[i * p + j] + jcl[j * p + i]);
        }
    }
}

/// `sym(Θ̂ T)` (`p × p`, full) into `sym`, from `Θ̂` (`p × d`) and `T` (`d × p`), both
/// row-major.
#[inline(always)]
pub(crate) fn sym_theta_t(theta: &[f64], tmat: &[f64], sym: &mut [f64], p: usize, d: usize) {
    for i in 0..p {
        for j in 0..p {
            let (mut a, mut b) = (0.0, 0.0);
            for l in 0..d {
                a += theta[i * d + l] * tmat[l * p + j];
                b += theta[j * d + l] * tmat[l * p + i];
            }
            sym[i * p + j] = 0.5 * (a + b);
        }
    }
}

/// `β̂ = −λ_max(sym)` of a `p × p` symmetric matrix (`work` as
/// [`linalg::sym_eig_extremes`]).
#[inline(always)]
pub(crate) fn rate_of_sym(sym: &[f64], p: usize, work: &mut [f64]) -> f64 {
    -linalg::sym_eig_extremes(sym, p, work).1
}

/// `β̂ = −λ_max(sym)` from the upper triangle of a `p × p` symmetric matrix
/// ([`linalg::sym_eig_max`], the same bits as [`rate_of_sym`] on the full matrix for
/// `p < 10`).
#[inline(always)]
pub(crate) fn rate_of_upper(sym: &[f64], p: usize, work: &mut [f64]) -> f64 {
    -linalg::sym_eig_max(sym, p, work)
}

/// `σ²_max`: the largest variance of `vᵀ(Θ̂ − Θ) T v` over unit `v`, bounded by
/// `λ_max(Ω̂)` of the score's covariance `Ω̂` (`p² × p²`), and for `p = 2` also by the
/// rank-one bound ([`rank_one_variance_bound`]), whichever is smaller.
#[inline(always)]
pub(crate) fn direction_variance(score_cov: &[f64], p: usize, work: &mut [f64]) -> f64 {
    let variance = linalg::sym_eig_extremes(score_cov, p * p, work).1;
    if p == 2 { variance.min(rank_one_variance_bound(score_cov)) } else { variance }
}
