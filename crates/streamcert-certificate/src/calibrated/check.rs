//! The check of a calibrated state read back from a checkpoint: rebuilt from its
//! configuration, every buffer must have the fresh state's shape.

use streamcert_regression::{Interval, RegressionConfig};

use super::{CalibratedState, CouplingConfig};
use crate::{CertifyError, NonlinearConfig};

impl CalibratedState {
    /// Check a deserialised state.
    pub(crate) fn check(
        &self,
        nonlinear: Option<NonlinearConfig>,
        coupling: Option<&CouplingConfig>,
        reg: &RegressionConfig,
        gain: &[f64],
    ) -> Result<(), CertifyError> {
        let fresh = Self::new(self.cal, nonlinear, coupling, reg, gain)?;
        let coupling_ok = match (&self.coupling, &fresh.coupling) {
            (Some(a), Some(b)) => a.matches(b),
            (None, None) => true,
            _ => false,
        };
        match (&self.nonlinear, &fresh.nonlinear) {
            (Some(a), Some(b)) => a.check(b)?,
            (None, None) => {}
            _ => {
                return Err(CertifyError::Checkpoint(
                    "nonlinear state does not match the configuration".into(),
                ));
            }
        }
        self.windows.check_state()?;
        let order_ok = self.model.len() == fresh.model.len()
            && self.model.iter().zip(&fresh.model).all(|(a, b)| a.matches(b));
        let change_ok = match (&self.change, &fresh.change) {
            (Some(a), Some(b)) => a.matches(b),
            (None, None) => true,
            _ => false,
        };
        let anchored_ok = match (&self.anchored, &fresh.anchored) {
            (Some(a), Some(b)) => a.matches(b, &self.windows, self.seen),
            (None, None) => true,
            _ => false,
        };
        let trail_ok =
            self.trail.as_ref().is_some_and(|t| {
                t.fits(reg, super::replay::trail_cap(&self.windows, self.horizon))
            }) && !self.rings_replayed;
        let ok = coupling_ok
            && trail_ok
            && anchored_ok
            && self.sliding_share == fresh.sliding_share
            && order_ok
            && change_ok
            && self.affine == fresh.affine
            && self.zaug.len() == fresh.zaug.len()
            && self.nl_origin.is_finite()
            && self.horizon == fresh.horizon
            && self.ridge == fresh.ridge
            && self.min_pivot == fresh.min_pivot
            && self.windows.count() == fresh.windows.count()
            && self.windows.batch() == fresh.windows.batch()
            && (0..self.windows.count()).all(|w| self.windows.window(w) == fresh.windows.window(w))
            && self.tmat == fresh.tmat
            && self.shares == fresh.shares
            && self.until_look.len() == fresh.until_look.len()
            && self.look_cols.len() == fresh.look_cols.len()
            && self.look_cols.iter().all(|&c| c <= self.seen)
            && self.looks.len() == fresh.looks.len()
            && self.latest.len() == fresh.latest.len()
            && self.weak.len() == fresh.weak.len()
            && (self.follows.is_empty() || self.follows.len() == fresh.follows.len())
            && self.weak.iter().flatten().all(|m| *m >= 0.0)
            && self.est.matches(&fresh.est)
            && self.sym.len() == fresh.sym.len()
            && self.eig_work.len() == fresh.eig_work.len()
            && self.regions.len() == fresh.regions.len()
            && self.regions.iter().all(|r| *r == Interval::EMPTY || r.is_proper())
            && self.ts.len() == fresh.ts.len()
            && self.ys.len() == fresh.ys.len()
            && self.col_range.len() == fresh.col_range.len();
        if !ok {
            return Err(CertifyError::Checkpoint(
                "calibrated state does not match its configuration".into(),
            ));
        }
        Ok(())
    }
}
