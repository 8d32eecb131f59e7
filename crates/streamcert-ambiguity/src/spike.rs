//! Spike fraction `ŝ(t)` and the scale `σ0` it is measured in.

use serde::{Deserialize, Serialize};

use crate::{AmbiguityError, next};

/// Where the scale `σ0` of the spike threshold `3 σ0` comes from. The paper uses `σ0` (the
/// nominal disturbance scale, 0.08) without saying how it applies to residuals, which live in
/// other units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum SpikeScale {
    /// A fixed `σ0 > 0`, in the units of the stream.
    Fixed {
        /// The scale.
        sigma0: f64,
    },
    /// `σ0 = 1.4826 · MAD` of the first `samples` values of the stream, then frozen. The MAD
    /// is robust to the spikes it is meant to detect, and `1.4826` makes it consistent for
    /// the Gaussian standard deviation. No spike is counted until it is frozen.
    Calibrated {
        /// Calibration length (at least 4).
        samples: usize,
    },
}

/// Robust scale from the median absolute deviation of a calibration period, computed once
/// without allocation (the buffer is reserved at construction).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobustScale {
    buf: Vec<f64>,
    len: usize,
    value: Option<f64>,
}

/// Consistency factor of the MAD for the Gaussian standard deviation, `1 / Φ⁻¹(3/4)`.
pub const MAD_TO_SIGMA: f64 = 1.482_602_218_505_602;

impl RobustScale {
    /// Collect `samples >= 4` values, then freeze `1.4826 · MAD`.
    ///
    /// # Errors
    /// [`AmbiguityError::CalibrationTooShort`].
    pub fn new(samples: usize) -> Result<Self, AmbiguityError> {
        if samples < 4 {
            return Err(AmbiguityError::CalibrationTooShort { got: samples, min: 4 });
        }
        Ok(Self { buf: vec![0.0; samples], len: 0, value: None })
    }

    /// Feed one finite value; returns the scale once frozen.
    pub fn push(&mut self, x: f64) -> Option<f64> {
        if self.value.is_none() {
            self.buf[self.len] = x;
            self.len += 1;
            if self.len == self.buf.len() {
                let med = median_in_place(&mut self.buf);
                for v in &mut self.buf {
                    *v = (*v - med).abs();
                }
                self.value = Some(MAD_TO_SIGMA * median_in_place(&mut self.buf));
            }
        }
        self.value
    }

    /// `true` when a deserialised state is one `push` could have produced.
    #[must_use]
    pub fn is_consistent(&self) -> bool {
        let n = self.buf.len();
        n >= 4
            && self.len <= n
            && (self.value.is_some() || self.len < n)
            && self.buf.iter().all(|v| v.is_finite())
            && self.value.is_none_or(|v| v.is_finite() && v >= 0.0)
    }

    /// The frozen scale, if calibration is complete.
    #[must_use]
    pub fn value(&self) -> Option<f64> {
        self.value
    }
}

/// Median by selection (reorders `v`); the mean of the two middle values for even lengths.
fn median_in_place(v: &mut [f64]) -> f64 {
    let n = v.len();
    let (_, &mut hi, _) = v.select_nth_unstable_by(n / 2, f64::total_cmp);
    if n % 2 == 1 {
        hi
    } else {
        let lo = v[..n / 2].iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lo + hi)
    }
}

/// Share of the last `window` values with `|x| > 3 σ0` (paper Section III-A), O(1) per value.
///
/// The threshold is about zero, not about the window mean: the stream is a residual whose
/// model mean is zero, and a burst of same-sign spikes must not shift its own reference.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpikeCounter {
    flags: Vec<bool>,
    head: usize,
    len: usize,
    count: usize,
    sigma0: Option<f64>,
}

impl SpikeCounter {
    /// A counter over `window >= 1` values with threshold `3 σ0` once `σ0` is known.
    #[must_use]
    pub fn new(window: usize, sigma0: Option<f64>) -> Self {
        Self { flags: vec![false; window.max(1)], head: 0, len: 0, count: 0, sigma0 }
    }

    /// Set `σ0` and recount the window from its values (oldest first).
    pub fn set_scale(&mut self, sigma0: f64, window_values: impl Iterator<Item = f64>) {
        self.sigma0 = Some(sigma0);
        self.len = 0;
        self.head = 0;
        self.count = 0;
        for x in window_values {
            self.push(x);
        }
    }

    /// Record one value.
    #[inline]
    pub fn push(&mut self, x: f64) {
        let n = self.flags.len();
        let spike = self.sigma0.is_some_and(|s| x.abs() > 3.0 * s);
        if self.len == n {
            self.count -= usize::from(self.flags[self.head]);
        } else {
            self.len += 1;
        }
        self.flags[self.head] = spike;
        self.count += usize::from(spike);
        self.head = next(self.head, n);
    }

    /// `ŝ = count / len` (0 when empty).
    #[must_use]
    pub fn fraction(&self) -> f64 {
        if self.len == 0 { 0.0 } else { self.count as f64 / self.len as f64 }
    }

    /// The threshold `3 σ0`, once known.
    #[must_use]
    pub fn threshold(&self) -> Option<f64> {
        self.sigma0.map(|s| 3.0 * s)
    }

    /// The scale `σ0`, once known.
    #[must_use]
    pub fn sigma0(&self) -> Option<f64> {
        self.sigma0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mad_scale_of_a_known_sample() {
        let mut r = RobustScale::new(5).unwrap();
        for x in [1.0, 2.0, 3.0, 4.0] {
            assert_eq!(r.push(x), None);
        }
        // Values 1..5, 100: median 3, deviations 2,1,0,1,97 -> MAD 1.
        assert_eq!(r.push(100.0), Some(MAD_TO_SIGMA));
        let mut even = RobustScale::new(4).unwrap();
        for x in [1.0, 2.0, 4.0, 8.0] {
            even.push(x);
        }
        // Median 3, deviations 2,1,1,5 -> MAD 1.5.
        assert_eq!(even.value(), Some(1.5 * MAD_TO_SIGMA));
    }

    #[test]
    fn counts_spikes_in_the_window_only() {
        let mut c = SpikeCounter::new(4, Some(1.0));
        for x in [0.0, 5.0, -4.0, 0.0] {
            c.push(x);
        }
        assert_eq!(c.fraction(), 0.5);
        c.push(0.0); // evicts the first 0
        assert_eq!(c.fraction(), 0.5);
        c.push(0.0); // evicts the 5
        assert_eq!(c.fraction(), 0.25);
        c.push(0.0); // evicts the −4
        assert_eq!(c.fraction(), 0.0);
        assert_eq!(c.threshold(), Some(3.0));
    }
}
