//! [`Calibration::validate`]: the calibrated certificate's settings checked against the
//! regression and the margin, each refusal saying what would be valid.

use streamcert_regression::RegressionConfig;

use super::Calibration;
use crate::CertifyError;

impl Calibration {
    /// Check the settings against the regression and the margin.
    ///
    /// # Errors
    /// [`CertifyError::InvalidConfig`] with what would be valid.
    pub fn validate(&self, reg: &RegressionConfig, margin: f64) -> Result<(), CertifyError> {
        self.check_risks(margin)?;
        self.check_shape()?;
        self.check_window(reg)
    }

    /// The risks, the margin and the ridge.
    fn check_risks(&self, margin: f64) -> Result<(), CertifyError> {
        if !(self.delta > 0.0 && self.delta < 1.0) {
            return CertifyError::refuse(
                "calibration.delta",
                format!("must lie in (0, 1), got {}", self.delta),
            );
        }
        if !(margin > 0.0) {
            return CertifyError::refuse(
                "margin",
                format!(
                    "must be > 0 for the calibrated certificate, got {margin}: a certified rate \
                     at or below 0 does not mean the loop contracts (use a small positive margin, \
                     for example 0.05)"
                ),
            );
        }
        if !(0.0..=1e-3).contains(&self.relative_ridge) {
            return CertifyError::refuse(
                "calibration.relative_ridge",
                format!("must lie in [0, 1e-3], got {}", self.relative_ridge),
            );
        }
        if let Some(r) = self.change_risk
            && !(r > 0.0 && r < 1.0)
        {
            return CertifyError::refuse(
                "calibration.change_risk",
                format!("must lie in (0, 1), got {r}"),
            );
        }
        if let Some(r) = self.guard_risk
            && !(r > 0.0 && r < 1.0)
        {
            return CertifyError::refuse(
                "calibration.guard_risk",
                format!("must lie in (0, 1), got {r}"),
            );
        }
        if !(self.auto_batch_risk > 0.0 && self.auto_batch_risk < 1.0) {
            return CertifyError::refuse(
                "calibration.auto_batch_risk",
                format!("must lie in (0, 1), got {}", self.auto_batch_risk),
            );
        }
        Ok(())
    }

    /// The windows' count, the anchored window's rule, the looks' spacing and the batches.
    fn check_shape(&self) -> Result<(), CertifyError> {
        if let Some(n) = self.windows
            && !(1..=16).contains(&n)
        {
            return CertifyError::refuse(
                "calibration.windows",
                format!("must lie in 1..=16, got {n}"),
            );
        }
        if !(0.0..1.0).contains(&self.anchored_share) {
            return CertifyError::refuse(
                "calibration.anchored_share",
                format!(
                    "must lie in [0, 1) (0 turns the anchored window off), got {}",
                    self.anchored_share
                ),
            );
        }
        if !(self.anchored_growth > 1.0 && self.anchored_growth <= 4.0) {
            return CertifyError::refuse(
                "calibration.anchored_growth",
                format!("must lie in (1, 4], got {}", self.anchored_growth),
            );
        }
        if !(1..=64).contains(&self.anchored_looks) {
            return CertifyError::refuse(
                "calibration.anchored_looks",
                format!("must lie in 1..=64, got {}", self.anchored_looks),
            );
        }
        if !(self.look_spacing > 0.0 && self.look_spacing <= 1.0) {
            return CertifyError::refuse(
                "calibration.look_spacing",
                format!("must lie in (0, 1], got {}", self.look_spacing),
            );
        }
        if !(1..=8).contains(&self.instrument_intervals) {
            return CertifyError::refuse(
                "calibration.instrument_intervals",
                format!("must lie in 1..=8, got {}", self.instrument_intervals),
            );
        }
        if !(1..=8).contains(&self.batch_blocks) {
            return CertifyError::refuse(
                "calibration.batch_blocks",
                format!(
                    "must lie in 1..=8 (the settings `cargo xtask validity` measures reach 8), \
                     got {}",
                    self.batch_blocks
                ),
            );
        }
        if !(self.auto_batches == 0 || self.auto_batches >= 8) {
            return CertifyError::refuse(
                "calibration.auto_batches",
                format!(
                    "must be 0 (off) or at least 8 (on fewer batches the Student-t quantile \
                     outweighs any spread it saves), got {}",
                    self.auto_batches
                ),
            );
        }
        Ok(())
    }

    /// The smallest window (columns) [`check_window`](Self::check_window) accepts for `reg`'s
    /// dimensions and horizon: `h · (unknowns + 2)` with the guards' extra regressors, or the
    /// batched fit's `h · (b (unknowns + 1) + 1)` where that is larger.
    pub(crate) fn smallest_valid_window(&self, reg: &RegressionConfig) -> usize {
        let d = reg.outputs
            + reg.inputs
            + usize::from(reg.model == streamcert_regression::Model::Affine);
        let min = self.smallest_window(reg.horizon, d);
        let guarded = Self::min_window(reg.horizon, d + self.guard_unknowns(reg.outputs));
        min.max(guarded)
    }

    /// The window against the fits it must hold.
    fn check_window(&self, reg: &RegressionConfig) -> Result<(), CertifyError> {
        // The affine model's intercept is one more unknown; the model guard's larger fit has
        // its extra regressors (in batches of one block: see `guard_unknowns`).
        let d = reg.outputs
            + reg.inputs
            + usize::from(reg.model == streamcert_regression::Model::Affine);
        let g = self.guard_unknowns(reg.outputs);
        let min = self.smallest_window(reg.horizon, d);
        let guarded = Self::min_window(reg.horizon, d + g);
        let counted = "p + m, + 1 for the affine model's intercept";
        if reg.window < guarded && guarded >= min {
            return CertifyError::refuse(
                "window",
                format!(
                    "M = {} is too short for a calibrated bound with its guards with h = {}: \
                     the guards' larger fits have up to {} unknowns per output ({counted}, + p \
                     for the hidden-dynamics guard or + 2p for the nonlinearity guard), so the \
                     smallest valid window is {guarded} columns (h · (unknowns + 2)); without \
                     the guards it would be {min}",
                    reg.window,
                    reg.horizon,
                    d + g
                ),
            );
        }
        if reg.window < min && self.batch_blocks == 1 {
            return CertifyError::refuse(
                "window",
                format!(
                    "M = {} is too short for a calibrated bound with h = {} and {d} unknowns \
                     per output ({counted}): the smallest valid window is {min} columns \
                     (h · (unknowns + 2))",
                    reg.window, reg.horizon
                ),
            );
        }
        if reg.window < min {
            return CertifyError::refuse(
                "window",
                format!(
                    "M = {} is too short for a calibrated bound with h = {}, {d} unknowns per \
                     output ({counted}) and batches of b = {} blocks: the smallest valid window \
                     is {min} columns (h · (b (unknowns + 1) + 1)), or use fewer blocks per \
                     batch",
                    reg.window, reg.horizon, self.batch_blocks
                ),
            );
        }
        if let Some(cap) = self.max_window
            && cap < reg.window
        {
            return CertifyError::refuse(
                "calibration.max_window",
                format!("must be at least the window M = {}, got {cap}", reg.window),
            );
        }
        Ok(())
    }
}
