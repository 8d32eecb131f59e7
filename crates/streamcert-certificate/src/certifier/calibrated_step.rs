//! The calibrated and nonlinear certificates' part of a step: feed the newest column to the
//! calibrated state, update the two gates, and keep only what the evidence needs of the
//! standing looks.

use streamcert_regression::Interval;

use super::{Certifier, closed_reason};
use crate::{GateState, NotCertified, Verdict};

pub(super) type NonlinearStep = (GateState, Option<NotCertified>, Option<Standing>);

/// The calibrated verdict the evidence reports, with its look's window, horizon and order.
pub(super) type CalibratedStep = (Verdict, Option<usize>, Option<usize>, Option<usize>);

/// What the evidence needs of a standing look: its certificate, radius, window length and,
/// for the nonlinear certificate, region (not the whole look, which is copied otherwise).
#[derive(Clone, Copy)]
pub(super) struct Standing {
    pub(super) value: f64,
    pub(super) radius: f64,
    pub(super) window: usize,
    pub(super) region: Interval,
}

impl Certifier {
    /// Feed the newest column to the calibrated (and nonlinear) certificate, update their
    /// gates, say why closed; with a horizon ladder, feed the sample to the other rungs and
    /// combine (`ladder_step.rs`). `y`: the sample's outputs in the metric's units (the
    /// nonlinear gate stays closed while `y` lies outside the standing look's region, which
    /// is all that look speaks for), `u` its inputs.
    #[inline]
    pub(super) fn calibrated_step(
        &mut self,
        t: f64,
        y: &[f64],
        u: &[f64],
    ) -> (CalibratedStep, NonlinearStep) {
        let (gate, reason, best, nl) = self.own_calibrated_step(t, y);
        let own = Verdict {
            value: best.map(|b| b.value),
            radius: best.map(|b| b.radius),
            open: gate.open,
            reason,
        };
        let window = best.map(|b| b.window);
        if self.rungs.is_empty() {
            let (h, n) = (self.cfg.regression.horizon, self.cfg.regression.order.order());
            return ((own, window, own.value.map(|_| h), own.value.map(|_| n)), nl);
        }
        (self.ladder_step(t, y, u, (own, window)), nl)
    }

    /// [`calibrated_step`](Self::calibrated_step) at this certifier's own horizon.
    fn own_calibrated_step(
        &mut self,
        t: f64,
        y: &[f64],
    ) -> (GateState, Option<NotCertified>, Option<Standing>, NonlinearStep) {
        let Some(state) = &mut self.calibrated else {
            // Without a calibration the calibrated gates never see a certificate.
            let nl = (self.nonlinear_gate.state(), Some(NotCertified::NoNonlinearModel), None);
            return (self.calibrated_gate.state(), Some(NotCertified::NoCalibration), None, nl);
        };
        let verdict = state.update(t, &self.regression, self.cfg.margin);
        let (blocked, nonlinear_blocked) = (verdict.blocked, verdict.nonlinear_blocked);
        let best = verdict.best.as_ref().map(|b| Standing {
            value: b.certificate(),
            radius: b.radius,
            window: b.window,
            region: Interval::EMPTY,
        });
        let nonlinear = verdict.nonlinear.as_ref().map(|b| Standing {
            value: b.certificate,
            radius: b.beta_hat_min - b.certificate,
            window: b.window,
            region: b.region,
        });
        self.calibrated_window = best.map(|b| b.window);
        let cert = best.map(|b| b.value);
        let gate = self.calibrated_gate.update(t, cert);
        let reason = closed_reason(blocked, cert, &gate, &self.calibrated_gate);
        let nl = if self.cfg.nonlinear.is_some() {
            // The certificate speaks for its region only: outside it the gate sees none.
            let outside =
                nonlinear.zip(y.first()).and_then(|(b, &y)| {
                    (!(b.region.lo <= y && y <= b.region.hi)).then_some(
                        NotCertified::OutsideRegion { y, lo: b.region.lo, hi: b.region.hi },
                    )
                });
            let nonlinear_blocked = outside.or(nonlinear_blocked);
            let cert = nonlinear.map(|b| b.value).filter(|_| outside.is_none());
            let gate = self.nonlinear_gate.update(t, cert);
            (gate, closed_reason(nonlinear_blocked, cert, &gate, &self.nonlinear_gate), nonlinear)
        } else {
            (self.nonlinear_gate.state(), Some(NotCertified::NoNonlinearModel), None)
        };
        (gate, reason, best, nl)
    }
}
