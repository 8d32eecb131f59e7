//! A ladder's step ([`HorizonLadder`](crate::HorizonLadder) or
//! [`OrderLadder`](crate::OrderLadder)): every other rung fed the same sample, the calibrated
//! verdict open when any rung's gate is, the standing rung's certificate reported (see the
//! `ladder` module for the rule and why its risk holds).

use super::Certifier;
use super::calibrated_step::CalibratedStep;
use crate::{CertifierConfig, CertifyError, GateState, NotCertified, Verdict};

/// The ladder's rungs other than this certifier's own (its horizon, or the first order), each
/// a certifier of the calibrated certificate only (empty without a ladder).
pub(super) fn rungs(cfg: &CertifierConfig) -> Result<Vec<Certifier>, CertifyError> {
    let own = cfg.regression.horizon;
    let configs: Vec<CertifierConfig> = match (&cfg.ladder, &cfg.orders) {
        (Some(l), _) => l.horizons.iter().filter(|&&h| h != own).map(|&h| cfg.rung(h)).collect(),
        (None, Some(o)) => {
            o.orders.iter().filter(|&&n| n > 1).map(|&n| cfg.order_rung(n)).collect()
        }
        (None, None) => Vec::new(),
    };
    configs
        .into_iter()
        .map(|c| {
            let mut c = Certifier::new(c)?;
            c.calibrated_only = true;
            Ok(c)
        })
        .collect()
}

/// How many rungs the ladder has, this certifier's own among them (0 without a ladder).
fn rung_count(cfg: &CertifierConfig) -> usize {
    match (&cfg.ladder, &cfg.orders) {
        (Some(l), _) => l.horizons.len(),
        (None, Some(o)) => o.orders.len(),
        (None, None) => 0,
    }
}

/// One closed verdict per rung (empty without a ladder).
pub(super) fn verdicts(cfg: &CertifierConfig) -> Vec<Verdict> {
    vec![Verdict::closed(NotCertified::WarmingUp { columns: 0, needed: 0 }); rung_count(cfg)]
}

/// Whether verdict `a` stands before `b`: an open gate before a closed one, then the larger
/// certificate (none is the smallest).
fn stands_before(a: &Verdict, b: &Verdict) -> bool {
    match (a.open, b.open) {
        (true, false) => true,
        (false, true) => false,
        _ => match (a.value, b.value) {
            (Some(x), Some(y)) => x > y,
            (Some(_), None) => true,
            _ => false,
        },
    }
}

/// One rung of a ladder, as [`Certifier::rungs_status`] reports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RungStatus {
    /// The rung's model order `n` (1 on every rung of a horizon ladder).
    pub order: usize,
    /// The rung's horizon `h` (samples per column).
    pub horizon: usize,
    /// The rung's base window `M` (columns).
    pub window: usize,
    /// The rung's latest calibrated verdict (its own gate, at risk `δ / K`).
    pub verdict: Verdict,
}

impl Certifier {
    /// With a ladder (the caller checks that there are rungs), feed the sample to the other
    /// rungs and combine: `own` is this certifier's calibrated verdict and window. Returns the
    /// calibrated verdict, window, horizon and order the evidence reports. No allocation.
    pub(super) fn ladder_step(
        &mut self,
        t: f64,
        y: &[f64],
        u: &[f64],
        own: (Verdict, Option<usize>),
    ) -> CalibratedStep {
        let own_horizon = own.0.value.map(|_| self.cfg.regression.horizon);
        let own_order = own.0.value.map(|_| self.cfg.regression.order.order());
        let at = self.own_slot();
        self.rung_verdicts[at] = own.0;
        let mut best = (own.0, own.1, own_horizon, own_order);
        // With an order ladder and no certificate at any order: the highest order past its
        // warm-up says why (its model is the widest tried).
        let mut highest = None;
        self.standing = None;
        for (i, rung) in self.rungs.iter_mut().enumerate() {
            // The rungs validate the sample as this certifier did; a rung that refuses it
            // anyway (an overflow in its own sums) closes its gate for this sample.
            let ev = rung.push_scaled(t, y, u).unwrap_or_else(|_| rung.skip(t));
            self.rung_verdicts[i + usize::from(i >= at)] = ev.calibrated;
            let step =
                (ev.calibrated, ev.calibrated_window, ev.calibrated_horizon, ev.calibrated_order);
            if stands_before(&ev.calibrated, &best.0) {
                best = step;
                self.standing = Some(i);
            }
            if !matches!(ev.calibrated.reason, Some(NotCertified::WarmingUp { .. })) {
                highest = Some(step);
            }
        }
        match highest {
            Some(h) if self.cfg.orders.is_some() && best.0.value.is_none() && !best.0.open => h,
            _ => best,
        }
    }

    /// This certifier's slot among the ladder's rungs (an order ladder's first order is its
    /// first rung).
    fn own_slot(&self) -> usize {
        let h = self.cfg.regression.horizon;
        self.cfg.ladder.as_ref().map_or(0, |l| l.horizons.iter().take_while(|&&k| k < h).count())
    }

    /// A skipped sample closes every rung's gate too.
    pub(super) fn skip_rungs(&mut self, t: f64) {
        let at = self.own_slot();
        if let Some(v) = self.rung_verdicts.get_mut(at) {
            *v = Verdict::closed(NotCertified::SkippedSample);
        }
        for (i, rung) in self.rungs.iter_mut().enumerate() {
            self.rung_verdicts[i + usize::from(i >= at)] = rung.skip(t).calibrated;
        }
        self.standing = None;
    }

    /// With a [`HorizonLadder`](crate::HorizonLadder) or an
    /// [`OrderLadder`](crate::OrderLadder), each rung's order, horizon, base window and latest
    /// calibrated verdict, in the ladder's order; empty without one.
    pub fn rungs_status(&self) -> impl ExactSizeIterator<Item = RungStatus> + '_ {
        let at = self.own_slot();
        self.rung_verdicts.iter().enumerate().map(move |(slot, &verdict)| {
            let c = match slot.cmp(&at) {
                std::cmp::Ordering::Less => &self.rungs[slot],
                std::cmp::Ordering::Equal => self,
                std::cmp::Ordering::Greater => &self.rungs[slot - 1],
            };
            let r = &c.cfg.regression;
            RungStatus { order: r.order.order(), horizon: r.horizon, window: r.window, verdict }
        })
    }

    /// The calibrated gate's state: with a ladder, open while any rung's is, the longest
    /// streak, the earliest current and first openings over the rungs.
    pub(super) fn calibrated_gate_state(&self) -> GateState {
        let mut s = self.calibrated_gate.state();
        for r in &self.rungs {
            let g = r.calibrated_gate.state();
            let earliest = |a: Option<f64>, b: Option<f64>| match (a, b) {
                (Some(x), Some(y)) => Some(x.min(y)),
                (x, y) => x.or(y),
            };
            s = GateState {
                open: s.open || g.open,
                streak: s.streak.max(g.streak),
                opened_at: earliest(s.opened_at, g.opened_at),
                first_opened_at: earliest(s.first_opened_at, g.first_opened_at),
            };
        }
        s
    }

    /// The certifier whose calibrated look stands: a rung, or this one.
    pub(super) fn standing_rung(&self) -> &Self {
        self.standing.and_then(|i| self.rungs.get(i)).unwrap_or(self)
    }

    /// A deserialised ladder checked against its configuration: the rungs' configurations,
    /// flags and count, each rung verified ([`Certifier::verify`]).
    pub(super) fn verify_rungs(&mut self) -> Result<(), CertifyError> {
        let bad = |m: &str| Err(CertifyError::Checkpoint(m.into()));
        let fresh = rungs(&self.cfg)?;
        if fresh.len() != self.rungs.len()
            || self.rung_verdicts.len() != verdicts(&self.cfg).len()
            || self.standing.is_some_and(|i| i >= self.rungs.len())
            || self.calibrated.as_ref().map(|c| c.calibration())
                != self.cfg.calibration_in_effect().filter(|_| self.order_n.is_none())
        {
            return bad("the ladder does not match its configuration");
        }
        let rungs = std::mem::take(&mut self.rungs);
        for (r, f) in rungs.into_iter().zip(&fresh) {
            if r.cfg != f.cfg || !r.calibrated_only || !r.rungs.is_empty() {
                return bad("a rung of the ladder does not match its configuration");
            }
            self.rungs.push(r.verify()?);
        }
        Ok(())
    }
}
