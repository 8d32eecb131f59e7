//! # streamcert-timely
//!
//! The live network certificate of `streamcert-network` across threads, processes and
//! machines, on [timely-dataflow](https://github.com/TimelyDataflow/timely-dataflow): the
//! subsystems are sharded over timely's workers (subsystem `i` lives on worker
//! `i mod workers`, samples exchanged by subsystem id), and at every composition point every
//! worker sends the newest snapshots of the subsystems it advanced to worker 0, which composes
//! the epochs with the same [`Composer`] as the one-process
//! [`NetworkCertifier`].
//!
//! **Same verdicts as one process, bit for bit.** Worker 0 reads the rows in order and runs
//! the epoch clock ([`Composer::due`]) on each row's time, as the one-process certifier does
//! on each sample: the rows between two composition points form one timely timestamp (a
//! *segment*). A worker advances its subsystems through a segment's samples in row order once
//! timely's frontier says the segment is complete, and worker 0 composes the epochs due after
//! a segment once every worker's snapshots of that segment have arrived. Each subsystem sees
//! exactly its samples in order, and each epoch is composed from exactly the snapshots the
//! one-process run composes it from, with the same code (tested over two processes).
//!
//! **Processes.** [`run`] takes timely's own arguments: `-w` threads per process, `-n`
//! processes, `-p` this process's index, `-h` a host file (one `host:port` per process, in
//! process order). Every process runs the same configuration; the rows are read and the
//! epoch reports produced in process 0 only (the `source` of the other processes is never
//! called).
//!
//! **Failures.** A row the source rejects, a time too far ahead
//! ([`NetworkError::TimeJump`]) or a sample a subsystem rejects stops the run like the
//! one-process run: the epochs due before that row are composed and reported, no later one,
//! and the first failure (in row order) is returned.

mod shard;
mod wire;

use std::cell::RefCell;
use std::collections::{BTreeMap, VecDeque};
use std::ops::Range;
use std::rc::Rc;
use std::sync::{Arc, Mutex, mpsc};

use serde::{Deserialize, Serialize};
use shard::Shard;
use streamcert_network::{
    Composer, EpochReport, LocalSnapshot, NetworkCertifier, NetworkConfig, NetworkError,
};
use timely::container::CapacityContainerBuilder;
use timely::dataflow::channels::pact::Exchange;
use timely::dataflow::operators::generic::operator::Operator;
use timely::dataflow::operators::{Capability, Input, Probe};
use timely::dataflow::{InputHandle, ProbeHandle};
use wire::WireSnapshot;

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

/// What a run read.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Outcome {
    /// Rows read (process 0; 0 elsewhere).
    pub rows: u64,
    /// Time of the last row read.
    pub last_time: Option<f64>,
}

/// Why a run stopped.
#[derive(Debug, thiserror::Error)]
pub enum TimelyError<E: std::error::Error + 'static> {
    /// Timely's arguments or its start failed.
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
    /// not have).
    #[error("line {line}: {source}")]
    Network {
        /// The row's [`Row::line`].
        line: u64,
        /// The refusal.
        source: NetworkError,
    },
    /// A subsystem rejected its sample of the row named `line` (the message crossed processes
    /// as text).
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
    /// A worker failed (a panic, or a composition error on worker 0).
    #[error("worker: {0}")]
    Worker(String),
}

/// A sample on its way to the subsystem's worker.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Sample {
    row: u64,
    line: u64,
    index: u32,
    t: f64,
    values: Vec<f64>,
}

/// What a worker tells worker 0 about one segment.
#[derive(Debug, Clone, Serialize, Deserialize)]
enum ShardMsg {
    Snapshot { index: u32, snapshot: WireSnapshot },
    Failed { row: u64, line: u64, index: u32, message: String },
}

/// What worker 0 tells the calling thread.
enum Event<E> {
    Epoch(EpochReport),
    Failed(Failure<E>),
    Done(Outcome),
}

enum Failure<E> {
    Source { row: u64, source: E },
    Network { row: u64, line: u64, source: NetworkError },
    Subsystem { row: u64, line: u64, index: usize, message: String },
    Compose(NetworkError),
}

impl<E> Failure<E> {
    fn row(&self) -> u64 {
        match self {
            Self::Source { row, .. } | Self::Network { row, .. } | Self::Subsystem { row, .. } => {
                *row
            }
            Self::Compose(_) => 0,
        }
    }
}

/// Certify the network `cfg` on timely with timely's arguments `args` (for example
/// `["-w", "2"]`, or `["-n", "2", "-p", "0", "-h", "hosts.txt"]`); process 0 reads `source`
/// and hands every epoch report to `on_epoch` as it is composed, on the calling thread.
///
/// # Errors
/// [`TimelyError`]: the first failure in row order (the epochs before it are reported).
pub fn run<E, S, I>(
    cfg: NetworkConfig,
    args: &[String],
    source: S,
    mut on_epoch: impl FnMut(&EpochReport),
) -> Result<Outcome, TimelyError<E>>
where
    E: std::error::Error + Send + 'static,
    S: FnOnce() -> I + Send + 'static,
    I: Iterator<Item = Result<Row, E>>,
{
    // Every check of the one-process certifier, including each subsystem's certifier, before
    // any worker starts (a worker must not meet a configuration it cannot build).
    NetworkCertifier::new(cfg.clone()).map_err(|e| TimelyError::Config(e.to_string()))?;
    let config = timely::Config::from_args(args.iter().cloned()).map_err(TimelyError::Config)?;
    let (tx, rx) = mpsc::channel::<Event<E>>();
    let tx = Arc::new(Mutex::new(tx));
    let source = Arc::new(Mutex::new(Some(source)));
    let cfg = Arc::new(cfg);
    let names: Vec<String> = cfg.subsystems.iter().map(|s| s.name.clone()).collect();
    let guards = timely::execute(config, move |worker| {
        let send = |e: Event<E>| {
            if let Ok(tx) = tx.lock() {
                let _ = tx.send(e);
            }
        };
        worker_main(worker, &cfg, &source, &send)
    })
    .map_err(TimelyError::Config)?;
    let mut outcome = Outcome::default();
    let mut failure = None;
    for event in rx {
        match event {
            Event::Epoch(r) => on_epoch(&r),
            Event::Done(o) => outcome = o,
            // The earliest failure in row order (a composition failure first).
            Event::Failed(f) => {
                if failure.as_ref().is_none_or(|g: &Failure<E>| f.row() < g.row()) {
                    failure = Some(f);
                }
            }
        }
    }
    for result in guards.join() {
        result.map_err(TimelyError::Worker)?;
    }
    match failure {
        None => Ok(outcome),
        Some(Failure::Source { row, source }) => Err(TimelyError::Source { row, source }),
        Some(Failure::Network { line, source, .. }) => Err(TimelyError::Network { line, source }),
        Some(Failure::Subsystem { line, index, message, .. }) => {
            let name = names.get(index).cloned().unwrap_or_default();
            Err(TimelyError::Subsystem { line, index, name, message })
        }
        Some(Failure::Compose(e)) => Err(TimelyError::Worker(e.to_string())),
    }
}

type Boundaries = Rc<RefCell<VecDeque<(u64, Range<u64>)>>>;

/// One worker: the shard operator, worker 0's composer and reader.
fn worker_main<E, S, I>(
    worker: &mut timely::worker::Worker,
    cfg: &Arc<NetworkConfig>,
    source: &Mutex<Option<S>>,
    send: &dyn Fn(Event<E>),
) where
    E: std::error::Error + Send + 'static,
    S: FnOnce() -> I + Send + 'static,
    I: Iterator<Item = Result<Row, E>>,
{
    let (index, peers) = (worker.index(), worker.peers());
    let mut input = InputHandle::<u64, CapacityContainerBuilder<Vec<Sample>>>::new();
    let probe = ProbeHandle::new();
    let composer = Rc::new(RefCell::new(Composer::new()));
    let boundaries: Boundaries = Rc::new(RefCell::new(VecDeque::new()));
    let reports: Rc<RefCell<Vec<Event<E>>>> = Rc::new(RefCell::new(Vec::new()));
    worker.dataflow::<u64, _, _>(|scope| {
        let shard_cfg = Arc::clone(cfg);
        let snapshots = scope.input_from(&mut input).unary_frontier(
            Exchange::new(|s: &Sample| u64::from(s.index)),
            "Shard",
            move |_, _| {
                let mut shard = Shard::new(&shard_cfg, index, peers);
                let mut queues: BTreeMap<u64, (Capability<u64>, Vec<Sample>)> = BTreeMap::new();
                move |(input, frontier), output| {
                    input.for_each_stamp(|cap, data| {
                        if let Some(cap) = cap.retain_least(output.output_index()) {
                            let q = queues.entry(*cap.time()).or_insert_with(|| (cap, Vec::new()));
                            for batch in data {
                                q.1.append(batch);
                            }
                        }
                    });
                    while let Some(entry) = queues.first_entry() {
                        if frontier.less_equal(entry.key()) {
                            break;
                        }
                        let (cap, samples) = entry.remove();
                        let mut session = output.session(&cap);
                        shard.segment(&shard_cfg, samples, |m| session.give(m));
                    }
                }
            },
        );
        let compose_cfg = Arc::clone(cfg);
        let (composer, boundaries, reports) =
            (Rc::clone(&composer), Rc::clone(&boundaries), Rc::clone(&reports));
        snapshots
            .unary_frontier::<CapacityContainerBuilder<Vec<()>>, _, _, _>(
                Exchange::new(|_: &ShardMsg| 0),
                "Compose",
                move |_, _| {
                    let mut merged = Merged::new(compose_cfg.subsystems.len());
                    move |(input, frontier), _output| {
                        input.for_each_stamp(|cap, data| {
                            if let Some(&t) = cap.least() {
                                let q = merged.stash.entry(t).or_default();
                                for batch in data {
                                    q.append(batch);
                                }
                            }
                        });
                        let complete = |t: &u64| !frontier.less_equal(t);
                        loop {
                            let next = boundaries.borrow().front().cloned();
                            let Some((segment, due)) = next else { break };
                            if !complete(&segment) {
                                break;
                            }
                            merged.merge_until(&complete, segment, &reports);
                            boundaries.borrow_mut().pop_front();
                            if merged.stopped {
                                continue;
                            }
                            for k in due {
                                match composer.borrow_mut().compose(&compose_cfg, k, &merged.last) {
                                    Ok(r) => reports.borrow_mut().push(Event::Epoch(r)),
                                    Err(e) => {
                                        merged.stopped = true;
                                        reports
                                            .borrow_mut()
                                            .push(Event::Failed(Failure::Compose(e)));
                                        break;
                                    }
                                }
                            }
                        }
                        // Complete segments after the last composition point: only failures
                        // matter there (no epoch is due after them).
                        merged.merge_until(&complete, u64::MAX, &reports);
                    }
                },
            )
            .probe_with(&probe);
    });
    let flush = || {
        for e in reports.borrow_mut().drain(..) {
            send(e);
        }
    };
    if index == 0 {
        let take = source.lock().ok().and_then(|mut s| s.take());
        let mut outcome = Outcome::default();
        if let Some(source) = take {
            let mut segment = 0u64;
            for (row, item) in (1u64..).zip(source()) {
                let r = match item {
                    Ok(r) => r,
                    Err(source) => {
                        send(Event::Failed(Failure::Source { row, source }));
                        break;
                    }
                };
                let due = composer.borrow_mut().due(cfg, r.t);
                match due {
                    Ok(due) if due.is_empty() => {}
                    Ok(due) => {
                        boundaries.borrow_mut().push_back((segment, due));
                        segment += 1;
                        input.advance_to(segment);
                        worker.step();
                        flush();
                    }
                    Err(source) => {
                        send(Event::Failed(Failure::Network { row, line: r.line, source }));
                        break;
                    }
                }
                // A sample of a subsystem the network does not have stops the run, as in one
                // process (`NetworkError::UnknownSubsystem`), before anything of its row is sent.
                let len = cfg.subsystems.len();
                if let Some(&(index, _)) = r.samples.iter().find(|(i, _)| *i >= len) {
                    let source = NetworkError::UnknownSubsystem { index, len };
                    send(Event::Failed(Failure::Network { row, line: r.line, source }));
                    break;
                }
                outcome.rows = row;
                outcome.last_time = Some(r.t);
                for (i, values) in r.samples {
                    let index = u32::try_from(i).unwrap_or(u32::MAX);
                    input.send(Sample { row, line: r.line, index, t: r.t, values });
                }
                if row % 4096 == 0 {
                    worker.step();
                    flush();
                }
            }
        }
        drop(input);
        while !probe.done() {
            worker.step();
            flush();
        }
        flush();
        send(Event::Done(outcome));
    } else {
        drop(input);
        while !probe.done() {
            worker.step();
        }
    }
}

/// Worker 0's view of the shards: every subsystem's newest snapshot, the shards' messages
/// of segments not merged yet, and whether a failure stopped the compositions.
struct Merged {
    last: Vec<Option<LocalSnapshot>>,
    stash: BTreeMap<u64, Vec<ShardMsg>>,
    stopped: bool,
}

impl Merged {
    fn new(n: usize) -> Self {
        Self { last: vec![None; n], stash: BTreeMap::new(), stopped: false }
    }

    /// Merge the complete segments up to `bound` into the newest snapshots; the first segment
    /// with a failure reports its earliest failure and stops the compositions.
    fn merge_until<E>(
        &mut self,
        complete: &impl Fn(&u64) -> bool,
        bound: u64,
        reports: &RefCell<Vec<Event<E>>>,
    ) {
        while let Some(entry) = self.stash.first_entry() {
            if *entry.key() > bound || !complete(entry.key()) {
                break;
            }
            let mut first_failure: Option<(u64, u64, u32, String)> = None;
            for m in entry.remove() {
                match m {
                    ShardMsg::Snapshot { index, snapshot } => {
                        if let Some(slot) = self.last.get_mut(index as usize) {
                            *slot = Some(snapshot.into());
                        }
                    }
                    ShardMsg::Failed { row, line, index, message } => {
                        if first_failure.as_ref().is_none_or(|f| row < f.0) {
                            first_failure = Some((row, line, index, message));
                        }
                    }
                }
            }
            if let (Some((row, line, index, message)), false) = (first_failure, self.stopped) {
                self.stopped = true;
                let index = index as usize;
                let failure = Failure::Subsystem { row, line, index, message };
                reports.borrow_mut().push(Event::Failed(failure));
            }
        }
    }
}
