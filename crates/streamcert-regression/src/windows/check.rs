//! The check of an [`InstrumentedWindows`] read back from a checkpoint: every buffer the
//! shape a fresh structure of the same dimensions has, every counter in range, every value
//! finite.

use super::InstrumentedWindows;
use crate::{Interval, RegressionError};

impl InstrumentedWindows {
    /// Check a deserialised state against its own dimensions.
    ///
    /// # Errors
    /// [`RegressionError::CorruptState`] naming the first inconsistency.
    pub fn check_state(&self) -> Result<(), RegressionError> {
        let columns: Vec<usize> = self.windows.iter().map(|&b| b * self.horizon).collect();
        let fresh = Self::new(self.p, self.m, self.horizon, self.lag, self.intervals, &columns)?;
        let sizes_ok = self.ring_z.len() == fresh.ring_z.len()
            && self.ring_dy.len() == fresh.ring_dy.len()
            && self.open.len() == fresh.open.len()
            && self.blocks.len() == fresh.blocks.len()
            && self.w.len() == fresh.w.len()
            && self.windows == fresh.windows
            && self.batch >= 1
            && self.windows[0].div_ceil(self.batch) > self.p + self.m
            && self.open_range.len() == self.range_channels
            && self.block_ranges.len() == self.range_channels * fresh.block_cap()
            && (self.block_values.is_empty() && self.open_values.is_empty()
                || self.open_values.len() == self.horizon
                    && self.block_values.len() == self.horizon * fresh.block_cap()
                    && self.coarse == 1);
        if !sizes_ok {
            return Err(RegressionError::CorruptState("window buffers have the wrong size".into()));
        }
        let counters_ok = self.head < self.cap()
            && self.len <= self.cap()
            && self.in_open < self.horizon
            && self.block_head < self.block_cap()
            && self.block_len <= self.block_cap()
            && self.coarse.is_power_of_two()
            && (self.block_len * self.coarse) as u64 <= self.usable / self.horizon as u64
            && (self.usable == 0 || self.len == self.cap());
        if !counters_ok {
            return Err(RegressionError::CorruptState("window counters out of range".into()));
        }
        let mut values = self.ring_z.iter().chain(&self.ring_dy).chain(&self.open);
        let range_ok = |r: &Interval| *r == Interval::EMPTY || r.is_proper();
        let ranges_ok = self.open_range.iter().chain(&self.block_ranges).all(range_ok);
        if !values.all(|v| v.is_finite())
            || !self
                .blocks
                .iter()
                .chain(&self.open_values)
                .chain(&self.block_values)
                .all(|v| v.is_finite())
            || !ranges_ok
        {
            return Err(RegressionError::CorruptState("non-finite value in the windows".into()));
        }
        Ok(())
    }
}
