//! `streamcert network` on timely-dataflow (`--workers`, `--processes`, `--process`,
//! `--hostfile`: timely's own `-w`, `-n`, `-p`, `-h`). Every process is a site: it reads its
//! own `--input`, holding the subsystems whose `[[subsystem]] process` is its index, and
//! certifies them; only their epoch snapshots cross to process 0, which composes and writes
//! the epoch rows: those of the one-process run over the sites' rows merged in time order,
//! byte for byte (tested over three processes).
//!
//! **Checkpoints.** `--checkpoint FILE` on a process writes its own sealed checkpoint (the
//! configuration's and placement's fingerprint, its process, its site at the newest epoch
//! boundary it crossed, and on process 0 the composer and the summary). When a peer dies,
//! the other processes reload their own checkpoints and wait for it (their inputs must be
//! files: they are read again from the start, the rows a checkpoint holds passed over);
//! the dead process is restarted with `--resume FILE`. Process 0 writes no epoch row twice
//! while it stays up.

use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use streamcert_timely::{ComposerState, Output, Placement, Resume, SiteState, TimelyError};

use super::config::NetConfig;
mod site_input;
use super::output::EpochWriter;
use super::{NetOptions, NetSummary, estimated_columns};
use crate::output::Header;
use crate::{CliError, RowError};
pub use site_input::{OpenLive, Reopen, SiteInput};
use site_input::{RowIter, check_live, open_site};

/// Timely's process configuration.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Cluster {
    /// Worker threads per process (`-w`, default 1).
    pub workers: Option<usize>,
    /// Number of processes (`-n`, default 1).
    pub processes: Option<usize>,
    /// This process's index (`-p`, default 0).
    pub process: Option<usize>,
    /// One `host:port` per process, in process order (`-h`; default `localhost:2101` and up).
    pub hostfile: Option<PathBuf>,
    /// A site whose input is silent this long (wall clock, seconds) advances its clock (its
    /// subsystems turn stale instead of holding every epoch back).
    pub silence: Option<f64>,
    /// With `--checkpoint`: checkpoint every this many epochs (default 1).
    pub checkpoint_epochs: Option<u64>,
}

impl Cluster {
    /// Whether any option is set (the run then goes through timely).
    #[must_use]
    pub fn is_set(&self) -> bool {
        *self != Self::default()
    }

    /// This process's index.
    #[must_use]
    pub fn index(&self) -> usize {
        self.process.unwrap_or(0)
    }

    fn placement(&self, cfg: &NetConfig) -> Result<Placement, String> {
        let silence = match self.silence {
            Some(s) if s.is_finite() && s > 0.0 => Some(std::time::Duration::from_secs_f64(s)),
            Some(s) => {
                return Err(format!("--silence must be a positive number of seconds, got {s}"));
            }
            None => None,
        };
        let processes = self.processes.unwrap_or(1);
        Ok(Placement {
            // One process reads every subsystem, wherever the configuration places it.
            process_of: if processes > 1 {
                cfg.process_of.clone()
            } else {
                vec![0; cfg.dims.len()]
            },
            processes,
            process: self.index(),
            workers: self.workers.unwrap_or(1),
            hosts: self.hostfile.clone(),
            silence,
        })
    }
}

/// One process's checkpoint on the distributed path.
#[derive(Serialize, Deserialize)]
struct SiteFile {
    process: usize,
    processes: usize,
    site: Option<SiteState>,
    composer: Option<ComposerState>,
    summary: Option<NetSummary>,
}

impl SiteFile {
    /// What a process started again after a crash resumes from, and the summary of the rows
    /// written when it was checkpointed.
    fn restart(self) -> (Option<Resume>, NetSummary) {
        let summary = self.summary.clone().unwrap_or_default();
        (Some(self.resume(false)), summary)
    }

    /// What timely resumes from: this file's site and composer; `rejoin` when this process
    /// stayed up and rejoins after a lost peer (else it was started again after a crash).
    fn resume(self, rejoin: bool) -> Resume {
        Resume { site: self.site, composer: self.composer, rejoin }
    }
}

fn sealed_config<'a>(
    cfg: &'a NetConfig,
    place: &'a Placement,
) -> (&'a streamcert_network::NetworkConfig, &'a Vec<usize>, usize) {
    (&cfg.network, &place.process_of, place.processes)
}

fn save(path: &Path, cfg: &NetConfig, place: &Placement, file: &SiteFile) -> Result<(), String> {
    let bytes = streamcert_certificate::seal_value(
        file,
        streamcert_certificate::Encoding::Binary,
        &sealed_config(cfg, place),
    )
    .map_err(|e| e.to_string())?;
    crate::resume::write_atomic(path, &bytes).map_err(|e| e.to_string())
}

fn load(path: &Path, cfg: &NetConfig, place: &Placement) -> Result<SiteFile, CliError> {
    let bad = |message: String| CliError::Checkpoint { path: path.display().to_string(), message };
    let bytes = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    let sealed =
        streamcert_certificate::unseal(&bytes, Some(&sealed_config(cfg, place))).map_err(|e| {
            bad(format!(
                "{e} (or another placement of the subsystems on the processes, or another \
                 number of processes)"
            ))
        })?;
    let file: SiteFile = sealed.decode().map_err(|e| bad(crate::resume::inner(e)))?;
    if file.process != place.process || file.processes != place.processes {
        return Err(bad(format!(
            "the checkpoint is process {}'s of {}, not process {}'s of {}: give every process \
             its own checkpoint",
            file.process, file.processes, place.process, place.processes
        )));
    }
    let site = match file.site {
        Some(s) => Some(s.verify(&cfg.network, place.process, &place.process_of).map_err(bad)?),
        None => None,
    };
    let composer = match file.composer {
        Some(c) if place.process == 0 => {
            Some(c.verify(&cfg.network, place.processes).map_err(bad)?)
        }
        Some(_) => return Err(bad("only process 0's checkpoint holds the composer".into())),
        None if place.process == 0 => {
            return Err(bad("process 0's checkpoint holds no composer".into()));
        }
        None => None,
    };
    Ok(SiteFile { site, composer, ..file })
}

/// What a distributed run reports beside the summary.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SiteReport {
    /// Rows this process certified.
    pub rows: u64,
    /// Bytes this process sent to process 0 (0 on process 0).
    pub bytes_sent: u64,
    /// Times the run rejoined after a lost peer.
    pub rejoins: u64,
}

/// Quiet the panics timely's threads raise when a peer's connection fails (the run reports
/// the lost peer in one line); every other panic keeps the default report.
fn quiet_timely_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let message = info
                .payload()
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| info.payload().downcast_ref::<&str>().copied())
                .unwrap_or("");
            let timely = ["timely communication error", "MergeQueue poisoned", "Send thread panic"];
            let worker = std::thread::current().name().is_some_and(|n| n.starts_with("timely:"));
            if !(timely.iter().any(|m| message.contains(m)) || worker && message.is_empty()) {
                default(info);
            }
        }));
    });
}

/// Say on standard error that every process is back and the run resumes at epoch `k`, and
/// which processes were started again from their checkpoints.
fn announce_resume(process: usize, k: u64, restarted: &[usize]) {
    let who: Vec<String> = restarted.iter().map(ToString::to_string).collect();
    let again = if who.is_empty() {
        String::new()
    } else {
        format!(
            " (process {} started again from its checkpoint; no epoch was composed while it \
             was down)",
            who.join(", ")
        )
    };
    eprintln!("process {process}: every process is back; the run resumes at epoch {k}{again}");
}

/// Why `--checkpoint-every` is refused over timely.
const CHECKPOINT_EVERY: &str = "--checkpoint-every counts rows of a one-process run: over \
    timely, every process checkpoints at epoch boundaries (every epoch boundary, or \
    --checkpoint-epochs N)";

/// Run this process of the network on timely: read its own input (`open` opens it, again
/// after a lost peer: a file, or a live source for its subsystems' columns), certify its
/// subsystems; process 0 also writes the epoch rows to `out`. A live source's gap or bad
/// payload restarts the windows of this site's subsystems at its next row.
///
/// # Errors
/// Timely's configuration; this process's input, row, output and checkpoint errors; a
/// refused start; a lost peer when the run cannot rejoin (no checkpoint, or standard input).
pub fn run_timely<W: Write>(
    cfg: &NetConfig,
    open: SiteInput<'_>,
    input_name: &str,
    out: W,
    opts: &NetOptions,
    cluster: &Cluster,
) -> Result<(NetSummary, SiteReport), CliError> {
    let bad = |message: String| CliError::Config { path: "timely".into(), message };
    let place = cluster.placement(cfg).map_err(bad)?;
    check_live(cfg, open, &place).map_err(bad)?;
    if opts.checkpoint_every.is_some() {
        return Err(bad(CHECKPOINT_EVERY.into()));
    }
    if place.processes > 1 {
        quiet_timely_panics();
    }
    let names: Vec<String> = cfg.network.subsystems.iter().map(|s| s.name.clone()).collect();
    let (mut resume, mut summary) = match &opts.resume {
        Some(path) => load(path, cfg, &place)?.restart(),
        None => (None, NetSummary::default()),
    };
    let writer = EpochWriter::new(
        out,
        opts.format,
        opts.flush,
        Header::when_fresh(opts.resume.as_ref()),
        estimated_columns(&cfg.network, &names),
    );
    let mut h = Handler {
        writer,
        names,
        written: None,
        site: None,
        composer: None,
        checkpoint: opts.checkpoint.clone(),
        cfg,
        place: &place,
    };
    let mut report = SiteReport::default();
    loop {
        h.site = resume.as_ref().and_then(|r| r.site.clone());
        h.composer = None;
        let (rows_cfg, name, process) = (cfg.clone(), input_name.to_string(), place.process);
        let process_of = place.process_of.clone();
        let input = open_site(cfg, open, &process_of, process)?;
        let source = move || RowIter::opened(&rows_cfg, &process_of, process, input, &name);
        let every = opts.checkpoint.as_ref().map(|_| cluster.checkpoint_epochs.unwrap_or(1).max(1));
        let result = streamcert_timely::run(
            cfg.network.clone(),
            &place,
            resume.take(),
            every,
            source,
            |o| h.handle(o, &mut summary),
        );
        match result {
            Ok(outcome) => {
                h.writer.flush().map_err(|e| CliError::io("writing output", e))?;
                summary.rows = outcome.network_rows;
                summary.last_time = outcome.network_last_time;
                report.rows = outcome.rows;
                report.bytes_sent += outcome.bytes_sent;
                return Ok((summary, report));
            }
            Err(e @ (TimelyError::PeerLost(_) | TimelyError::PeerRefused(_))) => {
                let rejoin = opts.checkpoint.as_ref().filter(|_| input_name != "-");
                let Some(path) = rejoin else {
                    return Err(bad(format!(
                        "{e}; the run is lost (rejoining needs --checkpoint and an input file)"
                    )));
                };
                h.writer.flush().map_err(|e| CliError::io("writing output", e))?;
                report.rejoins += 1;
                eprintln!(
                    "process {}: {e}; rejoining from {} once every process is back",
                    place.process,
                    path.display()
                );
                resume =
                    if path.exists() { Some(load(path, cfg, &place)?.resume(true)) } else { None };
            }
            Err(e) => return Err(map_error(e, input_name, &bad)),
        }
    }
}

/// What this process does with timely's outputs: writes the epoch rows (process 0), and
/// keeps and checkpoints its newest site and composer.
struct Handler<'a, W: Write> {
    writer: EpochWriter<W>,
    names: Vec<String>,
    /// The newest epoch whose row was written (no row twice after a rejoin).
    written: Option<u64>,
    site: Option<SiteState>,
    /// Process 0's file holds its site and the composer with the summary of the rows
    /// written when the composer was checkpointed; either event rewrites it whole.
    composer: Option<(ComposerState, NetSummary)>,
    checkpoint: Option<PathBuf>,
    cfg: &'a NetConfig,
    place: &'a Placement,
}

impl<W: Write> Handler<'_, W> {
    /// Handle one output, the rows written counted into `summary`.
    fn handle(&mut self, o: Output<'_>, summary: &mut NetSummary) -> Result<(), String> {
        match o {
            Output::Started { resumed_at: Some(k), restarted } => {
                announce_resume(self.place.process, k, restarted);
                return Ok(());
            }
            Output::Started { .. } => return Ok(()),
            Output::Epoch(r) => {
                if self.written.is_some_and(|w| r.epoch <= w) {
                    return Ok(());
                }
                self.written = Some(r.epoch);
                return self
                    .writer
                    .write(r, &self.names, summary)
                    .map_err(|e| format!("writing output: {e}"));
            }
            Output::Site(s) => self.site = Some(s.clone()),
            Output::Composer(c) => {
                self.writer.flush().map_err(|e| format!("writing output: {e}"))?;
                self.composer = Some((c.clone(), summary.clone()));
            }
        }
        let Some(path) = &self.checkpoint else { return Ok(()) };
        let (composer, summary) = self.composer.clone().unzip();
        let file = SiteFile {
            process: self.place.process,
            processes: self.place.processes,
            site: self.site.clone(),
            composer,
            summary,
        };
        save(path, self.cfg, self.place, &file)
    }
}

fn map_error(
    e: TimelyError<CliError>,
    input_name: &str,
    bad: &dyn Fn(String) -> CliError,
) -> CliError {
    let row = |line: u64, message: String| {
        CliError::Row(RowError { file: input_name.into(), line, column: None, message })
    };
    match e {
        TimelyError::Source { source, .. } => source,
        TimelyError::Network { line, source } => row(line, source.to_string()),
        e @ TimelyError::NotOwned { line, .. } => {
            let text = e.to_string();
            let message = text.split_once(": ").map_or(text.clone(), |(_, m)| m.to_string());
            row(line, message)
        }
        TimelyError::Subsystem { line, index, name, message } => {
            row(line, format!("subsystem {index} (`{name}`): {message}"))
        }
        // Another site stopped; its own error names its file and line.
        TimelyError::Remote { process, line: 0, message } => {
            CliError::Input { file: format!("process {process}"), message }
        }
        TimelyError::Remote { process, line, message } => CliError::Row(RowError {
            file: format!("process {process}'s input"),
            line,
            column: None,
            message,
        }),
        TimelyError::Checkpoint(m) => CliError::Checkpoint { path: "--resume".into(), message: m },
        TimelyError::Output(m) => CliError::io(m, std::io::Error::other("the run stopped")),
        e @ (TimelyError::Config(_)
        | TimelyError::Worker(_)
        | TimelyError::PeerLost(_)
        | TimelyError::PeerRefused(_)) => bad(e.to_string()),
    }
}
