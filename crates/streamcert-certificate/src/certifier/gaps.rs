//! Samples that are missing or cannot be used: a sample the model refuses, the step and the
//! gap it makes, a declared gap, a skipped sample.

use super::Certifier;
use crate::gap::Gap;
use crate::{BadSamplePolicy, CertifyError, Evidence, NotCertified, Verdict};

impl Certifier {
    /// A sample the model refused: the error under [`BadSamplePolicy::Reject`], a skipped
    /// sample under [`BadSamplePolicy::Skip`].
    pub(super) fn refused(&mut self, e: CertifyError, t: f64) -> Result<Evidence, CertifyError> {
        match self.cfg.bad_samples {
            BadSamplePolicy::Reject => Err(e),
            BadSamplePolicy::Skip => Ok(self.skip(t)),
        }
    }

    /// The step from the `previous` sample's time to `t` (NaN for the first sample, which
    /// also clears a gap declared before any sample) and the gap it makes, if any.
    #[inline(always)]
    pub(super) fn step_gap(&mut self, previous: Option<f64>, t: f64) -> (f64, Option<Gap>) {
        let dt = previous.map_or(f64::NAN, |p| t - p);
        if previous.is_none() {
            self.gap.unforce();
        }
        (dt, if dt > 0.0 { self.gap.observe(dt) } else { None })
    }

    /// A gap closes every verdict this certifier computes (the Wasserstein one where an
    /// ambiguity model is, `wass`) with the gap as its reason: `reasons` are the Gaussian,
    /// Wasserstein, calibrated and nonlinear verdicts' reasons.
    pub(super) fn gap_reasons(&self, g: Gap, wass: bool, reasons: [&mut Option<NotCertified>; 4]) {
        let [gauss, wasserstein, calibrated, nonlinear] = reasons;
        let computed = [
            Some(gauss),
            wass.then_some(wasserstein),
            self.calibrated.is_some().then_some(calibrated),
            self.cfg.nonlinear.is_some().then_some(nonlinear),
        ];
        for r in computed.into_iter().flatten() {
            *r = Some(NotCertified::Gap { dt: g.dt, reference: g.reference });
        }
    }

    /// Declare that samples are missing before the next one (a live source's outage): the
    /// next [`push`](Self::push) treats its step as a gap whatever its length, as a step above
    /// `gap_factor` times the reference ([`NotCertified::Gap`]: new windows, gates closed);
    /// nothing is integrated across it. Declared twice, or before the first sample, one gap.
    ///
    /// ```
    /// use streamcert_certificate::{Certifier, CertifierConfig, NotCertified};
    /// use streamcert_regression::RegressionConfig;
    /// let cfg = CertifierConfig::new(RegressionConfig::new(1, 1, 20, 2, 1e-6), vec![-1.0], 0.1, 0.0, 3);
    /// let mut c = Certifier::new(cfg).unwrap();
    /// for k in 0..10 {
    ///     c.push(0.1 * f64::from(k), &[1.0 / f64::from(k + 1)], &[0.0]).unwrap();
    /// }
    /// c.gap();
    /// // One regular step later, but declared a gap: the windows restart here.
    /// let ev = c.push(1.0, &[0.05], &[0.0]).unwrap();
    /// assert!(matches!(ev.gaussian.reason, Some(NotCertified::Gap { .. })));
    /// assert_eq!((ev.columns, c.gaps()), (0, 1));
    /// ```
    pub fn gap(&mut self) {
        self.gap.force();
        self.rungs.iter_mut().for_each(Self::gap);
    }

    /// A sample that cannot be used (a NaN or infinite value, a time not after the previous
    /// one, the wrong number of values, or a row the caller could not parse): it is not
    /// absorbed, it is counted, and every gate closes (a stream that delivers bad samples is
    /// not evidence for deployment). This is what [`BadSamplePolicy::Skip`] does inside
    /// [`push`](Self::push), and what the command line's `--on-bad-row skip` calls. `t` is
    /// only echoed in the evidence (NaN when the caller has none).
    pub fn skip(&mut self, t: f64) -> Evidence {
        self.skipped += 1;
        let closed = Verdict::closed(NotCertified::SkippedSample);
        self.gauss.update(t, None);
        self.wass.update(t, None);
        self.calibrated_gate.update(t, None);
        self.nonlinear_gate.update(t, None);
        self.calibrated_window = None;
        self.skip_rungs(t);
        Evidence {
            t,
            columns: self.regression.columns(),
            fit: None,
            ambiguity: self.ambiguity_snapshot(),
            gaussian: closed,
            wasserstein: closed,
            calibrated: closed,
            calibrated_window: None,
            calibrated_horizon: None,
            calibrated_order: None,
            nonlinear: closed,
            nonlinear_window: None,
            nonlinear_region: None,
        }
    }
}
