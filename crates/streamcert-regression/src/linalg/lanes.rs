//! Kernels in the widest vectors the processor offers, chosen at run time by [`pulp::Arch`]
//! (AVX-512, AVX2, SSE2 or scalar), with the same numbers on every width.
//!
//! Every vector operation here is element-wise (a multiply, an add, a subtract or a divide
//! per lane, never a fused multiply-add and never a sum across lanes), and every sum over an
//! index runs in the same order whatever the width, so a result is the same bit for bit on
//! every processor: the width changes the speed, not the numbers. Sums of products that run
//! along a vector's lanes use [`super::dot`]'s fixed four-lane order. The kernels dispatch
//! through [`pulp::Arch`] with everything they call inlined, so it is compiled for each width.

use pulp::Simd;

/// `Σ_k w_k · row_k[c .. c + lanes]` over the terms `(w_k, row_k)`, as `Σ_{k even} + Σ_{k odd}`,
/// each sum in order of `k` (the vector form of [`weighted_entries`]).
#[inline(always)]
pub(crate) fn weighted_rows<'a, S: Simd>(
    simd: S,
    mut terms: impl Iterator<Item = (f64, &'a [f64])>,
    c: usize,
) -> S::f64s {
    let (mut even, mut odd) = (simd.splat_f64s(0.0), simd.splat_f64s(0.0));
    while let Some((w0, r0)) = terms.next() {
        even = simd.add_f64s(even, simd.mul_f64s(simd.splat_f64s(w0), load::<S>(&r0[c..])));
        let Some((w1, r1)) = terms.next() else { break };
        odd = simd.add_f64s(odd, simd.mul_f64s(simd.splat_f64s(w1), load::<S>(&r1[c..])));
    }
    simd.add_f64s(even, odd)
}

/// `Σ_k w_k · row_k[c]` over the terms `(w_k, row_k)`, as `Σ_{k even} + Σ_{k odd}`, each sum
/// in order of `k`: one lane of [`weighted_rows`].
#[inline(always)]
pub(crate) fn weighted_entries<'a>(
    mut terms: impl Iterator<Item = (f64, &'a [f64])>,
    c: usize,
) -> f64 {
    let (mut even, mut odd) = (0.0, 0.0);
    while let Some((w0, r0)) = terms.next() {
        even += w0 * r0[c];
        let Some((w1, r1)) = terms.next() else { break };
        odd += w1 * r1[c];
    }
    even + odd
}

/// `x[c] ← f(c, x[c])` for every `c`, a vector at a time (`$vector` with `$c` the offset and
/// `$v` the vector `x[c .. c + lanes]`) where `x` holds one, entry by entry (`$entry`) where it
/// is shorter than a vector. A length that is not a multiple of the width ends with the
/// vector that ends at `x.len()`, computed from the entries as they were before any store
/// and stored last, so the entries it shares with the vector before it get the same value
/// twice (`$vector` and `$entry` compute the same arithmetic, lane by lane). A macro, not a
/// function taking closures: closures are not compiled with the target features of the
/// function they are written in, and a vector passed to one leaves the registers.
macro_rules! in_chunks {
    ($s:ty, $x:expr, |$c:ident, $v:ident| $vector:expr, |$ce:ident, $ve:ident| $entry:expr) => {{
        let x: &mut [f64] = $x;
        let (k, lanes) = (x.len(), <$s>::F64_LANES);
        if k < lanes {
            for ($ce, slot) in x.iter_mut().enumerate() {
                let $ve = *slot;
                *slot = $entry;
            }
        } else {
            let last = k - lanes;
            let tail = if k % lanes != 0 {
                let ($c, $v) = (last, $crate::linalg::lanes::load::<$s>(&x[last..]));
                Some($vector)
            } else {
                None
            };
            let mut $c = 0;
            while $c + lanes <= k {
                let $v = $crate::linalg::lanes::load::<$s>(&x[$c..]);
                $crate::linalg::lanes::store::<$s>(&mut x[$c..], $vector);
                $c += lanes;
            }
            if let Some(v) = tail {
                $crate::linalg::lanes::store::<$s>(&mut x[last..], v);
            }
        }
    }};
}
pub(crate) use in_chunks;

/// The vector of the first `S::F64_LANES` entries of `x` (an unaligned load).
#[inline(always)]
pub(crate) fn load<S: Simd>(x: &[f64]) -> S::f64s {
    S::as_simd_f64s(x).0[0]
}

/// Store `v` into the first `S::F64_LANES` entries of `x`.
#[inline(always)]
pub(crate) fn store<S: Simd>(x: &mut [f64], v: S::f64s) {
    S::as_mut_simd_f64s(x).0[0] = v;
}
