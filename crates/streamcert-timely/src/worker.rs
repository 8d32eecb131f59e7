//! One timely worker: the start's handshake, the composing operator (worker 0), and the site
//! (the first worker of every process), which reads this process's rows on a reader thread.

use std::collections::BTreeMap;
use std::sync::mpsc::{self, RecvTimeoutError, TryRecvError};
use std::time::{Duration, Instant};

use streamcert_network::NetworkError;
use timely::container::CapacityContainerBuilder;
use timely::dataflow::channels::pact::Exchange;
use timely::dataflow::operators::generic::operator::Operator;
use timely::dataflow::operators::{Input, Probe};
use timely::dataflow::{InputHandle, ProbeHandle};

use crate::wire::Msg;
use crate::{
    ComposerState, Event, Failure, Outcome, Row, Shared, SiteState, Tx, ask, handshake, send,
};

type MsgInput = InputHandle<u64, CapacityContainerBuilder<Vec<Msg>>>;

/// One worker of the run.
pub(crate) fn main<E, S, I>(worker: &mut timely::worker::Worker, sh: &Shared<S>, tx: &Tx<E>)
where
    E: std::error::Error + Send + 'static,
    S: FnOnce() -> I + Send + 'static,
    I: Iterator<Item = Result<Row, E>>,
{
    let index = worker.index();
    let site_worker = index == sh.place.process * sh.place.workers.max(1);
    let resume = if site_worker { sh.resume.lock().ok().and_then(|mut r| r.take()) } else { None };
    let site_resumed = resume.as_ref().and_then(|r| r.site.as_ref());
    let composer_resumed = resume.as_ref().and_then(|r| r.composer.as_ref());
    let hello = site_worker.then(|| handshake::Hello {
        process: u32::try_from(sh.place.process).unwrap_or(u32::MAX),
        fingerprint: sh.fingerprint,
        run: composer_resumed
            .map(ComposerState::run_id)
            .or_else(|| site_resumed.map(SiteState::run_id))
            .unwrap_or_else(new_run_id),
        composer_next: composer_resumed.and_then(ComposerState::next_epoch),
        resumed: resume.is_some(),
        valid_from: site_resumed.map(SiteState::valid_from),
    });
    let hellos = handshake::exchange(worker, hello);
    let plan = match handshake::decide(&hellos, sh.place.processes.max(1)) {
        Ok(plan) => plan,
        Err(r) => {
            if site_worker {
                let mine = r.refused.iter().find(|(p, _)| *p == sh.place.process);
                send(
                    tx,
                    Event::Failed(match mine {
                        Some((_, m)) => Failure::Checkpoint(m.clone()),
                        None => Failure::PeerRefused(
                            r.refused
                                .iter()
                                .map(|(_, m)| m.as_str())
                                .collect::<Vec<_>>()
                                .join("; "),
                        ),
                    }),
                );
            }
            return;
        }
    };
    let start = plan.start;
    let (composer, site) = match resume {
        Some(r) => (r.composer, r.site),
        None => (None, None),
    };
    let composer = (index == 0).then(|| {
        let mut c = composer.unwrap_or_else(|| {
            ComposerState::new(sh.cfg.subsystems.len(), sh.place.processes.max(1))
        });
        c.set_run(plan.run);
        c
    });
    // A site checkpointed after the composer's epoch reads its input again from the start.
    let site = site.filter(|_| plan.use_site.get(sh.place.process).copied().unwrap_or(false));
    let mut input = MsgInput::new();
    let probe = ProbeHandle::new();
    worker.dataflow::<u64, _, _>(|scope| {
        let (cfg, checkpoints, tx) = (sh.cfg.clone(), sh.checkpoints, tx.clone());
        scope
            .input_from(&mut input)
            .unary_frontier::<CapacityContainerBuilder<Vec<()>>, _, _, _>(
                Exchange::new(|_: &Msg| 0),
                "Compose",
                move |cap, _| {
                    let mut state = composer;
                    // Worker 0 holds a capability at its next epoch; the others none.
                    let mut cap = state.as_ref().map(|s| {
                        let mut cap = cap;
                        if let Some(k) = s.next_epoch() {
                            cap.downgrade(&k);
                        }
                        cap
                    });
                    let mut stash: BTreeMap<u64, Vec<Msg>> = BTreeMap::new();
                    move |(input, frontier), _output| {
                        input.for_each_stamp(|c, data| {
                            if let Some(&t) = c.least() {
                                let q = stash.entry(t).or_default();
                                for batch in data {
                                    q.append(batch);
                                }
                            }
                        });
                        let (Some(st), Some(_)) = (state.as_mut(), cap.as_ref()) else {
                            stash.clear();
                            return;
                        };
                        let complete = |k: u64| !frontier.less_equal(&k);
                        let every = checkpoints.unwrap_or(u64::MAX);
                        let failed: Option<Failure<E>> = loop {
                            let epoch = |r| send(&tx, Event::Epoch(Box::new(r)));
                            match st.advance(&cfg, &mut stash, &complete, every, epoch) {
                                Ok((progressed, paused, failed)) => {
                                    // The epochs' reports were handed out; a due checkpoint
                                    // is written before the probe shows the next epoch.
                                    let written = !(paused && checkpoints.is_some())
                                        || ask(&tx, |a| Event::Composer(Box::new(st.clone()), a));
                                    if !written {
                                        cap = None;
                                        state = None;
                                        return;
                                    }
                                    if let (Some(c), Some(k), true) =
                                        (cap.as_mut(), st.next_epoch(), progressed)
                                    {
                                        c.downgrade(&k);
                                    }
                                    if failed.is_some() || !paused {
                                        break failed.map(|f| Failure::Remote {
                                            process: f.process,
                                            line: f.line,
                                            message: f.message,
                                        });
                                    }
                                }
                                Err(e) => break Some(Failure::Compose(e)),
                            }
                        };
                        if let Some(f) = failed {
                            send(&tx, Event::Failed(f));
                            let (rows, last) = st.rows();
                            send(&tx, Event::Network(rows, last));
                            cap = None;
                            state = None;
                            return;
                        }
                        if frontier.is_empty() {
                            if let Some(f) = st.drain(&mut stash) {
                                let (process, line, message) = (f.process, f.line, f.message);
                                send(
                                    &tx,
                                    Event::Failed(Failure::Remote { process, line, message }),
                                );
                            }
                            let (rows, last) = st.rows();
                            send(&tx, Event::Network(rows, last));
                            cap = None;
                        }
                    }
                },
            )
            .probe_with(&probe);
    });
    if site_worker {
        let restored = site.is_some();
        let site = site
            .map_or_else(|| SiteState::new(&sh.cfg, sh.place.process, &sh.place.process_of), Ok);
        match site {
            Ok(mut site) => {
                site.set_run(plan.run);
                let mut s = Site {
                    worker,
                    sh,
                    tx,
                    input: &mut input,
                    probe: &probe,
                    site,
                    outcome: Outcome { resumed_at: start, ..Outcome::default() },
                };
                s.run(start, restored);
            }
            Err(e) => send(tx, Event::Failed(Failure::Checkpoint(e.to_string()))),
        }
    }
    drop(input);
    while !probe.done() {
        worker.step();
    }
}

/// What the input gives next.
enum Next<E> {
    Row(Option<Result<Row, E>>),
    /// Nothing for a while (a live input read on a reader thread).
    Quiet,
}

/// The site: this process's subsystems, fed from its own input.
struct Site<'a, S, E> {
    worker: &'a mut timely::worker::Worker,
    sh: &'a Shared<S>,
    tx: &'a Tx<E>,
    input: &'a mut MsgInput,
    probe: &'a ProbeHandle<u64>,
    site: SiteState,
    outcome: Outcome,
}

impl<S, E> Site<'_, S, E>
where
    E: std::error::Error + Send + 'static,
{
    /// Send one message to the composer, counting what crosses a process boundary.
    fn give(&mut self, m: Msg) {
        if self.sh.place.process != 0 {
            self.outcome.bytes_sent += bincode::serialized_size(&m).unwrap_or(0);
        }
        self.outcome.messages += 1;
        self.input.send(m);
    }

    fn give_changed(&mut self) {
        let mut out = Vec::new();
        self.site.drain_changed(|index, snapshot| out.push(Msg::Snap { index, snapshot }));
        for m in out {
            self.give(m);
        }
    }

    /// Wait until worker 0 has composed every epoch before `a`.
    fn wait_composed_before(&mut self, a: u64) {
        if a == 0 {
            return;
        }
        while self.probe.less_equal(&(a - 1)) {
            self.worker.step();
        }
    }

    /// The row (or clock tick) at hand crossed the boundaries `a..b`: checkpoint the state
    /// valid for them, send what changed, advance. `false`: the checkpoint was not written.
    fn boundary(&mut self, a: u64, b: u64) -> bool {
        self.wait_composed_before(a);
        // A checkpoint when the range holds a multiple of the period.
        let due = self.sh.checkpoints.is_some_and(|e| (b - 1) / e * e >= a);
        if due {
            self.site.seal_at(a, false);
            let state = Box::new(self.site.clone());
            if !ask(self.tx, |ack| Event::Site(state, ack)) {
                return false;
            }
        }
        self.give_changed();
        self.give(Msg::Reached { end: b });
        if *self.input.time() < b {
            self.input.advance_to(b);
        }
        true
    }

    /// Resume at epoch `k`: re-send what the composer needs from `k` on (a site without a
    /// checkpoint only waits at `k`: its rows are read again from the start, every send at a
    /// timestamp no earlier than `k`).
    fn resume_at(&mut self, k: u64, restored: bool) {
        self.input.advance_to(k);
        if !restored {
            return;
        }
        self.site.mark_all();
        let next = self.site.next_epoch();
        if self.site.finished() || next.is_some_and(|b| k < b) {
            self.give_changed();
            self.site.mark_all();
            // Nothing changed since: only the marks stay pending.
            self.site.drain_changed(|_, _| {});
        }
        if let Some(b) = next.filter(|&b| b > k) {
            self.give(Msg::Reached { end: b });
            self.input.advance_to(b);
        }
    }

    fn run<I>(&mut self, start: Option<u64>, restored: bool)
    where
        S: FnOnce() -> I + Send + 'static,
        I: Iterator<Item = Result<Row, E>>,
    {
        if let Some(k) = start {
            self.resume_at(k, restored);
        }
        let source = self.sh.source.lock().ok().and_then(|mut s| s.take());
        let failure = match source {
            // Without a silence rule the rows are read on the worker itself (fastest); with
            // one, on a reader thread, so that a quiet input leaves the worker free to step
            // and to advance its clock.
            Some(source) if self.sh.place.silence.is_none() => {
                let mut rows = source();
                self.read(|| Next::Row(rows.next()), restored)
            }
            Some(source) => {
                let (row_tx, rows) = mpsc::sync_channel::<Result<Row, E>>(4096);
                std::thread::spawn(move || {
                    for item in source() {
                        let stop = item.is_err();
                        if row_tx.send(item).is_err() || stop {
                            break;
                        }
                    }
                });
                self.read(
                    || match rows.try_recv() {
                        Ok(item) => Next::Row(Some(item)),
                        Err(TryRecvError::Disconnected) => Next::Row(None),
                        Err(TryRecvError::Empty) => {
                            match rows.recv_timeout(Duration::from_millis(1)) {
                                Ok(item) => Next::Row(Some(item)),
                                Err(RecvTimeoutError::Disconnected) => Next::Row(None),
                                Err(RecvTimeoutError::Timeout) => Next::Quiet,
                            }
                        }
                    },
                    restored,
                )
            }
            None => None,
        };
        let process = u32::try_from(self.sh.place.process).unwrap_or(u32::MAX);
        match failure {
            None => {
                // The input ended: the final snapshots hold from the clock's next epoch on.
                let at = *self.input.time();
                if self.sh.checkpoints.is_some() && self.site.next_epoch().is_some() {
                    self.wait_composed_before(at);
                    self.site.seal_at(at, true);
                    let state = Box::new(self.site.clone());
                    if !ask(self.tx, |ack| Event::Site(state, ack)) {
                        let why = "the checkpoint was not written".to_string();
                        self.give(Msg::Failed { process, line: 0, message: why });
                    }
                }
                self.give_changed();
            }
            Some((line, f)) => {
                let message = describe(&f, &self.sh.cfg);
                self.give(Msg::Failed { process, line, message });
                send(self.tx, Event::Failed(f));
            }
        }
        let (rows, last_time) = (self.site.rows(), self.site.last_time());
        self.give(Msg::Rows { process, rows, last_time });
        self.outcome.rows = rows;
        self.outcome.last_time = last_time;
        send(self.tx, Event::Done(self.outcome));
    }

    /// Read and certify until the input ends or fails; the failure and its line.
    fn read(
        &mut self,
        mut next: impl FnMut() -> Next<E>,
        resumed: bool,
    ) -> Option<(u64, Failure<E>)> {
        let cfg = &self.sh.cfg;
        let n = cfg.subsystems.len();
        let mut replaying = resumed;
        let mut count = 0u64;
        let mut quiet_since = Instant::now();
        loop {
            let item = match next() {
                Next::Row(Some(item)) => item,
                Next::Row(None) => return None,
                Next::Quiet => {
                    // A quiet input: keep the dataflow moving, and advance a silent site's
                    // clock.
                    self.worker.step();
                    if let Some(f) = self.silence(quiet_since) {
                        return Some(f);
                    }
                    continue;
                }
            };
            quiet_since = Instant::now();
            count += 1;
            let r = match item {
                Ok(r) => r,
                Err(source) => return Some((0, Failure::Source { row: count, source })),
            };
            if replaying {
                if r.samples.iter().all(|(i, _)| self.site.held(*i, r.t)) {
                    continue;
                }
                replaying = false;
            }
            // A sample of a subsystem the network does not have, or another process reads,
            // stops the site where the one-process run stops: after the epochs the row's
            // earlier samples made due.
            let bad = r.samples.iter().position(|&(i, _)| i >= n || !self.site.owns(i));
            let refuse = |i: usize| {
                if i >= n {
                    let source = NetworkError::UnknownSubsystem { index: i, len: n };
                    (r.line, Failure::Network { line: r.line, source })
                } else {
                    let owner = self.sh.place.process_of[i];
                    (r.line, Failure::NotOwned { line: r.line, index: i, owner })
                }
            };
            if bad == Some(0) {
                return Some(refuse(r.samples[0].0));
            }
            let first = self.site.next_epoch().is_none();
            match self.site.due(cfg, r.t) {
                Ok(due) if first => {
                    if let Some(f) = self.site.next_epoch() {
                        self.give(Msg::Start { first: f });
                        if *self.input.time() < f {
                            self.input.advance_to(f);
                        }
                    }
                    let _ = due;
                }
                Ok(due) if due.is_empty() => {}
                Ok(due) => {
                    if !self.boundary(due.start, due.end) {
                        let f = Failure::Output("the checkpoint was not written".into());
                        return Some((r.line, f));
                    }
                }
                Err(source) => return Some((r.line, Failure::Network { line: r.line, source })),
            }
            for (i, values) in &r.samples[..bad.unwrap_or(r.samples.len())] {
                if let Err(e) = self.site.push(cfg, *i, r.t, values) {
                    let f = Failure::Subsystem { line: r.line, index: *i, message: e.to_string() };
                    return Some((r.line, f));
                }
            }
            if let Some(b) = bad {
                return Some(refuse(r.samples[b].0));
            }
            self.site.count(r.t);
            if count % 1024 == 0 {
                self.worker.step();
            }
        }
    }

    /// A live input silent for [`Placement::silence`]: advance the clock by the wall-clock
    /// time since its last row.
    fn silence(&mut self, quiet_since: Instant) -> Option<(u64, Failure<E>)> {
        let d = self.sh.place.silence?;
        let last = self.site.last_time()?;
        let quiet = quiet_since.elapsed();
        if quiet < d {
            return None;
        }
        let t = last + quiet.as_secs_f64();
        match self.site.due(&self.sh.cfg, t) {
            Ok(due) if due.is_empty() => None,
            Ok(due) => {
                if self.boundary(due.start, due.end) {
                    None
                } else {
                    Some((0, Failure::Output("the checkpoint was not written".into())))
                }
            }
            Err(source) => Some((0, Failure::Network { line: 0, source })),
        }
    }
}

/// An identifier for a new run (its checkpoints carry it): the wall clock and the process id.
fn new_run_id() -> u64 {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let text = format!("{nanos}-{}", std::process::id());
    streamcert_certificate::fnv1a64(text.as_bytes())
}

/// A site's failure as text for process 0.
fn describe<E: std::error::Error>(
    f: &Failure<E>,
    cfg: &streamcert_network::NetworkConfig,
) -> String {
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
