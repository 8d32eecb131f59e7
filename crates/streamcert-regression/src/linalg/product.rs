//! [`closed_loop_jacobian`]: `Ĵ_cl = Ĵ_obs + B̂_obs K` from the regression's `Θ̂`, in the
//! widest vectors the processor offers for wide rows (the same numbers on every width, see
//! [`crate::linalg::lanes`]).

use pulp::{Arch, Simd, WithSimd};

use crate::linalg::lanes::{load, store};

/// From this many outputs the rows are formed in vectors chosen at run time; below, entry by
/// entry, inlined (for the paper's `p = 1` the dispatch would cost more than the product).
const VECTOR_FROM: usize = 8;

/// `Ĵ_cl = Ĵ_obs + B̂_obs K` into `jcl` (`p × p`, row-major) from `Θ̂ = [Ĵ_obs B̂_obs]`
/// (`p × (p + m)`, row-major) and the gain `K` (`m × p`, row-major): the closed-loop Jacobian
/// of the paper's Section II (`J_cl = J_obs + B_obs K`). Each entry is
/// `J_obs[i, j] + B_obs[i, 0] K[0, j] + … + B_obs[i, m−1] K[m−1, j]`, added left to right
/// without fused multiply-adds, so the result is the same bit for bit on every processor and
/// for every `p`: from `p = 8` row `i` accumulates the rows of `K` along its contiguous
/// entries in vectors (one multiply and one add per lane and term), below entry by entry.
///
/// # Panics
/// If a buffer is shorter than stated.
#[inline(always)]
pub fn closed_loop_jacobian(theta: &[f64], k: &[f64], jcl: &mut [f64], p: usize, m: usize) {
    let d = p + m;
    let (theta, k, jcl) = (&theta[..p * d], &k[..m * p], &mut jcl[..p * p]);
    if p >= VECTOR_FROM {
        Arch::new().dispatch(Product { theta, k, jcl, p, m });
        return;
    }
    for i in 0..p {
        row_by_entries(&theta[i * d..(i + 1) * d], k, &mut jcl[i * p..(i + 1) * p], p, m);
    }
}

/// One row of [`closed_loop_jacobian`] entry by entry: `out[j] = row[j] + Σ_l row[p + l] K[l, j]`,
/// the terms added in order of `l` (the rows of `K` accumulated along `out`).
#[inline(always)]
fn row_by_entries(row: &[f64], k: &[f64], out: &mut [f64], p: usize, m: usize) {
    out[..p].copy_from_slice(&row[..p]);
    for l in 0..m {
        let b = row[p + l];
        for j in 0..p {
            out[j] += b * k[l * p + j];
        }
    }
}

/// The arguments of [`closed_loop_jacobian`], for [`Arch::dispatch`].
struct Product<'a> {
    theta: &'a [f64],
    k: &'a [f64],
    jcl: &'a mut [f64],
    p: usize,
    m: usize,
}

impl WithSimd for Product<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Product { theta, k, jcl, p, m } = self;
        let (d, lanes) = (p + m, S::F64_LANES);
        for i in 0..p {
            let (row, out) = (&theta[i * d..(i + 1) * d], &mut jcl[i * p..(i + 1) * p]);
            // One vector of row i's entries c .. c + lanes, from the inputs only (so the
            // last vector may overlap the one before it and store the same values again).
            let entries = |c: usize| {
                let mut v = load::<S>(&row[c..]);
                for l in 0..m {
                    let term =
                        simd.mul_f64s(simd.splat_f64s(row[p + l]), load::<S>(&k[l * p + c..]));
                    v = simd.add_f64s(v, term);
                }
                v
            };
            if p < lanes {
                row_by_entries(row, k, out, p, m);
                continue;
            }
            let mut c = 0;
            while c + lanes <= p {
                store::<S>(&mut out[c..], entries(c));
                c += lanes;
            }
            if c < p {
                store::<S>(&mut out[p - lanes..], entries(p - lanes));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The definition, entry by entry.
    fn reference(theta: &[f64], k: &[f64], p: usize, m: usize) -> Vec<f64> {
        let d = p + m;
        let mut out = vec![0.0; p * p];
        for i in 0..p {
            for j in 0..p {
                let mut v = theta[i * d + j];
                for l in 0..m {
                    v += theta[i * d + p + l] * k[l * p + j];
                }
                out[i * p + j] = v;
            }
        }
        out
    }

    /// The product at one vector width.
    fn with<S: Simd>(simd: S, theta: &[f64], k: &[f64], p: usize, m: usize) -> Vec<u64> {
        let mut jcl = vec![f64::NAN; p * p];
        Product { theta, k, jcl: &mut jcl, p, m }.with_simd(simd);
        jcl.iter().map(|x| x.to_bits()).collect()
    }

    proptest! {
        #[test]
        fn every_width_gives_the_definitions_bits(
            p in 1usize..30,
            m in 0usize..12,
            v in prop::collection::vec(-1e3f64..1e3, 30 * 42 + 12 * 30),
        ) {
            let d = p + m;
            let (theta, k) = (&v[..p * d], &v[30 * 42..30 * 42 + m * p]);
            let want: Vec<u64> = reference(theta, k, p, m).iter().map(|x| x.to_bits()).collect();
            let mut jcl = vec![f64::NAN; p * p];
            closed_loop_jacobian(theta, k, &mut jcl, p, m);
            prop_assert_eq!(jcl.iter().map(|x| x.to_bits()).collect::<Vec<_>>(), want.clone());
            prop_assert_eq!(with(pulp::Scalar::new(), theta, k, p, m), want.clone());
            #[cfg(target_arch = "x86_64")]
            {
                if let Some(v3) = pulp::x86::V3::try_new() {
                    prop_assert_eq!(with(v3, theta, k, p, m), want.clone());
                }
                if let Some(v4) = pulp::x86::V4::try_new() {
                    prop_assert_eq!(with(v4, theta, k, p, m), want);
                }
            }
        }
    }
}
