//! The site's loop on its process's first worker: read the rows (inline, or from a reader
//! thread under a silence rule), certify them, cross the epoch boundaries (wait for the
//! composition, checkpoint, send the changed snapshots and a mark), and report the end.

use std::sync::mpsc::{self, RecvTimeoutError, TryRecvError};
use std::time::{Duration, Instant};

use streamcert_network::NetworkError;
use timely::dataflow::ProbeHandle;

use crate::site::{Input, Pending};
use crate::wire::Msg;
use crate::wire::MsgInput;
use crate::{Event, Failure, Outcome, Row, Shared, SiteState, Tx, ask, send};

/// What the input gives next.
pub(crate) enum Next<E> {
    Row(Option<Result<Row, E>>),
    /// Nothing for a while (a live input read on a reader thread).
    Quiet,
}

/// The site: this process's subsystems, fed from its own input.
pub(crate) struct Site<'a, S, E> {
    pub(crate) worker: &'a mut timely::worker::Worker,
    pub(crate) sh: &'a Shared<S>,
    pub(crate) tx: &'a Tx<E>,
    pub(crate) input: &'a mut MsgInput,
    pub(crate) probe: &'a ProbeHandle<u64>,
    pub(crate) site: SiteState,
    pub(crate) outcome: Outcome,
    /// Samples read since the last boundary, certified together (over the process's worker
    /// threads) before the next boundary, the end, or when there are `FLUSH` of them.
    pub(crate) pending: Vec<Pending>,
}

/// Samples held before they are certified together.
const FLUSH: usize = 4096;

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
            self.worker.step_or_park(Some(Duration::from_millis(1)));
        }
    }

    /// Certify the samples held; the first one rejected, as the site's failure.
    fn flush(&mut self) -> Option<(u64, Failure<E>)> {
        let threads = self.sh.place.workers.max(1);
        let mut pending = std::mem::take(&mut self.pending);
        let result = self.site.push_pending(&self.sh.cfg, &mut pending, threads);
        self.pending = pending;
        result.err().map(|r| {
            let index = self.site.subsystem_at(r.pos);
            let message = r.error.to_string();
            (r.line, Failure::Subsystem { line: r.line, index, message })
        })
    }

    /// The row (or clock tick) at hand crossed the boundaries `a..b`: certify the samples
    /// before it, checkpoint the state valid for them, send what changed, advance.
    fn boundary(&mut self, a: u64, b: u64, line: u64) -> Option<(u64, Failure<E>)> {
        if let Some(f) = self.flush() {
            return Some(f);
        }
        self.wait_composed_before(a);
        // A checkpoint when the range holds a multiple of the period.
        let due = self.sh.checkpoints.is_some_and(|e| (b - 1) / e * e >= a);
        if due {
            self.site.seal_at(a, Input::Open);
            let state = Box::new(self.site.clone());
            if !ask(self.tx, |ack| Event::Site(state, ack)) {
                return Some((line, Failure::Output("the checkpoint was not written".into())));
            }
        }
        self.give_changed();
        self.give(Msg::Reached { end: b });
        if *self.input.time() < b {
            self.input.advance_to(b);
        }
        None
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
        // Its snapshots hold at `k`: send them there. (Otherwise they stay marked and go out
        // at the next boundary.)
        if self.site.finished() || next.is_some_and(|b| k < b) {
            self.give_changed();
        }
        if let Some(b) = next.filter(|&b| b > k) {
            self.give(Msg::Reached { end: b });
            self.input.advance_to(b);
        }
    }

    pub(crate) fn run<I>(&mut self, start: Option<u64>, restored: bool)
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
                    self.site.seal_at(at, Input::Finished);
                    let state = Box::new(self.site.clone());
                    if !ask(self.tx, |ack| Event::Site(state, ack)) {
                        let why = "the checkpoint was not written".to_string();
                        self.give(Msg::Failed { process, line: 0, message: why });
                    }
                }
                self.give_changed();
            }
            Some((line, f)) => {
                let message = Failure::describe(&f, &self.sh.cfg);
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

    /// Read and certify until the input ends or fails; the failure and its line (a sample
    /// held and rejected precedes the failure that ended the reading).
    fn read(&mut self, next: impl FnMut() -> Next<E>, resumed: bool) -> Option<(u64, Failure<E>)> {
        let stopped = self.read_rows(next, resumed);
        self.flush().or(stopped)
    }

    /// The epochs a row at `t` (input line `line`) makes due: the first row starts the site
    /// at its first epoch; a later one crosses the boundaries up to it.
    fn advance_epochs(&mut self, t: f64, line: u64) -> Option<(u64, Failure<E>)> {
        let first = self.site.next_epoch().is_none();
        match self.site.due(&self.sh.cfg, t) {
            Ok(_) if first => {
                if let Some(f) = self.site.next_epoch() {
                    self.give(Msg::Start { first: f });
                    if *self.input.time() < f {
                        self.input.advance_to(f);
                    }
                }
                None
            }
            Ok(due) if due.is_empty() => None,
            Ok(due) => self.boundary(due.start, due.end, line),
            Err(source) => Some((line, Failure::Network { line, source })),
        }
    }

    /// The reading loop of [`read`](Self::read): each row certified into the pending samples,
    /// the epochs it makes due composed; replayed rows passed over after a resume.
    fn read_rows(
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
            if let Some(f) = self.advance_epochs(r.t, r.line) {
                return Some(f);
            }
            let refused = bad.map(|b| refuse(r.samples[b].0));
            let (line, t, gap) = (r.line, r.t, r.gap);
            for (i, values) in r.samples.into_iter().take(bad.unwrap_or(usize::MAX)) {
                if let Some(pos) = self.site.position(i) {
                    self.pending.push(Pending { pos, seq: count, line, t, values, gap });
                }
            }
            if refused.is_some() {
                return refused;
            }
            self.site.count(t);
            if self.pending.len() >= FLUSH
                && let Some(f) = self.flush()
            {
                return Some(f);
            }
            if count.is_multiple_of(1024) {
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
            Ok(due) => self.boundary(due.start, due.end, 0),
            Err(source) => Some((0, Failure::Network { line: 0, source })),
        }
    }
}
