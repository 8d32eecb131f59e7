//! Which subsystem and which coupling limit the network rate: the sensitivity of the
//! spectral abscissa `α(Γ)` of the Metzler gain matrix to its entries.

use serde::{Deserialize, Serialize};
use streamcert_compose::Network;

/// Sensitivities of `α(Γ)` at the current network.
///
/// For a simple Perron root with right and left Perron vectors `v`, `w` (`Γ v = α v`,
/// `wᵀ Γ = α wᵀ`), `∂α/∂Γ_ij = w_i v_j / (wᵀ v)`. So `p_i = w_i v_i / (wᵀ v)` (the
/// participation of subsystem `i`, summing to 1) is how much the network rate gains per unit
/// of local rate `β_i`, and `e_ij = γ_ij w_i v_j / (wᵀ v)` is the share of the coupling
/// `γ_ij` in `α` (the rate lost per relative growth of `γ_ij`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sensitivity {
    /// Participation `p_i` of each subsystem.
    pub participation: Vec<f64>,
    /// The subsystem with the largest participation (the one whose rate limits the network).
    pub limiting_subsystem: usize,
    /// The coupling `(i, j)` with the largest `e_ij`, if there is any coupling.
    pub limiting_coupling: Option<(usize, usize)>,
    /// Power iterations used (each is one product with `Γ` and one with `Γᵀ`).
    pub iterations: usize,
    /// Whether the iteration met its tolerance (otherwise it stopped at `max_iterations` and
    /// the sensitivities are those of its last iterate: informative, not converged).
    pub converged: bool,
}

/// Perron vectors of `Γ + cI` (`c = max β_i + 1`, which makes it nonnegative with the same
/// eigenvectors) by power iteration from the all-ones vector, to relative change `tolerance`
/// or `max_iterations`; then the sensitivities. `O(iterations · (N + edges))`.
///
/// For a reducible `Γ` (a cascade) the Perron vectors have zeros and the sensitivities are
/// those of the dominant block, which is what limits the rate.
#[must_use]
pub fn perron_sensitivity(net: &Network, max_iterations: usize, tolerance: f64) -> Sensitivity {
    let n = net.len();
    let beta = net.rates();
    let c = beta.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b)) + 1.0;
    let (mut v, mut w) = (vec![1.0; n], vec![1.0; n]);
    let (mut nv, mut nw) = (vec![0.0; n], vec![0.0; n]);
    let (mut iterations, mut converged) = (0, false);
    for _ in 0..max_iterations {
        iterations += 1;
        // nv = (Γ + cI) v, nw = (Γ + cI)ᵀ w.
        for i in 0..n {
            nv[i] = net.row_dot(i, &v) + (c - beta[i]) * v[i];
            nw[i] = (c - beta[i]) * w[i];
        }
        for i in 0..n {
            for (j, g) in net.row(i) {
                nw[j] += g * w[i];
            }
        }
        let change = normalise_and_compare(&mut nv, &v) + normalise_and_compare(&mut nw, &w);
        std::mem::swap(&mut v, &mut nv);
        std::mem::swap(&mut w, &mut nw);
        if change <= tolerance {
            converged = true;
            break;
        }
    }
    let wv: f64 = w.iter().zip(&v).map(|(a, b)| a * b).sum();
    let scale = if wv > 0.0 { 1.0 / wv } else { 0.0 };
    let participation: Vec<f64> = w.iter().zip(&v).map(|(a, b)| a * b * scale).collect();
    let limiting_subsystem = argmax(&participation);
    let mut limiting_coupling = None;
    let mut best = f64::NEG_INFINITY;
    for i in 0..n {
        for (j, g) in net.row(i) {
            let e = g * w[i] * v[j] * scale;
            if e > best {
                best = e;
                limiting_coupling = Some((i, j));
            }
        }
    }
    Sensitivity { participation, limiting_subsystem, limiting_coupling, iterations, converged }
}

/// Scale `x` to unit maximum; return the largest absolute change against `previous`.
fn normalise_and_compare(x: &mut [f64], previous: &[f64]) -> f64 {
    let max = x.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
    if max > 0.0 {
        x.iter_mut().for_each(|v| *v /= max);
    }
    x.iter().zip(previous).fold(0.0f64, |a, (x, p)| a.max((x - p).abs()))
}

fn argmax(x: &[f64]) -> usize {
    let mut best = 0;
    for (i, &v) in x.iter().enumerate() {
        if v > x[best] {
            best = i;
        }
    }
    best
}
