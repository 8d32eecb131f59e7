//! Checkpoint and restore of a [`Certifier`]: JSON with an exact float round trip, checked
//! against its configuration on the way in.

use super::Certifier;
use crate::CertifyError;

impl Certifier {
    /// Serialise the full streaming state as JSON (floats round-trip exactly).
    ///
    /// # Errors
    /// [`CertifyError::Checkpoint`] if serialisation fails.
    pub fn checkpoint(&self) -> Result<String, CertifyError> {
        serde_json::to_string(self).map_err(|e| CertifyError::Checkpoint(e.to_string()))
    }

    /// Restore a state written by [`checkpoint`](Self::checkpoint), checking its consistency.
    ///
    /// # Errors
    /// [`CertifyError::Checkpoint`] for malformed JSON or an inconsistent state.
    pub fn restore(json: &str) -> Result<Self, CertifyError> {
        let c: Self =
            serde_json::from_str(json).map_err(|e| CertifyError::Checkpoint(e.to_string()))?;
        c.cfg.validate()?;
        c.regression.check_state().map_err(|e| CertifyError::Checkpoint(e.to_string()))?;
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
        if c.regression.config() != &c.cfg.regression
            || c.jcl.len() != p * p
            || c.work.len() != p * p
            || c.resid.len() != p
            || c.calibrated.is_some() != c.cfg.calibration.is_some()
        {
            return Err(CertifyError::Checkpoint("state does not match its configuration".into()));
        }
        if let Some(state) = &c.calibrated {
            state.check(&c.cfg.regression, &c.cfg.gain)?;
        }
        Ok(c)
    }
}
