//! Trimmed regions of [`InstrumentedWindows`]: one value per column (for the nonlinear
//! certificate, the output at the column's start), kept per complete block, and a window's
//! region as the quantiles of its columns' values.
//!
//! A window of `n` columns with trim `q` has the region `[v_(k), v_(n−1−k)]` with
//! `k = ⌊q n⌋` and `v_(0) <= … <= v_(n−1)` the sorted values: the `q` and `1 − q` sample
//! quantiles (at most `k` values below the region and at most `k` above). `q = 0` is the
//! smallest and largest value.

use super::InstrumentedWindows;
use crate::Interval;

impl InstrumentedWindows {
    /// Track one value per column (see [`push_column_valued`](Self::push_column_valued) and
    /// [`window_quantiles`](Self::window_quantiles)): `h` values per block of the ring. Not
    /// for a coarsened ring (the anchored window's records merge blocks).
    #[must_use]
    pub fn with_values(mut self) -> Self {
        self.open_values = vec![0.0; self.horizon];
        self.block_values = vec![0.0; self.horizon * self.block_cap()];
        self
    }

    /// Whether values are tracked ([`with_values`](Self::with_values); off in a state written
    /// before it existed).
    #[must_use]
    pub fn tracks_values(&self) -> bool {
        !self.block_values.is_empty()
    }

    /// [`push_column_ranged`](Self::push_column_ranged), and the column's `value` kept with
    /// its block when the column is absorbed (values are kept only with
    /// [`with_values`](Self::with_values)). `O(1)` beyond the push, no allocation.
    #[inline]
    pub fn push_column_valued(
        &mut self,
        z: &[f64],
        dy: &[f64],
        range: &[Interval],
        value: f64,
    ) -> bool {
        let (before, slot, at) = (self.usable, self.block_head, self.in_open);
        let done = self.push_column_ranged(z, dy, range);
        if self.usable > before && self.tracks_values() {
            let h = self.horizon;
            self.open_values[at] = value;
            if done {
                self.block_values[slot * h..(slot + 1) * h].copy_from_slice(&self.open_values);
            }
        }
        done
    }

    /// The values' columns in window `w` (complete blocks only).
    #[must_use]
    pub fn window_values(&self, w: usize) -> usize {
        if self.tracks_values() { self.windows[w].min(self.block_len) * self.horizon } else { 0 }
    }

    /// The trimmed region of window `w`: the `trim` and `1 − trim` quantiles of its columns'
    /// values (module docs), [`Interval::EMPTY`] when the window holds none or values are not
    /// tracked. `scratch` holds at least [`window_values`](Self::window_values)`(w)` values.
    /// `O(M_w)` (two selections), no allocation.
    ///
    /// # Panics
    /// When `scratch` is shorter than the window's values, or `trim` is not in `[0, 0.5)`.
    pub fn window_quantiles(&self, w: usize, trim: f64, scratch: &mut [f64]) -> Interval {
        assert!((0.0..0.5).contains(&trim), "trim {trim} outside [0, 0.5)");
        let n = self.window_values(w);
        if n == 0 {
            return Interval::EMPTY;
        }
        let (head, cap, h) = (self.block_head, self.block_cap(), self.horizon);
        let count = n / h;
        // The window's blocks are the newest `count` of the ring: `[head − count, head)`,
        // wrapping to the end.
        let (recent, wrapped) = (head.min(count), count - head.min(count));
        let values = &mut scratch[..n];
        let (a, b) = values.split_at_mut(wrapped * h);
        a.copy_from_slice(&self.block_values[(cap - wrapped) * h..cap * h]);
        b.copy_from_slice(&self.block_values[(head - recent) * h..head * h]);
        // Truncation toward zero: `k = ⌊trim · n⌋`, at most `n / 2 − 1` since `trim < 0.5`.
        #[allow(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            clippy::cast_precision_loss
        )]
        let k = ((trim * n as f64).floor() as usize).min((n - 1) / 2);
        let (_, lo, above) = values.select_nth_unstable_by(k, f64::total_cmp);
        let lo = *lo;
        // The upper quantile is the `k`-th largest: among the values above the `k`-th
        // smallest, the `(n − 1 − k) − (k + 1)`-th smallest.
        let hi = if above.is_empty() {
            lo
        } else {
            let j = n - 1 - k - (k + 1);
            *above.select_nth_unstable_by(j.min(above.len() - 1), f64::total_cmp).1
        };
        Interval { lo, hi: hi.max(lo) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Windows of 3 and 6 blocks of `h = 2` columns, `p = m = 1`, one instrument interval,
    /// lag 0.
    fn windows() -> InstrumentedWindows {
        InstrumentedWindows::new(1, 1, 2, 0, 1, &[6, 12])
            .expect("valid windows")
            .with_ranges(1)
            .with_values()
    }

    /// The quantiles against a sort of the window's values (the values the window's complete
    /// blocks hold, known from the columns pushed), for every trim and fill level, across the
    /// ring's wrap.
    #[test]
    fn quantiles_equal_a_sort_of_the_window_values() {
        let mut win = windows();
        let mut absorbed = Vec::new();
        let mut scratch = vec![0.0; 12];
        for i in 0..60u32 {
            let v = f64::from((i * 37) % 23) - 11.0;
            let x = f64::from(i).sin();
            let before = win.usable;
            win.push_column_valued(
                &[x, v],
                &[0.5 * x],
                &[Interval { lo: v - 1.0, hi: v + 1.0 }],
                v,
            );
            if win.usable > before {
                absorbed.push(v);
            }
            for (w, trim) in [(0, 0.0), (0, 0.2), (1, 0.0), (1, 0.1), (1, 0.3), (1, 0.49)] {
                let n = win.window_values(w);
                assert_eq!(n, win.columns(w));
                let got = win.window_quantiles(w, trim, &mut scratch);
                if n == 0 {
                    assert_eq!(got, Interval::EMPTY);
                    continue;
                }
                // The complete blocks' columns are the newest absorbed values but the open
                // block's.
                let end = absorbed.len() - win.in_open;
                let mut want: Vec<f64> = absorbed[end - n..end].to_vec();
                want.sort_by(f64::total_cmp);
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let k = ((trim * n as f64).floor() as usize).min((n - 1) / 2);
                assert_eq!(got, Interval { lo: want[k], hi: want[n - 1 - k] }, "{i} {w} {trim}");
            }
        }
    }

    #[test]
    fn untracked_windows_have_no_values() {
        let mut win = InstrumentedWindows::new(1, 1, 2, 0, 1, &[6]).expect("valid").with_ranges(1);
        for i in 0..20 {
            win.push_column_valued(
                &[f64::from(i), 1.0],
                &[1.0],
                &[Interval { lo: 0.0, hi: 1.0 }],
                1.0,
            );
        }
        assert!(!win.tracks_values());
        assert_eq!(win.window_quantiles(0, 0.1, &mut []), Interval::EMPTY);
    }
}
