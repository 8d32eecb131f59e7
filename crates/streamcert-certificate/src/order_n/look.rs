//! What a look of the certificate of order `n` records: [`OrderNLook`] and its
//! [`OrderNRegion`].

use serde::{Deserialize, Serialize};

use crate::NotCertified;

/// One look of [`OrderNCertificate`](super::OrderNCertificate): the window's closed loop, its region and the verdict.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OrderNLook {
    /// The look's number `k >= 1` since the start (a [`reset`](super::OrderNCertificate::reset) does
    /// not restart it).
    pub index: u64,
    /// The time of the sample it falls on.
    pub time: f64,
    /// The rows fitted, `N`.
    pub rows: usize,
    /// The risk it spends, `δ_k = δ / (k (k + 1))`.
    pub risk: f64,
    /// What it found: the region and its margin, or why it certifies nothing.
    pub outcome: Result<OrderNRegion, NotCertified>,
}

impl OrderNLook {
    /// Whether this look certifies the margin.
    #[must_use]
    pub fn certified(&self) -> bool {
        self.outcome.as_ref().is_ok_and(|r| r.certified)
    }
}

/// The confidence region of a look and what it certifies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OrderNRegion {
    /// `β̂ = (β̂_1..β̂_n)`.
    pub beta: Vec<f64>,
    /// `Σ_β`, `n × n` row-major.
    pub covariance: Vec<f64>,
    /// The degrees of freedom `ν = ⌊N / (n h + 1)⌋ − d`.
    pub dof: usize,
    /// `r_k² = n · F_{n, ν}(1 − δ_k)`.
    pub radius2: f64,
    /// The largest margin every member of the region has (1/s), to the tolerance and never
    /// above it; `None` when no margin can be stated (the region reaches polynomials with
    /// roots anywhere).
    pub margin: Option<f64>,
    /// Whether every member has every root left of `−β_margin` (exact).
    pub certified: bool,
}
