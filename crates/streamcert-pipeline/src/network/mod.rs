//! `streamcert network`: every subsystem's columns of one wide CSV, one certifier per
//! subsystem, the network composed at every epoch; one output row per epoch and a summary.
//!
//! The configuration is the `certify` configuration with the subsystems and couplings added:
//! `[network]`, `[[subsystem]]` (name, outputs, inputs, gain) and `[[coupling]]` (`from`
//! drives `to` with bound `gamma`); `[columns]` gives the time column and the delimiter;
//! `[certificate]`, `[regression]`, `[ambiguity]` and `[calibration]` apply to every
//! subsystem. Each subsystem's certifier configuration is built by the `certify` parser, so
//! the two commands read the same keys the same way.

mod config;
#[cfg(feature = "distributed")]
mod distributed;
mod input;
mod output;
mod verdict;

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use streamcert_network::NetworkCertifier;

pub use config::{EXAMPLE_CONFIG, InputLayout, NetConfig, parse, template};
#[cfg(feature = "distributed")]
pub use distributed::{Cluster, OpenLive, Reopen, SiteInput, SiteReport, run_timely};
use input::{Item, Rows};
use output::EpochWriter;
pub use verdict::{
    epoch_reasons, local_kind, reason_words, summary_json, summary_text, verdict_line,
};

use crate::CliError;
use crate::output::{Flush, Format, Header};
pub use crate::summary::NetSummary;
use crate::watch::{NoWatch, Watch};

/// Options of a `network` run.
#[derive(Debug, Clone)]
pub struct NetOptions {
    /// Output format.
    pub format: Format,
    /// When epoch rows reach the output ([`Flush::EachRow`] for a live input).
    pub flush: Flush,
    /// Write the whole network's state here at the end (and every `checkpoint_every` rows).
    pub checkpoint: Option<PathBuf>,
    /// Checkpoint period in input rows.
    pub checkpoint_every: Option<u64>,
    /// Continue from this checkpoint: rows up to its last time are passed over, no header is
    /// written, so the outputs of a split run concatenate to the output of the whole run.
    pub resume: Option<PathBuf>,
    /// Draw a picture of the run into this `.png` or `.svg` file at the end (one-process
    /// runs).
    pub plot: Option<PathBuf>,
}

#[derive(Serialize, Deserialize)]
struct Checkpoint {
    network: NetworkCertifier,
    summary: NetSummary,
}

/// [`Checkpoint`] borrowed, for writing: the same fields and encoding, without a copy of the
/// network's state.
#[derive(Serialize)]
struct CheckpointRef<'a> {
    network: &'a NetworkCertifier,
    summary: &'a NetSummary,
}

fn save(path: &Path, net: &NetworkCertifier, summary: &NetSummary) -> Result<(), CliError> {
    let bad = |message: String| CliError::Checkpoint { path: path.display().to_string(), message };
    let cp = CheckpointRef { network: net, summary };
    let bytes = streamcert_certificate::seal_value(
        &cp,
        streamcert_certificate::Encoding::Binary,
        net.config(),
    )
    .map_err(|e| bad(crate::resume::inner(e)))?;
    crate::resume::write_atomic(path, &bytes)
}

fn load(path: &Path, cfg: &NetConfig) -> Result<(NetworkCertifier, NetSummary), CliError> {
    let bad = |message: String| CliError::Checkpoint { path: path.display().to_string(), message };
    let bytes = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    let cp: Checkpoint =
        crate::resume::open(&bytes, &cfg.network, |cp: &Checkpoint| cp.network.config())
            .map_err(bad)?;
    let net = cp.network.verify().map_err(|e| bad(e.to_string()))?;
    if net.config() != &cfg.network {
        return Err(bad("the checkpoint was written with a different configuration".into()));
    }
    Ok((net, cp.summary))
}

/// The output columns `gamma_<from>_<to>` of the estimated couplings.
fn estimated_columns(net: &streamcert_network::NetworkConfig, names: &[String]) -> Vec<String> {
    net.estimated.iter().map(|e| format!("gamma_{}_{}", names[e.from], names[e.to])).collect()
}

/// Run the network over a wide CSV stream.
///
/// # Errors
/// Configuration, input rows (the first malformed row stops the run), output, composition
/// and checkpoint errors.
pub fn run<R: Read, W: Write>(
    cfg: &NetConfig,
    input: R,
    input_name: &str,
    out: W,
    opts: &NetOptions,
) -> Result<NetSummary, CliError> {
    run_watched(cfg, input, input_name, out, opts, &mut NoWatch)
}

/// [`run`], with `watch` told of every epoch as it is composed, and of the end
/// ([`crate::watch`]).
///
/// # Errors
/// As [`run`].
pub fn run_watched<R: Read, W: Write>(
    cfg: &NetConfig,
    input: R,
    input_name: &str,
    out: W,
    opts: &NetOptions,
    watch: &mut dyn Watch,
) -> Result<NetSummary, CliError> {
    run_rows(cfg, Rows::new(cfg, input, input_name)?, input_name, out, opts, watch)
}

/// Run the network over wide rows from a live source (`streamcert-live`: every subsystem's
/// columns in one message), in one process, every epoch row flushed. A gap the source
/// declares starts new windows in every subsystem; a bad payload is counted and skipped.
/// With a checkpoint, one is written every `checkpoint_every` rows and whenever the source
/// asks, and the source acknowledges only what a written checkpoint holds.
///
/// # Errors
/// As [`run`], and a source's error that ends its stream.
pub fn run_source<W: Write>(
    cfg: &NetConfig,
    source: Box<dyn crate::source::Source>,
    input_name: &str,
    out: W,
    opts: &NetOptions,
) -> Result<NetSummary, CliError> {
    run_source_watched(cfg, source, input_name, out, opts, &mut NoWatch)
}

/// [`run_source`], with `watch` told of every epoch, gap and bad payload, of the source's
/// counts when it asks, and of the end ([`crate::watch`]).
///
/// # Errors
/// As [`run_source`].
pub fn run_source_watched<W: Write>(
    cfg: &NetConfig,
    source: Box<dyn crate::source::Source>,
    input_name: &str,
    out: W,
    opts: &NetOptions,
    watch: &mut dyn Watch,
) -> Result<NetSummary, CliError> {
    if cfg.layout != InputLayout::Wide {
        return Err(CliError::Config {
            path: input_name.into(),
            message: "a live [source] gives wide rows (every subsystem's columns in one \
                      message): set [network] input = \"wide\""
                .into(),
        });
    }
    let opts = NetOptions { flush: Flush::EachRow, ..opts.clone() };
    run_rows(cfg, Rows::<std::io::Empty>::live(cfg, source), input_name, out, &opts, watch)
}

/// The run over `rows`: the network built (or resumed), every row certified, the epochs
/// written, the checkpoints and the picture.
fn run_rows<R: Read, W: Write>(
    cfg: &NetConfig,
    mut rows: Rows<R>,
    input_name: &str,
    out: W,
    opts: &NetOptions,
    watch: &mut dyn Watch,
) -> Result<NetSummary, CliError> {
    let (mut net, mut summary) = match &opts.resume {
        Some(path) => load(path, cfg)?,
        None => (
            NetworkCertifier::new(cfg.network.clone()).map_err(|e| CliError::Config {
                path: "configuration".into(),
                message: e.to_string(),
            })?,
            NetSummary::default(),
        ),
    };
    let names: Vec<String> = cfg.network.subsystems.iter().map(|s| s.name.clone()).collect();
    if opts.plot.is_some() {
        summary.trace = Some(crate::picture::Trace::new());
    }
    if let (Some(source), Some(report)) = (rows.source(), &summary.source) {
        source.restore(report)?;
    }
    let estimated = estimated_columns(&cfg.network, &names);
    let mut writer = EpochWriter::new(
        out,
        opts.format,
        opts.flush,
        Header::when_fresh(opts.resume.as_ref()),
        estimated,
    );
    let mut run = NetRun { net: &mut net, summary: &mut summary, names: &names, input_name, watch };
    let outcome = run.rows(&mut rows, &mut writer, opts);
    summary.source = rows.source().and_then(|s| s.report());
    watch.source(summary.source.as_ref());
    watch.net_summary(&summary);
    watch.end(outcome.as_ref().err().map(ToString::to_string).as_deref());
    outcome?;
    writer.flush().map_err(|e| CliError::io("writing output", e))?;
    if let Some(path) = &opts.checkpoint {
        save(path, &net, &summary)?;
        if let Some(source) = rows.source() {
            source.committed()?;
        }
    }
    if let (Some(path), Some(trace)) = (&opts.plot, &summary.trace) {
        trace.draw_network(path, cfg.network.margin, &names)?;
    }
    Ok(summary)
}

/// The certifying side of one `network` run.
struct NetRun<'a> {
    net: &'a mut NetworkCertifier,
    summary: &'a mut NetSummary,
    names: &'a [String],
    input_name: &'a str,
    /// Told of every epoch, gap and bad payload.
    watch: &'a mut dyn Watch,
}

impl NetRun<'_> {
    /// Every row of `rows` certified and its epochs written, with the due checkpoints.
    fn rows<R: Read, W: Write>(
        &mut self,
        rows: &mut Rows<R>,
        writer: &mut EpochWriter<W>,
        opts: &NetOptions,
    ) -> Result<(), CliError> {
        let io = |e: std::io::Error| CliError::io("writing output", e);
        // Resuming: rows at the start of the input whose samples every subsystem in them
        // already holds (time not after its newest) are a replay and are passed over, counted.
        let mut replaying = opts.resume.is_some();
        let (mut values, mut items) = (Vec::new(), Vec::new());
        while let Some(next) = rows.next(&mut values, &mut items) {
            let certified = match next? {
                Item::Row(line, t) => self.row(line, t, &values, &items, writer, &mut replaying)?,
                Item::Gap(why) => {
                    eprintln!("gap: {why}; every subsystem's windows restart at the next row");
                    (0..self.names.len()).for_each(|i| self.net.gap(i));
                    self.watch.gap(&why);
                    false
                }
                Item::Bad(e) => {
                    eprintln!("skipped: {e}");
                    self.summary.skipped += 1;
                    self.watch.net_skipped(self.summary);
                    false
                }
                Item::Idle => false,
            };
            if self.watch.wants_source() {
                self.watch.source(rows.source().and_then(|s| s.report()).as_ref());
            }
            let every = matches!(opts.checkpoint_every, Some(n) if n > 0 && self.summary.rows.is_multiple_of(n));
            let asked = rows.source().is_some_and(|s| s.commit_due());
            if let Some(path) = opts.checkpoint.as_ref().filter(|_| (certified && every) || asked) {
                writer.flush().map_err(io)?;
                self.summary.source = rows.source().and_then(|s| s.report());
                save(path, self.net, self.summary)?;
                if let Some(source) = rows.source() {
                    source.committed()?;
                }
            }
        }
        Ok(())
    }

    /// One row at time `t` (`items` index `values` per subsystem): `true` once certified,
    /// `false` when passed over as a replay.
    fn row<W: Write>(
        &mut self,
        line: u64,
        t: f64,
        values: &[f64],
        items: &[(usize, usize, usize, usize)],
        writer: &mut EpochWriter<W>,
        replaying: &mut bool,
    ) -> Result<bool, CliError> {
        if *replaying {
            let held = |i: usize| {
                self.net
                    .subsystem(i)
                    .and_then(|c| c.regression().last_time())
                    .is_some_and(|l| t <= l)
            };
            if items.iter().all(|&(i, ..)| held(i)) {
                self.summary.replayed += 1;
                return Ok(false);
            }
            *replaying = false;
        }
        self.summary.rows += 1;
        self.summary.last_time = Some(t);
        let mut failed: Option<CliError> = None;
        for &(i, start, p, m) in items {
            let (y, u) = (&values[start..start + p], &values[start + p..start + p + m]);
            let (names, summary, watch) = (self.names, &mut *self.summary, &mut *self.watch);
            let pushed = self.net.push(i, t, y, u, |r| {
                if failed.is_none() {
                    if let Err(e) = writer.write(r, names, summary) {
                        failed = Some(CliError::io("writing output", e));
                    }
                    watch.epoch(r, names, summary);
                }
            });
            if let Err(e) = pushed {
                return Err(CliError::Row(crate::RowError {
                    file: self.input_name.into(),
                    line,
                    column: None,
                    message: e.to_string(),
                }));
            }
            if let Some(e) = failed.take() {
                return Err(e);
            }
        }
        Ok(true)
    }
}
