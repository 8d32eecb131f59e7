//! [`WindowLook`]: one window's latest look, and what a look of the calibrated certificate
//! tells the gate (its value, its stale bound).

use serde::{Deserialize, Serialize};

use crate::look::Look;

/// One window's latest look.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WindowLook {
    /// Window length `M_w` in columns.
    pub window: usize,
    /// Look number `k` of this window.
    pub look: u64,
    /// Time of the look.
    pub t: f64,
    /// `β̂_w` of the instrumented estimate.
    pub beta_hat: f64,
    /// `ρ_w`.
    pub radius: f64,
    /// The estimated standard deviation `√λ_max(Ω̂)` of `β̂_w` (before the quantile).
    pub sd: f64,
    /// Degrees of freedom `ν` of the quantile (effective blocks less `p + m`).
    pub nu: f64,
    /// The upper bound `β̂_w + t_ν(1 − δ) · sd_w` used to close stale certificates (one look's
    /// risk, not the run's spending: closing never costs validity). Computed only when `β̂_w`
    /// is below the margin; otherwise it cannot be below the margin and is `None`.
    pub upper: Option<f64>,
    /// `true` for the anchored window's look (every block since its epoch began;
    /// [`Calibration::anchored_share`](crate::Calibration::anchored_share)), whose `window`
    /// is then the columns it held; `false` for a sliding window's.
    #[serde(default)]
    pub anchored: bool,
}

impl Look for WindowLook {
    fn time(&self) -> f64 {
        self.t
    }
    fn window(&self) -> usize {
        self.window
    }
    fn value(&self) -> f64 {
        self.certificate()
    }
    fn upper(&self) -> Option<f64> {
        self.upper
    }
}

impl WindowLook {
    /// `β̂_w − ρ_w`.
    #[must_use]
    pub fn certificate(&self) -> f64 {
        self.beta_hat - self.radius
    }
}
