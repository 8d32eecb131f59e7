//! The public types of a run: its rows, the placement of subsystems on processes, a resume,
//! what the run hands the caller, its outcome and its errors.

use std::path::PathBuf;
use std::time::Duration;

use streamcert_network::{EpochReport, NetworkConfig, NetworkError};

use crate::{ComposerState, SiteState};

/// One input row: its time and the samples it carries, `(subsystem, outputs then inputs)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// The number errors name the row by (its line in the input file, say).
    pub line: u64,
    /// The row's time.
    pub t: f64,
    /// The samples of the row.
    pub samples: Vec<(usize, Vec<f64>)>,
    /// A gap before this row (a live source's outage): the windows of its subsystems
    /// restart here ([`Certifier::gap`](streamcert_certificate::Certifier::gap)), as at a gap
    /// in the time column.
    pub gap: bool,
}

/// Which process reads and certifies each subsystem, this process, and timely's setup.
#[derive(Debug, Clone, PartialEq)]
pub struct Placement {
    /// `process_of[i]`: the process that reads subsystem `i`'s samples.
    pub process_of: Vec<usize>,
    /// Number of processes (timely's `-n`).
    pub processes: usize,
    /// This process (timely's `-p`).
    pub process: usize,
    /// Worker threads per process (timely's `-w`); the first reads the site's rows, and the
    /// samples between two epoch boundaries are certified over this many threads (each a
    /// contiguous range of the site's subsystems); worker 0 also composes.
    pub workers: usize,
    /// One `host:port` per process, in process order (timely's `-h`).
    pub hosts: Option<PathBuf>,
    /// A site whose input gives no row for this long (wall clock) advances its clock by the
    /// time elapsed since its last row. `None`: wait for the input.
    pub silence: Option<Duration>,
}

impl Placement {
    /// Every subsystem in one process with `workers` threads.
    #[must_use]
    pub fn local(n: usize, workers: usize) -> Self {
        Self {
            process_of: vec![0; n],
            processes: 1,
            process: 0,
            workers,
            hosts: None,
            silence: None,
        }
    }

    pub(crate) fn args(&self) -> Vec<String> {
        let mut args = vec!["-w".to_string(), self.workers.max(1).to_string()];
        if self.processes > 1 {
            args.extend(["-n".into(), self.processes.to_string()]);
            args.extend(["-p".into(), self.process.to_string()]);
            if let Some(h) = &self.hosts {
                args.extend(["-h".into(), h.display().to_string()]);
            }
        }
        args
    }

    /// The fingerprint of `cfg` with this placement (what every process must agree on).
    ///
    /// # Errors
    /// The configuration cannot be serialised.
    pub fn fingerprint(&self, cfg: &NetworkConfig) -> Result<u64, String> {
        streamcert_certificate::config_fingerprint(&(cfg, &self.process_of, self.processes))
            .map_err(|e| e.to_string())
    }
}

/// What a process resumes from: its own site, and (process 0) the composer.
#[derive(Debug, Clone, PartialEq)]
pub struct Resume {
    /// This process's site, as checkpointed (`None`: it had crossed no boundary).
    pub site: Option<SiteState>,
    /// Process 0: the composer, as checkpointed.
    pub composer: Option<ComposerState>,
    /// `true`: this process stayed up and rejoins after a lost peer; `false`: it was started
    /// again (after a crash) from its checkpoint.
    pub rejoin: bool,
}

/// What the run hands the caller, on the calling thread, in order.
#[derive(Debug)]
pub enum Output<'a> {
    /// Process 0: an epoch's report.
    Epoch(&'a EpochReport),
    /// Write this process's site checkpoint (checkpoints on).
    Site(&'a SiteState),
    /// Process 0: write the composer's checkpoint (checkpoints on), after the epochs before.
    Composer(&'a ComposerState),
    /// Every process agreed to start: at this epoch (`None`: a new run), with these
    /// processes started again from their checkpoints (the ones that had been down).
    Started {
        /// The epoch the run resumes at.
        resumed_at: Option<u64>,
        /// The processes that were started again (not rejoining from memory).
        restarted: &'a [usize],
    },
}

/// What a run read.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Outcome {
    /// Rows this process certified (counted over resumes).
    pub rows: u64,
    /// Time of its last row.
    pub last_time: Option<f64>,
    /// Process 0: rows over every site, and the latest time.
    pub network_rows: u64,
    /// Process 0: the latest time over every site.
    pub network_last_time: Option<f64>,
    /// Bytes of the messages this process sent to process 0 (bincode, as timely serialises
    /// them; 0 on process 0, whose messages do not cross a process boundary).
    pub bytes_sent: u64,
    /// Messages this process sent to the composer.
    pub messages: u64,
    /// The epoch this run resumed at (`None`: a new run).
    pub resumed_at: Option<u64>,
}

/// Why a run stopped.
#[derive(Debug, thiserror::Error)]
pub enum TimelyError<E: std::error::Error + 'static> {
    /// Timely's arguments or its start failed, or the placement is invalid.
    #[error("timely configuration: {0}")]
    Config(String),
    /// The source rejected the row after row number `row` (1-based count of rows read).
    #[error("{source}")]
    Source {
        /// Rows read before it, plus one.
        row: u64,
        /// The source's error.
        source: E,
    },
    /// The network refused the row named `line` (a time too far ahead, a subsystem it does
    /// not have or another process reads).
    #[error("line {line}: {source}")]
    Network {
        /// The row's [`Row::line`].
        line: u64,
        /// The refusal.
        source: NetworkError,
    },
    /// The row named `line` carries a sample of a subsystem another process reads.
    #[error(
        "line {line}: subsystem {index} (`{name}`) is read by process {owner}, not by this \
         process ({process}): each process's input holds only the subsystems placed on it"
    )]
    NotOwned {
        /// The row's [`Row::line`].
        line: u64,
        /// Subsystem index.
        index: usize,
        /// Its name.
        name: String,
        /// The process it is placed on.
        owner: usize,
        /// This process.
        process: usize,
    },
    /// A subsystem rejected its sample of the row named `line`.
    #[error("line {line}: subsystem {index} (`{name}`): {message}")]
    Subsystem {
        /// The row's [`Row::line`].
        line: u64,
        /// Subsystem index.
        index: usize,
        /// Its name.
        name: String,
        /// The certifier's error.
        message: String,
    },
    /// Process 0: another site stopped (its own process returns the error itself).
    #[error("process {process} stopped at line {line} of its input: {message}")]
    Remote {
        /// The site's process.
        process: usize,
        /// The line of its input.
        line: u64,
        /// Its error.
        message: String,
    },
    /// This process's checkpoint does not fit the run (the start's check).
    #[error("{0}")]
    Checkpoint(String),
    /// Another process's start was refused (its checkpoint or configuration).
    #[error("{0}")]
    PeerRefused(String),
    /// A connection to another process failed (it died): the run is down until every
    /// process is back.
    #[error("a peer process was lost: {0}")]
    PeerLost(String),
    /// The caller's output or checkpoint writer failed.
    #[error("{0}")]
    Output(String),
    /// A worker failed (a panic, or a composition error on worker 0).
    #[error("worker: {0}")]
    Worker(String),
}
