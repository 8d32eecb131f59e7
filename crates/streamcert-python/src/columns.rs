//! [`EvidenceColumns`]: a block of evidence in columns, as numpy and pandas want it.

use streamcert_certificate::{Evidence, EvidenceRow, Interval, NotCertified};

/// The number columns, in the order of the command line's CSV (the certificate crate's
/// [`NUMBER_COLUMNS`](streamcert_certificate::NUMBER_COLUMNS): `EVIDENCE_COLUMNS` without the
/// gates, windows and reasons); an absent value is NaN.
pub use streamcert_certificate::NUMBER_COLUMNS as FLOAT_COLUMNS;
/// The window-length columns (`M_w` of the calibrated and nonlinear looks); absent is NaN.
pub use streamcert_certificate::WINDOW_COLUMNS;

/// The four gates, in the CSV's order: `gauss_open`, `wass_open`, `calibrated_open`,
/// `nonlinear_open`; their reasons are `reason_<gate>` (without `_open`).
pub const GATES: [&str; 4] = ["gauss", "wass", "calibrated", "nonlinear"];

/// The values of the [`FLOAT_COLUMNS`] of one row, in that order.
#[must_use]
pub fn float_values(r: &EvidenceRow) -> [Option<f64>; 13] {
    r.numbers()
}

/// Evidence of consecutive samples, one vector per column: the values the command line
/// writes into its CSV, as numbers (bit for bit the same `f64`s: the CSV prints the shortest
/// text that reads back to them).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EvidenceColumns {
    /// One vector per [`FLOAT_COLUMNS`] name.
    pub floats: [Vec<f64>; 13],
    /// One vector per [`GATES`] name: whether that gate is open.
    pub open: [Vec<bool>; 4],
    /// One vector per [`WINDOW_COLUMNS`] name.
    pub windows: [Vec<f64>; WINDOW_COLUMNS.len()],
    /// One column per [`GATES`] name: why that gate is closed.
    pub reasons: [ReasonColumn; 4],
    /// The region columns' names (`region_lo_<channel>`, `region_hi_<channel>`, as in the CSV).
    pub region_names: Vec<String>,
    /// One vector per region name; NaN where the CSV's field is empty (no region yet).
    pub regions: Vec<Vec<f64>>,
}

impl EvidenceColumns {
    /// Empty columns with room for `n` samples and the region columns `region_names`.
    #[must_use]
    pub fn with_capacity(n: usize, region_names: Vec<String>) -> Self {
        let v = || Vec::with_capacity(n);
        Self {
            floats: std::array::from_fn(|_| v()),
            open: std::array::from_fn(|_| Vec::with_capacity(n)),
            windows: std::array::from_fn(|_| v()),
            reasons: std::array::from_fn(|_| ReasonColumn::with_capacity(n)),
            regions: region_names.iter().map(|_| v()).collect(),
            region_names,
        }
    }

    /// Samples held.
    #[must_use]
    pub fn len(&self) -> usize {
        self.floats[0].len()
    }

    /// Whether no sample is held.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Append one sample's evidence and its region values (one [`Interval`] per region
    /// channel, as the command line's `write_with_region`: a missing or improper interval
    /// is NaN).
    pub fn push(&mut self, ev: &Evidence, region: &[Interval]) {
        let r = EvidenceRow::from(ev);
        let values = float_values(&r);
        for (col, v) in self.floats.iter_mut().zip(values) {
            col.push(v.unwrap_or(f64::NAN));
        }
        let gates = [&ev.gaussian, &ev.wasserstein, &ev.calibrated, &ev.nonlinear];
        for ((open, reason), g) in self.open.iter_mut().zip(&mut self.reasons).zip(gates) {
            open.push(g.open);
            reason.push(g.reason);
        }
        let windows =
            [r.calibrated_window, r.calibrated_horizon, r.calibrated_order, r.nonlinear_window];
        for (col, w) in self.windows.iter_mut().zip(windows) {
            col.push(w.map_or(f64::NAN, |w| w as f64));
        }
        for (i, pair) in self.regions.chunks_exact_mut(2).enumerate() {
            let r = region.get(i).copied().filter(Interval::is_proper);
            pair[0].push(r.map_or(f64::NAN, |r| r.lo));
            pair[1].push(r.map_or(f64::NAN, |r| r.hi));
        }
    }

    /// The reason codes of gate `g` ([`GATES`] index): 0 where the gate is open, otherwise
    /// [`NotCertified::code`] (1 to 21; names in [`NotCertified::KINDS`]).
    #[must_use]
    pub fn reason_codes(&self, g: usize) -> &[u8] {
        &self.reasons[g].codes
    }

    /// The reason texts of gate `g`, exactly the CSV's `reason_<gate>` fields (empty where
    /// the gate is open).
    #[must_use]
    pub fn reason_texts(&self, g: usize) -> Vec<String> {
        self.reasons[g].texts()
    }
}

/// Why one gate is closed, sample by sample, in little memory: a code per sample and the
/// reasons themselves only where they change (a run of samples with the same reason, such as
/// "warming up" or "no nonlinear model configured", holds it once). A block of a million
/// samples then takes 5 bytes per sample and gate instead of the reason's 32.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReasonColumn {
    /// [`NotCertified::code`] per sample, 0 where the gate is open.
    pub codes: Vec<u8>,
    /// Per sample, the position of its reason in `values` (`u32::MAX` where open).
    index: Vec<u32>,
    values: Vec<NotCertified>,
}

impl ReasonColumn {
    fn with_capacity(n: usize) -> Self {
        Self { codes: Vec::with_capacity(n), index: Vec::with_capacity(n), values: Vec::new() }
    }

    /// Append one sample's reason (`None`: the gate is open).
    pub fn push(&mut self, reason: Option<NotCertified>) {
        let Some(r) = reason else {
            self.codes.push(0);
            self.index.push(u32::MAX);
            return;
        };
        self.codes.push(r.code());
        if !self.values.last().is_some_and(|last| last.identical(&r)) {
            self.values.push(r);
        }
        // At most one value per sample, and a block's samples are counted in u32 by numpy's
        // users long before this saturates; a saturated index still names a stored value.
        let at = u32::try_from(self.values.len() - 1).unwrap_or(u32::MAX - 1);
        self.index.push(at);
    }

    /// Samples held.
    #[must_use]
    pub fn len(&self) -> usize {
        self.index.len()
    }

    /// Whether no sample is held.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// The reason of sample `k` (`None`: open or out of range).
    #[must_use]
    pub fn get(&self, k: usize) -> Option<NotCertified> {
        self.index.get(k).and_then(|&i| self.values.get(i as usize)).copied()
    }

    /// The texts, exactly the CSV's `reason_<gate>` fields (`""` where open).
    #[must_use]
    pub fn texts(&self) -> Vec<String> {
        let mut cache: Option<(u32, String)> = None;
        self.index
            .iter()
            .map(|&i| match self.values.get(i as usize) {
                None => String::new(),
                Some(r) => match &cache {
                    Some((j, text)) if *j == i => text.clone(),
                    _ => {
                        let text = r.to_string();
                        cache = Some((i, text.clone()));
                        text
                    }
                },
            })
            .collect()
    }
}
