//! [`CsvRows`]: the CSV encoding of [`EvidenceRow`] and its region values, byte for byte what
//! the csv crate's serde writer produces (its `QuoteStyle::Necessary`, numbers by the
//! shortest round-trip form), written straight into one reused buffer.
//!
//! The csv crate is the specification: the tests compare every byte with
//! `csv::Writer::serialize` on random rows, texts with delimiters, quotes and line breaks
//! included. What makes it faster than the serde path (`cargo bench --bench cli`, the
//! `cli_write` group, in BENCHMARKS.md): numbers cannot need quotes, so their bytes are copied
//! without a scan; `zmij` formats a float (the same digits as `ryu`, only the exponent's `+`
//! differs and is removed); and a column whose value did not change since the previous row
//! (the region's bounds, `ε` at its floor, a standing reason) copies its previous bytes.

use std::fmt::Write as _;

use streamcert_certificate::{EvidenceRow, NotCertified};

/// One column's previous number and its text.
#[derive(Clone, Copy)]
struct FloatCache {
    bits: u64,
    len: u8,
    bytes: [u8; 32],
}

impl FloatCache {
    const EMPTY: Self = Self { bits: 0, len: 0, bytes: [0; 32] };
}

/// One reason column's previous value and its (quoted if necessary) text.
#[derive(Default)]
struct ReasonCache {
    last: Option<NotCertified>,
    text: Vec<u8>,
}

/// Encodes rows into a byte buffer; the caller writes [`CsvRows::bytes`] out and
/// [`clear`](CsvRows::clear)s it.
pub(crate) struct CsvRows {
    buf: Vec<u8>,
    floats: Vec<FloatCache>,
    reasons: [ReasonCache; 4],
    zmij: zmij::Buffer,
    scratch: String,
}

/// Whether the csv crate's writer (`QuoteStyle::Necessary`, delimiter `,`, quote `"`) quotes
/// a field with these bytes.
fn needs_quotes(field: &[u8]) -> bool {
    field.iter().any(|&b| matches!(b, b',' | b'"' | b'\n' | b'\r'))
}

/// Append `field` as the csv crate writes it: quoted, with inner quotes doubled, when needed.
pub(crate) fn push_text(buf: &mut Vec<u8>, field: &[u8]) {
    if needs_quotes(field) {
        buf.push(b'"');
        for &b in field {
            if b == b'"' {
                buf.push(b'"');
            }
            buf.push(b);
        }
        buf.push(b'"');
    } else {
        buf.extend_from_slice(field);
    }
}

impl CsvRows {
    /// An encoder for rows with `regions` region values after the evidence columns.
    pub(crate) fn new(regions: usize) -> Self {
        Self {
            buf: Vec::with_capacity(1 << 16),
            floats: vec![FloatCache::EMPTY; 13 + regions],
            reasons: Default::default(),
            zmij: zmij::Buffer::new(),
            scratch: String::new(),
        }
    }

    /// The encoded bytes not yet taken.
    pub(crate) fn bytes(&self) -> &[u8] {
        &self.buf
    }

    /// Forget the encoded bytes (after writing them out).
    pub(crate) fn clear(&mut self) {
        self.buf.clear();
    }

    /// The header line: `names`, quoted where the csv crate quotes them.
    pub(crate) fn header<'a>(&mut self, names: impl IntoIterator<Item = &'a str>) {
        for (i, name) in names.into_iter().enumerate() {
            if i > 0 {
                self.buf.push(b',');
            }
            push_text(&mut self.buf, name.as_bytes());
        }
        self.buf.push(b'\n');
    }

    /// A number in column slot `k`: empty when absent.
    fn float(&mut self, k: usize, v: Option<f64>) {
        let Some(x) = v else { return };
        let cache = &mut self.floats[k];
        if cache.len == 0 || cache.bits != x.to_bits() {
            let text = self.zmij.format(x).as_bytes();
            let n = text.len();
            cache.bytes[..n].copy_from_slice(text);
            cache.len = n as u8;
            cache.bits = x.to_bits();
            // zmij writes `1e+16` where ryu (and so the csv crate) writes `1e16`; it uses an
            // exponent from about 1e16 up (below 1e-5 the exponent is negative: no `+`).
            if x.abs() >= 1e15
                && let Some(at) = text.iter().position(|&b| b == b'+')
            {
                cache.bytes.copy_within(at + 1..n, at);
                cache.len -= 1;
            }
        }
        // A fixed-size copy (inlined, no `memmove` call) cut back to the text's length.
        let at = self.buf.len();
        self.buf.extend_from_slice(&cache.bytes);
        self.buf.truncate(at + cache.len as usize);
    }

    /// An unsigned integer (a gate, a window length).
    fn uint(&mut self, v: Option<usize>) {
        let Some(mut x) = v else { return };
        let mut digits = [0u8; 20];
        let mut i = digits.len();
        loop {
            i -= 1;
            digits[i] = b'0' + (x % 10) as u8;
            x /= 10;
            if x == 0 {
                break;
            }
        }
        self.buf.extend_from_slice(&digits[i..]);
    }

    /// A reason in reason slot `k`: its `Display` text, quoted if necessary.
    fn reason(&mut self, k: usize, r: Option<NotCertified>) {
        let Some(r) = r else { return };
        let cache = &mut self.reasons[k];
        if !cache.last.is_some_and(|last| last.identical(&r)) {
            self.scratch.clear();
            // Writing into a String cannot fail.
            let _ = write!(self.scratch, "{r}");
            cache.text.clear();
            push_text(&mut cache.text, self.scratch.as_bytes());
            cache.last = Some(r);
        }
        self.buf.extend_from_slice(&cache.text);
    }

    /// Append one row: the evidence columns, then `region` (already `None` where absent).
    pub(crate) fn row(&mut self, row: &EvidenceRow, region: &[Option<f64>]) {
        let sep = |s: &mut Self| s.buf.push(b',');
        self.float(0, Some(row.t));
        for (k, v) in [
            row.beta_hat,
            row.rho,
            row.eps,
            row.kurtosis,
            row.spike_fraction,
            row.cert_gauss,
            row.cert_wass,
        ]
        .into_iter()
        .enumerate()
        {
            sep(self);
            self.float(1 + k, v);
        }
        sep(self);
        self.uint(Some(usize::from(row.gauss_open)));
        sep(self);
        self.uint(Some(usize::from(row.wass_open)));
        sep(self);
        self.reason(0, row.reason_gauss.map(|r| r.0));
        sep(self);
        self.reason(1, row.reason_wass.map(|r| r.0));
        sep(self);
        self.float(8, row.rho_calibrated);
        sep(self);
        self.float(9, row.cert_calibrated);
        sep(self);
        self.uint(row.calibrated_window);
        sep(self);
        self.uint(row.calibrated_horizon);
        sep(self);
        self.uint(row.calibrated_order);
        sep(self);
        self.uint(Some(usize::from(row.calibrated_open)));
        sep(self);
        self.reason(2, row.reason_calibrated.map(|r| r.0));
        sep(self);
        self.float(10, row.cert_nonlinear);
        sep(self);
        self.uint(row.nonlinear_window);
        sep(self);
        self.uint(Some(usize::from(row.nonlinear_open)));
        sep(self);
        self.reason(3, row.reason_nonlinear.map(|r| r.0));
        sep(self);
        self.float(11, row.nonlinear_y_lo);
        sep(self);
        self.float(12, row.nonlinear_y_hi);
        for (k, &v) in region.iter().enumerate() {
            sep(self);
            self.float(13 + k, v);
        }
        self.buf.push(b'\n');
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use streamcert_certificate::ReasonText;

    /// Numbers from a small pool, so consecutive rows repeat values (the caches) and the
    /// awkward ones come up: signed zeros, exponents both ways, NaN, infinities.
    fn number() -> impl Strategy<Value = Option<f64>> {
        prop_oneof![
            Just(None),
            Just(Some(0.0)),
            Just(Some(-0.0)),
            Just(Some(1e16)),
            Just(Some(-2.5e-7)),
            Just(Some(f64::NAN)),
            Just(Some(f64::INFINITY)),
            Just(Some(f64::MAX)),
            any::<f64>().prop_map(Some),
            (-10.0..10.0f64).prop_map(Some),
        ]
    }

    fn reason() -> impl Strategy<Value = Option<ReasonText>> {
        let n = || prop_oneof![Just(0.0), Just(-0.0), any::<f64>()];
        prop_oneof![
            Just(None),
            Just(Some(NotCertified::NoCalibration)),
            (0usize..200, 1usize..200)
                .prop_map(|(columns, needed)| Some(NotCertified::WarmingUp { columns, needed })),
            (n(), n()).prop_map(|(certificate, margin)| Some(NotCertified::BelowMargin {
                certificate,
                margin
            })),
            (1usize..9, n(), n()).prop_map(|(window, statistic, threshold)| Some(
                NotCertified::VaryingDynamics { window, statistic, threshold }
            )),
            (1usize..9, n(), n()).prop_map(|(window, statistic, threshold)| Some(
                NotCertified::LibraryMisfit { window, statistic, threshold }
            )),
            (1usize..9, n(), n(), 1usize..=3).prop_map(|(window, statistic, threshold, order)| {
                Some(NotCertified::HiddenDynamics { window, statistic, threshold, order })
            }),
            (1usize..9, n(), n()).prop_map(|(window, beta_hat, newest_upper)| Some(
                NotCertified::PlantChanged { window, beta_hat, newest_upper }
            )),
        ]
        .prop_map(|r| r.map(ReasonText))
    }

    fn row() -> impl Strategy<Value = EvidenceRow> {
        (
            (number(), number(), number(), number(), number(), number(), number(), number()),
            (any::<bool>(), any::<bool>(), reason(), reason(), number(), number()),
            (
                proptest::option::of(0usize..100_000),
                any::<bool>(),
                reason(),
                number(),
                proptest::option::of(1usize..100),
            ),
            (proptest::option::of(0usize..9), any::<bool>(), reason(), number(), number()),
        )
            .prop_map(|(a, b, c, d)| EvidenceRow {
                t: a.0.unwrap_or(0.5),
                beta_hat: a.1,
                rho: a.2,
                eps: a.3,
                kurtosis: a.4,
                spike_fraction: a.5,
                cert_gauss: a.6,
                cert_wass: a.7,
                gauss_open: u8::from(b.0),
                wass_open: u8::from(b.1),
                reason_gauss: b.2,
                reason_wass: b.3,
                rho_calibrated: b.4,
                cert_calibrated: b.5,
                calibrated_window: c.0,
                calibrated_horizon: c.4,
                calibrated_order: c.4.map(|h| 1 + h % 3),
                calibrated_open: u8::from(c.1),
                reason_calibrated: c.2,
                cert_nonlinear: c.3,
                nonlinear_window: d.0,
                nonlinear_open: u8::from(d.1),
                reason_nonlinear: d.2,
                nonlinear_y_lo: d.3,
                nonlinear_y_hi: d.4,
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(500))]
        /// Byte for byte the csv crate's serde writer, row after row (so the caches are
        /// exercised), with and without region columns.
        #[test]
        fn writes_what_the_csv_crate_writes(
            rows in proptest::collection::vec((row(), proptest::collection::vec(number(), 4)), 1..12),
            regions in 0usize..5,
        ) {
            let mut ours = CsvRows::new(regions);
            let mut theirs = csv::WriterBuilder::new().has_headers(false).from_writer(Vec::new());
            for (row, region) in &rows {
                let region = &region[..regions];
                ours.row(row, region);
                if region.is_empty() {
                    theirs.serialize(row).expect("in memory");
                } else {
                    theirs.serialize((row, region)).expect("in memory");
                }
            }
            let theirs = theirs.into_inner().expect("in memory");
            prop_assert_eq!(String::from_utf8_lossy(ours.bytes()), String::from_utf8_lossy(&theirs));
        }

        /// Texts (header names, reasons) are quoted exactly where the csv crate quotes them.
        #[test]
        fn quotes_text_as_the_csv_crate_does(names in proptest::collection::vec("[a-c ,\"\r\n;]{0,6}", 2..5)) {
            let mut ours = CsvRows::new(0);
            ours.header(names.iter().map(String::as_str));
            let mut theirs = csv::WriterBuilder::new().has_headers(false).from_writer(Vec::new());
            theirs.write_record(&names).expect("in memory");
            let theirs = theirs.into_inner().expect("in memory");
            prop_assert_eq!(ours.bytes(), &theirs[..]);
        }
    }
}
