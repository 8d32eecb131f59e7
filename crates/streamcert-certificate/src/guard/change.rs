//! The change guard ([`Calibration::plant_change`]): a window's certificate stands only while
//! its data agree with the newest data.
//!
//! A window's look is held until its next look, up to half its span later, and the longest
//! windows hold up to `200 h` columns of the past: after a plant change they keep certifying
//! the plant that was, or an average of the two. The guard takes a *fresh* estimate of each
//! window `v` on its newest columns at the end of every `P_v`-th block of `h` columns
//! (counted from the state's start, so at the same blocks for windows at the same pace) and
//! at each window's look: `P_0 = P_1 = ⌈B_0 / 8⌉` (`B_0` the shortest window's blocks) and
//! `P_v = 2^(v−1) P_0` for the longer windows, which double in length (each window from the
//! second on is refreshed about fifteen times per its own span, and window `v − 1` is due
//! at every block window `v` is). A fresh estimate (`β̂_v` and its standard deviation
//! `s_v`: the calibrated look's estimate and degrees of freedom, with the first-order
//! variance from the windows' segment sums, see *Cost* below; at a window's look, the look's
//! own numbers) spends no risk of `δ` and certifies nothing; two tests decide:
//!
//! ```text
//! split test of window v >= 1:  β̂_{v−1} + t_{ν_{v−1}}(1 − α) · √(s_{v−1}² + s_o²)  >=  β̂_o
//! held look of window w:        β̂_v + t_{ν_v}(1 − α) · √(s_v² + s_w²)  >=  β̂_w   (v <= w)
//! ```
//!
//! The split test compares window `v`'s blocks older than window `v − 1` (`β̂_o`, `s_o`)
//! with window `v − 1`'s fresh estimate, which ends now: two disjoint parts, so a change near
//! the middle of a window is seen at full strength. Where it rejects, the start of that newer
//! part becomes the *change point*, and from then on no look whose data start before the
//! latest change point stands (any window's: the change lies somewhere in window `v`, and a
//! look that holds data from before its newer part may hold the old plant; once the change
//! has moved deep into the longer windows their halves no longer differ enough to see it,
//! which is why the point is kept). A false rejection thus closes the looks of the longer
//! windows until they have filled past it, at most the longest window's span; the shorter
//! windows' looks after it still stand. The second compares each window's
//! latest look with the fresh estimates of itself and of every shorter window: it catches a
//! look taken before the change. Risks: `α = δ / (W (W + 1) / 2 + W)` per split test (`W`
//! windows; a false rejection is kept as a change point), and
//! [`Calibration::change_risk`](crate::Calibration::change_risk) per held-look comparison
//! (default `δ`: a false rejection closes that look until the next comparison only, an
//! eighth of the shortest window, so its price is a few samples of power; at `δ / 14`, the
//! split tests' risk, the gate at `dt = 0.01` stayed open more than 1.5 spans after a drop
//! in 5.5 to 7 % of VALIDITY.md's runs, at `δ` in 2 to 3.5 %, with the same power). Both
//! quantiles are taken at the integer above `ν` (no larger than the exact ones: a closing
//! never less often; see [`Fresh::quantile`]). Where the plant
//! is unchanged, each difference has mean zero and variance at most the sum of the two
//! variances (disjoint parts: about equal; overlapping estimates have a positive
//! covariance), so a comparison closes falsely with probability at most about its risk. One-sided,
//! because a rate that rose leaves the older certificate on the safe side. Where a test
//! rejects, the look does not stand (`NotCertified::PlantChanged`, with both numbers); the
//! next looks, on post-change data, decide again.
//!
//! **Closing delay.** A drop of the rate by `Δ` is seen once a newer part, a mixture of the
//! old and the new plant weighted by its share `f` of post-change columns, falls
//! `t √(s² + s_o²)` below the older part: `f ≈ t s √2 / Δ` of the shorter window's span,
//! plus the time to the next comparison. A slow drift is a sequence of small changes: the
//! guard closes once the rate has drifted by about `t √(s² + s_o²)` between a window's two
//! parts, so a slow enough drift keeps the gate open on looks at most that far above the
//! newest rate (VALIDITY.md measures steps and two drifts: the certificate mostly falls
//! below the margin with the rate before the crossing).
//!
//! Closing never costs validity; its price is power (a false comparison closes a standing
//! look until the next comparison, and a change to a still contracting plant closes the
//! longer windows' looks until the shorter windows certify the new plant).
//!
//! **Cost.** A fresh estimate is
//! [`InstrumentedWindows::fresh_estimate`](streamcert_regression::InstrumentedWindows::fresh_estimate):
//! the span's sums and the second moments of its blocks' sums from segment sums kept along the
//! block ring (at most one subtraction over at most the longest window's blocks), the solve
//! of the look, and each block's first-order influence summed as a quadratic form in those
//! moments with `B/(B − d)` for the fitted directions; `O(1)` in the window's length (about
//! `(d + p)² k²/2` products per block to keep the moments, a solve and a quadratic form per
//! estimate), no allocation, and the same numbers after a restore (the moments are rebuilt
//! from the ring). Where a quadratic form falls below `10⁻⁹` of its terms' magnitude, or
//! with batches of more than one block, it is the look's pass over the blocks (the
//! jackknife) instead. A first-order estimate decides nothing by itself: where it would
//! close something (a held look below it, a split test that rejects), it is retaken with the
//! look's variance, the delete-one-block jackknife (`O(B_v)`, on the window's newest blocks
//! at that block), and the comparison is made on that. The first-order variance is the
//! smaller where an input moved in a few blocks (it has no leverage factor): taken alone it
//! closed the heat exchanger's gate (`cargo xtask real`) on 15 % more of its rows; retaken,
//! the gate is the same at every row as with the jackknife throughout. About 1.2 fresh
//! estimates per block of `h` columns for the default five windows, each `O(1)` unless
//! retaken (the pass over the blocks each used to cost, about 98 block visits per block,
//! was a third of the default step; BENCHMARKS.md).
//! Pace and closing delay, measured (`cargo xtask validity --only-change 200`, dt = 0.01,
//! drops from rate 3 to −0.2, 0, 0.04): open later than 1.5 spans in 2.0 / 3.0 / 2.5 % of
//! runs with every window at the shortest window's pace, 2.0 / 3.5 / 3.0 % with the pace
//! above, 2.0 / 6.5 / 4.5 % with every window at an eighth of itself.
//!
//! [`Calibration::plant_change`]: crate::Calibration::plant_change

use serde::{Deserialize, Serialize};

use crate::NotCertified;
use crate::look::quantile::t_quantile;

/// The fresh estimate of the shortest window.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub(crate) struct Fresh {
    /// Time of the estimate.
    pub t: f64,
    /// `β̂_f`.
    pub beta_hat: f64,
    /// `s_f`.
    pub sd: f64,
    /// Degrees of freedom `ν_f`.
    pub nu: f64,
    /// `t_{⌈ν_f⌉}(1 − α_held)`, the quantile of the held-look comparisons, and
    /// `t_{⌈ν_f⌉}(1 − α)`, the split test's, both set by [`ChangeGuard::set`]. At the integer
    /// above `ν_f` (a quantile at most the exact one: a closing never less often, a false
    /// one slightly more often than the stated risk, by under 1 % of the quantile at the
    /// default windows' `ν >= 25`), so that they come from the guard's cache by `⌈ν⌉`
    /// instead of an incomplete beta function at every estimate.
    pub quantile: f64,
    /// See [`quantile`](Self::quantile).
    pub split_quantile: f64,
    /// `true` for the look's variance (the jackknife), `false` for the first-order one of
    /// the segment sums (*Cost* in the module docs), which is replaced by the jackknife's
    /// before it closes anything.
    #[serde(default)]
    pub exact: bool,
}

impl Fresh {
    /// An estimate `β̂`, `s`, `ν` at time `t` (first-order), its quantiles not yet set.
    pub(crate) fn new(t: f64, beta_hat: f64, sd: f64, nu: f64) -> Self {
        Self { t, beta_hat, sd, nu, quantile: f64::NAN, split_quantile: f64::NAN, exact: false }
    }

    /// This estimate, marked as taken with the look's variance.
    pub(crate) fn exact(self) -> Self {
        Self { exact: true, ..self }
    }
}

/// Fresh estimates per shortest window: every `⌈B_0 / SPACING⌉` blocks.
const SPACING: usize = 8;

/// Slots of the quantile cache per window (32 per window: 3.8 kB for five windows).
const CACHE: usize = 32;

/// The guard's state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct ChangeGuard {
    /// Risk `α` of each split test.
    alpha: f64,
    /// Risk `α_held` of each comparison of a held look with a fresh estimate.
    held: f64,
    /// Blocks between fresh estimates of each window, `P_v` (module docs).
    spacing: Vec<usize>,
    /// Each window's latest fresh estimate (`None`: none yet, or its fit not ready).
    fresh: Vec<Option<Fresh>>,
    /// Each window's latest split test (`v >= 1`): its older part's `β̂`, the newer part's
    /// (window `v − 1`'s fresh estimate) one-sided upper bound, and the newer part's first
    /// column (in the calibrated state's column count); `None` when not run.
    split: Vec<Option<(f64, f64, u64)>>,
    /// The latest change point: the newer part's first column of the latest split test that
    /// rejected, with its older `β̂` and newer upper bound (sticky until a reset: a look whose
    /// data start before it may hold the old plant).
    changed: Option<(f64, f64, u64)>,
    /// Quantiles by window and `⌈ν⌉`, direct-mapped: slot `32 v + ⌈ν⌉ mod 32` holds window
    /// `v`'s `(⌈ν⌉, t_held, t_split)` (`(0, 0, 0)`: empty). A window's `ν` moves over a few
    /// to a few tens of integers, which then cost no incomplete beta function: on G5's
    /// subsystem B (20 000 samples) 12.5 % of the estimates missed (7.9 % are a key's first
    /// use), against 24.8 % with one cache of 64 slots shared by the windows, 42.4 % with 8
    /// and 25.3 % with 16 per window, 8.6 % with 64 per window.
    cache: Vec<(u32, f64, f64)>,
}

impl ChangeGuard {
    /// The guard for windows of `blocks` blocks each (shortest first), at risk `alpha` per
    /// split test and `held` per comparison of a held look with a fresh estimate.
    pub(crate) fn new(blocks: &[usize], alpha: f64, held: f64) -> Self {
        Self {
            alpha,
            held,
            // Windows 0 and 1 at the shortest window's pace, window v >= 2 at 2^(v−1) times
            // it (see the module docs).
            spacing: {
                let pace = blocks.first().map_or(1, |b0| b0.div_ceil(SPACING).max(1));
                (0..blocks.len()).map(|v| pace << v.saturating_sub(1).min(16)).collect()
            },
            fresh: vec![None; blocks.len()],
            split: vec![None; blocks.len()],
            changed: None,
            cache: vec![(0, 0.0, 0.0); CACHE * blocks.len()],
        }
    }

    /// Forget the fresh estimates.
    pub(crate) fn reset(&mut self) {
        self.fresh.fill(None);
        self.split.fill(None);
        self.changed = None;
    }

    /// Whether window `v`'s fresh estimate is due at the end of block `block` (counted from
    /// the state's start): every `spacing[v]` blocks, at the same blocks for every window at
    /// the same pace, so that a split test finds the shorter window's estimate of the same
    /// block already taken.
    pub(crate) fn due(&self, v: usize, block: u64) -> bool {
        block.is_multiple_of(self.spacing[v] as u64)
    }

    /// Replace window `v`'s fresh estimate (kept only when every number is finite), with its
    /// quantiles (those of the estimate it replaces when `⌊ν⌋` is the same).
    pub(crate) fn set(&mut self, v: usize, fresh: Option<Fresh>) {
        self.fresh[v] = fresh
            .filter(|f| f.t.is_finite() && f.beta_hat.is_finite() && f.sd.is_finite())
            .filter(|f| f.nu.is_finite() && f.nu > 0.0 && f.nu < f64::from(u32::MAX))
            .map(|f| {
                let (quantile, split_quantile) = self.quantiles(v, f.nu.ceil() as u32);
                Fresh { quantile, split_quantile, ..f }
            })
            .filter(|f| f.quantile.is_finite() && f.split_quantile.is_finite());
    }

    /// `(t_ν(1 − α_held), t_ν(1 − α))` at `ν = key >= 1` for window `v`, from the cache when
    /// its slot holds them.
    fn quantiles(&mut self, v: usize, key: u32) -> (f64, f64) {
        let slot = &mut self.cache[v * CACHE + key as usize % CACHE];
        if slot.0 != key {
            let nu = f64::from(key);
            *slot = (key, t_quantile(nu, self.held), t_quantile(nu, self.alpha));
        }
        (slot.1, slot.2)
    }

    /// Replace window `v`'s split test (`v >= 1`) with the estimate `older` of its blocks
    /// older than window `v − 1` against window `v − 1`'s fresh estimate (set first), whose
    /// first column is `boundary`.
    pub(crate) fn set_split(&mut self, v: usize, older: Option<Fresh>, boundary: u64) {
        let newer = v.checked_sub(1).and_then(|u| self.fresh[u]);
        self.split[v] = older.zip(newer).and_then(|(old, new)| {
            let spread = (new.sd * new.sd + old.sd * old.sd).sqrt();
            let upper = new.beta_hat + new.split_quantile * spread;
            // A test without a finite bound (too few degrees of freedom) is not run.
            upper.is_finite().then_some((old.beta_hat, upper, boundary))
        });
        if let Some(s) = self.split[v].filter(|s| s.1 < s.0)
            && self.changed.is_none_or(|c| c.2 < s.2)
        {
            self.changed = Some(s);
        }
    }

    /// Whether window `v >= 1`'s split test with `older` against window `v − 1`'s fresh
    /// estimate would reject while one of the two is first-order (so that both are retaken
    /// with the look's variance first).
    pub(crate) fn split_needs_exact(&self, v: usize, older: Option<Fresh>) -> bool {
        let newer = v.checked_sub(1).and_then(|u| self.fresh[u]);
        older.zip(newer).is_some_and(|(old, new)| {
            let spread = (new.sd * new.sd + old.sd * old.sd).sqrt();
            let upper = new.beta_hat + new.split_quantile * spread;
            upper < old.beta_hat && !(old.exact && new.exact)
        })
    }

    /// The windows whose first-order fresh estimate would close one of the held `looks`
    /// (window `v`'s against the looks of windows `w >= v`, as [`admits`](Self::admits)
    /// compares them), as a bit set: each is retaken with the look's variance before it
    /// closes anything.
    pub(crate) fn needs_exact(&self, looks: &[Option<(f64, f64)>]) -> u32 {
        let mut out = 0u32;
        for (v, f) in self.fresh.iter().enumerate() {
            let Some(f) = f.filter(|f| !f.exact) else { continue };
            let rejects = looks.iter().skip(v).flatten().any(|&(beta_hat, sd)| {
                let spread = (f.sd * f.sd + sd * sd).sqrt();
                f.beta_hat + f.quantile * spread < beta_hat
            });
            if rejects {
                out |= 1 << v;
            }
        }
        out
    }

    /// The shortest window's latest fresh estimate.
    pub(crate) fn fresh(&self) -> Option<Fresh> {
        self.fresh.first().copied().flatten()
    }

    /// Whether window `w`'s look (its length in columns `window`, its `β̂_w` and `s_w`), whose
    /// data start at column `first`, agrees with the newest data: `Err(PlantChanged)` when a
    /// window's split test rejects and the look holds data from before that split's newer
    /// part, or when the fresh estimate of any window `v <= w` (taken at every look, so at
    /// least as recent as any) lies significantly below it.
    pub(crate) fn admits(
        &self,
        w: usize,
        (window, beta_hat, sd): (usize, f64, f64),
        first: u64,
    ) -> Result<(), NotCertified> {
        // A drop inside a window: its newer part significantly below its older one, now or
        // at the latest change point.
        for &(older, upper, boundary) in self.split.iter().flatten().chain(&self.changed) {
            if upper < older && first < boundary {
                return Err(NotCertified::PlantChanged {
                    window,
                    beta_hat: older,
                    newest_upper: upper,
                });
            }
        }
        for f in self.fresh.iter().take(w + 1).flatten() {
            let spread = (f.sd * f.sd + sd * sd).sqrt();
            let upper = f.beta_hat + f.quantile * spread;
            if upper < beta_hat {
                return Err(NotCertified::PlantChanged { window, beta_hat, newest_upper: upper });
            }
        }
        Ok(())
    }

    /// Whether the evidence against a look (`β̂`, `s`) whose data start at column `first` is
    /// strong enough to drop its data, not only to close it: a change point after `first`
    /// (a split test that rejected), or a window's fresh estimate significantly below it at
    /// the split test's risk `α` (smaller than the held comparisons' `α_held`). The anchored
    /// window starts a new epoch on it; a held comparison alone closes its look until the
    /// next comparison, as for a window's.
    pub(crate) fn drops(&self, (beta_hat, sd): (f64, f64), first: u64) -> bool {
        let split = self.split.iter().flatten().chain(&self.changed);
        if split.into_iter().any(|&(older, upper, boundary)| upper < older && first < boundary) {
            return true;
        }
        self.fresh.iter().flatten().any(|f| {
            let spread = (f.sd * f.sd + sd * sd).sqrt();
            f.beta_hat + f.split_quantile * spread < beta_hat
        })
    }

    /// Whether a deserialised guard matches a fresh one of the same configuration.
    pub(crate) fn matches(&self, fresh: &Self) -> bool {
        self.alpha == fresh.alpha
            && self.held == fresh.held
            && self.cache.len() == fresh.cache.len()
            && self.cache.iter().enumerate().all(|(i, &(key, held, split))| {
                let nu = f64::from(key);
                (key == 0 && held == 0.0 && split == 0.0)
                    || (key as usize % CACHE == i % CACHE
                        && held.to_bits() == t_quantile(nu, self.held).to_bits()
                        && split.to_bits() == t_quantile(nu, self.alpha).to_bits())
            })
            && self.spacing == fresh.spacing
            && self.fresh.len() == fresh.fresh.len()
            && self.split.len() == fresh.split.len()
            && self
                .split
                .iter()
                .flatten()
                .chain(&self.changed)
                .all(|s| s.0.is_finite() && s.1.is_finite())
            && self.fresh.iter().flatten().all(|f| {
                f.t.is_finite()
                    && f.beta_hat.is_finite()
                    && f.sd >= 0.0
                    && f.nu.is_finite()
                    && f.quantile.to_bits() == t_quantile(f.nu.ceil(), self.held).to_bits()
                    && f.split_quantile.to_bits() == t_quantile(f.nu.ceil(), self.alpha).to_bits()
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Oracle: every estimate's quantiles equal the Student-t quantiles at `⌈ν⌉`, whether
    /// they come from the cache or not, through `ν` whose `⌈ν⌉` share a window's slot (4 and
    /// 68 on window 0, 69 and 5 on window 1) and repeat; and a guard whose cache was filled
    /// still `matches` a new one.
    #[test]
    fn cached_quantiles_equal_the_quantiles_at_the_integer_above_nu() {
        let (alpha, held) = (0.01 / 14.0, 0.01);
        let mut guard = ChangeGuard::new(&[30, 60, 120, 240], alpha, held);
        let fresh = ChangeGuard::new(&[30, 60, 120, 240], alpha, held);
        for (i, nu) in
            [3.2, 68.5, 3.9, 4.0, 68.0, 4.5, 4.5, 200.0, 0.3, 67.1, 3.2, 200.0, 3.9, 68.5]
                .into_iter()
                .enumerate()
        {
            guard.set(i % 4, Some(Fresh::new(1.0, 0.5, 0.2, nu)));
            let f = guard.fresh[i % 4].expect("a finite estimate");
            assert_eq!(f.quantile.to_bits(), t_quantile(nu.ceil(), held).to_bits(), "{nu}");
            assert_eq!(f.split_quantile.to_bits(), t_quantile(nu.ceil(), alpha).to_bits(), "{nu}");
        }
        assert!(guard.matches(&fresh));
        // A cache of another shape (a checkpoint from before the per-window slots) is refused.
        let mut other = guard.clone();
        other.cache.truncate(CACHE);
        assert!(!other.matches(&fresh));
        // A cache slot that does not hold its key's quantile is refused.
        guard.cache[5] = (69, 1.0, 1.0);
        assert!(!guard.matches(&fresh));
        // No estimate at ν <= 0.
        guard.set(0, Some(Fresh::new(1.0, 0.5, 0.2, 0.0)));
        assert!(guard.fresh[0].is_none());
    }

    /// The pace: windows 0 and 1 every `⌈B_0 / 8⌉` blocks, window `v >= 2` every `2^(v−1)`
    /// times that, so window `v − 1` is due at every block window `v` is (its split test
    /// reuses that estimate).
    #[test]
    fn a_window_is_due_only_where_the_shorter_one_is() {
        let guard = ChangeGuard::new(&[30, 60, 120, 240, 480], 0.001, 0.01);
        assert_eq!(guard.spacing, vec![4, 4, 8, 16, 32]);
        for block in 0..2000u64 {
            for v in 1..5 {
                assert!(!guard.due(v, block) || guard.due(v - 1, block), "{v} {block}");
            }
        }
        assert_eq!((0..2000u64).filter(|&b| guard.due(3, b)).count(), 125);
    }
}
