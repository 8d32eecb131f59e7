//! The ambiguity radius `ε(t)` (paper eq. eps_est).

use serde::{Deserialize, Serialize};

use crate::{AmbiguityError, RobustScale, SlidingKurtosis, SpikeScale};

/// Parameters of eq. eps_est.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AmbiguityConfig {
    /// `N_tail >= 4`: values in the tail window (paper: 150).
    pub tail_window: usize,
    /// `ε_floor >= 0` (paper Table I: 0.015).
    pub eps_floor: f64,
    /// `ε_cap >= ε_floor` (paper Table I: 0.32).
    pub eps_cap: f64,
    /// `α_κ >= 0`, weight of the positive excess kurtosis. Not given by the paper.
    pub alpha_kurtosis: f64,
    /// `α_s >= 0`, weight of the spike fraction. Not given by the paper.
    pub alpha_spike: f64,
    /// Source of `σ0` for the `3 σ0` spike threshold.
    pub spike_scale: SpikeScale,
}

impl AmbiguityConfig {
    /// Table I's `ε_floor = 0.015`, `ε_cap = 0.32`, the given tail window, and our choices
    /// where the paper is silent: `α_κ = 0.03` (so a Laplace tail, `κ_e = 3`, gives
    /// `ε ≈ 0.1`, the plateau the paper describes for Regime 2), `α_s = 2` (a 5 % spike share
    /// adds 0.1), and `σ0` calibrated by the scaled MAD of the first `tail_window` values.
    #[must_use]
    pub fn paper(tail_window: usize) -> Self {
        Self {
            tail_window,
            eps_floor: 0.015,
            eps_cap: 0.32,
            alpha_kurtosis: 0.03,
            alpha_spike: 2.0,
            spike_scale: SpikeScale::Calibrated { samples: tail_window },
        }
    }

    /// Check every field.
    ///
    /// # Errors
    /// [`AmbiguityError::TailWindowTooShort`], [`AmbiguityError::InvalidBounds`],
    /// [`AmbiguityError::InvalidParameter`], [`AmbiguityError::CalibrationTooShort`].
    pub fn validate(&self) -> Result<(), AmbiguityError> {
        if self.tail_window < SlidingKurtosis::MIN_WINDOW {
            return Err(AmbiguityError::TailWindowTooShort {
                window: self.tail_window,
                min: SlidingKurtosis::MIN_WINDOW,
            });
        }
        let ok = |v: f64| v.is_finite() && v >= 0.0;
        if !(ok(self.eps_floor) && ok(self.eps_cap) && self.eps_floor <= self.eps_cap) {
            return Err(AmbiguityError::InvalidBounds { floor: self.eps_floor, cap: self.eps_cap });
        }
        for (name, value) in
            [("alpha_kurtosis", self.alpha_kurtosis), ("alpha_spike", self.alpha_spike)]
        {
            if !ok(value) {
                return Err(AmbiguityError::InvalidParameter { name, value });
            }
        }
        match self.spike_scale {
            SpikeScale::Fixed { sigma0 } if !(sigma0 > 0.0 && sigma0.is_finite()) => {
                Err(AmbiguityError::InvalidParameter { name: "sigma0", value: sigma0 })
            }
            SpikeScale::Calibrated { samples } if samples < 4 => {
                Err(AmbiguityError::CalibrationTooShort { got: samples, min: 4 })
            }
            _ => Ok(()),
        }
    }

    /// Eq. eps_est: `clip(ε_floor + α_κ max(0, κ_e) + α_s ŝ, ε_floor, ε_cap)`. An undefined
    /// kurtosis (fewer than 4 values, zero spread) counts as 0.
    #[must_use]
    #[inline]
    pub fn radius(&self, kurtosis: Option<f64>, spike_fraction: f64) -> f64 {
        let k = kurtosis.unwrap_or(0.0).max(0.0);
        let raw = self.eps_floor + self.alpha_kurtosis * k + self.alpha_spike * spike_fraction;
        raw.clamp(self.eps_floor, self.eps_cap)
    }
}

/// The radius and the statistics behind it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Ambiguity {
    /// `ε(t)`.
    pub eps: f64,
    /// `κ_e(t)` over the tail window (`None` when undefined).
    pub kurtosis: Option<f64>,
    /// `ŝ(t)`.
    pub spike_fraction: f64,
    /// `σ0` in use (`None` while calibrating).
    pub sigma0: Option<f64>,
}

/// Streaming `ε(t)` from a scalar residual stream.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
///
/// The spike count shares the moments' window: a value is counted when it enters and
/// uncounted when the moments evict it (the same bookkeeping as [`crate::SpikeCounter`],
/// without a second ring).
pub struct AmbiguityRadius {
    cfg: AmbiguityConfig,
    moments: SlidingKurtosis,
    /// `σ0` of the `3 σ0` threshold, once known.
    sigma0: Option<f64>,
    /// Values of the window with `|x| > 3 σ0`.
    spikes: usize,
    /// `1 / N_tail`.
    inv_window: f64,
    calibration: Option<RobustScale>,
}

impl AmbiguityRadius {
    /// Validate and reserve.
    ///
    /// # Errors
    /// See [`AmbiguityConfig::validate`].
    ///
    /// ```
    /// use streamcert_ambiguity::{AmbiguityConfig, AmbiguityError, AmbiguityRadius};
    /// assert!(AmbiguityRadius::new(AmbiguityConfig::paper(150)).is_ok());
    /// let bad = AmbiguityConfig { eps_floor: 0.5, ..AmbiguityConfig::paper(150) };
    /// assert!(matches!(AmbiguityRadius::new(bad), Err(AmbiguityError::InvalidBounds { .. })));
    /// ```
    pub fn new(cfg: AmbiguityConfig) -> Result<Self, AmbiguityError> {
        cfg.validate()?;
        let (sigma0, calibration) = match cfg.spike_scale {
            SpikeScale::Fixed { sigma0 } => (Some(sigma0), None),
            SpikeScale::Calibrated { samples } => (None, Some(RobustScale::new(samples)?)),
        };
        Ok(Self {
            moments: SlidingKurtosis::new(cfg.tail_window)?,
            sigma0,
            spikes: 0,
            inv_window: 1.0 / cfg.tail_window as f64,
            calibration,
            cfg,
        })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &AmbiguityConfig {
        &self.cfg
    }

    /// Absorb one residual: amortised O(1), no allocation.
    ///
    /// # Errors
    /// [`AmbiguityError::NonFinite`]; the value is not absorbed.
    #[inline]
    pub fn push(&mut self, x: f64) -> Result<(), AmbiguityError> {
        self.push_inline(x)
    }

    /// [`push`](Self::push), always inlined.
    #[inline(always)]
    fn push_inline(&mut self, x: f64) -> Result<(), AmbiguityError> {
        let evicted = self.moments.oldest();
        self.moments.push(x)?;
        if let Some(sigma0) = self.sigma0 {
            let threshold = 3.0 * sigma0;
            self.spikes += usize::from(x.abs() > threshold);
            if let Some(e) = evicted {
                self.spikes -= usize::from(e.abs() > threshold);
            }
        } else if let Some(cal) = &mut self.calibration
            && let Some(sigma0) = cal.push(x)
        {
            // Frozen now: count the spikes already in the window.
            self.sigma0 = Some(sigma0);
            let threshold = 3.0 * sigma0;
            self.spikes = self.moments.values().filter(|v| v.abs() > threshold).count();
        }
        Ok(())
    }

    /// [`push`](Self::push) then [`snapshot`](Self::snapshot), in one inlined piece, so the
    /// snapshot reads the moments' sums where `push` left them (in registers) rather than
    /// from memory after the stores: the certifier's `p = 1` step, where `ε` is at the end
    /// of the longest chain of dependent operations.
    ///
    /// # Errors
    /// [`AmbiguityError::NonFinite`]; the value is not absorbed (nor a snapshot taken).
    #[inline(always)]
    pub fn push_and_snapshot(&mut self, x: f64) -> Result<Ambiguity, AmbiguityError> {
        self.push_inline(x)?;
        Ok(self.snapshot_inline())
    }

    /// `ε(t)` with its inputs.
    #[must_use]
    #[inline]
    pub fn snapshot(&self) -> Ambiguity {
        self.snapshot_inline()
    }

    /// [`snapshot`](Self::snapshot), always inlined.
    #[inline(always)]
    fn snapshot_inline(&self) -> Ambiguity {
        let kurtosis = self.moments.excess_kurtosis();
        let len = self.moments.len();
        // Full window (every sample after warm-up): multiply by the reciprocal computed once.
        let spike_fraction = if len == self.cfg.tail_window {
            self.spikes as f64 * self.inv_window
        } else if len == 0 {
            0.0
        } else {
            self.spikes as f64 / len as f64
        };
        Ambiguity {
            eps: self.cfg.radius(kurtosis, spike_fraction),
            kurtosis,
            spike_fraction,
            sigma0: self.sigma0,
        }
    }

    /// The sliding moments.
    #[must_use]
    pub fn moments(&self) -> &SlidingKurtosis {
        &self.moments
    }

    /// `true` when a deserialised state agrees with its own configuration: window length,
    /// cached `1 / N_tail`, spike count no larger than the window and equal to a recount of
    /// the values it holds, `σ0` known exactly when it should be. `O(N_tail)`; meant for
    /// checkpoint restore, not for the per-sample path.
    #[must_use]
    pub fn is_consistent(&self) -> bool {
        // The structure first: the recount below walks the window.
        if !self.moments.is_consistent()
            || !self.calibration.as_ref().is_none_or(RobustScale::is_consistent)
        {
            return false;
        }
        let window_ok = self.moments.window() == self.cfg.tail_window
            && self.inv_window == 1.0 / self.cfg.tail_window as f64;
        let recount = self
            .sigma0
            .map_or(0, |s0| self.moments.values().filter(|v| v.abs() > 3.0 * s0).count());
        let sigma_ok = match self.cfg.spike_scale {
            SpikeScale::Fixed { sigma0 } => self.sigma0 == Some(sigma0),
            SpikeScale::Calibrated { .. } => {
                self.sigma0 == self.calibration.as_ref().and_then(RobustScale::value)
            }
        };
        window_ok && sigma_ok && self.spikes == recount
    }
}
