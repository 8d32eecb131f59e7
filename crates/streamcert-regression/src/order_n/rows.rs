//! The order-`n` row built directly from the samples of its span, as weights on the samples:
//! the batch estimator's row, its noise kernels, and the oracle the streaming recursion is
//! tested against.
//!
//! A row ending at sample `k` spans the `n h + 1` samples `k − n h, …, k` (position `0` is the
//! oldest) and has its knots on samples, `τ_j = t_{k − (n − j) h}`. Between samples `y` is the
//! linear interpolant and `u` is held (zero-order hold: `u_i` on `[t_i, t_{i+1})`); each
//! integral is then of a polynomial of degree at most three per sample interval, which the
//! three-point Gauss–Legendre rule integrates exactly.

use super::spline::{Kernel, Poly, divided_difference_weights, eval};
use super::{MAX_ORDER, Shape};
use crate::linalg::dot;

/// Three-point Gauss–Legendre nodes on `[−1, 1]` and their weights (exact to degree five).
const GL_NODES: [f64; 3] = [-0.774_596_669_241_483_4, 0.0, 0.774_596_669_241_483_4];
const GL_WEIGHTS: [f64; 3] = [5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0];

/// `(∫ P ℓ₀, ∫ P ℓ₁, ∫ P)` over the sample interval `[a, b]` (local to the knot interval),
/// with `ℓ₀ = (b − s)/(b − a)` and `ℓ₁ = (s − a)/(b − a)` the interpolant's hat functions.
#[inline]
fn hat_moments(p: &Poly, a: f64, b: f64) -> (f64, f64, f64) {
    let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
    let (mut w0, mut w1, mut w) = (0.0, 0.0, 0.0);
    for (x, g) in GL_NODES.iter().zip(GL_WEIGHTS) {
        let s = mid + half * x;
        let v = g * half * eval(p, s);
        let l1 = 0.5 * (1.0 + x);
        w0 += v * (1.0 - l1);
        w1 += v * l1;
        w += v;
    }
    (w0, w1, w)
}

/// The weights of one row on its span's samples.
///
/// With `L̄ = (τ_n − τ_0)/n` and `M` the kernel of [`Kernel`]:
/// - `z = L̄ⁿ n! y[τ_0..τ_n] = Σ_i wz_i y_i` (the regressand),
/// - `φ^y_k = −L̄ⁿ (−1)^{n−k} ⟨M^{(n−k)}, y⟩ = Σ_i wy[k]_i y_i` (coefficient `a_k`),
/// - `φ^u_k = L̄ⁿ (−1)^{n−k} ⟨M^{(n−k)}, u⟩ = Σ_i wu[k]_i u_i` (coefficient `b_k`, the
///   same weights for every input),
/// - the intercept `L̄ⁿ` (coefficient `c`),
/// - `wv_i = L̄ⁿ ∫_{[t_i, t_{i+1}]} M / √(t_{i+1} − t_i)`: the row's response to white noise
///   of unit intensity entering where `c` enters, per sample interval.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RowWeights {
    /// `n h + 1` weights of the regressand.
    pub(crate) wz: Vec<f64>,
    /// `n × (n h + 1)`: regressor `k = 1..n` in row `k − 1`.
    pub(crate) wy: Vec<f64>,
    /// `n × n h` (per sample interval, on `u_i`).
    pub(crate) wu: Vec<f64>,
    /// `n h`, per sample interval.
    pub(crate) wv: Vec<f64>,
    /// `L̄ⁿ`.
    pub(crate) intercept: f64,
}

impl RowWeights {
    /// Zeroed weights for `shape`.
    pub(crate) fn new(shape: Shape) -> Self {
        let (n, span) = (shape.n, shape.span());
        Self {
            wz: vec![0.0; span + 1],
            wy: vec![0.0; n * (span + 1)],
            wu: vec![0.0; n * span],
            wv: vec![0.0; span],
            intercept: 0.0,
        }
    }

    /// Fill the weights for the span's sample times `t` (`n h + 1` of them, increasing).
    pub(crate) fn fill(&mut self, shape: Shape, t: &[f64]) {
        let (n, h, span) = (shape.n, shape.h, shape.span());
        debug_assert_eq!(t.len(), span + 1);
        let mut tau = [0.0; MAX_ORDER + 1];
        for (j, tj) in tau.iter_mut().enumerate().take(n + 1) {
            *tj = t[j * h];
        }
        let kernel = Kernel::new(&tau, n);
        let lbar = (tau[n] - tau[0]) / n as f64;
        let scale = lbar.powi(n as i32);
        self.intercept = scale;
        self.wz.fill(0.0);
        let dd = divided_difference_weights(&tau, n);
        let fact = (1..=n).product::<usize>() as f64;
        for j in 0..=n {
            self.wz[j * h] = scale * fact * dd[j];
        }
        self.wy.fill(0.0);
        self.wu.fill(0.0);
        for i in 0..span {
            let j = i / h;
            let (a, b) = (t[i] - tau[j], t[i + 1] - tau[j]);
            for k in 1..=n {
                let sign = if (n - k) % 2 == 0 { 1.0 } else { -1.0 };
                let (w0, w1, w) = hat_moments(&kernel.pieces[n - k][j], a, b);
                let row = &mut self.wy[(k - 1) * (span + 1)..k * (span + 1)];
                row[i] -= scale * sign * w0;
                row[i + 1] -= scale * sign * w1;
                self.wu[(k - 1) * span + i] = scale * sign * w;
            }
            let (_, _, m) = hat_moments(&kernel.pieces[0][j], a, b);
            self.wv[i] = scale * m / (t[i + 1] - t[i]).sqrt();
        }
    }

    /// The row `[φ^y_1..φ^y_n, φ^{u_1}_1..φ^{u_1}_n, …, L̄ⁿ]` and its regressand `z` from the
    /// span's outputs `y` (`n h + 1`) and inputs `u` (`(n h + 1) × m`, row-major; the last
    /// sample's input is not used: it is held after the span). Each sum of weights times
    /// samples is in [`dot`]'s four-lane order.
    #[inline(always)]
    pub(crate) fn apply(&self, shape: Shape, y: &[f64], u: &[f64], row: &mut [f64]) -> f64 {
        let (n, m, span) = (shape.n, shape.m, shape.span());
        for k in 0..n {
            let w = &self.wy[k * (span + 1)..(k + 1) * (span + 1)];
            row[k] = dot(w, y);
            let w = &self.wu[k * span..(k + 1) * span];
            for input in 0..m {
                row[n + input * n + k] =
                    if m == 1 { dot(w, u) } else { dot_strided(w, &u[input..], m) };
            }
        }
        row[shape.width() - 1] = self.intercept;
        dot(&self.wz, y)
    }
}

/// [`dot`] of `w` with every `stride`-th entry of `x` from the first, in the same order.
fn dot_strided(w: &[f64], x: &[f64], stride: usize) -> f64 {
    let n = w.len().min(x.len().div_ceil(stride));
    let mut lanes = [0.0f64; 4];
    for i in 0..n / 4 * 4 {
        lanes[i % 4] += w[i] * x[i * stride];
    }
    let mut tail = 0.0;
    for i in n / 4 * 4..n {
        tail += w[i] * x[i * stride];
    }
    (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]) + tail
}

/// Whether the times `b` have the offsets from their first that `a` has, each to within
/// `1e-12` of `a`'s span.
pub(super) fn same_offsets(a: &[f64], b: &[f64]) -> bool {
    let (a0, b0) = (a[0], b[0]);
    let tol = 1e-12 * (a[a.len() - 1] - a0);
    a.iter().zip(b).all(|(x, y)| ((x - a0) - (y - b0)).abs() <= tol)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// A strided dot product is the dot product of the entries it takes, bit for bit.
        #[test]
        fn a_strided_dot_is_the_dot_of_its_entries(
            w in prop::collection::vec(-1e3f64..1e3, 0..60),
            x in prop::collection::vec(-1e3f64..1e3, 0..200),
            stride in 1usize..4,
        ) {
            let taken: Vec<f64> = x.iter().step_by(stride).copied().collect();
            prop_assert_eq!(dot_strided(&w, &x, stride).to_bits(), dot(&w, &taken).to_bits());
        }
    }
}
