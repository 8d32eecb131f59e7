//! [`OrderNWindow`]: a sliding window's looks of order `n` (the fit, the past-row test and the
//! curvature test, each with the model-structured covariance) from what earlier looks
//! computed, instead of from the window's samples alone.
//!
//! ## What is kept, and why the answer does not depend on it
//!
//! - **Rows.** Each row is computed once, from its own samples, relative to its own first
//!   sample, with the weights of its spacing `Δ` rounded to 36 bits (the rows of an equally
//!   spaced stream share them, or one of two neighbours'). At a look every row is moved to
//!   the window's origin by [`shift_ops`](filter::shift_ops).
//! - **Filtered products in units.** The covariance needs `H = Σ_J Ψ_J Ψ_Jᵀ` of the rows
//!   filtered by the residual's kernel; that kernel is `wz − Σ_k â_k wy_k`, so `H` is a
//!   quadratic form in `(1, −â)` over the products of the rows filtered by the fixed kernels
//!   `wz, wy_1..wy_n` (and `wv` for the equation noise). Those products are summed over units
//!   of [`UNIT`] samples aligned on the sample count, each relative to its own origin (the
//!   first sample of the first row it reaches, `n h` before it), and moved to the window's
//!   origin at a look.
//!
//! Everything kept is a function of the samples it was computed from, never of when it was
//! computed: a look gives the same bits whether its rows and units were kept from earlier
//! looks or computed at once from the window (after a restore, say). Which units a look takes
//! whole is fixed by the window alone: those wholly inside a fit's samples whose filtered rows
//! have all their rows in the fit (`Ψ_J` for `J` from the fit's first row plus `n h` to its
//! last row); the rest (the window's two edges of `n h` samples, the parts of units at the
//! ends) is computed at the look, relative to the window's origin.
//!
//! ## Equal spacing
//!
//! The shared kernels need every row of the window to be equally spaced (the offsets of its
//! samples from its first within `10⁻¹²` of its span of `i Δ`) with spacings that agree to
//! `10⁻⁹`. A window with any other row is not taken ([`OrderNWindow::prepare`] returns
//! `None`) and the caller fits the samples ([`OrderNRecord`](super::OrderNRecord)).

mod filter;
mod look;

use super::rows::RowWeights;
use super::{OrderNConfig, Shape};
use crate::RegressionError;
use filter::{Kernels, Layout, Products, accumulate, input_column, output_steps, two_runs};
pub use look::WindowLook;
use pulp::{Arch, Simd, WithSimd};
use std::mem::take;

/// Samples per unit of kept filtered products.
pub(crate) const UNIT: u64 = 32;

/// One unit's filtered products, relative to its origin.
#[derive(Debug, Clone, PartialEq)]
struct Unit {
    /// Its first sample `J` (a multiple of [`UNIT`]).
    first: u64,
    /// `[y; u]` of the sample it is relative to.
    origin: Vec<f64>,
    /// Whether its rows' past rows were all available (the past columns are valid).
    past: bool,
    sums: Products,
}

/// Buffers reused from look to look (their contents are never read before written): not part
/// of the window's state, so they take no part in equality.
#[derive(Clone, Default)]
struct Scratch {
    x: Vec<f64>,
    a: Vec<f64>,
    psi: Vec<f64>,
    ys: Vec<f64>,
    us: Vec<f64>,
}

impl PartialEq for Scratch {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl std::fmt::Debug for Scratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Scratch")
    }
}

/// The sliding window's looks of order `n` from kept rows and filtered products (module docs).
/// Feed it each look's window of samples with the count of the samples before it
/// ([`prepare`](Self::prepare)); [`clear`](Self::clear) it after a gap.
#[derive(Debug, Clone, PartialEq)]
pub struct OrderNWindow {
    shape: Shape,
    min_excitation_ratio: f64,
    /// The weights of the spacings seen last, by their key (at most four), and their kernels.
    weights: Vec<(u64, RowWeights, Kernels)>,
    /// Kept rows from row `rows_first`: `d + 3` values each (`φ`, `z`, the square, the cube)
    /// relative to the row's first sample, that sample's `[y; u]`, the row's spacing key.
    rows_first: u64,
    rows: Vec<f64>,
    origins: Vec<f64>,
    keys: Vec<Option<u64>>,
    units: Vec<Unit>,
    scratch: Scratch,
}

/// A row's weights' key: the spacing `Δ` of its span rounded to 36 significant bits (rows of
/// an equally spaced stream share it, or take one of two neighbours); `None` when its samples'
/// offsets from the first are not within `10⁻¹²` of its span of `i Δ`.
fn spacing_key(t: &[f64]) -> Option<u64> {
    let span = t.len() - 1;
    let length = t[span] - t[0];
    let delta = length / span as f64;
    let regular = t
        .iter()
        .enumerate()
        .all(|(i, ti)| ((ti - t[0]) - i as f64 * delta).abs() <= 1e-12 * length);
    regular.then_some((delta.to_bits() + (1 << 15)) & !((1u64 << 16) - 1))
}

/// Whether two keys' spacings agree to `10⁻⁹` (their weights are interchangeable).
fn alike(a: u64, b: u64) -> bool {
    let (a, b) = (f64::from_bits(a), f64::from_bits(b));
    (a - b).abs() <= 1e-9 * a.abs()
}

impl OrderNWindow {
    /// An empty window for `cfg` (its `window`, `min_rows` and `refresh_period` are the
    /// caller's).
    ///
    /// # Errors
    /// [`RegressionError::InvalidConfig`] as [`OrderNConfig::validate`].
    pub fn new(cfg: &OrderNConfig) -> Result<Self, RegressionError> {
        cfg.validate()?;
        Ok(Self {
            shape: cfg.shape(),
            min_excitation_ratio: cfg.min_excitation_ratio,
            weights: Vec::new(),
            rows_first: 0,
            rows: Vec::new(),
            origins: Vec::new(),
            keys: Vec::new(),
            units: Vec::new(),
            scratch: Scratch::default(),
        })
    }

    /// Forget every kept row and unit (after a gap, when the samples' count starts again).
    pub fn clear(&mut self) {
        self.rows.clear();
        self.origins.clear();
        self.keys.clear();
        self.units.clear();
    }

    fn base(&self) -> usize {
        self.shape.width() + 3
    }

    fn weights_of(&mut self, key: u64) -> usize {
        if let Some(i) = self.weights.iter().position(|(k, ..)| *k == key) {
            return i;
        }
        let span = self.shape.span();
        let step = f64::from_bits(key);
        let ideal: Vec<f64> = (0..=span).map(|i| i as f64 * step).collect();
        let mut w = RowWeights::new(self.shape);
        w.fill(self.shape, &ideal);
        if self.weights.len() == 4 {
            self.weights.remove(0);
        }
        let kernels = Kernels::new(&w, self.shape);
        self.weights.push((key, w, kernels));
        self.weights.len() - 1
    }

    /// Row `first + i`'s kept values from the window's samples (`i` its first sample).
    #[inline(always)]
    fn push_row(&mut self, i: usize, t: &[f64], y: &[f64], u: &[f64]) {
        let Shape { n, m, .. } = self.shape;
        let (span, d) = (self.shape.span(), self.shape.width());
        let s = i..i + span + 1;
        let key = spacing_key(&t[s.clone()]);
        let (y0, u0) = (y[i], &u[i * m..(i + 1) * m]);
        let at = self.rows.len();
        self.rows.resize(at + d + 3, 0.0);
        if let Some(key) = key {
            let (mut ys, mut us) = (take(&mut self.scratch.ys), take(&mut self.scratch.us));
            ys.clear();
            ys.extend(y[s.clone()].iter().map(|v| v - y0));
            us.clear();
            us.extend(u[i * m..(i + span + 1) * m].iter().enumerate().map(|(k, v)| v - u0[k % m]));
            let w = self.weights_of(key);
            let w = &self.weights[w].1;
            let row = &mut self.rows[at..];
            row[d] = w.apply(self.shape, &ys, &us, &mut row[..d]);
            let wn = &w.wy[(n - 1) * (span + 1)..n * (span + 1)];
            let (mut square, mut cube) = (0.0, 0.0);
            for (wi, e) in wn.iter().zip(&ys) {
                let e2 = e * e;
                square += wi * e2;
                cube += wi * e2 * e;
            }
            (row[d + 1], row[d + 2]) = (square, cube);
            (self.scratch.ys, self.scratch.us) = (ys, us);
        }
        self.origins.push(y0);
        self.origins.extend_from_slice(u0);
        self.keys.push(key);
    }
}

/// The rows `new` kept from the window's samples (whose first is sample `first`), compiled
/// for the widest vectors (the same numbers on every width).
struct PushRows<'a> {
    window: &'a mut OrderNWindow,
    first: u64,
    new: std::ops::Range<u64>,
    t: &'a [f64],
    y: &'a [f64],
    u: &'a [f64],
}

impl WithSimd for PushRows<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, _: S) {
        let PushRows { window, first, new, t, y, u } = self;
        // A loop, not a closure: a closure is not compiled with the vectors' features.
        for r in new {
            window.push_row((r - first) as usize, t, y, u);
        }
    }
}

impl OrderNWindow {
    /// Take a look's window: the samples `t`, `y`, `u` (`u` row-major, `m` per sample), the
    /// first of them the `first`-th sample since the start or the last [`clear`](Self::clear).
    /// Computes the rows and the units not kept yet, and drops what left the window. `None`
    /// when the window's rows are not all equally spaced alike (fit the samples instead) or
    /// it holds no row.
    pub fn prepare<'a>(
        &'a mut self,
        first: u64,
        t: &[f64],
        y: &[f64],
        u: &[f64],
    ) -> Option<WindowLook<'a>> {
        let (span, m, base) = (self.shape.span(), self.shape.m, self.base());
        let count = t.len();
        if count <= span || y.len() != count || u.len() != count * m {
            return None;
        }
        let end = first + (count - span) as u64;
        let kept_end = self.rows_first + self.keys.len() as u64;
        if self.keys.is_empty() || self.rows_first > first || kept_end < first || kept_end > end {
            self.clear();
            self.rows_first = first;
        } else if self.rows_first < first {
            let gone = (first - self.rows_first) as usize;
            self.rows.drain(..gone * base);
            self.origins.drain(..gone * (1 + m));
            self.keys.drain(..gone);
            self.rows_first = first;
        }
        let new = self.rows_first + self.keys.len() as u64..end;
        Arch::new().dispatch(PushRows { window: self, first, new, t, y, u });
        let key = self.keys[0]?;
        if !self.keys.iter().all(|k| k.is_some_and(|k| alike(k, key))) {
            return None;
        }
        self.units.retain(|unit| unit.first >= first + span as u64 && unit.first + UNIT <= end);
        let mut j = (first + span as u64).div_ceil(UNIT) * UNIT;
        while j + UNIT <= end {
            if self.units.binary_search_by_key(&j, |unit| unit.first).is_err() {
                self.keep_unit(j, first, key);
            }
            j += UNIT;
        }
        Some(WindowLook::new(self, first, end, key))
    }

    /// The rows `rows` widened relative to `origin`, by column (`wide` columns of
    /// `rows.len()`), into `x`; their past columns (from row `r − n h − 1`) where `past(r)`,
    /// else zero. Column by column, each row's entries take [`shift_ops`]'s operations in
    /// their order (the same numbers as moving each row by itself). `a`: scratch.
    fn widened_columns(
        &self,
        rows: std::ops::Range<u64>,
        origin: &[f64],
        past: impl Fn(u64) -> bool,
        x: &mut Vec<f64>,
        a: &mut Vec<f64>,
    ) {
        let lay = Layout::new(self.shape);
        let (d, n, m, base, wide) = (lay.d, lay.n, lay.m, self.base(), lay.wide());
        let len = (rows.end - rows.start) as usize;
        let at0 = (rows.start - self.rows_first) as usize;
        x.clear();
        x.resize(wide * len, 0.0);
        let kept = &self.rows[at0 * base..(at0 + len) * base];
        for (i, row) in kept.chunks_exact(base).enumerate() {
            for c in 0..d {
                x[c * len + i] = row[c];
            }
            x[lay.square() * len + i] = row[d + 1];
            x[lay.cube() * len + i] = row[d + 2];
        }
        let origins = &self.origins[at0 * (1 + m)..(at0 + len) * (1 + m)];
        // `x_t += a x_s` down two columns, `a` per row.
        let axpy = |x: &mut [f64], t: usize, s: usize, a: &[f64]| {
            let (target, source) = two_runs(x, len, t, s);
            for ((xt, xs), ai) in target.iter_mut().zip(source).zip(a) {
                *xt += ai * xs;
            }
        };
        a.clear();
        a.resize(2 * len, 0.0);
        let (dy, coef) = a.split_at_mut(len);
        for (dy, o) in dy.iter_mut().zip(origins.chunks_exact(1 + m)) {
            *dy = o[0] - origin[0];
        }
        for (t, s, f) in output_steps(lay) {
            f.fill(dy, coef);
            axpy(x, t, s, coef);
        }
        for j in 0..m {
            for (c, o) in coef.iter_mut().zip(origins.chunks_exact(1 + m)) {
                *c = o[1 + j] - origin[1 + j];
            }
            axpy(x, input_column(lay, j), lay.intercept(), coef);
        }
        let l1 = self.shape.span() as u64 + 1;
        for (i, r) in rows.enumerate() {
            if !past(r) {
                continue;
            }
            let p = (r - l1 - self.rows_first) as usize;
            let (prow, po) = (&self.rows[p * base..][..base], &self.origins[p * (1 + m)..]);
            x[lay.past_z() * len + i] = prow[d];
            for k in 0..n {
                x[(lay.past_z() + 1 + k) * len + i] = prow[k];
            }
            x[(wide - 1) * len + i] -= (po[0] - origin[0]) * prow[lay.intercept()];
        }
    }

    /// The unit of samples `j..j + UNIT` (the window's first row is `first`), relative to the
    /// first sample of its first row `j − n h`, kept in order.
    fn keep_unit(&mut self, j: u64, first: u64, key: u64) -> usize {
        let unit = self.unit(j, first, key);
        let at = self.units.partition_point(|u| u.first < j);
        if self.units.get(at).is_some_and(|u| u.first == j) {
            self.units[at] = unit;
        } else {
            self.units.insert(at, unit);
        }
        at
    }

    fn unit(&mut self, j: u64, first: u64, window_key: u64) -> Unit {
        let lay = Layout::new(self.shape);
        let (span, m, wide) = (self.shape.span() as u64, self.shape.m, lay.wide());
        let lo = j - span;
        let past = lo > first + span;
        let at = (lo - self.rows_first) as usize;
        let origin = self.origins[at * (1 + m)..(at + 1) * (1 + m)].to_vec();
        let rows = lo..j + UNIT;
        let (mut x, mut a, mut psi) =
            (take(&mut self.scratch.x), take(&mut self.scratch.a), take(&mut self.scratch.psi));
        self.widened_columns(rows.clone(), &origin, |_| past, &mut x, &mut a);
        // The unit's weights are its first row's (every row of a window taken has a key).
        let key = self.keys[at].unwrap_or(window_key);
        let w = self.weights_of(key);
        let kernels = &self.weights[w].2;
        let mut sums = Products::zero(kernels.groups, wide);
        let len = (span + UNIT) as usize;
        accumulate(&x, lo, len, kernels, rows, j..j + UNIT, &mut sums, &mut psi);
        sums.mirror(kernels.groups, wide);
        self.scratch = Scratch { x, a, psi, ..take(&mut self.scratch) };
        Unit { first: j, origin, past, sums }
    }
}

#[cfg(test)]
mod tests {
    use super::filter::{shift_ops, shift_products};
    use super::*;
    use crate::LoopModel;

    /// The widened columns, moved column by column, are the kept rows moved one at a time by
    /// [`shift_ops`] in its order, bit for bit, past columns included.
    #[test]
    fn widened_columns_are_each_row_moved_by_itself() {
        for (n, m) in [(2, 1), (3, 2)] {
            let cfg = OrderNConfig::new(LoopModel::of_order(n).unwrap(), m, 400, 5);
            let len = 600;
            let t: Vec<f64> = (0..len).map(|k| k as f64 * 0.01).collect();
            let y: Vec<f64> =
                t.iter().map(|t| 3.0 + (1.3 * t).sin() + 0.2 * (7.1 * t).cos()).collect();
            let u: Vec<f64> =
                (0..len * m).map(|k| ((k / m) as f64 * 0.037 + k as f64).sin()).collect();
            let mut window = OrderNWindow::new(&cfg).unwrap();
            assert!(window.prepare(0, &t, &y, &u).is_some());
            let lay = Layout::new(window.shape);
            let (d, base, wide) = (lay.d, window.base(), lay.wide());
            let origin = vec![2.5; 1 + m];
            let l1 = window.shape.span() as u64 + 1;
            let rows = 3..len as u64 - window.shape.span() as u64;
            let past = |r: u64| r >= 3 + l1;
            let (mut x, mut a, mut ops) = (Vec::new(), Vec::new(), Vec::new());
            window.widened_columns(rows.clone(), &origin, past, &mut x, &mut a);
            let count = (rows.end - rows.start) as usize;
            for (i, r) in rows.enumerate() {
                let at = |r: u64| r as usize;
                let (row, o) =
                    (&window.rows[at(r) * base..][..base], &window.origins[at(r) * (1 + m)..]);
                let mut want = vec![0.0; wide];
                want[..d].copy_from_slice(&row[..d]);
                (want[lay.square()], want[lay.cube()]) = (row[d + 1], row[d + 2]);
                shift_ops(lay, &o[..1 + m], &origin, false, &mut ops);
                for &(t, s, a) in &ops {
                    want[t] += a * want[s];
                }
                if past(r) {
                    let p = at(r - l1);
                    let (prow, po) =
                        (&window.rows[p * base..][..base], &window.origins[p * (1 + m)..]);
                    want[lay.past_z()] = prow[d];
                    want[lay.past_z() + 1..].copy_from_slice(&prow[..n]);
                    want[wide - 1] -= (po[0] - origin[0]) * prow[lay.intercept()];
                }
                for (c, w) in want.iter().enumerate() {
                    assert_eq!(x[c * count + i].to_bits(), w.to_bits(), "n {n} row {r} column {c}");
                }
            }
        }
    }

    /// The units' move, along rows, is each operation's rows then its columns, one entry at a
    /// time, bit for bit.
    #[test]
    fn shift_products_is_each_operation_rows_then_columns() {
        let (groups, wide) = (3, 10);
        let dim = groups * wide;
        let s: Vec<f64> =
            (0..dim * dim).map(|k| ((k * 7919) % 1000) as f64 / 37.0 - 13.0).collect();
        let ops = vec![(7, 5, 0.3), (7, 1, -1.7), (6, 4, 2.9), (1, 4, -0.11), (9, 4, 5.5)];
        let mut want = s.clone();
        for &(t, src, a) in &ops {
            for p in 0..groups {
                for k in 0..dim {
                    want[(p * wide + t) * dim + k] += a * want[(p * wide + src) * dim + k];
                }
            }
            for row in 0..dim {
                for p in 0..groups {
                    want[row * dim + p * wide + t] += a * want[row * dim + p * wide + src];
                }
            }
        }
        let mut got = s;
        shift_products(&mut got, dim, groups, wide, &ops);
        assert!(got.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()));
    }
}
