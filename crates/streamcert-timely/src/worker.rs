//! One timely worker: the start's handshake, the dataflow with its composing operator (worker
//! 0), and the site (the first worker of every process, `ingest.rs`).

use timely::container::CapacityContainerBuilder;
use timely::dataflow::ProbeHandle;
use timely::dataflow::channels::pact::Exchange;
use timely::dataflow::operators::generic::operator::Operator;
use timely::dataflow::operators::{Input, Probe};

use crate::ingest::Site;
use crate::operator::ComposeOp;
use crate::wire::{Msg, MsgInput};
use crate::{
    ComposerState, Event, Failure, Outcome, Resume, Row, Shared, SiteState, Tx, handshake, send,
};

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
    let hello = site_worker.then(|| hello(sh, resume.as_ref()));
    let hellos = handshake::exchange(worker, hello);
    let plan = match handshake::decide(&hellos, sh.place.processes.max(1)) {
        Ok(plan) => plan,
        Err(r) => {
            if site_worker {
                send(tx, Event::Failed(refusal(&r, sh.place.process)));
            }
            return;
        }
    };
    let start = plan.start;
    if site_worker {
        send(tx, Event::Started(start, plan.restarted.clone()));
    }
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
                    let mut op = ComposeOp::new(composer, cap, cfg, checkpoints, tx);
                    move |(input, frontier), _output| {
                        input.for_each_stamp(|c, data| {
                            if let Some(&t) = c.least() {
                                op.stash(t, data);
                            }
                        });
                        op.step(|k| !frontier.less_equal(&k), frontier.is_empty());
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
                    pending: Vec::new(),
                };
                s.run(start, restored);
            }
            Err(e) => send(tx, Event::Failed(Failure::Checkpoint(e.to_string()))),
        }
    }
    drop(input);
    // The rest of the run: park between events instead of spinning.
    while !probe.done() {
        worker.step_or_park(Some(std::time::Duration::from_millis(10)));
    }
}

/// This process's hello for the start's handshake: its run (the checkpoint's, else a new
/// one), what it resumes from, and whether it was started again after a crash.
fn hello<S>(sh: &Shared<S>, resume: Option<&Resume>) -> handshake::Hello {
    let site_resumed = resume.and_then(|r| r.site.as_ref());
    let composer_resumed = resume.and_then(|r| r.composer.as_ref());
    handshake::Hello {
        process: u32::try_from(sh.place.process).unwrap_or(u32::MAX),
        fingerprint: sh.fingerprint,
        run: composer_resumed
            .map(ComposerState::run_id)
            .or_else(|| site_resumed.map(SiteState::run_id))
            .unwrap_or_else(new_run_id),
        composer_next: composer_resumed.and_then(ComposerState::next_epoch),
        resumed: resume.is_some(),
        valid_from: site_resumed.map(SiteState::valid_from),
        restarted: resume.is_some_and(|r| !r.rejoin),
    }
}

/// The failure a refused start reports on `process`: its own checkpoint's refusal, or the
/// peers' refusals.
fn refusal<E>(r: &handshake::Refusal, process: usize) -> Failure<E> {
    match r.refused.iter().find(|(p, _)| *p == process) {
        Some((_, m)) => Failure::Checkpoint(m.clone()),
        None => Failure::PeerRefused(
            r.refused.iter().map(|(_, m)| m.as_str()).collect::<Vec<_>>().join("; "),
        ),
    }
}

/// An identifier for a new run (its checkpoints carry it): the wall clock and the process id.
pub(crate) fn new_run_id() -> u64 {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let text = format!("{nanos}-{}", std::process::id());
    streamcert_certificate::fnv1a64(text.as_bytes())
}
