//! Certificates for large sparse networks: no eigenvalues, only sparse products and (optionally)
//! sparse Cholesky factorisations.

use faer::Side;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use serde::{Deserialize, Serialize};

use crate::{ComposeError, Network};

/// Which test produced a certified rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// A vector `x > 0` with `(Γ + μ I) x <= 0` (Collatz–Wielandt; weighted `ℓ∞` norm
    /// `max_i |y_i| / x_i`).
    CollatzWielandt,
    /// A successful sparse Cholesky of `diag β − sym Γ_off − μ I` (Euclidean norm).
    SymmetricCholesky,
}

/// Options of [`certify_sparse`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SparseOptions {
    /// Power iterations for the Collatz–Wielandt certificate (each is one sparse product).
    pub max_iterations: usize,
    /// Stop once the Collatz–Wielandt bracket `[lower, upper]` on `−α(Γ)` is narrower than
    /// `tolerance · max(1, max β)`.
    pub tolerance: f64,
    /// Bisection steps on the symmetric bound (each is one sparse Cholesky); 0 skips it.
    pub cholesky_steps: usize,
}

impl Default for SparseOptions {
    /// 50 iterations, tolerance `1e-6`, 0 Cholesky steps (the Collatz–Wielandt certificate is
    /// never worse than the symmetric one once converged, and far cheaper).
    fn default() -> Self {
        Self { max_iterations: 50, tolerance: 1e-6, cholesky_steps: 0 }
    }
}

/// The certified network guarantee of a large sparse network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SparseCertificate {
    /// Best certified lower bound on the network rate `−α(Γ)`.
    pub rate: f64,
    /// The method that gave `rate`.
    pub method: Method,
    /// Collatz–Wielandt certified rate `min_i −(Γ x)_i / x_i`.
    pub metzler_rate: f64,
    /// Collatz–Wielandt upper bound on `−α(Γ)` (`max_i −(Γ x)_i / x_i` at the best iterate):
    /// the true rate lies in `[metzler_rate, metzler_upper]`.
    pub metzler_upper: f64,
    /// The certificate vector `x > 0` (max 1).
    pub certificate: Vec<f64>,
    /// Power iterations used.
    pub iterations: usize,
    /// Certified lower bound on the symmetric bound by Cholesky bisection (`None` if skipped).
    pub symmetric_rate: Option<f64>,
    /// Certified lower bound on the critical coupling scale `s* = 1/ρ(D⁻¹ Γ_off)` (0 when a
    /// local rate is not positive, `∞` without coupling).
    pub critical_scale: f64,
}

/// Collatz–Wielandt bracket of the Perron root of a nonnegative operator with positive
/// diagonal, given row by row (`row(i, x) = (B x)_i`): returns `(best upper, best lower, vector
/// of the best upper, iterations)`. One fused pass per iteration computes `B x`, the ratio
/// bounds `max/min (Bx)_i / x_i` and the maximum used to renormalise.
pub(crate) fn collatz_wielandt(
    n: usize,
    row: impl Fn(usize, &[f64]) -> f64,
    max_iterations: usize,
    tol: f64,
) -> (f64, f64, Vec<f64>, usize) {
    collatz_wielandt_from(vec![1.0; n], row, max_iterations, tol)
}

/// [`collatz_wielandt`] from the positive start vector `x`.
pub(crate) fn collatz_wielandt_from(
    mut x: Vec<f64>,
    row: impl Fn(usize, &[f64]) -> f64,
    max_iterations: usize,
    tol: f64,
) -> (f64, f64, Vec<f64>, usize) {
    let n = x.len();
    let mut y = vec![0.0; n];
    let mut best_x = x.clone();
    let (mut upper, mut lower) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut iters = 0;
    for k in 0..=max_iterations {
        let (mut u, mut l, mut ymax) = (f64::NEG_INFINITY, f64::INFINITY, 0.0f64);
        for i in 0..n {
            let yi = row(i, &x);
            let r = yi / x[i];
            u = u.max(r);
            l = l.min(r);
            ymax = ymax.max(yi);
            y[i] = yi;
        }
        iters = k;
        if u < upper {
            upper = u;
            best_x.copy_from_slice(&x);
        }
        lower = lower.max(l);
        if upper - lower <= tol || !(ymax > 0.0 && ymax.is_finite()) {
            break;
        }
        let inv = 1.0 / ymax;
        for i in 0..n {
            // Keep x strictly positive even if a component underflows.
            x[i] = (y[i] * inv).max(f64::MIN_POSITIVE);
        }
    }
    (upper, lower, best_x, iters)
}

/// The rate certified by a given `x > 0`: `min_i (β_i x_i − Σ_j γ_ij x_j) / x_i`. Any positive
/// result proves the network contracts at that rate in the norm `max_i |y_i| / x_i`.
///
/// # Errors
/// [`ComposeError::DimensionMismatch`]; [`ComposeError::NonFinite`] or a non-positive entry of
/// `x` ([`ComposeError::NonPositiveRate`] naming `x`).
pub fn metzler_rate(net: &Network, x: &[f64]) -> Result<f64, ComposeError> {
    let n = net.len();
    if x.len() != n {
        return Err(ComposeError::DimensionMismatch { name: "x", expected: n, got: x.len() });
    }
    if let Some(&v) = x.iter().find(|v| !(v.is_finite() && **v > 0.0)) {
        return Err(ComposeError::NonPositiveRate { name: "x", value: v });
    }
    let mut y = vec![0.0; n];
    net.coupling_times(x, &mut y);
    Ok((0..n).map(|i| net.rates()[i] - y[i] / x[i]).fold(f64::INFINITY, f64::min))
}

/// The lower triangle of `S = diag β − sym Γ_off` in CSC form, with the position of each
/// diagonal entry.
struct SymmetricMatrix {
    symbolic: SymbolicSparseColMat<usize>,
    values: Vec<f64>,
    diag: Vec<usize>,
}

fn symmetric_lower(net: &Network) -> Result<SymmetricMatrix, ComposeError> {
    let n = net.len();
    let mut entries: Vec<(usize, usize, f64)> = Vec::with_capacity(n + net.edges());
    for i in 0..n {
        entries.push((i, i, net.rates()[i]));
        for (j, g) in net.row(i) {
            entries.push((i.min(j), i.max(j), -0.5 * g));
        }
    }
    let (col_ptr, row_idx, values) = crate::network::compress(entries, n);
    // Rows within a column are sorted and >= the column, so the diagonal comes first.
    let diag = col_ptr[..n].to_vec();
    let symbolic = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
    Ok(SymmetricMatrix { symbolic, values, diag })
}

/// One Cholesky test per `μ` on the fixed pattern, reusing the symbolic factorisation.
struct CholeskyTest {
    m: SymmetricMatrix,
    symbolic_llt: SymbolicLlt<usize>,
}

impl CholeskyTest {
    fn new(net: &Network) -> Result<Self, ComposeError> {
        let m = symmetric_lower(net)?;
        let symbolic_llt = SymbolicLlt::try_new(m.symbolic.as_ref(), Side::Lower)
            .map_err(|e| ComposeError::Numerical(format!("symbolic Cholesky: {e:?}")))?;
        Ok(Self { m, symbolic_llt })
    }

    /// `true` iff `S − μ I` has a Cholesky factorisation (is positive definite).
    fn at_least(&self, mu: f64) -> bool {
        let mut values = self.m.values.clone();
        for &d in &self.m.diag {
            values[d] -= mu;
        }
        let mat = SparseColMat::new(self.m.symbolic.clone(), values);
        Llt::try_new_with_symbolic(self.symbolic_llt.clone(), mat.as_ref(), Side::Lower).is_ok()
    }
}

/// Is the symmetric bound at least `μ`, i.e. is `diag β − sym Γ_off − μ I` positive definite?
/// Decided by one sparse Cholesky factorisation (faer).
///
/// # Errors
/// [`ComposeError::NonFinite`] for a NaN `μ`; [`ComposeError::Numerical`] if the symbolic
/// factorisation fails (out of memory).
pub fn symmetric_rate_at_least(net: &Network, mu: f64) -> Result<bool, ComposeError> {
    crate::finite("mu", mu)?;
    Ok(CholeskyTest::new(net)?.at_least(mu))
}

/// Certify a (large, sparse) network: the Collatz–Wielandt rate from power iteration on
/// `Γ + cI` (`c = max β + 1`, so the operator is nonnegative with a positive diagonal), the
/// optional Cholesky bisection on the symmetric bound, and a certified lower bound on the
/// critical coupling scale. `O(iterations · nnz)` plus the factorisations.
///
/// # Errors
/// [`ComposeError::NonFinite`] for a non-finite tolerance; [`ComposeError::Numerical`] from a
/// factorisation.
pub fn certify_sparse(
    net: &Network,
    opts: &SparseOptions,
) -> Result<SparseCertificate, ComposeError> {
    crate::finite("tolerance", opts.tolerance)?;
    let n = net.len();
    let beta = net.rates();
    let bmax = beta.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b));
    let c = bmax + 1.0;
    let tol = opts.tolerance * bmax.abs().max(1.0);
    let (upper, lower, x, iterations) = collatz_wielandt(
        n,
        |i, x| net.row_dot(i, x) + (c - beta[i]) * x[i],
        opts.max_iterations,
        tol,
    );
    // ρ(Γ + cI) <= upper  =>  −α(Γ) >= c − upper. Recompute it exactly from x to avoid
    // relying on the iteration's arithmetic.
    let metzler = metzler_rate(net, &x)?;
    let metzler_upper = c - lower;
    let xmax = x.iter().fold(0.0f64, |a, &v| a.max(v));
    let certificate: Vec<f64> = x.iter().map(|v| v / xmax).collect();
    let _ = upper;

    let symmetric_rate = if opts.cholesky_steps > 0 {
        let test = CholeskyTest::new(net)?;
        // Gershgorin: λ_min(S) >= min_i (β_i − Σ_j |S_ij|), certified without factorising.
        let mut radius = vec![0.0; n];
        for i in 0..n {
            for (j, g) in net.row(i) {
                radius[i] += 0.5 * g;
                radius[j] += 0.5 * g;
            }
        }
        let mut lo = (0..n).map(|i| beta[i] - radius[i]).fold(f64::INFINITY, f64::min);
        let mut hi = beta.iter().fold(f64::INFINITY, |a, &b| a.min(b));
        for _ in 0..opts.cholesky_steps {
            let mid = 0.5 * (lo + hi);
            if test.at_least(mid) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(lo)
    } else {
        None
    };

    let critical_scale = if beta.iter().any(|&b| b <= 0.0) {
        0.0
    } else if net.edges() == 0 {
        f64::INFINITY
    } else {
        let (u, _, _, _) = collatz_wielandt(
            n,
            |i, x| net.row_dot(i, x) / beta[i] + x[i],
            opts.max_iterations,
            opts.tolerance,
        );
        // ρ(D⁻¹Γ_off) <= u − 1.
        if u > 1.0 { 1.0 / (u - 1.0) } else { f64::INFINITY }
    };

    let (rate, method) = match symmetric_rate {
        Some(s) if s > metzler => (s, Method::SymmetricCholesky),
        _ => (metzler, Method::CollatzWielandt),
    };
    Ok(SparseCertificate {
        rate,
        method,
        metzler_rate: metzler,
        metzler_upper,
        certificate,
        iterations,
        symmetric_rate,
        critical_scale,
    })
}
