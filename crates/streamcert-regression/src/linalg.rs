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
pub fn cholesky_in_place(a: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let mut diag = a[j * n + j];
        for k in 0..j {
            diag -= a[j * n + k] * a[j * n + k];
        }
        if !(diag > 0.0 && diag.is_finite()) {
            return false;
        }
        let ljj = diag.sqrt();
        a[j * n + j] = ljj;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s / ljj;
        }
    }
    true
}

/// Solve `L Lᵀ x = b` in place in `b`, with `L` from [`cholesky_in_place`].
pub fn cholesky_solve_in_place(l: &[f64], n: usize, b: &mut [f64]) {
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i * n + k] * b[k];
        }
        b[i] = s / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= l[k * n + i] * b[k];
        }
        b[i] = s / l[i * n + i];
    }
}

/// LU factorisation with partial pivoting in place (`P A = L U`, unit-diagonal `L` below the
/// diagonal, `U` on and above). `piv[i]` records the row swapped into position `i`.
///
/// Returns the ratio `min |u_ii| / max |u_ii|` (0 for an exactly singular matrix), a cheap
/// conditioning indicator.
#[must_use]
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

/// Smallest and largest eigenvalue of the symmetric `n × n` matrix `a` (row-major; only
/// the upper triangle is read), using `work` (`>= n²`) as scratch.
///
/// `n = 1, 2` use closed forms; larger `n` use cyclic Jacobi rotations, which are accurate to
/// a few ulps of `‖A‖` and converge quadratically (at most 50 sweeps).
#[must_use]
pub fn sym_eig_extremes(a: &[f64], n: usize, work: &mut [f64]) -> (f64, f64) {
    match n {
        0 => (f64::NAN, f64::NAN),
        1 => (a[0], a[0]),
        2 => {
            let (p, q, r) = (a[0], a[1], a[3]);
            let mean = 0.5 * (p + r);
            let half = (0.5 * (p - r)).hypot(q);
            (mean - half, mean + half)
        }
        _ => {
            let w = &mut work[..n * n];
            for i in 0..n {
                for j in 0..n {
                    w[i * n + j] = if j >= i { a[i * n + j] } else { a[j * n + i] };
                }
            }
            jacobi_diagonalise(w, n);
            let mut lo = f64::INFINITY;
            let mut hi = f64::NEG_INFINITY;
            for i in 0..n {
                lo = lo.min(w[i * n + i]);
                hi = hi.max(w[i * n + i]);
            }
            (lo, hi)
        }
    }
}

/// Cyclic Jacobi: drive the off-diagonal of the symmetric `w` to zero in place.
fn jacobi_diagonalise(w: &mut [f64], n: usize) {
    for _sweep in 0..50 {
        let mut off = 0.0;
        let mut diag = 0.0;
        for i in 0..n {
            diag += w[i * n + i] * w[i * n + i];
            for j in i + 1..n {
                off += w[i * n + j] * w[i * n + j];
            }
        }
        if off <= 1e-30 * diag || off == 0.0 || !off.is_finite() {
            return;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = w[p * n + q];
                if apq == 0.0 {
                    continue;
                }
                let (app, aqq) = (w[p * n + p], w[q * n + q]);
                let theta = (aqq - app) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (akp, akq) = (w[k * n + p], w[k * n + q]);
                    w[k * n + p] = c * akp - s * akq;
                    w[k * n + q] = s * akp + c * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (w[p * n + k], w[q * n + k]);
                    w[p * n + k] = c * apk - s * aqk;
                    w[q * n + k] = s * apk + c * aqk;
                }
            }
        }
    }
}

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
    let mut work = vec![0.0; c * c];
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

    proptest! {
        #[test]
        fn eigen_extremes_on_random_symmetric(a in (1usize..12).prop_flat_map(sym)) {
            let n = (a.len() as f64).sqrt() as usize;
            let mut work = vec![0.0; n * n];
            let (lo, hi) = sym_eig_extremes(&a, n, &mut work);
            let eig = DMatrix::from_row_slice(n, n, &a).symmetric_eigen().eigenvalues;
            let scale = 1.0 + eig.amax();
            prop_assert!((lo - eig.min()).abs() < 1e-10 * scale, "{lo} vs {}", eig.min());
            prop_assert!((hi - eig.max()).abs() < 1e-10 * scale, "{hi} vs {}", eig.max());
        }

        #[test]
        fn cholesky_and_lu_solve_spd_systems(
            v in (1usize..10).prop_flat_map(|n| prop::collection::vec(-3.0f64..3.0, n * n + n))
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
