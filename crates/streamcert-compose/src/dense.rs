//! Dense N-subsystem composition: every quantity is the Perron root of a nonnegative matrix,
//! bracketed by Collatz–Wielandt along a power iteration (`O(N + edges)` per step), with
//! faer's eigendecomposition (`O(N³)`) on request or where a bracket does not close.

use faer::{Mat, Side};
use serde::{Deserialize, Serialize};

use crate::{ComposeError, Network};

mod perron;
use perron::perron;

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
    /// The upper end of the bracket on the network rate (`rate` is its lower, safe end; equal
    /// for the eigendecomposition).
    pub rate_upper: f64,
    /// How the numbers were computed.
    pub method: DenseMethod,
    /// Power iterations spent (0 for the eigendecomposition).
    pub iterations: usize,
    /// `false` when a bracket did not close within the iteration budget and the network was
    /// too large for the eigendecomposition: every number is then the safe end of its
    /// bracket (rates and scale never overstated), just not tight.
    pub converged: bool,
}

/// How [`network_rate_with`] computed a [`NetworkCertificate`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DenseMethod {
    /// Perron roots by Collatz–Wielandt brackets along power iterations.
    Perron,
    /// faer's eigendecomposition of the dense matrices.
    Eigendecomposition,
}

/// Options of [`network_rate_with`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DenseOptions {
    /// Use the eigendecomposition (`O(N³)`) instead of the Perron brackets.
    pub exact: bool,
    /// A bracket is closed when its width is at most `tolerance` times the scale
    /// `max(max β, max γ, 1)` (default `1e-13`).
    pub tolerance: f64,
    /// Power iterations per bracket (default 1000).
    pub max_iterations: usize,
    /// Largest `N` for which an unclosed bracket falls back to the eigendecomposition
    /// (default 256); above it the safe ends are returned with `converged = false`.
    pub eigen_limit: usize,
}

impl Default for DenseOptions {
    fn default() -> Self {
        Self { exact: false, tolerance: 1e-13, max_iterations: 1000, eigen_limit: 256 }
    }
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

/// Which end of a symmetric matrix's spectrum.
#[derive(Clone, Copy)]
enum End {
    Smallest,
    Largest,
}

fn sym_extreme(m: &Mat<f64>, end: End) -> Result<f64, ComposeError> {
    let ev = m
        .self_adjoint_eigenvalues(Side::Lower)
        .map_err(|e| ComposeError::Numerical(format!("{e:?}")))?;
    Ok(match end {
        End::Largest => ev[ev.len() - 1],
        End::Smallest => ev[0],
    })
}

/// Dense composition of `N` subsystems (see the crate docs for the formulas) with the default
/// [`DenseOptions`]: Perron brackets, the eigendecomposition where one does not close and
/// `N <= 256`.
///
/// # Errors
/// [`ComposeError::Numerical`] if an eigensolver fails.
pub fn network_rate(net: &Network) -> Result<NetworkCertificate, ComposeError> {
    network_rate_with(net, &DenseOptions::default())
}

/// Dense composition of `N` subsystems with `opts`.
///
/// The gain matrix `Γ` is Metzler, so its spectral abscissa is the Perron root of the
/// nonnegative `A = Γ + cI` less `c` (`c = max β + 0.1 max γ`, which also makes the diagonal
/// positive, so an irreducible `A` is primitive and the power iteration converges). For any
/// `x > 0`, `min_i (Ax)_i/x_i <= ρ(A) <= max_i (Ax)_i/x_i` (Collatz–Wielandt): each step
/// brackets the root, and the certificate reports the safe end (the smaller rate). The same
/// holds for the symmetric bound (`sym Γ` is a symmetric Metzler matrix), the weighted rate
/// (started at `√(v ∘ w)`, the exact Perron vector of the weighted symmetric part) and the
/// critical scale (`ρ(D⁻¹Γ_off)`, upper end, so the scale is never overstated). The weights
/// come from the right and left iterates. A bracket that does not close within
/// `max_iterations` falls back to the eigendecomposition for `N <= eigen_limit`.
///
/// # Errors
/// [`ComposeError::Numerical`] if an eigensolver fails; [`ComposeError::NonFinite`] for a
/// non-finite tolerance.
pub fn network_rate_with(
    net: &Network,
    opts: &DenseOptions,
) -> Result<NetworkCertificate, ComposeError> {
    crate::finite("tolerance", opts.tolerance)?;
    if !opts.exact
        && let Some(cert) = perron(net, opts)?
    {
        return Ok(cert);
    }
    eigendecomposition(net)
}

/// Transposed coupling rows: `(j, γ_ij)` for every `i` driven by `j`, grouped by `j`.
fn transposed(net: &Network) -> Vec<Vec<(usize, f64)>> {
    let mut t = vec![Vec::new(); net.len()];
    for i in 0..net.len() {
        for (j, g) in net.row(i) {
            t[j].push((i, g));
        }
    }
    t
}

/// The eigendecomposition path (`O(N³)`).
fn eigendecomposition(net: &Network) -> Result<NetworkCertificate, ComposeError> {
    let n = net.len();
    let g = net.dense_gain_matrix();

    // Symmetric bound.
    let sym =
        mat(n, |i, j| if i == j { -g[i * n + i] } else { -0.5 * (g[i * n + j] + g[j * n + i]) });
    let symmetric_rate = sym_extreme(&sym, End::Smallest)?;

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
    let weighted_rate = -sym_extreme(&weighted, End::Largest)?;
    Ok(NetworkCertificate {
        rate: -alpha,
        weights,
        weighted_rate,
        symmetric_rate,
        critical_scale,
        weight_regularization: delta,
        rate_upper: -alpha,
        method: DenseMethod::Eigendecomposition,
        iterations: 0,
        converged: true,
    })
}
