//! The gain-matrix description of a network of `N` subsystems.

use serde::{Deserialize, Serialize};

use crate::{ComposeError, finite, gain};

/// Local rates `β_i` and coupling bounds `γ_ij >= 0` (`γ_ij` bounds how subsystem `j` drives
/// subsystem `i`). Stored as a compressed sparse row structure of the off-diagonal part; the
/// gain matrix is `Γ = −diag β + Γ_off`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Network {
    beta: Vec<f64>,
    row_ptr: Vec<usize>,
    col: Vec<usize>,
    val: Vec<f64>,
}

impl Network {
    /// From local rates and `(i, j, γ_ij)` triplets. Repeated `(i, j)` pairs are summed (two
    /// coupling terms between the same pair add their bounds); zero gains are dropped.
    ///
    /// # Errors
    /// [`ComposeError::Empty`], [`ComposeError::NonFinite`] for a rate or gain,
    /// [`ComposeError::NegativeGain`], [`ComposeError::InvalidEdge`] for an index out of range
    /// or a self-loop.
    ///
    /// ```
    /// use streamcert_compose::{ComposeError, Network};
    /// let net = Network::new(vec![1.0, 2.0], &[(0, 1, 0.5)])?;
    /// assert_eq!(net.len(), 2);
    /// assert!(matches!(Network::new(vec![1.0], &[(0, 0, 0.5)]), Err(ComposeError::InvalidEdge { .. })));
    /// # Ok::<(), ComposeError>(())
    /// ```
    pub fn new(beta: Vec<f64>, edges: &[(usize, usize, f64)]) -> Result<Self, ComposeError> {
        let n = beta.len();
        if n == 0 {
            return Err(ComposeError::Empty);
        }
        for &b in &beta {
            finite("beta", b)?;
        }
        let mut e: Vec<(usize, usize, f64)> = Vec::with_capacity(edges.len());
        for &(i, j, g) in edges {
            if i >= n || j >= n || i == j {
                return Err(ComposeError::InvalidEdge { i, j, n });
            }
            gain("gamma", g)?;
            if g > 0.0 {
                e.push((i, j, g));
            }
        }
        let (row_ptr, col, val) = compress(e, n);
        for &v in &val {
            finite("gamma (summed)", v)?;
        }
        Ok(Self { beta, row_ptr, col, val })
    }

    /// From local rates and a dense row-major `N × N` gain matrix whose off-diagonal entry
    /// `(i, j)` is `γ_ij`; the diagonal must be zero.
    ///
    /// # Errors
    /// As [`new`](Self::new), plus [`ComposeError::DimensionMismatch`] and
    /// [`ComposeError::InvalidEdge`] for a non-zero diagonal entry.
    pub fn from_dense(beta: &[f64], gamma: &[f64]) -> Result<Self, ComposeError> {
        let n = beta.len();
        if gamma.len() != n * n {
            return Err(ComposeError::DimensionMismatch {
                name: "gains",
                expected: n * n,
                got: gamma.len(),
            });
        }
        let mut edges = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let g = gamma[i * n + j];
                if i == j {
                    finite("gamma", g)?;
                    if g != 0.0 {
                        return Err(ComposeError::InvalidEdge { i, j, n });
                    }
                } else if g != 0.0 || !g.is_finite() {
                    edges.push((i, j, g));
                }
            }
        }
        Self::new(beta.to_vec(), &edges)
    }

    /// Number of subsystems `N`.
    #[must_use]
    pub fn len(&self) -> usize {
        self.beta.len()
    }

    /// `true` for a network without subsystems (never, after validation).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.beta.is_empty()
    }

    /// Local rates `β`.
    #[must_use]
    pub fn rates(&self) -> &[f64] {
        &self.beta
    }

    /// Number of coupling edges (after summing duplicates).
    #[must_use]
    pub fn edges(&self) -> usize {
        self.val.len()
    }

    /// The edges of row `i`: `(j, γ_ij)`.
    pub fn row(&self, i: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let r = self.row_ptr[i]..self.row_ptr[i + 1];
        self.col[r.clone()].iter().copied().zip(self.val[r].iter().copied())
    }

    /// `(Γ_off x)_i = Σ_j γ_ij x_j` for one row.
    #[inline]
    #[must_use]
    pub fn row_dot(&self, i: usize, x: &[f64]) -> f64 {
        let r = self.row_ptr[i]..self.row_ptr[i + 1];
        self.col[r.clone()].iter().zip(&self.val[r]).map(|(&j, &g)| g * x[j]).sum()
    }

    /// `y ← Γ_off x` (the coupling part only).
    pub fn coupling_times(&self, x: &[f64], y: &mut [f64]) {
        for (i, yi) in y.iter_mut().enumerate() {
            *yi = self.row_dot(i, x);
        }
    }

    /// The dense gain matrix `Γ` (row-major), for small networks and tests.
    #[must_use]
    pub fn dense_gain_matrix(&self) -> Vec<f64> {
        let n = self.len();
        let mut m = vec![0.0; n * n];
        for i in 0..n {
            m[i * n + i] = -self.beta[i];
            for (j, g) in self.row(i) {
                m[i * n + j] += g;
            }
        }
        m
    }
}

/// Compress `(outer, inner, value)` entries into `(ptr, inner indices, values)` (CSR when
/// `outer` is the row, CSC when it is the column): a stable sort by `(outer, inner)`, then
/// duplicates summed in input order, so the sums are deterministic.
pub(crate) fn compress(
    mut entries: Vec<(usize, usize, f64)>,
    n: usize,
) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
    entries.sort_by_key(|a| (a.0, a.1));
    let mut ptr = vec![0usize; n + 1];
    let mut idx = Vec::with_capacity(entries.len());
    let mut val: Vec<f64> = Vec::with_capacity(entries.len());
    let mut last: Option<(usize, usize)> = None;
    for (o, i, v) in entries {
        if last == Some((o, i)) {
            if let Some(x) = val.last_mut() {
                *x += v;
            }
            continue;
        }
        last = Some((o, i));
        ptr[o + 1] += 1;
        idx.push(i);
        val.push(v);
    }
    for k in 0..n {
        ptr[k + 1] += ptr[k];
    }
    (ptr, idx, val)
}
