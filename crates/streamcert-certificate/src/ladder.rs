//! [`HorizonLadder`]: the calibrated certificate at several integration horizons side by
//! side, the run's risk split over them.
//!
//! The horizon `h` (samples per column) decides what a first-order model sees: at one sample
//! per column a sensor's own lag is a second state (the hidden-dynamics guard closes the
//! gate), at ten the slow mode dominates. Which `h` a plant needs is not known before its data
//! are, and trying horizons until one certifies spends the risk once per horizon tried. The
//! ladder spends it once, in the open:
//!
//! - rung `k` is the calibrated certificate at horizon `h_k` and base window `M_k`, with
//!   every guard, at risk `δ / K` (`K` rungs);
//! - the calibrated gate is open when any rung's gate is open (each rung its own `n_s`
//!   consecutive samples), and the certificate reported is the standing rung's: among the
//!   open rungs the one with the largest certificate, else the largest certificate.
//!
//! **Why the risk holds.** Each rung's false-opening probability over the whole run is at
//! most `δ / K` (its own guarantee, valid at every look of every window, so for any stopping
//! rule). The ladder opens falsely only if some rung does, so by the union bound with
//! probability at most `K · δ / K = δ`, whichever rung stands and whenever the run stops. No
//! choice among the rungs is made from data the certificate also uses; there is no choice.
//!
//! **What it costs.** Every rung runs every guard at every look: the step costs about the
//! sum of the rungs' steps, and a checkpoint holds every rung (BENCHMARKS.md gives both).
//! The price in power is the smaller risk per rung: the Student-t quantile at `δ / K` instead
//! of `δ` (VALIDITY.md's power cells).

use serde::{Deserialize, Serialize};

use crate::{CertifierConfig, CertifyError};

mod orders;
pub use orders::OrderLadder;

/// The calibrated certificate at several horizons, the risk split equally over them (see the
/// module docs for the rule and why its risk holds).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HorizonLadder {
    /// The horizons `h_k`, increasing, distinct, at most [`MAX_RUNGS`](Self::MAX_RUNGS); the
    /// regression's own `horizon` must be one of them (the paper's certificates run there).
    pub horizons: Vec<usize>,
    /// Blocks per base window: rung `k`'s base window is `M_k = blocks · h_k` columns (the
    /// regression's `window` must be `blocks · horizon`). `None`: every rung has the
    /// regression's window.
    pub blocks: Option<usize>,
}

impl HorizonLadder {
    /// The most rungs a ladder may hold.
    pub const MAX_RUNGS: usize = 8;
    /// The automatic choice's horizons: the 1-2-5 series up to ten samples per column, which
    /// holds the paper's `h = 5`.
    pub const AUTOMATIC_HORIZONS: [usize; 4] = [1, 2, 5, 10];
    /// The automatic choice's blocks per base window: 30, the paper's `M = 150` at `h = 5`.
    pub const AUTOMATIC_BLOCKS: usize = 30;
    /// The horizon the paper's certificates (Gaussian, Wasserstein) run at in the automatic
    /// choice: the paper's experiments' `h = 5`.
    pub const PAPER_HORIZON: usize = 5;

    /// The automatic choice: [`AUTOMATIC_HORIZONS`](Self::AUTOMATIC_HORIZONS) with
    /// [`AUTOMATIC_BLOCKS`](Self::AUTOMATIC_BLOCKS) blocks per base window.
    #[must_use]
    pub fn automatic() -> Self {
        Self { horizons: Self::AUTOMATIC_HORIZONS.to_vec(), blocks: Some(Self::AUTOMATIC_BLOCKS) }
    }

    /// The base window (columns) the rule gives the rung at horizon `h`: `blocks · h`, or
    /// `fixed` (the regression's window) without `blocks`. A rung's window is this, raised to
    /// the smallest its calibrated fits hold where that is larger
    /// ([`CertifierConfig::rung`]).
    #[must_use]
    pub fn window(&self, h: usize, fixed: usize) -> usize {
        self.blocks.map_or(fixed, |b| b.saturating_mul(h))
    }

    /// Each rung's risk: `δ / K`.
    #[must_use]
    pub fn rung_delta(&self, delta: f64) -> f64 {
        delta / self.horizons.len() as f64
    }

    /// Check the ladder against the rest of `cfg` (each rung's own configuration is checked
    /// by [`CertifierConfig::validate`]).
    pub(crate) fn validate(&self, cfg: &CertifierConfig) -> Result<(), CertifyError> {
        let bad = |message: String| CertifyError::refuse::<()>("horizon", message);
        let h = cfg.regression.horizon;
        if self.horizons.is_empty() || self.horizons.len() > Self::MAX_RUNGS {
            return bad(format!(
                "a horizon ladder holds 1 to {} horizons, got {}",
                Self::MAX_RUNGS,
                self.horizons.len()
            ));
        }
        if self.horizons.first() == Some(&0) || self.horizons.windows(2).any(|w| w[0] >= w[1]) {
            return bad(format!(
                "the ladder's horizons must be increasing and at least 1, got {:?}",
                self.horizons
            ));
        }
        if !self.horizons.contains(&h) {
            return bad(format!(
                "the regression's horizon h = {h} must be one of the ladder's {:?} (the paper's \
                 certificates run there)",
                self.horizons
            ));
        }
        if let Some(b) = self.blocks
            && (b == 0 || b.checked_mul(h) != Some(cfg.regression.window))
        {
            return bad(format!(
                "with {b} blocks per base window the regression's window must be {b} · {h} \
                 columns, got {}",
                cfg.regression.window
            ));
        }
        if cfg.calibration.is_none() {
            return bad("a horizon ladder is the calibrated certificate's: it needs a \
                        calibration"
                .into());
        }
        if cfg.couplings.is_some() {
            return bad("a networked subsystem's coupling gains are estimated at one horizon: \
                        set `horizon` to a number"
                .into());
        }
        Ok(())
    }
}

impl CertifierConfig {
    /// The calibration the certifier runs at: the configured one, with risk `δ / K` when a
    /// [`HorizonLadder`] or an [`OrderLadder`] splits it over `K` rungs.
    #[must_use]
    pub fn calibration_in_effect(&self) -> Option<crate::Calibration> {
        let mut c = self.calibration?;
        if let Some(l) = &self.ladder {
            c.delta = l.rung_delta(c.delta);
        }
        if let Some(l) = &self.orders {
            c.delta = l.rung_delta(c.delta);
        }
        Some(c)
    }

    /// The configuration of the ladder's rung at horizon `h`: this one at `h` and its base
    /// window ([`HorizonLadder::window`], raised to the smallest the rung's fits hold; its
    /// warm-up the window), with the risk in effect
    /// ([`calibration_in_effect`](Self::calibration_in_effect)), without the paper's ambiguity model, the nonlinear certificate or a ladder (those run
    /// at the regression's own horizon only).
    #[must_use]
    pub fn rung(&self, h: usize) -> Self {
        let mut c = self.clone();
        c.regression.horizon = h;
        if let Some(l) = &self.ladder {
            c.regression.window = l.window(h, self.regression.window);
            // A window set by number is raised, at a rung, to the smallest its fits hold.
            if let Some(cal) = &self.calibration {
                c.regression.window =
                    c.regression.window.max(cal.smallest_valid_window(&c.regression));
            }
        }
        // A rung computes no paper's estimate: its warm-up is its window. Its sums are
        // recomputed as often, in windows, as the regression's (every window by default).
        c.regression.min_columns = c.regression.window;
        if self.regression.refresh_period >= self.regression.window {
            c.regression.refresh_period = c.regression.window;
        } else {
            c.regression.refresh_period = self.regression.refresh_period.min(c.regression.window);
        }
        c.calibration = self.calibration_in_effect();
        c.ambiguity = None;
        c.nonlinear = None;
        c.ladder = None;
        c.orders = None;
        c
    }
}
