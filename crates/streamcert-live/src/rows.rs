//! What every per-signal source shares: the aligner, the row it fills, its state in a
//! checkpoint, and what a silent signal is told.

use std::time::{Duration, Instant};

use streamcert_pipeline::CliError;
use streamcert_pipeline::input::Sample;
use streamcert_pipeline::source::{Next, SourceReport};

use crate::align::{AlignRule, Aligned, Aligner, Late};

/// Per-signal updates into rows (outputs, then inputs).
pub(crate) struct SignalRows {
    aligner: Aligner,
    row: Vec<f64>,
    outputs: usize,
}

impl SignalRows {
    /// Rows of `signals` values, the first `outputs` of them outputs.
    pub(crate) fn new(signals: usize, outputs: usize, rule: AlignRule) -> Result<Self, CliError> {
        let aligner = Aligner::new(signals, rule)
            .map_err(|m| CliError::Config { path: "[source]".into(), message: m })?;
        Ok(Self { aligner, row: vec![0.0; signals], outputs })
    }

    /// The rule.
    pub(crate) fn rule(&self) -> AlignRule {
        self.aligner.rule()
    }

    /// One signal's update.
    ///
    /// # Errors
    /// [`Late`]: its rows are out already.
    pub(crate) fn push(&mut self, signal: usize, t: f64, v: f64) -> Result<(), Late> {
        self.aligner.push(signal, t, v)
    }

    /// The next row or gap, into `s`; counted in `report`.
    pub(crate) fn next(&mut self, s: &mut Sample, report: &mut SourceReport) -> Option<Next> {
        let next = self.aligner.pop(&mut self.row)?;
        report.stale_rows = self.aligner.stale();
        Some(match next {
            Aligned::Row(t) => {
                s.t = t;
                s.y.clear();
                s.y.extend_from_slice(&self.row[..self.outputs]);
                s.u.clear();
                s.u.extend_from_slice(&self.row[self.outputs..]);
                s.line = report.messages;
                report.rows += 1;
                Next::Row
            }
            Aligned::Gap => {
                report.gaps += 1;
                Next::Gap("a signal was older than max_age or missing".into())
            }
        })
    }

    /// The aligner's state, for a checkpoint.
    pub(crate) fn state(&self) -> Option<serde_json::Value> {
        serde_json::to_value(&self.aligner).ok()
    }

    /// The aligner's state back from a checkpoint, checked before use.
    ///
    /// # Errors
    /// A state that does not parse, is inconsistent, or was written with another rule.
    pub(crate) fn restore(&mut self, state: &serde_json::Value) -> Result<(), CliError> {
        let bad = |message: String| CliError::Checkpoint { path: "[source]".into(), message };
        let saved: Aligner = serde_json::from_value(state.clone())
            .map_err(|e| bad(format!("the aligner's state does not parse: {e}")))?;
        if !saved.is_consistent() {
            return Err(bad("the aligner's state is inconsistent".into()));
        }
        if saved.rule() != self.aligner.rule() || saved.signals() != self.aligner.signals() {
            return Err(bad("the checkpoint was written with another [source.align]".into()));
        }
        self.aligner = saved;
        Ok(())
    }
}

/// Names the signals (topics, nodes) that delivered nothing, once, after `after`.
pub(crate) struct Silence {
    started: Instant,
    after: Duration,
    reported: bool,
}

impl Silence {
    /// From now on.
    pub(crate) fn new(after: Duration) -> Self {
        Self { started: Instant::now(), after, reported: false }
    }

    /// Count from now (the source has just subscribed: what came before was no silence of
    /// a signal).
    pub(crate) fn restart(&mut self) {
        self.started = Instant::now();
    }

    /// Once `after` has passed: the names in `names` whose flag is false, on stderr and in
    /// `report.silent`.
    pub(crate) fn check(&mut self, names: &[(String, bool)], report: &mut SourceReport) {
        if self.reported || self.started.elapsed() < self.after {
            return;
        }
        self.reported = true;
        let silent: Vec<String> =
            names.iter().filter(|(_, seen)| !seen).map(|(t, _)| t.clone()).collect();
        if !silent.is_empty() {
            eprintln!(
                "source: nothing received after {:.0} s on {}",
                self.after.as_secs_f64(),
                silent.join(", ")
            );
        }
        report.silent = silent;
    }
}
