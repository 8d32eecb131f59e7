//! `streamcert certify`: one output row per sample ([`EvidenceWriter`]) and a summary.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use streamcert_certificate::{Certifier, Interval, NotCertified};

use crate::CliError;
use crate::config::Config;
use crate::input::{Sample, SampleReader};
pub use crate::output::Format;
use crate::output::{EvidenceWriter, region_columns};

/// What to do with a malformed row.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BadRows {
    /// Stop with the row's error (exit code 3). Default.
    Stop,
    /// Report it on stderr, count it in the summary, and go on; the row never reaches the
    /// certifier, so the next integral spans the gap using the actual times.
    Skip,
}

/// Options of a run.
#[derive(Debug, Clone)]
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
    /// Flush every row as soon as it is written (for a live input: a pipe or a terminal).
    /// Otherwise the output is buffered and flushed at the end and at each checkpoint.
    pub flush_each_row: bool,
}

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

    /// Share of rows with the nonlinear gate open.
    #[must_use]
    pub fn share_nonlinear(&self) -> f64 {
        if self.rows == 0 { 0.0 } else { self.nonlinear_open as f64 / self.rows as f64 }
    }
}

#[derive(Serialize, Deserialize)]
struct Checkpoint {
    certifier: Certifier,
    summary: Summary,
}

fn save(path: &Path, cert: &Certifier, summary: &Summary) -> Result<(), CliError> {
    let bad = |message: String| CliError::Checkpoint { path: path.display().to_string(), message };
    let cp = Checkpoint { certifier: cert.clone(), summary: summary.clone() };
    let json = serde_json::to_string(&cp).map_err(|e| bad(e.to_string()))?;
    let text =
        streamcert_certificate::seal(&json, cert.config()).map_err(|e| bad(e.to_string()))?;
    write_atomic(path, &text)
}

/// Write `text` to `path` atomically: a unique temporary file beside the target, flushed to
/// disk, then renamed over it, so a crash leaves either the old file or the new one, never a
/// torn one.
///
/// # Errors
/// [`CliError::Io`] naming the checkpoint.
pub(crate) fn write_atomic(path: &Path, text: &str) -> Result<(), CliError> {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let name = path.file_name().map_or_else(|| "checkpoint".into(), |n| n.to_string_lossy());
    let tmp = path.with_file_name(format!(".{name}.{}.{nanos}.tmp", std::process::id()));
    let write = || -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(text.as_bytes())?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)?;
        // Make the rename itself durable where the platform allows opening a directory.
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            if let Ok(d) = std::fs::File::open(dir) {
                let _ = d.sync_all();
            }
        }
        Ok(())
    };
    write().map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        CliError::io(format!("writing the checkpoint {}", path.display()), e)
    })
}

fn load(path: &Path, cfg: &Config) -> Result<(Certifier, Summary), CliError> {
    let bad = |message: String| CliError::Checkpoint { path: path.display().to_string(), message };
    let bytes = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|_| bad("not a streamcert checkpoint (not UTF-8 text)".into()))?;
    let json = streamcert_certificate::unseal(text, Some(&cfg.certifier))
        .map_err(|e| bad(e.to_string()))?;
    let cp: Checkpoint = serde_json::from_str(json).map_err(|e| bad(e.to_string()))?;
    let cert = cp.certifier.verify().map_err(|e| bad(e.to_string()))?;
    if cert.config() != &cfg.certifier {
        return Err(bad("the checkpoint was written with a different configuration".into()));
    }
    Ok((cert, cp.summary))
}

/// Rows a reader thread hands over at a time (when the input is not live).
const BATCH: usize = 1024;

/// Parsed rows in input order: each sample with the outcome of reading it (`None` = parsed).
/// Batches travel back to the reader to be refilled, so their buffers are reused.
struct Batch {
    samples: Vec<Sample>,
    outcomes: Vec<Option<CliError>>,
}

impl Batch {
    fn new() -> Self {
        Self {
            samples: (0..BATCH).map(|_| Sample::default()).collect(),
            outcomes: Vec::with_capacity(BATCH),
        }
    }
}

/// Certify a stream: one output row per accepted input row (flushed per row with
/// [`Options::flush_each_row`]).
///
/// A live input (`flush_each_row`) is read and certified row by row on the calling thread, so
/// every row is answered as soon as its line is complete. Otherwise a second thread reads and
/// parses the input in batches of 1024 rows while this one certifies and writes; the rows,
/// their errors and the output are in input order either way, so the output is the same.
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
    let (mut cert, mut summary) = match &opts.resume {
        Some(path) => load(path, cfg)?,
        None => (
            Certifier::new(cfg.certifier.clone()).map_err(|e| CliError::Config {
                path: "configuration".into(),
                message: e.to_string(),
            })?,
            Summary::default(),
        ),
    };
    let mut reader = SampleReader::new(input, input_name, &cfg.columns)?;
    let io = |e| CliError::io("writing output", e);
    // The region columns: every output and input over the paper's window, then every output
    // over the standing calibrated window.
    let mut channels: Vec<String> =
        cfg.columns.outputs.iter().chain(&cfg.columns.inputs).cloned().collect();
    if cfg.certifier.calibration.is_some() {
        channels.extend(cfg.columns.outputs.iter().map(|o| format!("calibrated_{o}")));
    }
    let writer = EvidenceWriter::new(
        out,
        opts.format,
        opts.resume.is_none(),
        opts.flush_each_row,
        region_columns(&channels),
    )
    .map_err(io)?;
    let region = Vec::with_capacity(channels.len());
    let mut run = Run { cert: &mut cert, summary: &mut summary, writer, opts, input_name, region };
    // Resuming: rows up to the checkpoint's last time at the start of the input are a replay
    // of what the checkpoint already holds (the same file, or a live source restarted after a
    // crash) and are passed over, counted; from the first later row on, times must increase
    // as usual, so an out-of-order row later in the input is still an error.
    let mut replay = run.summary.last_time;
    if opts.flush_each_row {
        let mut s = Sample::default();
        while let Some(next) = reader.next_into(&mut s) {
            run.row(next, &s, &mut replay)?;
        }
    } else {
        std::thread::scope(|scope| -> Result<(), CliError> {
            let (full_tx, full_rx) = std::sync::mpsc::sync_channel::<Batch>(4);
            let (empty_tx, empty_rx) = std::sync::mpsc::channel::<Batch>();
            scope.spawn(move || {
                loop {
                    let mut batch = empty_rx.try_recv().unwrap_or_else(|_| Batch::new());
                    batch.outcomes.clear();
                    let mut done = false;
                    while batch.outcomes.len() < BATCH {
                        let i = batch.outcomes.len();
                        match reader.next_into(&mut batch.samples[i]) {
                            None => {
                                done = true;
                                break;
                            }
                            Some(Ok(())) => batch.outcomes.push(None),
                            Some(Err(e)) => {
                                // Reading stops after an error that is not one row's.
                                done = !matches!(e, CliError::Row(_));
                                batch.outcomes.push(Some(e));
                                if done {
                                    break;
                                }
                            }
                        }
                    }
                    // A closed channel means the certifying side stopped (an error): stop too.
                    if full_tx.send(batch).is_err() || done {
                        return;
                    }
                }
            });
            for mut batch in full_rx {
                for (s, outcome) in batch.samples.iter().zip(batch.outcomes.drain(..)) {
                    run.row(outcome.map_or(Ok(()), Err), s, &mut replay)?;
                }
                // The reader may have finished: a failed return is harmless.
                let _ = empty_tx.send(batch);
            }
            Ok(())
        })?;
    }
    run.writer.flush().map_err(io)?;
    if let Some(path) = &opts.checkpoint {
        save(path, &cert, &summary)?;
    }
    Ok(summary)
}

/// The state of one `certify` run that every row updates.
struct Run<'a, W: Write> {
    cert: &'a mut Certifier,
    summary: &'a mut Summary,
    writer: EvidenceWriter<W>,
    opts: &'a Options,
    input_name: &'a str,
    /// One row's region values (reused).
    region: Vec<Interval>,
}

impl<W: Write> Run<'_, W> {
    /// One input row: `next` is the outcome of reading it into `s`.
    fn row(
        &mut self,
        next: Result<(), CliError>,
        s: &Sample,
        replay: &mut Option<f64>,
    ) -> Result<(), CliError> {
        let (opts, summary) = (self.opts, &mut *self.summary);
        let io = |e| CliError::io("writing output", e);
        match next {
            Ok(()) => {}
            Err(CliError::Row(e)) if opts.bad_rows == BadRows::Skip => {
                // One skip semantics, the library's: not absorbed, counted, every gate closes.
                eprintln!("skipped: {e}");
                summary.skipped += 1;
                self.cert.skip(f64::NAN);
                return Ok(());
            }
            Err(e) => return Err(e),
        }
        if let Some(last) = *replay {
            if s.t <= last {
                summary.replayed += 1;
                return Ok(());
            }
            *replay = None;
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
                    return Ok(());
                }
                return Err(CliError::Row(err));
            }
        };
        summary.rows += 1;
        summary.gaps += u64::from(matches!(ev.gaussian.reason, Some(NotCertified::Gap { .. })));
        let first = |open: bool, first: Option<f64>| first.or(open.then_some(s.t));
        summary.gauss_open += u64::from(ev.gaussian.open);
        summary.wass_open += u64::from(ev.wasserstein.open);
        summary.calibrated_open += u64::from(ev.calibrated.open);
        summary.first_deploy_gauss = first(ev.gaussian.open, summary.first_deploy_gauss);
        summary.first_deploy_wass = first(ev.wasserstein.open, summary.first_deploy_wass);
        summary.first_deploy_calibrated =
            first(ev.calibrated.open, summary.first_deploy_calibrated);
        summary.nonlinear_open += u64::from(ev.nonlinear.open);
        summary.first_deploy_nonlinear = first(ev.nonlinear.open, summary.first_deploy_nonlinear);
        summary.last_time = Some(s.t);
        self.region.clear();
        self.region.extend_from_slice(self.cert.region());
        if self.cert.config().calibration.is_some() {
            let p = self.cert.config().regression.outputs;
            let cal = self.cert.calibrated_region();
            self.region.extend((0..p).map(|i| cal.get(i).copied().unwrap_or(Interval::EMPTY)));
        }
        self.writer.write_with_region(&ev, &self.region).map_err(io)?;
        if let (Some(path), Some(every)) = (&opts.checkpoint, opts.checkpoint_every) {
            if every > 0 && summary.rows % every == 0 {
                // The rows a checkpoint holds are on the output before it is written.
                self.writer.flush().map_err(io)?;
                save(path, self.cert, summary)?;
            }
        }
        Ok(())
    }
}
