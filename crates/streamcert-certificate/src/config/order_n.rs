//! The certifier's configuration at `[regression] order = 2 | 3`: what the certificate of
//! order `n` takes from it, and what it refuses.

use streamcert_regression::{LoopModel, OrderNConfig};

use super::CertifierConfig;
use crate::{CertifyError, OrderNCertificateConfig};

impl CertifierConfig {
    /// The certificate of order `n` this configuration asks for: `None` at the first order.
    ///
    /// It takes the regression's order, inputs, horizon `h` and window `M` (in rows; the
    /// first look when the window is full), its identification threshold, the gain, the
    /// margin, and from the calibration `δ`, the hidden-dynamics and nonlinearity guards and
    /// their risk (default
    /// `δ` per look). The first order's other calibration keys (its windows, instruments,
    /// anchored window) are not read.
    #[must_use]
    pub fn order_n(&self) -> Option<OrderNCertificateConfig> {
        let model = self.regression.order;
        if model.is_first_order() {
            return None;
        }
        let r = &self.regression;
        let mut regression = OrderNConfig::new(model, r.inputs, r.window, r.horizon);
        regression.min_excitation_ratio = r.min_excitation_ratio;
        let delta = self.calibration.map_or(0.01, |c| c.delta);
        let mut cfg =
            OrderNCertificateConfig::new(regression, self.gain.clone(), self.margin, delta);
        if let Some(c) = &self.calibration {
            cfg.hidden_dynamics = c.hidden_dynamics;
            cfg.nonlinearity = c.nonlinearity;
            cfg.guard_risk = c.guard_risk.unwrap_or(delta);
        }
        Some(cfg)
    }

    /// [`validate`](Self::validate) at order `n > 1`: one output, the calibrated certificate
    /// configured (its `δ`), no nonlinear certificate, no estimated couplings, no horizon
    /// ladder, no metric; then the certificate of order `n`'s own checks.
    pub(super) fn validate_order_n(&self, model: LoopModel) -> Result<(), CertifyError> {
        let n = model.order();
        let refuse = |field: &'static str, why: &str| {
            CertifyError::refuse::<()>(
                field,
                format!("is not supported at order {n}: {why} (order = 1 supports it)"),
            )
        };
        if self.regression.outputs != 1 {
            return CertifyError::refuse(
                "regression.outputs",
                format!(
                    "must be 1 at order {n}, got {}: the certificate of order n reads one output",
                    self.regression.outputs
                ),
            );
        }
        if self.calibration.is_none() {
            return CertifyError::refuse(
                "calibration",
                format!("is needed at order {n}: the certificate of order n is calibrated (its δ)"),
            );
        }
        if self.nonlinear.is_some() {
            refuse("nonlinear", "the nonlinear certificate is of the first-order model")?;
        }
        if self.couplings.is_some() {
            refuse("couplings", "estimated coupling bounds are of the first-order model")?;
        }
        if self.ladder.is_some() {
            refuse("horizon", "a horizon ladder (horizon = \"auto\") runs the first order")?;
        }
        if self.metric.is_some() {
            refuse("metric", "a metric weighs several outputs")?;
        }
        if self.consecutive == 0 {
            return CertifyError::refuse("consecutive", "n_s must be at least 1".into());
        }
        if !(self.gap_factor > 1.0 && self.gap_factor.is_finite()) {
            return CertifyError::refuse(
                "gap_factor",
                format!("must be finite and > 1, got {}", self.gap_factor),
            );
        }
        self.order_n().map_or(Ok(()), |c| c.validate())
    }
}
