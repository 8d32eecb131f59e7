//! What the calibrated state tells the certifier: the latest looks, regions, tests, fresh
//! estimates and coupling bounds.

use streamcert_regression::Interval;

use super::{CalibratedState, CouplingBound, WindowLook};
use crate::guard::{ChangeGuard, Fresh, ModelGuard};
use crate::nonlinear::NonlinearLook;

impl CalibratedState {
    /// The latest nonlinear look of each window (empty without a nonlinear configuration).
    pub(crate) fn nonlinear_looks(&self) -> &[Option<NonlinearLook>] {
        self.nonlinear.as_ref().map_or(&[], |n| n.looks())
    }

    /// The calibration the state runs at (with a horizon ladder, at the rung's risk).
    pub(crate) fn calibration(&self) -> super::Calibration {
        self.cal
    }

    /// The region (output ranges) of the standing look's data: the anchored window's when
    /// it stands, else that of window length `window`'s latest look.
    pub(crate) fn region(&self, window: usize) -> &[Interval] {
        let anchored = self.verdict.and_then(|v| v.best).is_some_and(|b| b.anchored);
        if let Some(a) = self.anchored.as_ref().filter(|_| anchored) {
            return &a.region;
        }
        let p = self.col_range.len();
        (0..self.windows.count())
            .find(|&w| self.windows.window(w) == window)
            .map_or(&[], |w| &self.regions[w * p..(w + 1) * p])
    }

    /// The hidden-dynamics guard's latest test per window (empty without the guard).
    pub(crate) fn order_tests(&self) -> &[Option<crate::NonlinearityTest>] {
        self.model.iter().map(ModelGuard::tests).find(|t| !t.is_empty()).unwrap_or(&[])
    }

    /// The nonlinearity guard's latest test per window (empty without the guard).
    pub(crate) fn curvature_tests(&self) -> &[Option<crate::NonlinearityTest>] {
        self.model.iter().map(ModelGuard::curvature_tests).find(|t| !t.is_empty()).unwrap_or(&[])
    }

    /// The change guard's latest fresh estimate (`None` without the guard or before one).
    pub(crate) fn fresh(&self) -> Option<Fresh> {
        self.change.as_ref().and_then(ChangeGuard::fresh)
    }

    /// The latest look of each window.
    pub(crate) fn looks(&self) -> &[Option<WindowLook>] {
        &self.latest
    }

    /// The anchored window's latest look (`None` without one, or before its first look of
    /// the epoch).
    pub(crate) fn anchored_look(&self) -> Option<WindowLook> {
        self.anchored.as_ref().and_then(|a| a.latest)
    }

    /// The anchored window's epoch (0 without one).
    pub(crate) fn anchored_epoch(&self) -> u64 {
        self.anchored.as_ref().map_or(0, |a| a.epoch)
    }

    /// The current coupling bound per block (empty without a coupling configuration).
    pub(crate) fn coupling_bounds(&self) -> &[Option<CouplingBound>] {
        self.coupling.as_ref().map_or(&[], |c| c.bounds())
    }
}
