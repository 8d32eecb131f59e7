//! # streamcert-timely
//!
//! The live network certificate of `streamcert-network` across processes and machines, on
//! [timely-dataflow](https://github.com/TimelyDataflow/timely-dataflow). Every process is a
//! *site*: it reads its own input, holding only the subsystems the [`Placement`] gives it,
//! and certifies them itself. Raw samples never leave a site; what crosses to worker 0 (process
//! 0), which composes the epochs with the same [`Composer`] as the one-process
//! [`NetworkCertifier`](streamcert_network::NetworkCertifier), is per epoch the snapshots
//! ([`LocalSnapshot`]: time, verdict, coupling bounds) of the subsystems whose samples changed
//! them, and two marks (the site's first epoch, the epochs its rows made due).
//!
//! **Event time.** The timely timestamp is the epoch index `k` (composed at `t = k · epoch`
//! from every sample at `t < k · epoch`). A site runs its own epoch clock ([`Composer::due`])
//! on its rows; when a row crosses the boundaries `a..b` it sends the changed snapshots at
//! timestamp `a` and advances its input to `b`. Worker 0 composes epoch `k` once timely's
//! frontier has passed `k`: every site has passed it. The epochs composed are those the
//! one-process run over the sites' rows merged in time order composes, from the same
//! snapshots, with the same code: the same reports, bit for bit (tested over three processes).
//!
//! **Pace and memory.** Before a site crosses a boundary `a` it waits until worker 0 has
//! composed every epoch before `a` (a probe on the composer, which holds a capability at its
//! next epoch): no site runs more than one epoch ahead of the composition, so nothing queues
//! without bound when one site is slow, behind in event time, or down. The network runs at
//! the pace of its slowest site. A site whose live input is silent for
//! [`Placement::silence`] of wall-clock time advances its own clock by the wall-clock time
//! elapsed since its last row (the one-process run's `advance` on a clock tick), so its
//! subsystems turn stale under `stale_after` and the network is not certified, instead of
//! holding every epoch back. A time far ahead at one site (within `max_epoch_jump`) makes the
//! epochs up to it due, where the other sites' subsystems are stale, as in one process; beyond
//! `max_epoch_jump` it stops that site with [`NetworkError::TimeJump`].
//!
//! **Checkpoints and restart.** With checkpoints every `e` epochs, every site hands out its
//! [`SiteState`] when a row crosses a boundary range `a..b` holding a multiple of `e` (before
//! it sends anything of the new epochs) and when its input ends, and process 0 its
//! [`ComposerState`] at the run's first epoch and whenever its next epoch is a multiple of
//! `e` (after the reports before it were handed out, before its next epoch shows on the
//! probe). The caller writes them; the worker waits until the caller says they are written.
//! A restarted run resumes at the composer's checkpointed epoch `K`: every site whose
//! checkpoint holds epochs from `valid_from <= K` resumes it and re-sends its snapshots at
//! `K`; a site whose checkpoint is newer than the composer's reads its input again from the
//! start (every send is at a timestamp no earlier than `K`, so the composer sees at `K` the
//! state its rows give at `K`). Either way the reports from `K` on are the uninterrupted
//! run's (tested by restarting from the checkpoints of every moment of a run). At the start
//! every process broadcasts what it resumes from; a process whose checkpoint is of another
//! configuration, placement or run is refused ([`TimelyError::Checkpoint`]) and the others
//! get [`TimelyError::PeerRefused`]. Timely takes the whole computation down when one
//! process dies (its connections fail): the others return [`TimelyError::PeerLost`] and may
//! rejoin from their own checkpoints; no epoch is composed while a process is down (held
//! back until it returns).
//!
//! **Failures.** A row the source rejects, a time too far ahead or a sample a subsystem
//! rejects stops that site, like the one-process run: the epochs before it are composed and
//! reported, no later one; the site returns its error and process 0
//! [`TimelyError::Remote`] naming the site.

mod compose;
mod handshake;
mod ingest;
mod site;
mod wire;
mod worker;

use std::path::PathBuf;
use std::sync::{Arc, Mutex, mpsc};
use std::time::Duration;

pub use compose::ComposerState;
pub use site::SiteState;
use streamcert_network::{EpochReport, NetworkConfig, NetworkError};

/// One input row: its time and the samples it carries, `(subsystem, outputs then inputs)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// The number errors name the row by (its line in the input file, say).
    pub line: u64,
    /// The row's time.
    pub t: f64,
    /// The samples of the row.
    pub samples: Vec<(usize, Vec<f64>)>,
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

    fn args(&self) -> Vec<String> {
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

/// What workers tell the calling thread.
pub(crate) enum Event<E> {
    Started(Option<u64>, Vec<usize>),
    Epoch(Box<EpochReport>),
    Site(Box<SiteState>, mpsc::SyncSender<bool>),
    Composer(Box<ComposerState>, mpsc::SyncSender<bool>),
    Failed(Failure<E>),
    /// This site's outcome.
    Done(Outcome),
    /// Process 0: rows over every site and the latest time.
    Network(u64, Option<f64>),
}

pub(crate) enum Failure<E> {
    Source { row: u64, source: E },
    Network { line: u64, source: NetworkError },
    NotOwned { line: u64, index: usize, owner: usize },
    Subsystem { line: u64, index: usize, message: String },
    Remote { process: usize, line: u64, message: String },
    Checkpoint(String),
    PeerRefused(String),
    Output(String),
    Compose(NetworkError),
}

/// The sender every worker shares.
pub(crate) type Tx<E> = Arc<Mutex<mpsc::Sender<Event<E>>>>;

pub(crate) fn send<E>(tx: &Tx<E>, e: Event<E>) {
    if let Ok(tx) = tx.lock() {
        let _ = tx.send(e);
    }
}

/// Send the event `make` builds and wait for the calling thread's answer (`false`: stop).
pub(crate) fn ask<E>(tx: &Tx<E>, make: impl FnOnce(mpsc::SyncSender<bool>) -> Event<E>) -> bool {
    let (ack, answer) = mpsc::sync_channel(1);
    send(tx, make(ack));
    answer.recv().unwrap_or(false)
}

/// What every worker reads.
pub(crate) struct Shared<S> {
    pub(crate) cfg: NetworkConfig,
    pub(crate) place: Placement,
    pub(crate) fingerprint: u64,
    pub(crate) checkpoints: Option<u64>,
    pub(crate) resume: Mutex<Option<Resume>>,
    pub(crate) source: Mutex<Option<S>>,
}

/// Certify the network `cfg` over the processes of `place`; this process reads `source` (the
/// rows of the subsystems placed on it) and hands what the run produces to `handler` on the
/// calling thread: process 0 every epoch report as it is composed, and with
/// `checkpoints = Some(e)` every process its checkpoints to write, every `e` epochs (the run
/// waits for `handler` to return; an error stops it). `resume`: this process's own
/// checkpoints.
///
/// # Errors
/// [`TimelyError`]: this site's first failure; on process 0 also another site's
/// ([`TimelyError::Remote`]); a refused start; a lost peer.
pub fn run<E, S, I>(
    cfg: NetworkConfig,
    place: &Placement,
    resume: Option<Resume>,
    checkpoints: Option<u64>,
    source: S,
    mut handler: impl FnMut(Output<'_>) -> Result<(), String>,
) -> Result<Outcome, TimelyError<E>>
where
    E: std::error::Error + Send + 'static,
    S: FnOnce() -> I + Send + 'static,
    I: Iterator<Item = Result<Row, E>>,
{
    // Every check of the one-process certifier, including each subsystem's certifier, before
    // any worker starts.
    streamcert_network::NetworkCertifier::new(cfg.clone())
        .map_err(|e| TimelyError::Config(e.to_string()))?;
    let n = cfg.subsystems.len();
    let processes = place.processes.max(1);
    if place.process_of.len() != n {
        return Err(TimelyError::Config(format!(
            "the placement names {} subsystems, the network has {n}",
            place.process_of.len()
        )));
    }
    if let Some(&p) = place.process_of.iter().find(|&&p| p >= processes) {
        return Err(TimelyError::Config(format!(
            "a subsystem is placed on process {p}, but there are {processes} processes"
        )));
    }
    if place.process >= processes {
        return Err(TimelyError::Config(format!("process {} of {processes}", place.process)));
    }
    // A resumed state is checked here, whatever the caller did: a state that does not fit
    // this run is refused before any connection.
    let resume = match resume {
        Some(r) if place.process != 0 && r.composer.is_some() => {
            return Err(TimelyError::Checkpoint(
                "only process 0 resumes a composer: this is process 0's checkpoint".into(),
            ));
        }
        Some(Resume { site, composer, rejoin }) => Some(Resume {
            site: site
                .map(|s| s.verify(&cfg, place.process, &place.process_of))
                .transpose()
                .map_err(TimelyError::Checkpoint)?,
            composer: composer
                .map(|c| c.verify(&cfg, processes))
                .transpose()
                .map_err(TimelyError::Checkpoint)?,
            rejoin,
        }),
        None => None,
    };
    let config =
        timely::Config::from_args(place.args().into_iter()).map_err(TimelyError::Config)?;
    let fingerprint = place.fingerprint(&cfg).map_err(TimelyError::Config)?;
    let (tx, rx) = mpsc::channel::<Event<E>>();
    let tx: Tx<E> = Arc::new(Mutex::new(tx));
    let names: Vec<String> = cfg.subsystems.iter().map(|s| s.name.clone()).collect();
    let shared = Arc::new(Shared {
        cfg,
        place: place.clone(),
        fingerprint,
        checkpoints: checkpoints.map(|e| e.max(1)),
        resume: Mutex::new(resume),
        source: Mutex::new(Some(source)),
    });
    let guards = timely::execute(config, move |w| worker::main(w, &shared, &tx))
        .map_err(TimelyError::Config)?;
    let mut outcome = Outcome::default();
    let mut failure: Option<Failure<E>> = None;
    let mut output_failed = false;
    let mut out = |o: Output<'_>, failure: &mut Option<Failure<E>>| -> bool {
        if output_failed {
            return false;
        }
        match handler(o) {
            Ok(()) => true,
            Err(e) => {
                output_failed = true;
                *failure = Some(Failure::Output(e));
                false
            }
        }
    };
    for event in rx {
        match event {
            Event::Started(resumed_at, restarted) => {
                out(Output::Started { resumed_at, restarted: &restarted }, &mut failure);
            }
            Event::Epoch(r) => {
                out(Output::Epoch(&r), &mut failure);
            }
            Event::Site(s, ack) => {
                let _ = ack.send(out(Output::Site(&s), &mut failure));
            }
            Event::Composer(c, ack) => {
                let _ = ack.send(out(Output::Composer(&c), &mut failure));
            }
            Event::Done(o) => {
                outcome = Outcome {
                    network_rows: outcome.network_rows,
                    network_last_time: outcome.network_last_time,
                    ..o
                };
            }
            Event::Network(rows, last) => {
                outcome.network_rows = rows;
                outcome.network_last_time = last;
            }
            Event::Failed(f) => {
                // This site's own failure before another site's, else the first one.
                let remote = |f: &Failure<E>| matches!(f, Failure::Remote { .. });
                if failure.as_ref().is_none_or(|g| remote(g) && !remote(&f)) {
                    failure = Some(f);
                }
            }
        }
    }
    // When a peer died, timely's communication threads panicked, and dropping the guards
    // (which joins them) panics too: caught, it is the same lost peer.
    let joined = std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || guards.join()));
    let lost = match joined {
        Ok(results) => results.into_iter().find_map(Result::err),
        Err(panic) => Some(
            panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| (*s).to_string()))
                .map_or_else(
                    || "timely communication error".to_string(),
                    |m| format!("timely communication error: {m}"),
                ),
        ),
    };
    if let Some(e) = lost {
        // Timely reports a worker's panic without its message; with several processes it is
        // the cascade of a failed connection (this crate's workers do not panic).
        return Err(if processes > 1 {
            TimelyError::PeerLost(format!("a connection to another process failed ({e})"))
        } else {
            TimelyError::Worker(e)
        });
    }
    match failure {
        None => Ok(outcome),
        Some(Failure::Source { row, source }) => Err(TimelyError::Source { row, source }),
        Some(Failure::Network { line, source }) => Err(TimelyError::Network { line, source }),
        Some(Failure::NotOwned { line, index, owner }) => Err(TimelyError::NotOwned {
            line,
            index,
            name: names.get(index).cloned().unwrap_or_default(),
            owner,
            process: place.process,
        }),
        Some(Failure::Subsystem { line, index, message }) => {
            let name = names.get(index).cloned().unwrap_or_default();
            Err(TimelyError::Subsystem { line, index, name, message })
        }
        Some(Failure::Remote { process, line, message }) => {
            Err(TimelyError::Remote { process, line, message })
        }
        Some(Failure::Checkpoint(m)) => Err(TimelyError::Checkpoint(m)),
        Some(Failure::PeerRefused(m)) => Err(TimelyError::PeerRefused(m)),
        Some(Failure::Output(m)) => Err(TimelyError::Output(m)),
        Some(Failure::Compose(e)) => Err(TimelyError::Worker(e.to_string())),
    }
}
