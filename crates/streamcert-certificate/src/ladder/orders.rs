//! [`OrderLadder`]: the calibrated certificate at several model orders side by side, the run's
//! risk split over them (the configuration's `order = "auto"`).
//!
//! Which order a loop's one output needs is not known before its data are: a tank behind the
//! measured tank, a sensor lag or a mass read by its position each add a state the first-order
//! model does not hold (its hidden-dynamics guard then closes the gate). Trying orders until
//! one certifies spends the risk once per order tried; the order ladder spends it once, in the
//! open, by the horizon ladder's rule (the `ladder` module):
//!
//! - rung `k` is the calibrated certificate at order `n_k` (the first order's, or the
//!   certificate of order `n`, [`OrderNCertificate`](crate::OrderNCertificate)), at the
//!   regression's horizon and window, with every guard of its order at every look, at risk
//!   `δ / K` (`K` rungs);
//! - the calibrated gate is open when any rung's gate is open (each rung its own `n_s`
//!   consecutive samples), and the certificate reported is the standing rung's: among the open
//!   rungs the one with the largest certificate, else the largest certificate; a tie stands
//!   at the lower order.
//!
//! **Why the risk holds.** With one output every rung certifies the same number, the closed
//! loop's margin `−max Re λ` in 1/s (at the first order `−λ_max(sym J_cl)` is the scalar
//! `−J_cl`, its only eigenvalue). Each rung's gate opens falsely over the whole run with
//! probability at most `δ / K`, for any stopping rule; the ladder opens falsely only if some
//! rung does, so with probability at most `δ` by the union bound, whichever rung stands.
//!
//! **What it costs.** The rungs share no pass: the orders' regressors are different
//! integrals (a row of order `n` spans `n h` samples, its regressors the `n`-fold integrals of
//! its span), so the step costs about the sum of the three rungs' steps (BENCHMARKS.md), and
//! in power the smaller risk per rung (ORDER.md's cells).

use serde::{Deserialize, Serialize};
use streamcert_regression::LoopModel;

use crate::{CertifierConfig, CertifyError};

/// The calibrated certificate at several model orders, the risk split equally over them (see
/// the module docs for the rule and why its risk holds).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OrderLadder {
    /// The orders `n_k`: increasing, distinct, each `1`, `2` or `3`, the first `1` (the
    /// regression's own order, where the paper's certificates run).
    pub orders: Vec<usize>,
}

impl OrderLadder {
    /// The automatic choice's orders (`order = "auto"`): every order the certificate
    /// supports.
    pub const AUTOMATIC_ORDERS: [usize; 3] = [1, 2, 3];

    /// The automatic choice: [`AUTOMATIC_ORDERS`](Self::AUTOMATIC_ORDERS).
    #[must_use]
    pub fn automatic() -> Self {
        Self { orders: Self::AUTOMATIC_ORDERS.to_vec() }
    }

    /// Each rung's risk: `δ / K`.
    #[must_use]
    pub fn rung_delta(&self, delta: f64) -> f64 {
        delta / self.orders.len() as f64
    }

    /// Check the ladder against the rest of `cfg` (each rung's own configuration is checked
    /// by [`CertifierConfig::validate`]).
    pub(crate) fn validate(&self, cfg: &CertifierConfig) -> Result<(), CertifyError> {
        let bad = |message: String| CertifyError::refuse::<()>("regression.order", message);
        if self.orders.first() != Some(&1)
            || self.orders.windows(2).any(|w| w[0] >= w[1])
            || self.orders.iter().any(|&n| LoopModel::of_order(n).is_none())
        {
            return bad(format!(
                "an order ladder's orders must be increasing, each 1, 2 or 3, the first 1, got \
                 {:?}",
                self.orders
            ));
        }
        if !cfg.regression.order.is_first_order() {
            return bad(format!(
                "with an order ladder the regression's own order is its first rung, 1, got {}",
                cfg.regression.order.order()
            ));
        }
        if cfg.regression.outputs != 1 {
            return bad(format!(
                "order = \"auto\" needs one output, got {}: the orders above 1 read one output \
                 (order = 1 takes several)",
                cfg.regression.outputs
            ));
        }
        if cfg.calibration.is_none() {
            return bad(
                "an order ladder is the calibrated certificate's: it needs a calibration".into()
            );
        }
        if cfg.ladder.is_some() {
            return bad("order = \"auto\" and horizon = \"auto\" together would split the risk \
                        over every pair: choose a number for one of them"
                .into());
        }
        if cfg.couplings.is_some() {
            return bad(
                "a networked subsystem's coupling gains are estimated at the first order: \
                        set order = 1"
                    .into(),
            );
        }
        if cfg.metric.is_some() {
            return bad("a metric weighs several outputs, and order = \"auto\" reads one".into());
        }
        Ok(())
    }
}

impl CertifierConfig {
    /// The configuration of the order ladder's rung at order `n > 1`: this one at that order
    /// and horizon, its window (rows) this one's raised to the smallest the order's fits hold
    /// ([`OrderNCertificateConfig::smallest_window`](crate::OrderNCertificateConfig::smallest_window),
    /// `(d + n + 3)(n h + 1)` rows with every guard), with the risk in effect
    /// ([`calibration_in_effect`](Self::calibration_in_effect)), without the paper's
    /// ambiguity model, the nonlinear certificate or a ladder (those run at the first order
    /// only).
    #[must_use]
    pub fn order_rung(&self, n: usize) -> Self {
        let mut c = self.clone();
        c.regression.order = LoopModel::of_order(n).unwrap_or_default();
        c.calibration = self.calibration_in_effect();
        c.ambiguity = None;
        c.nonlinear = None;
        c.ladder = None;
        c.orders = None;
        if let Some(on) = c.order_n() {
            c.regression.window = c.regression.window.max(on.smallest_window());
        }
        c
    }
}
