//! The calibrated gate's share of open rows on a public record at fixed integration horizons
//! `h` and base windows `M`, the rest of the configuration at its defaults (only the record's
//! columns, candidate gain and margin kept): how much the verdict's power depends on two
//! numbers a user cannot know. A sensitivity report, not a verdict: choosing the pair that
//! certifies would spend the run's risk `δ` once per pair tried.

use std::fmt::Write as _;

use anyhow::{Context, Result};

use streamcert_pipeline::config::parse;

use super::certify_text;
use crate::common::markdown;

/// The horizons `h` (samples per column) of the grid.
const HORIZONS: [usize; 4] = [1, 2, 5, 10];
/// The base windows `M` (columns) of the grid.
const WINDOWS: [usize; 5] = [40, 60, 100, 150, 300];

/// The record's configuration reduced to its `[columns]` section, its `gain` and its
/// `margin`, with `window = m` and `horizon = h`, or (`None`) both `"auto"`.
pub(super) fn minimal(config: &str, fixed: Option<(usize, usize)>) -> Result<String> {
    let regression = fixed.map_or_else(
        || "\n[regression]\nwindow = \"auto\"\nhorizon = \"auto\"\n".to_string(),
        |(h, m)| format!("\n[regression]\nwindow = {m}\nhorizon = {h}\n"),
    );
    minimal_with(config, &regression)
}

/// The record's columns, gain and margin, then `regression` (a section's text) as given.
pub(super) fn minimal_with(config: &str, regression: &str) -> Result<String> {
    let mut lines = config.lines().skip_while(|l| l.trim() != "[columns]");
    let mut columns = String::new();
    if let Some(head) = lines.next() {
        columns.push_str(head);
        columns.push('\n');
    }
    for l in lines.take_while(|l| !l.trim_start().starts_with('[')) {
        columns.push_str(l);
        columns.push('\n');
    }
    let line = |key: &str| {
        config
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{key} =")))
            .map(|l| l.split('#').next().unwrap_or(l).trim().to_string())
            .with_context(|| format!("no `{key}` in the record's configuration"))
    };
    Ok(format!(
        "{columns}\n[controller]\n{}\n\n[certificate]\n{}\n{regression}",
        line("gain")?,
        line("margin")?,
    ))
}

/// The grid for one record (`name`, its configuration and CSV) as a paragraph of REAL.md.
pub(super) fn grid(name: &str, config: &str, csv: &str) -> Result<String> {
    let mut rows = Vec::new();
    for h in HORIZONS {
        let mut row = vec![format!("h = {h}")];
        for m in WINDOWS {
            let text = minimal(config, Some((h, m)))?;
            // A window shorter than the fit allows (`h (p + m + 1)` columns at least for
            // every window) is refused by the configuration's validation; any other error
            // stops the report.
            row.push(if parse(&text, name).is_err() {
                "refused".to_string()
            } else {
                let c = certify_text(&text, csv, name)?;
                format!("{:.1} %", 100.0 * c.summary.share_calibrated())
            });
        }
        rows.push(row);
    }
    let header: Vec<String> = std::iter::once("h \\ M".to_string())
        .chain(WINDOWS.iter().map(|m| format!("M = {m}")))
        .collect();
    let header: Vec<&str> = header.iter().map(String::as_str).collect();
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{name}: the share of rows with the calibrated gate open at each fixed horizon `h` and base window `M`, every other setting at its default (only the record's columns, gain and margin kept). A sensitivity report: trying pairs until one certifies spends the risk once per pair.\n"
    );
    let _ = writeln!(s, "{}", markdown(&header, &rows));
    let auto = certify_text(&minimal(config, None)?, csv, name)?;
    let _ = writeln!(
        s,
        "With `horizon` and `window` set to `\"auto\"` (the calibrated certificate at h = 1, 2, 5 and 10 side by side, M = 30 h, each at risk δ/4): the gate open on {:.1} % of rows ({}).\n\n{}\n",
        100.0 * auto.summary.share_calibrated(),
        auto.summary
            .first_deploy_calibrated
            .map_or("never opened".into(), |t| format!("first at t = {t} s")),
        auto.summary.horizons_line().unwrap_or_default(),
    );
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::minimal;

    /// The reduced configuration keeps the columns, the gain and the margin (without their
    /// comments) and sets the two numbers; the rest is left to the defaults.
    #[test]
    fn the_reduced_configuration_keeps_columns_gain_and_margin() {
        let config = "# a record\n[columns]\ntime = \"t\"\noutputs = [\"y\"]\n\n[controller]\ngain = [[0.5]]  # K\n\n[certificate]\nconservatism = 0.1\nmargin = 0.05\n\n[regression]\nwindow = 150\nhorizon = 5\n";
        let text = minimal(config, Some((10, 60))).unwrap();
        assert!(text.starts_with("[columns]\ntime = \"t\"\noutputs = [\"y\"]\n"), "{text}");
        assert!(text.contains("gain = [[0.5]]\n") && text.contains("margin = 0.05\n"), "{text}");
        assert!(text.contains("window = 60\nhorizon = 10\n") && !text.contains("conservatism"));
        assert!(minimal("[columns]\n", Some((1, 40))).is_err());
        let auto = minimal(config, None).unwrap();
        assert!(auto.contains("window = \"auto\"\nhorizon = \"auto\"\n"), "{auto}");
        assert!(auto.contains("margin = 0.05\n") && !auto.contains("conservatism"), "{auto}");
    }
}
