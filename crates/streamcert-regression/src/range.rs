//! [`SlidingRange`]: the smallest and largest value of each channel over the last `W` samples,
//! the *region* a window's certificate speaks for.
//!
//! A linear certificate estimates one averaged (secant) Jacobian over the states its window
//! visited; the ranges say which states those are. Each channel keeps two monotonic deques
//! (indices and values, in ring buffers of `W` slots): the maximum's deque holds the samples
//! not dominated by a later, larger one, so its front is the window's maximum (likewise the
//! minimum). A push costs amortised `O(1)` per channel, allocates nothing, and the ranges are
//! exact (no rounding: they are sample values).

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

/// One monotonic deque in a ring of `width` slots.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Deque {
    idx: Vec<u64>,
    val: Vec<f64>,
    head: usize,
    len: usize,
}

impl Deque {
    fn new(width: usize) -> Self {
        Self { idx: vec![0; width], val: vec![0.0; width], head: 0, len: 0 }
    }

    /// Push sample `n` with value `x`, dropping samples at or before `n − width` from the
    /// front and, from the back, the samples `x` dominates (`dominates(x, old)`).
    #[inline(always)]
    fn push(&mut self, n: u64, x: f64, width: usize, dominates: impl Fn(f64, f64) -> bool) -> f64 {
        let slot = |i: usize| if i >= width { i - width } else { i };
        if self.len > 0 && self.idx[self.head] + width as u64 <= n {
            self.head = slot(self.head + 1);
            self.len -= 1;
        }
        while self.len > 0 && dominates(x, self.val[slot(self.head + self.len - 1)]) {
            self.len -= 1;
        }
        let back = slot(self.head + self.len);
        self.idx[back] = n;
        self.val[back] = x;
        self.len += 1;
        self.val[self.head]
    }

    /// Indices strictly increasing within the window ending at sample `n − 1`, values ordered
    /// by `ordered(earlier, later)`, every value finite.
    fn is_consistent(&self, n: u64, width: usize, ordered: impl Fn(f64, f64) -> bool) -> bool {
        if self.idx.len() != width || self.val.len() != width || self.head >= width {
            return false;
        }
        if self.len > width || (self.len == 0) != (n == 0) {
            return false;
        }
        let slot = |i: usize| (self.head + i) % width;
        let newest_ok = self.len == 0 || self.idx[slot(self.len - 1)] + 1 == n;
        let oldest_ok = self.len == 0 || self.idx[self.head] + width as u64 >= n;
        newest_ok
            && oldest_ok
            && (0..self.len).all(|i| self.val[slot(i)].is_finite())
            && (1..self.len).all(|i| {
                let (a, b) = (slot(i - 1), slot(i));
                self.idx[a] < self.idx[b] && ordered(self.val[a], self.val[b])
            })
    }
}

/// Sliding minimum and maximum of `channels` values over the last `width` pushes; see the
/// module docs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlidingRange {
    width: usize,
    count: u64,
    max: Vec<Deque>,
    min: Vec<Deque>,
    ranges: Vec<Interval>,
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
            max: (0..channels).map(|_| Deque::new(width)).collect(),
            min: (0..channels).map(|_| Deque::new(width)).collect(),
            ranges: vec![Interval::EMPTY; channels],
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
    /// are read). Amortised `O(1)` per channel, no allocation.
    #[inline]
    pub fn push(&mut self, values: impl IntoIterator<Item = f64>) {
        let (n, width) = (self.count, self.width);
        for (((x, hi), lo), out) in
            values.into_iter().zip(&mut self.max).zip(&mut self.min).zip(&mut self.ranges)
        {
            out.hi = hi.push(n, x, width, |new, old| new >= old);
            out.lo = lo.push(n, x, width, |new, old| new <= old);
        }
        self.count += 1;
    }

    /// The range of each channel over the last `min(count, width)` samples
    /// ([`Interval::EMPTY`] before the first).
    #[must_use]
    pub fn ranges(&self) -> &[Interval] {
        &self.ranges
    }

    /// Forget every sample.
    pub fn reset(&mut self) {
        self.count = 0;
        for d in self.max.iter_mut().chain(&mut self.min) {
            d.head = 0;
            d.len = 0;
        }
        self.ranges.fill(Interval::EMPTY);
    }

    /// Check a deserialised state: `channels` channels of width `width`, deques ordered and
    /// within the window, and the reported ranges equal to the deques' fronts.
    ///
    /// # Errors
    /// [`RegressionError::CorruptState`].
    pub fn check_state(&self, channels: usize, width: usize) -> Result<(), RegressionError> {
        let shape = self.width == width
            && self.max.len() == channels
            && self.min.len() == channels
            && self.ranges.len() == channels;
        let n = self.count;
        let ok = shape
            && self.max.iter().all(|d| d.is_consistent(n, width, |a, b| a > b))
            && self.min.iter().all(|d| d.is_consistent(n, width, |a, b| a < b))
            && self.max.iter().zip(&self.min).zip(&self.ranges).all(|((hi, lo), r)| {
                if n == 0 {
                    *r == Interval::EMPTY
                } else {
                    r.hi == hi.val[hi.head] && r.lo == lo.val[lo.head]
                }
            });
        if ok { Ok(()) } else { Err(RegressionError::CorruptState("sliding ranges".into())) }
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
                assert_eq!(r.ranges()[c], Interval { lo, hi }, "step {k} channel {c}");
            }
            r.check_state(2, 7).unwrap();
        }
        r.reset();
        assert_eq!(r.ranges()[0], Interval::EMPTY);
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
        bad.max[0].head = 9;
        assert!(bad.check_state(1, 4).is_err());
        let mut bad = r.clone();
        bad.ranges[0].hi = 7.0;
        assert!(bad.check_state(1, 4).is_err());
        let mut bad = r.clone();
        bad.count += 10;
        assert!(bad.check_state(1, 4).is_err());
        assert!(r.check_state(1, 5).is_err());
    }
}
