//! [`AnchoredWindow`]: a window that grows from its last reset, fed the complete blocks of an
//! [`InstrumentedWindows`], in a bounded number of records that merge in pairs as it grows.

use serde::{Deserialize, Serialize};

use super::{InstrumentedWindows, Solve, WindowEstimate};
use crate::{Interval, RegressionError};

/// A window of every block since its last [`reset`](Self::reset), for a bound that tightens as
/// the data accumulate (the calibrated certificate's anchored window).
///
/// Its memory is bounded: it keeps fewer than `records` records (an even number), each the
/// sum of `c` consecutive blocks of `h` columns, `c` a power of two. Blocks enter an open
/// record; a record closes when it holds `c` blocks; when the closed records fill all
/// `records` slots, neighbouring records are summed in pairs (oldest first) and `c` doubles.
/// So a window of `B` blocks is held in `records / 2` to `records − 1` records of
/// `c ≈ B / records` blocks (fewer before the first merge), plus the
/// open record's fewer than `c` newest blocks, which the estimate leaves out until the record
/// closes.
///
/// [`estimate`](Self::estimate) is [`InstrumentedWindows::estimate`] with the records as the
/// blocks: the solve on the sum of every closed record (the same sums as the blocks', to
/// rounding), and the batch-means covariance of the records' delete-one-record changes with
/// the overlap factor of a batch of `c` blocks, `c_{c,h} = 3ch²/(3ch² − h² + 1)`
/// (`InstrumentedWindows::with_batch` explains it): the delete-a-group jackknife, with about
/// `records / 2` or more degrees of freedom at any length (tested against a recompute that
/// deletes each record from the sums and solves again). Cost per block `O(stride)`, and `O(records · stride)` once per
/// `records / 2` records for the merge (no allocation).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AnchoredWindow {
    /// The closed records, as the block ring of a one-window structure of `records` slots.
    ring: InstrumentedWindows,
    /// The open record's sums, its region and its block count.
    open: Vec<f64>,
    open_range: Vec<Interval>,
    in_open: usize,
    /// Complete blocks since the last reset (closed records and the open one).
    blocks: u64,
}

impl AnchoredWindow {
    /// An anchored window over the blocks of `source` (the same outputs, regressors,
    /// instrument intervals and region channels), in at most `records` records.
    ///
    /// # Errors
    /// [`RegressionError::InvalidConfig`] for `records` odd, or not more than twice `p + m`
    /// (so that a merged window keeps more records than regressors).
    pub fn new(source: &InstrumentedWindows, records: usize) -> Result<Self, RegressionError> {
        let d = source.p + source.m;
        if !records.is_multiple_of(2) || records <= 2 * (d + 1) {
            return Err(RegressionError::InvalidConfig {
                field: "records",
                reason: format!(
                    "must be even and above 2 (p + m + 1) = {}, got {records}",
                    2 * (d + 1)
                ),
            });
        }
        let ring = InstrumentedWindows::new(
            source.p,
            source.m,
            source.horizon,
            source.lag,
            source.intervals,
            &[records * source.horizon],
        )?
        .with_ranges(source.range_channels);
        Ok(Self {
            open: vec![0.0; source.layout().stride()],
            open_range: vec![Interval::EMPTY; source.range_channels],
            in_open: 0,
            blocks: 0,
            ring,
        })
    }

    /// Add `source`'s newest complete block (call it when
    /// [`InstrumentedWindows::push_column`] returns `true`). No allocation.
    pub fn push_newest(&mut self, source: &InstrumentedWindows) {
        if source.block_len == 0 {
            return;
        }
        let stride = source.layout().stride();
        let cap = source.block_cap();
        let slot = (source.block_head + cap - 1) % cap;
        for (o, v) in self.open.iter_mut().zip(&source.blocks[slot * stride..(slot + 1) * stride]) {
            *o += v;
        }
        let c = source.range_channels;
        if c > 0 && c == self.open_range.len() {
            for (o, r) in self.open_range.iter_mut().zip(&source.block_ranges[slot * c..][..c]) {
                *o = o.hull(*r);
            }
        }
        self.blocks += 1;
        self.in_open += 1;
        if self.in_open < self.ring.coarse {
            return;
        }
        self.ring.push_record(&self.open, &self.open_range);
        self.open.fill(0.0);
        self.open_range.fill(Interval::EMPTY);
        self.in_open = 0;
        // A full ring merges at once, so that the next record, of the doubled size, has room.
        if self.ring.block_len == self.ring.block_cap() {
            self.ring.coarsen();
        }
    }

    /// Forget every block.
    pub fn reset(&mut self) {
        self.ring.reset();
        self.ring.coarse = 1;
        self.open.fill(0.0);
        self.open_range.fill(Interval::EMPTY);
        self.in_open = 0;
        self.blocks = 0;
    }

    /// Complete blocks since the last reset.
    #[must_use]
    pub fn blocks(&self) -> u64 {
        self.blocks
    }

    /// Blocks per record, `c` (a power of two).
    #[must_use]
    pub fn coarse(&self) -> usize {
        self.ring.coarse
    }

    /// Closed records (the estimate's batches of one record).
    #[must_use]
    pub fn records(&self) -> usize {
        self.ring.block_len
    }

    /// Columns in the closed records (what [`estimate`](Self::estimate) uses).
    #[must_use]
    pub fn columns(&self) -> usize {
        self.ring.columns(0)
    }

    /// The estimate on every closed record, as [`InstrumentedWindows::estimate`] on a window
    /// of those records (see the type's docs for the covariance).
    pub fn estimate(&self, solve: Solve<'_>, out: &mut WindowEstimate) {
        self.ring.estimate(0, solve, out);
    }

    /// As [`estimate`](Self::estimate), and the covariance in batches of `batch >= 2` records
    /// into `out.batched` from the same pass
    /// ([`InstrumentedWindows::estimate_batched`]).
    pub fn estimate_batched(&self, batch: usize, solve: Solve<'_>, out: &mut WindowEstimate) {
        self.ring.estimate_batched(0, batch, solve, out);
    }

    /// The hull of the closed records' regions (see [`InstrumentedWindows::window_range`]).
    pub fn range(&self, out: &mut [Interval]) {
        self.ring.window_range(0, out);
    }

    /// Check a deserialised state against `source`'s dimensions and `records`.
    ///
    /// # Errors
    /// [`RegressionError::CorruptState`] naming the first inconsistency.
    pub fn check_state(
        &self,
        source: &InstrumentedWindows,
        records: usize,
    ) -> Result<(), RegressionError> {
        self.ring.check_state()?;
        let fresh = Self::new(source, records)?;
        let ok = self.ring.windows == fresh.ring.windows
            && self.ring.layout().stride() == fresh.ring.layout().stride()
            && self.ring.range_channels == fresh.ring.range_channels
            && self.ring.batch == 1
            && self.open.len() == fresh.open.len()
            && self.open_range.len() == fresh.open_range.len()
            && self.in_open < self.ring.coarse
            && (self.ring.block_len * self.ring.coarse + self.in_open) as u64 == self.blocks
            && self.open.iter().all(|v| v.is_finite())
            && self.open_range.iter().all(|r| *r == Interval::EMPTY || r.is_proper());
        if !ok {
            return Err(RegressionError::CorruptState("anchored window out of shape".into()));
        }
        Ok(())
    }
}

impl InstrumentedWindows {
    /// Append a closed record (`stride` values) and its region to the block ring, which
    /// must have room (the anchored window merges first).
    fn push_record(&mut self, record: &[f64], range: &[Interval]) {
        let stride = self.layout().stride();
        let slot = self.block_head;
        self.blocks[slot * stride..(slot + 1) * stride].copy_from_slice(record);
        let c = self.range_channels;
        self.block_ranges[slot * c..(slot + 1) * c].copy_from_slice(&range[..c]);
        self.block_head = (slot + 1) % self.block_cap();
        self.block_len = (self.block_len + 1).min(self.block_cap());
        self.usable += (self.coarse * self.horizon) as u64;
        // The column ring is never filled here: a record arrives whole.
        self.len = self.cap();
    }

    /// Sum the full block ring's records in pairs, oldest first, into its first half; the
    /// records then hold twice the blocks. In place (a rotation, then a forward pass).
    fn coarsen(&mut self) {
        let (stride, cap, c) = (self.layout().stride(), self.block_cap(), self.range_channels);
        let len = self.block_len;
        let start = (self.block_head + cap - len) % cap;
        self.blocks.rotate_left(start * stride);
        self.block_ranges.rotate_left(start * c);
        let half = len / 2;
        for i in 0..half {
            for a in 0..stride {
                self.blocks[i * stride + a] =
                    self.blocks[2 * i * stride + a] + self.blocks[(2 * i + 1) * stride + a];
            }
            for a in 0..c {
                self.block_ranges[i * c + a] =
                    self.block_ranges[2 * i * c + a].hull(self.block_ranges[(2 * i + 1) * c + a]);
            }
        }
        debug_assert!(len.is_multiple_of(2), "the anchored window merges a full, even ring");
        let kept = half;
        self.block_len = kept;
        self.block_head = kept % cap;
        self.coarse *= 2;
    }
}
