//! The composing operator's state on worker 0: the composer, its capability at the next
//! epoch, and the sites' messages stashed by timestamp until their epochs are complete.

use std::collections::BTreeMap;
use timely::dataflow::operators::Capability;

use crate::wire::Msg;
use crate::{ComposerState, Event, Failure, Tx, ask, send};
use streamcert_network::NetworkConfig;

/// Worker 0's composing operator (the other workers hold no state and no capability).
pub(crate) struct ComposeOp<E> {
    state: Option<ComposerState>,
    cap: Option<Capability<u64>>,
    stash: BTreeMap<u64, Vec<Msg>>,
    cfg: NetworkConfig,
    checkpoints: Option<u64>,
    tx: Tx<E>,
}

impl<E: std::error::Error + Send + 'static> ComposeOp<E> {
    /// The operator with `state` (worker 0), holding `cap` at the state's next epoch.
    pub(crate) fn new(
        state: Option<ComposerState>,
        cap: Capability<u64>,
        cfg: NetworkConfig,
        checkpoints: Option<u64>,
        tx: Tx<E>,
    ) -> Self {
        let cap = state.as_ref().map(|s| {
            let mut cap = cap;
            if let Some(k) = s.next_epoch() {
                cap.downgrade(&k);
            }
            cap
        });
        Self { state, cap, stash: BTreeMap::new(), cfg, checkpoints, tx }
    }

    /// Stash a batch of messages at timestamp `t`.
    pub(crate) fn stash<'a>(&mut self, t: u64, data: impl Iterator<Item = &'a mut Vec<Msg>>) {
        let q = self.stash.entry(t).or_default();
        for batch in data {
            q.append(batch);
        }
    }

    /// Compose every epoch whose timestamps are `complete`, checkpoint where due, and at the
    /// end of the input (`done`) drain what is left and report the network's rows.
    pub(crate) fn step(&mut self, complete: impl Fn(u64) -> bool, done: bool) {
        let (Some(st), Some(_)) = (self.state.as_mut(), self.cap.as_ref()) else {
            self.stash.clear();
            return;
        };
        let every = self.checkpoints.unwrap_or(u64::MAX);
        let failed: Option<Failure<E>> = loop {
            let tx = &self.tx;
            let epoch = |r| send(tx, Event::Epoch(Box::new(r)));
            match st.advance(&self.cfg, &mut self.stash, &complete, every, epoch) {
                Ok((progressed, paused, failed)) => {
                    // The epochs' reports were handed out; a due checkpoint is written before
                    // the probe shows the next epoch.
                    let written = !(paused && self.checkpoints.is_some())
                        || ask(&self.tx, |a| Event::Composer(Box::new(st.clone()), a));
                    if !written {
                        self.stop();
                        return;
                    }
                    if let (Some(c), Some(k), true) =
                        (self.cap.as_mut(), st.next_epoch(), progressed)
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
            send(&self.tx, Event::Failed(f));
            let (rows, last) = st.rows();
            send(&self.tx, Event::Network(rows, last));
            self.stop();
            return;
        }
        if done {
            if let Some(f) = st.drain(&mut self.stash) {
                let (process, line, message) = (f.process, f.line, f.message);
                send(&self.tx, Event::Failed(Failure::Remote { process, line, message }));
            }
            let (rows, last) = st.rows();
            send(&self.tx, Event::Network(rows, last));
            self.cap = None;
        }
    }

    /// Give up the capability and the state: the run stops composing.
    fn stop(&mut self) {
        self.cap = None;
        self.state = None;
    }
}
