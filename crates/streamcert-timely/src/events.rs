//! What the workers tell the calling thread ([`Event`], [`Failure`]) over the channel they
//! share ([`Tx`], [`send`], [`ask`]), and what every worker reads ([`Shared`]).

use std::sync::{Arc, Mutex, mpsc};

use streamcert_network::{EpochReport, NetworkConfig, NetworkError};

use crate::{ComposerState, Outcome, Placement, Resume, SiteState};

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

impl<E: std::error::Error> Failure<E> {
    /// A site's failure as text for process 0.
    pub(crate) fn describe(f: &Self, cfg: &NetworkConfig) -> String {
        let name = |i: usize| cfg.subsystems.get(i).map_or("", |s| s.name.as_str()).to_string();
        match f {
            Failure::Source { source, .. } => source.to_string(),
            Failure::Network { source, .. } => source.to_string(),
            Failure::NotOwned { index, owner, .. } => {
                format!("subsystem {index} (`{}`) is read by process {owner}", name(*index))
            }
            Failure::Subsystem { index, message, .. } => {
                format!("subsystem {index} (`{}`): {message}", name(*index))
            }
            Failure::Remote { message, .. }
            | Failure::Checkpoint(message)
            | Failure::PeerRefused(message)
            | Failure::Output(message) => message.clone(),
            Failure::Compose(e) => e.to_string(),
        }
    }
}
