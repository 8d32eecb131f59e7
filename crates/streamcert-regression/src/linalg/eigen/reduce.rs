//! The Householder reduction of [`super::sym_eig_extremes`] from `n = 10` on, in the widest
//! vectors the processor offers (see [`crate::linalg::lanes`]: the same numbers on every
//! width).

use pulp::{Arch, Simd, WithSimd};

use crate::linalg::dot;
use crate::linalg::lanes::{in_chunks, load, weighted_entries, weighted_rows};

/// Householder reduction of the symmetric `n × n` matrix held in both triangles of `a`
/// (row-major) to tridiagonal form: diagonal in `d`, sub-diagonal in `e[1..]` (`e[0] = 0`).
/// EISPACK `tred1` on full rows, with one exact power-of-two scaling of the whole matrix to
/// entries of unit size instead of a scaling per step: at step `i`, with `u` row `i`'s first
/// `i` entries shifted (`u_{i−1} −= g`, `g = ∓‖u‖`), `h = ‖u‖² − u_{i−1} g`, `p = A u / h`
/// (as `Σ_k u_k A_k`, the rows of the leading block weighted and added in order of `k`, even
/// and odd `k` in two sums added at the end, times `1/h`), `q = p − (uᵀp / 2h) u`, and the
/// rank-two update `A ← A − u qᵀ − q uᵀ` of the leading `i × i` block.
pub(super) fn tridiagonalise_full(a: &mut [f64], n: usize, d: &mut [f64], e: &mut [f64]) {
    Arch::new().dispatch(Reduce { a, n, d, e });
}

/// The arguments of [`tridiagonalise_full`], for [`Arch::dispatch`].
struct Reduce<'a> {
    a: &'a mut [f64],
    n: usize,
    d: &'a mut [f64],
    e: &'a mut [f64],
}

impl WithSimd for Reduce<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Reduce { a, n, d, e } = self;
        let exp = scale_down(a);
        for i in (1..n).rev() {
            step(simd, a, n, e, i);
        }
        finish(a, n, d, e, exp);
    }
}

/// [`tridiagonalise_full`] of two matrices, their steps alternating (two independent chains
/// of dependent operations, which the processor overlaps); each result is bit for bit the
/// one alone.
#[allow(clippy::too_many_arguments)]
pub(super) fn tridiagonalise_pair(
    a: &mut [f64],
    n: usize,
    d: &mut [f64],
    e: &mut [f64],
    a2: &mut [f64],
    n2: usize,
    d2: &mut [f64],
    e2: &mut [f64],
) {
    Arch::new().dispatch(Pair(Reduce { a, n, d, e }, Reduce { a: a2, n: n2, d: d2, e: e2 }));
}

/// The arguments of [`tridiagonalise_pair`], for [`Arch::dispatch`].
struct Pair<'a>(Reduce<'a>, Reduce<'a>);

impl WithSimd for Pair<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Pair(Reduce { a, n, d, e }, Reduce { a: a2, n: n2, d: d2, e: e2 }) = self;
        let (exp, exp2) = (scale_down(a), scale_down(a2));
        let (mut i, mut i2) = (n, n2);
        while i > 1 || i2 > 1 {
            if i > 1 {
                i -= 1;
                step(simd, a, n, e, i);
            }
            if i2 > 1 {
                i2 -= 1;
                step(simd, a2, n2, e2, i2);
            }
        }
        finish(a, n, d, e, exp);
        finish(a2, n2, d2, e2, exp2);
    }
}

/// One power-of-two scaling of the whole matrix (exact) to entries of unit size, so no
/// `‖u‖²` overflows or underflows and the steps need no scaling of their own; returns the
/// exponent to scale back by.
#[inline(always)]
fn scale_down(a: &mut [f64]) -> i32 {
    let big = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    // ⌊log₂ big⌋ from the exponent bits (a subnormal `big` reads as −1023 and is clamped).
    let exp = if big.is_finite() && big > 0.0 {
        (((big.to_bits() >> 52) & 0x7ff) as i32 - 1023).clamp(-1000, 1000)
    } else {
        0
    };
    if exp != 0 {
        let down = pow2(-exp);
        for v in a.iter_mut() {
            *v *= down;
        }
    }
    exp
}

/// Step `i` of the reduction: annihilate row `i` left of its sub-diagonal entry.
#[inline(always)]
fn step<S: Simd>(simd: S, a: &mut [f64], n: usize, e: &mut [f64], i: usize) {
    let l = i - 1;
    let (head, tail) = a.split_at_mut(i * n);
    let u = &mut tail[..i];
    let h = if l > 0 { dot(u, u) } else { 0.0 };
    // `h == 0`: nothing to annihilate (NaN goes on and carries into the result).
    if l == 0 || h == 0.0 {
        e[i] = u[l];
        return;
    }
    let f = u[l];
    let g = if f >= 0.0 { -h.sqrt() } else { h.sqrt() };
    e[i] = g;
    let h = h - f * g;
    u[l] = f - g;
    let rh = 1.0 / h;
    let p = &mut e[..i];
    weighted_rows_of(simd, head, n, u, p);
    let rv = simd.splat_f64s(rh);
    in_chunks!(S, p, |_c, v| simd.mul_f64s(v, rv), |_c, v| v * rh);
    let hh = 0.5 * rh * dot(p, u);
    for (pj, &uj) in p.iter_mut().zip(u.iter()) {
        *pj -= hh * uj;
    }
    rank_two_update(simd, head, n, u, p);
}

/// The diagonal and the off-diagonal, scaled back by `2^exp`.
#[inline(always)]
fn finish(a: &[f64], n: usize, d: &mut [f64], e: &mut [f64], exp: i32) {
    let up = pow2(exp);
    e[0] = 0.0;
    for v in &mut e[1..n] {
        *v *= up;
    }
    for i in 0..n {
        d[i] = a[i * n + i] * up;
    }
}

/// `2^e` for `|e| ≤ 1000`, from its bits.
#[inline(always)]
fn pow2(e: i32) -> f64 {
    f64::from_bits(((1023 + e) as u64) << 52)
}

/// `p ← Σ_k u_k A[k, ..k']` over the rows `k < k' = u.len()` of `head` (stride `n`), each
/// entry as `Σ_{k even} + Σ_{k odd}`, each sum in order of `k`.
#[inline(always)]
fn weighted_rows_of<S: Simd>(simd: S, head: &[f64], n: usize, u: &[f64], p: &mut [f64]) {
    let terms = || u.iter().copied().zip(head.chunks_exact(n));
    in_chunks!(S, p, |j, _v| weighted_rows(simd, terms(), j), |j, _v| weighted_entries(terms(), j));
}

/// `A[j, ..k] ← A[j, ..k] − (u_j q + q_j u)` for the rows `j < k = u.len()` of `head`.
#[inline(always)]
fn rank_two_update<S: Simd>(simd: S, head: &mut [f64], n: usize, u: &[f64], q: &[f64]) {
    let k = u.len();
    // Row `k − 1` first: it is the next step's `u`, so the next step's sums can start while
    // the other rows are updated.
    for j in (0..k).rev() {
        let (uj, qj) = (u[j], q[j]);
        let (ujv, qjv) = (simd.splat_f64s(uj), simd.splat_f64s(qj));
        in_chunks!(
            S,
            &mut head[j * n..j * n + k],
            |c, r| simd.sub_f64s(
                r,
                simd.add_f64s(
                    simd.mul_f64s(ujv, load::<S>(&q[c..])),
                    simd.mul_f64s(qjv, load::<S>(&u[c..]))
                )
            ),
            |c, r| r - (uj * q[c] + qj * u[c])
        );
    }
}

#[cfg(test)]
mod tests {
    use super::Reduce;
    use proptest::prelude::*;
    use pulp::Simd;

    /// The reduction of `a` with the vectors of `simd`: `(d, e)`.
    fn reduce_with<S: Simd>(simd: S, a: &[f64], n: usize) -> (Vec<f64>, Vec<f64>) {
        let (mut w, mut d, mut e) = (a.to_vec(), vec![0.0; n], vec![0.0; n]);
        simd.vectorize(Reduce { a: &mut w, n, d: &mut d, e: &mut e });
        (d, e)
    }

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    proptest! {
        #[test]
        fn every_vector_width_gives_the_same_bits(
            n in 10usize..40,
            v in prop::collection::vec(-3.0f64..3.0, 40 * 40),
            exponent in -200i32..200,
        ) {
            // A symmetric matrix in both triangles, at scales where the power-of-two scaling
            // matters; every width the processor has against the scalar code.
            let k = 10f64.powi(exponent);
            let a: Vec<f64> = (0..n * n)
                .map(|x| {
                    let (i, j) = (x / n, x % n);
                    k * (v[i * 40 + j] + v[j * 40 + i])
                })
                .collect();
            let scalar = reduce_with(pulp::Scalar::new(), &a, n);
            #[cfg(target_arch = "x86_64")]
            {
                if let Some(v3) = pulp::x86::V3::try_new() {
                    let (d, e) = reduce_with(v3, &a, n);
                    prop_assert_eq!(bits(&d), bits(&scalar.0));
                    prop_assert_eq!(bits(&e), bits(&scalar.1));
                }
                if let Some(v4) = pulp::x86::V4::try_new() {
                    let (d, e) = reduce_with(v4, &a, n);
                    prop_assert_eq!(bits(&d), bits(&scalar.0));
                    prop_assert_eq!(bits(&e), bits(&scalar.1));
                }
            }
            // The tridiagonal has the matrix's trace and Frobenius norm (an orthogonal
            // similarity), to rounding (compared at unit scale, where squares do not underflow).
            let unit = |x: &f64| x / k;
            let trace: f64 = (0..n).map(|i| unit(&a[i * n + i])).sum();
            let frob = a.iter().map(|x| unit(x) * unit(x)).sum::<f64>().sqrt();
            let (d, e) = &scalar;
            let trace_t: f64 = d.iter().map(unit).sum();
            let frob_t = (d.iter().map(|x| unit(x) * unit(x)).sum::<f64>()
                + 2.0 * e[1..].iter().map(|x| unit(x) * unit(x)).sum::<f64>())
            .sqrt();
            prop_assert!((trace_t - trace).abs() <= 1e-10 * frob, "{trace_t} vs {trace}");
            prop_assert!((frob_t - frob).abs() <= 1e-10 * frob, "{frob_t} vs {frob}");
        }
    }
}
