//! [`EvidenceRow`]: the one flat, serialisable shape of [`Evidence`] for output files (the
//! command line's CSV and JSON lines, the experiments' traces).

use std::fmt::Write as _;

use serde::{Serialize, Serializer};

use crate::{Evidence, NotCertified};

/// The column names of [`EvidenceRow`], in order (the CSV header).
pub const EVIDENCE_COLUMNS: [&str; 23] = [
    "t",
    "beta_hat",
    "rho",
    "eps",
    "kurtosis",
    "spike_fraction",
    "cert_gauss",
    "cert_wass",
    "gauss_open",
    "wass_open",
    "reason_gauss",
    "reason_wass",
    "rho_calibrated",
    "cert_calibrated",
    "calibrated_window",
    "calibrated_open",
    "reason_calibrated",
    "cert_nonlinear",
    "nonlinear_window",
    "nonlinear_open",
    "reason_nonlinear",
    "nonlinear_y_lo",
    "nonlinear_y_hi",
];

/// A reason, serialised as its `Display` text (formatted on the stack: no allocation for
/// texts up to 192 bytes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReasonText(pub NotCertified);

impl Serialize for ReasonText {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut buf = StackText::default();
        if write!(buf, "{}", self.0).is_ok() {
            serializer.serialize_str(buf.as_str())
        } else {
            serializer.collect_str(&self.0)
        }
    }
}

/// A fixed-capacity text buffer; `write_str` fails when full.
struct StackText {
    bytes: [u8; 192],
    len: usize,
}

impl Default for StackText {
    fn default() -> Self {
        Self { bytes: [0; 192], len: 0 }
    }
}

impl StackText {
    fn as_str(&self) -> &str {
        // Only whole `&str`s are ever copied in, so the bytes are valid UTF-8.
        std::str::from_utf8(&self.bytes[..self.len]).unwrap_or_default()
    }
}

impl std::fmt::Write for StackText {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        let end = self.len + s.len();
        let dst = self.bytes.get_mut(self.len..end).ok_or(std::fmt::Error)?;
        dst.copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

/// One output row per sample, flat, with the columns of [`EVIDENCE_COLUMNS`]: the numbers of
/// [`Evidence`] (empty or `null` when absent), gates as 0/1, and the reasons as text.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EvidenceRow {
    /// Sample time.
    pub t: f64,
    /// `β̂` (eq. betahat).
    pub beta_hat: Option<f64>,
    /// `ρ` (eq. rho).
    pub rho: Option<f64>,
    /// `ε(t)` (eq. eps_est).
    pub eps: Option<f64>,
    /// Excess kurtosis of the residual tail window (largest over outputs).
    pub kurtosis: Option<f64>,
    /// Spike fraction `ŝ(t)` (largest over outputs).
    pub spike_fraction: Option<f64>,
    /// `β̂ − ρ`.
    pub cert_gauss: Option<f64>,
    /// `β̂ − ρ(1 + 2ε)` (eq. wass_cert).
    pub cert_wass: Option<f64>,
    /// Gaussian gate, 0 or 1.
    pub gauss_open: u8,
    /// Wasserstein gate, 0 or 1.
    pub wass_open: u8,
    /// Why the Gaussian gate is closed.
    pub reason_gauss: Option<ReasonText>,
    /// Why the Wasserstein gate is closed.
    pub reason_wass: Option<ReasonText>,
    /// `ρ_w` of the calibrated certificate's window.
    pub rho_calibrated: Option<f64>,
    /// `β̂_w − ρ_w`.
    pub cert_calibrated: Option<f64>,
    /// `M_w`.
    pub calibrated_window: Option<usize>,
    /// Calibrated gate, 0 or 1.
    pub calibrated_open: u8,
    /// Why the calibrated gate is closed.
    pub reason_calibrated: Option<ReasonText>,
    /// The nonlinear certificate `min_y β̂(y) − c s(y)` over its region.
    pub cert_nonlinear: Option<f64>,
    /// Its window length.
    pub nonlinear_window: Option<usize>,
    /// Nonlinear gate, 0 or 1.
    pub nonlinear_open: u8,
    /// Why the nonlinear gate is closed.
    pub reason_nonlinear: Option<ReasonText>,
    /// The region the nonlinear certificate speaks for: smallest output.
    pub nonlinear_y_lo: Option<f64>,
    /// Largest output.
    pub nonlinear_y_hi: Option<f64>,
}

impl From<&Evidence> for EvidenceRow {
    fn from(e: &Evidence) -> Self {
        let amb = e.ambiguity;
        Self {
            t: e.t,
            beta_hat: e.beta_hat(),
            rho: e.rho(),
            eps: amb.map(|a| a.eps),
            kurtosis: amb.and_then(|a| a.kurtosis),
            spike_fraction: amb.map(|a| a.spike_fraction),
            cert_gauss: e.gaussian.value,
            cert_wass: e.wasserstein.value,
            gauss_open: u8::from(e.gaussian.open),
            wass_open: u8::from(e.wasserstein.open),
            reason_gauss: e.gaussian.reason.map(ReasonText),
            reason_wass: e.wasserstein.reason.map(ReasonText),
            rho_calibrated: e.calibrated.radius,
            cert_calibrated: e.calibrated.value,
            calibrated_window: e.calibrated_window,
            calibrated_open: u8::from(e.calibrated.open),
            reason_calibrated: e.calibrated.reason.map(ReasonText),
            cert_nonlinear: e.nonlinear.value,
            nonlinear_window: e.nonlinear_window,
            nonlinear_open: u8::from(e.nonlinear.open),
            reason_nonlinear: e.nonlinear.reason.map(ReasonText),
            nonlinear_y_lo: e.nonlinear_region.map(|r| r.lo),
            nonlinear_y_hi: e.nonlinear_region.map(|r| r.hi),
        }
    }
}
