//! [`SlidingRange`]: the smallest and largest value of each channel over the last `W` samples,
//! the *region* a window's certificate speaks for.
//!
//! A linear certificate estimates one averaged (secant) Jacobian over the states its window
//! visited; the ranges say which states those are. The samples are cut into blocks of `W`; the
//! window ending at a sample is the tail of the previous block and the head of the current
//! one, so its extremes are those of the previous block's suffix (formed once when the block
//! ended) and of the current block's prefix (a running extreme): the block algorithm of van
//! Herk (1992) and Gil and Werman (1993). A push stores the value and updates the prefix
//! extremes (one comparison per channel and extreme, plus, amortised, two more when a block
//! ends); the range itself is formed when it is asked for ([`SlidingRange::ranges`], one more
//! comparison per extreme), since most samples are never asked. Nothing is allocated, and the
//! ranges are exact (no rounding: they are sample values).

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::RegressionError;

/// The smallest and largest value of one channel over a window (`lo <= hi`).
///
/// Serialised as `[lo, hi]`; a bound that is not finite (the [`EMPTY`](Self::EMPTY)
/// interval's) is written as `null` and read back as `EMPTY`'s bound, so that formats without
/// infinities (JSON) round-trip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interval {
    /// Smallest value.
    pub lo: f64,
    /// Largest value.
    pub hi: f64,
}

impl Serialize for Interval {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let finite = |v: f64| v.is_finite().then_some(v);
        (finite(self.lo), finite(self.hi)).serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for Interval {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let (lo, hi) = <(Option<f64>, Option<f64>)>::deserialize(deserializer)?;
        Ok(Self { lo: lo.unwrap_or(f64::INFINITY), hi: hi.unwrap_or(f64::NEG_INFINITY) })
    }
}

impl Interval {
    /// The empty interval (`lo = +∞`, `hi = −∞`), the identity of [`hull`](Self::hull).
    pub const EMPTY: Self = Self { lo: f64::INFINITY, hi: f64::NEG_INFINITY };

    /// The smallest interval containing both.
    #[must_use]
    #[inline]
    pub fn hull(self, other: Self) -> Self {
        Self { lo: self.lo.min(other.lo), hi: self.hi.max(other.hi) }
    }

    /// `true` when `lo <= hi` and both are finite.
    #[must_use]
    pub fn is_proper(&self) -> bool {
        self.lo.is_finite() && self.hi.is_finite() && self.lo <= self.hi
    }
}

/// The smaller of two finite values. Plain comparisons: the values are finite (the
/// regression checks them first), so the NaN handling of `f64::min` is not needed.
#[inline(always)]
fn lt(a: f64, b: f64) -> f64 {
    if a < b { a } else { b }
}

/// The larger of two finite values (see [`lt`]).
#[inline(always)]
fn gt(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

/// Sliding minimum and maximum of `channels` values over the last `width` pushes; see the
/// module docs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlidingRange {
    width: usize,
    count: u64,
    // `count mod width`: the position of the next sample in its block.
    pos: usize,
    // Per channel `c`, slots `c·width .. (c + 1)·width`: the values of the current block of
    // `width` samples (position `n mod width`; positions after the current one still hold
    // the previous block), and the previous block's suffix maxima and minima.
    vals: Vec<f64>,
    suffix_max: Vec<f64>,
    suffix_min: Vec<f64>,
    // Per channel: the current block's prefix extremes.
    prefix: Vec<Interval>,
}

impl SlidingRange {
    /// `channels` channels over windows of `width >= 1` samples.
    ///
    /// # Errors
    /// [`RegressionError::InvalidConfig`] for `width = 0`.
    pub fn new(channels: usize, width: usize) -> Result<Self, RegressionError> {
        if width == 0 {
            return Err(RegressionError::InvalidConfig {
                field: "window",
                reason: "the range window must hold at least one sample".into(),
            });
        }
        Ok(Self {
            width,
            count: 0,
            pos: 0,
            vals: vec![0.0; channels * width],
            suffix_max: vec![0.0; channels * width],
            suffix_min: vec![0.0; channels * width],
            prefix: vec![Interval::EMPTY; channels],
        })
    }

    /// The window width in samples.
    #[must_use]
    pub fn width(&self) -> usize {
        self.width
    }

    /// Samples pushed since construction or the last [`reset`](Self::reset).
    #[must_use]
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Absorb one sample, the channels' values in order (the first `channels` of `values`
    /// are read). `O(1)` amortised per channel (the block algorithm of van Herk and
    /// Gil–Werman: a block's suffix extremes are formed once, when the next block starts),
    /// no allocation.
    #[inline]
    pub fn push(&mut self, values: impl IntoIterator<Item = f64>) {
        let (w, i) = (self.width, self.pos);
        if i == 0 && self.count > 0 {
            self.close_block();
        }
        let vals = self.vals.chunks_exact_mut(w);
        for ((v, p), x) in vals.zip(&mut self.prefix).zip(values) {
            v[i] = x;
            *p = if i == 0 {
                Interval { lo: x, hi: x }
            } else {
                Interval { lo: lt(x, p.lo), hi: gt(x, p.hi) }
            };
        }
        self.pos = if i + 1 == w { 0 } else { i + 1 };
        self.count += 1;
    }

    /// The block that just ended becomes the previous block: its suffix extremes.
    #[cold]
    fn close_block(&mut self) {
        let w = self.width;
        for ((v, hi), lo) in self
            .vals
            .chunks_exact(w)
            .zip(self.suffix_max.chunks_exact_mut(w))
            .zip(self.suffix_min.chunks_exact_mut(w))
        {
            let (mut mx, mut mn) = (v[w - 1], v[w - 1]);
            for j in (0..w).rev() {
                (mx, mn) = (if v[j] > mx { v[j] } else { mx }, if v[j] < mn { v[j] } else { mn });
                hi[j] = mx;
                lo[j] = mn;
            }
        }
    }

    /// The range of each channel over the last `min(count, width)` samples, in channel order
    /// ([`Interval::EMPTY`] before the first): the current block's prefix extremes, joined
    /// with the previous block's suffix extremes from the position after the newest sample
    /// while the window reaches back into that block. `O(channels)`, formed on each call.
    pub fn ranges(&self) -> impl ExactSizeIterator<Item = Interval> + '_ {
        let w = self.width;
        // The newest sample is at position i; the window is positions i + 1 .. w of the
        // previous block (when there is one and the window reaches it) and 0 ..= i of this one.
        let i = if self.pos == 0 { w - 1 } else { self.pos - 1 };
        let reaches_back = self.count > w as u64 && i + 1 < w;
        self.prefix.iter().enumerate().map(move |(c, p)| {
            if reaches_back {
                let j = c * w + i + 1;
                Interval { lo: lt(self.suffix_min[j], p.lo), hi: gt(self.suffix_max[j], p.hi) }
            } else {
                *p
            }
        })
    }

    /// Forget every sample.
    pub fn reset(&mut self) {
        self.count = 0;
        self.pos = 0;
        self.prefix.fill(Interval::EMPTY);
    }

    /// Check a deserialised state: `channels` channels of width `width`, every value finite,
    /// and the prefix extremes, the suffix extremes still in use and the reported ranges equal
    /// to what the stored values give.
    ///
    /// # Errors
    /// [`RegressionError::CorruptState`].
    pub fn check_state(&self, channels: usize, width: usize) -> Result<(), RegressionError> {
        let w = width;
        let shape = self.width == w
            && self.vals.len() == channels * w
            && self.suffix_max.len() == channels * w
            && self.suffix_min.len() == channels * w
            && self.prefix.len() == channels
            && self.pos as u64 == self.count % w as u64;
        let bad = || Err(RegressionError::CorruptState("sliding ranges".into()));
        if !shape {
            return bad();
        }
        if self.count == 0 {
            let empty = |r: &Interval| *r == Interval::EMPTY;
            return if self.prefix.iter().all(empty) { Ok(()) } else { bad() };
        }
        // The newest sample is at position i of the current block.
        let i = ((self.count - 1) % w as u64) as usize;
        let full = self.count > w as u64;
        for (c, range) in self.ranges().enumerate() {
            let v = &self.vals[c * w..(c + 1) * w];
            if !v.iter().all(|x| x.is_finite()) {
                return bad();
            }
            let hull = |r: std::ops::Range<usize>| {
                v[r].iter().fold(Interval::EMPTY, |a, &x| a.hull(Interval { lo: x, hi: x }))
            };
            let prefix = hull(0..i + 1);
            let mut want = prefix;
            if full && i + 1 < w {
                // Positions after i still hold the previous block, whose suffix is in use.
                for j in i + 1..w {
                    let tail = hull(j..w);
                    if self.suffix_max[c * w + j] != tail.hi
                        || self.suffix_min[c * w + j] != tail.lo
                    {
                        return bad();
                    }
                }
                want = want.hull(hull(i + 1..w));
            }
            if self.prefix[c] != prefix || range != want {
                return bad();
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_equal_a_batch_scan_at_every_step() {
        let mut r = SlidingRange::new(2, 7).unwrap();
        let mut hist: Vec<[f64; 2]> = Vec::new();
        let mut x = 0.3f64;
        for k in 0..500 {
            // A chaotic sequence with repeats (ties) and plateaus.
            x = if k % 37 < 5 { x } else { (3.9 * x * (1.0 - x)).clamp(0.0, 1.0) };
            let v = [x, (k % 11) as f64 - 5.0];
            r.push(v);
            hist.push(v);
            let from = hist.len().saturating_sub(7);
            for c in 0..2 {
                let lo = hist[from..].iter().map(|s| s[c]).fold(f64::INFINITY, f64::min);
                let hi = hist[from..].iter().map(|s| s[c]).fold(f64::NEG_INFINITY, f64::max);
                assert_eq!(r.ranges().nth(c), Some(Interval { lo, hi }), "step {k} channel {c}");
            }
            r.check_state(2, 7).unwrap();
        }
        r.reset();
        assert!(r.ranges().eq([Interval::EMPTY; 2]));
        r.check_state(2, 7).unwrap();
    }

    #[test]
    fn intervals_round_trip_through_json_including_the_empty_one() {
        for r in [Interval::EMPTY, Interval { lo: -1.5, hi: 2.25 }] {
            let text = serde_json::to_string(&r).unwrap();
            assert_eq!(serde_json::from_str::<Interval>(&text).unwrap(), r, "{text}");
        }
        let mut r = SlidingRange::new(2, 3).unwrap();
        let text = serde_json::to_string(&r).unwrap();
        assert_eq!(serde_json::from_str::<SlidingRange>(&text).unwrap(), r);
        r.push([1.0, -2.0]);
        let text = serde_json::to_string(&r).unwrap();
        assert_eq!(serde_json::from_str::<SlidingRange>(&text).unwrap(), r);
    }

    #[test]
    fn damaged_states_are_refused() {
        let mut r = SlidingRange::new(1, 4).unwrap();
        for v in [1.0, 3.0, 2.0, 0.5, 4.0] {
            r.push([v]);
        }
        let mut bad = r.clone();
        bad.suffix_max[3] = 9.0;
        assert!(bad.check_state(1, 4).is_err());
        let mut bad = r.clone();
        bad.vals[0] = f64::NAN;
        assert!(bad.check_state(1, 4).is_err());
        let mut bad = r.clone();
        bad.prefix[0].hi = 7.0;
        assert!(bad.check_state(1, 4).is_err());
        let mut bad = r.clone();
        bad.pos = 3;
        assert!(bad.check_state(1, 4).is_err());
        let mut bad = r.clone();
        bad.count += 10;
        assert!(bad.check_state(1, 4).is_err());
        assert!(r.check_state(1, 5).is_err());
    }
}
