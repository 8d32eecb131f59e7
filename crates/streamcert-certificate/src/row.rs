//! [`EvidenceRow`]: the one flat, serialisable shape of [`Evidence`] for output files (the
//! command line's CSV and JSON lines, the experiments' traces).

use std::fmt::Write as _;

use serde::{Serialize, Serializer};

use crate::{Evidence, NotCertified};

/// What a column of [`EVIDENCE_COLUMNS`] holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColumnKind {
    /// A number (absent: an empty CSV field, `null`, NaN in arrays).
    Number,
    /// A gate, open or closed (0/1).
    Gate,
    /// Why a gate is closed (text).
    Reason,
    /// A count that describes a look: its window length `M_w` (columns), for
    /// `calibrated_horizon` its horizon `h` (samples per column), for `calibrated_order` its
    /// model order `n`; absent before a look.
    Window,
}

/// Every evidence column with what it holds, in the order of [`EvidenceRow`] and the CSV
/// header: the one list the header, the Python package's arrays and their kinds come from.
pub const EVIDENCE_COLUMN_KINDS: [(&str, ColumnKind); 25] = {
    use ColumnKind::{Gate, Number, Reason, Window};
    [
        ("t", Number),
        ("beta_hat", Number),
        ("rho", Number),
        ("eps", Number),
        ("kurtosis", Number),
        ("spike_fraction", Number),
        ("cert_gauss", Number),
        ("cert_wass", Number),
        ("gauss_open", Gate),
        ("wass_open", Gate),
        ("reason_gauss", Reason),
        ("reason_wass", Reason),
        ("rho_calibrated", Number),
        ("cert_calibrated", Number),
        ("calibrated_window", Window),
        ("calibrated_horizon", Window),
        ("calibrated_order", Window),
        ("calibrated_open", Gate),
        ("reason_calibrated", Reason),
        ("cert_nonlinear", Number),
        ("nonlinear_window", Window),
        ("nonlinear_open", Gate),
        ("reason_nonlinear", Reason),
        ("nonlinear_y_lo", Number),
        ("nonlinear_y_hi", Number),
    ]
};

/// The column names of [`EvidenceRow`], in order (the CSV header).
pub const EVIDENCE_COLUMNS: [&str; 25] = of_kind(None);

/// The [`ColumnKind::Number`] columns, in order ([`EvidenceRow::numbers`] gives their values).
pub const NUMBER_COLUMNS: [&str; 13] = of_kind(Some(ColumnKind::Number));

/// The [`ColumnKind::Window`] columns, in order.
pub const WINDOW_COLUMNS: [&str; 4] = of_kind(Some(ColumnKind::Window));

/// The names of the columns of `kind` (every column for `None`), in order; a count that is
/// not `N` fails the build.
const fn of_kind<const N: usize>(kind: Option<ColumnKind>) -> [&'static str; N] {
    let mut out = [""; N];
    let (mut i, mut n) = (0, 0);
    while i < EVIDENCE_COLUMN_KINDS.len() {
        let (name, k) = EVIDENCE_COLUMN_KINDS[i];
        let wanted = match kind {
            Some(want) => want as u8 == k as u8,
            None => true,
        };
        if wanted {
            assert!(n < N, "more columns of this kind than the array holds");
            out[n] = name;
            n += 1;
        }
        i += 1;
    }
    assert!(n == N, "fewer columns of this kind than the array holds");
    out
}

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
    /// `h` of the standing calibrated look ([`Evidence::calibrated_horizon`]).
    pub calibrated_horizon: Option<usize>,
    /// The model order `n` of the standing calibrated look ([`Evidence::calibrated_order`]).
    pub calibrated_order: Option<usize>,
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

impl EvidenceRow {
    /// The values of the [`NUMBER_COLUMNS`], in that order (`None` where absent).
    #[must_use]
    pub fn numbers(&self) -> [Option<f64>; 13] {
        [
            Some(self.t),
            self.beta_hat,
            self.rho,
            self.eps,
            self.kurtosis,
            self.spike_fraction,
            self.cert_gauss,
            self.cert_wass,
            self.rho_calibrated,
            self.cert_calibrated,
            self.cert_nonlinear,
            self.nonlinear_y_lo,
            self.nonlinear_y_hi,
        ]
    }
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
            calibrated_horizon: e.calibrated_horizon,
            calibrated_order: e.calibrated_order,
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Oracle: serde's own field names and values. The columns are the serialised row's keys
    /// in order, and `numbers()` gives the values serde writes under `NUMBER_COLUMNS`.
    #[test]
    fn the_column_lists_are_the_serialised_rows() {
        let row = EvidenceRow {
            t: 1.5,
            beta_hat: Some(2.0),
            rho: None,
            eps: Some(0.25),
            kurtosis: Some(3.0),
            spike_fraction: Some(0.01),
            cert_gauss: Some(-1.0),
            cert_wass: None,
            rho_calibrated: Some(0.5),
            cert_calibrated: Some(1.25),
            cert_nonlinear: Some(0.75),
            nonlinear_y_lo: Some(-2.0),
            nonlinear_y_hi: Some(2.5),
            gauss_open: 1,
            wass_open: 0,
            reason_gauss: None,
            reason_wass: Some(ReasonText(NotCertified::WarmingUp { columns: 3, needed: 150 })),
            calibrated_window: Some(600),
            calibrated_horizon: Some(5),
            calibrated_order: Some(2),
            calibrated_open: 1,
            reason_calibrated: None,
            nonlinear_window: None,
            nonlinear_open: 0,
            reason_nonlinear: Some(ReasonText(NotCertified::NoNonlinearModel)),
        };
        let json = serde_json::to_value(row).expect("serialised");
        let object = json.as_object().expect("an object");
        let keys: Vec<&str> = object.keys().map(String::as_str).collect();
        let mut sorted = EVIDENCE_COLUMNS.to_vec();
        sorted.sort_unstable();
        let mut keys_sorted = keys.clone();
        keys_sorted.sort_unstable();
        assert_eq!(keys_sorted, sorted, "the same names");
        for (name, value) in NUMBER_COLUMNS.iter().zip(row.numbers()) {
            assert_eq!(object[*name].as_f64(), value, "{name}");
        }
        let kinds = |k: ColumnKind| EVIDENCE_COLUMN_KINDS.iter().filter(move |c| c.1 == k);
        assert!(kinds(ColumnKind::Gate).all(|(n, _)| n.ends_with("_open")));
        assert!(kinds(ColumnKind::Reason).all(|(n, _)| n.starts_with("reason_")));
        assert_eq!(
            WINDOW_COLUMNS,
            ["calibrated_window", "calibrated_horizon", "calibrated_order", "nonlinear_window"]
        );
    }
}
