//! The row's kernel: the B-spline `M` of degree `n − 1` on the knots `τ_0 < … < τ_n` with
//! `∫ M = 1` (Curry–Schoenberg), its derivatives as polynomials on each knot interval, and the
//! divided difference `f[τ_0..τ_n]` as weights on the knots' values.
//!
//! Everything here is a fixed-size array on the stack: `n <= 3`, so at most three knot
//! intervals and polynomials of degree at most two.

use super::MAX_ORDER;

/// Coefficients of a polynomial of degree `< MAX_ORDER` in the local variable `s = x − τ_j`,
/// lowest power first.
pub(crate) type Poly = [f64; MAX_ORDER];

/// `M⁽ᵐ⁾` on each knot interval, for `m = 0..n`: `pieces[m][j]` is the `m`-th derivative of `M`
/// on `[τ_j, τ_{j+1}]` as a polynomial in `s = x − τ_j`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Kernel {
    pub(crate) pieces: [[Poly; MAX_ORDER]; MAX_ORDER],
}

impl Kernel {
    /// The kernel of order `n` (`1 <= n <= 3`) on the increasing knots `tau[0..=n]`, by the
    /// recursion `M_{i,1} = 1/(τ_{i+1} − τ_i)` on `[τ_i, τ_{i+1})` and
    /// `M_{i,k}(x) = k [(x − τ_i) M_{i,k−1}(x) + (τ_{i+k} − x) M_{i+1,k−1}(x)] / ((k − 1)(τ_{i+k} − τ_i))`,
    /// each piece carried as a polynomial in its interval's local variable.
    pub(crate) fn new(tau: &[f64], n: usize) -> Self {
        debug_assert!((1..=MAX_ORDER).contains(&n) && tau.len() > n);
        // `level[i][j]`: M_{i,k} on interval j, for the current k.
        let mut level = [[[0.0; MAX_ORDER]; MAX_ORDER]; MAX_ORDER];
        for (i, row) in level.iter_mut().enumerate().take(n) {
            row[i][0] = 1.0 / (tau[i + 1] - tau[i]);
        }
        for k in 2..=n {
            let mut next = [[[0.0; MAX_ORDER]; MAX_ORDER]; MAX_ORDER];
            for i in 0..=n - k {
                let scale = k as f64 / ((k - 1) as f64 * (tau[i + k] - tau[i]));
                for (j, piece) in next[i].iter_mut().enumerate().take(i + k).skip(i) {
                    // (x − τ_i) = s + (τ_j − τ_i); (τ_{i+k} − x) = (τ_{i+k} − τ_j) − s.
                    let (left, right) = (&level[i][j], &level[i + 1][j]);
                    let (cl, cr) = (tau[j] - tau[i], tau[i + k] - tau[j]);
                    for p in 0..MAX_ORDER {
                        let mut v = cl * left[p] + cr * right[p];
                        if p > 0 {
                            v += left[p - 1] - right[p - 1];
                        }
                        piece[p] = scale * v;
                    }
                }
            }
            level = next;
        }
        let mut pieces = [[[0.0; MAX_ORDER]; MAX_ORDER]; MAX_ORDER];
        pieces[0] = level[0];
        for m in 1..n {
            for j in 0..n {
                for p in 1..MAX_ORDER {
                    pieces[m][j][p - 1] = p as f64 * pieces[m - 1][j][p];
                }
            }
        }
        Self { pieces }
    }
}

/// Evaluate a [`Poly`] at `s` (Horner).
#[inline(always)]
pub(crate) fn eval(p: &Poly, s: f64) -> f64 {
    (p[2] * s + p[1]) * s + p[0]
}

/// Weights `w_j` with `f[τ_0..τ_n] = Σ_j w_j f(τ_j)`: `w_j = 1 / Π_{l≠j} (τ_j − τ_l)`.
pub(crate) fn divided_difference_weights(tau: &[f64], n: usize) -> [f64; MAX_ORDER + 1] {
    let mut w = [0.0; MAX_ORDER + 1];
    for (j, wj) in w.iter_mut().enumerate().take(n + 1) {
        let mut d = 1.0;
        for (l, &tl) in tau.iter().enumerate().take(n + 1) {
            if l != j {
                d *= tau[j] - tl;
            }
        }
        *wj = 1.0 / d;
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `∫ p(s) ds` over `[0, len]`.
    fn integral(p: &Poly, len: f64) -> f64 {
        p[0] * len + p[1] * len * len / 2.0 + p[2] * len * len * len / 3.0
    }

    /// On equal spacing `L` the kernel is the cardinal B-spline scaled to unit integral: the box
    /// `1/L`, the hat `Λ(v)/L²` and the quadratic `B(v)/L³` of the design's table, and every
    /// kernel integrates to one on irregular knots too.
    #[test]
    fn the_kernel_is_the_normalised_b_spline() {
        let l = 0.3;
        let k1 = Kernel::new(&[1.0, 1.0 + l], 1);
        assert!((k1.pieces[0][0][0] - 1.0 / l).abs() < 1e-14);
        let k2 = Kernel::new(&[0.0, l, 2.0 * l], 2);
        for v in [0.05, 0.1, 0.25, 0.35, 0.5] {
            let (j, s) = if v < l { (0, v) } else { (1, v - l) };
            let hat = v.min(2.0 * l - v) / (l * l);
            assert!((eval(&k2.pieces[0][j], s) - hat).abs() < 1e-12, "{v}");
        }
        let k3 = Kernel::new(&[0.0, l, 2.0 * l, 3.0 * l], 3);
        for v in [0.05, 0.2, 0.31, 0.5, 0.61, 0.8] {
            let j = ((v / l) as usize).min(2);
            let b = match j {
                0 => v * v / 2.0,
                1 => (-2.0 * v * v + 6.0 * l * v - 3.0 * l * l) / 2.0,
                _ => (3.0 * l - v).powi(2) / 2.0,
            } / l.powi(3);
            assert!((eval(&k3.pieces[0][j], v - j as f64 * l) - b).abs() < 1e-11, "{v}");
        }
        for tau in [[0.0, 0.13, 0.4, 0.47], [2.0, 2.5, 2.51, 3.3]] {
            for n in 1..=3 {
                let k = Kernel::new(&tau, n);
                let total: f64 =
                    (0..n).map(|j| integral(&k.pieces[0][j], tau[j + 1] - tau[j])).sum();
                assert!((total - 1.0).abs() < 1e-12, "{n} {tau:?}");
                // The derivatives of order ≤ n − 2 vanish at both ends (what the row's
                // integration by parts needs) and M⁽ⁿ⁻¹⁾ integrates to zero.
                for m in 0..n.saturating_sub(1) {
                    assert!(eval(&k.pieces[m][0], 0.0).abs() < 1e-9, "{n} {m}");
                    let end = tau[n] - tau[n - 1];
                    assert!(eval(&k.pieces[m][n - 1], end).abs() < 1e-9, "{n} {m}");
                }
                if n > 1 {
                    let d: f64 =
                        (0..n).map(|j| integral(&k.pieces[n - 1][j], tau[j + 1] - tau[j])).sum();
                    assert!(d.abs() < 1e-9, "{n} {d}");
                }
            }
        }
    }

    /// `n! f[τ_0..τ_n]` is the `n`-th derivative of a polynomial of degree `n`, on any knots.
    #[test]
    fn divided_differences_take_the_nth_derivative_of_a_polynomial() {
        let tau = [0.1, 0.35, 0.4, 0.9];
        let f = |x: f64| 2.0 - x + 0.5 * x * x - 1.5 * x * x * x;
        for (n, want) in [(1usize, None), (2, Some(1.0)), (3, Some(-9.0))] {
            let w = divided_difference_weights(&tau, n);
            let dd: f64 = (0..=n).map(|j| w[j] * f(tau[j])).sum();
            if let Some(want) = want {
                let fact = (1..=n).product::<usize>() as f64;
                // The cubic's second divided difference is not constant; only check n = 3
                // exactly and n = 2 against the quadratic part plus its cubic correction.
                if n == 3 {
                    assert!((fact * dd - want).abs() < 1e-10);
                } else {
                    let cubic = -1.5 * (tau[0] + tau[1] + tau[2]);
                    assert!((dd - (0.5 + cubic)).abs() < 1e-10, "{dd} {want}");
                }
            } else {
                assert!((dd - (f(tau[1]) - f(tau[0])) / (tau[1] - tau[0])).abs() < 1e-12);
            }
        }
    }
}
