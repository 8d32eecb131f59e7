//! The lack-of-fit check of the feature library ([`NonlinearConfig::check_terms`]) and the
//! nonlinear certificate's hidden-dynamics test
//! ([`Calibration::hidden_dynamics`](crate::Calibration::hidden_dynamics)): a second
//! instrumented fit on the library plus `e` powers of `y` it lacks, and a third on the
//! library plus the output's increment over the `h` samples before the column (`ΔY_{q−h}`,
//! as the linear certificate's guard, `guard::model`), on the same columns, windows and
//! looks, and the Wald test of the extra coefficients. Separate fits: where the library
//! misses the drift the past increment carries the missing terms, so in one fit the powers'
//! test loses its power to it (`tests/all/nonlinear.rs`'s lack-of-fit test runs with the
//! order test on),
//!
//! ```text
//! W = θ̂_Eᵀ Ω̂_EE⁻¹ θ̂_E   against   ν e/(ν − e + 1) · F_{e, ν−e+1}(1 − α)
//! ```
//!
//! (Hotelling's quantile, as the nonlinearity test; `ν` = effective blocks less the larger
//! fit's unknowns, `α` = the test risk or `δ`). If the drift lies in the library's span the
//! extra coefficients are zero and the test rejects with probability about `α`; where it
//! rejects, the certificate's model is contradicted by the data. Under a first-order plant in
//! the library's span with white noise the past increment's coefficient is zero (its
//! interval ends where the column's noise begins); where its test rejects, the output carries
//! a state the model does not hold. The order test belongs in this fit, not in the linear
//! model's: on a nonlinear loop the linear model's misfit reads as a past-increment term.
//! `O(h e + (D + e + m)²)` per column, no allocation.
//!
//! [`NonlinearConfig::check_terms`]: super::NonlinearConfig::check_terms

use serde::{Deserialize, Serialize};

use crate::look::guard_variance::GuardVariance;
use crate::look::hotelling::NonlinearityTest;
use crate::look::larger::LargerFit;
use crate::{CertifyError, NotCertified};

/// The larger fit and what its terms are.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(super) struct LackOfFit {
    /// The exponents `k` of the extra terms `y^k`.
    powers: Vec<u8>,
    /// Library features `D` (the extra terms follow them, then the past increment when
    /// `order`, then the inputs).
    features: usize,
    horizon: usize,
    /// Whether the fit holds the past increment `ΔY_{q−h}` (the order test).
    #[serde(default)]
    order: bool,
    /// The larger fit (its fields inline in a checkpoint).
    #[serde(flatten)]
    fit: LargerFit,
}

impl LackOfFit {
    /// The check with extra terms `y^k`, `k` in `powers`, and the past increment when
    /// `order`, after `features` library features and before `inputs` inputs, on windows
    /// `lengths`.
    pub(super) fn new(
        (powers, order): (Vec<u8>, bool),
        features: usize,
        inputs: usize,
        (horizon, lag, intervals): (usize, usize, usize),
        lengths: &[usize],
    ) -> Result<Self, CertifyError> {
        let e = powers.len();
        let d = features + e + usize::from(order) + inputs;
        let q = e + usize::from(order);
        let fit = LargerFit::new((1, d, horizon), (lag, intervals, 1), lengths, order, q)?;
        Ok(Self { powers, features, horizon, order, fit })
    }

    pub(super) fn reset(&mut self) {
        self.fit.reset();
    }

    /// Absorb a column: `z_main` holds the library's integrals then the inputs' (`D + m`),
    /// `ts`/`ys` the column's `h + 1` samples; the extra terms are integrated by the same
    /// trapezoidal rule. The past increment is the increment of the column `h` columns
    /// earlier (zero for the first `h` columns after a reset, as the linear guard's).
    pub(super) fn push(&mut self, z_main: &[f64], dy: &[f64], ts: &[f64], ys: &[f64]) {
        let (dg, e) = (self.features, self.powers.len());
        let o = usize::from(self.order);
        let z = &mut self.fit.z;
        z[..dg].copy_from_slice(&z_main[..dg]);
        z[dg + e + o..].copy_from_slice(&z_main[dg..]);
        if self.order {
            self.fit.past_increment(dg + e, &dy[..1]);
        }
        let extra = &mut self.fit.z[dg..dg + e];
        extra.fill(0.0);
        // Each sample's powers once (`y^k` by repeated multiplication), then the trapezoids.
        let top = usize::from(self.powers.iter().copied().max().unwrap_or(1));
        let powers = |y: f64, out: &mut [f64; 9]| {
            out[1] = y;
            for k in 2..=top {
                out[k] = out[k - 1] * y;
            }
        };
        let (mut pa, mut pb) = ([0.0; 9], [0.0; 9]);
        powers(ys[0], &mut pa);
        for i in 1..ts.len() {
            let half = 0.5 * (ts[i] - ts[i - 1]);
            powers(ys[i], &mut pb);
            for (v, &k) in extra.iter_mut().zip(&self.powers) {
                *v += half * (pa[usize::from(k)] + pb[usize::from(k)]);
            }
            pa = pb;
        }
        self.fit.push(dy);
    }

    /// Window `w`'s test at a look: the Wald test of every extra term of this fit (the powers,
    /// or the past increment; `None` when the larger fit is not ready). `dir_main` is the
    /// certificate's direction `a(y_mid)` (library slopes, then `K`), extended by zeros for
    /// the extra terms (it only weighs the blocks for `ν`).
    pub(super) fn test(
        &mut self,
        w: usize,
        dir_main: &[f64],
        ridge: f64,
        min_pivot: f64,
        alpha: f64,
    ) -> Option<NonlinearityTest> {
        let (dg, e, o) = (self.features, self.powers.len(), usize::from(self.order));
        let d = self.fit.z.len();
        let dir = &mut self.fit.dir;
        dir[..dg].copy_from_slice(&dir_main[..dg]);
        dir[dg..dg + e + o].fill(0.0);
        dir[dg + e + o..].copy_from_slice(&dir_main[dg..d - e - o]);
        let nu = self.fit.fit(w, (ridge, min_pivot), GuardVariance::Jackknife, dg)?;
        self.fit.wald(dg, e + o, nu, alpha)
    }

    /// Whether a deserialised check matches a fresh one.
    pub(super) fn matches(&self, fresh: &Self) -> bool {
        self.powers == fresh.powers
            && self.features == fresh.features
            && self.horizon == fresh.horizon
            && self.order == fresh.order
            && self.fit.matches(&fresh.fit)
    }
}

/// Why a test (run when `on`) keeps a look from standing: `untested`
/// (`NotCertified::OrderUntested` or `NotCertified::LibraryUntested`) where it did not run,
/// its rejection (`HiddenDynamics`, `LibraryMisfit`) where it rejects, `None` where it ran and
/// found nothing or is off.
pub(super) fn refused(
    on: bool,
    test: Option<NonlinearityTest>,
    untested: NotCertified,
) -> Option<NotCertified> {
    let t = match test {
        _ if !on => return None,
        None => return Some(untested),
        Some(t) if !t.significant() => return None,
        Some(t) => t,
    };
    let (statistic, threshold) = (t.statistic, t.threshold);
    Some(match untested {
        NotCertified::OrderUntested { window } => {
            NotCertified::HiddenDynamics { window, statistic, threshold, order: 1 }
        }
        NotCertified::LibraryUntested { window } => {
            NotCertified::LibraryMisfit { window, statistic, threshold }
        }
        other => other,
    })
}

impl super::NonlinearState {
    /// Check a deserialised state against a fresh one.
    pub(crate) fn check(&self, fresh: &Self) -> Result<(), CertifyError> {
        self.windows.check_state()?;
        let ok = self.cfg == fresh.cfg
            && self.library == fresh.library
            && self.horizon == fresh.horizon
            && self.gain == fresh.gain
            && crate::look::same_windows(&self.windows, &fresh.windows)
            && self.est.matches(&fresh.est)
            && self.latest.len() == fresh.latest.len()
            && self.shares == fresh.shares
            && [(&self.check, &fresh.check), (&self.order, &fresh.order)].iter().all(|p| match p {
                (Some(a), Some(b)) => a.matches(b),
                (None, None) => true,
                _ => false,
            })
            && [
                (self.z.len(), fresh.z.len()),
                (self.dir.len(), fresh.dir.len()),
                (self.cov.len(), fresh.cov.len()),
                (self.poly_f.len(), fresh.poly_f.len()),
                (self.poly_s.len(), fresh.poly_s.len()),
                (self.work.len(), fresh.work.len()),
                (self.sub.len(), fresh.sub.len()),
                (self.rhs.len(), fresh.rhs.len()),
            ]
            .iter()
            .all(|(a, b)| a == b);
        if ok {
            Ok(())
        } else {
            Err(CertifyError::Checkpoint("nonlinear state does not match its configuration".into()))
        }
    }
}
