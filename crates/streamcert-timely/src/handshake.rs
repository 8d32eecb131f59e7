//! The start of every run: each process broadcasts what it resumes from, and every process
//! decides from the same list whether the run may start, and at which epoch.

use std::cell::RefCell;
use std::rc::Rc;

use serde::{Deserialize, Serialize};
use timely::container::CapacityContainerBuilder;
use timely::dataflow::operators::vec::Broadcast;
use timely::dataflow::operators::{Input, Inspect, Probe};
use timely::dataflow::{InputHandle, ProbeHandle};

/// What one process says at the start.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct Hello {
    pub(crate) process: u32,
    /// Fingerprint of the network configuration and the placement.
    pub(crate) fingerprint: u64,
    /// The run its checkpoints belong to (process 0 on a new run: a new identifier).
    pub(crate) run: u64,
    /// Process 0: the resumed composer's next epoch (`None`: a new run).
    pub(crate) composer_next: Option<u64>,
    /// Whether this process resumes from a checkpoint.
    pub(crate) resumed: bool,
    /// The first epoch its checkpointed site holds (`None`: it had written none).
    pub(crate) valid_from: Option<u64>,
    /// Whether it was started again from its checkpoint (not rejoining from memory).
    pub(crate) restarted: bool,
}

/// Broadcast `mine` (the process's first worker has one) and collect every process's.
pub(crate) fn exchange(worker: &mut timely::worker::Worker, mine: Option<Hello>) -> Vec<Hello> {
    let got: Rc<RefCell<Vec<Hello>>> = Rc::new(RefCell::new(Vec::new()));
    let mut input = InputHandle::<u64, CapacityContainerBuilder<Vec<Hello>>>::new();
    let probe = ProbeHandle::new();
    let sink = Rc::clone(&got);
    worker.dataflow::<u64, _, _>(|scope| {
        scope
            .input_from(&mut input)
            .broadcast()
            .inspect(move |h: &Hello| sink.borrow_mut().push(h.clone()))
            .probe_with(&probe);
    });
    if let Some(h) = mine {
        input.send(h);
    }
    drop(input);
    while !probe.done() {
        worker.step_or_park(Some(std::time::Duration::from_millis(10)));
    }
    let mut all = got.borrow().clone();
    all.sort_by_key(|h| h.process);
    all
}

/// Why the run cannot start.
pub(crate) struct Refusal {
    /// The processes refused, with the reason for each.
    pub(crate) refused: Vec<(usize, String)>,
}

/// How the run starts.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Plan {
    /// The epoch the run resumes at (`None`: a new run).
    pub(crate) start: Option<u64>,
    /// The run's identifier.
    pub(crate) run: u64,
    /// Per process: whether it resumes its checkpointed site (else it reads its input
    /// again from the start: its checkpoint holds epochs after the composer's).
    pub(crate) use_site: Vec<bool>,
    /// The processes started again from their checkpoints (they had been down).
    pub(crate) restarted: Vec<usize>,
}

/// The plan every process computes from the same hellos, or the processes refused.
pub(crate) fn decide(hellos: &[Hello], processes: usize) -> Result<Plan, Refusal> {
    let mut refused = Vec::new();
    let Some(zero) = hellos.iter().find(|h| h.process == 0) else {
        return Err(Refusal { refused: vec![(0, "process 0 did not start".into())] });
    };
    let mut use_site = vec![false; processes];
    for p in 0..processes {
        let Some(h) = hellos.iter().find(|h| h.process as usize == p) else {
            refused.push((p, format!("process {p} did not start")));
            continue;
        };
        let refuse = |why: String| (p, why);
        if h.fingerprint != zero.fingerprint {
            refused.push(refuse(format!(
                "process {p} runs another configuration or subsystem placement than process 0 \
                 (fingerprint {:016x}, process 0's {:016x})",
                h.fingerprint, zero.fingerprint
            )));
            continue;
        }
        match zero.composer_next {
            None if h.resumed => refused.push(refuse(format!(
                "process 0 starts a new run, but process {p} resumes a checkpoint: start process \
                 {p} without --resume, or resume process 0 from its checkpoint"
            ))),
            None => {}
            Some(k) if !h.resumed => refused.push(refuse(format!(
                "process 0 resumes at epoch {k}: process {p} must resume from its own \
                 checkpoint (--resume), or every process starts over"
            ))),
            Some(_) if h.run != zero.run => refused.push(refuse(format!(
                "process {p}'s checkpoint is of another run than process 0's (run {:016x}, \
                 process 0's {:016x}): give it its own checkpoint of this run",
                h.run, zero.run
            ))),
            Some(k) => use_site[p] = h.valid_from.is_some_and(|v| v <= k),
        }
    }
    if refused.is_empty() {
        let restarted = hellos
            .iter()
            .filter(|h| h.restarted && zero.composer_next.is_some())
            .map(|h| h.process as usize)
            .collect();
        Ok(Plan { start: zero.composer_next, run: zero.run, use_site, restarted })
    } else {
        Err(Refusal { refused })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hello(process: u32, resumed: bool, valid_from: Option<u64>) -> Hello {
        Hello {
            process,
            fingerprint: 7,
            run: 42,
            composer_next: None,
            resumed,
            valid_from,
            restarted: resumed && process == 1,
        }
    }

    #[test]
    fn a_resumed_run_starts_at_the_composers_epoch() {
        let fresh = [hello(0, false, None), hello(1, false, None)];
        let plan = decide(&fresh, 2).ok().expect("a new run");
        assert_eq!((plan.start, plan.run), (None, 42));
        let mut zero = hello(0, true, Some(10));
        zero.composer_next = Some(11);
        // A site whose checkpoint holds epochs from 9 resumes it; one from 12 (written after
        // the composer's) reads its input again; one with none too.
        for (valid_from, used) in
            [(Some(9), true), (Some(11), true), (Some(12), false), (None, false)]
        {
            let plan = decide(&[zero.clone(), hello(1, true, valid_from)], 2).ok().expect("ok");
            assert_eq!(plan.start, Some(11));
            assert_eq!(plan.use_site, vec![true, used], "{valid_from:?}");
            assert_eq!(plan.restarted, vec![1], "the process started again is named");
        }
        // Refused, naming the process: a fresh process beside a resumed composer, a resumed
        // one beside a new run, another run's checkpoint, another configuration, a missing one.
        let mut other_run = hello(1, true, Some(9));
        other_run.run = 43;
        let mut other_cfg = hello(1, false, None);
        other_cfg.fingerprint = 8;
        for (hellos, needle) in [
            (vec![zero.clone(), hello(1, false, None)], "must resume"),
            (vec![hello(0, false, None), hello(1, true, Some(3))], "starts a new run"),
            (vec![zero.clone(), other_run], "another run"),
            (vec![hello(0, false, None), other_cfg], "another configuration"),
            (vec![hello(0, false, None)], "did not start"),
        ] {
            let r = decide(&hellos, 2).expect_err(needle);
            assert_eq!(r.refused.len(), 1);
            assert_eq!(r.refused[0].0, 1);
            assert!(r.refused[0].1.contains(needle), "{}", r.refused[0].1);
        }
    }
}
