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
    /// Process 0: the resumed composer's next epoch (`None`: a new run).
    pub(crate) composer_next: Option<u64>,
    /// Whether this process resumes its site from a checkpoint.
    pub(crate) resumed: bool,
    pub(crate) valid_from: u64,
    pub(crate) clock_next: Option<u64>,
    pub(crate) finished: bool,
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
        worker.step();
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

/// The epoch the run resumes at (`None`: a new run), or the processes whose start is refused.
pub(crate) fn decide(hellos: &[Hello], processes: usize) -> Result<Option<u64>, Refusal> {
    let mut refused = Vec::new();
    let Some(zero) = hellos.iter().find(|h| h.process == 0) else {
        return Err(Refusal { refused: vec![(0, "process 0 did not start".into())] });
    };
    for p in 0..processes {
        let Some(h) = hellos.iter().find(|h| h.process as usize == p) else {
            refused.push((p, format!("process {p} did not start")));
            continue;
        };
        if h.fingerprint != zero.fingerprint {
            refused.push((
                p,
                format!(
                    "process {p} runs another configuration or subsystem placement than \
                     process 0 (fingerprint {:016x}, process 0's {:016x})",
                    h.fingerprint, zero.fingerprint
                ),
            ));
            continue;
        }
        match zero.composer_next {
            None if h.resumed => refused.push((
                p,
                format!(
                    "process 0 starts a new run, but process {p} resumes a checkpoint: start \
                     process {p} without --resume, or resume process 0 from its checkpoint"
                ),
            )),
            None => {}
            Some(k) if !h.resumed => refused.push((
                p,
                format!(
                    "process 0 resumes at epoch {k}: process {p} must resume from its own \
                     checkpoint (--resume), or every process starts over"
                ),
            )),
            Some(k) => {
                let fits =
                    h.valid_from <= k && (h.finished || h.clock_next.is_none_or(|next| k <= next));
                if !fits {
                    let upto = if h.finished {
                        "on".to_string()
                    } else {
                        format!("to {}", h.clock_next.map_or(0, |n| n.saturating_sub(1)))
                    };
                    refused.push((
                        p,
                        format!(
                            "process {p}'s checkpoint holds epochs {} {upto}, but process 0 \
                             composes from epoch {k}: resume process {p} from its newest \
                             checkpoint (its own file, written with this run)",
                            h.valid_from
                        ),
                    ));
                }
            }
        }
    }
    if refused.is_empty() { Ok(zero.composer_next) } else { Err(Refusal { refused }) }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hello(process: u32, resumed: bool, valid_from: u64, next: Option<u64>) -> Hello {
        Hello {
            process,
            fingerprint: 7,
            composer_next: None,
            resumed,
            valid_from,
            clock_next: next,
            finished: false,
        }
    }

    #[test]
    fn a_resumed_run_needs_every_site_at_the_composers_epoch() {
        let fresh = [hello(0, false, 0, None), hello(1, false, 0, None)];
        assert_eq!(decide(&fresh, 2).ok(), Some(None));
        let mut zero = hello(0, true, 10, Some(12));
        zero.composer_next = Some(11);
        // Site 1 holds epochs 9..11 (valid from 9, next 12): it covers 11.
        assert_eq!(decide(&[zero.clone(), hello(1, true, 9, Some(12))], 2).ok(), Some(Some(11)));
        // Its next epoch is exactly the composer's: it sends at its next boundary.
        assert!(decide(&[zero.clone(), hello(1, true, 9, Some(11))], 2).is_ok());
        // An older checkpoint (epochs 3..5) or a newer one (from 12) is refused, naming it.
        for late in [hello(1, true, 3, Some(6)), hello(1, true, 12, Some(13))] {
            let r = decide(&[zero.clone(), late], 2).expect_err("refused");
            assert_eq!(r.refused.len(), 1);
            assert_eq!(r.refused[0].0, 1);
            assert!(r.refused[0].1.contains("composes from epoch 11"), "{}", r.refused[0].1);
        }
        // A fresh process beside a resumed composer, a resumed one beside a new run, another
        // configuration, a missing process.
        assert!(decide(&[zero.clone(), hello(1, false, 0, None)], 2).is_err());
        assert!(decide(&[hello(0, false, 0, None), hello(1, true, 0, Some(3))], 2).is_err());
        let mut other = hello(1, false, 0, None);
        other.fingerprint = 8;
        let r = decide(&[hello(0, false, 0, None), other], 2).expect_err("refused");
        assert!(r.refused[0].1.contains("another configuration"));
        assert!(decide(&[hello(0, false, 0, None)], 2).is_err());
    }
}
