//! Small dense linear algebra on caller-provided row-major buffers, without allocation.
//!
//! The streaming estimators solve `d × d` systems (`d = p + m`, a few to a few tens) and need
//! the extreme eigenvalues of small symmetric matrices at every sample. General-purpose
//! libraries allocate for dynamically sized matrices; these routines work in place on scratch
//! buffers reserved once, so the hot path stays allocation-free. They are checked against
//! nalgebra's dense solvers in the tests.

/// Cholesky factorisation `A = L Lᵀ` in place (lower triangle of `a` becomes `L`; the strict
/// upper triangle is left untouched). `a` is `n × n` row-major.
///
/// Returns `false` when `A` is not numerically positive definite (a pivot `<= 0` or not finite).
#[must_use]
#[inline(always)]
pub fn cholesky_in_place(a: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let row_j = &a[j * n..j * n + j];
        let diag = a[j * n + j] - dot(row_j, row_j);
        if !(diag > 0.0 && diag.is_finite()) {
            return false;
        }
        let ljj = diag.sqrt();
        a[j * n + j] = ljj;
        for i in j + 1..n {
            let s = a[i * n + j] - dot(&a[i * n..i * n + j], &a[j * n..j * n + j]);
            a[i * n + j] = s / ljj;
        }
    }
    true
}

/// `Σ a_k b_k` over the shorter length, in four independent lanes (so the compiler can keep
/// four multiply-adds in flight and vectorise; the summation order differs from a left fold):
/// lane `j` sums the products at `4 i + j` in order, the sum is
/// `(lane₀ + lane₁) + (lane₂ + lane₃) + tail`, the tail the last `len mod 4` products in order.
#[inline(always)]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    if n >= 16 {
        let (lanes, tail) = dot_lanes(a, b);
        // The lanes pass through memory: without it the compiler keeps them interleaved
        // across two half-width registers to suit the final sum's order and permutes them at
        // every chunk (about 2.7 times the instructions on long runs). The sum is the same.
        let lanes = std::hint::black_box(lanes);
        (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]) + tail
    } else {
        let (lanes, tail) = dot_lanes(a, b);
        (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]) + tail
    }
}

/// [`dot`]'s four lanes and its tail.
#[inline(always)]
fn dot_lanes(a: &[f64], b: &[f64]) -> ([f64; 4], f64) {
    let mut lanes = [0.0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for j in 0..4 {
            lanes[j] += x[j] * y[j];
        }
    }
    let mut tail = 0.0;
    for (x, y) in ra.iter().zip(rb) {
        tail += x * y;
    }
    (lanes, tail)
}

/// Solve `L Lᵀ x = b` in place in `b`, with `L` from [`cholesky_in_place`]: forward
/// substitution by dot products with the rows of `L`, back substitution by updates along the
/// rows of `L` (both walk `L` contiguously).
#[inline(always)]
pub fn cholesky_solve_in_place(l: &[f64], n: usize, b: &mut [f64]) {
    let b = &mut b[..n];
    for i in 0..n {
        let row = &l[i * n..i * n + i];
        b[i] = (b[i] - dot(row, &b[..i])) / l[i * n + i];
    }
    for i in (0..n).rev() {
        let bi = b[i] / l[i * n + i];
        b[i] = bi;
        for (bk, &lik) in b[..i].iter_mut().zip(&l[i * n..i * n + i]) {
            *bk -= lik * bi;
        }
    }
}

/// `√(a² + b²)`: the plain formula when it neither overflows nor underflows, `hypot` (which
/// scales) otherwise. About ten times cheaper than `hypot` on the common path.
#[inline(always)]
pub(crate) fn fast_hypot(a: f64, b: f64) -> f64 {
    let r2 = a * a + b * b;
    if r2.is_finite() && r2 >= f64::MIN_POSITIVE { r2.sqrt() } else { a.hypot(b) }
}

/// LU factorisation with partial pivoting in place (`P A = L U`, unit-diagonal `L` below the
/// diagonal, `U` on and above). `piv[i]` records the row swapped into position `i`.
///
/// Returns the ratio `min |u_ii| / max |u_ii|` (0 for an exactly singular matrix), a cheap
/// conditioning indicator.
#[must_use]
#[inline(always)]
pub fn lu_in_place(a: &mut [f64], n: usize, piv: &mut [usize]) -> f64 {
    let (mut umin, mut umax) = (f64::INFINITY, 0.0f64);
    for k in 0..n {
        let mut p = k;
        let mut best = a[k * n + k].abs();
        for i in k + 1..n {
            let v = a[i * n + k].abs();
            if v > best {
                best = v;
                p = i;
            }
        }
        piv[k] = p;
        if p != k {
            for j in 0..n {
                a.swap(k * n + j, p * n + j);
            }
        }
        umin = umin.min(best);
        umax = umax.max(best);
        if best == 0.0 || !best.is_finite() {
            return 0.0;
        }
        let pivot = a[k * n + k];
        for i in k + 1..n {
            let f = a[i * n + k] / pivot;
            a[i * n + k] = f;
            for j in k + 1..n {
                a[i * n + j] -= f * a[k * n + j];
            }
        }
    }
    if umax > 0.0 { umin / umax } else { 0.0 }
}

/// Solve `A x = b` in place in `b` from the factors of [`lu_in_place`].
#[inline(always)]
pub fn lu_solve_in_place(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64]) {
    for k in 0..n {
        b.swap(k, piv[k]);
    }
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= lu[i * n + k] * b[k];
        }
        b[i] = s;
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= lu[i * n + k] * b[k];
        }
        b[i] = s / lu[i * n + i];
    }
}

/// Solve `Aᵀ x = b` in place with the factors of [`lu_in_place`] (`P A = L U`):
/// `Uᵀ z = b`, `Lᵀ w = z`, `x = Pᵀ w`. The same pivots and factors as
/// [`lu_solve_in_place`], for the transposed system.
pub fn lu_solve_transpose_in_place(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64]) {
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= lu[k * n + i] * b[k];
        }
        b[i] = s / lu[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= lu[k * n + i] * b[k];
        }
        b[i] = s;
    }
    for k in (0..n).rev() {
        b.swap(k, piv[k]);
    }
}

mod eigen;
pub(crate) mod lanes;
mod outer;
mod product;

pub use eigen::{
    eig_work_len, psd_eig_extremes, psd_extremes_and_sym_max, sym_eig_extremes, sym_eig_max,
};
#[cfg(test)]
use eigen::{tridiagonal_extremes_for_test as tridiagonal_extremes, tridiagonal_ql};
pub(crate) use outer::add_outer_products;
pub use product::closed_loop_jacobian;

/// Spectral norm `‖K‖₂` of an `r × c` row-major matrix: `√λ_max(Kᵀ K)`. Allocates (it is
/// meant for configuration time, not the hot path).
#[must_use]
pub fn spectral_norm(k: &[f64], r: usize, c: usize) -> f64 {
    if r == 0 || c == 0 {
        return 0.0;
    }
    let mut ktk = vec![0.0; c * c];
    for i in 0..c {
        for j in 0..c {
            ktk[i * c + j] = (0..r).map(|l| k[l * c + i] * k[l * c + j]).sum();
        }
    }
    let mut work = vec![0.0; eig_work_len(c)];
    sym_eig_extremes(&ktk, c, &mut work).1.max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;
    use proptest::prelude::*;

    fn sym(n: usize) -> impl Strategy<Value = Vec<f64>> {
        prop::collection::vec(-10.0f64..10.0, n * n).prop_map(move |v| {
            let mut s = v.clone();
            for i in 0..n {
                for j in 0..n {
                    s[i * n + j] = 0.5 * (v[i * n + j] + v[j * n + i]);
                }
            }
            s
        })
    }

    /// [`dot`]'s documented order, one product at a time.
    fn dot_in_order(a: &[f64], b: &[f64]) -> f64 {
        let n = a.len().min(b.len());
        let mut lanes = [0.0f64; 4];
        for i in 0..n / 4 * 4 {
            lanes[i % 4] += a[i] * b[i];
        }
        let mut tail = 0.0;
        for i in n / 4 * 4..n {
            tail += a[i] * b[i];
        }
        (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]) + tail
    }

    /// `dot` through the vector dispatch, as its callers in the order-n window use it.
    fn dot_dispatched(a: &[f64], b: &[f64]) -> f64 {
        struct Dot<'a>(&'a [f64], &'a [f64]);
        impl pulp::WithSimd for Dot<'_> {
            type Output = f64;
            #[inline(always)]
            fn with_simd<S: pulp::Simd>(self, _: S) -> f64 {
                dot(self.0, self.1)
            }
        }
        pulp::Arch::new().dispatch(Dot(a, b))
    }

    proptest! {
        /// The same bits as the documented order, at every length (both sides of the
        /// threshold at which the lanes pass through memory), with and without the dispatch.
        #[test]
        fn dot_is_its_documented_order_bit_for_bit(
            a in prop::collection::vec(-1e3f64..1e3, 0..80),
            b in prop::collection::vec(-1e3f64..1e3, 0..80),
        ) {
            let want = dot_in_order(&a, &b).to_bits();
            prop_assert_eq!(dot(&a, &b).to_bits(), want);
            prop_assert_eq!(dot_dispatched(&a, &b).to_bits(), want);
        }
    }

    proptest! {
        #[test]
        fn transposed_lu_solve_equals_dense(
            n in 1usize..8,
            a in prop::collection::vec(-3.0f64..3.0, 64),
            b in prop::collection::vec(-3.0f64..3.0, 8),
        ) {
            // Diagonally loaded so that the matrix is well conditioned.
            let mut m: Vec<f64> = (0..n * n).map(|i| a[i] + if i / n == i % n { 8.0 } else { 0.0 }).collect();
            let dense = DMatrix::from_row_slice(n, n, &m);
            let mut piv = vec![0; n];
            prop_assert!(lu_in_place(&mut m, n, &mut piv) > 0.0);
            let mut x = b[..n].to_vec();
            lu_solve_transpose_in_place(&m, n, &piv, &mut x);
            let want = dense.transpose().lu().solve(&nalgebra::DVector::from_column_slice(&b[..n])).expect("regular");
            for i in 0..n {
                prop_assert!((x[i] - want[i]).abs() < 1e-10, "{} vs {}", x[i], want[i]);
            }
        }

        #[test]
        fn eigen_extremes_on_random_symmetric(a in (1usize..24).prop_flat_map(sym)) {
            let n = (a.len() as f64).sqrt() as usize;
            let mut work = vec![0.0; eig_work_len(n)];
            let (lo, hi) = sym_eig_extremes(&a, n, &mut work);
            let eig = DMatrix::from_row_slice(n, n, &a).symmetric_eigen().eigenvalues;
            let scale = 1.0 + eig.amax();
            prop_assert!((lo - eig.min()).abs() < 1e-10 * scale, "{lo} vs {}", eig.min());
            prop_assert!((hi - eig.max()).abs() < 1e-10 * scale, "{hi} vs {}", eig.max());
        }

        #[test]
        fn laguerre_extremes_equal_ql_on_tridiagonals(
            n in 2usize..40,
            seed in prop::collection::vec(-2.0f64..2.0, 80),
            zeros in prop::collection::vec(any::<bool>(), 40),
            repeat in any::<bool>(),
        ) {
            // Random tridiagonals, with decoupled blocks (zero off-diagonals) and, if `repeat`,
            // a constant diagonal (clustered and repeated eigenvalues).
            let d: Vec<f64> = (0..n).map(|i| if repeat { 1.0 } else { seed[i] }).collect();
            let e: Vec<f64> =
                (0..n - 1).map(|i| if zeros[i] { 0.0 } else { seed[40 + i] }).collect();
            let (lo, hi) = tridiagonal_extremes(&d, &e, true).expect("Laguerre settles");
            let mut dq = d.clone();
            let mut eq = vec![0.0; n];
            eq[1..].copy_from_slice(&e);
            prop_assert!(tridiagonal_ql(&mut dq, &mut eq));
            let (qlo, qhi) = dq.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
            let scale = 1.0 + qlo.abs().max(qhi.abs());
            prop_assert!((lo - qlo).abs() <= 1e-12 * scale, "{lo} vs {qlo}");
            prop_assert!((hi - qhi).abs() <= 1e-12 * scale, "{hi} vs {qhi}");
        }

        #[test]
        fn the_largest_alone_is_the_largest_of_the_pair(a in (1usize..24).prop_flat_map(sym)) {
            // `sym_eig_max` skips `λ_min` from n = 10 on; `λ_max` must not change by a bit.
            let n = (a.len() as f64).sqrt() as usize;
            let mut work = vec![0.0; eig_work_len(n)];
            let pair = sym_eig_extremes(&a, n, &mut work);
            let top = sym_eig_max(&a, n, &mut work);
            prop_assert_eq!(top.to_bits(), pair.1.to_bits());
        }

        #[test]
        fn gram_extremes_start_at_zero_and_still_match_the_dense_solver(
            n in 1usize..24,
            cols in 1usize..48,
            v in prop::collection::vec(-2.0f64..2.0, 24 * 48),
            decay in 0.0f64..4.0,
            indefinite in any::<bool>(),
        ) {
            // Gram matrices Σ z zᵀ, rank-deficient when cols < n, with a spread of column
            // scales down to 10⁻⁴ (clusters of small eigenvalues); with `indefinite` a
            // multiple of I is subtracted, so the checked start at 0⁻ is inside the spectrum
            // and the run must restart from Gershgorin's bound.
            let z = DMatrix::from_fn(n, cols, |i, j| v[i * 48 + j] * 10f64.powf(-decay * i as f64 / n as f64));
            let mut g = &z * z.transpose();
            if indefinite {
                g -= DMatrix::identity(n, n) * (0.5 * g.diagonal().max());
            }
            let a: Vec<f64> = (0..n * n).map(|k| g[(k / n, k % n)]).collect();
            let mut work = vec![0.0; eig_work_len(n)];
            let (lo, hi) = psd_eig_extremes(&a, n, &mut work);
            let general = sym_eig_extremes(&a, n, &mut work);
            // λ_max's run is untouched; below n = 10 the whole result is.
            prop_assert_eq!(hi.to_bits(), general.1.to_bits());
            if n < 10 {
                prop_assert_eq!(lo.to_bits(), general.0.to_bits());
            }
            let eig = g.symmetric_eigen().eigenvalues;
            let scale = 1.0 + eig.amax();
            prop_assert!((lo - eig.min()).abs() < 1e-10 * scale, "{lo} vs {}", eig.min());
            prop_assert!((hi - eig.max()).abs() < 1e-10 * scale, "{hi} vs {}", eig.max());
        }

        #[test]
        fn the_pair_side_by_side_is_each_alone_bit_for_bit(
            n in 1usize..24,
            s in (1usize..24).prop_flat_map(sym),
            v in prop::collection::vec(-2.0f64..2.0, 24 * 30),
            cols in 1usize..30,
            special in 0usize..4,
        ) {
            // A Gram matrix (rank-deficient when cols < n) and a symmetric one; sometimes the
            // symmetric one is zero, NaN somewhere, or huge, so the side-by-side path falls
            // back to each problem's own.
            let z = DMatrix::from_fn(n, cols, |i, j| v[i * 30 + j]);
            let gm = &z * z.transpose();
            let g: Vec<f64> = (0..n * n).map(|k| gm[(k / n, k % n)]).collect();
            let m = (s.len() as f64).sqrt() as usize;
            let mut s = s;
            match special {
                1 => s.iter_mut().for_each(|x| *x = 0.0),
                2 => s[0] = f64::NAN,
                3 => s.iter_mut().for_each(|x| *x *= 1e300),
                _ => {}
            }
            let (mut wg, mut ws) = (vec![0.0; eig_work_len(n)], vec![0.0; eig_work_len(m)]);
            let ((lo, hi), top) = psd_extremes_and_sym_max(&g, n, &mut wg, &s, m, &mut ws);
            let (alo, ahi) = psd_eig_extremes(&g, n, &mut wg);
            let atop = sym_eig_max(&s, m, &mut ws);
            prop_assert_eq!((lo.to_bits(), hi.to_bits()), (alo.to_bits(), ahi.to_bits()));
            prop_assert_eq!(top.to_bits(), atop.to_bits());
        }

        #[test]
        fn a_value_that_is_not_finite_gives_nan_extremes(
            a in (1usize..24).prop_flat_map(sym),
            at in any::<prop::sample::Index>(),
            bad in prop::sample::select(vec![f64::NAN, f64::INFINITY, f64::NEG_INFINITY]),
        ) {
            // Every path (closed forms, QL, Laguerre) must not turn a bad input into a number.
            let n = (a.len() as f64).sqrt() as usize;
            let mut a = a;
            let k = at.index(a.len());
            let (i, j) = (k / n, k % n);
            a[i * n + j] = bad;
            a[j * n + i] = bad;
            let mut work = vec![0.0; eig_work_len(n)];
            let (lo, hi) = sym_eig_extremes(&a, n, &mut work);
            prop_assert!(!(lo.is_finite() && hi.is_finite()), "n = {n}: {lo}, {hi}");
            let (plo, phi) = psd_eig_extremes(&a, n, &mut work);
            prop_assert!(!(plo.is_finite() && phi.is_finite()), "n = {n}: {plo}, {phi}");
            let top = sym_eig_max(&a, n, &mut work);
            prop_assert!(!top.is_finite() || top.to_bits() == hi.to_bits(), "n = {n}: {top}");
        }

        #[test]
        fn eigen_extremes_at_extreme_scales(
            a in (3usize..12).prop_flat_map(sym),
            exponent in prop::sample::select(vec![-300i32, -150, 150, 300]),
        ) {
            // Squares of these entries overflow or underflow: the QL rotations fall back to
            // the scaled `hypot`.
            let n = (a.len() as f64).sqrt() as usize;
            let k = 10f64.powi(exponent);
            let scaled: Vec<f64> = a.iter().map(|x| x * k).collect();
            let mut work = vec![0.0; eig_work_len(n)];
            let (lo, hi) = sym_eig_extremes(&scaled, n, &mut work);
            let eig = DMatrix::from_row_slice(n, n, &a).symmetric_eigen().eigenvalues;
            let scale = 1.0 + eig.amax();
            prop_assert!((lo / k - eig.min()).abs() < 1e-9 * scale, "{lo} vs {}", eig.min() * k);
            prop_assert!((hi / k - eig.max()).abs() < 1e-9 * scale, "{hi} vs {}", eig.max() * k);
        }

        #[test]
        fn cholesky_and_lu_solve_spd_systems(
            v in (1usize..24).prop_flat_map(|n| prop::collection::vec(-3.0f64..3.0, n * n + n))
        ) {
            let n = ((1.0 + 4.0 * v.len() as f64).sqrt() as usize - 1) / 2;
            let m = DMatrix::from_row_slice(n, n, &v[..n * n]);
            let spd = &m * m.transpose() + DMatrix::identity(n, n);
            let b: Vec<f64> = v[n * n..].to_vec();
            let exact = spd.clone().lu().solve(&nalgebra::DVector::from_row_slice(&b)).unwrap();
            let mut a: Vec<f64> = (0..n * n).map(|k| spd[(k / n, k % n)]).collect();
            prop_assert!(cholesky_in_place(&mut a, n));
            let mut x = b.clone();
            cholesky_solve_in_place(&a, n, &mut x);
            let mut lu: Vec<f64> = (0..n * n).map(|k| spd[(k / n, k % n)]).collect();
            let mut piv = vec![0; n];
            prop_assert!(lu_in_place(&mut lu, n, &mut piv) > 0.0);
            let mut y = b.clone();
            lu_solve_in_place(&lu, n, &piv, &mut y);
            for i in 0..n {
                prop_assert!((x[i] - exact[i]).abs() < 1e-9 * (1.0 + exact[i].abs()));
                prop_assert!((y[i] - exact[i]).abs() < 1e-9 * (1.0 + exact[i].abs()));
            }
        }
    }

    #[test]
    fn singular_inputs_are_reported() {
        let mut a = vec![1.0, 1.0, 1.0, 1.0];
        assert!(!cholesky_in_place(&mut a, 2));
        let mut b = vec![1.0, 2.0, 2.0, 4.0];
        let mut piv = [0; 2];
        assert_eq!(lu_in_place(&mut b, 2, &mut piv), 0.0);
        assert!((spectral_norm(&[3.0, 0.0, 0.0, -4.0], 2, 2) - 4.0).abs() < 1e-12);
    }
}
