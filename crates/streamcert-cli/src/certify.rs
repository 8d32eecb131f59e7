//! `streamcert certify`: one output row per sample, flushed, and a summary.

use std::io::{Read, Write};
use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use streamcert_certificate::{Certifier, Evidence, NotCertified};

use crate::CliError;
use crate::config::Config;
use crate::input::{Sample, SampleReader};

/// Output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// Comma-separated values with a header.
    Csv,
    /// One JSON object per line.
    Jsonl,
}

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

/// The CSV header of the output.
/// The calibrated columns stay empty (and `calibrated_open` 0) unless `[calibration]` is
/// enabled; `cert_calibrated` is `β̂_w − ρ_w` of the window `calibrated_window` (its own
/// instrumented estimate, not `beta_hat`).
pub const HEADER: &str = "t,beta_hat,rho,eps,kurtosis,spike_fraction,cert_gauss,cert_wass,gauss_open,wass_open,reason_gauss,reason_wass,rho_calibrated,cert_calibrated,calibrated_window,calibrated_open,reason_calibrated";

fn num(v: Option<f64>) -> String {
    v.map_or(String::new(), |x| format!("{x}"))
}

fn row_csv(e: &Evidence) -> String {
    let reason = |r: Option<streamcert_certificate::NotCertified>| {
        r.map_or(String::new(), |r| r.to_string().replace(',', ";"))
    };
    format!(
        "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
        e.t,
        num(e.beta_hat),
        num(e.rho),
        num(e.eps),
        num(e.kurtosis),
        num(e.spike_fraction),
        num(e.cert_gauss),
        num(e.cert_wass),
        u8::from(e.gauss_gate.open),
        u8::from(e.wass_gate.open),
        reason(e.reason),
        reason(e.wass_reason),
        num(e.rho_calibrated),
        num(e.cert_calibrated),
        e.calibrated_window.map_or(String::new(), |w| w.to_string()),
        u8::from(e.calibrated_gate.open),
        reason(e.calibrated_reason)
    )
}

fn row_json(e: &Evidence) -> String {
    let reason = |r: Option<streamcert_certificate::NotCertified>| r.map(|r| r.to_string());
    let v = serde_json::json!({
        "t": e.t, "beta_hat": e.beta_hat, "rho": e.rho, "eps": e.eps, "kurtosis": e.kurtosis,
        "spike_fraction": e.spike_fraction, "cert_gauss": e.cert_gauss, "cert_wass": e.cert_wass,
        "gauss_open": e.gauss_gate.open, "wass_open": e.wass_gate.open,
        "reason_gauss": reason(e.reason), "reason_wass": reason(e.wass_reason),
        "rho_calibrated": e.rho_calibrated, "cert_calibrated": e.cert_calibrated,
        "calibrated_window": e.calibrated_window, "calibrated_open": e.calibrated_gate.open,
        "reason_calibrated": reason(e.calibrated_reason),
    });
    format!("{v}\n")
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

/// Certify a stream: one output row per accepted input row, flushed immediately.
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
    if opts.resume.is_none() && opts.format == Format::Csv {
        writeln!(out, "{HEADER}").map_err(io)?;
    }
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
        summary.gaps += u64::from(matches!(ev.reason, Some(NotCertified::Gap { .. })));
        summary.gauss_open += u64::from(ev.gauss_gate.open);
        summary.wass_open += u64::from(ev.wass_gate.open);
        summary.first_deploy_gauss = summary.first_deploy_gauss.or(ev.gauss_gate.first_opened_at);
        summary.first_deploy_wass = summary.first_deploy_wass.or(ev.wass_gate.first_opened_at);
        summary.calibrated_open += u64::from(ev.calibrated_gate.open);
        summary.first_deploy_calibrated =
            summary.first_deploy_calibrated.or(ev.calibrated_gate.first_opened_at);
        summary.last_time = Some(s.t);
        let line = match opts.format {
            Format::Csv => row_csv(&ev),
            Format::Jsonl => row_json(&ev),
        };
        out.write_all(line.as_bytes()).map_err(io)?;
        out.flush().map_err(io)?;
        if let (Some(path), Some(every)) = (&opts.checkpoint, opts.checkpoint_every) {
            if every > 0 && summary.rows % every == 0 {
                save(path, &cert, &summary)?;
            }
        }
    }
    if let Some(path) = &opts.checkpoint {
        save(path, &cert, &summary)?;
    }
    Ok(summary)
}
