//! Exact sliding-window mean, variance and excess kurtosis in amortised O(1).

use serde::{Deserialize, Serialize};

use crate::{AmbiguityError, next};

/// Cancellation tolerance: recompute when the magnitude that passed through a sum since the
/// last exact recompute exceeds this multiple of the sum itself (rounding error is then at
/// most about `window · ε_mach · RECOMPUTE_RATIO ≈ 2e-11` relative for a window of 150).
const RECOMPUTE_RATIO: f64 = 1e3;

/// Sliding-window moments of the last `window` values.
///
/// With `d = x − c` for a shift `c` and `Sₖ = Σ dᵏ` over the window, `a = S₁/n`:
///
/// ```text
/// mean = c + a
/// m₂   = S₂/n − a²                                  (population variance)
/// m₄   = S₄/n − 4a S₃/n + 6a² S₂/n − 3a⁴
/// κ_e  = m₄ / m₂² − 3                               (excess kurtosis, g₂)
/// ```
///
/// Exactness: the sums are recomputed by two passes over the window (mean, then centred
/// powers, resetting `c` to the mean) every `window` pushes, whenever an evicted value's
/// magnitude dominated a sum (`Σ|d|ᵏ` since the last recompute `> 10³ Sₖ` for `k = 2, 4`),
/// and whenever the mean drifts more than a quarter of the root-mean-square deviation from
/// `c` (beyond that, forming central moments from shifted sums loses digits). Each spike costs
/// at most one recompute when it leaves, so the cost is O(1) amortised for a bounded spike
/// rate, with no allocation after construction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlidingKurtosis {
    buf: Vec<f64>,
    head: usize,
    len: usize,
    shift: f64,
    s: [f64; 4],
    /// `Σ|d|²` and `Σ|d|⁴` of every value added or evicted since the last recompute.
    mag: [f64; 2],
    since_recompute: usize,
    recomputes: u64,
}

impl SlidingKurtosis {
    /// Smallest window accepted.
    pub const MIN_WINDOW: usize = 4;

    /// An empty window of `window >= 4` values.
    ///
    /// # Errors
    /// [`AmbiguityError::TailWindowTooShort`].
    ///
    /// ```
    /// use streamcert_ambiguity::{SlidingKurtosis, AmbiguityError};
    /// let mut k = SlidingKurtosis::new(150)?;
    /// k.push(1.0)?;
    /// assert!(k.excess_kurtosis().is_none()); // fewer than 4 values
    /// assert!(matches!(SlidingKurtosis::new(3), Err(AmbiguityError::TailWindowTooShort { .. })));
    /// # Ok::<(), AmbiguityError>(())
    /// ```
    pub fn new(window: usize) -> Result<Self, AmbiguityError> {
        if window < Self::MIN_WINDOW {
            return Err(AmbiguityError::TailWindowTooShort { window, min: Self::MIN_WINDOW });
        }
        Ok(Self {
            buf: vec![0.0; window],
            head: 0,
            len: 0,
            shift: 0.0,
            s: [0.0; 4],
            mag: [0.0; 2],
            since_recompute: 0,
            recomputes: 0,
        })
    }

    /// Window length `N`.
    #[must_use]
    pub fn window(&self) -> usize {
        self.buf.len()
    }

    /// Values currently in the window.
    #[must_use]
    pub fn len(&self) -> usize {
        self.len
    }

    /// `true` before the first value.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Exact recomputes performed so far (for diagnostics and benchmarks).
    #[must_use]
    pub fn recomputes(&self) -> u64 {
        self.recomputes
    }

    /// The value that the next [`push`](Self::push) evicts, if the window is full.
    #[must_use]
    pub fn oldest(&self) -> Option<f64> {
        (self.len == self.buf.len()).then(|| self.buf[self.head])
    }

    /// The values in the window, oldest first.
    pub fn values(&self) -> impl Iterator<Item = f64> + '_ {
        let (older, newer) = self.slices();
        older.iter().chain(newer).copied()
    }

    /// The window as two contiguous runs, oldest first (the ring may wrap once).
    fn slices(&self) -> (&[f64], &[f64]) {
        let n = self.buf.len();
        if self.len < n {
            // Not yet wrapped: the values fill `[0, len)` (`head == len`).
            (&self.buf[..self.len], &[])
        } else {
            (&self.buf[self.head..], &self.buf[..self.head])
        }
    }

    /// Add a value, evicting the oldest when the window is full.
    ///
    /// # Errors
    /// [`AmbiguityError::NonFinite`]; the value is not absorbed.
    #[inline]
    pub fn push(&mut self, x: f64) -> Result<(), AmbiguityError> {
        if !x.is_finite() {
            return Err(AmbiguityError::NonFinite(x));
        }
        let n = self.buf.len();
        if self.len == 0 {
            self.shift = x;
        }
        if self.len == n {
            let e = self.buf[self.head] - self.shift;
            let e2 = e * e;
            self.s[0] -= e;
            self.s[1] -= e2;
            self.s[2] -= e2 * e;
            self.s[3] -= e2 * e2;
            self.mag[0] += e2;
            self.mag[1] += e2 * e2;
        } else {
            self.len += 1;
        }
        self.buf[self.head] = x;
        self.head = next(self.head, n);
        let d = x - self.shift;
        let d2 = d * d;
        self.s[0] += d;
        self.s[1] += d2;
        self.s[2] += d2 * d;
        self.s[3] += d2 * d2;
        self.mag[0] += d2;
        self.mag[1] += d2 * d2;
        self.since_recompute += 1;
        let lenf = self.len as f64;
        if self.since_recompute >= n
            || self.mag[0] > RECOMPUTE_RATIO * self.s[1]
            || self.mag[1] > RECOMPUTE_RATIO * self.s[3]
            || 16.0 * self.s[0] * self.s[0] > lenf * self.s[1]
        {
            self.recompute();
        }
        Ok(())
    }

    /// `true` when a deserialised state is one `push` could have produced: the ring's indices
    /// in range, every stored value finite, and the running sums within rounding of an exact
    /// recompute from the window (mean, variance and excess kurtosis to `1e-9` of their scale).
    #[must_use]
    pub fn is_consistent(&self) -> bool {
        let n = self.buf.len();
        let structure = n >= Self::MIN_WINDOW
            && self.head < n
            && self.len <= n
            && (self.len == n || self.head == self.len)
            && self.buf.iter().chain(&self.s).chain(&self.mag).all(|v| v.is_finite())
            && self.shift.is_finite();
        if !structure {
            return false;
        }
        let mut exact = self.clone();
        exact.recompute();
        let close = |a: Option<f64>, b: Option<f64>, scale: f64| match (a, b) {
            (Some(a), Some(b)) => (a - b).abs() <= 1e-9 * (scale + a.abs().max(b.abs())),
            (None, None) => true,
            _ => false,
        };
        let sd = exact.variance().unwrap_or(0.0).sqrt();
        close(self.mean(), exact.mean(), sd)
            && close(self.variance(), exact.variance(), 0.0)
            && close(self.excess_kurtosis(), exact.excess_kurtosis(), 3.0)
    }

    /// Exact two-pass recompute of the sums about the window mean.
    pub fn recompute(&mut self) {
        let lenf = self.len as f64;
        if self.len == 0 {
            self.s = [0.0; 4];
            self.mag = [0.0; 2];
            self.since_recompute = 0;
            return;
        }
        let (older, newer) = self.slices();
        let mean = (lanes(older, |x| x) + lanes(newer, |x| x)) / lenf;
        let mut s = [0.0; 4];
        for run in [older, newer] {
            s[0] += lanes(run, |x| x - mean);
            s[1] += lanes(run, |x| (x - mean).powi(2));
            s[2] += lanes(run, |x| (x - mean).powi(3));
            s[3] += lanes(run, |x| (x - mean).powi(4));
        }
        self.shift = mean;
        self.s = s;
        self.mag = [s[1], s[3]];
        self.since_recompute = 0;
        self.recomputes += 1;
    }

    /// Window mean (`None` when empty).
    #[must_use]
    pub fn mean(&self) -> Option<f64> {
        (self.len > 0).then(|| self.shift + self.s[0] / self.len as f64)
    }

    /// Population variance `m₂` (`None` when empty).
    #[must_use]
    pub fn variance(&self) -> Option<f64> {
        if self.len == 0 {
            return None;
        }
        let n = self.len as f64;
        let a = self.s[0] / n;
        Some((self.s[1] / n - a * a).max(0.0))
    }

    /// Excess kurtosis `κ_e = m₄ / m₂² − 3` (population form `g₂`). `None` with fewer than 4
    /// values or a window whose spread is zero to rounding (no shape information).
    #[must_use]
    #[inline]
    pub fn excess_kurtosis(&self) -> Option<f64> {
        if self.len < Self::MIN_WINDOW {
            return None;
        }
        // With the raw sums, n² m₂ = n S₂ − S₁² and
        // n⁴ m₄ = n³ S₄ − 4 n² S₁ S₃ + 6 n S₁² S₂ − 3 S₁⁴, so κ_e + 3 = n⁴ m₄ / (n² m₂)² needs
        // a single division (this is on the per-sample path).
        let n = self.len as f64;
        let [s1, s2, s3, s4] = self.s;
        let s1sq = s1 * s1;
        let m2n2 = n * s2 - s1sq;
        let m4n4 = n * (n * (n * s4 - 4.0 * s1 * s3) + 6.0 * s1sq * s2) - 3.0 * s1sq * s1sq;
        // Spread below rounding of the shift: the shape is not defined.
        let floor = 1e-24 * self.shift * self.shift * n * n;
        if !(m2n2 > floor && m2n2 > 0.0) {
            return None;
        }
        Some(m4n4 / (m2n2 * m2n2) - 3.0)
    }
}

/// `Σ f(x)` over `xs` with four independent partial sums (the recompute is the only `O(N)`
/// work of the estimator; independent lanes let it run at the machine's throughput instead
/// of one addition latency per value).
#[inline]
fn lanes(xs: &[f64], f: impl Fn(f64) -> f64) -> f64 {
    let mut acc = [0.0f64; 4];
    let mut chunks = xs.chunks_exact(4);
    for c in &mut chunks {
        for (a, &x) in acc.iter_mut().zip(c) {
            *a += f(x);
        }
    }
    let tail: f64 = chunks.remainder().iter().map(|&x| f(x)).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_window_has_no_kurtosis_and_rejects_nan() {
        let mut k = SlidingKurtosis::new(10).unwrap();
        for _ in 0..20 {
            k.push(3.0).unwrap();
        }
        assert_eq!(k.variance(), Some(0.0));
        assert_eq!(k.excess_kurtosis(), None);
        let before = k.clone();
        assert!(matches!(k.push(f64::NAN), Err(AmbiguityError::NonFinite(_))));
        assert!(matches!(k.push(f64::INFINITY), Err(AmbiguityError::NonFinite(_))));
        assert_eq!(k, before);
    }
}
