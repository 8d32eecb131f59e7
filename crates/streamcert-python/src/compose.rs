//! [`Composition`]: the network guarantee from local rates and coupling gains, as the
//! command line's `compose` computes it, with the limiting subsystem and coupling.

use streamcert_compose::{DenseMethod, Network, SparseOptions, certify_sparse, network_rate};
use streamcert_network::perron_sensitivity;

use crate::Error;

/// Above this many subsystems the sparse certificate is used (the command line's `auto`).
pub const DENSE_LIMIT: usize = 2000;

/// The network guarantee of rates `β_i` and couplings `γ_ij` (`j` drives `i`).
#[derive(Debug, Clone, PartialEq)]
pub struct Composition {
    /// The network contraction rate `−α(Γ)`, `Γ = −diag β + Γ_off` (its safe end).
    pub rate: f64,
    /// The weights `η_i` of the norm `Σ η_i x_i²` that attains the rate (dense), or the
    /// Collatz–Wielandt certificate vector (sparse).
    pub weights: Vec<f64>,
    /// The symmetric, unweighted bound `λ_min(diag β − sym Γ_off)` (Lemma 1's form for `N`
    /// subsystems), when computed.
    pub symmetric_rate: Option<f64>,
    /// `s* = 1/ρ(D⁻¹ Γ_off)`: the network with every coupling scaled by `s` contracts iff
    /// `s < s*`.
    pub critical_scale: f64,
    /// Each subsystem's participation `p_i = w_i v_i / (wᵀ v)` in the rate (Perron vectors).
    pub participation: Vec<f64>,
    /// The subsystem whose local rate the network rate depends on most.
    pub limiting_subsystem: usize,
    /// The coupling `(i, j)` with the largest share in the rate, if any.
    pub limiting_coupling: Option<(usize, usize)>,
    /// `"dense"`, `"dense-eigendecomposition"` or `"sparse"`.
    pub method: &'static str,
}

/// Compose `rates` with coupling `edges` `(i, j, γ_ij)`: dense up to [`DENSE_LIMIT`]
/// subsystems, sparse above (`dense` forces one or the other).
///
/// # Errors
/// [`Error::Compose`] for an invalid network (negative or non-finite values, an index out of
/// range, a self-loop).
pub fn compose(
    rates: &[f64],
    edges: &[(usize, usize, f64)],
    dense: Option<bool>,
) -> Result<Composition, Error> {
    let bad = |e: streamcert_compose::ComposeError| Error::Compose(e.to_string());
    let net = Network::new(rates.to_vec(), edges).map_err(bad)?;
    let s = perron_sensitivity(&net, 1000, 1e-12);
    let common = |rate, weights, symmetric_rate, critical_scale, method| Composition {
        rate,
        weights,
        symmetric_rate,
        critical_scale,
        participation: s.participation.clone(),
        limiting_subsystem: s.limiting_subsystem,
        limiting_coupling: s.limiting_coupling,
        method,
    };
    if dense.unwrap_or(net.len() <= DENSE_LIMIT) {
        let c = network_rate(&net).map_err(bad)?;
        let method = match c.method {
            DenseMethod::Perron => "dense",
            DenseMethod::Eigendecomposition => "dense-eigendecomposition",
        };
        Ok(common(c.rate, c.weights, Some(c.symmetric_rate), c.critical_scale, method))
    } else {
        let c = certify_sparse(&net, &SparseOptions::default()).map_err(bad)?;
        Ok(common(c.rate, c.certificate, c.symmetric_rate, c.critical_scale, "sparse"))
    }
}

/// The edges of a dense row-major `n × n` gain matrix (zeros dropped, as the command line's
/// dense gains file).
///
/// # Errors
/// [`Error::Shape`] when `gains` is not `n × n`.
pub fn dense_edges(n: usize, gains: &[f64]) -> Result<Vec<(usize, usize, f64)>, Error> {
    if gains.len() != n * n {
        return Err(Error::Shape(format!(
            "{n} rates need an {n} × {n} gain matrix, got {} values",
            gains.len()
        )));
    }
    Ok((0..n)
        .flat_map(|i| (0..n).map(move |j| (i, j)))
        .filter(|&(i, j)| gains[i * n + j] != 0.0)
        .map(|(i, j)| (i, j, gains[i * n + j]))
        .collect())
}
