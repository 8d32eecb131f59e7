//! The model guard: does the window's data need more than the linear first-order model
//! `ΔY_q ≈ Θ Z_q (+ c τ_q)` holds? One larger fit on the same columns, windows and looks as
//! the calibrated certificate, with up to two groups of extra regressors, each tested by its
//! own Wald statistic:
//!
//! ```text
//! ΔY_q ≈ Θ Z_q (+ c τ_q) + Φ ΔY_{q−h} + Σ_i (a_i ∫(y_i − o_i)² + b_i ∫(y_i − o_i)³)
//! ```
//!
//! * **Hidden dynamics (model order, [`Calibration::hidden_dynamics`]).** A sensor sees one
//!   coordinate of a plant with many states (the paper's `p ≪ n`). When the output carries a
//!   hidden state (a mass measured by its position, a tank behind a tank), its increment over
//!   a column depends on that state at the column's start, which the model has no term for.
//!   The extra regressor is the output's increment over the `h` samples before the column (a
//!   proxy for the hidden state's effect at the column's start). Under a first-order plant
//!   with white noise `Φ = 0`: `ΔY_{q−h}` ends where column `q`'s noise begins. Tested:
//!   the `q = p²` entries of `Φ̂`.
//! * **Nonlinearity ([`Calibration::nonlinearity`]).** The calibrated certificate assumes
//!   one Jacobian over its window; a drift whose slope varies over the explored region is
//!   certified on its average. The extra regressors are the integrals over the column of the
//!   square and the cube of each output's excursion from the regression's working origin
//!   `o` (the first sample); under linear dynamics their coefficients are zero. Tested: the
//!   `q = 2p²` coefficients `a_i, b_i` of every output's equation, jointly (per output
//!   squares and cubes: a state dependence through cross products `y_i y_j` only is not
//!   seen). With the affine model the test does not depend on `o` (the square and cube of
//!   `y − o` span the same functions as those of `y` with the intercept and `y`).
//!
//! Every regressor is instrumented as the windows' are (by the regressors of the intervals
//! before the column). Each Wald statistic,
//!
//! ```text
//! W = vec(Φ̂_S)ᵀ Ω̂_SS⁻¹ vec(Φ̂_S)   against   ν q/(ν − q + 1) · F_{q, ν−q+1}(1 − α)
//! ```
//!
//! (Hotelling's quantile, `Ω̂` the batch-means coefficient covariance of the larger fit, by
//! default from each block's first-order influence with `B/(B − d)`, or its delete-one-block
//! change, [`Calibration::guard_variance`](crate::Calibration::guard_variance); `ν`
//! its effective number of batches less its unknowns per output, `α` the guard's risk per
//! test, [`Calibration::guard_risk`](crate::Calibration::guard_risk), by default `δ/W` per
//! look of each of the `W` windows), rejects at risk about `α` when the linear
//! first-order model holds. Where a window's latest test rejects, neither that window's look
//! nor any shorter window's stands (`NotCertified::HiddenDynamics`,
//! `NotCertified::VaryingDynamics`: a shorter window's data are the newest part of the
//! longer one's, and the longer windows' tests have the power); a longer window is judged by
//! its own test and the still longer ones' (on linear loops the shortest window's curvature
//! test, on few batches, rejects far above its nominal risk; letting it close every window
//! kept a network of 10⁴ subsystems closed at every epoch, NETWORK.md at ab02361);
//! where a window's tests could not run (the larger fit not ready), that window's look does
//! not stand (`NotCertified::OrderUntested`, `NotCertified::LinearityUntested`): the
//! certificate's model is then unchecked. The larger fit has `p` (order) and `2p`
//! (nonlinearity) more unknowns per output, so the smallest window the calibrated
//! certificate accepts grows with them
//! ([`Calibration::smallest_window`](crate::Calibration::smallest_window)). The nonlinear
//! certificate is not gated by this guard: a larger fit of its own holds the library and the
//! past increment (`nonlinear::check`), since on a nonlinear loop the linear model's misfit
//! reads as a past-increment term.
//!
//! **What it sees**: dynamics whose effect on the next `h` samples is carried by the past
//! increment (second-order and lightly damped outputs, an integrator behind a lag, a measured
//! output of a chain), and a drift whose slope varies with the output over the window
//! (quadratic and cubic components of it). **What it cannot see**: hidden states that the
//! increment over `h` samples does not reflect (much faster than `h` samples: then the
//! first-order model is a fair reduction; much slower than the window: their effect looks like
//! an operating point, which the intercept absorbs), dynamics the dither does not excite,
//! state dependence orthogonal to squares and cubes of each output (cross products only), and
//! an effect smaller than the test's resolution at the window's length. Closing never costs
//! validity; a false closing costs power (measured in the tests and VALIDITY.md).
//!
//! `O(k d' + k²)` per column (`d'` the larger fit's regressors, `k` its instruments), no
//! allocation; a test per look `O(B (d' k + q k + k²) + q³)` for one output with the
//! first-order covariance, whose blocks form their influence on the `q` tested coefficients
//! only (with more outputs or the jackknife, the whole covariance: `O(B p² d'²)` more). The curvature regressors are kept per sample
//! interval, so a column adds its newest interval's (`curvature.rs`). On the default
//! `p = m = 1` step the two guards cost about 280 ns per sample together, of which about 23
//! and 32 ns push their columns (BENCHMARKS.md).
//!
//! [`Calibration::hidden_dynamics`]: crate::Calibration::hidden_dynamics
//! [`Calibration::nonlinearity`]: crate::Calibration::nonlinearity

use serde::{Deserialize, Serialize};

use streamcert_regression::{InstrumentedWindows, SlidingRegression};

use super::curvature::CurvatureTerms;
use crate::look::guard_variance::GuardVariance;
use crate::look::hotelling::NonlinearityTest;
use crate::look::larger::LargerFit;
use crate::{CertifyError, NotCertified};

/// Which groups of extra regressors the guard fits and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct Groups {
    /// The past increment `ΔY_{q−h}` (`p` regressors): hidden dynamics, the first-order
    /// model's test of itself
    /// ([`HiddenDynamicsTest::PastIncrement`](streamcert_regression::HiddenDynamicsTest::PastIncrement)).
    pub order: bool,
    /// `∫(y_i − o_i)²`, `∫(y_i − o_i)³` per output (`2p` regressors): nonlinearity.
    pub curvature: bool,
}

impl Groups {
    /// Extra regressors for `p` outputs.
    #[must_use]
    pub(crate) fn extra(self, p: usize) -> usize {
        p * (usize::from(self.order) + 2 * usize::from(self.curvature))
    }
}

/// The guard's state: its own windows of the larger fit, the ring of the last `h` columns'
/// increments, the latest tests per window, and scratch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct ModelGuard {
    /// Outputs `p` and the linear windows' regressors `d` (the extras follow them: the past
    /// increments, then the squares and cubes output by output).
    p: usize,
    d: usize,
    horizon: usize,
    groups: Groups,
    /// The risk `α` of each test.
    alpha: f64,
    /// The larger fit (its fields inline in a checkpoint).
    #[serde(flatten)]
    fit: LargerFit,
    /// The latest order test of each window (`None`: not run, or its fit not ready).
    latest: Vec<Option<NonlinearityTest>>,
    /// The latest nonlinearity test of each window.
    curvature: Vec<Option<NonlinearityTest>>,
    /// The covariance of the tests ([`Calibration::guard_variance`](crate::Calibration::guard_variance)).
    #[serde(default)]
    variance: GuardVariance,
    /// The curvature regressors' per-interval terms (a cache: not in a checkpoint, sized by
    /// [`restore_scratch`](Self::restore_scratch)).
    #[serde(skip)]
    terms: CurvatureTerms,
}

impl ModelGuard {
    /// The guard for `p` outputs on windows of `d` regressors, `lengths`, with the extra
    /// regressors of `groups`, at risk `alpha` per test; `batch` blocks per batch as the
    /// linear windows.
    pub(crate) fn new(
        (p, d, horizon): (usize, usize, usize),
        groups: Groups,
        (lag, intervals, batch): (usize, usize, usize),
        lengths: &[usize],
        alpha: f64,
    ) -> Result<Self, CertifyError> {
        let dd = d + groups.extra(p);
        // The tested coefficients' direction (ones) in standardised coefficients: the weights
        // behind `ν` are then the same in any units of the outputs. A test takes at most the
        // `2p` curvature terms of every output.
        let shape = (lag, intervals, batch);
        let fit = LargerFit::new((p, dd, horizon), shape, lengths, groups.order, 2 * p * p)?
            .standardised();
        Ok(Self {
            p,
            d,
            horizon,
            groups,
            alpha,
            fit,
            latest: vec![None; lengths.len()],
            curvature: vec![None; lengths.len()],
            variance: GuardVariance::FirstOrder,
            terms: if groups.curvature {
                CurvatureTerms::new(p, horizon)
            } else {
                CurvatureTerms::default()
            },
        })
    }

    /// This guard with its tests on the covariance `variance`.
    pub(crate) fn with_variance(mut self, variance: GuardVariance) -> Self {
        self.variance = variance;
        self
    }

    /// Size the scratch a checkpoint does not carry (its fit's batched covariance), as a
    /// fresh guard's, after a restore.
    pub(crate) fn restore_scratch(&mut self) {
        let pp = self.p * self.p;
        self.fit.est.batched.score_cov.resize(pp * pp, 0.0);
        if self.groups.curvature {
            self.terms = CurvatureTerms::new(self.p, self.horizon);
        }
    }

    /// Forget every column and test.
    pub(crate) fn reset(&mut self) {
        self.fit.reset();
        self.latest.fill(None);
        self.curvature.fill(None);
    }

    /// The latest order test of each window (empty without the order group).
    pub(crate) fn tests(&self) -> &[Option<NonlinearityTest>] {
        if self.groups.order { &self.latest } else { &[] }
    }

    /// The latest nonlinearity test of each window (empty without the curvature group).
    pub(crate) fn curvature_tests(&self) -> &[Option<NonlinearityTest>] {
        if self.groups.curvature { &self.curvature } else { &[] }
    }

    /// Absorb the newest column of `reg`: the linear windows' regressors `z` (`d`) and its
    /// `dy` (`p`); with the curvature group, the integrals of the squares and cubes of the
    /// outputs' excursions from the working origin over the column (trapezoidal, as the
    /// outputs are; `curvature.rs`). The order group's regressor is the increment of the
    /// column `h` columns earlier (zero for the first `h` columns after a reset, so the
    /// guard's blocks stay aligned with the linear ones).
    pub(crate) fn push(&mut self, z: &[f64], dy: &[f64], reg: &SlidingRegression) {
        let (p, d) = (self.p, self.d);
        self.fit.z[..d].copy_from_slice(&z[..d]);
        let mut at = d;
        if self.groups.order {
            self.fit.past_increment(at, &dy[..p]);
            at += p;
        }
        if self.groups.curvature {
            self.terms.column(reg, &mut self.fit.z[at..at + 2 * p]);
        }
        self.fit.push(dy);
    }

    /// The larger fit's windows (whose block ring a checkpoint may leave out, `replay.rs`).
    pub(crate) fn ring(&self) -> &InstrumentedWindows {
        &self.fit.windows
    }

    /// The larger fit's windows, to strip or refill.
    pub(crate) fn ring_mut(&mut self) -> &mut InstrumentedWindows {
        &mut self.fit.windows
    }

    /// How many columns before the `held` newest a replay feeds to the ring of past
    /// increments only: the `h` whose increments the oldest held column's regressors take
    /// (fewer where fewer were pushed since the reset), none without the order group.
    pub(crate) fn lead_in(&self, held: usize) -> usize {
        if self.groups.order {
            self.fit.pushed().saturating_sub(held as u64).min(self.horizon as u64) as usize
        } else {
            0
        }
    }

    /// A replay's column before the held ones ([`lead_in`](Self::lead_in)): its increment
    /// joins the ring of past increments.
    pub(crate) fn lead_column(&mut self, dy: &[f64]) {
        self.fit.skip_column(self.d, &dy[..self.p]);
    }

    /// Window `w`'s tests at a look: replace the window's latest tests.
    pub(crate) fn look(&mut self, w: usize, ridge: f64, min_pivot: f64) {
        let (p, d) = (self.p, self.d);
        self.latest[w] = None;
        self.curvature[w] = None;
        if !self.fit.windows.is_full(w) {
            return;
        }
        // The direction weighs the blocks for the effective number `ν` by the tested
        // coefficients (ones on the extra rows), whose `ν` the test's quantile needs. (Against
        // the certificate's direction the curvature test's rejection rate on a linear loop
        // measured the same, 2–4 % of looks against a nominal 0.25 %: the direction is not
        // what makes that test anti-conservative.)
        self.fit.dir.fill(0.0);
        self.fit.dir[d * p..].fill(1.0);
        let Some(nu) = self.fit.fit(w, (ridge, min_pivot), self.variance, d) else { return };
        let mut first = d;
        if self.groups.order {
            self.latest[w] = self.fit.wald(first, p, nu, self.alpha);
            first += p;
        }
        if self.groups.curvature {
            self.curvature[w] = self.fit.wald(first, 2 * p, nu, self.alpha);
        }
    }

    /// Whether window `w`'s look may stand: `Ok` when its latest tests ran and found nothing
    /// and no longer window's latest test rejects (their data hold window `w`'s, and their
    /// tests have the power), else the reason.
    pub(crate) fn admits(&self, w: usize, window: usize) -> Result<(), NotCertified> {
        let rejected = |tests: &[Option<NonlinearityTest>]| {
            tests
                .iter()
                .enumerate()
                .skip(w)
                .find_map(|(v, t)| t.filter(NonlinearityTest::significant).map(|t| (v, t)))
        };
        if let Some((v, t)) = rejected(self.tests()) {
            return Err(NotCertified::HiddenDynamics {
                window: self.fit.windows.window(v),
                statistic: t.statistic,
                threshold: t.threshold,
                order: 1,
            });
        }
        if let Some((v, t)) = rejected(self.curvature_tests()) {
            return Err(NotCertified::VaryingDynamics {
                window: self.fit.windows.window(v),
                statistic: t.statistic,
                threshold: t.threshold,
            });
        }
        if self.groups.order && self.latest.get(w).copied().flatten().is_none() {
            return Err(NotCertified::OrderUntested { window });
        }
        if self.groups.curvature && self.curvature.get(w).copied().flatten().is_none() {
            return Err(NotCertified::LinearityUntested { window });
        }
        Ok(())
    }

    /// Whether the data fit the first-order model as far as this guard has tested them: no
    /// window's latest hidden-dynamics test rejects (always, without the order group). A
    /// model of the wrong order leaves a rejection in the windows with the power to see it,
    /// and then a rate that depends on the window is the model's misfit, not a change (the
    /// verdict's words: `NotCertified::PlantChanged` only where this holds, `admits(0, _)`'s
    /// rejection otherwise). The curvature test is left out: a window that straddles a
    /// real change holds two slopes, which it reads as curvature (measured on the
    /// plant-change cells, `crates/streamcert-cli/tests/blame.rs`).
    pub(crate) fn fits(&self) -> bool {
        !self.tests().iter().flatten().any(NonlinearityTest::significant)
    }

    /// Whether a deserialised guard matches a fresh one of the same configuration.
    pub(crate) fn matches(&self, fresh: &Self) -> bool {
        (self.p, self.d, self.horizon) == (fresh.p, fresh.d, fresh.horizon)
            && self.groups == fresh.groups
            && self.alpha == fresh.alpha
            && self.variance == fresh.variance
            && self.fit.matches(&fresh.fit)
            && self.latest.len() == fresh.latest.len()
            && self.curvature.len() == fresh.curvature.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rejection closes its own window and every shorter one, never a longer one; a window
    /// without its own test does not stand.
    #[test]
    fn a_rejection_closes_its_window_and_the_shorter_ones() {
        let groups = Groups { order: true, curvature: false };
        let mut g =
            ModelGuard::new((1, 3, 5), groups, (1, 1, 1), &[150, 300, 600], 0.0025).expect("valid");
        let (pass, fail) = (
            NonlinearityTest { statistic: 1.0, threshold: 10.0 },
            NonlinearityTest { statistic: 11.0, threshold: 10.0 },
        );
        let closed_by = |g: &ModelGuard, w: usize| match g.admits(w, g.fit.windows.window(w)) {
            Ok(()) => None,
            Err(NotCertified::HiddenDynamics { window, .. }) => Some(window),
            Err(other) => panic!("{other:?}"),
        };
        g.latest = vec![Some(fail), Some(pass), Some(pass)];
        assert_eq!((0..3).map(|w| closed_by(&g, w)).collect::<Vec<_>>(), [Some(150), None, None]);
        g.latest = vec![Some(pass), Some(fail), Some(pass)];
        assert_eq!(
            (0..3).map(|w| closed_by(&g, w)).collect::<Vec<_>>(),
            [Some(300), Some(300), None]
        );
        g.latest = vec![Some(pass), Some(pass), Some(fail)];
        assert!((0..3).all(|w| closed_by(&g, w) == Some(600)));
        g.latest = vec![Some(pass), None, Some(pass)];
        assert!(matches!(g.admits(1, 300), Err(NotCertified::OrderUntested { window: 300 })));
        assert_eq!(closed_by(&g, 0), None);
    }
}
