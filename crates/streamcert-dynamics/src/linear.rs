//! Linear time-invariant systems `dx = (A x + B u) dt + E dη`, `y = C x`.

use crate::{Dynamics, DynamicsError};

/// A linear system `ẋ = A x + B u + E η`, `y = C x` (all matrices dense, row-major).
///
/// Used as the known-answer system of tests and calibration studies: its Jacobian is `A`
/// everywhere, so the true closed-loop rate under `u = K y` is
/// `−λ_max(sym(A + B K C))`.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearSystem {
    n: usize,
    m: usize,
    p: usize,
    q: usize,
    a: Vec<f64>,
    b: Vec<f64>,
    c: Vec<f64>,
    e: Vec<f64>,
}

impl LinearSystem {
    /// Build from row-major `A` (n×n), `B` (n×m), `C` (p×n) and `E` (n×q).
    ///
    /// # Errors
    /// [`DynamicsError::DimensionMismatch`] when a matrix length does not match the
    /// dimensions; [`DynamicsError::NonFinite`] for a NaN or infinite entry.
    ///
    /// ```
    /// use streamcert_dynamics::{LinearSystem, DynamicsError};
    /// // ẏ = 0.5 y + u + w
    /// let sys = LinearSystem::new(1, 1, 1, 1, vec![0.5], vec![1.0], vec![1.0], vec![1.0])?;
    /// assert!(LinearSystem::new(1, 1, 1, 1, vec![0.5, 0.0], vec![1.0], vec![1.0], vec![1.0])
    ///     .is_err());
    /// # Ok::<(), DynamicsError>(())
    /// ```
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        n: usize,
        m: usize,
        p: usize,
        q: usize,
        a: Vec<f64>,
        b: Vec<f64>,
        c: Vec<f64>,
        e: Vec<f64>,
    ) -> Result<Self, DynamicsError> {
        for (name, mat, len) in
            [("A", &a, n * n), ("B", &b, n * m), ("C", &c, p * n), ("E", &e, n * q)]
        {
            if mat.len() != len {
                return Err(DynamicsError::DimensionMismatch {
                    name,
                    expected: len,
                    got: mat.len(),
                });
            }
            for &v in mat.iter() {
                crate::finite(name, v)?;
            }
        }
        Ok(Self { n, m, p, q, a, b, c, e })
    }

    /// The state matrix `A` (row-major).
    #[must_use]
    pub fn a(&self) -> &[f64] {
        &self.a
    }
    /// The input matrix `B` (row-major).
    #[must_use]
    pub fn b(&self) -> &[f64] {
        &self.b
    }
    /// The output matrix `C` (row-major).
    #[must_use]
    pub fn c(&self) -> &[f64] {
        &self.c
    }
}

impl Dynamics for LinearSystem {
    fn state_dim(&self) -> usize {
        self.n
    }
    fn input_dim(&self) -> usize {
        self.m
    }
    fn output_dim(&self) -> usize {
        self.p
    }
    fn disturbance_dim(&self) -> usize {
        self.q
    }
    fn drift(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        for i in 0..self.n {
            let ax: f64 = (0..self.n).map(|j| self.a[i * self.n + j] * x[j]).sum();
            let bu: f64 = (0..self.m).map(|j| self.b[i * self.m + j] * u[j]).sum();
            dx[i] = ax + bu;
        }
    }
    fn output(&self, x: &[f64], y: &mut [f64]) {
        for (i, yi) in y.iter_mut().enumerate().take(self.p) {
            *yi = (0..self.n).map(|j| self.c[i * self.n + j] * x[j]).sum();
        }
    }
    fn disturbance_gain(&self) -> &[f64] {
        &self.e
    }
    fn jacobian(&self, _t: f64, _x: &[f64], _u: &[f64], jac: &mut [f64]) -> bool {
        jac.copy_from_slice(&self.a);
        true
    }
}
