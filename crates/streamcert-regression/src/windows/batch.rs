//! Batches of blocks for the batch-means covariances of [`InstrumentedWindows`]: the setting
//! ([`InstrumentedWindows::with_batch`]), its overlap factor and the counter that groups a
//! window's blocks.

use super::InstrumentedWindows;
use crate::RegressionError;

impl InstrumentedWindows {
    /// Batches of `batch` blocks (`b h` columns) for the batch-means covariance of
    /// [`estimate`](Self::estimate) and [`coefficient_covariance`](Self::coefficient_covariance)
    /// (default 1: every block is a batch). White sensor noise on `y` enters `ΔY_q` and
    /// `ΔY_{q+h}` with opposite signs, so neighbouring blocks are negatively correlated and
    /// batch means count that noise once per batch boundary although it telescopes in the
    /// window's sum; longer batches have fewer boundaries per column, at the price of fewer
    /// batches (fewer degrees of freedom). A window then needs more than `p + m` batches.
    ///
    /// # Errors
    /// [`RegressionError::InvalidConfig`] for `batch` of zero, or one that leaves the
    /// shortest window `p + m` batches or fewer.
    pub fn with_batch(mut self, batch: usize) -> Result<Self, RegressionError> {
        let d = self.p + self.m;
        if batch == 0 || self.windows[0].div_ceil(batch) <= d {
            return Err(RegressionError::InvalidConfig {
                field: "batch",
                reason: format!(
                    "must be at least 1 and leave the shortest window ({} blocks of h) more than \
                     p + m = {d} batches, got {batch}",
                    self.windows[0]
                ),
            });
        }
        self.batch = batch;
        Ok(self)
    }

    /// Compute the following estimates with batches of `batch >= 1` blocks (the window sums
    /// do not depend on it): for a second covariance beside the first at the same look. A
    /// window with at most `d` batches is then not ready.
    pub fn set_batch(&mut self, batch: usize) {
        self.batch = batch.max(1);
    }

    /// Blocks per batch ([`with_batch`](Self::with_batch)).
    #[must_use]
    pub fn batch(&self) -> usize {
        self.batch
    }

    /// Blocks of `h` columns per record of the ring: 1, but for the anchored window's ring
    /// ([`AnchoredWindow`](crate::AnchoredWindow)), whose records merge in pairs as it grows.
    #[must_use]
    pub fn coarse(&self) -> usize {
        self.coarse
    }

    /// The overlap factor `c_{b,h}` of a batch of `batch` records (`batch · coarse` blocks).
    pub(super) fn overlap(&self, batch: usize) -> f64 {
        overlap_factor(batch * self.coarse, self.horizon)
    }
}

pub(super) fn one() -> usize {
    1
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's `skip_serializing_if` passes a reference
pub(super) fn is_one(b: &usize) -> bool {
    *b == 1
}

/// `c_{b,h} = 3bh² / (3bh² − h² + 1)`: a batch of `b` blocks of `h` columns has `N = bh`
/// columns whose errors, under white process noise, have the triangular autocorrelation
/// `1 − |l|/h`; the sum's variance is then `Nh − (h² − 1)/3` and its long-run variance `Nh`
/// (in units of one column's), and `c_{b,h}` is their ratio (`b = 1`: `3h²/(2h² + 1)`, bit
/// for bit the factor written that way).
pub(super) fn overlap_factor(batch: usize, horizon: usize) -> f64 {
    let (b, h) = (batch as f64, horizon as f64);
    3.0 * b * h * h / (3.0 * b * h * h - h * h + 1.0)
}

/// A window's blocks, oldest first, in batches of `size`; the oldest batch holds the remainder
/// `B mod size` when there is one, and its outer product is weighted by
/// `c_{r,h} / c_{size,h}` so that the common factor `c_{size,h}` applied at the end gives it
/// its own overlap factor.
pub(super) struct Batches {
    size: usize,
    target: usize,
    filled: usize,
    partial: f64,
}

impl Batches {
    /// `blocks` records of `coarse` blocks of `horizon` columns each (`coarse = 1` but for
    /// the anchored window's merged records), in batches of `size` records.
    pub(super) fn new(blocks: usize, size: usize, horizon: usize, coarse: usize) -> Self {
        let rem = blocks % size;
        let partial = if rem == 0 {
            1.0
        } else {
            overlap_factor(rem * coarse, horizon) / overlap_factor(size * coarse, horizon)
        };
        Self { size, target: if rem == 0 { size } else { rem }, filled: 0, partial }
    }

    /// Count one block; the factor of the batch's outer product when the block closes a batch.
    pub(super) fn close(&mut self) -> Option<f64> {
        self.filled += 1;
        if self.filled < self.target {
            return None;
        }
        let factor = if self.target < self.size { self.partial } else { 1.0 };
        (self.filled, self.target) = (0, self.size);
        Some(factor)
    }
}
