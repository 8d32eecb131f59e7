//! [`SiteState`]: the subsystems one process reads and certifies, with its epoch clock.

use serde::{Deserialize, Serialize};
use streamcert_certificate::{CertificateKind, Certifier, CertifyError};
use streamcert_network::{Composer, LocalSnapshot, NetworkConfig, NetworkError};

use crate::wire::WireSnapshot;

/// Whether a site's input goes on past a sealed state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Input {
    /// More rows may come.
    Open,
    /// The input has ended: the state also holds every epoch after its clock.
    Finished,
}

/// A sample waiting to be certified: its subsystem's position in the site, its row's order
/// and line, its time and values.
pub(crate) struct Pending {
    pub(crate) pos: u32,
    pub(crate) seq: u64,
    pub(crate) line: u64,
    pub(crate) t: f64,
    pub(crate) values: Vec<f64>,
    /// The windows restart at this sample (a declared gap).
    pub(crate) gap: bool,
}

/// A sample its certifier rejected.
pub(crate) struct Rejected {
    pub(crate) seq: u64,
    pub(crate) line: u64,
    pub(crate) pos: u32,
    pub(crate) error: CertifyError,
}

/// What one process (a *site*) holds: the certifiers of the subsystems it owns, their newest
/// snapshots, and its epoch clock. Serde-serialisable: it is the site's checkpoint, written at
/// an epoch boundary (before the row that crossed it is certified).
///
/// The snapshots it holds are those of every epoch `k` with `valid_from <= k < next` (its
/// clock's next epoch), and of every later epoch as well once its input has ended
/// (`finished`): a site resumed from this state re-sends them for the epoch its composer
/// resumes at, so a restarted run composes what the uninterrupted one composed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SiteState {
    process: usize,
    owned: Vec<usize>,
    certifiers: Vec<Certifier>,
    snapshots: Vec<Option<LocalSnapshot>>,
    clock: Composer,
    valid_from: u64,
    finished: bool,
    rows: u64,
    last_time: Option<f64>,
    /// The run this state belongs to (set at the start of every run).
    #[serde(default)]
    run: u64,
    /// Position of every subsystem in `owned` (`u32::MAX`: another process's).
    #[serde(skip)]
    slot: Vec<u32>,
    #[serde(skip)]
    changed: Vec<bool>,
    #[serde(skip)]
    touched: Vec<u32>,
}

impl SiteState {
    /// The site of `process`: the subsystems `i` with `process_of[i] == process`, each with a
    /// new certifier.
    ///
    /// # Errors
    /// [`NetworkError::Subsystem`] for a certifier configuration that is refused.
    pub fn new(
        cfg: &NetworkConfig,
        process: usize,
        process_of: &[usize],
    ) -> Result<Self, NetworkError> {
        let owned: Vec<usize> =
            (0..cfg.subsystems.len()).filter(|&i| process_of.get(i) == Some(&process)).collect();
        let certifiers = owned
            .iter()
            .map(|&i| {
                Certifier::new(cfg.subsystems[i].certifier.clone()).map_err(|source| {
                    NetworkError::Subsystem {
                        index: i,
                        name: cfg.subsystems[i].name.clone(),
                        source,
                    }
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut s = Self {
            process,
            snapshots: vec![None; owned.len()],
            owned,
            certifiers,
            clock: Composer::new(),
            valid_from: 0,
            finished: false,
            rows: 0,
            last_time: None,
            run: 0,
            slot: Vec::new(),
            changed: Vec::new(),
            touched: Vec::new(),
        };
        s.index(cfg.subsystems.len());
        Ok(s)
    }

    fn index(&mut self, n: usize) {
        self.slot = vec![u32::MAX; n];
        for (k, &i) in self.owned.iter().enumerate() {
            if let Some(s) = self.slot.get_mut(i) {
                *s = u32::try_from(k).unwrap_or(u32::MAX);
            }
        }
        self.changed = vec![false; self.owned.len()];
        self.touched.clear();
    }

    /// Check a state read back from a checkpoint against this run: the same process, the
    /// same subsystems, each certifier valid ([`Certifier::verify`]) and built from its
    /// subsystem's configuration, every stored number finite. A state that fails is refused.
    ///
    /// # Errors
    /// A message naming what is wrong.
    pub fn verify(
        mut self,
        cfg: &NetworkConfig,
        process: usize,
        process_of: &[usize],
    ) -> Result<Self, String> {
        if self.process != process {
            return Err(format!(
                "the checkpoint is process {}'s, not process {process}'s",
                self.process
            ));
        }
        let owned: Vec<usize> =
            (0..cfg.subsystems.len()).filter(|&i| process_of.get(i) == Some(&process)).collect();
        if owned != self.owned {
            return Err("the checkpoint holds other subsystems than this process owns".into());
        }
        if self.certifiers.len() != owned.len() || self.snapshots.len() != owned.len() {
            return Err("the checkpoint's certifiers do not match its subsystems".into());
        }
        let mut certifiers = Vec::with_capacity(owned.len());
        for (c, &i) in std::mem::take(&mut self.certifiers).into_iter().zip(&owned) {
            let c = c.verify().map_err(|e| format!("subsystem {i}: {e}"))?;
            if c.config() != &cfg.subsystems[i].certifier {
                return Err(format!("subsystem {i} has another configuration"));
            }
            certifiers.push(c);
        }
        self.certifiers = certifiers;
        let bad = self.snapshots.iter().flatten().any(|s| !s.is_valid())
            || self.last_time.is_some_and(|t| !t.is_finite());
        if bad {
            return Err("a stored time or certificate is not finite".into());
        }
        self.index(cfg.subsystems.len());
        Ok(self)
    }

    /// The process this site is.
    #[must_use]
    pub fn process(&self) -> usize {
        self.process
    }

    /// The subsystems it owns (indices in the network).
    #[must_use]
    pub fn owned(&self) -> &[usize] {
        &self.owned
    }

    /// The first epoch whose snapshots this state holds.
    #[must_use]
    pub fn valid_from(&self) -> u64 {
        self.valid_from
    }

    /// Its clock's next epoch (`None` before its first row).
    #[must_use]
    pub fn next_epoch(&self) -> Option<u64> {
        self.clock.next_epoch()
    }

    /// Whether the state was written after the site's input ended.
    #[must_use]
    pub fn finished(&self) -> bool {
        self.finished
    }

    /// Rows the site has certified.
    #[must_use]
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Time of its last row.
    #[must_use]
    pub fn last_time(&self) -> Option<f64> {
        self.last_time
    }

    /// The run this state belongs to.
    #[must_use]
    pub fn run_id(&self) -> u64 {
        self.run
    }

    pub(crate) fn set_run(&mut self, run: u64) {
        self.run = run;
    }

    /// Whether this site owns subsystem `i`.
    pub(crate) fn owns(&self, i: usize) -> bool {
        self.slot.get(i).is_some_and(|&s| s != u32::MAX)
    }

    /// Whether subsystem `i`'s certifier already holds a sample at time `t` or later (a row
    /// replayed after a restart).
    pub(crate) fn held(&self, i: usize, t: f64) -> bool {
        self.slot
            .get(i)
            .and_then(|&s| self.certifiers.get(s as usize))
            .and_then(|c| c.regression().last_time())
            .is_some_and(|l| t <= l)
    }

    /// The epochs made due by a row at `t` on this site's clock.
    pub(crate) fn due(
        &mut self,
        cfg: &NetworkConfig,
        t: f64,
    ) -> Result<std::ops::Range<u64>, NetworkError> {
        self.clock.due(cfg, t)
    }

    /// Mark the state as holding the epochs from `from` on ([`Input::Finished`]: and after
    /// its clock).
    pub(crate) fn seal_at(&mut self, from: u64, input: Input) {
        self.valid_from = from;
        self.finished = input == Input::Finished;
    }

    /// Certify the samples `pending` collected since the last call, over `threads` scoped
    /// threads, each owning a contiguous range of this site's subsystems (every subsystem's
    /// samples in their order, so the result is that of pushing them one by one); empties
    /// `pending`. The first failure in row order is returned.
    pub(crate) fn push_pending(
        &mut self,
        cfg: &NetworkConfig,
        pending: &mut Vec<Pending>,
        threads: usize,
    ) -> Result<(), Rejected> {
        if pending.is_empty() {
            return Ok(());
        }
        pending.sort_by_key(|p| (p.pos, p.seq));
        let parts = threads.clamp(1, 64).min(pending.len().div_ceil(64)).max(1);
        let cuts = cuts(pending, parts);
        let kind = cfg.certificate;
        let mut results: Vec<(Vec<u32>, Option<Rejected>)> = Vec::with_capacity(cuts.len());
        {
            let (mut certs, mut snaps) = (&mut self.certifiers[..], &mut self.snapshots[..]);
            let mut offset = 0usize;
            let mut jobs = Vec::with_capacity(cuts.len());
            for w in cuts.windows(2) {
                let part = &pending[w[0]..w[1]];
                let last = part.last().map_or(offset, |p| p.pos as usize + 1);
                let (c, rest_c) = std::mem::take(&mut certs).split_at_mut(last - offset);
                let (sn, rest_s) = std::mem::take(&mut snaps).split_at_mut(last - offset);
                jobs.push((part, offset, c, sn));
                (certs, snaps, offset) = (rest_c, rest_s, last);
            }
            let run = |(part, offset, c, sn)| certify_part(part, offset, c, sn, kind);
            if jobs.len() == 1 {
                results.extend(jobs.into_iter().map(run));
            } else {
                std::thread::scope(|scope| {
                    let handles: Vec<_> =
                        jobs.into_iter().map(|job| scope.spawn(move || run(job))).collect();
                    for h in handles {
                        if let Ok(r) = h.join() {
                            results.push(r);
                        }
                    }
                });
            }
        }
        pending.clear();
        let mut first: Option<Rejected> = None;
        for (pushed, failed) in results {
            for pos in pushed {
                let k = pos as usize;
                if !self.changed[k] {
                    self.changed[k] = true;
                    self.touched.push(pos);
                }
            }
            if let Some(f) = failed
                && first.as_ref().is_none_or(|g| f.seq < g.seq)
            {
                first = Some(f);
            }
        }
        first.map_or(Ok(()), Err)
    }

    /// The subsystem at position `pos` of this site.
    pub(crate) fn subsystem_at(&self, pos: u32) -> usize {
        self.owned.get(pos as usize).copied().unwrap_or(usize::MAX)
    }

    /// The position of owned subsystem `i` (`None`: another process's).
    pub(crate) fn position(&self, i: usize) -> Option<u32> {
        self.slot.get(i).copied().filter(|&s| s != u32::MAX)
    }

    /// One row certified at `t`.
    pub(crate) fn count(&mut self, t: f64) {
        self.rows += 1;
        self.last_time = Some(t);
    }

    /// Every owned subsystem's snapshot counts as changed (after a restart).
    pub(crate) fn mark_all(&mut self) {
        self.touched.clear();
        for (k, c) in self.changed.iter_mut().enumerate() {
            *c = true;
            self.touched.push(u32::try_from(k).unwrap_or(u32::MAX));
        }
    }

    /// Hand out the snapshots changed since the last call, in subsystem order.
    pub(crate) fn drain_changed(&mut self, mut give: impl FnMut(u32, WireSnapshot)) {
        self.touched.sort_unstable();
        for &s in &self.touched {
            let k = s as usize;
            self.changed[k] = false;
            if let Some(snap) = &self.snapshots[k] {
                give(u32::try_from(self.owned[k]).unwrap_or(u32::MAX), snap.into());
            }
        }
        self.touched.clear();
    }
}

/// Where `pending` (sorted by subsystem) is cut into at most `parts` runs at subsystem
/// boundaries: the runs' starts, then its length.
fn cuts(pending: &[Pending], parts: usize) -> Vec<usize> {
    let mut cuts = vec![0];
    for k in 1..parts {
        let mut at = pending.len() * k / parts;
        while at > 0 && at < pending.len() && pending[at].pos == pending[at - 1].pos {
            at += 1;
        }
        if at > *cuts.last().unwrap_or(&0) && at < pending.len() {
            cuts.push(at);
        }
    }
    cuts.push(pending.len());
    cuts
}

/// Certify one run of pending samples (`part`, subsystems from `offset` on) with their
/// certifiers `c` and snapshots `sn`: the positions pushed, in order, and the first sample
/// rejected (a subsystem's later samples are passed over after its rejection).
fn certify_part(
    part: &[Pending],
    offset: usize,
    c: &mut [Certifier],
    sn: &mut [Option<LocalSnapshot>],
    kind: CertificateKind,
) -> (Vec<u32>, Option<Rejected>) {
    let mut pushed = Vec::new();
    let mut failed: Option<Rejected> = None;
    for p in part {
        let k = p.pos as usize - offset;
        if failed.as_ref().is_some_and(|f| f.pos == p.pos) {
            continue;
        }
        let cert = &mut c[k];
        if p.gap {
            cert.gap();
        }
        let m = cert.config().regression.outputs.min(p.values.len());
        let (y, u) = p.values.split_at(m);
        match cert.push(p.t, y, u) {
            Ok(ev) => {
                let v = *ev.verdict(kind);
                match &mut sn[k] {
                    Some(snap) => snap.update(p.t, v, cert),
                    None => sn[k] = Some(LocalSnapshot::new(p.t, v, cert)),
                }
                if pushed.last() != Some(&p.pos) {
                    pushed.push(p.pos);
                }
            }
            Err(e) => {
                let r = Rejected { seq: p.seq, line: p.line, pos: p.pos, error: e };
                if failed.as_ref().is_none_or(|f| r.seq < f.seq) {
                    failed = Some(r);
                }
            }
        }
    }
    (pushed, failed)
}
