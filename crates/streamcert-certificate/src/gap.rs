//! Gaps and irregular sampling.
//!
//! A step `Δt` larger than `factor` times the reference step is a *gap*: a sensor paused or
//! rows were lost. Integrating across it would read the missing stretch as one enormous
//! column and one enormous residual, so the certifier resets its window and closes its gates
//! there ([`NotCertified::Gap`](crate::NotCertified::Gap)), and the sample after the gap starts
//! a new window.
//!
//! The reference step is the median of the last 32 accepted steps (recomputed at every step
//! while fewer than 32 are in, then every 32 steps, from a fixed-size buffer: no allocation,
//! `O(1)` amortised). Gap steps do not enter it. (For 32 values a sort measured faster than
//! `select_nth_unstable`.)
//!
//! The same reference normalises the one-step residuals that feed `ε`: a residual over an
//! interval `Δt` has a variance proportional to `Δt`, so it is multiplied by `√(Δt_ref/Δt)`
//! (only when `Δt` differs from the reference by more than one part in a million, so regular
//! sampling keeps its residuals bit for bit). Irregular sampling then does not read as heavy
//! tails.

use serde::{Deserialize, Serialize};

const RECENT: usize = 32;

/// The gap detector's state (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct GapDetector {
    factor: f64,
    recent: [f64; RECENT],
    len: usize,
    head: usize,
    since: usize,
    /// NaN before the first step, which JSON writes as `null`: read back as NaN.
    #[serde(deserialize_with = "nan_from_null")]
    reference: f64,
    gaps: u64,
    /// A gap the caller declared ([`Certifier::gap`](crate::Certifier::gap)): the next step is
    /// one, whatever its length. Written only while set, so checkpoints without a pending
    /// declared gap are byte for byte what they were.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    forced: bool,
}

/// An `f64` that JSON may hold as `null` (serde_json writes NaN so): `null` reads as NaN.
fn nan_from_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(<Option<f64> as serde::Deserialize>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// A detected gap.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Gap {
    /// The step.
    pub dt: f64,
    /// The reference step it was compared with.
    pub reference: f64,
}

impl GapDetector {
    pub(crate) fn new(factor: f64) -> Self {
        Self {
            factor,
            recent: [0.0; RECENT],
            len: 0,
            head: 0,
            since: 0,
            reference: f64::NAN,
            gaps: 0,
            forced: false,
        }
    }

    /// Gaps seen so far.
    pub(crate) fn gaps(&self) -> u64 {
        self.gaps
    }

    /// The reference step (NaN before the first step).
    pub(crate) fn reference(&self) -> f64 {
        self.reference
    }

    /// The factor `√(Δt_ref/Δt)` for a residual over a step `dt` (1 for a step within one
    /// part in a million of the reference, and before there is one).
    #[inline]
    pub(crate) fn residual_scale(&self, dt: f64) -> f64 {
        let r = self.reference;
        if !(r > 0.0) || (dt - r).abs() <= 1e-6 * r { 1.0 } else { (r / dt).sqrt() }
    }

    /// Declare that samples are missing before the next one: its step is a gap whatever its
    /// length.
    pub(crate) fn force(&mut self) {
        self.forced = true;
    }

    /// Forget a declared gap (the next sample starts the stream: there is no step to span).
    pub(crate) fn unforce(&mut self) {
        self.forced = false;
    }

    /// Observe a step `dt > 0`; `Some` when it is a gap (which is not recorded): a declared
    /// one, or one larger than `factor` times the reference.
    #[inline]
    pub(crate) fn observe(&mut self, dt: f64) -> Option<Gap> {
        if self.forced {
            self.forced = false;
            self.gaps += 1;
            return Some(Gap { dt, reference: self.reference });
        }
        if self.reference > 0.0 && dt > self.factor * self.reference {
            self.gaps += 1;
            return Some(Gap { dt, reference: self.reference });
        }
        self.recent[self.head] = dt;
        self.head = (self.head + 1) % RECENT;
        self.len = (self.len + 1).min(RECENT);
        self.since += 1;
        if self.len < RECENT || self.since >= RECENT {
            self.since = 0;
            let mut sorted = [0.0; RECENT];
            let window = &mut sorted[..self.len];
            window.copy_from_slice(&self.recent[..self.len]);
            window.sort_unstable_by(f64::total_cmp);
            self.reference = window[self.len / 2];
        }
        None
    }

    /// `true` when the state is one `observe` could have produced.
    pub(crate) fn is_consistent(&self, factor: f64) -> bool {
        self.factor.to_bits() == factor.to_bits()
            && self.len <= RECENT
            && self.head < RECENT
            && self.since < RECENT
            && self.recent[..self.len].iter().all(|v| v.is_finite() && *v > 0.0)
            && (self.len == 0) == self.reference.is_nan()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Oracle: the element a full sort of the steps the detector holds places at `len / 2`.
    fn sorted_median(steps: &[f64]) -> f64 {
        let mut v = steps.to_vec();
        v.sort_unstable_by(f64::total_cmp);
        v[v.len() / 2]
    }

    #[test]
    fn reference_is_the_sorted_median_at_every_refresh() {
        let mut det = GapDetector::new(1e9);
        let mut held: Vec<f64> = Vec::new();
        let (mut since, mut expected, mut refreshes) = (0usize, f64::NAN, 0usize);
        // Steps with many ties (a few distinct values) and a spread, deterministic.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for i in 0..2000usize {
            state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            let r = (state >> 40) as f64 / f64::from(1u32 << 24);
            let dt = if i % 3 == 0 { 0.01 } else { 0.005 + 0.01 * r };
            assert!(det.observe(dt).is_none());
            held.push(dt);
            if held.len() > RECENT {
                held.remove(0);
            }
            // The refresh rule: every step while fewer than 32 are held, then every 32 steps.
            since += 1;
            if held.len() < RECENT || since >= RECENT {
                since = 0;
                expected = sorted_median(&held);
                refreshes += 1;
            }
            assert_eq!(det.reference().to_bits(), expected.to_bits(), "step {i}");
        }
        assert!(refreshes > 60);
    }
}
