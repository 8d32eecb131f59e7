//! The certifier's step at order `n`: the certificate of order `n`
//! ([`OrderNCertificate`](crate::OrderNCertificate)) in place of the paper's first-order
//! certificates, which are not computed ([`NotCertified::FirstOrderOnly`]).

use streamcert_regression::RegressionError;

use super::Certifier;
use super::closed::closed_reason;
use crate::{CertifyError, Evidence, NotCertified, OrderNCertificate, Verdict};

impl Certifier {
    /// [`push`](Self::push) at order `n`: the sample into the certificate of order `n`, its
    /// latest look through the calibrated gate (`n_s` consecutive samples), the gap detector
    /// as at the first order.
    pub(super) fn push_order_n(
        &mut self,
        t: f64,
        y: &[f64],
        u: &[f64],
    ) -> Result<Evidence, CertifyError> {
        let Some(mut cert) = self.order_n.take() else {
            return Err(CertifyError::InvalidConfig {
                field: "regression.order",
                reason: "the certificate of order n is not built".into(),
            });
        };
        let evidence = self.step_order_n(&mut cert, t, y, u);
        self.order_n = Some(cert);
        evidence
    }

    /// [`push_order_n`](Self::push_order_n) with the certificate taken out of `self`.
    fn step_order_n(
        &mut self,
        cert: &mut OrderNCertificate,
        t: f64,
        y: &[f64],
        u: &[f64],
    ) -> Result<Evidence, CertifyError> {
        let previous = cert.last_time();
        let pushed = match y {
            [y] => cert.push(t, *y, u).map(|look| look.is_some()),
            _ => Err(CertifyError::Regression(RegressionError::DimensionMismatch {
                field: "y",
                expected: 1,
                got: y.len(),
            })),
        };
        if let Err(e) = pushed {
            return self.refused(e, t);
        }
        let (_, gap) = self.step_gap(previous, t);
        if gap.is_some() {
            // A new window from this sample on; the looks keep the run's risk schedule.
            cert.reset();
            cert.push(t, y[0], u)?;
        }
        self.samples += 1;
        let (value, blocked, window) = look_value(cert);
        let columns = cert.rows();
        let horizon = cert.config().regression.horizon;
        let order = cert.config().regression.model.order();
        let state = self.calibrated_gate.update(t, value);
        let mut reason = closed_reason(blocked, value, &state, &self.calibrated_gate);
        if let Some(g) = gap {
            reason = Some(NotCertified::Gap { dt: g.dt, reference: g.reference });
        }
        self.calibrated_window = window;
        let paper = Verdict::closed(NotCertified::FirstOrderOnly);
        Ok(Evidence {
            t,
            columns,
            fit: None,
            ambiguity: None,
            gaussian: paper,
            wasserstein: paper,
            calibrated: Verdict { value, radius: None, open: state.open, reason },
            calibrated_window: window,
            calibrated_horizon: window.map(|_| horizon),
            calibrated_order: window.map(|_| order),
            nonlinear: Verdict::closed(NotCertified::NoNonlinearModel),
            nonlinear_window: None,
            nonlinear_region: None,
        })
    }
}

/// The latest look as the gate reads it: its value, why it certifies nothing, its window.
///
/// The value is the reported margin, raised to `β_margin` where the exact test certified
/// `β_margin` (the bisection's value may sit up to its tolerance below a margin the exact
/// test established; where the test did not certify, the value is below `β_margin`).
fn look_value(cert: &OrderNCertificate) -> (Option<f64>, Option<NotCertified>, Option<usize>) {
    let margin = cert.config().margin;
    match cert.latest() {
        None => {
            let needed = cert.config().regression.min_rows;
            (None, Some(NotCertified::WarmingUp { columns: cert.rows(), needed }), None)
        }
        Some(look) => match &look.outcome {
            Err(reason) => (None, Some(*reason), Some(look.rows)),
            Ok(region) if region.certified => {
                (Some(region.margin.unwrap_or(margin).max(margin)), None, Some(look.rows))
            }
            Ok(region) => {
                let value = region.margin.map(|m| m.min(margin.next_down()));
                (
                    value,
                    value.is_none().then_some(NotCertified::InsufficientExcitation),
                    Some(look.rows),
                )
            }
        },
    }
}
