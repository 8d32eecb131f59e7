//! A ladder in the summary: for each rung (a horizon `h`, or with `order = "auto"` an order
//! `n`) its base window, the rows its gate was open and its look stood, and why it was closed
//! the rest of the time, in words ("h = 10 stood on 29 % of rows; h = 1 never opened: the
//! output has dynamics the model does not hold, 61 % of rows").

use serde::{Deserialize, Serialize};
use streamcert_certificate::{Evidence, RungStatus};

use super::Summary;
use crate::reasons::reason_phrase;

/// One rung of a ladder over a run.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct HorizonCount {
    /// The model order `n` (1 on every rung of a horizon ladder).
    #[serde(default = "first_order")]
    pub order: usize,
    /// `h` (samples per column).
    pub horizon: usize,
    /// The base window `M` (columns).
    pub window: usize,
    /// Rows with this horizon's gate open (its own risk `δ / K`).
    pub open: u64,
    /// Rows whose open calibrated verdict was this horizon's look.
    pub stood: u64,
    /// First time its gate opened.
    pub first_open: Option<f64>,
    /// Rows with its gate closed, by kind of reason, in the order first seen.
    pub reasons: Vec<(String, u64)>,
}

impl HorizonCount {
    /// The kind of reason that closed this horizon's gate on the most rows, and on how many.
    fn main_reason(&self) -> Option<(&str, u64)> {
        self.reasons.iter().max_by_key(|(_, n)| *n).map(|(k, n)| (k.as_str(), *n))
    }
}

/// A rung written before orders were counted: the first order.
fn first_order() -> usize {
    1
}

/// `n` of `rows` as a percentage with one decimal.
fn share(n: u64, rows: u64) -> String {
    format!("{:.1} %", if rows == 0 { 0.0 } else { 100.0 * n as f64 / rows as f64 })
}

impl Summary {
    /// Count one accepted row's horizons (nothing without a ladder).
    pub(crate) fn count_rungs(
        &mut self,
        t: f64,
        ev: &Evidence,
        rungs: impl ExactSizeIterator<Item = RungStatus>,
    ) {
        if rungs.len() == 0 {
            return;
        }
        self.calibrated_horizon = ev.calibrated_horizon.filter(|_| ev.calibrated.open);
        self.calibrated_order = ev.calibrated_order.filter(|_| ev.calibrated.open);
        if self.horizons.len() != rungs.len() {
            self.horizons = vec![HorizonCount::default(); rungs.len()];
        }
        for (c, r) in self.horizons.iter_mut().zip(rungs) {
            (c.order, c.horizon, c.window) = (r.order, r.horizon, r.window);
            if r.verdict.open {
                c.open += 1;
                c.first_open.get_or_insert(t);
                let standing = ev.calibrated.open
                    && ev.calibrated_horizon == Some(r.horizon)
                    && ev.calibrated_order == Some(r.order);
                c.stood += u64::from(standing);
            } else if let Some(reason) = r.verdict.reason {
                let kind = reason.kind();
                match c.reasons.iter_mut().find(|(k, _)| k == kind) {
                    Some((_, n)) => *n += 1,
                    None => c.reasons.push((kind.to_string(), 1)),
                }
            }
        }
    }

    /// A skipped row closes every horizon's gate.
    pub(crate) fn count_rungs_skip(&mut self) {
        self.calibrated_horizon = None;
        self.calibrated_order = None;
        for c in &mut self.horizons {
            match c.reasons.iter_mut().find(|(k, _)| k == "skipped_sample") {
                Some((_, n)) => *n += 1,
                None => c.reasons.push(("skipped_sample".into(), 1)),
            }
        }
    }

    /// The rungs in words, for the text summary and the verdict: which stood and on how many
    /// rows, and for each that never opened, the reason that held it closed longest. `None`
    /// without a ladder.
    #[must_use]
    pub fn horizons_line(&self) -> Option<String> {
        if self.horizons.is_empty() {
            return None;
        }
        let k = self.horizons.len();
        let orders = self.horizons.iter().any(|c| c.order > 1);
        let parts: Vec<String> = self
            .horizons
            .iter()
            .map(|c| {
                let head = if orders {
                    format!("order {} (h = {}, M = {})", c.order, c.horizon, c.window)
                } else {
                    format!("h = {} (M = {})", c.horizon, c.window)
                };
                if c.open > 0 {
                    return format!(
                        "{head} open {}, its look the verdict's on {}",
                        share(c.open, self.rows),
                        share(c.stood, self.rows)
                    );
                }
                match c.main_reason() {
                    Some((kind, n)) => format!(
                        "{head} never opened: {} on {}",
                        reason_phrase(kind),
                        share(n, self.rows)
                    ),
                    None => format!("{head} never opened"),
                }
            })
            .collect();
        Some(format!(
            "{} (each at risk delta/{k}, the gate open when any is): {}",
            if orders { "orders" } else { "horizons" },
            parts.join("; ")
        ))
    }
}
