//! What a certifier shows besides its evidence: its configuration, counts and gates, the calibrated and nonlinear looks, the
//! guards' latest tests, the regions its certificates speak for, the coupling bounds and the
//! regression.

use streamcert_regression::{Interval, SlidingRegression};

use super::Certifier;
use crate::{
    CertificateKind, CertifierConfig, CouplingBound, GateState, NonlinearLook, WindowLook,
};

impl Certifier {
    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &CertifierConfig {
        &self.cfg
    }

    /// `‖K‖₂`.
    #[must_use]
    pub fn gain_norm(&self) -> f64 {
        self.gain_norm
    }

    /// Samples absorbed so far.
    #[must_use]
    pub fn samples(&self) -> u64 {
        self.samples
    }

    /// Bad samples skipped so far (policy [`BadSamplePolicy::Skip`](crate::BadSamplePolicy::Skip)).
    #[must_use]
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// The full state of one certificate's gate (streak, current and first opening).
    #[must_use]
    pub fn gate(&self, kind: CertificateKind) -> GateState {
        match kind {
            CertificateKind::Gaussian => self.gauss.state(),
            CertificateKind::Wasserstein => self.wass.state(),
            CertificateKind::Calibrated => self.calibrated_gate_state(),
            CertificateKind::Nonlinear => self.nonlinear_gate.state(),
        }
    }

    /// Gaps detected so far (see [`NotCertified::Gap`](crate::NotCertified::Gap)).
    #[must_use]
    pub fn gaps(&self) -> u64 {
        self.gap.gaps()
    }

    /// The reference sampling step: the median of the last 32 accepted steps (NaN before
    /// the second sample).
    #[must_use]
    pub fn reference_step(&self) -> f64 {
        self.gap.reference()
    }

    /// The latest look of each calibrated window, shortest window first (empty without a
    /// calibration; `None` for a window that has not looked yet or whose last look had no
    /// estimate).
    #[must_use]
    pub fn calibrated_looks(&self) -> &[Option<WindowLook>] {
        self.calibrated.as_ref().map_or(&[], |c| c.looks())
    }

    /// The anchored window's latest look in its current epoch (`None` without one: no
    /// calibration, [`anchored_share`](crate::Calibration::anchored_share) of 0, before its
    /// first look of the epoch, or a look without an estimate), and the epoch
    /// (1 from the start; one more after each gap or change point).
    #[must_use]
    pub fn anchored_look(&self) -> (Option<WindowLook>, u64) {
        self.calibrated.as_ref().map_or((None, 0), |c| (c.anchored_look(), c.anchored_epoch()))
    }

    /// The certificate of order `n`'s latest look (`None` at order 1, or before its first
    /// look): its index, the rows it fitted, the risk it spent and its region and margin.
    #[must_use]
    pub fn order_n_look(&self) -> Option<&crate::OrderNLook> {
        self.order_n.as_ref().and_then(|c| c.latest())
    }

    /// The latest nonlinear look of each window, shortest window first (empty without a
    /// nonlinear configuration).
    #[must_use]
    pub fn nonlinear_looks(&self) -> &[Option<NonlinearLook>] {
        self.calibrated.as_ref().map_or(&[], |c| c.nonlinear_looks())
    }

    /// The hidden-dynamics guard's latest test of each calibrated window (the Wald statistic
    /// of the past increment's coefficients and its threshold; `None` where it has not run
    /// or its fit was not ready); empty without the guard
    /// ([`Calibration::hidden_dynamics`](crate::Calibration::hidden_dynamics)).
    #[must_use]
    pub fn hidden_dynamics_tests(&self) -> &[Option<crate::NonlinearityTest>] {
        self.calibrated.as_ref().map_or(&[], |c| c.order_tests())
    }

    /// The nonlinearity guard's latest test of each calibrated window (the joint Wald
    /// statistic of the outputs' squares and cubes and its threshold); empty without the guard
    /// ([`Calibration::nonlinearity`](crate::Calibration::nonlinearity)).
    #[must_use]
    pub fn nonlinearity_tests(&self) -> &[Option<crate::NonlinearityTest>] {
        self.calibrated.as_ref().map_or(&[], |c| c.curvature_tests())
    }

    /// The change guard's latest fresh estimate of the shortest window, `(t, β̂_f, s_f)`
    /// ([`Calibration::plant_change`](crate::Calibration::plant_change)); `None` without the
    /// guard or before the shortest window's first fit.
    #[must_use]
    pub fn newest_estimate(&self) -> Option<(f64, f64, f64)> {
        self.calibrated.as_ref().and_then(|c| c.fresh()).map(|f| (f.t, f.beta_hat, f.sd))
    }

    /// The region of the paper's certificates: the range of each output, then each input,
    /// over the samples of the regression window (`M + h` samples; see
    /// [`SlidingRegression::ranges`]). The Gaussian and Wasserstein certificates speak for the
    /// averaged linearisation over this region, nothing more. Formed on each call (`O(p + m)`).
    pub fn region(&self) -> impl ExactSizeIterator<Item = Interval> + '_ {
        self.regression.ranges().enumerate().map(|(i, r)| self.logged_units(i, r))
    }

    /// An output range in the metric's units back in the logged units (`/ w_i`; inputs and
    /// the identity metric unchanged).
    fn logged_units(&self, i: usize, r: Interval) -> Interval {
        match self.cfg.metric.as_ref().and_then(|w| w.get(i)) {
            Some(&w) => Interval { lo: r.lo / w, hi: r.hi / w },
            None => r,
        }
    }

    /// The current upper bound on each coupling block's gain `‖C_ij‖₂`
    /// ([`CertifierConfig::couplings`](crate::CertifierConfig::couplings), in its block order; `None` for a block with no bound
    /// yet; empty without couplings). See [`CouplingConfig`](crate::CouplingConfig).
    #[must_use]
    pub fn coupling_bounds(&self) -> &[Option<CouplingBound>] {
        self.calibrated.as_ref().map_or(&[], |c| c.coupling_bounds())
    }

    /// The region of the standing calibrated certificate: the range of each output over the
    /// samples of its window at its look (empty when none stands).
    #[must_use]
    pub fn calibrated_region(&self) -> impl ExactSizeIterator<Item = Interval> + '_ {
        // With a horizon ladder, the standing rung's look (its outputs in the same units).
        let standing = self.standing_rung();
        let region = match (&standing.calibrated, standing.calibrated_window) {
            (Some(c), Some(w)) => c.region(w),
            _ => &[],
        };
        region.iter().enumerate().map(|(i, &r)| self.logged_units(i, r))
    }

    /// The underlying regression.
    #[must_use]
    pub fn regression(&self) -> &SlidingRegression {
        &self.regression
    }
}
