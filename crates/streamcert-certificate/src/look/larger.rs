//! [`LargerFit`]: a fit of the linear windows' regressors and extra terms in windows of its
//! own, and the Wald test of the extra terms' coefficients. The model guards (hidden
//! dynamics, nonlinearity) and the nonlinear certificate's lack-of-fit check are each one.

use serde::{Deserialize, Serialize};
use streamcert_regression::{InstrumentedWindows, RateMap, Solve, WindowEstimate};

use super::guard_variance::GuardVariance;
use super::hotelling::{NonlinearityTest, hotelling_wald, wald_entries};
use super::same_windows;
use crate::CertifyError;

/// A larger fit of `p` outputs on `d` regressors (the extra terms among them), its ring of
/// past increments (the hidden-dynamics test's regressor `ΔY_{q−h}`), and the scratch of its
/// Wald tests. The caller writes each column's regressors into [`z`](Self::z) and its
/// direction into [`dir`](Self::dir).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct LargerFit {
    pub(crate) windows: InstrumentedWindows,
    pub(crate) est: WindowEstimate,
    /// The increments `ΔY` of the last `h` columns (ring, `h p` values when the fit holds the
    /// past increment), and the columns pushed since the last reset.
    #[serde(default)]
    lags: Vec<f64>,
    #[serde(default)]
    pushed: u64,
    // Scratch (meaningless between calls): the column's regressors, the direction that
    // weighs the blocks for `ν`, the coefficients' covariance, a test's block and solve.
    pub(crate) z: Vec<f64>,
    pub(crate) dir: Vec<f64>,
    cov: Vec<f64>,
    /// Where `cov` holds only the coefficients of regressors `tail..d` (see [`fit`](Self::fit));
    /// written with `cov`, so that a restored fit equals the live one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    tail: Option<usize>,
    sub: Vec<f64>,
    rhs: Vec<f64>,
    work: Vec<f64>,
}

impl LargerFit {
    /// The fit of `p` outputs on `d` regressors over windows `lengths` (instrument `lag`,
    /// `intervals`, `batch` blocks per batch), with a ring of past increments when `order`,
    /// whose tests take at most `q` coefficients.
    pub(crate) fn new(
        (p, d, horizon): (usize, usize, usize),
        (lag, intervals, batch): (usize, usize, usize),
        lengths: &[usize],
        order: bool,
        q: usize,
    ) -> Result<Self, CertifyError> {
        let windows = InstrumentedWindows::with_regressors(p, d, horizon, lag, intervals, lengths)?;
        let windows = if batch == 1 { windows } else { windows.with_batch(batch)? };
        Ok(Self {
            windows,
            est: WindowEstimate::with_regressors(p, d, intervals),
            lags: vec![0.0; if order { horizon * p } else { 0 }],
            pushed: 0,
            z: vec![0.0; d],
            dir: vec![0.0; d * p],
            cov: vec![0.0; (p * d) * (p * d)],
            tail: None,
            sub: vec![0.0; q * q],
            rhs: vec![0.0; q],
            work: vec![0.0; q],
        })
    }

    /// This fit with the direction read in standardised coefficients (the weights behind
    /// `ν` then the same in any units of the regressors).
    pub(crate) fn standardised(mut self) -> Self {
        self.est = self.est.standardised();
        self
    }

    /// Forget every column.
    pub(crate) fn reset(&mut self) {
        self.windows.reset();
        self.lags.fill(0.0);
        self.pushed = 0;
    }

    /// The past increment of this column into `z[at..at + p]`: the increment `dy` of the
    /// column `h` columns earlier (zero for the first `h` columns after a reset, so that the
    /// fit's blocks stay aligned with the linear ones); `dy` (`p`) joins the ring.
    pub(crate) fn past_increment(&mut self, at: usize, dy: &[f64]) {
        let p = dy.len();
        let h = self.lags.len() / p;
        let slot = (self.pushed % h as u64) as usize;
        self.z[at..at + p].copy_from_slice(&self.lags[slot * p..(slot + 1) * p]);
        self.lags[slot * p..(slot + 1) * p].copy_from_slice(dy);
    }

    /// The columns pushed since the last reset.
    pub(crate) fn pushed(&self) -> u64 {
        self.pushed
    }

    /// Count a column that only feeds the ring of past increments (a replay's columns before
    /// the windows' oldest, `replay.rs`): its `dy` joins the ring (read into `z[at..]` as
    /// [`past_increment`](Self::past_increment) does), the windows take nothing.
    pub(crate) fn skip_column(&mut self, at: usize, dy: &[f64]) {
        if !self.lags.is_empty() {
            self.past_increment(at, dy);
        }
        self.pushed += 1;
    }

    /// Absorb the column whose regressors are in `z`, its increments `dy`.
    pub(crate) fn push(&mut self, dy: &[f64]) {
        self.pushed += 1;
        self.windows.push_column(&self.z, dy);
    }

    /// Fit window `w` (the direction in `dir`) with the covariance `variance`: the degrees
    /// of freedom `ν = min(ESS, B) − d` of its tests, `None` when the fit is not ready. The
    /// tests read only the coefficients of regressors `tested..d`; with the first-order
    /// covariance, one output and batches of one block, only their covariance is formed
    /// ([`InstrumentedWindows::estimate_tail_first_order`], the same bits as the corner of
    /// the whole covariance), else the whole.
    pub(crate) fn fit(
        &mut self,
        w: usize,
        (ridge, min_pivot): (f64, f64),
        variance: GuardVariance,
        tested: usize,
    ) -> Option<f64> {
        let (windows, est, cov) = (&self.windows, &mut self.est, &mut self.cov);
        let solve =
            Solve { ridge, rate: RateMap::SymmetricPart(&self.dir), min_pivot_ratio: min_pivot };
        self.tail = None;
        let ready = match variance {
            GuardVariance::FirstOrder => {
                match windows.estimate_tail_first_order(w, solve, tested, est, cov) {
                    Some(ready) => {
                        self.tail = Some(tested);
                        ready
                    }
                    None => windows.estimate_coefficients_first_order(w, solve, est, cov),
                }
            }
            GuardVariance::Jackknife => windows.estimate_coefficients(w, solve, est, cov),
        };
        ready.then(|| self.est.effective_blocks.min(self.est.batches as f64) - self.z.len() as f64)
    }

    /// The Wald test `θ̂_Sᵀ Ω̂_SS⁻¹ θ̂_S` of the coefficients of regressors `first .. first + e`
    /// in every output's equation (`q = p e` entries of `vec(Θ̂)`) after [`fit`](Self::fit)
    /// (whose `tested` is at most `first`), against Hotelling's quantile with `q` and `ν`
    /// degrees of freedom at risk `alpha`. `None` when `e = 0`, `Ω̂_SS` is not positive
    /// definite, or `ν − q + 1 <= 0`.
    pub(crate) fn wald(
        &mut self,
        first: usize,
        e: usize,
        nu: f64,
        alpha: f64,
    ) -> Option<NonlinearityTest> {
        let dd = self.z.len();
        let p = self.est.theta.len() / dd;
        // Entry a: output a / e, regressor first + a % e, at index (a / e)·d + first + a % e.
        let index = |a: usize| (a / e) * dd + first + a % e;
        let scratch = (&mut self.sub[..], &mut self.rhs[..], &mut self.work[..]);
        match self.tail {
            // One output: the covariance of regressors `tail..d` only.
            Some(tail) => {
                let n = dd - tail;
                let at = |a: usize| index(a) - tail;
                tail_wald((&self.est.theta, &self.cov, n), (p * e, index, at), (nu, alpha), scratch)
            }
            None => {
                wald_entries((&self.est.theta, &self.cov), (p * e, index), (nu, alpha), scratch)
            }
        }
    }

    /// Whether a deserialised fit matches a fresh one of the same configuration.
    pub(crate) fn matches(&self, fresh: &Self) -> bool {
        self.windows.check_state().is_ok()
            && same_windows(&self.windows, &fresh.windows)
            && self.est.matches(&fresh.est)
            && self.lags.iter().all(|v| v.is_finite())
            && [
                (self.lags.len(), fresh.lags.len()),
                (self.z.len(), fresh.z.len()),
                (self.dir.len(), fresh.dir.len()),
                (self.cov.len(), fresh.cov.len()),
                (self.sub.len(), fresh.sub.len()),
                (self.rhs.len(), fresh.rhs.len()),
                (self.work.len(), fresh.work.len()),
            ]
            .iter()
            .all(|(a, b)| a == b)
    }
}

/// [`wald_entries`] on a covariance of some coefficients only: entry `a` of the test is
/// `theta[index(a)]`, its covariances at `cov[at(a) n + at(b)]` (`n × n`).
fn tail_wald(
    (theta, cov, n): (&[f64], &[f64], usize),
    (q, index, at): (usize, impl Fn(usize) -> usize, impl Fn(usize) -> usize),
    (nu, alpha): (f64, f64),
    (sub, rhs, work): (&mut [f64], &mut [f64], &mut [f64]),
) -> Option<NonlinearityTest> {
    if q == 0 {
        return None;
    }
    for a in 0..q {
        for b in 0..q {
            sub[a * q + b] = cov[at(a) * n + at(b)];
        }
        rhs[a] = theta[index(a)];
    }
    hotelling_wald(q, nu, alpha, (sub, rhs, work))
}
