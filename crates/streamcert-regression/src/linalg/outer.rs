//! [`add_outer_products`]: the sums a refresh recomputes from the column ring, in the widest
//! vectors the processor offers for wide regressions (the same numbers on every width, see
//! [`crate::linalg::lanes`]).

use pulp::{Arch, Simd, WithSimd};

use crate::linalg::lanes::{in_chunks, load};

/// From this width `d = p + m` the rows are updated in vectors chosen at run time; below,
/// entry by entry (a row shorter than a vector has nothing to gain).
const VECTOR_FROM: usize = 8;

/// For every column `(z, Δy)` of `zs` (`d` values each) and `dys` (`p` each), in order: the
/// upper triangle of `G += z zᵀ` (`d × d`), `C += Δy zᵀ` (`p × d`) and the upper triangle of
/// `S += Δy Δyᵀ` (`p × p`), all row-major. Each entry gains one product per column, added in
/// column order without fused multiply-adds, so the sums are the same bit for bit on every
/// processor and equal to the entry-by-entry loop: from `d = 8` a row is updated in vectors
/// along its contiguous entries (one multiply and one add per lane), below entry by entry.
/// The lower triangles are not written.
///
/// # Panics
/// If a buffer is shorter than stated.
#[inline]
pub(crate) fn add_outer_products(
    zs: &[f64],
    dys: &[f64],
    sums: (&mut [f64], &mut [f64], &mut [f64]),
    p: usize,
    d: usize,
) {
    let (g, cm, s) = (&mut sums.0[..d * d], &mut sums.1[..p * d], &mut sums.2[..p * p]);
    let outer = Outer { zs, dys, g, cm, s, p, d };
    if d >= VECTOR_FROM {
        Arch::new().dispatch(outer);
    } else {
        outer.with_simd(pulp::Scalar::new());
    }
}

/// The arguments of [`add_outer_products`], for [`Arch::dispatch`].
struct Outer<'a> {
    zs: &'a [f64],
    dys: &'a [f64],
    g: &'a mut [f64],
    cm: &'a mut [f64],
    s: &'a mut [f64],
    p: usize,
    d: usize,
}

impl WithSimd for Outer<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Outer { zs, dys, g, cm, s, p, d } = self;
        for (z, dy) in zs.chunks_exact(d).zip(dys.chunks_exact(p)) {
            for i in 0..d {
                accumulate(simd, &mut g[i * d + i..(i + 1) * d], z[i], &z[i..]);
            }
            for i in 0..p {
                accumulate(simd, &mut cm[i * d..(i + 1) * d], dy[i], z);
                accumulate(simd, &mut s[i * p + i..(i + 1) * p], dy[i], &dy[i..]);
            }
        }
    }
}

/// `row[j] += w · x[j]` for every `j < row.len()` (a multiply, then an add).
#[inline(always)]
fn accumulate<S: Simd>(simd: S, row: &mut [f64], w: f64, x: &[f64]) {
    let wv = simd.splat_f64s(w);
    in_chunks!(S, row, |c, v| simd.add_f64s(v, simd.mul_f64s(wv, load::<S>(&x[c..]))), |c, v| v
        + w * x[c]);
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The entry-by-entry loop (the refresh's before the vectors).
    fn reference(zs: &[f64], dys: &[f64], p: usize, d: usize) -> Vec<u64> {
        let (mut g, mut c, mut s) = (vec![0.5; d * d], vec![0.25; p * d], vec![0.125; p * p]);
        for (z, dy) in zs.chunks_exact(d).zip(dys.chunks_exact(p)) {
            for i in 0..d {
                for j in i..d {
                    g[i * d + j] += z[i] * z[j];
                }
            }
            for i in 0..p {
                for j in 0..d {
                    c[i * d + j] += dy[i] * z[j];
                }
                for j in i..p {
                    s[i * p + j] += dy[i] * dy[j];
                }
            }
        }
        g.iter().chain(&c).chain(&s).map(|x| x.to_bits()).collect()
    }

    /// The sums at one vector width (`None`: through the dispatch).
    fn with<S: Simd>(simd: Option<S>, zs: &[f64], dys: &[f64], p: usize, d: usize) -> Vec<u64> {
        let (mut g, mut c, mut s) = (vec![0.5; d * d], vec![0.25; p * d], vec![0.125; p * p]);
        match simd {
            Some(simd) => {
                Outer { zs, dys, g: &mut g, cm: &mut c, s: &mut s, p, d }.with_simd(simd);
            }
            None => add_outer_products(zs, dys, (&mut g, &mut c, &mut s), p, d),
        }
        g.iter().chain(&c).chain(&s).map(|x| x.to_bits()).collect()
    }

    proptest! {
        #[test]
        fn every_width_gives_the_entry_loops_bits(
            p in 1usize..14,
            m in 0usize..14,
            columns in 0usize..9,
            v in prop::collection::vec(-1e3f64..1e3, 8 * 28 + 8 * 14),
        ) {
            let d = (p + m).max(1);
            let (zs, dys) = (&v[..columns * d], &v[8 * 28..8 * 28 + columns * p]);
            let want = reference(zs, dys, p, d);
            prop_assert_eq!(with(None::<pulp::Scalar>, zs, dys, p, d), want.clone());
            prop_assert_eq!(with(Some(pulp::Scalar::new()), zs, dys, p, d), want.clone());
            #[cfg(target_arch = "x86_64")]
            {
                if let Some(v3) = pulp::x86::V3::try_new() {
                    prop_assert_eq!(with(Some(v3), zs, dys, p, d), want.clone());
                }
                if let Some(v4) = pulp::x86::V4::try_new() {
                    prop_assert_eq!(with(Some(v4), zs, dys, p, d), want);
                }
            }
        }
    }
}
