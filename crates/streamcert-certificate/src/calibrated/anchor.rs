//! The calibrated certificate's anchored window: every block since its epoch began, looked at
//! sizes growing by `g`, at the risk of [`anchored_look_risk`]; what closes it and starts a new
//! epoch.

use serde::{Deserialize, Serialize};
use streamcert_regression::{
    AnchoredWindow, InstrumentedWindows, Interval, RateMap, RegressionError, Solve,
};

use super::{CalibratedState, WindowLook, anchored_look_risk};
use crate::Calibration;

/// Records of the anchored window (`AnchoredWindow`): between 128 and 255 records once it
/// has merged, and its memory bounded (about 43 kB for one output, one input and the
/// intercept). Its `ν` is the effective number of records less `d`, about 0.4 of the records
/// under VALIDITY.md's dither (55 to 95), so its Student-t quantile is 4 to 8 % above the
/// normal one at the risks its looks spend; 512 records certified the loop at 5× the margin in
/// one run more of 100 (`--only-power 200` at an earlier commit), at twice the memory.
pub(crate) const ANCHORED_RECORDS: usize = 256;

/// The anchored window's state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct AnchoredState {
    pub(super) window: AnchoredWindow,
    /// The epoch (1 from the start; one more at every restart).
    pub(super) epoch: u64,
    /// Looks taken in this epoch.
    pub(super) looks: u64,
    /// Blocks since the epoch began at the next look.
    pub(super) next: u64,
    /// The calibrated state's column count (`seen`) when the epoch began.
    pub(super) start: u64,
    /// The latest look of this epoch.
    pub(super) latest: Option<WindowLook>,
    /// Its region (output ranges).
    pub(super) region: Vec<Interval>,
}

impl AnchoredState {
    /// The anchored window over `windows`' blocks (`h` columns each), `p` outputs.
    pub(super) fn new(
        windows: &InstrumentedWindows,
        cal: &Calibration,
        p: usize,
        horizon: usize,
    ) -> Result<Self, RegressionError> {
        Ok(Self {
            window: AnchoredWindow::new(windows, ANCHORED_RECORDS)?,
            epoch: 1,
            looks: 0,
            next: cal.anchored_size(windows.window(0) / horizon, 1),
            start: 0,
            latest: None,
            region: vec![Interval::EMPTY; p],
        })
    }

    /// Whether a deserialised state has the shape of `fresh` (built from the same
    /// configuration) over `windows`, with `seen` columns absorbed.
    pub(super) fn matches(&self, fresh: &Self, windows: &InstrumentedWindows, seen: u64) -> bool {
        self.window.check_state(windows, ANCHORED_RECORDS).is_ok()
            && self.epoch >= 1
            && self.start <= seen
            && self.next > self.window.blocks()
            && self.region.len() == fresh.region.len()
            && self.region.iter().all(|r| *r == Interval::EMPTY || r.is_proper())
            && self.latest.is_none_or(|l| l.anchored && l.look == self.looks)
    }

    /// Start a new epoch at column `seen`: forget every block and the latest look.
    pub(super) fn restart(&mut self, cal: &Calibration, base: usize, seen: u64) {
        self.window.reset();
        self.epoch += 1;
        self.looks = 0;
        self.next = cal.anchored_size(base, 1);
        self.start = seen;
        self.latest = None;
        self.region.fill(Interval::EMPTY);
    }
}

impl CalibratedState {
    /// The shortest window's blocks, `B_0`.
    pub(super) fn base_blocks(&self) -> usize {
        self.windows.window(0) / self.horizon
    }

    /// Feed the windows' newest block to the anchored window and look when it holds the next
    /// look's size: `true` when it looked.
    pub(super) fn anchored_block(&mut self, t: f64, margin: f64) -> bool {
        let base = self.base_blocks();
        let (cap, horizon) = (self.cal.max_window, self.horizon as u64);
        let Some(a) = &mut self.anchored else { return false };
        // Past `max_window` the anchored window holds data no window may: its look is dropped
        // (once) and it takes no more blocks until its epoch restarts.
        if cap.is_some_and(|c| (a.window.blocks() + 1) * horizon > c as u64) {
            return a.latest.take().is_some();
        }
        a.window.push_newest(&self.windows);
        if a.window.blocks() < a.next {
            return false;
        }
        a.looks += 1;
        let (epoch, look) = (a.epoch, a.looks);
        a.next = self.cal.anchored_size(base, look + 1);
        let p = self.sym.len().isqrt();
        let d = self.tmat.len() / p;
        // The second covariance where about `auto_batches` batches of at least two records
        // fit, as for a sliding window of as many blocks.
        let records = a.window.records();
        let b = self.cal.auto_batch_blocks(records, d);
        let auto = self.cal.batch_blocks == 1 && b >= 2;
        let solve = Solve {
            ridge: self.ridge,
            rate: RateMap::SymmetricPart(&self.tmat),
            min_pivot_ratio: self.min_pivot,
        };
        if auto {
            a.window.estimate_batched(b, solve, &mut self.est);
        } else {
            a.window.estimate(solve, &mut self.est);
        }
        let columns = a.window.columns();
        let batched = if auto { self.batched_rate() } else { None };
        let risk = anchored_look_risk(
            self.cal.delta,
            self.cal.anchored_share,
            epoch,
            look,
            self.cal.anchored_looks as u64,
        );
        let look_at = super::look::Bound { risk, margin, auto };
        let latest = self.rate_of_estimate().and_then(|(beta_hat, variance, nu)| {
            self.bound(&look_at, (beta_hat, variance, nu), batched).map(|b| WindowLook {
                window: columns,
                look,
                t,
                beta_hat,
                radius: b.radius,
                sd: b.sd,
                nu: b.nu,
                upper: b.upper,
                anchored: true,
            })
        });
        if let Some(a) = &mut self.anchored {
            a.latest = latest;
            if latest.is_some() {
                a.window.range(&mut a.region);
            }
        }
        true
    }

    /// Whether the evidence against the anchored window's latest look is strong enough to
    /// drop its data and start a new epoch: the change guard's change point after the epoch
    /// began, or a fresh estimate below it at the split test's risk
    /// ([`ChangeGuard::drops`](crate::guard::ChangeGuard)). Weaker evidence only closes the
    /// look, as for a window's: a held comparison at the change guard's larger risk until the
    /// next comparison, and a newer look whose one-look upper bound is below the margin while
    /// it is the newer (the shortest window's just-identified estimate sits four of its
    /// spreads below a 5× loop's rate in about one run in ten: restarting on it dropped the
    /// data of 26 of 300 such runs).
    pub(super) fn anchored_contradicted(&self) -> bool {
        let Some(look) = self.anchored.as_ref().and_then(|a| a.latest) else { return false };
        let start = self.anchored.as_ref().map_or(0, |a| a.start);
        self.change.as_ref().is_some_and(|c| c.drops((look.beta_hat, look.sd), start))
    }
}
