//! [`ComposerState`]: worker 0's view of the network (every subsystem's newest snapshot, the
//! epochs due, the network gate), advanced one complete timely timestamp at a time.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use streamcert_network::{Composer, EpochReport, LocalSnapshot, NetworkConfig, NetworkError};

use crate::wire::Msg;

/// What composes the epochs: every subsystem's newest snapshot as of the last composed epoch,
/// the next epoch to compose, the epochs the sites have made due, and the network gate.
/// Serde-serialisable: process 0 checkpoints it after every batch of epochs it composes
/// (after their rows were handed out).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ComposerState {
    composer: Composer,
    last: Vec<Option<LocalSnapshot>>,
    /// The next epoch to compose (`None` until every site's first row is known).
    next: Option<u64>,
    /// The earliest first epoch over the sites.
    start: Option<u64>,
    /// Epochs `k < target` are due (some site has a row at `t >= k · epoch`).
    target: u64,
    /// Rows and last time per process, as last reported.
    sites: Vec<(u64, Option<f64>)>,
    /// The run this state belongs to.
    #[serde(default)]
    run: u64,
}

/// A failure a site reported, in the composer's hands.
#[derive(Debug, Clone)]
pub(crate) struct Reported {
    pub(crate) process: usize,
    pub(crate) line: u64,
    pub(crate) message: String,
}

impl ComposerState {
    /// Before any row.
    #[must_use]
    pub fn new(n: usize, processes: usize) -> Self {
        Self {
            composer: Composer::new(),
            last: vec![None; n],
            next: None,
            start: None,
            target: 0,
            sites: vec![(0, None); processes],
            run: 0,
        }
    }

    /// The run this state belongs to.
    #[must_use]
    pub fn run_id(&self) -> u64 {
        self.run
    }

    pub(crate) fn set_run(&mut self, run: u64) {
        self.run = run;
    }

    /// The next epoch to compose (`None` before the run's first epoch is known).
    #[must_use]
    pub fn next_epoch(&self) -> Option<u64> {
        self.next
    }

    /// Rows certified over every site and the latest time any site read, as reported.
    #[must_use]
    pub fn rows(&self) -> (u64, Option<f64>) {
        let rows = self.sites.iter().map(|s| s.0).sum();
        let last = self.sites.iter().filter_map(|s| s.1).reduce(f64::max);
        (rows, last)
    }

    /// Check a state read back from a checkpoint against this run.
    ///
    /// # Errors
    /// A message naming what is wrong.
    pub fn verify(self, cfg: &NetworkConfig, processes: usize) -> Result<Self, String> {
        if self.last.len() != cfg.subsystems.len() || self.sites.len() != processes {
            return Err("the composer's checkpoint is for another network".into());
        }
        if self.last.iter().flatten().any(|s| !s.is_valid()) {
            return Err("a stored time or certificate is not finite".into());
        }
        if self.next.is_none() {
            return Err("the composer's checkpoint was written before its first epoch".into());
        }
        Ok(self)
    }

    /// Merge one message (of a complete timestamp); a failure is returned.
    fn merge(&mut self, m: Msg) -> Option<Reported> {
        match m {
            Msg::Start { first } => {
                self.start = Some(self.start.map_or(first, |s| s.min(first)));
                self.target = self.target.max(first);
            }
            Msg::Reached { end } => self.target = self.target.max(end),
            Msg::Snap { index, snapshot } => {
                if let Some(slot) = self.last.get_mut(index as usize) {
                    *slot = Some(snapshot.into());
                }
            }
            Msg::Rows { process, rows, last_time } => {
                if let Some(s) = self.sites.get_mut(process as usize) {
                    *s = (rows, last_time);
                }
            }
            Msg::Failed { process, line, message } => {
                return Some(Reported { process: process as usize, line, message });
            }
        }
        None
    }

    /// Merge the stashed messages of timestamps up to `bound`; the first failure stops.
    fn merge_until(&mut self, stash: &mut BTreeMap<u64, Vec<Msg>>, bound: u64) -> Option<Reported> {
        let mut failed = None;
        while let Some(entry) = stash.first_entry() {
            if *entry.key() > bound {
                break;
            }
            for m in entry.remove() {
                if let Some(f) = self.merge(m) {
                    failed.get_or_insert(f);
                }
            }
        }
        failed
    }

    /// Compose every epoch that is complete (`complete(k)`: no site can still send for
    /// timestamps `<= k`), handing each report to `epoch`, and pause when the next epoch is
    /// the run's start or a multiple of `every` (a checkpoint is due); returns whether
    /// anything advanced, whether it paused, and the first failure merged.
    pub(crate) fn advance(
        &mut self,
        cfg: &NetworkConfig,
        stash: &mut BTreeMap<u64, Vec<Msg>>,
        complete: &impl Fn(u64) -> bool,
        every: u64,
        mut epoch: impl FnMut(EpochReport),
    ) -> Result<(bool, bool, Option<Reported>), NetworkError> {
        let mut progressed = false;
        loop {
            let k = match self.next {
                Some(k) => k,
                None => {
                    // Every site's first row is at timestamp 0, before its clock starts.
                    if !complete(0) {
                        break;
                    }
                    if let Some(f) = self.merge_until(stash, 0) {
                        return Ok((progressed, false, Some(f)));
                    }
                    match self.start {
                        Some(s) => {
                            self.next = Some(s);
                            return Ok((true, true, None));
                        }
                        None => break,
                    }
                }
            };
            if !complete(k) {
                break;
            }
            if let Some(f) = self.merge_until(stash, k) {
                return Ok((progressed, false, Some(f)));
            }
            if k >= self.target {
                break;
            }
            let report = self.composer.compose(cfg, k, &self.last)?;
            epoch(report);
            self.next = Some(k + 1);
            progressed = true;
            if (k + 1) % every.max(1) == 0 {
                return Ok((true, true, None));
            }
        }
        Ok((progressed, false, None))
    }

    /// Merge everything left (the end of the run: no epoch is due after it).
    pub(crate) fn drain(&mut self, stash: &mut BTreeMap<u64, Vec<Msg>>) -> Option<Reported> {
        self.merge_until(stash, u64::MAX)
    }
}
