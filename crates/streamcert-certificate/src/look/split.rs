//! [`RiskSplit`]: how a certificate's risk `δ` is split across its windows, shared by the
//! calibrated and the nonlinear certificates.

use serde::{Deserialize, Serialize};

/// How a certificate splits its risk `δ` across its `W` windows `M_w` (the calibrated
/// certificate's [`Calibration::risk_split`](crate::Calibration::risk_split), the nonlinear
/// certificate's [`NonlinearConfig::risk_split`](crate::NonlinearConfig::risk_split)); window
/// `w`'s `k`-th look then spends `δ · share_w / (k (k + 1))`
/// ([`look_risk`](crate::look_risk)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RiskSplit {
    /// `share_w = 1 / W` (the calibrated certificate's default): each doubling of the window
    /// is one more time scale the loop may need, and none is favoured. The shortest window,
    /// which certifies a fast loop first, keeps its share when longer windows are added.
    #[default]
    Equal,
    /// `share_w = M_w / Σ_v M_v`: the longer windows, which look less often, get more (the
    /// split before the default changed to [`Equal`](Self::Equal); with five windows the
    /// shortest gets `1/31` of `δ`, and a fast loop waits a look longer).
    ByLength,
    /// `share_w = M_w² / Σ_v M_v²`: most of `δ` on the longest windows (with five doubling
    /// windows the longest gets `256/341 ≈ 0.75` of it, the shortest `1/341`). For a
    /// certificate whose verdicts come from its longest windows: the nonlinear certificate's
    /// default ([`NonlinearConfig::risk_split`](crate::NonlinearConfig::risk_split)), whose
    /// bound at the region's edge needs the most data a window holds.
    ByLengthSquared,
}

impl RiskSplit {
    /// Whether this is [`Equal`](Self::Equal), the calibrated certificate's default split.
    #[must_use]
    pub fn is_equal(&self) -> bool {
        *self == Self::Equal
    }

    /// The weight of a window of `columns` columns, to which its share is proportional: 1,
    /// `M_w` or `M_w²`.
    #[must_use]
    pub fn weight(self, columns: usize) -> f64 {
        let m = columns as f64;
        match self {
            Self::Equal => 1.0,
            Self::ByLength => m,
            Self::ByLengthSquared => m * m,
        }
    }

    /// The shares `share_w = weight(M_w) / Σ_v weight(M_v)` of the windows `lengths`
    /// (columns), summing to 1 ([`weight`](Self::weight)).
    #[must_use]
    pub fn shares(self, lengths: &[usize]) -> Vec<f64> {
        if self == Self::Equal {
            return vec![1.0 / lengths.len().max(1) as f64; lengths.len()];
        }
        let total: f64 = lengths.iter().map(|&w| self.weight(w)).sum();
        lengths.iter().map(|&w| self.weight(w) / total).collect()
    }
}
