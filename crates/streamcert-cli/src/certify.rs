//! `streamcert certify`: one output row per sample ([`EvidenceWriter`]) and a summary.

use std::io::{Read, Write};
use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use streamcert_certificate::{Certifier, NotCertified};

use crate::CliError;
use crate::config::Config;
use crate::input::{Sample, SampleReader};
use crate::output::EvidenceWriter;
pub use crate::output::Format;

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
}

#[derive(Serialize, Deserialize)]
struct Checkpoint {
    certifier: Certifier,
    summary: Summary,
}

fn save(path: &PathBuf, cert: &Certifier, summary: &Summary) -> Result<(), CliError> {
    let bad = |message: String| CliError::Checkpoint { path: path.display().to_string(), message };
    let cp = Checkpoint { certifier: cert.clone(), summary: summary.clone() };
    let json = serde_json::to_string(&cp).map_err(|e| bad(e.to_string()))?;
    let text =
        streamcert_certificate::seal(&json, cert.config()).map_err(|e| bad(e.to_string()))?;
    // Atomically: a unique temporary file beside the target, flushed to disk, then renamed
    // over it, so a crash leaves either the old checkpoint or the new one, never a torn one.
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

fn load(path: &PathBuf, cfg: &Config) -> Result<(Certifier, Summary), CliError> {
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

/// Certify a stream: one output row per accepted input row (flushed per row with
/// [`Options::flush_each_row`]).
///
/// # Errors
/// The first malformed row under [`BadRows::Stop`], input/output errors, checkpoint errors.
pub fn run<R: Read, W: Write>(
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
    // Resuming: rows up to the checkpoint's last time at the start of the input are a replay
    // of what the checkpoint already holds (the same file, or a live source restarted after a
    // crash) and are passed over, counted; from the first later row on, times must increase
    // as usual, so an out-of-order row later in the input is still an error.
    let mut replay = summary.last_time;
    let io = |e| CliError::io("writing output", e);
    let mut writer =
        EvidenceWriter::new(out, opts.format, opts.resume.is_none(), opts.flush_each_row)
            .map_err(io)?;
    let mut s = Sample::default();
    while let Some(next) = reader.next_into(&mut s) {
        match next {
            Ok(()) => {}
            Err(CliError::Row(e)) if opts.bad_rows == BadRows::Skip => {
                // One skip semantics, the library's: not absorbed, counted, every gate closes.
                eprintln!("skipped: {e}");
                summary.skipped += 1;
                cert.skip(f64::NAN);
                continue;
            }
            Err(e) => return Err(e),
        }
        if let Some(last) = replay {
            if s.t <= last {
                summary.replayed += 1;
                continue;
            }
            replay = None;
        }
        let ev = match cert.push(s.t, &s.y, &s.u) {
            Ok(ev) => ev,
            Err(e) => {
                let err = crate::RowError {
                    file: input_name.into(),
                    line: s.line,
                    column: None,
                    message: e.to_string(),
                };
                if opts.bad_rows == BadRows::Skip {
                    eprintln!("skipped: {err}");
                    summary.skipped += 1;
                    cert.skip(s.t);
                    continue;
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
        summary.last_time = Some(s.t);
        writer.write(&ev).map_err(io)?;
        if let (Some(path), Some(every)) = (&opts.checkpoint, opts.checkpoint_every) {
            if every > 0 && summary.rows % every == 0 {
                // The rows a checkpoint holds are on the output before it is written.
                writer.flush().map_err(io)?;
                save(path, &cert, &summary)?;
            }
        }
    }
    writer.flush().map_err(io)?;
    if let Some(path) = &opts.checkpoint {
        save(path, &cert, &summary)?;
    }
    Ok(summary)
}
