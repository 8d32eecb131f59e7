//! [`OrderNFit`]: the batch estimator of order `n`, with the coefficients' covariance from the
//! residual's known structure.

use super::rows::{RowWeights, same_offsets};
use super::variance::sandwich;
use super::{OrderNConfig, check_sample};
use crate::RegressionError;
use crate::linalg::{cholesky_in_place, cholesky_solve_in_place, eig_work_len, psd_eig_extremes};

/// The order-`n` coefficients of one record, fitted by least squares over every row, and their
/// covariance.
///
/// ## Why not `s² (ΦᵀΦ)⁻¹`
///
/// Consecutive rows share `n h` of their `n h + 1` samples, so their residuals are correlated:
/// white sensor noise `e` on `y` leaves the row residual `ε_k = Σ_j w_{k,j} e_j`, with
/// `w_k = wz_k − Σ_i a_i wy_{k,i}` (the regressand's and the output regressors' weights on the
/// span's samples). That residual is over-differenced (`Σ_j w_{k,j} = a_n L̄ⁿ`, near zero): its
/// autocorrelation is strongly negative at lags up to `n h`. Given the rows, the estimation
/// error is exactly `θ̂ − θ = G⁻¹ Σ_j e_j Ψ_j` with `G = ΦᵀΦ` and `Ψ_j = Σ_k w_{k,j} φ_k`, so
/// `Var θ̂ = σ_e² G⁻¹ ΨᵀΨ G⁻¹`. The covariance that uses only the residual's variance ignores
/// this structure and is 1.5–4× too wide here; a HAC estimate from the few independent spans
/// of a window is too noisy in the tail a split risk asks for.
///
/// ## The model-structured covariance
///
/// The fit allows two white noises: `e` on the sensor (variance `σ_e²` per sample) and `v`
/// entering the plant where `c` enters (intensity `σ_v²`; the row's response is
/// `L̄ⁿ ∫ M v`, discretised per sample interval). The two variances are fitted, non-negative,
/// by least squares of the residuals' autocovariances `γ̂(ℓ) = Σ_k r_k r_{k+ℓ} / (N − ℓ)` at the
/// lags `ℓ = 0..n h` on the two shapes the noises give, `s(ℓ) = Σ_o w̄_o w̄_{o+ℓ}` (`w̄` the
/// rows' mean kernel; the rows' own kernels on equal spacing). Then
///
/// ```text
/// V = G⁻¹ (σ_e² Ψ_eᵀΨ_e + σ_v² Ψ_vᵀΨ_v) G⁻¹ · N / (N − d).
/// ```
///
/// It is valid for white sensor noise and white noise at the intercept's position; other noise
/// (coloured sensor noise, process noise entering elsewhere) would need its own kernel. With
/// `u` the input applied (known exactly), the sensor noise that re-enters the loop through `u`
/// biases least squares by `O(σ² dt / L^{2n−1})`, which a long horizon keeps small.
///
/// ```
/// use streamcert_regression::{LoopModel, OrderNConfig, OrderNFit};
/// // ÿ + 3 ẏ + 2 y = u: y = x₀ − x₁ with the modes e^{−t}, e^{−2t}, at 100 Hz.
/// let (dt, mut x) = (0.01f64, [0.0f64, 0.0]);
/// let (mut t, mut y, mut u) = (vec![], vec![], vec![]);
/// for k in 0..2000 {
///     let uk = if (k / 37) % 2 == 0 { 1.0 } else { -1.0 };
///     (t.push(k as f64 * dt), y.push(x[0] - x[1]), u.push(uk));
///     x[0] = (-dt).exp() * x[0] + (1.0 - (-dt).exp()) * uk;
///     x[1] = (-2.0 * dt).exp() * x[1] + (1.0 - (-2.0 * dt).exp()) / 2.0 * uk;
/// }
/// let cfg = OrderNConfig::new(LoopModel::of_order(2).unwrap(), 1, 400, 20);
/// let fit = OrderNFit::fit(&cfg, &t, &y, &u)?;
/// // θ = (a₁, a₂, b₁, b₂, c) = (3, 2, 0, 1, 0).
/// assert!((fit.theta()[0] - 3.0).abs() < 1e-3 && (fit.theta()[3] - 1.0).abs() < 1e-3);
/// // The closed loop under u = −y: s² + 3 s + 3.
/// let closed = fit.closed_loop(&[-1.0])?;
/// assert!((closed.beta[1] - 3.0).abs() < 1e-3);
/// # Ok::<(), streamcert_regression::RegressionError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct OrderNFit {
    pub(super) n: usize,
    pub(super) m: usize,
    pub(super) rows: usize,
    pub(super) theta: Vec<f64>,
    pub(super) covariance: Vec<f64>,
    pub(super) sensor_variance: f64,
    pub(super) equation_variance: f64,
    pub(super) residual_rms: f64,
}

/// The closed loop's characteristic coefficients under `u = K y` and their covariance: the
/// polynomial `p(s) = sⁿ + β_1 sⁿ⁻¹ + … + β_n` with `β = a − Σ_inputs K_j b_j = T θ`,
/// `Σ_β = T V Tᵀ`.
#[derive(Debug, Clone, PartialEq)]
pub struct ClosedLoop {
    /// `β_1..β_n`.
    pub beta: Vec<f64>,
    /// `Σ_β`, `n × n` row-major.
    pub covariance: Vec<f64>,
}

impl ClosedLoop {
    /// `(β − β̂)ᵀ Σ_β⁻¹ (β − β̂)`: the squared distance of `beta` from the estimate in the
    /// covariance's metric (`χ²_n`-distributed at the truth for Gaussian errors). `None` when
    /// `Σ_β` is not positive definite.
    #[must_use]
    pub fn mahalanobis(&self, beta: &[f64]) -> Option<f64> {
        let n = self.beta.len();
        let mut l = self.covariance.clone();
        if beta.len() != n || !cholesky_in_place(&mut l, n) {
            return None;
        }
        let mut x: Vec<f64> = beta.iter().zip(&self.beta).map(|(b, e)| b - e).collect();
        let diff = x.clone();
        cholesky_solve_in_place(&l, n, &mut x);
        Some(x.iter().zip(&diff).map(|(a, b)| a * b).sum())
    }
}

/// The rows of one record, built once, for fits over any run of consecutive rows (a look's
/// window): one row ends at every sample from the `n h + 1`-th; row `r` ends at sample
/// `r + n h`.
#[derive(Debug, Clone, PartialEq)]
pub struct OrderNRecord {
    pub(super) n: usize,
    pub(super) m: usize,
    pub(super) span: usize,
    pub(super) min_excitation_ratio: f64,
    pub(super) origin: Vec<f64>,
    pub(super) phi: Vec<f64>,
    pub(super) z: Vec<f64>,
    /// The rows' weights: each distinct set once (one set on equal spacing), and the set of
    /// each row.
    pub(super) weights: Vec<RowWeights>,
    pub(super) weights_of: Vec<usize>,
    /// The output's samples relative to the first (`y − origin[0]`), for the curvature
    /// test's regressors.
    pub(super) ys: Vec<f64>,
}

impl OrderNRecord {
    /// The rows of the record `t` (increasing), `y` (one output), `u` (`t.len() × m`,
    /// row-major), relative to its first sample. `cfg.window`, `min_rows` and
    /// `refresh_period` belong to the streaming estimator and are not used.
    ///
    /// # Errors
    /// - [`RegressionError::InvalidConfig`] for a bad configuration;
    /// - [`RegressionError::DimensionMismatch`], [`RegressionError::NonFinite`],
    ///   [`RegressionError::NonIncreasingTime`] for a bad record.
    pub fn new(
        cfg: &OrderNConfig,
        t: &[f64],
        y: &[f64],
        u: &[f64],
    ) -> Result<Self, RegressionError> {
        let mut probe = *cfg;
        probe.window = probe.window.max(cfg.width());
        probe.min_rows = probe.min_rows.clamp(cfg.width(), probe.window);
        probe.refresh_period = probe.refresh_period.clamp(1, probe.window);
        probe.validate()?;
        let shape = cfg.shape();
        let (n, m, span, d) = (shape.n, shape.m, shape.span(), shape.width());
        if y.len() != t.len() {
            return Err(RegressionError::DimensionMismatch {
                field: "y",
                expected: t.len(),
                got: y.len(),
            });
        }
        if u.len() != t.len() * m {
            return Err(RegressionError::DimensionMismatch {
                field: "u",
                expected: t.len() * m,
                got: u.len(),
            });
        }
        for k in 0..t.len() {
            let previous = k.checked_sub(1).map(|p| t[p]);
            check_sample(previous, t[k], y[k], &u[k * m..(k + 1) * m], m)?;
        }
        let rows = t.len().saturating_sub(span);
        // Relative to the first sample: only the intercept sees the origin.
        let mut origin = vec![0.0; 1 + m];
        if let (Some(&y0), Some(u0)) = (y.first(), u.get(..m)) {
            origin[0] = y0;
            origin[1..].copy_from_slice(u0);
        }
        let ys: Vec<f64> = y.iter().map(|v| v - origin[0]).collect();
        let us: Vec<f64> = u.iter().enumerate().map(|(i, v)| v - origin[1 + i % m]).collect();
        let mut weights = RowWeights::new(shape);
        let mut record = Self {
            n,
            m,
            span,
            min_excitation_ratio: cfg.min_excitation_ratio,
            origin,
            phi: vec![0.0; rows * d],
            z: vec![0.0; rows],
            weights: Vec::new(),
            weights_of: vec![0; rows],
            ys: Vec::new(),
        };
        // The weights depend on the span's times relative to its first: a row whose times
        // match the last filled row's to `1e-12` of the span (equal sampling, up to the
        // rounding of the times) takes its weights, a change far below the fill's own
        // accuracy; any other row (jitter, a gap) is filled anew.
        let mut filled: Option<usize> = None;
        for r in 0..rows {
            let s = r..r + span + 1;
            let same = filled.is_some_and(|q| same_offsets(&t[q..=q + span], &t[s.clone()]));
            if !same {
                weights.fill(shape, &t[s.clone()]);
                filled = Some(r);
            }
            let row = &mut record.phi[r * d..(r + 1) * d];
            record.z[r] = weights.apply(shape, &ys[s], &us[r * m..(r + span + 1) * m], row);
            if !same {
                record.weights.push(weights.clone());
            }
            record.weights_of[r] = record.weights.len() - 1;
        }
        record.ys = ys;
        Ok(record)
    }

    /// The number of rows.
    #[must_use]
    pub fn rows(&self) -> usize {
        self.z.len()
    }

    /// Row `r`'s weights of the regressand on its span's samples.
    pub(super) fn wz(&self, r: usize) -> &[f64] {
        &self.weights[self.weights_of[r]].wz
    }

    /// Row `r`'s weights of the output regressor `k + 1` on its span's samples.
    pub(super) fn wy(&self, r: usize, k: usize) -> &[f64] {
        let span = self.span;
        &self.weights[self.weights_of[r]].wy[k * (span + 1)..(k + 1) * (span + 1)]
    }

    /// Row `r`'s response to white noise where the intercept enters, per sample interval.
    pub(super) fn wv(&self, r: usize) -> &[f64] {
        &self.weights[self.weights_of[r]].wv
    }

    /// Fit the consecutive rows `rows` (row `r` ends at sample `r + n h`).
    ///
    /// # Errors
    /// - [`RegressionError::InsufficientData`] when the range has no more than `d` rows (or
    ///   reaches past the record);
    /// - [`RegressionError::NotIdentified`] when the column-scaled Gram matrix has
    ///   `λ_min <= min_excitation_ratio · λ_max` (the inputs do not excite every coefficient).
    pub fn fit(&self, rows: std::ops::Range<usize>) -> Result<OrderNFit, RegressionError> {
        let (n, m, span) = (self.n, self.m, self.span);
        let d = n * (1 + m) + 1;
        let count = rows.end.saturating_sub(rows.start);
        if rows.end > self.rows() || count <= d {
            return Err(RegressionError::InsufficientData {
                needed: d + 1 + span,
                got: count.min(self.rows().saturating_sub(rows.start)) + span,
            });
        }
        let first = rows.start;
        let phi = &self.phi[first * d..rows.end * d];
        let z = &self.z[rows.clone()];

        let (theta, ginv) = self.solve(phi, z, d)?;
        let resid: Vec<f64> = phi
            .chunks_exact(d)
            .zip(z)
            .map(|(row, zr)| zr - row.iter().zip(&theta).map(|(x, t)| x * t).sum::<f64>())
            .collect();
        let residual_rms = (resid.iter().map(|r| r * r).sum::<f64>() / count as f64).sqrt();

        let (covariance, sensor_variance, equation_variance) =
            self.structured_covariance(first, phi, &theta, &resid, &ginv);
        let (theta, covariance) = self.in_plant_coordinates(theta, &covariance);
        Ok(OrderNFit {
            n,
            m,
            rows: count,
            theta,
            covariance,
            sensor_variance,
            equation_variance,
            residual_rms,
        })
    }

    /// `θ̂` and `G⁻¹` by least squares on the column-scaled Gram matrix, after the
    /// identification test.
    pub(super) fn solve(
        &self,
        phi: &[f64],
        z: &[f64],
        d: usize,
    ) -> Result<(Vec<f64>, Vec<f64>), RegressionError> {
        solve(phi, z, d, self.n, self.min_excitation_ratio)
    }

    /// `θ` and its covariance moved from the origin's coordinates to the plant's.
    fn in_plant_coordinates(&self, theta: Vec<f64>, covariance: &[f64]) -> (Vec<f64>, Vec<f64>) {
        in_plant_coordinates(&self.origin, self.n, self.m, theta, covariance)
    }
}

/// `θ̂` and `G⁻¹` by least squares of `z` on the rows `phi` (`d` columns, row-major) on the
/// column-scaled Gram matrix, after the identification test
/// (`λ_min > min_excitation_ratio · λ_max`; `n` the order, for the refusal's words).
pub(super) fn solve(
    phi: &[f64],
    z: &[f64],
    d: usize,
    n: usize,
    min_excitation_ratio: f64,
) -> Result<(Vec<f64>, Vec<f64>), RegressionError> {
    let mut g = vec![0.0; d * d];
    let mut rhs = vec![0.0; d];
    // The upper triangle over the rows in order, then mirrored (the same products).
    for (row, zr) in phi.chunks_exact(d).zip(z) {
        for (a, (ra, ga)) in row.iter().zip(g.chunks_exact_mut(d)).enumerate() {
            rhs[a] += ra * zr;
            for (gab, rb) in ga[a..].iter_mut().zip(&row[a..]) {
                *gab += ra * rb;
            }
        }
    }
    for a in 0..d {
        for b in 0..a {
            g[a * d + b] = g[b * d + a];
        }
    }
    solve_gram(&g, &rhs, d, n, min_excitation_ratio)
}

/// `θ̂ = G⁻¹ r` and `G⁻¹` from the Gram matrix `G = ΦᵀΦ` (`d × d`, symmetric) and `r = Φᵀz`,
/// on the column-scaled matrix, after the identification test.
pub(super) fn solve_gram(
    g: &[f64],
    rhs: &[f64],
    d: usize,
    n: usize,
    min_excitation_ratio: f64,
) -> Result<(Vec<f64>, Vec<f64>), RegressionError> {
    let scale: Vec<f64> = (0..d).map(|a| g[a * d + a].sqrt()).collect();
    if scale.iter().any(|s| !(*s > 0.0 && s.is_finite())) {
        return Err(RegressionError::NotIdentified("a regressor is zero over the rows".into()));
    }
    let gs: Vec<f64> = (0..d * d).map(|i| g[i] / (scale[i / d] * scale[i % d])).collect();
    let mut work = vec![0.0; eig_work_len(d)];
    let (lo, hi) = psd_eig_extremes(&gs, d, &mut work);
    if !(lo > min_excitation_ratio * hi) {
        return Err(RegressionError::NotIdentified(format!(
            "the column-scaled Gram matrix has λ_min/λ_max = {:.3e}, at most {:.1e}: the inputs do not excite every coefficient of order {n}",
            lo / hi,
            min_excitation_ratio
        )));
    }
    let mut l = gs.clone();
    if !cholesky_in_place(&mut l, d) {
        return Err(RegressionError::NotIdentified(
            "the Gram matrix is not positive definite".into(),
        ));
    }
    let mut theta: Vec<f64> = (0..d).map(|a| rhs[a] / scale[a]).collect();
    cholesky_solve_in_place(&l, d, &mut theta);
    for (th, s) in theta.iter_mut().zip(&scale) {
        *th /= s;
    }
    // G⁻¹ as columns, through the scaled factor: G⁻¹ = D⁻¹ Gs⁻¹ D⁻¹.
    let mut ginv = vec![0.0; d * d];
    for c in 0..d {
        let mut e = vec![0.0; d];
        e[c] = 1.0;
        cholesky_solve_in_place(&l, d, &mut e);
        for a in 0..d {
            ginv[a * d + c] = e[a] / (scale[a] * scale[c]);
        }
    }

    Ok((theta, ginv))
}

/// `θ` and its covariance moved from the coordinates of the origin `[y₀; u₀]` to the plant's:
/// `c = c' + a_n y₀ − Σ_j b_{j,n} u₀_j`.
pub(super) fn in_plant_coordinates(
    origin: &[f64],
    n: usize,
    m: usize,
    mut theta: Vec<f64>,
    covariance: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let d = theta.len();
    // Back to the plant's coordinates: c = c' + a_n y₀ − Σ_j b_{j,n} u₀_j.
    let mut map = vec![0.0; d * d];
    for a in 0..d {
        map[a * d + a] = 1.0;
    }
    map[(d - 1) * d + (n - 1)] = origin[0];
    for j in 0..m {
        map[(d - 1) * d + n + j * n + n - 1] = -origin[1 + j];
    }
    let shifted = theta.clone();
    for (a, th) in theta.iter_mut().enumerate() {
        *th = (0..d).map(|b| map[a * d + b] * shifted[b]).sum();
    }
    let covariance = sandwich(&map, covariance, d);
    (theta, covariance)
}

impl OrderNFit {
    /// Fit every row of the record `t` (increasing), `y` (one output), `u` (`t.len() × m`,
    /// row-major): [`OrderNRecord::new`] then [`OrderNRecord::fit`] over all its rows.
    ///
    /// # Errors
    /// As [`OrderNRecord::new`] and [`OrderNRecord::fit`].
    pub fn fit(
        cfg: &OrderNConfig,
        t: &[f64],
        y: &[f64],
        u: &[f64],
    ) -> Result<Self, RegressionError> {
        let record = OrderNRecord::new(cfg, t, y, u)?;
        record.fit(0..record.rows())
    }

    /// `θ̂ = (a_1..a_n, b_{1,1}..b_{1,n}, …, c)`.
    #[must_use]
    pub fn theta(&self) -> &[f64] {
        &self.theta
    }

    /// The covariance of [`theta`](Self::theta), `d × d` row-major (model-structured; see the
    /// type's docs).
    #[must_use]
    pub fn covariance(&self) -> &[f64] {
        &self.covariance
    }

    /// The order `n`.
    #[must_use]
    pub fn order(&self) -> usize {
        self.n
    }

    /// The rows fitted.
    #[must_use]
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// The fitted sensor-noise variance `σ_e²` (per sample, in the output's units squared).
    #[must_use]
    pub fn sensor_variance(&self) -> f64 {
        self.sensor_variance
    }

    /// The fitted intensity `σ_v²` of white noise at the intercept's position.
    #[must_use]
    pub fn equation_variance(&self) -> f64 {
        self.equation_variance
    }

    /// `√(Σ r_k² / N)` of the rows' residuals.
    #[must_use]
    pub fn residual_rms(&self) -> f64 {
        self.residual_rms
    }

    /// The closed loop under `u = K y` (`gain`: `m` values).
    ///
    /// # Errors
    /// [`RegressionError::DimensionMismatch`] when `gain` does not have `m` values.
    pub fn closed_loop(&self, gain: &[f64]) -> Result<ClosedLoop, RegressionError> {
        let (n, m) = (self.n, self.m);
        if gain.len() != m {
            return Err(RegressionError::DimensionMismatch {
                field: "gain",
                expected: m,
                got: gain.len(),
            });
        }
        let d = self.theta.len();
        let mut tmat = vec![0.0; n * d];
        for i in 0..n {
            tmat[i * d + i] = 1.0;
            for (j, k) in gain.iter().enumerate() {
                tmat[i * d + n + j * n + i] = -k;
            }
        }
        let beta = (0..n).map(|i| (0..d).map(|a| tmat[i * d + a] * self.theta[a]).sum()).collect();
        let mut tv = vec![0.0; n * d];
        for i in 0..n {
            for b in 0..d {
                tv[i * d + b] = (0..d).map(|a| tmat[i * d + a] * self.covariance[a * d + b]).sum();
            }
        }
        let mut covariance = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                covariance[i * n + j] = (0..d).map(|b| tv[i * d + b] * tmat[j * d + b]).sum();
            }
        }
        Ok(ClosedLoop { beta, covariance })
    }
}
