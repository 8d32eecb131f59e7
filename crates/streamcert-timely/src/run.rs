//! [`run`]: certify a network over timely processes, in named steps.

use std::sync::{Arc, Mutex, mpsc};

use streamcert_network::NetworkConfig;

use crate::events::{Event, Failure, Shared, Tx};
use crate::{Outcome, Output, Placement, Resume, Row, TimelyError, worker};

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
    handler: impl FnMut(Output<'_>) -> Result<(), String>,
) -> Result<Outcome, TimelyError<E>>
where
    E: std::error::Error + Send + 'static,
    S: FnOnce() -> I + Send + 'static,
    I: Iterator<Item = Result<Row, E>>,
{
    let resume = checked_start(&cfg, place, resume)?;
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
    let (outcome, failure) = drain(rx, handler);
    // When a peer died, timely's communication threads panicked, and dropping the guards
    // (which joins them) panics too: caught, it is the same lost peer.
    let joined = std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || guards.join()));
    if let Some(e) = lost_peer(joined) {
        // Timely reports a worker's panic without its message; with several processes it is
        // the cascade of a failed connection (this crate's workers do not panic).
        return Err(if place.processes.max(1) > 1 {
            TimelyError::PeerLost(format!("a connection to another process failed ({e})"))
        } else {
            TimelyError::Worker(e)
        });
    }
    match failure {
        None => Ok(outcome),
        Some(f) => Err(into_error(f, &names, place)),
    }
}

/// Every check before any worker starts: the one-process certifier's (each subsystem's
/// certifier included), the placement, and a resumed state against this run (a state that
/// does not fit is refused before any connection).
fn checked_start<E: std::error::Error + 'static>(
    cfg: &NetworkConfig,
    place: &Placement,
    resume: Option<Resume>,
) -> Result<Option<Resume>, TimelyError<E>> {
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
    match resume {
        Some(r) if place.process != 0 && r.composer.is_some() => Err(TimelyError::Checkpoint(
            "only process 0 resumes a composer: this is process 0's checkpoint".into(),
        )),
        Some(Resume { site, composer, rejoin }) => Ok(Some(Resume {
            site: site
                .map(|s| s.verify(cfg, place.process, &place.process_of))
                .transpose()
                .map_err(TimelyError::Checkpoint)?,
            composer: composer
                .map(|c| c.verify(cfg, processes))
                .transpose()
                .map_err(TimelyError::Checkpoint)?,
            rejoin,
        })),
        None => Ok(None),
    }
}

/// The workers' events on the calling thread until they finish: each handed to `handler`
/// (after its first error, none), the outcome gathered, and the failure that counts (this
/// site's own before another site's, else the first).
fn drain<E>(
    rx: mpsc::Receiver<Event<E>>,
    mut handler: impl FnMut(Output<'_>) -> Result<(), String>,
) -> (Outcome, Option<Failure<E>>) {
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
                let remote = |f: &Failure<E>| matches!(f, Failure::Remote { .. });
                if failure.as_ref().is_none_or(|g| remote(g) && !remote(&f)) {
                    failure = Some(f);
                }
            }
        }
    }
    (outcome, failure)
}

/// The message of a worker that failed, from the joined guards or their caught panic.
fn lost_peer<T>(joined: std::thread::Result<Vec<Result<T, String>>>) -> Option<String> {
    match joined {
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
    }
}

/// A failure as the caller's error, subsystems named.
fn into_error<E: std::error::Error + 'static>(
    failure: Failure<E>,
    names: &[String],
    place: &Placement,
) -> TimelyError<E> {
    match failure {
        Failure::Source { row, source } => TimelyError::Source { row, source },
        Failure::Network { line, source } => TimelyError::Network { line, source },
        Failure::NotOwned { line, index, owner } => TimelyError::NotOwned {
            line,
            index,
            name: names.get(index).cloned().unwrap_or_default(),
            owner,
            process: place.process,
        },
        Failure::Subsystem { line, index, message } => {
            let name = names.get(index).cloned().unwrap_or_default();
            TimelyError::Subsystem { line, index, name, message }
        }
        Failure::Remote { process, line, message } => {
            TimelyError::Remote { process, line, message }
        }
        Failure::Checkpoint(m) => TimelyError::Checkpoint(m),
        Failure::PeerRefused(m) => TimelyError::PeerRefused(m),
        Failure::Output(m) => TimelyError::Output(m),
        Failure::Compose(e) => TimelyError::Worker(e.to_string()),
    }
}
