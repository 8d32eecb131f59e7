//! The model-structured covariance ([`OrderNFit`](super::OrderNFit)): the filtered rows, the
//! two noise variances fitted to the residual's autocovariances, and the sandwich.

use pulp::{Arch, Simd, WithSimd};

use super::OrderNRecord;
use crate::linalg::dot;

/// `Σ_j x_j x_jᵀ` over the rows of `x`, given by its columns (`x` holds them one after the
/// other, each `len` long): entry `(a, b)` is the sum over `j` in order of `x_a[j] x_b[j]`,
/// taken once for `a <= b` and mirrored (the products are the same numbers).
fn gram_of_columns(x: &[f64], len: usize) -> Vec<f64> {
    let d = x.len() / len.max(1);
    let mut g = vec![0.0; d * d];
    for a in 0..d {
        let xa = &x[a * len..(a + 1) * len];
        for b in a..d {
            let xb = &x[b * len..(b + 1) * len];
            let mut sum = 0.0;
            for (p, q) in xa.iter().zip(xb) {
                sum += p * q;
            }
            (g[a * d + b], g[b * d + a]) = (sum, sum);
        }
    }
    g
}

/// `Ψ_{i + o} += w_o · row` for `o` over `w`: one row's contribution (row `i` of the range)
/// to the filtered rows its kernel reaches, with `Ψ` stored by column (`psi` holds the
/// columns one after the other, each `len` long).
fn scatter(psi: &mut [f64], len: usize, i: usize, w: &[f64], row: &[f64]) {
    for (column, x) in psi.chunks_exact_mut(len).zip(row) {
        for (p, wo) in column[i..i + w.len()].iter_mut().zip(w) {
            *p += wo * x;
        }
    }
}

/// `A B Aᵀ` for `d × d` matrices.
pub(super) fn sandwich(a: &[f64], b: &[f64], d: usize) -> Vec<f64> {
    let mut ab = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..d {
            ab[i * d + j] = (0..d).map(|k| a[i * d + k] * b[k * d + j]).sum();
        }
    }
    let mut out = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..d {
            out[i * d + j] = (0..d).map(|k| ab[i * d + k] * a[j * d + k]).sum();
        }
    }
    out
}

/// The autocorrelation `s(ℓ) = Σ_o w_o w_{o+ℓ}` of a kernel at the lags `0..len`.
fn shape_of(w: &[f64], lags: usize) -> Vec<f64> {
    (0..lags).map(|l| w.iter().zip(w.iter().skip(l)).map(|(a, b)| a * b).sum()).collect()
}

/// `γ̂(ℓ) = Σ_k r_k r_{k+ℓ} / (N − ℓ)` at the lags `ℓ = 0..lags` (`lags <= N`), each sum a
/// [`dot`] (its fixed four-lane order), compiled for the widest vectors the processor offers
/// (the same numbers on every width).
fn autocovariances(resid: &[f64], lags: usize) -> Vec<f64> {
    struct Lags<'a>(&'a [f64], usize);
    impl WithSimd for Lags<'_> {
        type Output = Vec<f64>;
        #[inline(always)]
        fn with_simd<S: Simd>(self, _: S) -> Vec<f64> {
            // A loop, not a closure: a closure is not compiled with the vectors' features.
            let (resid, len) = (self.0, self.0.len());
            let mut gamma = vec![0.0; self.1];
            for (l, g) in gamma.iter_mut().enumerate() {
                *g = dot(&resid[..len - l], &resid[l..]) / (len - l) as f64;
            }
            gamma
        }
    }
    Arch::new().dispatch(Lags(resid, lags))
}

/// `(σ_e², σ_v²) >= 0` minimising `Σ_ℓ (γ̂(ℓ) − σ_e² s_e(ℓ) − σ_v² s_v(ℓ))²` over the lags
/// `0..=n h` (two-variable non-negative least squares: the unconstrained solution when both
/// are positive, else the better of the two one-variable fits, else zero).
fn fit_variances(resid: &[f64], kernel_e: &[f64], kernel_v: &[f64]) -> (f64, f64) {
    let lags = kernel_e.len().min(resid.len());
    let gamma: Vec<f64> = autocovariances(resid, lags);
    let (se, sv) = (shape_of(kernel_e, lags), shape_of(kernel_v, lags));
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let (ee, vv, ev, eg, vg) =
        (dot(&se, &se), dot(&sv, &sv), dot(&se, &sv), dot(&se, &gamma), dot(&sv, &gamma));
    let sse = |a: f64, b: f64| {
        gamma
            .iter()
            .zip(se.iter().zip(&sv))
            .map(|(g, (e, v))| (g - a * e - b * v).powi(2))
            .sum::<f64>()
    };
    let det = ee * vv - ev * ev;
    if det > 0.0 {
        let a = (eg * vv - vg * ev) / det;
        let b = (vg * ee - eg * ev) / det;
        if a >= 0.0 && b >= 0.0 {
            return (a, b);
        }
    }
    let only_e = if ee > 0.0 { (eg / ee).max(0.0) } else { 0.0 };
    let only_v = if vv > 0.0 { (vg / vv).max(0.0) } else { 0.0 };
    if sse(only_e, 0.0) <= sse(0.0, only_v) { (only_e, 0.0) } else { (0.0, only_v) }
}

/// A weight set's residual kernel on the sensor noise and the two kernels over the rows'
/// number: `(set, w, w / N, wv / N)`.
type SetKernels = (usize, Vec<f64>, Vec<f64>, Vec<f64>);

/// What the covariance needs of the filtered rows: `H_e = Ψ_eᵀΨ_e`, `H_v = Ψ_vᵀΨ_v` (`d × d`)
/// and the rows' mean kernels `w̄_e`, `w̄_v`.
pub(super) struct Filtered {
    pub(super) he: Vec<f64>,
    pub(super) hv: Vec<f64>,
    pub(super) mean_e: Vec<f64>,
    pub(super) mean_v: Vec<f64>,
}

/// The model-structured covariance from the filtered rows' products and the residuals:
/// `(σ_e², σ_v²)` fitted to the residuals' autocovariances, then
/// `V = G⁻¹ (σ_e² H_e + σ_v² H_v) G⁻¹ · N / (N − d)` (in the rows' coordinates).
pub(super) fn finish_covariance(
    filtered: &Filtered,
    resid: &[f64],
    ginv: &[f64],
    d: usize,
) -> (Vec<f64>, f64, f64) {
    let count = resid.len();
    let (sensor_variance, equation_variance) =
        fit_variances(resid, &filtered.mean_e, &filtered.mean_v);
    let middle: Vec<f64> = filtered
        .he
        .iter()
        .zip(&filtered.hv)
        .map(|(e, v)| sensor_variance * e + equation_variance * v)
        .collect();
    let dof = count as f64 / (count - d) as f64;
    let mut covariance = sandwich(ginv, &middle, d);
    for c in &mut covariance {
        *c *= dof;
    }
    (covariance, sensor_variance, equation_variance)
}

impl OrderNRecord {
    /// The model-structured covariance of the rows from `first` (see [`OrderNFit`]), in the
    /// origin's coordinates, with the fitted `(σ_e², σ_v²)`.
    pub(super) fn structured_covariance(
        &self,
        first: usize,
        phi: &[f64],
        theta: &[f64],
        resid: &[f64],
        ginv: &[f64],
    ) -> (Vec<f64>, f64, f64) {
        let filtered = self.filtered(first, phi, theta, resid.len());
        finish_covariance(&filtered, resid, ginv, theta.len())
    }

    /// The rows from `first` filtered by their own kernels, each row's contribution
    /// scattered: `O(N n h d)`.
    fn filtered(&self, first: usize, phi: &[f64], theta: &[f64], count: usize) -> Filtered {
        let (n, span, d) = (self.n, self.span, theta.len());
        // The residual's kernel on the sensor noise (with â) and on the equation noise; their
        // filtered rows Ψ (indexed from the range's first sample; stored by column, each
        // `N + n h` long) and the rows' mean kernels.
        let len = count + span;
        let mut psi_e = vec![0.0; len * d];
        let mut psi_v = vec![0.0; len * d];
        let mut mean_e = vec![0.0; span + 1];
        let mut mean_v = vec![0.0; span];
        let count_f = count as f64;
        // Each weight set's residual kernel `w = wz − Σ_k â_k wy_k`, and both kernels over the
        // rows' number, computed once for the rows that share the set (one set on equal
        // spacing): `(set, w, w / N, wv / N)`.
        let mut kernel: Option<SetKernels> = None;
        for (i, row) in phi.chunks_exact(d).enumerate() {
            let r = first + i;
            let set = self.weights_of[r];
            if kernel.as_ref().is_some_and(|k| k.0 != set) {
                kernel = None;
            }
            let (_, w, we, wv) = kernel.get_or_insert_with(|| {
                let mut w = self.wz(r).to_vec();
                for (k, th) in theta.iter().enumerate().take(n) {
                    for (wo, wi) in w.iter_mut().zip(self.wy(r, k)) {
                        *wo -= th * wi;
                    }
                }
                let we = w.iter().map(|wo| wo / count_f).collect();
                let wv = self.wv(r).iter().map(|wo| wo / count_f).collect();
                (set, w, we, wv)
            });
            for (me, wo) in mean_e.iter_mut().zip(we) {
                *me += *wo;
            }
            scatter(&mut psi_e, len, i, w, row);
            for (mv, wo) in mean_v.iter_mut().zip(wv) {
                *mv += *wo;
            }
            scatter(&mut psi_v, len, i, self.wv(r), row);
        }
        let he = gram_of_columns(&psi_e, len);
        let hv = gram_of_columns(&psi_v, len);
        Filtered { he, hv, mean_e, mean_v }
    }
}
