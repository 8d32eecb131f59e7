//! A ring's data left out and rebuilt: what a compact checkpoint writes instead of the block
//! sums is the samples they were formed from; the caller replays those samples through a
//! reset copy of the windows (the same code, the same order of additions, so the same bits),
//! and [`InstrumentedWindows::refill_from`] moves the replay's columns and blocks into the
//! slots the original held them in. Windows that keep values or merged records (the
//! anchored window's) are not stripped: their values and merges are not columns a replay
//! pushes.

use super::InstrumentedWindows;
use crate::Interval;

/// `a` and `b` hold the same bits (`-0.0 ≠ 0.0`, a NaN equal only to the same NaN).
fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

fn same_intervals(a: &[Interval], b: &[Interval]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x.lo.to_bits() == y.lo.to_bits() && x.hi.to_bits() == y.hi.to_bits())
}

/// Copy the newest `count` records of `width` values of ring `src` (next slot `src_head`)
/// into the same chronological places of ring `dst` (next slot `dst_head`), both of `cap`
/// records.
fn copy_newest<T: Copy>(
    dst: &mut [T],
    dst_head: usize,
    src: &[T],
    src_head: usize,
    (count, cap, width): (usize, usize, usize),
) {
    for i in 0..count {
        let (s, d) = ((src_head + cap - count + i) % cap, (dst_head + cap - count + i) % cap);
        dst[d * width..(d + 1) * width].copy_from_slice(&src[s * width..(s + 1) * width]);
    }
}

impl InstrumentedWindows {
    /// The newest columns whose values the windows hold: the instruments' reach `J h + L`
    /// before the oldest complete block's first column, the complete blocks and the open one
    /// (fewer before the first instrumented column). Pushing these columns into a
    /// [`reset`](Self::reset) copy rebuilds every block bit for bit, in other slots.
    #[must_use]
    pub fn columns_held(&self) -> usize {
        if self.usable == 0 {
            self.len
        } else {
            self.reach() + self.in_open + self.block_len * self.coarse * self.horizon
        }
    }

    /// The instruments' reach `J h + L`: the column ring holds one more (from the shape, not
    /// the buffers, which a stripped state has left out).
    fn reach(&self) -> usize {
        self.intervals * self.horizon + self.lag
    }

    /// The most columns [`columns_held`](Self::columns_held) can be: `J h + L` and every
    /// block of the longest window, open one included.
    #[must_use]
    pub fn columns_held_max(&self) -> usize {
        self.reach() + self.block_cap() * self.coarse * self.horizon + self.horizon - 1
    }

    /// Leave out the columns, blocks and their ranges (counters and shape kept): a state only
    /// [`refill_from`](Self::refill_from) completes. `false` (nothing left out) for windows
    /// that keep values ([`with_values`](Self::with_values)) or merged records (the anchored
    /// window's), which a replay of columns does not rebuild.
    #[must_use]
    pub fn strip(&mut self) -> bool {
        if !self.open_values.is_empty() || self.coarse != 1 {
            return false;
        }
        for v in [&mut self.ring_z, &mut self.ring_dy, &mut self.open, &mut self.blocks] {
            *v = Vec::new();
        }
        self.w = Vec::new();
        self.open_range = Vec::new();
        self.block_ranges = Vec::new();
        true
    }

    /// A reset copy with every buffer at its full size (of a stripped state too): what a
    /// replay pushes its columns into.
    #[must_use]
    pub fn cleared(&self) -> Self {
        let mut c = self.clone();
        let (lay, cap, bcap) = (self.layout(), self.reach() + 1, self.block_cap());
        let (stride, rc) = (lay.stride(), self.range_channels);
        c.ring_z = vec![0.0; cap * lay.d];
        c.ring_dy = vec![0.0; cap * lay.p];
        c.open = vec![0.0; stride];
        c.blocks = vec![0.0; bcap * stride];
        c.w = vec![0.0; lay.k];
        c.open_range = vec![Interval::EMPTY; rc];
        c.block_ranges = vec![Interval::EMPTY; bcap * rc];
        c.reset();
        c
    }

    /// Take the columns, blocks, ranges and values from `replayed` (a reset copy of these
    /// windows that was pushed the [`columns_held`](Self::columns_held) newest columns) into
    /// the slots these windows hold them in. `false` (nothing changed) when `replayed` is not
    /// of the same shape or does not hold the same number of columns and blocks.
    #[must_use]
    pub fn refill_from(&mut self, replayed: &Self) -> bool {
        let r = replayed;
        let shape = (self.p, self.m, self.horizon, self.lag, self.intervals, &self.windows);
        let same_shape = shape == (r.p, r.m, r.horizon, r.lag, r.intervals, &r.windows)
            && (self.batch, self.coarse, self.range_channels) == (r.batch, 1, r.range_channels)
            && (self.len, self.in_open, self.block_len) == (r.len, r.in_open, r.block_len)
            && (self.usable == 0) == (r.usable == 0)
            && self.block_values.is_empty() == r.block_values.is_empty()
            && r.open_values.is_empty();
        let (cap, bcap) = (r.cap(), r.block_cap());
        if !same_shape || self.head >= cap || self.block_head >= bcap {
            return false;
        }
        let (d, p, c) = (self.p + self.m, self.p, self.range_channels);
        let stride = self.layout().stride();
        self.ring_z = vec![0.0; r.ring_z.len()];
        self.ring_dy = vec![0.0; r.ring_dy.len()];
        self.blocks = vec![0.0; r.blocks.len()];
        self.block_ranges = vec![Interval::EMPTY; r.block_ranges.len()];
        let cols = (self.len, cap, d);
        copy_newest(&mut self.ring_z, self.head, &r.ring_z, r.head, cols);
        copy_newest(&mut self.ring_dy, self.head, &r.ring_dy, r.head, (self.len, cap, p));
        let blocks = (self.block_len, bcap, stride);
        copy_newest(&mut self.blocks, self.block_head, &r.blocks, r.block_head, blocks);
        let ranges = (self.block_len, bcap, c);
        copy_newest(&mut self.block_ranges, self.block_head, &r.block_ranges, r.block_head, ranges);
        self.open = r.open.clone();
        self.w = r.w.clone();
        self.open_range = r.open_range.clone();
        true
    }

    /// `true` when `other` holds the same shape, counters and values bit for bit (the segment
    /// sums, derived, aside).
    #[must_use]
    pub fn same_bits(&self, other: &Self) -> bool {
        let counters = |s: &Self| {
            (s.p, s.m, s.horizon, s.lag, s.intervals, s.head, s.len, s.usable, s.in_open)
        };
        let blocks = |s: &Self| (s.block_head, s.block_len, s.range_channels, s.batch, s.coarse);
        counters(self) == counters(other)
            && blocks(self) == blocks(other)
            && self.windows == other.windows
            && same_bits(&self.ring_z, &other.ring_z)
            && same_bits(&self.ring_dy, &other.ring_dy)
            && same_bits(&self.open, &other.open)
            && same_bits(&self.blocks, &other.blocks)
            && same_bits(&self.w, &other.w)
            && same_bits(&self.open_values, &other.open_values)
            && same_bits(&self.block_values, &other.block_values)
            && same_intervals(&self.open_range, &other.open_range)
            && same_intervals(&self.block_ranges, &other.block_ranges)
    }
}
