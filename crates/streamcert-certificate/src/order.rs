//! The hidden-dynamics guard (model order): does the output need more than the first-order
//! model `ΔY_q ≈ Θ Z_q (+ c τ_q)` holds?
//!
//! A sensor sees one coordinate of a plant with many states (the paper's `p ≪ n`). When the
//! output carries a hidden state (a mass measured by its position, a tank behind a tank), its
//! increment over a column depends on that state at the column's start, which the model has
//! no term for, and a rate estimated on the first-order model speaks for a system that does
//! not exist. The guard fits, on the same columns, windows and looks as the calibrated
//! certificate, the larger model
//!
//! ```text
//! ΔY_q ≈ Θ Z_q (+ c τ_q) + Φ ΔY_{q−h}
//! ```
//!
//! whose extra regressor is the output's increment over the `h` samples before the column
//! (a proxy for the hidden state's effect at the column's start), instrumented as every
//! regressor of the windows is (by the regressors of the intervals before the column). Under
//! a first-order plant with white noise `Φ = 0`: `ΔY_{q−h}` ends where column `q`'s noise
//! begins. The Wald statistic of the `p²` entries of `Φ̂`,
//!
//! ```text
//! W = vec(Φ̂)ᵀ Ω̂_ΦΦ⁻¹ vec(Φ̂)   against   ν q/(ν − q + 1) · F_{q, ν−q+1}(1 − α),   q = p²
//! ```
//!
//! (Hotelling's quantile, `Ω̂` the batch-means coefficient covariance of the larger fit, `ν`
//! its effective number of batches less its unknowns per output, `α = δ/W` the guard's risk
//! per look of each of the `W` windows), rejects at risk about `α` when the model holds. Where any window's latest test
//! rejects, no calibrated look stands (`NotCertified::HiddenDynamics`: a hidden state seen on
//! one window is a hidden state of the plant, and the longest windows have the power); where a
//! window's test could not run (the larger fit not ready), that window's look does not stand
//! (`NotCertified::OrderUntested`): the certificate's model is then unchecked. The nonlinear
//! certificate is not gated by this test of the linear model's order.
//!
//! **What it sees**: dynamics whose effect on the next `h` samples is carried by the past
//! increment: second-order and lightly damped outputs, an integrator behind a lag, a
//! measured output of a chain. **What it cannot see**: hidden states that the increment over
//! `h` samples does not reflect (much faster than `h` samples: then the first-order model is a
//! fair reduction; much slower than the window: their effect looks like an operating point,
//! which the intercept absorbs), hidden dynamics that the dither does not excite, and a
//! higher-order effect smaller than the test's resolution at the window's length. Closing
//! never costs validity; a false closing costs power (measured in the tests and VALIDITY.md).
//!
//! `O(k d' + k²)` per column (`d' = d + p`), no allocation; a test per look `O(B p² d'² + p⁶)`.

use serde::{Deserialize, Serialize};
use streamcert_regression::{InstrumentedWindows, WindowEstimate};

use crate::nonlinear::{NonlinearityTest, hotelling_wald, same_windows};
use crate::{CertifyError, NotCertified};

/// The guard's state: its own windows of the larger fit, the ring of the last `h` columns'
/// increments, the latest test per window, and scratch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct OrderGuard {
    /// Outputs `p` and the linear windows' regressors `d` (the extra `p` follow them).
    p: usize,
    d: usize,
    horizon: usize,
    /// The risk `α` of each test.
    alpha: f64,
    windows: InstrumentedWindows,
    est: WindowEstimate,
    /// The increments `ΔY` of the last `h` columns (ring, `h p` values), `pushed` columns so
    /// far since the last reset.
    lags: Vec<f64>,
    pushed: u64,
    /// The latest test of each window (`None`: not run, or its fit not ready).
    latest: Vec<Option<NonlinearityTest>>,
    // Scratch (meaningless between calls).
    z: Vec<f64>,
    dir: Vec<f64>,
    cov: Vec<f64>,
    sub: Vec<f64>,
    rhs: Vec<f64>,
    work: Vec<f64>,
}

impl OrderGuard {
    /// The guard for `p` outputs on windows of `d` regressors, `lengths`, at risk `alpha` per
    /// look; `batch` blocks per batch as the linear windows.
    pub(crate) fn new(
        p: usize,
        d: usize,
        horizon: usize,
        (lag, intervals, batch): (usize, usize, usize),
        lengths: &[usize],
        alpha: f64,
    ) -> Result<Self, CertifyError> {
        let dd = d + p;
        let windows =
            InstrumentedWindows::with_regressors(p, dd, horizon, lag, intervals, lengths)?
                .with_batch(batch)?;
        let q = p * p;
        Ok(Self {
            p,
            d,
            horizon,
            alpha,
            windows,
            est: WindowEstimate::with_regressors(p, dd, intervals),
            lags: vec![0.0; horizon * p],
            pushed: 0,
            latest: vec![None; lengths.len()],
            z: vec![0.0; dd],
            dir: vec![0.0; dd * p],
            cov: vec![0.0; (p * dd) * (p * dd)],
            sub: vec![0.0; q * q],
            rhs: vec![0.0; q],
            work: vec![0.0; q],
        })
    }

    /// Forget every column and test.
    pub(crate) fn reset(&mut self) {
        self.windows.reset();
        self.lags.fill(0.0);
        self.pushed = 0;
        self.latest.fill(None);
    }

    /// The latest test of each window.
    pub(crate) fn tests(&self) -> &[Option<NonlinearityTest>] {
        &self.latest
    }

    /// Absorb a column: the linear windows' regressors `z` (`d`) and its `dy` (`p`). The
    /// extra regressor is the increment of the column `h` columns earlier (zero for the first
    /// `h` columns after a reset, so the guard's blocks stay aligned with the linear ones).
    pub(crate) fn push(&mut self, z: &[f64], dy: &[f64]) {
        let (p, d, h) = (self.p, self.d, self.horizon);
        let slot = (self.pushed % h as u64) as usize;
        self.z[..d].copy_from_slice(&z[..d]);
        self.z[d..d + p].copy_from_slice(&self.lags[slot * p..(slot + 1) * p]);
        self.lags[slot * p..(slot + 1) * p].copy_from_slice(&dy[..p]);
        self.pushed += 1;
        self.windows.push_column(&self.z, dy);
    }

    /// Window `w`'s test at a look, for the certificate's directions `tmat` (`d × p`, the
    /// extra rows zero): replaces the window's latest test.
    pub(crate) fn look(&mut self, w: usize, tmat: &[f64], ridge: f64, min_pivot: f64) {
        let (p, d) = (self.p, self.d);
        let dd = d + p;
        self.latest[w] = None;
        if !self.windows.is_full(w) {
            return;
        }
        self.dir[..d * p].copy_from_slice(&tmat[..d * p]);
        self.dir[d * p..].fill(0.0);
        self.windows.estimate(w, ridge, &self.dir, min_pivot, &mut self.est);
        if !self.est.ready || !self.windows.coefficient_covariance(w, &mut self.est, &mut self.cov)
        {
            return;
        }
        let nu = self.est.effective_blocks.min(self.est.batches as f64) - dd as f64;
        // The tested entries: Φ̂[i][j] = θ̂[i][d + j], at index i·d' + d + j of vec(Θ̂).
        let q = p * p;
        let index = |e: usize| (e / p) * dd + d + e % p;
        for a in 0..q {
            for b in 0..q {
                self.sub[a * q + b] = self.cov[index(a) * (p * dd) + index(b)];
            }
            self.rhs[a] = self.est.theta[index(a)];
        }
        self.latest[w] =
            hotelling_wald(q, nu, self.alpha, (&mut self.sub, &mut self.rhs, &mut self.work));
    }

    /// Whether window `w`'s look may stand: `Ok` when its latest test ran and found nothing
    /// and no window's latest test rejects (the longer windows' tests have the power: a hidden
    /// state seen on any window is a hidden state of the plant), else the reason.
    pub(crate) fn admits(&self, w: usize, window: usize) -> Result<(), NotCertified> {
        if let Some((v, t)) = self
            .latest
            .iter()
            .enumerate()
            .find_map(|(v, t)| t.filter(NonlinearityTest::significant).map(|t| (v, t)))
        {
            return Err(NotCertified::HiddenDynamics {
                window: self.windows.window(v),
                statistic: t.statistic,
                threshold: t.threshold,
            });
        }
        match self.latest.get(w).copied().flatten() {
            Some(t) if t.significant() => Err(NotCertified::HiddenDynamics {
                window,
                statistic: t.statistic,
                threshold: t.threshold,
            }),
            Some(_) => Ok(()),
            None => Err(NotCertified::OrderUntested { window }),
        }
    }

    /// Whether a deserialised guard matches a fresh one of the same configuration.
    pub(crate) fn matches(&self, fresh: &Self) -> bool {
        self.windows.check_state().is_ok()
            && (self.p, self.d, self.horizon) == (fresh.p, fresh.d, fresh.horizon)
            && self.alpha == fresh.alpha
            && same_windows(&self.windows, &fresh.windows)
            && self.est.matches(&fresh.est)
            && self.latest.len() == fresh.latest.len()
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
            && self.lags.iter().all(|v| v.is_finite())
    }
}
