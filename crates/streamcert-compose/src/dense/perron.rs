//! The Perron path of [`network_rate_with`](super::network_rate_with): every quantity the
//! Perron root of a nonnegative matrix `Γ + cI` (or a form of it), bracketed by
//! Collatz–Wielandt along a power iteration, `O(N + edges)` per step.

use super::{DenseMethod, DenseOptions, NetworkCertificate};
use crate::sparse::{collatz_wielandt, collatz_wielandt_from};
use crate::{ComposeError, Network};

/// The Perron path's problem and bookkeeping: the network, its transposed rows, the shift
/// `c`, the iteration's limits, and the iterations spent and whether every bracket closed.
struct Perron<'a> {
    net: &'a Network,
    tr: Vec<Vec<(usize, f64)>>,
    beta: &'a [f64],
    c: f64,
    scale: f64,
    tol: f64,
    it: usize,
    /// Whether the eigendecomposition takes over where a bracket does not close.
    fallback: bool,
    iterations: usize,
    converged: bool,
}

/// Positive right and left Perron vectors, and the regularisation `δ` they needed.
struct Vectors {
    right: Vec<f64>,
    left: Vec<f64>,
    delta: f64,
}

/// The Perron path; `None` when a bracket does not close and the eigendecomposition should
/// take over.
pub(super) fn perron(
    net: &Network,
    opts: &DenseOptions,
) -> Result<Option<NetworkCertificate>, ComposeError> {
    let n = net.len();
    let beta = net.rates();
    let gmax = (0..n).flat_map(|i| net.row(i).map(|(_, g)| g)).fold(0.0f64, f64::max);
    let bmax = beta.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b));
    let scale = bmax.abs().max(gmax).max(1.0);
    let mut p = Perron {
        net,
        tr: super::transposed(net),
        beta,
        c: bmax + 0.1 * gmax.max(f64::MIN_POSITIVE),
        scale,
        tol: opts.tolerance * scale,
        it: opts.max_iterations,
        fallback: n <= opts.eigen_limit,
        iterations: 0,
        converged: true,
    };
    // Network rate: ρ(Γ + cI), right vector; the rate is recomputed from the vector.
    let c = p.c;
    let (upper, lower, v, k) =
        collatz_wielandt(n, |i, x| net.row_dot(i, x) + (c - beta[i]) * x[i], p.it, p.tol);
    if p.gives_up(upper, lower, k) {
        return Ok(None);
    }
    let rate = crate::metzler_rate(net, &v)?.min(c - upper);
    let rate_upper = c - lower;
    // Left vector: the same root for Γᵀ.
    let (ul, ll, w, k) = collatz_wielandt(n, |i, x| p.row_t(i, x), p.it, p.tol);
    if p.gives_up(ul, ll, k) {
        return Ok(None);
    }
    let Some(Vectors { right: vr, left: wl, delta }) = p.positive_vectors(v, w)? else {
        return Ok(None);
    };
    let eta: Vec<f64> = wl.iter().zip(&vr).map(|(a, b)| a / b).collect();
    let emax = eta.iter().fold(0.0f64, |a, &x| a.max(x));
    let weights: Vec<f64> = eta.iter().map(|x| x / emax).collect();
    let Some(weighted_rate) = p.weighted_rate(&weights, &vr, &wl) else { return Ok(None) };
    let Some(symmetric_rate) = p.symmetric_rate() else { return Ok(None) };
    let Some(critical_scale) = p.critical_scale(opts.tolerance) else { return Ok(None) };
    Ok(Some(NetworkCertificate {
        rate,
        weights,
        weighted_rate,
        symmetric_rate: symmetric_rate.min(rate),
        critical_scale,
        weight_regularization: delta,
        rate_upper,
        method: DenseMethod::Perron,
        iterations: p.iterations,
        converged: p.converged,
    }))
}

impl Perron<'_> {
    /// Count a bracket `[lower, upper]` closed after `k` steps; true when it did not close
    /// and the eigendecomposition takes over.
    fn gives_up(&mut self, upper: f64, lower: f64, k: usize) -> bool {
        self.iterations += k;
        let ok = upper - lower <= self.tol;
        self.converged &= ok;
        !ok && self.fallback
    }

    /// Row `i` of `(Γ + cI)ᵀ x`.
    fn row_t(&self, i: usize, x: &[f64]) -> f64 {
        self.tr[i].iter().map(|&(r, g)| g * x[r]).sum::<f64>() + (self.c - self.beta[i]) * x[i]
    }

    /// The right and left Perron vectors, positive: a vector with (near) zeros means a
    /// reducible `Γ`, regularised as the eigendecomposition does (`Γ + δ (11ᵀ − I)`), with
    /// the `δ` used; `None` where a bracket does not close.
    fn positive_vectors(
        &mut self,
        v: Vec<f64>,
        w: Vec<f64>,
    ) -> Result<Option<Vectors>, ComposeError> {
        let positive = |x: &[f64]| {
            let max = x.iter().fold(0.0f64, |a, &y| a.max(y));
            max > 0.0 && x.iter().all(|&y| y > 1e-12 * max)
        };
        let (n, net, beta, c) = (self.net.len(), self.net, self.beta, self.c);
        let mut delta = 0.0;
        let (mut vr, mut wl) = (v, w);
        while !(positive(&vr) && positive(&wl)) {
            delta = if delta == 0.0 { 1e-9 * self.scale } else { delta * 100.0 };
            if delta > 1e-3 * self.scale {
                return Err(ComposeError::Numerical("no positive Perron vectors".into()));
            }
            let d = delta;
            let right = |i: usize, x: &[f64]| {
                let sum: f64 = x.iter().sum();
                net.row_dot(i, x) + (c - beta[i]) * x[i] + d * (sum - x[i])
            };
            let (u1, l1, v1, k1) = collatz_wielandt(n, right, self.it, self.tol);
            let left = |i: usize, x: &[f64]| {
                let sum: f64 = x.iter().sum();
                self.row_t(i, x) + d * (sum - x[i])
            };
            let (u2, l2, w1, k2) = collatz_wielandt(n, left, self.it, self.tol);
            if self.gives_up(u1, l1, k1) | self.gives_up(u2, l2, k2) {
                return Ok(None);
            }
            (vr, wl) = (v1, w1);
        }
        Ok(Some(Vectors { right: vr, left: wl, delta }))
    }

    /// The rate the weights attain, `λ_max(sym(P^½ Γ P^−½))` with `P = diag(weights)`,
    /// started at `√(v ∘ w)`; `None` where the bracket does not close.
    fn weighted_rate(&mut self, weights: &[f64], vr: &[f64], wl: &[f64]) -> Option<f64> {
        let sq: Vec<f64> = weights.iter().map(|x| x.sqrt()).collect();
        let start: Vec<f64> =
            vr.iter().zip(wl).map(|(a, b)| (a * b).sqrt().max(f64::MIN_POSITIVE)).collect();
        let (net, tr, beta, c) = (self.net, &self.tr, self.beta, self.c);
        let row_w = |i: usize, x: &[f64]| {
            let mut acc = (c - beta[i]) * x[i];
            for (j, g) in net.row(i) {
                acc += 0.5 * sq[i] * g / sq[j] * x[j];
            }
            for &(r, g) in &tr[i] {
                acc += 0.5 * sq[r] * g / sq[i] * x[r];
            }
            acc
        };
        let (uw, lw, _, k) = collatz_wielandt_from(start, row_w, self.it, self.tol);
        (!self.gives_up(uw, lw, k)).then_some(c - uw)
    }

    /// The symmetric bound `λ_max(sym Γ)`; `None` where the bracket does not close.
    fn symmetric_rate(&mut self) -> Option<f64> {
        let (net, tr, beta, c) = (self.net, &self.tr, self.beta, self.c);
        let row_s = |i: usize, x: &[f64]| {
            let mut acc = (c - beta[i]) * x[i];
            for (j, g) in net.row(i) {
                acc += 0.5 * g * x[j];
            }
            for &(r, g) in &tr[i] {
                acc += 0.5 * g * x[r];
            }
            acc
        };
        let (us, ls, _, k) = collatz_wielandt(net.len(), row_s, self.it, self.tol);
        (!self.gives_up(us, ls, k)).then_some(c - us)
    }

    /// The critical scale: `ρ(D⁻¹Γ_off) <= u − 1` for the iteration on `D⁻¹Γ_off + I`, at the
    /// relative `tolerance`; `None` where the bracket does not close.
    fn critical_scale(&mut self, tolerance: f64) -> Option<f64> {
        let (net, beta) = (self.net, self.beta);
        if beta.iter().any(|&b| b <= 0.0) {
            return Some(0.0);
        }
        if net.edges() == 0 {
            return Some(f64::INFINITY);
        }
        let row = |i: usize, x: &[f64]| net.row_dot(i, x) / beta[i] + x[i];
        let (u, l, _, k) = collatz_wielandt(net.len(), row, self.it, tolerance);
        if self.gives_up(u, l, k) {
            return None;
        }
        Some(if u > 1.0 { 1.0 / (u - 1.0) } else { f64::INFINITY })
    }
}
