//! The verdict line of a `network` run, the first line of its summary: the network gate at
//! the end, at which risk, and, when it is closed, the reason that held longest and the one
//! at the end.

use serde_json::json;
use streamcert_certificate::Sig;
use streamcert_network::{EpochReport, NetworkConfig, NotCertifiedLocal};

use super::NetSummary;

/// Subsystems named in the reason at the end, at most.
const NAMED: usize = 3;

/// A not-certified subsystem's reason kind: `no_sample`, `stale`, `coupling_unbounded` or the
/// local gate's reason kind ([`NotCertified::kind`](streamcert_certificate::NotCertified::kind)).
#[must_use]
pub fn local_kind(why: &NotCertifiedLocal) -> &'static str {
    match why {
        NotCertifiedLocal::NoSample => "no_sample",
        NotCertifiedLocal::Stale { .. } => "stale",
        NotCertifiedLocal::Local(r) => r.kind(),
        NotCertifiedLocal::CouplingUnbounded { .. } => "coupling_unbounded",
    }
}

/// A network reason's kind in words, with the kind.
fn words(kind: &str) -> String {
    use crate::reasons::reason_words;
    match kind {
        "no_sample" => "a subsystem has no sample yet [no_sample]".into(),
        "stale" => "a subsystem's samples stopped (stale) [stale]".into(),
        "coupling_unbounded" => {
            "an estimated coupling has no upper bound yet [coupling_unbounded]".into()
        }
        "network_below_margin" => "every subsystem certified, the network rate below the margin \
             [network_below_margin]"
            .into(),
        "accumulating_epochs" => {
            "certified, not yet for `consecutive` epochs [accumulating_epochs]".into()
        }
        local => format!("a subsystem is not certified: {}", reason_words(local)),
    }
}

/// Count one epoch `r` into the summary's verdict (`names`: the subsystems' names): the time
/// since which the network gate is open, the network rate, and for a closed gate each kind of
/// reason present at that epoch (once per epoch) and the reason in words.
pub(super) fn count(summary: &mut NetSummary, r: &EpochReport, names: &[String]) {
    summary.open_since = if r.open { summary.open_since.or(Some(r.t)) } else { None };
    summary.last_rate = r.rate;
    if r.open {
        summary.last_reason = None;
        return;
    }
    for kind in epoch_reasons(r) {
        match summary.reasons.iter_mut().find(|(k, _)| k == kind) {
            Some((_, n)) => *n += 1,
            None => summary.reasons.push((kind.to_string(), 1)),
        }
    }
    let named: Vec<String> = r
        .not_certified
        .iter()
        .take(NAMED)
        .map(|(i, why)| format!("{}: {why}", names.get(*i).map_or("?", String::as_str)))
        .collect();
    summary.last_reason = Some(if named.is_empty() {
        match (r.certified, r.rate) {
            (true, _) => "certified, not yet for `consecutive` epochs".into(),
            (false, Some(rate)) => format!("the network rate {} is below the margin", Sig(rate)),
            (false, None) => "no network rate".into(),
        }
    } else if r.not_certified.len() > NAMED {
        format!("{}; and {} more", named.join("; "), r.not_certified.len() - NAMED)
    } else {
        named.join("; ")
    });
}

/// Why the network gate is closed at epoch `r`, by kind, sorted, each once (empty when it is
/// open): the not-certified subsystems' kinds ([`local_kind`]), or `network_below_margin`,
/// or `accumulating_epochs`.
#[must_use]
pub fn epoch_reasons(r: &EpochReport) -> Vec<&'static str> {
    if r.open {
        return Vec::new();
    }
    let mut kinds: Vec<&str> = r.not_certified.iter().map(|(_, why)| local_kind(why)).collect();
    if kinds.is_empty() {
        kinds.push(if r.certified { "accumulating_epochs" } else { "network_below_margin" });
    }
    kinds.sort_unstable();
    kinds.dedup();
    kinds
}

/// A network reason's kind in words, with the kind (the summary's, the status page's and the
/// verdict messages').
#[must_use]
pub fn reason_words(kind: &str) -> String {
    words(kind)
}

/// The verdict line: certified from when to the end, at which run-level risk, over how many
/// subsystems; or not, with the reason that held longest (in how many epochs) and the one at
/// the end; or, composing the paper's certificates, that the verdict carries no stated risk.
#[must_use]
pub fn verdict_line(cfg: &NetworkConfig, s: &NetSummary) -> String {
    let n = cfg.subsystems.len();
    // Epochs fall on `k · epoch`: the step their times resolve.
    let at = |t: f64| crate::summary::at_time(t, Some(cfg.epoch));
    let since = s.open_since.filter(|_| s.open_at_end);
    let Some(risk) = cfg.total_risk() else {
        return format!(
            "verdict (paper-only mode, NO STATED RISK): the network gate is {} at the end; the \
             paper's local certificates carry no bound on the chance of a false deployment \
             ([network] certificate = \"calibrated\" for one)",
            since.map_or_else(|| "closed".into(), |t| format!("open since {}", at(t)))
        );
    };
    match since {
        Some(t) => format!(
            "verdict: network CERTIFIED from {} to the end (the calibrated certificates of \
             {n} subsystems composed, risk delta = {} over the run), network rate {} at the \
             last epoch (margin {}); the risk assumes every subsystem's certificate's \
             assumptions and coupling bounds that hold",
            at(t),
            Sig(risk),
            s.last_rate.map_or_else(|| "none".into(), |r| Sig(r).to_string()),
            Sig(cfg.margin),
        ),
        None => {
            let longest = s.reasons.iter().max_by_key(|(_, k)| *k);
            format!(
                "verdict: network NOT CERTIFIED at the end (the calibrated certificates of {n} \
                 subsystems composed, risk delta = {}); the reason that held longest: {}{}",
                Sig(risk),
                longest.map_or_else(
                    || "none (no epochs)".into(),
                    |(kind, k)| format!("{} (in {k} of {} epochs)", words(kind), s.epochs)
                ),
                s.last_reason.as_ref().map_or_else(String::new, |r| format!("; at the end: {r}")),
            )
        }
    }
}

/// The summary as text (stderr): the verdict line, then the counts.
#[must_use]
pub fn summary_text(cfg: &NetworkConfig, s: &NetSummary) -> String {
    let mut text = format!(
        "{}\nsummary: {} rows ({} replayed), {} epochs, certified in {}, network gate open in {} \
         ({})",
        verdict_line(cfg, s),
        s.rows,
        s.replayed,
        s.epochs,
        s.certified,
        s.open,
        s.first_open.map_or("never opened".into(), |t| {
            format!("first at {}", crate::summary::at_time(t, Some(cfg.epoch)))
        }),
    );
    if let Some(report) = &s.source {
        text.push('\n');
        text.push_str(&report.line());
    }
    text
}

/// The summary as the JSON object `network --summary FILE` writes: the verdict line first,
/// whether the gate is open at the last epoch, the run-level risk (`null` in the paper-only
/// mode), the counts, since when the gate is open, the last network rate, the epochs per
/// reason kind, and the reason at the end.
#[must_use]
pub fn summary_json(cfg: &NetworkConfig, s: &NetSummary) -> serde_json::Value {
    let reasons: serde_json::Map<String, serde_json::Value> =
        s.reasons.iter().map(|(k, n)| (k.clone(), json!(n))).collect();
    json!({
        "verdict": verdict_line(cfg, s),
        "certified_at_end": s.open_at_end,
        "risk": cfg.total_risk(),
        "subsystems": cfg.subsystems.len(),
        "rows": s.rows,
        "replayed": s.replayed,
        "skipped": s.skipped,
        "source": s.source,
        "epochs": s.epochs,
        "certified_epochs": s.certified,
        "open_epochs": s.open,
        "first_open": s.first_open,
        "open_since": s.open_since.filter(|_| s.open_at_end),
        "last_rate": s.last_rate,
        "reasons": reasons,
        "reason_at_end": s.last_reason,
    })
}
