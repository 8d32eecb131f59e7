//! The regions of [`InstrumentedWindows`]: each complete block keeps the hull of the value
//! ranges passed with its columns, and a window's region is the hull of its blocks'.

use super::InstrumentedWindows;
use crate::Interval;

impl InstrumentedWindows {
    /// Track the region of every block: the hull of `channels` value ranges passed with each
    /// column to [`push_column_ranged`](Self::push_column_ranged).
    #[must_use]
    pub fn with_ranges(mut self, channels: usize) -> Self {
        self.range_channels = channels;
        self.open_range = vec![Interval::EMPTY; channels];
        self.block_ranges = vec![Interval::EMPTY; channels * self.block_cap()];
        self
    }

    /// [`push_column`](Self::push_column), and the column's value ranges (`channels` of them,
    /// see [`with_ranges`](Self::with_ranges)) joined to its block's region when the column
    /// is absorbed. Use one of the two push methods throughout.
    #[inline]
    pub fn push_column_ranged(&mut self, z: &[f64], dy: &[f64], range: &[Interval]) -> bool {
        let (before, slot) = (self.usable, self.block_head);
        let done = self.push_column(z, dy);
        if self.usable > before {
            for (o, r) in self.open_range.iter_mut().zip(range) {
                *o = o.hull(*r);
            }
            if done {
                // Element by element: for the few channels a loop beats a call to `memcpy`.
                let c = self.range_channels;
                let closed = &mut self.block_ranges[slot * c..(slot + 1) * c];
                for (b, o) in closed.iter_mut().zip(&mut self.open_range) {
                    (*b, *o) = (*o, Interval::EMPTY);
                }
            }
        }
        done
    }

    /// The region of window `w`: the hull of its complete blocks' ranges, into `out`
    /// (`channels` values; [`Interval::EMPTY`] for an empty window). `O(B_w · channels)`.
    pub fn window_range(&self, w: usize, out: &mut [Interval]) {
        let c = self.range_channels;
        let out = &mut out[..c];
        out.fill(Interval::EMPTY);
        if c == 0 {
            return;
        }
        let count = self.windows[w].min(self.block_len);
        let (head, cap) = (self.block_head, self.block_cap());
        // The window's blocks are the newest `count` of the ring: `[head - count, head)`,
        // wrapping to the end. Each channel's hull runs over the blocks in four independent
        // hulls held in registers (one hull would be a chain of dependent minima), joined at
        // the end. `Interval::hull` gives the same bits in any order, signed zeros included
        // (tested against the hull in block order).
        let (recent, wrapped) = (head.min(count), count - head.min(count));
        for (ch, o) in out.iter_mut().enumerate() {
            let hull = strided_hull(&self.block_ranges[(head - recent) * c..head * c], c, ch);
            *o = hull.hull(strided_hull(&self.block_ranges[(cap - wrapped) * c..cap * c], c, ch));
        }
    }
}

/// The hull of channel `ch` over every block of `ranges` (`c` channels per block), in four
/// independent hulls joined at the end.
#[inline]
fn strided_hull(ranges: &[Interval], c: usize, ch: usize) -> Interval {
    let mut acc = [Interval::EMPTY; 4];
    let mut quads = ranges.chunks_exact(4 * c);
    for quad in &mut quads {
        for (k, a) in acc.iter_mut().enumerate() {
            *a = a.hull(quad[k * c + ch]);
        }
    }
    for (k, block) in quads.remainder().chunks_exact(c).enumerate() {
        acc[k] = acc[k].hull(block[ch]);
    }
    acc[0].hull(acc[1]).hull(acc[2].hull(acc[3]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The four-hull join against one hull in block order, bit for bit, on ranges full of
    /// signed zeros and ties (where an order-dependent minimum would show).
    #[test]
    fn four_hulls_are_the_hull_in_block_order_bit_for_bit() {
        let values: [f64; 7] = [0.0, -0.0, 1.0, -1.0, 0.0, -0.0, 2.5];
        for c in 1..4 {
            for blocks in 0..23 {
                let ranges: Vec<Interval> = (0..blocks * c)
                    .map(|i| {
                        let (a, b) = (values[i % 7], values[(i * 3 + 1) % 7]);
                        Interval { lo: a.min(b), hi: a.max(b) }
                    })
                    .collect();
                for ch in 0..c {
                    let want =
                        ranges.iter().skip(ch).step_by(c).fold(Interval::EMPTY, |h, r| h.hull(*r));
                    let got = strided_hull(&ranges, c, ch);
                    assert_eq!(
                        (got.lo.to_bits(), got.hi.to_bits()),
                        (want.lo.to_bits(), want.hi.to_bits()),
                        "{c} channels, {blocks} blocks, channel {ch}"
                    );
                }
            }
        }
    }
}
