//! The filtered rows' products over a run of samples, and the change of origin they undergo.
//!
//! The look's rows are widened to the `D = d + 3 + n` columns every fit of a look draws from
//! ([`Layout`]). A row's columns are linear in the samples relative to an origin, and the
//! square and the cube are polynomials in it; a change of origin is a fixed sequence of column
//! operations `x_t += α x_s` ([`shift_ops`]), exact in exact arithmetic because the kernels'
//! sums are known: `Σ wy_k = 0` for `k < n`, `Σ wy_n = −L̄ⁿ`, `Σ wu_n = L̄ⁿ`, `Σ wz = 0`.

use super::super::Shape;
use super::super::rows::RowWeights;
use crate::linalg::dot;
use pulp::{Arch, Simd, WithSimd};

/// Where the columns of a widened row lie: the certificate's `d` regressors
/// (`φ^y_1..φ^y_n`, the inputs' `φ^u`, the intercept `L̄ⁿ`), then the square and the cube of
/// the excursion (weighted as `φ^y_n`), the past row's regressand and its `n` output
/// regressors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Layout {
    pub(super) n: usize,
    pub(super) m: usize,
    pub(super) d: usize,
}

impl Layout {
    pub(super) fn new(shape: Shape) -> Self {
        Self { n: shape.n, m: shape.m, d: shape.width() }
    }

    /// `D = d + 3 + n`.
    pub(super) fn wide(self) -> usize {
        self.d + 3 + self.n
    }

    pub(super) fn intercept(self) -> usize {
        self.d - 1
    }

    pub(super) fn square(self) -> usize {
        self.d
    }

    pub(super) fn cube(self) -> usize {
        self.d + 1
    }

    pub(super) fn past_z(self) -> usize {
        self.d + 2
    }

    /// The columns of the certificate's fit, of the curvature test's and of the past-row
    /// test's, in their regressors' order.
    pub(super) fn certificate(self) -> Vec<usize> {
        (0..self.d).collect()
    }

    pub(super) fn curvature(self) -> Vec<usize> {
        (0..self.d + 2).collect()
    }

    pub(super) fn past(self) -> Vec<usize> {
        (0..self.d).chain(self.past_z()..self.wide()).collect()
    }
}

/// The coefficient of an operation of the output's part of a change of origin by `dy`.
#[derive(Debug, Clone, Copy)]
pub(super) enum Coef {
    /// `3 dy`
    ThreeDy,
    /// `3 dy²`
    ThreeDy2,
    /// `−dy³`
    MinusDy3,
    /// `2 dy`
    TwoDy,
    /// `−dy²`
    MinusDy2,
    /// `−dy`
    MinusDy,
}

impl Coef {
    /// Its value at `dy`.
    #[inline(always)]
    pub(super) fn of(self, dy: f64) -> f64 {
        match self {
            Self::ThreeDy => 3.0 * dy,
            Self::ThreeDy2 => 3.0 * dy * dy,
            Self::MinusDy3 => -dy * dy * dy,
            Self::TwoDy => 2.0 * dy,
            Self::MinusDy2 => -dy * dy,
            Self::MinusDy => -dy,
        }
    }

    /// `out[i] = self.of(dy[i])`, the variant's expression compiled into the loop.
    #[inline(always)]
    pub(super) fn fill(self, dy: &[f64], out: &mut [f64]) {
        fn each(dy: &[f64], out: &mut [f64], f: impl Fn(f64) -> f64) {
            for (o, d) in out.iter_mut().zip(dy) {
                *o = f(*d);
            }
        }
        match self {
            Self::ThreeDy => each(dy, out, |d| Self::ThreeDy.of(d)),
            Self::ThreeDy2 => each(dy, out, |d| Self::ThreeDy2.of(d)),
            Self::MinusDy3 => each(dy, out, |d| Self::MinusDy3.of(d)),
            Self::TwoDy => each(dy, out, |d| Self::TwoDy.of(d)),
            Self::MinusDy2 => each(dy, out, |d| Self::MinusDy2.of(d)),
            Self::MinusDy => each(dy, out, |d| Self::MinusDy.of(d)),
        }
    }
}

/// [`shift_ops`]' operations on the output's columns, `(target, source, coefficient)` in the
/// order they apply.
pub(super) fn output_steps(lay: Layout) -> [(usize, usize, Coef); 6] {
    let (int, yn) = (lay.intercept(), lay.n - 1);
    let (sq, cube) = (lay.square(), lay.cube());
    [
        (cube, sq, Coef::ThreeDy),
        (cube, yn, Coef::ThreeDy2),
        (cube, int, Coef::MinusDy3),
        (sq, yn, Coef::TwoDy),
        (sq, int, Coef::MinusDy2),
        (yn, int, Coef::MinusDy),
    ]
}

/// The column `φ^{u_j}_n` input `j`'s change of origin moves (by `du_j L̄ⁿ`).
pub(super) fn input_column(lay: Layout, j: usize) -> usize {
    lay.n + j * lay.n + lay.n - 1
}

/// The column operations `(target, source, α)`, applied in order, that move a widened row's
/// columns from the origin `from = [y; u]` to `to` (`dy = from_y − to_y`,
/// `du = from_u − to_u`), into `ops`:
///
/// ```text
/// cube += 3 dy sq + 3 dy² φ^y_n − dy³ L̄ⁿ      sq += 2 dy φ^y_n − dy² L̄ⁿ
/// φ^y_n −= dy L̄ⁿ      φ^{u_j}_n += du_j L̄ⁿ      past φ^y_n −= dy L̄ⁿ (when `past`)
/// ```
///
/// (the cube's and the square's read the old `sq` and `φ^y_n`, hence the order).
pub(super) fn shift_ops(
    lay: Layout,
    from: &[f64],
    to: &[f64],
    past: bool,
    ops: &mut Vec<(usize, usize, f64)>,
) {
    let int = lay.intercept();
    let dy = from[0] - to[0];
    ops.clear();
    ops.extend(output_steps(lay).map(|(t, s, a)| (t, s, a.of(dy))));
    for j in 0..lay.m {
        ops.push((input_column(lay, j), int, from[1 + j] - to[1 + j]));
    }
    if past {
        ops.push((lay.wide() - 1, int, -dy));
    }
}

/// The runs `t` (to write) and `s` (to read), `t ≠ s`, of `x` cut in runs of `len`.
#[inline(always)]
pub(super) fn two_runs(x: &mut [f64], len: usize, t: usize, s: usize) -> (&mut [f64], &[f64]) {
    if t < s {
        let (lo, hi) = x.split_at_mut(s * len);
        (&mut lo[t * len..(t + 1) * len], &hi[..len])
    } else {
        let (lo, hi) = x.split_at_mut(t * len);
        (&mut hi[..len], &lo[s * len..(s + 1) * len])
    }
}

/// `S ← T S Tᵀ` for the products `S` (`dim × dim`, row-major) of `groups` stacked copies of
/// a widened row (`wide` columns each), `T` the column operations applied to every copy: for
/// each operation in order, its rows (`S_t += α S_s`, every copy), then its columns.
pub(super) fn shift_products(
    s: &mut [f64],
    dim: usize,
    groups: usize,
    wide: usize,
    ops: &[(usize, usize, f64)],
) {
    Arch::new().dispatch(ShiftProducts { s, dim, groups, wide, ops });
}

/// [`shift_products`]' arguments, compiled for the widest vectors (element-wise operations:
/// the same numbers on every width).
struct ShiftProducts<'a> {
    s: &'a mut [f64],
    dim: usize,
    groups: usize,
    wide: usize,
    ops: &'a [(usize, usize, f64)],
}

impl WithSimd for ShiftProducts<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _: S) {
        let ShiftProducts { s, dim, groups, wide, ops } = self;
        for &(t, src, a) in ops {
            for p in 0..groups {
                let (target, source) = two_runs(s, dim, p * wide + t, p * wide + src);
                for (x, y) in target.iter_mut().zip(source) {
                    *x += a * y;
                }
            }
            // Every row's copies in order: the matrix as runs of `wide`.
            assert!(t < wide && src < wide);
            for copy in s.chunks_exact_mut(wide) {
                copy[t] += a * copy[src];
            }
        }
    }
}

/// The kernels a widened row is filtered by: on the sensor noise the regressand's `wz` and
/// the output regressors' `wy_1..wy_n` (`n h + 1` taps each; the residual's kernel
/// `wz − Σ_k a_k wy_k` is their combination), on the equation noise `wv` (`n h` taps). The
/// dense ones are kept reversed (`rev[k] = w[n h − k]`), so that a filtered value is a dot
/// product of contiguous runs; `wz` is nonzero on the `n + 1` knots only.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct Kernels {
    /// `(offset, weight)` of `wz`'s nonzero taps.
    pub(super) wz: Vec<(usize, f64)>,
    /// `wy_1..wy_n` reversed.
    pub(super) wy: Vec<Vec<f64>>,
    /// `wv` reversed (`rev[k] = wv[n h − 1 − k]`).
    pub(super) wv: Vec<f64>,
    pub(super) groups: usize,
    pub(super) span: usize,
}

impl Kernels {
    pub(super) fn new(w: &RowWeights, shape: Shape) -> Self {
        let (n, span) = (shape.n, shape.span());
        let wz = w.wz.iter().copied().enumerate().filter(|(_, v)| *v != 0.0).collect();
        let wy = (0..n)
            .map(|k| w.wy[k * (span + 1)..(k + 1) * (span + 1)].iter().rev().copied().collect())
            .collect();
        let wv = w.wv.iter().rev().copied().collect();
        Self { wz, wy, wv, groups: n + 1, span }
    }
}

/// Products of the filtered rows, upper triangles: `e` over the `groups · wide` sensor-noise
/// series, `v` over the `wide` equation-noise ones.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Products {
    pub(super) e: Vec<f64>,
    pub(super) v: Vec<f64>,
}

impl Products {
    pub(super) fn zero(groups: usize, wide: usize) -> Self {
        let de = groups * wide;
        Self { e: vec![0.0; de * de], v: vec![0.0; wide * wide] }
    }

    /// The lower triangles from the upper ones.
    pub(super) fn mirror(&mut self, groups: usize, wide: usize) {
        for (s, dim) in [(&mut self.e, groups * wide), (&mut self.v, wide)] {
            for a in 0..dim {
                for b in 0..a {
                    s[a * dim + b] = s[b * dim + a];
                }
            }
        }
    }

    /// `self ← other`, reusing `self`'s storage.
    pub(super) fn copy_from(&mut self, other: &Self) {
        self.e.copy_from_slice(&other.e);
        self.v.copy_from_slice(&other.v);
    }

    pub(super) fn add(&mut self, other: &Self) {
        for (a, b) in self.e.iter_mut().zip(&other.e) {
            *a += b;
        }
        for (a, b) in self.v.iter_mut().zip(&other.v) {
            *a += b;
        }
    }
}

/// Add to `out`'s upper triangles `Σ_J Ψ_J Ψ_Jᵀ` over the samples `js`, with
/// `Ψ_J = Σ_I w_{J − I} x_I` over the rows `I ∈ rows` that reach `J` (`J − n h <= I <= J`;
/// row `I` starts at sample `I`). `x` holds the widened rows from row `x_first` by column:
/// column `c` is `x[c · len..(c + 1) · len]`. The filtered values of every `J` are formed
/// first (series by series, `psi`: scratch), then each product is one [`dot`] over the `J`s.
#[allow(clippy::too_many_arguments)]
pub(super) fn accumulate(
    x: &[f64],
    x_first: u64,
    len: usize,
    k: &Kernels,
    rows: std::ops::Range<u64>,
    js: std::ops::Range<u64>,
    out: &mut Products,
    psi: &mut Vec<f64>,
) {
    Arch::new().dispatch(Accumulate { x, x_first, len, k, rows, js, out, psi });
}

/// [`accumulate`]'s arguments, compiled for the widest vectors the processor offers: every
/// sum is a [`dot`] in its fixed four-lane order, so the numbers are the same on every width.
struct Accumulate<'a> {
    x: &'a [f64],
    x_first: u64,
    len: usize,
    k: &'a Kernels,
    rows: std::ops::Range<u64>,
    js: std::ops::Range<u64>,
    out: &'a mut Products,
    psi: &'a mut Vec<f64>,
}

impl WithSimd for Accumulate<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _: S) {
        let Accumulate { x, x_first, len, k, rows, js, out, psi } = self;
        let (groups, span) = (k.groups, k.span as u64);
        let wide = x.len() / len.max(1);
        let de = groups * wide;
        let count = (js.end - js.start) as usize;
        if count == 0 {
            return;
        }
        // Every entry of `psi[..need]` is written below before it is read.
        let need = (de + wide) * count;
        if psi.len() < need {
            psi.resize(need, 0.0);
        }
        let psi = &mut psi[..need];
        for (t, j) in js.enumerate() {
            let lo = rows.start.max(j.saturating_sub(span));
            let hi = rows.end.min(j + 1);
            let (i0, i1) = ((lo - x_first) as usize, (hi - x_first) as usize);
            let k0 = (span + lo - j) as usize;
            // `wv` reaches the rows from `J − n h + 1`.
            let lv = lo.max((j + 1).saturating_sub(span));
            let (v0, kv) = ((lv - x_first) as usize, (span + lv - j - 1) as usize);
            // `wz`'s taps that reach a row in `lo..hi` (offsets `j + 1 − hi ..= j − lo`, in
            // order), and where their rows lie in `x`.
            let (near, far) = ((j + 1 - hi) as usize, (j - lo) as usize);
            let taps = &k.wz[k.wz.partition_point(|(o, _)| *o < near)..];
            let taps = &taps[..taps.partition_point(|(o, _)| *o <= far)];
            let at = (j - x_first) as usize;
            for (c, col) in x.chunks_exact(len).enumerate() {
                let mut z = 0.0;
                for &(o, w) in taps {
                    z += w * col[at - o];
                }
                psi[c * count + t] = z;
                let run = &col[i0..i1];
                for (p, wy) in k.wy.iter().enumerate() {
                    psi[((p + 1) * wide + c) * count + t] = dot(&wy[k0..k0 + run.len()], run);
                }
                psi[(de + c) * count + t] =
                    if v0 < i1 { dot(&k.wv[kv..kv + (i1 - v0)], &col[v0..i1]) } else { 0.0 };
            }
        }
        let (pe, pv) = psi.split_at(de * count);
        for (series, out, dim) in [(pe, &mut out.e, de), (pv, &mut out.v, wide)] {
            for a in 0..dim {
                let sa = &series[a * count..(a + 1) * count];
                for b in a..dim {
                    out[a * dim + b] += dot(sa, &series[b * count..(b + 1) * count]);
                }
            }
        }
    }
}
