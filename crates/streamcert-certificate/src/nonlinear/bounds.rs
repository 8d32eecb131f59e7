//! The numbers behind a nonlinear look: rigorous bounds of a polynomial over an interval (the
//! F quantile and the simultaneous multiplier are the looks' shared machinery,
//! `look::hotelling`).

/// The Taylor coefficients of the polynomial `Σ_i c_i y^i` at `centre`, in place: afterwards
/// `c_i` is the coefficient of `(y − centre)^i`. Repeated synthetic division, `O(n²)`.
pub(crate) fn shift_in_place(c: &mut [f64], centre: f64) {
    let n = c.len();
    for i in 0..n {
        for j in (i..n.saturating_sub(1)).rev() {
            c[j] += centre * c[j + 1];
        }
    }
}

/// Lower and upper bounds of `Σ_i c_i y^i` over `[lo, hi]`: with the Taylor coefficients `q_i`
/// at the midpoint `m` and the half-width `r`, every value lies in
/// `q_0 ± Σ_{i>=1} |q_i| r^i` (the triangle inequality on `(y − m)^i ∈ [−r^i, r^i]`). Exact
/// when `lo = hi`; the overestimate is `O(r²)` where the polynomial is smooth. `work` holds
/// at least `c.len()` values.
pub fn polynomial_bounds(c: &[f64], lo: f64, hi: f64, work: &mut [f64]) -> (f64, f64) {
    let (m, r) = (0.5 * (lo + hi), 0.5 * (hi - lo));
    let q = &mut work[..c.len()];
    q.copy_from_slice(c);
    shift_in_place(q, m);
    let (mut spread, mut power) = (0.0, 1.0);
    for &qi in &q[1..] {
        power *= r;
        spread += qi.abs() * power;
    }
    (q[0] - spread, q[0] + spread)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shifted_coefficients_evaluate_the_same_polynomial() {
        let c = [0.3, -1.2, 0.7, 2.0, -0.4];
        let mut q = c;
        shift_in_place(&mut q, 0.8);
        for y in [-2.0, -0.5, 0.0, 0.8, 1.7] {
            let direct: f64 = c.iter().rev().fold(0.0, |a, &ci| a * y + ci);
            let shifted: f64 = q.iter().rev().fold(0.0, |a, &qi| a * (y - 0.8) + qi);
            assert!((direct - shifted).abs() < 1e-12 * (1.0 + direct.abs()), "{y}");
        }
    }

    #[test]
    fn polynomial_bounds_contain_a_dense_scan_and_tighten_with_width() {
        let c = [0.1, -1.0, 0.0, 1.0];
        let mut work = [0.0; 4];
        for (lo, hi) in [(-2.0, 2.0), (-0.2, 0.1), (0.5, 0.5), (1.0, 1.3)] {
            let (l, u) = polynomial_bounds(&c, lo, hi, &mut work);
            let (mut smin, mut smax) = (f64::INFINITY, f64::NEG_INFINITY);
            for i in 0..=2000 {
                let y = lo + (hi - lo) * f64::from(i) / 2000.0;
                let v: f64 = c.iter().rev().fold(0.0, |a, &ci| a * y + ci);
                smin = smin.min(v);
                smax = smax.max(v);
            }
            assert!(
                l <= smin + 1e-12 && u >= smax - 1e-12,
                "[{lo}, {hi}]: {l} {u} vs {smin} {smax}"
            );
            // The overestimate is second order in the width: here |q_i| <= 4, so at most
            // 2 · 4 Σ_{i>=2} r^i (the true extreme may sit where those terms change sign).
            let r: f64 = 0.5 * (hi - lo);
            let excess = 8.0 * (r * r + r * r * r) + 1e-12;
            assert!(smin - l <= excess && u - smax <= excess, "[{lo}, {hi}]: {l} {u}");
        }
    }
}
