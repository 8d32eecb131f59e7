//! Extreme eigenvalues of small symmetric matrices: closed forms for `n <= 2`, Householder
//! tridiagonalisation with implicit QL up to `n = 9`, and from `n = 10` the reduction on both
//! triangles in the processor's vectors ([`reduce`], the same bits on every width) with
//! Laguerre's iteration for the two extremes only.

mod reduce;

use super::fast_hypot;
use reduce::{tridiagonalise_full, tridiagonalise_pair};

/// Scratch length [`sym_eig_extremes`] needs for an `n × n` matrix: `n² + 2n`.
#[must_use]
pub const fn eig_work_len(n: usize) -> usize {
    n * n + 2 * n
}

/// Smallest and largest eigenvalue of the symmetric `n × n` matrix `a` (row-major; only the
/// upper triangle is read), using `work` (at least [`eig_work_len`]`(n)` long) as scratch.
///
/// `n = 1, 2` use closed forms; larger `n` use Householder tridiagonalisation followed by the
/// implicit QL iteration (EISPACK `tred1`/`tql1`, as in Numerical Recipes `tred2`/`tqli`
/// without eigenvectors): `O(n³)` with a small constant, backward stable. Returns NaNs if
/// the iteration fails to converge (it does not for finite input).
///
/// The closed forms are always inlined (with a literal `n` at the call site they reduce to a
/// few instructions); the iterative method for `n > 2` stays out of line.
#[must_use]
#[inline(always)]
pub fn sym_eig_extremes(a: &[f64], n: usize, work: &mut [f64]) -> (f64, f64) {
    match n {
        0 => (f64::NAN, f64::NAN),
        1 => (a[0], a[0]),
        2 => {
            let (p, q, r) = (a[0], a[1], a[3]);
            let mean = 0.5 * (p + r);
            let diff = 0.5 * (p - r);
            // √(diff² + q²) without the cost of `hypot`, which it falls back to on overflow.
            // The test is on the radicand, so the branch does not wait for the square root.
            let radicand = diff * diff + q * q;
            let half = if radicand.is_finite() { radicand.sqrt() } else { diff.hypot(q) };
            (mean - half, mean + half)
        }
        _ => sym_eig_extremes_iterative(a, n, work),
    }
}

/// [`sym_eig_extremes`] for a matrix the caller knows to be positive semi-definite in exact
/// arithmetic (a Gram matrix `Σ z zᵀ`): the same contract and, below `n = 10`, the same
/// result bit for bit. From `n = 10` Laguerre's iteration for `λ_min` starts at `0⁻`
/// (`λ = −10⁻¹²` on the matrix scaled to unit size) instead of Gershgorin's lower bound,
/// which for an ill-conditioned Gram matrix lies far below a cluster of small eigenvalues
/// that Laguerre then approaches linearly (about 10 iterations at `n = 20` on the `p = m = 10`
/// bench's stream against 5 from `0⁻`). The start is checked, not assumed: when rounding has
/// left an eigenvalue of the reduced matrix below it (a sign change in the `LDLᵀ` pivots of
/// `T − λ I`), that run restarts from Gershgorin's bound, which is then the arithmetic of
/// [`sym_eig_extremes`] exactly.
#[must_use]
#[inline(always)]
pub fn psd_eig_extremes(a: &[f64], n: usize, work: &mut [f64]) -> (f64, f64) {
    if n < FULL_ROWS_FROM {
        return sym_eig_extremes(a, n, work);
    }
    sym_eig_laguerre(a, n, work, Want::BothPsd)
}

/// The largest eigenvalue of the symmetric `n × n` matrix `a` (upper triangle read), with
/// `work` as in [`sym_eig_extremes`]: its `.1`, bit for bit, but from `n = 10` the smallest
/// eigenvalue's Laguerre iteration is skipped (about a quarter of the eigenvalue work of the
/// `p = 10` certifier step, whose `β̂ = −λ_max(sym J_cl)` needs only this end).
#[must_use]
#[inline(always)]
pub fn sym_eig_max(a: &[f64], n: usize, work: &mut [f64]) -> f64 {
    if n < FULL_ROWS_FROM {
        return sym_eig_extremes(a, n, work).1;
    }
    sym_eig_laguerre(a, n, work, Want::Max).1
}

/// Which extremes [`sym_eig_laguerre`] computes, and from where `λ_min`'s iteration starts.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Want {
    /// `λ_max` only (`λ_min` is NaN in the result).
    Max,
    /// Both, each from Gershgorin's bound.
    Both,
    /// Both, `λ_min` from `0⁻` (positive semi-definite input, see [`psd_eig_extremes`]).
    BothPsd,
}

/// From `n = 10`: both triangles, the reduction, Laguerre for the extremes `want` asks for;
/// QL for every eigenvalue when Laguerre does not settle.
#[inline(never)]
fn sym_eig_laguerre(a: &[f64], n: usize, work: &mut [f64], want: Want) -> (f64, f64) {
    let (w, d, e) = both_triangles(a, n, work);
    tridiagonalise_full(w, n, d, e);
    extremes_of_reduced(d, e, want)
}

/// `a`'s upper triangle into both triangles of `work`'s first `n²` entries, and the slices
/// for the diagonal and off-diagonal that follow.
fn both_triangles<'w>(
    a: &[f64],
    n: usize,
    work: &'w mut [f64],
) -> (&'w mut [f64], &'w mut [f64], &'w mut [f64]) {
    let (w, rest) = work[..eig_work_len(n)].split_at_mut(n * n);
    let (d, e) = rest.split_at_mut(n);
    // Each row's upper part in one copy, its lower part from the column above.
    for i in 0..n {
        w[i * n + i..(i + 1) * n].copy_from_slice(&a[i * n + i..(i + 1) * n]);
        for j in 0..i {
            w[i * n + j] = a[j * n + i];
        }
    }
    (w, d, e)
}

/// The extremes `want` asks for of the reduced matrix (`e[1..]` the sub-diagonal): Laguerre,
/// QL if it does not converge.
fn extremes_of_reduced(d: &mut [f64], e: &mut [f64], want: Want) -> (f64, f64) {
    if let Some(pair) = tridiagonal_extremes(d, &e[1..], want) {
        return pair;
    }
    ql_extremes(d, e)
}

/// `(`[`psd_eig_extremes`]`(g, n, g_work), `[`sym_eig_max`]`(s, m, s_work))`, bit for bit, with
/// the two problems advanced side by side from `n, m >= 10`: the two Householder reductions
/// step by step, then the three Laguerre runs (`λ_min` and `λ_max` of `g`, `λ_max` of `s`) in
/// one loop. Each problem's arithmetic is what it is alone; the processor overlaps the two
/// chains of dependent operations (the `p = m = 10` certifier step's Gram matrix and
/// `sym Ĵ_cl`: about 0.3 of 2.7 µs, BENCHMARKS.md). A problem whose tridiagonal is not
/// finite or is zero, or a run that does not settle, takes its own path as alone.
#[must_use]
pub fn psd_extremes_and_sym_max(
    g: &[f64],
    n: usize,
    g_work: &mut [f64],
    s: &[f64],
    m: usize,
    s_work: &mut [f64],
) -> ((f64, f64), f64) {
    if n < FULL_ROWS_FROM || m < FULL_ROWS_FROM {
        return (psd_eig_extremes(g, n, g_work), sym_eig_max(s, m, s_work));
    }
    let (wg, dg, eg) = both_triangles(g, n, g_work);
    let (ws, ds, es) = both_triangles(s, m, s_work);
    tridiagonalise_pair(wg, n, dg, eg, ws, m, ds, es);
    let nonzero = |d: &[f64], e: &[f64]| largest_entry(d, e).filter(|&s| s > 0.0);
    if let (Some(sg), Some(ss)) = (nonzero(dg, &eg[1..]), nonzero(ds, &es[1..])) {
        let (ig, is) = (1.0 / sg, 1.0 / ss);
        let runs = [(&dg[..], &eg[1..], ig), (&dg[..], &eg[1..], ig), (&ds[..], &es[1..], is)];
        if let Some([hi, lo, top]) = laguerre_runs(runs, [1.0, -1.0, 1.0], [false, true, false]) {
            return ((-lo * sg, hi * sg), top * ss);
        }
    }
    (extremes_of_reduced(dg, eg, Want::BothPsd), extremes_of_reduced(ds, es, Want::Max).1)
}

/// Every eigenvalue of the tridiagonal (`d`, `e[1..]`) by QL, then the two extremes (NaN
/// when QL does not converge).
fn ql_extremes(d: &mut [f64], e: &mut [f64]) -> (f64, f64) {
    if !tridiagonal_ql(d, e) {
        return (f64::NAN, f64::NAN);
    }
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for &v in d.iter() {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    (lo, hi)
}

/// [`sym_eig_extremes`] for `n > 2`: Householder tridiagonalisation and implicit QL.
#[inline(never)]
fn sym_eig_extremes_iterative(a: &[f64], n: usize, work: &mut [f64]) -> (f64, f64) {
    if n >= FULL_ROWS_FROM {
        return sym_eig_laguerre(a, n, work, Want::Both);
    }
    let (w, rest) = work[..eig_work_len(n)].split_at_mut(n * n);
    let (d, e) = rest.split_at_mut(n);
    // Lower triangle of w from the upper triangle of a.
    for i in 0..n {
        for j in 0..=i {
            w[i * n + j] = a[j * n + i];
        }
    }
    tridiagonalise(w, n, d, e);
    ql_extremes(d, e)
}

/// Householder reduction of the symmetric matrix held in the lower triangle of `a` to
/// tridiagonal form: diagonal in `d`, sub-diagonal in `e[1..]` (`e[0] = 0`).
fn tridiagonalise(a: &mut [f64], n: usize, d: &mut [f64], e: &mut [f64]) {
    for i in (1..n).rev() {
        let l = i - 1;
        let mut h = 0.0;
        if l > 0 {
            let scale: f64 = (0..=l).map(|k| a[i * n + k].abs()).sum();
            if scale == 0.0 {
                e[i] = a[i * n + l];
            } else {
                for k in 0..=l {
                    a[i * n + k] /= scale;
                    h += a[i * n + k] * a[i * n + k];
                }
                let f = a[i * n + l];
                let g = if f >= 0.0 { -h.sqrt() } else { h.sqrt() };
                e[i] = scale * g;
                h -= f * g;
                a[i * n + l] = f - g;
                let mut f = 0.0;
                for j in 0..=l {
                    let mut g = 0.0;
                    for k in 0..=j {
                        g += a[j * n + k] * a[i * n + k];
                    }
                    for k in j + 1..=l {
                        g += a[k * n + j] * a[i * n + k];
                    }
                    e[j] = g / h;
                    f += e[j] * a[i * n + j];
                }
                let hh = f / (h + h);
                for j in 0..=l {
                    let f = a[i * n + j];
                    let g = e[j] - hh * f;
                    e[j] = g;
                    for k in 0..=j {
                        a[j * n + k] -= f * e[k] + g * a[i * n + k];
                    }
                }
            }
        } else {
            e[i] = a[i * n + l];
        }
        d[i] = h;
    }
    e[0] = 0.0;
    for i in 0..n {
        d[i] = a[i * n + i];
    }
}

/// From this size on [`sym_eig_extremes`] reduces on both triangles ([`tridiagonalise_full`]:
/// contiguous rows, so the products vectorise) and finds the two extremes of the tridiagonal
/// by Laguerre ([`tridiagonal_extremes`]) instead of every eigenvalue by QL. Below it the
/// original path is kept, so the results for the paper's and the validity study's matrices
/// (up to the `9 × 9` score covariance of `p = 3`) stay bit for bit what they were.
const FULL_ROWS_FROM: usize = 10;

/// The smallest and largest eigenvalues of the symmetric tridiagonal matrix with diagonal `d`
/// and off-diagonal `e` (`d.len() − 1` entries), without the others: Laguerre's iteration on
/// `p(x) = det(xI − T)` from Gershgorin's bound outside the spectrum. For a polynomial with
/// real roots it converges monotonically (cubically near a simple root) to the extreme root
/// on that side. `G = (ln p)'` and `H = −(ln p)''` come from the `LDLᵀ` recurrence
/// `q_0 = x − d_0`, `q_i = x − d_i − e²_{i−1}/q_{i−1}` and its first two derivatives (one
/// division per entry, see [`laguerre_tops`]), on the matrix scaled to unit size (no overflow for any finite input),
/// and the step is `n / (G + √((n − 1)(nH − G²)))`. `None` when an iteration does not settle in
/// 100 steps (the caller then uses QL). About 10× cheaper than QL for all eigenvalues at
/// `n = 20`, whose square roots and divisions dominate it.
///
/// With [`Want::Max`] only `λ_max` is computed (`λ_min` is NaN in the result); with
/// [`Want::BothPsd`] `λ_min`'s run starts at `0⁻` when that is above `−λ_min` (checked).
fn tridiagonal_extremes(d: &[f64], e: &[f64], want: Want) -> Option<(f64, f64)> {
    // A value that is not finite goes to QL, which carries it into the result.
    let scale = largest_entry(d, e)?;
    if scale == 0.0 {
        return Some((0.0, 0.0));
    }
    let inv = 1.0 / scale;
    // The extreme on the upper side of (sign · d, e): sign = 1 gives λ_max, −1 gives −λ_min.
    // Both runs advance in the same loop (independent chains of divisions, which the
    // processor overlaps); each does exactly the arithmetic it would do alone.
    if want == Want::Max {
        let [hi] = laguerre_tops(d, e, inv, [1.0], [false])?;
        Some((f64::NAN, hi * scale))
    } else {
        let [hi, lo] = laguerre_tops(d, e, inv, [1.0, -1.0], [false, want == Want::BothPsd])?;
        Some((-lo * scale, hi * scale))
    }
}

/// `max |v|` over the diagonal `d` and off-diagonal `e`, `None` when a value is not finite
/// (`f64::max` would skip a NaN and report a number).
fn largest_entry(d: &[f64], e: &[f64]) -> Option<f64> {
    if !d.iter().chain(e).all(|v| v.is_finite()) {
        return None;
    }
    Some(d.iter().chain(e).fold(0.0f64, |m, v| m.max(v.abs())))
}

/// [`tridiagonal_extremes`] for a test: `want_min` selects [`Want::Both`] or [`Want::Max`].
#[cfg(test)]
pub(super) fn tridiagonal_extremes_for_test(
    d: &[f64],
    e: &[f64],
    want_min: bool,
) -> Option<(f64, f64)> {
    tridiagonal_extremes(d, e, if want_min { Want::Both } else { Want::Max })
}

/// Laguerre's iteration for [`tridiagonal_extremes`] on the matrix scaled by `inv`, one run
/// per sign, advanced side by side: each run starts at Gershgorin's bound (plus `1e-12`), or
/// at `1e-12` where `from_zero` says so (a positive semi-definite matrix's `−λ_min ≤ 0`), and
/// stops on its own test; `None` when any run does not settle in 100 steps or takes a step
/// that is not finite and positive. A run started at `1e-12` whose first pass meets a pivot
/// `q_i ≤ 0` (the start is not above the spectrum) starts again from Gershgorin's bound. The
/// reciprocal `1/q_{i−1}` of an entry is the one the previous entry computed (one division
/// per entry).
fn laguerre_tops<const S: usize>(
    d: &[f64],
    e: &[f64],
    inv: f64,
    signs: [f64; S],
    from_zero: [bool; S],
) -> Option<[f64; S]> {
    laguerre_runs([(d, e, inv); S], signs, from_zero)
}

/// Gershgorin's upper bound on the eigenvalues of the tridiagonal `sign · inv · (d, e)`.
#[inline(always)]
fn gershgorin_top(d: &[f64], e: &[f64], inv: f64, sign: f64) -> f64 {
    let n = d.len();
    let mut x = f64::NEG_INFINITY;
    for i in 0..n {
        let off =
            if i > 0 { e[i - 1].abs() } else { 0.0 } + if i + 1 < n { e[i].abs() } else { 0.0 };
        x = x.max(sign * d[i] * inv + off * inv);
    }
    x
}

/// [`laguerre_tops`] with each run on its own tridiagonal `(d, e, inv)` (the runs of two
/// matrices advance side by side as those of one do); each run's arithmetic is what it
/// would be alone.
pub(super) fn laguerre_runs<const S: usize>(
    mats: [(&[f64], &[f64], f64); S],
    signs: [f64; S],
    from_zero: [bool; S],
) -> Option<[f64; S]> {
    let lens = mats.map(|(d, _, _)| d.len());
    let longest = lens.iter().copied().max().unwrap_or(0);
    let mut gershgorin = [0.0f64; S];
    for s in 0..S {
        let (d, e, inv) = mats[s];
        gershgorin[s] = gershgorin_top(d, e, inv, signs[s]) + 1e-12;
    }
    let mut x = gershgorin;
    // Runs whose start is still to be checked (started at 1e-12 below Gershgorin's bound).
    let mut unchecked = [false; S];
    for s in 0..S {
        if from_zero[s] && 1e-12 < x[s] {
            x[s] = 1e-12;
            unchecked[s] = true;
        }
    }
    let mut done = [false; S];
    for _ in 0..100 {
        // Per run: q_{i−1}'s derivatives and reciprocal, G, H, and whether an entry reached an
        // eigenvalue to working precision (the run then ends at x).
        let (mut q1, mut q2, mut r) = ([0.0f64; S], [0.0f64; S], [0.0f64; S]);
        let (mut g, mut h) = ([0.0f64; S], [0.0f64; S]);
        let mut hit = done;
        for i in 0..longest {
            for s in 0..S {
                if hit[s] || i >= lens[s] {
                    continue;
                }
                let (d, e, inv) = mats[s];
                let b2 = if i == 0 { 0.0 } else { (e[i - 1] * inv) * (e[i - 1] * inv) };
                let di = signs[s] * d[i] * inv;
                let (qi, qi1, qi2) = if i == 0 {
                    (x[s] - di, 1.0, 0.0)
                } else {
                    let rp = r[s];
                    let (r1, r2) = (q1[s] * rp, q2[s] * rp);
                    (x[s] - di - b2 * rp, 1.0 + b2 * r1 * rp, b2 * rp * (r2 - 2.0 * r1 * r1))
                };
                if !(qi > 0.0) {
                    hit[s] = true;
                    continue;
                }
                let ri = 1.0 / qi;
                let a1 = qi1 * ri;
                g[s] += a1;
                h[s] += a1 * a1 - qi2 * ri;
                (q1[s], q2[s], r[s]) = (qi1, qi2, ri);
            }
        }
        for s in 0..S {
            if done[s] {
                continue;
            }
            if std::mem::take(&mut unchecked[s]) && hit[s] {
                // The start is inside the spectrum: Gershgorin's bound instead (this pass's
                // step is not taken).
                x[s] = gershgorin[s];
                continue;
            }
            if hit[s] {
                done[s] = true;
                continue;
            }
            let nf = lens[s] as f64;
            let disc = ((nf - 1.0) * (nf * h[s] - g[s] * g[s])).max(0.0);
            let step = nf / (g[s] + disc.sqrt());
            if !step.is_finite() || step < 0.0 {
                return None;
            }
            x[s] -= step;
            if step <= 4.0 * f64::EPSILON * x[s].abs().max(1.0) {
                done[s] = true;
            }
        }
        if done.iter().all(|&d| d) {
            return Some(x);
        }
    }
    None
}

/// Eigenvalues of the symmetric tridiagonal matrix (`d` diagonal, `e[1..]` sub-diagonal) by
/// the implicit QL method with Wilkinson shifts; overwrites `d` with the eigenvalues.
pub(super) fn tridiagonal_ql(d: &mut [f64], e: &mut [f64]) -> bool {
    let n = d.len();
    for i in 1..n {
        e[i - 1] = e[i];
    }
    e[n - 1] = 0.0;
    for l in 0..n {
        let mut iter = 0;
        loop {
            let mut m = l;
            while m + 1 < n {
                let dd = d[m].abs() + d[m + 1].abs();
                if e[m].abs() <= f64::EPSILON * dd {
                    break;
                }
                m += 1;
            }
            if m == l {
                break;
            }
            iter += 1;
            if iter > 60 {
                return false;
            }
            let mut g = (d[l + 1] - d[l]) / (2.0 * e[l]);
            let mut r = fast_hypot(g, 1.0);
            g = d[m] - d[l] + e[l] / (g + if g >= 0.0 { r.abs() } else { -r.abs() });
            let (mut s, mut c, mut p) = (1.0, 1.0, 0.0);
            let mut deflated = false;
            for i in (l..m).rev() {
                let f = s * e[i];
                let b = c * e[i];
                r = fast_hypot(f, g);
                e[i + 1] = r;
                if r == 0.0 {
                    d[i + 1] -= p;
                    e[m] = 0.0;
                    deflated = true;
                    break;
                }
                s = f / r;
                c = g / r;
                g = d[i + 1] - p;
                r = (d[i] - g) * s + 2.0 * c * b;
                p = s * r;
                d[i + 1] = g + p;
                g = c * r - b;
            }
            if deflated {
                continue;
            }
            d[l] -= p;
            e[l] = g;
            e[m] = 0.0;
        }
    }
    true
}
