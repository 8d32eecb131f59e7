//! [`PastRowTest`]: whether the order-`n` model holds the output, tested by what it cannot
//! explain: the regressand of the row that ends just before a row's span, as one more
//! regressor.

use super::OrderNRecord;
use crate::RegressionError;

/// The hidden-dynamics test of order `n` on a run of rows: the fit of
/// [`OrderNRecord::fit`] with one more regressor, the *past row's regressand*
/// `z_{r − n h − 1} = L̄ⁿ n! y[τ_0..τ_n]` of the row that ends at the sample before row `r`'s
/// span begins, and its coefficient `γ`.
///
/// When the output is linear of order at most `n` (with white sensor noise and white noise
/// where the intercept enters), row `r`'s residual depends only on the noise inside its span,
/// and the past row uses only samples before it: `γ = 0`. A state the model of order `n` does
/// not hold (a lag beyond the order, a resonance, a transport delay) leaves in the residual a
/// response to the past that the past row's regressand predicts: `γ ≠ 0`. It is the order-`n`
/// form of the first order's past-increment guard. It needs no fit of order `n + 1`, whose
/// rows are not identified when order `n` holds (every `(s + λ) p(s)` fits them), so it is
/// available at every order, the largest included.
///
/// `W = γ̂ᵀ (Var γ̂)⁻¹ γ̂`, with `Var γ̂` the model-structured covariance of the larger fit
/// ([`OrderNFit`](super::OrderNFit)): under the model, `W / q ~ F(q, ν)` (`q = n + 1`) when the
/// noise's scale is estimated with `ν` degrees of freedom. `coefficients` are `γ̂`, those of
/// the past row's regressand and of its `n` output regressors; `rows` are those of the range
/// that have a past row in the record.
pub type PastRowTest = RegressorTest;

/// A Wald test of `q` extra regressors in a larger fit of order `n` (the model guards'
/// [`PastRowTest`] and [`CurvatureTest`](super::CurvatureTest)): their coefficients `γ̂`,
/// the model-structured covariance of those coefficients, and the rows fitted.
#[derive(Debug, Clone, PartialEq)]
pub struct RegressorTest {
    /// `γ̂`: the extra regressors' coefficients.
    pub coefficients: Vec<f64>,
    /// `Var γ̂` (model-structured), `q × q` row-major.
    pub covariance: Vec<f64>,
    /// The rows of the larger fit.
    pub rows: usize,
}

impl RegressorTest {
    /// The Wald statistic `W = γ̂ᵀ (Var γ̂)⁻¹ γ̂` (`+∞` when the covariance is not positive
    /// definite).
    #[must_use]
    pub fn statistic(&self) -> f64 {
        let q = self.coefficients.len();
        let mut l = self.covariance.clone();
        if !crate::linalg::cholesky_in_place(&mut l, q) {
            return f64::INFINITY;
        }
        let mut x = self.coefficients.clone();
        crate::linalg::cholesky_solve_in_place(&l, q, &mut x);
        x.iter().zip(&self.coefficients).map(|(a, b)| a * b).sum()
    }
}

impl OrderNRecord {
    /// The past-row test ([`PastRowTest`]) on the rows `rows`: those of them whose past row is
    /// in the record (row `r >= n h + 1`) are fitted with the past row's regressand as one more
    /// regressor.
    ///
    /// # Errors
    /// As [`OrderNRecord::fit`], for the larger fit (`d + 1` coefficients).
    pub fn past_row_test(
        &self,
        rows: std::ops::Range<usize>,
    ) -> Result<PastRowTest, RegressionError> {
        let (span, d) = (self.span, self.n * (1 + self.m) + 1);
        let first = rows.start.max(span + 1);
        let count = rows.end.saturating_sub(first);
        if rows.end > self.rows() || count <= d + 1 {
            return Err(RegressionError::InsufficientData {
                needed: d + 2 + 2 * span + 1,
                got: count + 2 * span + 1,
            });
        }
        let n = self.n;
        let wide = d + 1 + n;
        let mut phi = vec![0.0; count * wide];
        for (i, row) in phi.chunks_exact_mut(wide).enumerate() {
            let r = first + i;
            let past = r - span - 1;
            row[..d].copy_from_slice(&self.phi[r * d..(r + 1) * d]);
            row[d] = self.z[past];
            row[d + 1..].copy_from_slice(&self.phi[past * d..past * d + n]);
        }
        self.regressor_test(first..rows.end, &phi, d)
    }

    /// The larger fit of the rows `rows` on `phi` (their `d` regressors, then the extra ones,
    /// row-major) with the model-structured covariance, and the test of the extra
    /// regressors' coefficients.
    pub(super) fn regressor_test(
        &self,
        rows: std::ops::Range<usize>,
        phi: &[f64],
        d: usize,
    ) -> Result<RegressorTest, RegressionError> {
        let count = rows.len();
        let wide = phi.len() / count.max(1);
        let z = &self.z[rows.clone()];
        let (theta, ginv) = self.solve(phi, z, wide)?;
        let resid: Vec<f64> = phi
            .chunks_exact(wide)
            .zip(z)
            .map(|(row, zr)| zr - row.iter().zip(&theta).map(|(x, t)| x * t).sum::<f64>())
            .collect();
        let (covariance, _, _) = self.structured_covariance(rows.start, phi, &theta, &resid, &ginv);
        let q = wide - d;
        let covariance = (0..q * q).map(|i| covariance[(d + i / q) * wide + d + i % q]).collect();
        Ok(RegressorTest { coefficients: theta[d..].to_vec(), covariance, rows: count })
    }
}
