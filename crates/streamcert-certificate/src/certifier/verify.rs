//! [`Certifier::verify`]: a deserialised state checked against its configuration and against
//! itself, whatever deserialised it (a checkpoint, or serde by other means).

use super::Certifier;
use crate::CertifyError;

impl Certifier {
    /// Check a deserialised state against its configuration and against itself (the
    /// checkpoint's checks, also for a state deserialised by other means); returns it
    /// unchanged when it passes.
    ///
    /// # Errors
    /// [`CertifyError::Checkpoint`] or the configuration's error, naming the first problem.
    pub fn verify(self) -> Result<Self, CertifyError> {
        let mut c = self;
        c.cfg.validate()?;
        c.regression.check_state().map_err(|e| CertifyError::Checkpoint(e.to_string()))?;
        c.regression.check_statistics(1e-9).map_err(|e| CertifyError::Checkpoint(e.to_string()))?;
        let p = c.cfg.regression.outputs;
        if c.ambiguity.len() != if c.cfg.ambiguity.is_some() { p } else { 0 }
            || c.ambiguity
                .iter()
                .any(|a| Some(*a.config()) != c.cfg.ambiguity || !a.is_consistent())
        {
            return Err(CertifyError::Checkpoint(
                "ambiguity state does not match its configuration".into(),
            ));
        }
        let gain = c.cfg.metric_gain();
        let gain_norm =
            streamcert_regression::linalg::spectral_norm(&gain, c.cfg.regression.inputs, p);
        // At order n the first-order regression is built at the first order and not fed.
        let first_order = streamcert_regression::RegressionConfig {
            order: streamcert_regression::LoopModel::FirstOrder,
            ..c.cfg.regression
        };
        let order_n = c.cfg.order_n();
        if c.regression.config() != &first_order
            || c.jcl.len() != p * p
            || c.work.len() != p * p
            || c.resid.len() != p
            || c.eig_work.len() != streamcert_regression::linalg::eig_work_len(p)
            || c.gain_norm.to_bits() != gain_norm.to_bits()
            || c.gain != gain
            || c.scaled.len() != if c.cfg.metric.is_some() { p } else { 0 }
            || c.calibrated.is_some() != (c.cfg.calibration.is_some() && order_n.is_none())
            || c.order_n.as_ref().map(|o| o.config()) != order_n.as_ref()
            || c.order_n.as_ref().is_some_and(|o| !o.is_consistent())
            || !c.gap.is_consistent(c.cfg.gap_factor)
        {
            return Err(CertifyError::Checkpoint("state does not match its configuration".into()));
        }
        if let Some(state) = &mut c.calibrated {
            state.rebuild_rings(&c.regression)?;
            state.check(c.cfg.nonlinear, c.cfg.couplings.as_ref(), &c.cfg.regression, &gain)?;
            state.rebuild();
        }
        c.verify_rungs()?;
        Ok(c)
    }
}
