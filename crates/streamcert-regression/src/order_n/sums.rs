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
use filter::{Kernels, Layout, Products, accumulate, shift_ops, shift_row};
pub use look::WindowLook;

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

/// The sliding window's looks of order `n` from kept rows and filtered products (module docs).
/// Feed it each look's window of samples with the count of the samples before it
/// ([`prepare`](Self::prepare)); [`clear`](Self::clear) it after a gap.
#[derive(Debug, Clone, PartialEq)]
pub struct OrderNWindow {
    shape: Shape,
    min_excitation_ratio: f64,
    /// The weights of the spacings seen last, by their key (at most four).
    weights: Vec<(u64, RowWeights)>,
    /// Kept rows from row `rows_first`: `d + 3` values each (`φ`, `z`, the square, the cube)
    /// relative to the row's first sample, that sample's `[y; u]`, the row's spacing key.
    rows_first: u64,
    rows: Vec<f64>,
    origins: Vec<f64>,
    keys: Vec<Option<u64>>,
    units: Vec<Unit>,
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
        if let Some(i) = self.weights.iter().position(|(k, _)| *k == key) {
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
        self.weights.push((key, w));
        self.weights.len() - 1
    }

    /// Row `first + i`'s kept values from the window's samples (`i` its first sample).
    fn push_row(&mut self, i: usize, t: &[f64], y: &[f64], u: &[f64]) {
        let Shape { n, m, .. } = self.shape;
        let (span, d) = (self.shape.span(), self.shape.width());
        let s = i..i + span + 1;
        let key = spacing_key(&t[s.clone()]);
        let (y0, u0) = (y[i], &u[i * m..(i + 1) * m]);
        let mut row = vec![0.0; d + 3];
        if let Some(key) = key {
            let ys: Vec<f64> = y[s.clone()].iter().map(|v| v - y0).collect();
            let us: Vec<f64> = u[i * m..(i + span + 1) * m]
                .iter()
                .enumerate()
                .map(|(k, v)| v - u0[k % m])
                .collect();
            let at = self.weights_of(key);
            let w = &self.weights[at].1;
            row[d] = w.apply(self.shape, &ys, &us, &mut row[..d]);
            let wn = &w.wy[(n - 1) * (span + 1)..n * (span + 1)];
            let (mut square, mut cube) = (0.0, 0.0);
            for (wi, e) in wn.iter().zip(&ys) {
                let e2 = e * e;
                square += wi * e2;
                cube += wi * e2 * e;
            }
            (row[d + 1], row[d + 2]) = (square, cube);
        }
        self.rows.extend_from_slice(&row);
        self.origins.push(y0);
        self.origins.extend_from_slice(u0);
        self.keys.push(key);
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
        for r in self.rows_first + self.keys.len() as u64..end {
            self.push_row((r - first) as usize, t, y, u);
        }
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

    /// Row `r`'s widened columns relative to `origin` into `x`, its past columns from row
    /// `r − n h − 1` when `past` (else zero). `ops`: scratch.
    fn widened(
        &self,
        r: u64,
        origin: &[f64],
        past: bool,
        x: &mut [f64],
        ops: &mut Vec<(usize, usize, f64)>,
    ) {
        let lay = Layout::new(self.shape);
        let (d, n, m, base) = (lay.d, lay.n, lay.m, self.base());
        let at = |r: u64| (r - self.rows_first) as usize;
        let (row, o) = (&self.rows[at(r) * base..][..base], &self.origins[at(r) * (1 + m)..]);
        x[..d].copy_from_slice(&row[..d]);
        (x[lay.square()], x[lay.cube()]) = (row[d + 1], row[d + 2]);
        shift_ops(lay, &o[..1 + m], origin, false, ops);
        shift_row(x, ops);
        x[lay.past_z()..].fill(0.0);
        if past {
            let p = r - (self.shape.span() as u64 + 1);
            let (prow, po) = (&self.rows[at(p) * base..][..base], &self.origins[at(p) * (1 + m)..]);
            x[lay.past_z()] = prow[d];
            x[lay.past_z() + 1..].copy_from_slice(&prow[..n]);
            x[lay.wide() - 1] -= (po[0] - origin[0]) * prow[lay.intercept()];
        }
    }

    /// The rows `rows` widened relative to `origin`, by column (`wide` columns of
    /// `rows.len()`), their past columns when `past`.
    fn widened_columns(
        &self,
        rows: std::ops::Range<u64>,
        origin: &[f64],
        past: impl Fn(u64) -> bool,
    ) -> Vec<f64> {
        let wide = Layout::new(self.shape).wide();
        let len = (rows.end - rows.start) as usize;
        let mut x = vec![0.0; wide * len];
        let (mut row, mut ops) = (vec![0.0; wide], Vec::new());
        for (i, r) in rows.enumerate() {
            self.widened(r, origin, past(r), &mut row, &mut ops);
            for (c, v) in row.iter().enumerate() {
                x[c * len + i] = *v;
            }
        }
        x
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
        let x = self.widened_columns(rows.clone(), &origin, |_| past);
        // The unit's weights are its first row's (every row of a window taken has a key).
        let key = self.keys[at].unwrap_or(window_key);
        let w = self.weights_of(key);
        let kernels = Kernels::new(&self.weights[w].1, self.shape);
        let mut sums = Products::zero(kernels.groups, wide);
        let mut psi = Vec::new();
        let len = (span + UNIT) as usize;
        accumulate(&x, lo, len, &kernels, rows, j..j + UNIT, &mut sums, &mut psi);
        sums.mirror(kernels.groups, wide);
        Unit { first: j, origin, past, sums }
    }
}
