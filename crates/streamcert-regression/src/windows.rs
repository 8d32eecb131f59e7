//! Several sliding windows of instrumented statistics over one column stream: the regression
//! behind the calibrated certificate.
//!
//! Columns `(Z_q, ΔY_q)` arrive one per sample (from [`SlidingRegression`](crate::SlidingRegression)
//! or any other source with stride one sample and horizon `h`). Column `q` is paired with the
//! instrument made of the regressors of `J` earlier intervals,
//!
//! ```text
//! W_q = [Z_{q − h − L}; Z_{q − 2h − L}; …; Z_{q − Jh − L}]      (k = J (p + m) values)
//! ```
//!
//! where `L >= 0` is the instrument lag. `W_q` is built from samples up to `t_q − L·dt` only,
//! so it is uncorrelated with the error `E_q = ΔY_q − Θ Z_q` whenever that error involves
//! noise after `t_q − L·dt` only: white process noise for any `L >= 0`, white sensor noise
//! for `L >= 1` (the trapezoidal integral of the newest instrument interval then ends before
//! the sample `y(t_q)` that `ΔY_q` differences), sensor noise correlated over `c` samples for
//! `L >= c`.
//!
//! With `J = 1` the estimator is the just-identified instrumental-variables estimator, whose
//! finite-sample distribution has no moments (a ratio of correlated sums): its tails are much
//! heavier than the normal approximation says. With `J >= 2` it is two-stage least squares,
//! over-identified by `(J − 1)(p + m)` restrictions, which has finite moments up to that
//! order; the calibrated certificate uses `J = 3` by default.
//!
//! Key design decision: the statistics live in *blocks* of `h` instrumented columns. Each
//! block keeps its own sums
//!
//! ```text
//! N_j = Σ Z Wᵀ (d × k),   Cw_j = Σ ΔY Wᵀ (p × k),   H_j = Σ W Wᵀ (k × k)
//! ```
//!
//! formed from zero, and a window of `M_w` columns is the newest `⌊M_w/h⌋` complete blocks.
//! A column costs one outer product added to the open block (`O(k d + k²)`, no allocation,
//! independent of the window lengths and of their number), nothing is ever subtracted, so
//! there is no rounding drift to refresh. A window's sums, and the block sums of its scores
//! that the variance needs, are formed only when the calibrated certificate looks
//! ([`InstrumentedWindows::estimate`]), at block boundaries.

use serde::{Deserialize, Serialize};

mod anchored;
mod batch;
mod check;
mod coefficients;
mod estimate;
mod fresh;
mod jackknife;
mod moments;
mod outcome;
mod quantile;
mod region;
mod replay;
mod scores;
mod tail;

pub use anchored::AnchoredWindow;
pub use jackknife::{MIN_LEVERAGE_PIVOT, MIN_RESIDUAL_SHARE};
pub use moments::MAX_MOMENT_ENTRIES;
pub use outcome::{BatchedCovariance, RateMap, Solve, WindowEstimate};
pub use tail::MAX_TAIL;

use crate::{Interval, RegressionError};

/// Layout of one window's sums inside the flat statistics buffer.
#[derive(Debug, Clone, Copy)]
struct Layout {
    p: usize,
    d: usize,
    k: usize,
}

impl Layout {
    /// `N` (d × k), `Cw` (p × k), `H` (k × k).
    fn stride(self) -> usize {
        self.d * self.k + self.p * self.k + self.k * self.k
    }
    fn cw(self) -> usize {
        self.d * self.k
    }
    fn h(self) -> usize {
        self.cw() + self.p * self.k
    }
}

/// Sliding instrumented statistics over several window lengths; see the module docs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InstrumentedWindows {
    p: usize,
    m: usize,
    horizon: usize,
    lag: usize,
    intervals: usize,
    /// Window lengths in blocks of `h` columns, ascending.
    windows: Vec<usize>,
    // Ring of the newest `J h + L + 1` columns (the instruments' reach); `head` is the next
    // slot, `len` the columns stored.
    ring_z: Vec<f64>,
    ring_dy: Vec<f64>,
    head: usize,
    len: usize,
    // Instrumented columns seen since the last reset.
    usable: u64,
    // The open block's sums and its column count.
    open: Vec<f64>,
    in_open: usize,
    // Ring of complete blocks (`stride` values each); `block_head` is the next slot.
    blocks: Vec<f64>,
    block_head: usize,
    block_len: usize,
    // One column's instrument (scratch, meaningless between calls).
    w: Vec<f64>,
    // Region tracking (`with_ranges`): channels per column, the open block's hull and one
    // hull per complete block, aligned with `blocks`.
    #[serde(default)]
    range_channels: usize,
    #[serde(default)]
    open_range: Vec<Interval>,
    #[serde(default)]
    block_ranges: Vec<Interval>,
    // Value tracking (`with_values`): one value per column, the open block's (`h`) and `h`
    // per complete block, aligned with `blocks`; empty when off (and in states written
    // before it).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    open_values: Vec<f64>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    block_values: Vec<f64>,
    // Blocks per batch of the batch-means covariance (`with_batch`; 1 by default, and then
    // not written, so a state without it reads as it always did).
    #[serde(default = "batch::one", skip_serializing_if = "batch::is_one")]
    batch: usize,
    // Blocks of `h` columns per record of the block ring: 1, but in the anchored window's
    // ring, whose records merge in pairs (`coarsen`); not written when 1.
    #[serde(default = "batch::one", skip_serializing_if = "batch::is_one")]
    coarse: usize,
    // The segment sums of the blocks' records (`with_moments`): derived from the block ring,
    // not serialised, rebuilt on restore (`rebuild_moments`).
    #[serde(skip)]
    moments: Option<moments::Moments>,
}

/// `out = Σ` of the `S`-value blocks in `older` then `newer`.
fn sum_runs<const S: usize>(older: &[f64], newer: &[f64], out: &mut [f64]) {
    let mut acc = [0.0f64; S];
    for blk in older.chunks_exact(S).chain(newer.chunks_exact(S)) {
        for (a, v) in acc.iter_mut().zip(blk) {
            *a += v;
        }
    }
    out.copy_from_slice(&acc);
}

impl InstrumentedWindows {
    /// Windows `windows` in columns (strictly ascending after rounding down to whole blocks of
    /// `h` columns, each at least `h (p + m + 1)` columns) over columns of horizon
    /// `horizon >= 1`, with instrument lag `lag` samples and `intervals >= 1` instrument
    /// intervals.
    ///
    /// # Errors
    /// [`RegressionError::InvalidConfig`] for empty or unsorted windows, a window shorter than
    /// `h (p + m + 1)`, or `p`, `m`, `horizon`, `intervals` of zero.
    ///
    /// ```
    /// use streamcert_regression::{InstrumentedWindows, RegressionError};
    /// assert!(InstrumentedWindows::new(1, 1, 5, 1, 3, &[150, 300]).is_ok());
    /// let err = InstrumentedWindows::new(1, 1, 5, 1, 3, &[300, 150]).unwrap_err();
    /// assert!(matches!(err, RegressionError::InvalidConfig { field: "windows", .. }));
    /// ```
    pub fn new(
        p: usize,
        m: usize,
        horizon: usize,
        lag: usize,
        intervals: usize,
        windows: &[usize],
    ) -> Result<Self, RegressionError> {
        let bad = |field: &'static str, reason: String| {
            Err(RegressionError::InvalidConfig { field, reason })
        };
        if p == 0 || m == 0 || horizon == 0 || intervals == 0 {
            return bad("outputs", "p, m, the horizon and the intervals must be at least 1".into());
        }
        let d = p + m;
        let blocks: Vec<usize> = windows.iter().map(|&w| w / horizon).collect();
        if blocks.is_empty() || blocks.windows(2).any(|w| w[0] >= w[1]) || blocks[0] <= d {
            return bad(
                "windows",
                format!(
                    "must be strictly ascending in whole blocks of h = {horizon} columns and at \
                     least h (p + m + 1) = {} columns, got {windows:?}",
                    horizon * (d + 1)
                ),
            );
        }
        let lay = Layout { p, d, k: intervals * d };
        let cap = intervals * horizon + lag + 1;
        Ok(Self {
            p,
            m,
            horizon,
            lag,
            intervals,
            ring_z: vec![0.0; cap * d],
            ring_dy: vec![0.0; cap * p],
            head: 0,
            len: 0,
            usable: 0,
            open: vec![0.0; lay.stride()],
            in_open: 0,
            blocks: vec![0.0; blocks[blocks.len() - 1] * lay.stride()],
            block_head: 0,
            block_len: 0,
            windows: blocks,
            w: vec![0.0; lay.k],
            range_channels: 0,
            open_range: Vec::new(),
            block_ranges: Vec::new(),
            open_values: Vec::new(),
            block_values: Vec::new(),
            batch: 1,
            coarse: 1,
            moments: None,
        })
    }

    /// Windows over a regression with `regressors` regressors per column (not necessarily
    /// `p + m`: a feature library, for example), `outputs` outputs; otherwise as
    /// [`new`](Self::new). The candidate directions passed to
    /// [`estimate`](Self::estimate) are then `regressors × p`.
    ///
    /// # Errors
    /// As [`new`](Self::new), and for `regressors <= outputs`.
    pub fn with_regressors(
        outputs: usize,
        regressors: usize,
        horizon: usize,
        lag: usize,
        intervals: usize,
        windows: &[usize],
    ) -> Result<Self, RegressionError> {
        if regressors <= outputs {
            return Err(RegressionError::InvalidConfig {
                field: "regressors",
                reason: format!("must exceed the outputs ({outputs}), got {regressors}"),
            });
        }
        Self::new(outputs, regressors - outputs, horizon, lag, intervals, windows)
    }

    fn layout(&self) -> Layout {
        let d = self.p + self.m;
        Layout { p: self.p, d, k: self.intervals * d }
    }

    fn cap(&self) -> usize {
        self.ring_z.len() / (self.p + self.m)
    }

    fn block_cap(&self) -> usize {
        self.windows[self.windows.len() - 1]
    }

    /// The number of windows.
    #[must_use]
    pub fn count(&self) -> usize {
        self.windows.len()
    }

    /// Length of window `w` in columns (a whole number of blocks of `h`).
    #[must_use]
    pub fn window(&self, w: usize) -> usize {
        self.windows[w] * self.horizon
    }

    /// Instrumented columns in window `w` (complete blocks only).
    #[must_use]
    pub fn columns(&self, w: usize) -> usize {
        self.block_len.min(self.windows[w]) * self.coarse * self.horizon
    }

    /// `true` when window `w` holds its full length.
    #[must_use]
    pub fn is_full(&self, w: usize) -> bool {
        self.block_len >= self.windows[w]
    }

    /// Complete blocks since construction or the last [`reset`](Self::reset), capped at the
    /// longest window.
    #[must_use]
    pub fn blocks(&self) -> usize {
        self.block_len
    }

    /// Instrumented columns seen since construction or the last [`reset`](Self::reset).
    #[must_use]
    pub fn seen(&self) -> u64 {
        self.usable
    }

    /// The sums of window `w`, `(N, Cw, H)` row-major (full matrices), into `out` (`3` slices
    /// of `d k`, `p k` and `k²` values, concatenated). `O(B_w (d k + k²))`.
    pub fn window_sums(&self, w: usize, out: &mut [f64]) {
        self.span_sums(self.span(w, 0), out);
    }

    /// The sums of the blocks `span` selects (see [`Self::span`]) into `out`.
    pub(crate) fn span_sums(&self, span: (usize, usize), out: &mut [f64]) {
        let stride = self.layout().stride();
        let (older, newer) = self.span_blocks(span);
        // One output, J = 1: a fixed-size accumulator the compiler keeps in registers (in
        // memory, every block would wait for the previous block's store to be read back).
        // Strides 10 and 21: one input through the origin and with the intercept; 36 and 55:
        // the model guards' larger fits (one or two more regressors) with the intercept.
        if stride == 10 {
            sum_runs::<10>(older, newer, &mut out[..10]);
        } else if stride == 21 {
            sum_runs::<21>(older, newer, &mut out[..21]);
        } else if stride == 36 {
            sum_runs::<36>(older, newer, &mut out[..36]);
        } else if stride == 55 {
            sum_runs::<55>(older, newer, &mut out[..55]);
        } else {
            let out = &mut out[..stride];
            out.fill(0.0);
            for blk in older.chunks_exact(stride).chain(newer.chunks_exact(stride)) {
                for (o, v) in out.iter_mut().zip(blk) {
                    *o += v;
                }
            }
        }
    }

    /// The blocks of window `w` as two contiguous runs of the block ring, oldest first (the
    /// first run is empty unless the window wraps around the ring).
    fn window_blocks(&self, w: usize) -> (&[f64], &[f64]) {
        self.span_blocks(self.span(w, 0))
    }

    /// Window `w`'s blocks less its newest `skip`: `(count, skip)`, `count` the blocks held
    /// of window `w` (at most its length).
    pub(crate) fn span(&self, w: usize, skip: usize) -> (usize, usize) {
        (self.windows[w].min(self.block_len), skip)
    }

    /// The blocks of `span = (count, skip)`: the newest `count` blocks less the newest `skip`,
    /// as two contiguous runs of the block ring, oldest first.
    pub(crate) fn span_blocks(&self, (count, skip): (usize, usize)) -> (&[f64], &[f64]) {
        let (stride, cap) = (self.layout().stride(), self.block_cap());
        let skip = skip.min(count);
        let count = count - skip;
        // The span ends `skip` blocks before the head (modulo the ring).
        let head = (self.block_head + cap - skip) % cap;
        if count <= head {
            (&[], &self.blocks[(head - count) * stride..head * stride])
        } else {
            let wrap = count - head;
            (&self.blocks[(cap - wrap) * stride..cap * stride], &self.blocks[..head * stride])
        }
    }

    /// Forget every column: every value zero (every range empty), as built, so that a state
    /// holds nothing from before its reset (and a replay of its newest columns rebuilds it
    /// bit for bit, see [`refill_from`](Self::refill_from)).
    pub fn reset(&mut self) {
        self.head = 0;
        self.len = 0;
        self.usable = 0;
        for v in [&mut self.ring_z, &mut self.ring_dy, &mut self.open, &mut self.blocks] {
            v.fill(0.0);
        }
        self.w.fill(0.0);
        self.open_values.fill(0.0);
        self.block_values.fill(0.0);
        self.block_ranges.fill(Interval::EMPTY);
        self.in_open = 0;
        self.block_head = 0;
        self.block_len = 0;
        self.open_range.fill(Interval::EMPTY);
        if let Some(mo) = &mut self.moments {
            mo.clear();
        }
    }

    /// Add the outer products of the column `(z, dy)` in ring slot `q`, paired with its
    /// instrument, to the open block (dimensions passed in, literal for `p = m = 1`).
    #[inline(always)]
    fn accumulate_dims(&mut self, q: usize, z: &[f64], dy: &[f64], p: usize, d: usize, k: usize) {
        let cap = self.cap();
        for j in 0..self.intervals {
            let back = (j + 1) * self.horizon + self.lag;
            let r = if q >= back { q - back } else { q + cap - back };
            self.w[j * d..(j + 1) * d].copy_from_slice(&self.ring_z[r * d..(r + 1) * d]);
        }
        let w = &self.w[..k];
        let (n, rest) = self.open[..d * k + p * k + k * k].split_at_mut(d * k);
        let (cw, h) = rest.split_at_mut(p * k);
        for (row, &zi) in n.chunks_exact_mut(k).zip(&z[..d]) {
            for (o, &wj) in row.iter_mut().zip(w) {
                *o += zi * wj;
            }
        }
        for (row, &di) in cw.chunks_exact_mut(k).zip(&dy[..p]) {
            for (o, &wj) in row.iter_mut().zip(w) {
                *o += di * wj;
            }
        }
        for (row, &wi) in h.chunks_exact_mut(k).zip(w) {
            for (o, &wj) in row.iter_mut().zip(w) {
                *o += wi * wj;
            }
        }
    }

    /// Absorb the newest column `(z, dy)` (`z` of length `p + m`, `dy` of length `p`). No
    /// allocation; `O(k d + k²)`. Returns `true` when the column completed a block (the
    /// windows changed).
    ///
    /// # Panics
    /// If `z` or `dy` has the wrong length (the caller builds them from a validated
    /// configuration).
    pub fn push_column(&mut self, z: &[f64], dy: &[f64]) -> bool {
        // Literal dimensions for p = m = 1 with one instrument interval.
        // One output and one instrument interval: literal dimensions for `d = 2` (p = m = 1),
        // 3 (with the affine model's `τ`), 4 (the hidden-dynamics guard's larger fit; the
        // nonlinear certificate's cubic library and one input), 5 (that with `τ`), 6 (the
        // cubic library, its two lack-of-fit terms and one input) and 7 (that with `τ`).
        let one = self.p == 1 && self.intervals == 1;
        if one && self.m == 1 {
            self.push_column_dims(z, dy, 1, 2, 2)
        } else if one && self.m == 2 {
            self.push_column_dims(z, dy, 1, 3, 3)
        } else if one && self.m == 3 {
            self.push_column_dims(z, dy, 1, 4, 4)
        } else if one && self.m == 4 {
            self.push_column_dims(z, dy, 1, 5, 5)
        } else if one && self.m == 5 {
            self.push_column_dims(z, dy, 1, 6, 6)
        } else if one && self.m == 6 {
            self.push_column_dims(z, dy, 1, 7, 7)
        } else {
            let lay = self.layout();
            self.push_column_dims(z, dy, lay.p, lay.d, lay.k)
        }
    }

    /// [`push_column`](Self::push_column) with the dimensions passed in.
    #[inline(always)]
    fn push_column_dims(&mut self, z: &[f64], dy: &[f64], p: usize, d: usize, k: usize) -> bool {
        let stride = Layout { p, d, k }.stride();
        let cap = self.cap();
        let k_slot = self.head;
        for (o, v) in self.ring_z[k_slot * d..(k_slot + 1) * d].iter_mut().zip(&z[..d]) {
            *o = *v;
        }
        for (o, v) in self.ring_dy[k_slot * p..(k_slot + 1) * p].iter_mut().zip(&dy[..p]) {
            *o = *v;
        }
        let k = k_slot;
        self.head = if k + 1 == cap { 0 } else { k + 1 };
        self.len = (self.len + 1).min(cap);
        if self.len < cap {
            return false;
        }
        self.usable += 1;
        self.accumulate_dims(k, z, dy, p, d, Layout { p, d, k: self.intervals * d }.k);
        self.in_open += 1;
        if self.in_open < self.horizon {
            return false;
        }
        let b = self.block_head;
        let (open, blocks) =
            (&mut self.open[..stride], &mut self.blocks[b * stride..(b + 1) * stride]);
        for (o, v) in blocks.iter_mut().zip(open.iter_mut()) {
            *o = *v;
            *v = 0.0;
        }
        if self.moments.is_some() {
            self.moments_push(b);
        }
        self.block_head = if b + 1 == self.block_cap() { 0 } else { b + 1 };
        self.block_len = (self.block_len + 1).min(self.block_cap());
        self.in_open = 0;
        true
    }
}
