//! The model-structured covariance's arithmetic ([`OrderNFit`](super::OrderNFit)): the two
//! noise variances fitted to the residual's autocovariances, and the sandwich.

/// `Σ_j x_j x_jᵀ` over the rows of `x` (`d` wide).
pub(super) fn gram(x: &[f64], d: usize) -> Vec<f64> {
    let mut g = vec![0.0; d * d];
    for row in x.chunks_exact(d) {
        for a in 0..d {
            for b in 0..d {
                g[a * d + b] += row[a] * row[b];
            }
        }
    }
    g
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

/// `(σ_e², σ_v²) >= 0` minimising `Σ_ℓ (γ̂(ℓ) − σ_e² s_e(ℓ) − σ_v² s_v(ℓ))²` over the lags
/// `0..=n h` (two-variable non-negative least squares: the unconstrained solution when both
/// are positive, else the better of the two one-variable fits, else zero).
pub(super) fn fit_variances(resid: &[f64], kernel_e: &[f64], kernel_v: &[f64]) -> (f64, f64) {
    let lags = kernel_e.len().min(resid.len());
    let gamma: Vec<f64> = (0..lags)
        .map(|l| {
            resid.iter().zip(&resid[l..]).map(|(a, b)| a * b).sum::<f64>()
                / (resid.len() - l) as f64
        })
        .collect();
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
