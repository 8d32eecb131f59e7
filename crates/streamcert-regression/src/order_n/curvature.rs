//! [`CurvatureTest`]: whether the loop is linear over the window's region, tested at order
//! `n` by the square and the cube of the output where the model's static term enters.

use super::{OrderNRecord, RegressorTest};
use crate::RegressionError;

/// The nonlinearity test of order `n` on a run of rows: the fit of [`OrderNRecord::fit`] with
/// two more regressors, the square and the cube of the output's excursion `y − y_0` (`y_0` the
/// record's first sample) integrated with the weights of the output regressor of index `n`,
/// the one whose coefficient `a_n` is the plant's static term:
///
/// ```text
/// z_r = φ_rᵀ θ + g_2 ⟨w^y_n, (y − y_0)²⟩_r + g_3 ⟨w^y_n, (y − y_0)³⟩_r + ε_r.
/// ```
///
/// A plant `y⁽ⁿ⁾ + a_1 y⁽ⁿ⁻¹⁾ + … + f(y) = b(u) + c` whose static term `f` bends over the region
/// the window explored (a valve's characteristic, a tank's outflow `∝ √level`, a spring that
/// stiffens) has `g_2, g_3 ≠ 0`: its slope, and with it the closed loop's rate, varies over the
/// region, and one linear fit certifies its average. Under linear dynamics of order at most
/// `n` (white sensor noise, white noise where the intercept enters), `g = 0`. With the
/// intercept the test does not depend on `y_0` (the square and the cube of `y − y_0` span, with
/// `1` and `y`, the same functions as those of `y`). A nonlinearity in the damping terms only
/// (`ẏ²`) or a state dependence the square and the cube of the output do not carry is not
/// seen.
///
/// `W = ĝᵀ (Var ĝ)⁻¹ ĝ` ([`RegressorTest::statistic`]), with `Var ĝ` the model-structured
/// covariance of the larger fit ([`OrderNFit`](super::OrderNFit)); under the model
/// `W / 2 ~ F(2, ν)` when the noise's scale is estimated with `ν` degrees of freedom.
/// `coefficients` are `ĝ = (ĝ_2, ĝ_3)`, those of the square and of the cube.
pub type CurvatureTest = RegressorTest;

impl OrderNRecord {
    /// The curvature test ([`CurvatureTest`]) on the rows `rows`.
    ///
    /// # Errors
    /// As [`OrderNRecord::fit`], for the larger fit (`d + 2` coefficients).
    pub fn curvature_test(
        &self,
        rows: std::ops::Range<usize>,
    ) -> Result<CurvatureTest, RegressionError> {
        let (n, span, d) = (self.n, self.span, self.n * (1 + self.m) + 1);
        let count = rows.end.saturating_sub(rows.start);
        if rows.end > self.rows() || count <= d + 2 {
            return Err(RegressionError::InsufficientData {
                needed: d + 3 + span,
                got: count.min(self.rows().saturating_sub(rows.start)) + span,
            });
        }
        let wide = d + 2;
        let mut phi = vec![0.0; count * wide];
        for (i, row) in phi.chunks_exact_mut(wide).enumerate() {
            let r = rows.start + i;
            row[..d].copy_from_slice(&self.phi[r * d..(r + 1) * d]);
            // The weights of the output regressor `k = n` on the span's samples.
            let w = self.wy(r, n - 1);
            let (mut square, mut cube) = (0.0, 0.0);
            for (wi, y) in w.iter().zip(&self.ys[r..=r + span]) {
                let y2 = y * y;
                square += wi * y2;
                cube += wi * y2 * y;
            }
            (row[d], row[d + 1]) = (square, cube);
        }
        self.regressor_test(rows, &phi, d)
    }
}
