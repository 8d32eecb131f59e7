//! Estimated coupling bounds (an addition to the paper, for network certification without
//! given gains): some of a subsystem's input channels are its neighbours' measured outputs,
//! not actuated (their rows of `K` are zero), and the norm of their coefficient block is the
//! coupling gain `γ_ij` of the composition (paper eq. coupling).
//!
//! With the neighbour's outputs `y_j` among the regressors, the integral regression of
//! subsystem `i` reads `ΔY ≈ Θ Z` with `Θ = [J_i  B_i  C_ij]` and `C_ij` the block of the
//! neighbour's channels; `‖C_ij‖₂` is the coupling gain. At every look of every calibrated
//! window, after the window's instrumented estimate, the bound is
//!
//! ```text
//! γ̄_ij,w = ‖Ĉ_ij‖₂ + c_w · √λ_max(Ω̂_C)
//! Ω̂_C  = the block of the coefficient covariance (InstrumentedWindows::coefficient_covariance)
//! c_w   = t_ν(1 − δ_{b,w,k}/2)                      (one entry: two-sided Student t)
//! c_w²  = ν r/(ν − r + 1) · F_{r, ν−r+1}(1 − δ_{b,w,k})  (r = p·q entries: Hotelling's T²)
//! δ_{b,w,k} = (δ_c / blocks) · (1 / W) / (k (k + 1))
//! ```
//!
//! `‖C‖₂ <= ‖Ĉ‖₂ + ‖C − Ĉ‖_F` and `‖e‖² <= λ_max(Ω) · eᵀΩ⁻¹e` for `e = vec(C − Ĉ)`, whose
//! studentised form is Hotelling's `T²` (`t²` for one entry); the risks of every look of every
//! window of every block sum to `δ_c`, so with probability at least `1 − δ_c` every bound of
//! the run holds at once, under the calibrated certificate's assumptions (the coupling is
//! constant over the window). The reported bound of a block is the smallest over the windows'
//! latest looks (every one of them holds on that event).

use serde::{Deserialize, Serialize};
use streamcert_regression::{InstrumentedWindows, RegressionConfig, WindowEstimate, linalg};

use crate::CertifyError;
use crate::look::hotelling::simultaneous_multiplier;
use crate::look::quantile::{look_risk, t_quantile};

/// One coupling block: the input channels `first .. first + len` of the subsystem are one
/// neighbour's measured outputs (not actuated: their rows of `K` must be zero).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CouplingBlock {
    /// First input channel of the block.
    pub first: usize,
    /// Number of channels (the neighbour's outputs).
    pub len: usize,
}

/// Which input channels are neighbours' outputs, and the risk of their bounds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CouplingConfig {
    /// The blocks, one per neighbour.
    pub blocks: Vec<CouplingBlock>,
    /// Risk `δ_c ∈ (0, 1)` over the run for every bound of every block together.
    pub delta: f64,
}

impl CouplingConfig {
    /// Check the blocks against the regression and the gain (`m × p` row-major).
    ///
    /// # Errors
    /// [`CertifyError::InvalidConfig`] with what would be valid.
    pub fn validate(
        &self,
        reg: &RegressionConfig,
        gain: &[f64],
        calibrated: bool,
    ) -> Result<(), CertifyError> {
        let bad = |reason: String| Err(CertifyError::InvalidConfig { field: "couplings", reason });
        if !calibrated {
            return bad(
                "estimated coupling bounds reuse the calibrated windows: add a calibration".into(),
            );
        }
        if !(self.delta > 0.0 && self.delta < 1.0) {
            return bad(format!("delta must lie in (0, 1), got {}", self.delta));
        }
        if self.blocks.is_empty() {
            return bad("at least one block".into());
        }
        let (p, m) = (reg.outputs, reg.inputs);
        let mut used = vec![false; m];
        for b in &self.blocks {
            if b.len == 0 || b.first.checked_add(b.len).is_none_or(|end| end > m) {
                return bad(format!(
                    "block at input {} with {} channels: must be non-empty and within the {m} \
                     inputs",
                    b.first, b.len
                ));
            }
            for c in b.first..b.first + b.len {
                if std::mem::replace(&mut used[c], true) {
                    return bad(format!("input {c} is in two blocks"));
                }
                if gain[c * p..(c + 1) * p].iter().any(|&g| g != 0.0) {
                    return bad(format!(
                        "input {c} is a neighbour's output, not actuated: its row of K must be zero"
                    ));
                }
            }
        }
        Ok(())
    }
}

/// The current upper bound on one block's coupling gain.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CouplingBound {
    /// `‖Ĉ‖₂` of the look that gives the bound.
    pub estimate: f64,
    /// The upper confidence bound `γ̄ = ‖Ĉ‖₂ + c · √λ_max(Ω̂_C)` (see the module docs).
    pub upper: f64,
    /// Window length `M_w` (columns) of that look.
    pub window: usize,
    /// Time of that look.
    pub t: f64,
}

/// The streaming state: the latest bound per (window, block).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct CouplingState {
    cfg: CouplingConfig,
    /// `windows × blocks`, window-major.
    latest: Vec<Option<CouplingBound>>,
    /// The smallest bound per block over the windows' latest looks.
    best: Vec<Option<CouplingBound>>,
    // Scratch: the coefficient covariance, a block's covariance and Gram matrix, eigen work.
    cov: Vec<f64>,
    sub: Vec<f64>,
    gram: Vec<f64>,
    eig_work: Vec<f64>,
}

/// What a look hands to [`CouplingState::look`].
pub(crate) struct CouplingLook {
    pub w: usize,
    pub k: u64,
    pub t: f64,
    pub share: f64,
    pub nu: f64,
    pub window: usize,
}

impl CouplingState {
    pub(crate) fn new(cfg: CouplingConfig, p: usize, m: usize, windows: usize) -> Self {
        let d = p + m;
        let r = cfg.blocks.iter().map(|b| b.len * p).max().unwrap_or(1);
        let q = cfg.blocks.iter().map(|b| b.len).max().unwrap_or(1);
        let n = cfg.blocks.len();
        Self {
            latest: vec![None; windows * n],
            best: vec![None; n],
            cov: vec![0.0; (p * d) * (p * d)],
            sub: vec![0.0; r * r],
            gram: vec![0.0; q * q],
            eig_work: vec![0.0; linalg::eig_work_len(r.max(q))],
            cfg,
        }
    }

    /// The current bound per block.
    pub(crate) fn bounds(&self) -> &[Option<CouplingBound>] {
        &self.best
    }

    pub(crate) fn reset(&mut self) {
        self.latest.fill(None);
        self.best.fill(None);
    }

    /// `true` when the buffers have the lengths `fresh`'s have and every bound is finite.
    pub(crate) fn matches(&self, fresh: &Self) -> bool {
        let finite = |b: &Option<CouplingBound>| {
            b.is_none_or(|b| b.estimate.is_finite() && b.upper.is_finite() && b.t.is_finite())
        };
        self.cfg == fresh.cfg
            && self.latest.len() == fresh.latest.len()
            && self.best.len() == fresh.best.len()
            && self.cov.len() == fresh.cov.len()
            && self.sub.len() == fresh.sub.len()
            && self.gram.len() == fresh.gram.len()
            && self.eig_work.len() == fresh.eig_work.len()
            && self.latest.iter().chain(&self.best).all(finite)
    }

    /// Window `w`'s look, after a ready estimate of the same window in `est`.
    pub(crate) fn look(
        &mut self,
        look: &CouplingLook,
        windows: &InstrumentedWindows,
        est: &mut WindowEstimate,
        p: usize,
    ) {
        let n = self.cfg.blocks.len();
        let row = &mut self.latest[look.w * n..(look.w + 1) * n];
        row.fill(None);
        if est.ready && windows.coefficient_covariance(look.w, est, &mut self.cov) {
            let d = est.theta.len() / p;
            let risk = look_risk(self.cfg.delta / n as f64, look.share, look.k);
            for (slot, b) in row.iter_mut().zip(&self.cfg.blocks) {
                let (q, r) = (b.len, b.len * p);
                let entry = |e: usize| (e / q) * d + p + b.first + e % q;
                for e in 0..r {
                    for f in 0..r {
                        self.sub[e * r + f] = self.cov[entry(e) * p * d + entry(f)];
                    }
                }
                let spread = linalg::sym_eig_extremes(&self.sub[..r * r], r, &mut self.eig_work).1;
                // ‖Ĉ‖₂ = √λ_max(ĈᵀĈ).
                for a in 0..q {
                    for c in 0..q {
                        self.gram[a * q + c] = (0..p)
                            .map(|i| {
                                est.theta[i * d + p + b.first + a]
                                    * est.theta[i * d + p + b.first + c]
                            })
                            .sum();
                    }
                }
                let norm = linalg::sym_eig_extremes(&self.gram[..q * q], q, &mut self.eig_work)
                    .1
                    .max(0.0)
                    .sqrt();
                let c = if r == 1 {
                    t_quantile(look.nu, 0.5 * risk)
                } else {
                    simultaneous_multiplier(r, look.nu, risk)
                };
                let upper = norm + c * spread.max(0.0).sqrt();
                *slot = (upper.is_finite() && norm.is_finite()).then_some(CouplingBound {
                    estimate: norm,
                    upper,
                    window: look.window,
                    t: look.t,
                });
            }
        }
        for (bi, best) in self.best.iter_mut().enumerate() {
            *best = (0..self.latest.len() / n)
                .filter_map(|w| self.latest[w * n + bi])
                .min_by(|a, b| a.upper.total_cmp(&b.upper));
        }
    }
}
