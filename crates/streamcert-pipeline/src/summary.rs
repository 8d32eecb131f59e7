//! [`Summary`]: the counts over a `certify` run, and the text and JSON a person reads, whose
//! first line is the calibrated verdict; [`NetSummary`], the same for a `network` run. They sit
//! beneath the runs and their watchers (`certify`, `network` and `watch` all read them).

use serde::{Deserialize, Serialize};
use streamcert_certificate::{CertifierConfig, Evidence, NotCertified, Sig, SigRange};

use crate::reasons::reason_words;

/// Reason kinds as counted, a kind under its earlier name (`rate_dropped`) read under its
/// current one (`rate_below_margin`), so that a resumed run counts them together.
fn current_kinds<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<(String, u64)>, D::Error> {
    let mut kinds = Vec::<(String, u64)>::deserialize(d)?;
    for (kind, _) in &mut kinds {
        if kind == "rate_dropped" {
            *kind = "rate_below_margin".into();
        }
    }
    Ok(kinds)
}

/// The time column's steps kept for [`Summary::time_unit_hint`].
pub(crate) const STEPS_KEPT: usize = 63;

/// Counts over a run (continued across checkpoint and resume).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Rows certified or not (accepted rows).
    pub rows: u64,
    /// Malformed rows skipped (each closes every gate, as the library's
    /// `Certifier::skip`).
    pub skipped: u64,
    /// Gaps in the time column (a step above `gap_factor` times the reference step): the
    /// window restarts there and the row's reason says so.
    #[serde(default)]
    pub gaps: u64,
    /// Rows passed over at the start of a resumed input because the checkpoint already holds
    /// them (times up to its last time).
    #[serde(default)]
    pub replayed: u64,
    /// Rows with the Gaussian gate open.
    pub gauss_open: u64,
    /// Rows with the Wasserstein gate open.
    pub wass_open: u64,
    /// First time the Gaussian gate opened (deployment decision).
    pub first_deploy_gauss: Option<f64>,
    /// First time the Wasserstein gate opened.
    pub first_deploy_wass: Option<f64>,
    /// Rows with the calibrated gate open (0 unless `[calibration]` is enabled).
    #[serde(default)]
    pub calibrated_open: u64,
    /// First time the calibrated gate opened.
    #[serde(default)]
    pub first_deploy_calibrated: Option<f64>,
    /// Rows with the nonlinear gate open (0 unless `[nonlinear]` is enabled).
    #[serde(default)]
    pub nonlinear_open: u64,
    /// First time the nonlinear gate opened.
    #[serde(default)]
    pub first_deploy_nonlinear: Option<f64>,
    /// Time of the last accepted row.
    pub last_time: Option<f64>,
    /// The range `(lo, hi)` of each output over the accepted rows (for the units warning).
    #[serde(default)]
    pub output_ranges: Vec<(f64, f64)>,
    /// While the calibrated gate is open, the time it last opened (`None` while closed).
    #[serde(default)]
    pub calibrated_since: Option<f64>,
    /// Rows with the calibrated gate closed, by kind of reason ([`NotCertified::kind`]), in
    /// the order first seen (a kind under its earlier name read under its current one).
    #[serde(default, deserialize_with = "current_kinds")]
    pub calibrated_reasons: Vec<(String, u64)>,
    /// The calibrated gate's reason at the last row, when closed.
    #[serde(default)]
    pub calibrated_last_reason: Option<NotCertified>,
    /// The last row's reason of each kind of `calibrated_reasons`, in the same order (the
    /// row's own words the verdict quotes; shorter after resuming an older checkpoint).
    #[serde(default)]
    pub calibrated_reason_examples: Vec<Option<NotCertified>>,
    /// The time column's first 63 steps, for the time unit's hint ([`Summary::time_unit_hint`]).
    #[serde(default)]
    pub first_steps: Vec<f64>,
    /// While the Gaussian gate is open, the time it last opened.
    #[serde(default)]
    pub gauss_since: Option<f64>,
    /// The region (output ranges) of the calibrated certificate standing at the last row.
    #[serde(default)]
    pub calibrated_region: Vec<(f64, f64)>,
    /// While the nonlinear (region-valid) gate is open, the time it last opened (`None` while
    /// closed or without `[nonlinear]`).
    #[serde(default)]
    pub nonlinear_since: Option<f64>,
    /// The nonlinear gate's reason at the last row, when closed.
    #[serde(default)]
    pub nonlinear_last_reason: Option<NotCertified>,
    /// The output range `(lo, hi)` the nonlinear certificate standing at the last row speaks
    /// for.
    #[serde(default)]
    pub nonlinear_region: Option<(f64, f64)>,
    /// A live source's counts (messages, bad payloads by kind, late messages, gaps,
    /// reconnections, silent signals) at the end of the run or the last checkpoint; `None`
    /// for a file or a pipe.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<crate::source::SourceReport>,
    /// The rows of the picture (`--plot`), not checkpointed: a resumed run's picture starts at
    /// the resume.
    #[serde(skip)]
    pub trace: Option<crate::picture::Trace>,
    /// With a horizon ladder, each horizon's counts (empty without one).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub horizons: Vec<HorizonCount>,
    /// With a horizon ladder, the horizon `h` whose look the open calibrated verdict was at
    /// the last row.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibrated_horizon: Option<usize>,
    /// With an order ladder (`order = "auto"`), the order `n` whose look the open calibrated
    /// verdict was at the last row.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibrated_order: Option<usize>,
}

impl Summary {
    /// Share of accepted rows with the Gaussian gate open.
    #[must_use]
    pub fn share_gauss(&self) -> f64 {
        if self.rows == 0 { 0.0 } else { self.gauss_open as f64 / self.rows as f64 }
    }
    /// Share of accepted rows with the Wasserstein gate open.
    #[must_use]
    pub fn share_wass(&self) -> f64 {
        if self.rows == 0 { 0.0 } else { self.wass_open as f64 / self.rows as f64 }
    }
    /// Share of accepted rows with the calibrated gate open.
    #[must_use]
    pub fn share_calibrated(&self) -> f64 {
        if self.rows == 0 { 0.0 } else { self.calibrated_open as f64 / self.rows as f64 }
    }

    /// With two or more outputs, the ratio of the widest output range to the narrowest over
    /// the run (`None` with one output, or while an output has not varied). A contraction
    /// rate in the identity metric depends on the units of each output: past `100` the
    /// outputs' units, not the plant, decide the metric, and the summary says to state one
    /// (`[certificate] metric`).
    #[must_use]
    pub fn output_scale_ratio(&self) -> Option<f64> {
        if self.output_ranges.len() < 2 {
            return None;
        }
        let spans = self.output_ranges.iter().map(|(lo, hi)| hi - lo);
        let (mut small, mut large) = (f64::INFINITY, 0.0f64);
        for v in spans {
            small = small.min(v);
            large = large.max(v);
        }
        (small > 0.0).then(|| large / small)
    }

    /// Share of rows with the nonlinear gate open.
    #[must_use]
    pub fn share_nonlinear(&self) -> f64 {
        if self.rows == 0 { 0.0 } else { self.nonlinear_open as f64 / self.rows as f64 }
    }
}

impl Summary {
    /// Count the calibrated verdict of one accepted row at time `t`.
    pub(crate) fn count_calibrated(&mut self, t: f64, ev: &Evidence) {
        self.gauss_since = if ev.gaussian.open { self.gauss_since.or(Some(t)) } else { None };
        if let Some(trace) = &mut self.trace {
            trace.push_evidence(ev);
        }
        if ev.nonlinear.open {
            self.nonlinear_since.get_or_insert(t);
            self.nonlinear_last_reason = None;
            self.nonlinear_region = ev.nonlinear_region.map(|r| (r.lo, r.hi));
        } else {
            self.nonlinear_since = None;
            self.nonlinear_last_reason = ev.nonlinear.reason;
            self.nonlinear_region = None;
        }
        let v = &ev.calibrated;
        if v.open {
            self.calibrated_since.get_or_insert(t);
            self.calibrated_last_reason = None;
            return;
        }
        self.calibrated_since = None;
        if let Some(r) = &v.reason {
            self.count_reason(*r);
        }
    }

    /// Count a skipped row (`--on-bad-row skip`): the certifier closes every gate there
    /// ([`Certifier::skip`](streamcert_certificate::Certifier::skip)), so no gate is open
    /// since an earlier time and a run whose last row is skipped is not certified at its end.
    pub(crate) fn count_skip(&mut self) {
        self.gauss_since = None;
        self.calibrated_since = None;
        self.nonlinear_since = None;
        self.nonlinear_region = None;
        self.nonlinear_last_reason = Some(NotCertified::SkippedSample);
        self.count_reason(NotCertified::SkippedSample);
        self.count_rungs_skip();
    }

    /// One row closed by `r`: counted by kind, and the latest reason.
    fn count_reason(&mut self, r: NotCertified) {
        let kind = r.kind();
        let i = match self.calibrated_reasons.iter().position(|(k, _)| k == kind) {
            Some(i) => i,
            None => {
                self.calibrated_reasons.push((kind.to_string(), 0));
                self.calibrated_reasons.len() - 1
            }
        };
        self.calibrated_reasons[i].1 += 1;
        if self.calibrated_reason_examples.len() <= i {
            self.calibrated_reason_examples.resize(i + 1, None);
        }
        self.calibrated_reason_examples[i] = Some(r);
        self.calibrated_last_reason = Some(r);
    }

    /// Count the step to a row at `t` into the first steps kept.
    pub(crate) fn count_step(&mut self, t: f64) {
        if let Some(last) = self.last_time.filter(|_| self.first_steps.len() < STEPS_KEPT) {
            self.first_steps.push(t - last);
        }
    }

    /// Why the calibrated gate was closed, for the verdict line: the kind that held longest
    /// in words, in how many rows, and the last such row's own words (the bound or the
    /// certificate that decided it); the reason at the last row when it says more.
    fn closed_because(&self) -> String {
        let Some(i) =
            self.calibrated_reasons.iter().enumerate().max_by_key(|(_, (_, n))| *n).map(|(i, _)| i)
        else {
            return "the input held no data row that could be certified, so nothing was \
                    certified (every row passed over)"
                .into();
        };
        let (kind, n) = &self.calibrated_reasons[i];
        let example = self.calibrated_reason_examples.get(i).copied().flatten();
        let mut text = format!("{} in {n} of {} rows", reason_words(kind), self.rows);
        if let Some(r) = example {
            text.push_str(&format!("; the last such row: {r}"));
        }
        match self.calibrated_last_reason {
            Some(last) if Some(last) != example => text.push_str(&format!("; at the end: {last}")),
            _ => {}
        }
        // A plant change is named wherever the change guard closed the gate, also when
        // another reason held more rows (after a change the newest windows soon bound the
        // new plant's rate below the margin, and that reason then holds the most rows).
        let changed = self.calibrated_reasons.iter().find(|(k, _)| k == "plant_changed");
        if let Some((_, rows)) = changed.filter(|(k, _)| k != kind) {
            text.push_str(&format!("; {} in {rows} rows", reason_words("plant_changed")));
        }
        text
    }

    /// The kind of reason that held the calibrated gate closed for the most rows.
    #[must_use]
    pub fn longest_reason(&self) -> Option<&str> {
        self.calibrated_reasons.iter().max_by_key(|(_, n)| *n).map(|(k, _)| k.as_str())
    }

    /// The verdict line: the candidate it judged (the gain and the margin), then the calibrated
    /// verdict at the end of the input (certified since when, at which risk, over which
    /// region; or not, with the reason that held longest), or, without a calibration, that the
    /// paper's gates carry no stated risk.
    #[must_use]
    pub fn verdict_line(&self, cfg: &CertifierConfig, outputs: &[String]) -> String {
        let candidate = candidate(cfg);
        let Some(cal) = &cfg.calibration else {
            return format!(
                "verdict (paper-only mode, NO STATED RISK) {candidate}: the Gaussian gate is \
                 {} at the end; the paper's gates carry no bound on the chance of a false \
                 deployment (enable [calibration] for one)",
                self.gauss_since.map_or_else(
                    || "closed".into(),
                    |t| format!("open since {}", self.when(Some(t)))
                )
            );
        };
        let linear = self.linear_verdict(cal, cfg, outputs, &candidate);
        match (&cfg.nonlinear, outputs.first()) {
            (Some(_), Some(name)) => format!("{linear}; {}", self.nonlinear_verdict(name)),
            _ => linear,
        }
    }

    /// The region-valid (nonlinear) verdict at the end: certified since when over which
    /// output range (the rate bounded at every state of it), or not, with the reason at the
    /// end.
    fn nonlinear_verdict(&self, output: &str) -> String {
        match (self.nonlinear_since, self.nonlinear_region) {
            (Some(since), region) => format!(
                "region-valid verdict: CERTIFIED from {} to the end (nonlinear certificate: the \
                 rate bounded at every state of {output} in {}; its gate closes while {output} \
                 is outside)",
                self.when(Some(since)),
                region.map_or_else(
                    || "(none recorded)".into(),
                    |(lo, hi)| SigRange(lo, hi).to_string()
                )
            ),
            (None, _) => format!(
                "region-valid verdict: NOT CERTIFIED at the end (nonlinear certificate){}",
                self.nonlinear_last_reason.map_or_else(String::new, |r| format!(": {r}"))
            ),
        }
    }

    /// The linear calibrated certificate's verdict at the end (the verdict line's first part).
    fn linear_verdict(
        &self,
        cal: &streamcert_certificate::Calibration,
        cfg: &CertifierConfig,
        outputs: &[String],
        candidate: &str,
    ) -> String {
        match self.calibrated_since {
            Some(since) => {
                let region: Vec<String> = outputs
                    .iter()
                    .zip(&self.calibrated_region)
                    .map(|(name, (lo, hi))| format!("{name} in {}", SigRange(*lo, *hi)))
                    .collect();
                // The risk is stated for one Jacobian over the region; the nonlinearity guard
                // tests that, it does not bound a rate that varies (NONLINEAR.md).
                let order = self.calibrated_order.unwrap_or(cfg.regression.order.order());
                let scope = if order > 1 && cal.nonlinearity {
                    "the nonlinearity guard of order n tests the curvature of the plant's static \
                     term over it, not a nonlinearity of its damping terms"
                } else if order > 1 {
                    "the nonlinearity guard is off"
                } else if cfg.nonlinear.is_some() {
                    "the region-valid verdict after it bounds the rate at every state of a region"
                } else if cal.nonlinearity {
                    "the nonlinearity guard tests this but does not bound a rate that varies \
                     over the region: for a nonlinear scalar loop, `[nonlinear] enabled = true` \
                     adds the region-valid verdict, a rate bounded at every state of the region"
                } else {
                    "the nonlinearity guard is off"
                };
                let at = self.calibrated_horizon.map_or(String::new(), |h| format!(" at h = {h}"));
                let at = if cfg.ladder.is_some() { at } else { String::new() };
                let of = if order > 1 || cfg.orders.is_some() {
                    format!(" of order {order}")
                } else {
                    String::new()
                };
                format!(
                    "verdict: CERTIFIED {candidate} from {} to the end (calibrated certificate{of}{at}, \
                     risk delta = {} over the run), over the region {}; the risk assumes dynamics \
                     linear over that region ({scope})",
                    self.when(Some(since)),
                    Sig(cal.delta),
                    if region.is_empty() { "(none recorded)".into() } else { region.join(", ") }
                )
            }
            None => format!(
                "verdict: NOT CERTIFIED {candidate} at the end (calibrated certificate, risk \
                 delta = {}): {}",
                Sig(cal.delta),
                self.closed_because()
            ),
        }
    }

    /// The text summary (stderr): the verdict line first, then the gates' shares.
    #[must_use]
    pub fn text(&self, cfg: &CertifierConfig, outputs: &[String]) -> String {
        let mut lines = vec![self.verdict_line(cfg, outputs)];
        lines.push(format!(
            "summary: {} rows, {} skipped, {} gaps",
            self.rows, self.skipped, self.gaps
        ));
        if cfg.calibration.is_some() {
            lines.push(format!(
                "calibrated gate (risk delta over the run) open {:.1} % of rows ({})",
                100.0 * self.share_calibrated(),
                self.first(self.first_deploy_calibrated),
            ));
        }
        lines.extend(self.horizons_line());
        if cfg.nonlinear.is_some() {
            lines.push(format!(
                "nonlinear gate (risk delta over the run, every state of the region) open {:.1} % \
                 ({})",
                100.0 * self.share_nonlinear(),
                self.first(self.first_deploy_nonlinear),
            ));
        }
        lines.push(format!(
            "paper's gates (no stated risk): Gaussian open {:.1} % ({}), Wasserstein \
             open {:.1} % ({})",
            100.0 * self.share_gauss(),
            self.first(self.first_deploy_gauss),
            100.0 * self.share_wass(),
            self.first(self.first_deploy_wass),
        ));
        if let Some(report) = &self.source {
            lines.push(report.line());
        }
        if let Some(hint) = self.time_unit_hint() {
            lines.push(format!("hint: {hint}"));
        }
        lines.join("\n")
    }

    /// Whether the verdict at the end is "certified": the calibrated gate open at the last
    /// row, or, in the paper-only mode, the Gaussian gate (for `--require-certified`).
    #[must_use]
    pub fn certified_at_end(&self, cfg: &CertifierConfig) -> bool {
        if cfg.calibration.is_some() {
            self.calibrated_since.is_some()
        } else {
            self.gauss_since.is_some()
        }
    }
}

impl Summary {
    /// A warning when the outputs' ranges differ by more than 100× and no metric was stated
    /// (the units as logged then decide the verdict).
    #[must_use]
    pub fn units_warning(&self, cfg: &CertifierConfig) -> Option<String> {
        let ratio = self.output_scale_ratio().filter(|r| *r > 100.0)?;
        cfg.metric.is_none().then(|| {
            format!(
                "the outputs' ranges differ by a factor of {ratio:.0}: the contraction rate is in \
                 the identity metric of the units as logged, which then decide the verdict; state \
                 the metric you mean ([certificate] metric = [w1, w2, ...], for example the \
                 inverse of each output's typical range)"
            )
        })
    }

    /// The summary as the JSON object `certify --summary FILE` writes (and the Python
    /// package's `CertifyResult.summary` holds): the verdict line first, then the counts,
    /// shares, first deployment times and the calibrated certificate's reasons and region.
    #[must_use]
    pub fn json(&self, cfg: &CertifierConfig, outputs: &[String]) -> serde_json::Value {
        serde_json::json!({
            "verdict": self.verdict_line(cfg, outputs),
            "certified_at_end": self.certified_at_end(cfg),
            "paper_only": cfg.calibration.is_none(),
            "calibrated_since": self.calibrated_since,
            "calibrated_reasons": self.calibrated_reasons,
            "calibrated_region": self.calibrated_region,
            "rows": self.rows, "skipped": self.skipped, "gaps": self.gaps,
            "share_gauss_gate_open": self.share_gauss(), "share_wass_gate_open": self.share_wass(),
            "first_deploy_gauss": self.first_deploy_gauss,
            "first_deploy_wass": self.first_deploy_wass,
            "share_calibrated_gate_open": self.share_calibrated(),
            "first_deploy_calibrated": self.first_deploy_calibrated,
            "share_nonlinear_gate_open": self.share_nonlinear(),
            "first_deploy_nonlinear": self.first_deploy_nonlinear,
            "last_time": self.last_time,
            "output_scale_ratio": self.output_scale_ratio(),
            "warning": self.units_warning(cfg),
            "hint": self.time_unit_hint(),
            "source": self.source,
            "horizons": self.horizons,
            "calibrated_horizon": self.calibrated_horizon,
            "calibrated_order": self.calibrated_order,
        })
    }
}

/// The candidate a verdict judges, as its line names it: `for K = [[-4]] at the margin
/// 0.05 /s` (rows of `K` are its inputs, `m × p`).
fn candidate(cfg: &CertifierConfig) -> String {
    let rows: Vec<String> = cfg
        .gain
        .chunks(cfg.regression.outputs.max(1))
        .map(|row| {
            let row: Vec<String> = row.iter().map(|k| Sig(*k).to_string()).collect();
            format!("[{}]", row.join(", "))
        })
        .collect();
    format!("for K = [{}] at the margin {} /s", rows.join(", "), Sig(cfg.margin))
}

mod time;
pub(crate) use time::at_time;

mod horizons;
mod net;
pub use horizons::HorizonCount;
pub use net::NetSummary;

#[cfg(test)]
mod tests;
