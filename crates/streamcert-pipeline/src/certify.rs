//! `streamcert certify`: one output row per sample ([`EvidenceWriter`]) and a summary.
//!
//! A live input (a pipe's `SampleReader` or a live [`Source`]) runs on
//! one thread, row by row, through [`run_source`]. A file runs in three stages
//! (`batched.rs`): one thread reads and parses, a second certifies, the calling thread writes,
//! in batches of 1024 rows carrying their evidence, region values, due checkpoints (sealed
//! bytes, written after the rows they hold are out) and the error that stops the run; the two
//! paths give the same output and checkpoints (tested). `checkpoint.rs`: the sealed checkpoint
//! (binary, or JSON with `seal_checkpoint_as`) written to a unique temporary file, fsynced and
//! renamed; on resume it is refused when damaged or written under another configuration, and
//! the rows it already holds at the start of the input are passed over. `summary.rs`: the
//! run's counts (continued across checkpoints) and its verdict line.

use std::io::{Read, Write};
use std::path::PathBuf;

use streamcert_certificate::{Certifier, Evidence, Interval, NotCertified};

use crate::CliError;
use crate::config::Config;
use crate::input::{Sample, SampleReader};
pub use crate::output::{Flush, Format, Header};
pub use crate::reasons::{reason_phrase, reason_words};
use crate::resume::write_atomic;
use crate::source::{Next, Source};
pub use crate::summary::{HorizonCount, Summary};
use crate::watch::{NoWatch, Watch};

mod batched;
mod checkpoint;
use crate::output::{EvidenceWriter, region_columns};
use checkpoint::{checkpoint_bytes, load, save};
pub use checkpoint::{open_checkpoint, seal_checkpoint, seal_checkpoint_as};

/// What to do with a malformed row.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum BadRows {
    /// Stop with the row's error (exit code 3). Default.
    #[default]
    Stop,
    /// Report it on stderr, count it in the summary, and go on; the row never reaches the
    /// certifier, so the next integral spans the gap using the actual times.
    Skip,
}

/// Options of a run. The default: CSV, stop at a malformed row, no checkpoint, no resume,
/// buffered output, no picture.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// Output format.
    pub format: Format,
    /// Bad-row policy.
    pub bad_rows: BadRows,
    /// Write the streaming state here at the end (and every `checkpoint_every` rows).
    pub checkpoint: Option<PathBuf>,
    /// Checkpoint period in accepted rows.
    pub checkpoint_every: Option<u64>,
    /// Continue from this checkpoint (the header is then not written again, so the outputs
    /// of a split run concatenate to the output of the whole run).
    pub resume: Option<PathBuf>,
    /// When rows reach the output: [`Flush::EachRow`] for a live input (a pipe or a
    /// terminal); buffered (the default) otherwise, flushed at the end and at each checkpoint.
    pub flush: Flush,
    /// Draw a picture of the run into this `.png` or `.svg` file at the end.
    pub plot: Option<PathBuf>,
}

/// Certify a stream: one output row per accepted input row (flushed per row with
/// [`Options::flush`]).
///
/// A live input ([`Flush::EachRow`]) is read, certified and written row by row on the calling
/// thread, so every row is answered as soon as its line is complete. Otherwise one thread
/// reads and parses the input, a second certifies it and this one formats and writes, in
/// batches of 1024 rows; rows, errors, checkpoints and output are in input order either way,
/// so the output is the same (tested).
///
/// # Errors
/// The first malformed row under [`BadRows::Stop`], input/output errors, checkpoint errors.
pub fn run<R: Read + Send, W: Write>(
    cfg: &Config,
    input: R,
    input_name: &str,
    out: &mut W,
    opts: &Options,
) -> Result<Summary, CliError> {
    run_watched(cfg, input, input_name, out, opts, &mut NoWatch)
}

/// [`run`], with `watch` told of every row as it is certified, and of the end
/// ([`crate::watch`]).
///
/// # Errors
/// As [`run`].
pub fn run_watched<R: Read + Send, W: Write>(
    cfg: &Config,
    input: R,
    input_name: &str,
    out: &mut W,
    opts: &Options,
    watch: &mut dyn Watch,
) -> Result<Summary, CliError> {
    let mut reader = SampleReader::new(input, input_name, &cfg.columns)?;
    let summary = if opts.flush == Flush::EachRow {
        run_source_watched(cfg, &mut reader, input_name, out, opts, watch)?
    } else {
        let (mut cert, mut summary, channels) = prepare(cfg, opts)?;
        let mut writer = evidence_writer(out, opts, &channels)?;
        let replay = summary.last_time;
        let step = Step { cert: &mut cert, summary: &mut summary, opts, input_name, replay, watch };
        let outcome = batched::run(step, &mut reader, &mut writer)
            .and_then(|()| conclude(cfg, opts, &mut writer, &cert, &mut summary));
        ended(watch, &summary, outcome.as_ref().err());
        outcome?;
        summary
    };
    no_data_row(&reader, input_name)?;
    Ok(summary)
}

/// A file with its header and no data row has no data, as an empty file has: the same
/// [`CliError::Input`] (exit 3), never a run that ends as if it had certified nothing.
fn no_data_row<R: Read>(reader: &SampleReader<R>, input_name: &str) -> Result<(), CliError> {
    if reader.records() > 0 {
        return Ok(());
    }
    Err(CliError::Input {
        file: input_name.into(),
        message: "no data row: the input has its header and no row after it, so there is \
                  nothing to certify"
            .into(),
    })
}

/// Tell `watch` the run ended with `summary`, and the error that stopped it if one did.
fn ended(watch: &mut dyn Watch, summary: &Summary, error: Option<&CliError>) {
    watch.summary(summary);
    watch.end(error.map(ToString::to_string).as_deref());
}

/// Certify what a [`Source`] yields, row by row on the calling thread, every row flushed as
/// it is written ([`Options::flush`] is taken as [`Flush::EachRow`] whatever it says): a CSV
/// pipe or a live plant source (the `streamcert-live` crate). A gap the source declares
/// starts new windows ([`Certifier::gap`]); a bad payload closes every gate and is counted
/// as a skipped row. With a checkpoint, one is written every `checkpoint_every` rows and
/// whenever the source asks ([`Source::commit_due`]), and the source is told once it is on
/// disk ([`Source::committed`]), so a source with at-least-once delivery acknowledges only
/// what a checkpoint holds. The source's counts go into the summary.
///
/// # Errors
/// As [`run`], and a source's error that ends its stream.
pub fn run_source<W: Write>(
    cfg: &Config,
    source: &mut dyn Source,
    input_name: &str,
    out: &mut W,
    opts: &Options,
) -> Result<Summary, CliError> {
    run_source_watched(cfg, source, input_name, out, opts, &mut NoWatch)
}

/// [`run_source`], with `watch` told of every item as it is certified, of the source's
/// counts when it asks, and of the end ([`crate::watch`]).
///
/// # Errors
/// As [`run_source`].
pub fn run_source_watched<W: Write>(
    cfg: &Config,
    source: &mut dyn Source,
    input_name: &str,
    out: &mut W,
    opts: &Options,
    watch: &mut dyn Watch,
) -> Result<Summary, CliError> {
    let live = Options { flush: Flush::EachRow, ..opts.clone() };
    let opts = &live;
    let (mut cert, mut summary, channels) = prepare(cfg, opts)?;
    if let Some(report) = &summary.source {
        source.restore(report)?;
    }
    let mut writer = evidence_writer(out, opts, &channels)?;
    let replay = summary.last_time;
    let step = Step { cert: &mut cert, summary: &mut summary, opts, input_name, replay, watch };
    let outcome = run_live(step, source, &mut writer, channels.len());
    summary.source = source.report();
    watch.source(summary.source.as_ref());
    let outcome = outcome.and_then(|()| conclude(cfg, opts, &mut writer, &cert, &mut summary));
    ended(watch, &summary, outcome.as_ref().err());
    outcome?;
    if opts.checkpoint.is_some() {
        source.committed()?;
    }
    Ok(summary)
}

/// The certifier and summary a run starts from (fresh, or the checkpoint's), the picture's
/// trace when one is asked for, and the region columns' channels: every output and input
/// over the paper's window, then every output over the standing calibrated window.
fn prepare(cfg: &Config, opts: &Options) -> Result<(Certifier, Summary, Vec<String>), CliError> {
    let (cert, mut summary) = start(cfg, opts)?;
    if opts.plot.is_some() {
        summary.trace = Some(crate::picture::Trace::new());
    }
    let mut channels: Vec<String> =
        cfg.columns.outputs.iter().chain(&cfg.columns.inputs).cloned().collect();
    if cfg.certifier.calibration.is_some() {
        channels.extend(cfg.columns.outputs.iter().map(|o| format!("calibrated_{o}")));
    }
    Ok((cert, summary, channels))
}

/// The run's evidence writer: the header only on a fresh run, so that the outputs of a split
/// run concatenate to the output of the whole run.
fn evidence_writer<'w, W: Write>(
    out: &'w mut W,
    opts: &Options,
    channels: &[String],
) -> Result<EvidenceWriter<&'w mut W>, CliError> {
    EvidenceWriter::new(
        out,
        opts.format,
        Header::when_fresh(opts.resume.as_ref()),
        opts.flush,
        region_columns(channels),
    )
    .map_err(|e| CliError::io("writing output", e))
}

/// The end of a run: the output flushed, the summary closed, the final checkpoint and the
/// picture written.
fn conclude<W: Write>(
    cfg: &Config,
    opts: &Options,
    writer: &mut EvidenceWriter<W>,
    cert: &Certifier,
    summary: &mut Summary,
) -> Result<(), CliError> {
    writer.flush().map_err(|e| CliError::io("writing output", e))?;
    finish(cert, summary);
    if let Some(path) = &opts.checkpoint {
        save(path, cert, summary)?;
    }
    if let (Some(path), Some(trace)) = (&opts.plot, &summary.trace) {
        let name = cfg.columns.outputs.join(", ");
        trace.draw_certify(path, cfg.certifier.margin, &name)?;
    }
    Ok(())
}

/// The configured certifier and an empty summary, or the checkpoint's to resume from.
fn start(cfg: &Config, opts: &Options) -> Result<(Certifier, Summary), CliError> {
    match &opts.resume {
        Some(path) => load(path, cfg),
        None => {
            let cert = Certifier::new(cfg.certifier.clone()).map_err(|e| CliError::Config {
                path: "configuration".into(),
                message: e.to_string(),
            })?;
            Ok((cert, Summary::default()))
        }
    }
}

/// Write a due checkpoint (sealed on the certifying side) where `opts` says, if it does.
fn write_checkpoint(opts: &Options, bytes: &[u8]) -> Result<(), CliError> {
    match &opts.checkpoint {
        Some(path) => write_atomic(path, bytes),
        None => Ok(()),
    }
}

/// A live input: each item of the source taken, certified and written on the calling
/// thread.
fn run_live<W: Write>(
    mut step: Step<'_>,
    source: &mut dyn Source,
    writer: &mut EvidenceWriter<W>,
    channels: usize,
) -> Result<(), CliError> {
    let io = |e| CliError::io("writing output", e);
    let mut s = Sample::default();
    let mut region = Vec::with_capacity(channels);
    while let Some(next) = source.next_into(&mut s) {
        region.clear();
        let row = match next {
            Ok(Next::Row) => step.row(Ok(()), &s, &mut region)?,
            Ok(Next::Gap(why)) => {
                eprintln!("gap: {why}; the windows restart at the next row");
                step.cert.gap();
                step.watch.gap(&why);
                None
            }
            Ok(Next::Bad(e)) => {
                // A live source's bad payload is skipped whatever the policy for a file's
                // rows: the plant goes on publishing.
                step.skip_bad(&e);
                None
            }
            Ok(Next::Idle) => None,
            Err(e) => step.row(Err(e), &s, &mut region)?,
        };
        if step.watch.wants_source() {
            step.watch.source(source.report().as_ref());
        }
        let wrote = row.is_some();
        if let Some(ev) = row {
            writer.write_with_region(&ev, &region).map_err(io)?;
        }
        let due = (wrote && step.checkpoint_every_due()) || source.commit_due();
        if let Some(path) = step.opts.checkpoint.as_ref().filter(|_| due) {
            // The rows a checkpoint holds are on the output before it is written, and the
            // source acknowledges them only once it is on disk.
            writer.flush().map_err(io)?;
            step.summary.source = source.report();
            write_atomic(path, &checkpoint_bytes(path, step.cert, step.summary)?)?;
            source.committed()?;
        }
    }
    Ok(())
}

/// The certifying side of one `certify` run: every accepted row updates it.
struct Step<'a> {
    cert: &'a mut Certifier,
    summary: &'a mut Summary,
    opts: &'a Options,
    input_name: &'a str,
    /// While resuming, the checkpoint's last time: rows up to it are passed over.
    replay: Option<f64>,
    /// Told of every row certified or skipped.
    watch: &'a mut dyn Watch,
}

impl Step<'_> {
    /// One input row: `next` is the outcome of reading it into `s`. `Some` is a row to write,
    /// its region values appended to `region`; `None` a row passed over (skipped or replayed).
    fn row(
        &mut self,
        next: Result<(), CliError>,
        s: &Sample,
        region: &mut Vec<Interval>,
    ) -> Result<Option<Evidence>, CliError> {
        let (opts, summary) = (self.opts, &mut *self.summary);
        match next {
            Ok(()) => {}
            Err(CliError::Row(e)) if opts.bad_rows == BadRows::Skip => {
                self.skip_bad(&e);
                return Ok(None);
            }
            Err(e) => return Err(e),
        }
        if let Some(last) = self.replay {
            if s.t <= last {
                summary.replayed += 1;
                return Ok(None);
            }
            self.replay = None;
        }
        let ev = match self.cert.push(s.t, &s.y, &s.u) {
            Ok(ev) => ev,
            Err(e) => {
                let err = crate::RowError {
                    file: self.input_name.into(),
                    line: s.line,
                    column: None,
                    message: e.to_string(),
                };
                if opts.bad_rows == BadRows::Skip {
                    eprintln!("skipped: {err}");
                    summary.skipped += 1;
                    self.cert.skip(s.t);
                    summary.count_skip();
                    self.watch.skipped(summary);
                    return Ok(None);
                }
                return Err(CliError::Row(err));
            }
        };
        record(self.cert, summary, s.t, &s.y, &ev, region);
        self.watch.sample(self.cert, summary, &ev);
        Ok(Some(ev))
    }

    /// A malformed row or a bad payload, under the one skip semantics, the library's: not
    /// absorbed, counted, every gate closes.
    fn skip_bad(&mut self, e: &crate::RowError) {
        eprintln!("skipped: {e}");
        self.summary.skipped += 1;
        self.cert.skip(f64::NAN);
        self.summary.count_skip();
        self.watch.skipped(self.summary);
    }

    /// The sealed checkpoint due after the row just certified (every `checkpoint_every`
    /// accepted rows), if any.
    fn due_checkpoint(&self) -> Result<Option<Vec<u8>>, CliError> {
        match &self.opts.checkpoint {
            Some(path) if self.checkpoint_every_due() => {
                checkpoint_bytes(path, self.cert, self.summary).map(Some)
            }
            _ => Ok(None),
        }
    }

    /// Whether `checkpoint_every` accepted rows have passed since the last checkpoint.
    fn checkpoint_every_due(&self) -> bool {
        matches!(self.opts.checkpoint_every, Some(every) if every > 0 && self.summary.rows.is_multiple_of(every))
    }
}

/// Count one certified sample into the run's summary and append its region values to
/// `region` (the paper's window's region of every output and input, then, with the
/// calibrated certificate, every output's calibrated region): what `certify` does with every
/// accepted row, shared with the Python package so that both give the same summary.
pub fn record(
    cert: &Certifier,
    summary: &mut Summary,
    t: f64,
    y: &[f64],
    ev: &Evidence,
    region: &mut Vec<Interval>,
) {
    summary.rows += 1;
    if summary.output_ranges.len() != y.len() {
        summary.output_ranges = y.iter().map(|&v| (v, v)).collect();
    }
    for (r, &v) in summary.output_ranges.iter_mut().zip(y) {
        *r = (r.0.min(v), r.1.max(v));
    }
    summary.count_step(t);
    summary.gaps += u64::from(matches!(ev.gaussian.reason, Some(NotCertified::Gap { .. })));
    let first = |open: bool, first: Option<f64>| first.or(open.then_some(t));
    summary.gauss_open += u64::from(ev.gaussian.open);
    summary.wass_open += u64::from(ev.wasserstein.open);
    summary.calibrated_open += u64::from(ev.calibrated.open);
    summary.first_deploy_gauss = first(ev.gaussian.open, summary.first_deploy_gauss);
    summary.first_deploy_wass = first(ev.wasserstein.open, summary.first_deploy_wass);
    summary.first_deploy_calibrated = first(ev.calibrated.open, summary.first_deploy_calibrated);
    summary.nonlinear_open += u64::from(ev.nonlinear.open);
    summary.first_deploy_nonlinear = first(ev.nonlinear.open, summary.first_deploy_nonlinear);
    summary.last_time = Some(t);
    summary.count_calibrated(t, ev);
    summary.count_rungs(t, ev, cert.rungs_status());
    region.extend(cert.region());
    if cert.config().calibration.is_some() {
        let p = cert.config().regression.outputs;
        let mut cal = cert.calibrated_region();
        region.extend((0..p).map(|_| cal.next().unwrap_or(Interval::EMPTY)));
    }
}

/// Close a run's summary: the calibrated region that stands at the end.
pub fn finish(cert: &Certifier, summary: &mut Summary) {
    summary.calibrated_region =
        cert.calibrated_region().map(|r| (r.lo, r.hi)).filter(|(lo, hi)| lo <= hi).collect();
}
