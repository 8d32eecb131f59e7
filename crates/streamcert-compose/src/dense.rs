//! Dense N-subsystem composition (`O(N³)`, faer's eigensolvers).

use faer::{Mat, Side};
use serde::{Deserialize, Serialize};

use crate::{ComposeError, Network};

/// The network guarantee computed from the full gain matrix.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NetworkCertificate {
    /// Network contraction rate `−α(Γ)` (positive iff the network contracts).
    pub rate: f64,
    /// Weights `η_i = w_i / v_i` (max 1) of the norm `‖x‖² = Σ η_i x_i²` that attains (up to
    /// `weight_regularization`) the rate.
    pub weights: Vec<f64>,
    /// The rate attained by `weights`: `−λ_max(sym(P^{½} Γ P^{−½}))`, `P = diag η`.
    pub weighted_rate: f64,
    /// The symmetric, unweighted bound `λ_min(diag β − sym Γ_off)` (Lemma 1's form for N
    /// subsystems); never above `rate`.
    pub symmetric_rate: f64,
    /// `s* = 1/ρ(D⁻¹ Γ_off)`, `D = diag β`: `diag(−β) + s Γ_off` is Hurwitz iff `s < s*`
    /// (requires every `β_i > 0`; `0` otherwise, `∞` without coupling).
    pub critical_scale: f64,
    /// For a reducible `Γ` (for example a cascade) the Perron vectors have zeros and no finite
    /// weights attain `−α(Γ)` exactly; the weights are then computed for
    /// `Γ + δ (11ᵀ − I)` with this `δ` (0 when not needed).
    pub weight_regularization: f64,
}

fn mat(n: usize, f: impl Fn(usize, usize) -> f64) -> Mat<f64> {
    Mat::from_fn(n, n, f)
}

/// Index of the eigenvalue with the largest real part, and that real part.
fn abscissa(m: &Mat<f64>) -> Result<(f64, usize, faer::linalg::solvers::Eigen<f64>), ComposeError> {
    let eig = m.eigen().map_err(|e| ComposeError::Numerical(format!("{e:?}")))?;
    let s = eig.S();
    let mut best = (f64::NEG_INFINITY, 0);
    for k in 0..m.nrows() {
        let re = s[k].re;
        if re > best.0 {
            best = (re, k);
        }
    }
    Ok((best.0, best.1, eig))
}

/// A real, sign-normalised eigenvector column; `None` if it is not strictly positive.
fn positive_vector(
    eig: &faer::linalg::solvers::Eigen<f64>,
    k: usize,
    n: usize,
) -> Option<Vec<f64>> {
    let u = eig.U();
    let mut v: Vec<f64> = (0..n).map(|i| u[(i, k)].re).collect();
    let sum: f64 = v.iter().sum();
    if sum < 0.0 {
        v.iter_mut().for_each(|x| *x = -*x);
    }
    let max = v.iter().fold(0.0f64, |a, &x| a.max(x.abs()));
    if max == 0.0 || v.iter().any(|&x| x <= 1e-12 * max) {
        return None;
    }
    Some(v)
}

fn sym_extreme(m: &Mat<f64>, largest: bool) -> Result<f64, ComposeError> {
    let ev = m
        .self_adjoint_eigenvalues(Side::Lower)
        .map_err(|e| ComposeError::Numerical(format!("{e:?}")))?;
    Ok(if largest { ev[ev.len() - 1] } else { ev[0] })
}

/// Dense composition of `N` subsystems (see the crate docs for the formulas). `O(N³)` time and
/// `O(N²)` memory: for networks beyond a few thousand subsystems use
/// [`certify_sparse`](crate::certify_sparse).
///
/// # Errors
/// [`ComposeError::Numerical`] if an eigensolver fails.
pub fn network_rate(net: &Network) -> Result<NetworkCertificate, ComposeError> {
    let n = net.len();
    let g = net.dense_gain_matrix();

    // Symmetric bound.
    let sym =
        mat(n, |i, j| if i == j { -g[i * n + i] } else { -0.5 * (g[i * n + j] + g[j * n + i]) });
    let symmetric_rate = sym_extreme(&sym, false)?;

    // Critical scale from the Perron root of D⁻¹ Γ_off.
    let beta = net.rates();
    let critical_scale = if beta.iter().any(|&b| b <= 0.0) {
        0.0
    } else if net.edges() == 0 {
        f64::INFINITY
    } else {
        let scaled = mat(n, |i, j| if i == j { 0.0 } else { g[i * n + j] / beta[i] });
        let ev = scaled.eigenvalues().map_err(|e| ComposeError::Numerical(format!("{e:?}")))?;
        let rho = ev.iter().fold(0.0f64, |a, z| a.max(z.norm()));
        if rho > 0.0 { 1.0 / rho } else { f64::INFINITY }
    };

    // Perron weights, regularising a reducible Γ.
    let scale = g.iter().fold(0.0f64, |a, &x| a.max(x.abs())).max(f64::MIN_POSITIVE);
    let mut delta = 0.0;
    let mut alpha = f64::NAN;
    let weights = loop {
        let m = mat(n, |i, j| g[i * n + j] + if i == j { 0.0 } else { delta });
        let (abscissa_m, kr, right) = abscissa(&m)?;
        if delta == 0.0 {
            // The first pass is on Γ itself: its abscissa is the network rate.
            alpha = abscissa_m;
        }
        let mt = mat(n, |i, j| m[(j, i)]);
        let (_, kl, left) = abscissa(&mt)?;
        match (positive_vector(&right, kr, n), positive_vector(&left, kl, n)) {
            (Some(v), Some(w)) => {
                let eta: Vec<f64> = w.iter().zip(&v).map(|(a, b)| a / b).collect();
                let max = eta.iter().fold(0.0f64, |a, &x| a.max(x));
                break eta.iter().map(|x| x / max).collect::<Vec<f64>>();
            }
            _ if delta == 0.0 => delta = 1e-9 * scale,
            _ if delta < 1e-3 * scale => delta *= 100.0,
            _ => return Err(ComposeError::Numerical("no positive Perron vectors".into())),
        }
    };
    let sq: Vec<f64> = weights.iter().map(|x| x.sqrt()).collect();
    let weighted =
        mat(n, |i, j| 0.5 * (sq[i] * g[i * n + j] / sq[j] + sq[j] * g[j * n + i] / sq[i]));
    let weighted_rate = -sym_extreme(&weighted, true)?;
    Ok(NetworkCertificate {
        rate: -alpha,
        weights,
        weighted_rate,
        symmetric_rate,
        critical_scale,
        weight_regularization: delta,
    })
}
