//! [`SampleBatch`] and [`NetworkCertifier::push_batch`]: many samples at once, the subsystems
//! sharded over threads between epochs (the fleet path).
//!
//! A batch is cut into segments at the samples that make an epoch due (in arrival order, as
//! [`NetworkCertifier::push`] would). Within a segment the subsystems are independent, so
//! each of `threads` scoped threads advances a contiguous range of subsystems through the
//! segment's samples of its range, in order; then the due epochs are composed from the
//! snapshots, as one thread would. The epoch reports are therefore those of pushing the
//! samples one by one, bit for bit, for any number of threads (tested).

use streamcert_certificate::Certifier;

use crate::composer::record;
use crate::{EpochReport, LocalSnapshot, NetworkCertifier, NetworkError};

/// Samples of several subsystems in arrival order, stored flat (reuse one with
/// [`clear`](Self::clear)).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SampleBatch {
    index: Vec<u32>,
    t: Vec<f64>,
    /// Start of each sample's values (`y` then `u`) in `values`; one more entry at the end.
    offset: Vec<usize>,
    values: Vec<f64>,
}

impl SampleBatch {
    /// An empty batch.
    #[must_use]
    pub fn new() -> Self {
        Self { offset: vec![0], ..Self::default() }
    }

    /// Append subsystem `i`'s sample at `t` with outputs `y` and inputs `u`.
    ///
    /// # Panics
    /// If `i` does not fit in 32 bits.
    pub fn push(&mut self, i: usize, t: f64, y: &[f64], u: &[f64]) {
        if self.offset.is_empty() {
            self.offset.push(0);
        }
        self.index.push(u32::try_from(i).expect("subsystem index fits in 32 bits"));
        self.t.push(t);
        self.values.extend_from_slice(y);
        self.values.extend_from_slice(u);
        self.offset.push(self.values.len());
    }

    /// Number of samples.
    #[must_use]
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// Whether the batch is empty.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Forget every sample (the buffers are kept).
    pub fn clear(&mut self) {
        self.index.clear();
        self.t.clear();
        self.values.clear();
        self.offset.clear();
        self.offset.push(0);
    }

    /// Sample `j`: subsystem, time, and its values (`y` then `u`).
    fn get(&self, j: usize) -> (usize, f64, &[f64]) {
        (self.index[j] as usize, self.t[j], &self.values[self.offset[j]..self.offset[j + 1]])
    }
}

/// Below this many samples a segment is run on the calling thread.
const MIN_PARALLEL: usize = 2048;

/// Push samples `range` of `batch` into the subsystems `first..first + certifiers.len()`;
/// the first error with its batch position. When the range holds at least two samples per
/// subsystem they are taken subsystem by subsystem (a counting sort of their positions into
/// `order`, stable, so each subsystem still sees its samples in arrival order): one
/// certifier's state stays in cache for all of its samples of the segment, instead of every
/// sample touching another certifier. The subsystems are independent within a segment, so
/// the states and snapshots are those of arrival order.
fn run_shard(
    batch: &SampleBatch,
    range: std::ops::Range<usize>,
    first: usize,
    certifiers: &mut [Certifier],
    last: &mut [Option<LocalSnapshot>],
    net: &crate::NetworkConfig,
    order: &mut Vec<u32>,
) -> Option<(usize, NetworkError)> {
    let n = certifiers.len();
    let end = first + n;
    let mut one = |j: usize| -> Option<(usize, NetworkError)> {
        let (i, t, v) = batch.get(j);
        let c = &mut certifiers[i - first];
        let (y, u) = v.split_at(c.config().regression.outputs.min(v.len()));
        match c.push(t, y, u) {
            Ok(ev) => {
                record(&mut last[i - first], t, net.certificate, c, &ev);
                None
            }
            Err(source) => {
                let name = net.subsystems[i].name.clone();
                Some((j, NetworkError::Subsystem { index: i, name, source }))
            }
        }
    };
    if range.len() < 2 * n {
        return range
            .filter(|&j| (first..end).contains(&(batch.index[j] as usize)))
            .find_map(&mut one);
    }
    // Counting sort of the positions by subsystem: `order` holds n + 1 bucket starts, then
    // the positions.
    order.clear();
    order.resize(n + 1, 0);
    for j in range.clone() {
        let i = batch.index[j] as usize;
        if (first..end).contains(&i) {
            order[i - first + 1] += 1;
        }
    }
    for s in 0..n {
        order[s + 1] += order[s];
    }
    let total = order[n] as usize;
    order.resize(n + 1 + total, 0);
    let (starts, positions) = order.split_at_mut(n + 1);
    // Place each position at its bucket's cursor; afterwards `starts[s]` is the end of bucket
    // `s` (the start of `s + 1`).
    for j in range {
        let i = batch.index[j] as usize;
        if (first..end).contains(&i) {
            positions[starts[i - first] as usize] = j as u32;
            starts[i - first] += 1;
        }
    }
    let mut first_error: Option<(usize, NetworkError)> = None;
    for s in 0..n {
        let lo = if s == 0 { 0 } else { starts[s - 1] as usize };
        for &j in &positions[lo..starts[s] as usize] {
            if let Some((j, e)) = one(j as usize) {
                if first_error.as_ref().is_none_or(|&(f, _)| j < f) {
                    first_error = Some((j, e));
                }
                break; // this subsystem stops at its first error; the others go on
            }
        }
    }
    first_error
}

impl NetworkCertifier {
    /// Push every sample of `batch` in order, with the subsystems sharded over `threads`
    /// scoped threads between the epochs the batch makes due; each composed epoch goes to
    /// `on_epoch`. The reports equal those of [`push`](Self::push) sample by sample, for any
    /// `threads >= 1`.
    ///
    /// A batch that names an unknown subsystem is refused whole. On another error the samples
    /// before it are pushed and its epoch segment may be partly pushed past it (the other
    /// threads do not stop): the error names the subsystem; restore a checkpoint to go back.
    ///
    /// # Errors
    /// [`NetworkError::UnknownSubsystem`], [`NetworkError::TimeJump`],
    /// [`NetworkError::Subsystem`], [`NetworkError::Compose`].
    pub fn push_batch(
        &mut self,
        batch: &SampleBatch,
        threads: usize,
        mut on_epoch: impl FnMut(&EpochReport),
    ) -> Result<(), NetworkError> {
        let len = self.certifiers.len();
        if let Some(&i) = batch.index.iter().find(|&&i| i as usize >= len) {
            return Err(NetworkError::UnknownSubsystem { index: i as usize, len });
        }
        let mut start = 0;
        for j in 0..=batch.len() {
            let due = if j < batch.len() {
                match self.composer.due(&self.cfg, batch.t[j]) {
                    Ok(due) if due.is_empty() => continue,
                    Ok(due) => Ok(due),
                    Err(e) => Err(e),
                }
            } else {
                Ok(0..0)
            };
            self.run_segment(batch, start..j, threads)?;
            start = j;
            for k in due? {
                let report = self.composer.compose(&self.cfg, k, &self.last)?;
                on_epoch(&report);
            }
        }
        Ok(())
    }

    /// Samples `range` of `batch` (no epoch due inside it), over `threads` threads.
    fn run_segment(
        &mut self,
        batch: &SampleBatch,
        range: std::ops::Range<usize>,
        threads: usize,
    ) -> Result<(), NetworkError> {
        let n = self.certifiers.len();
        let threads = threads.clamp(1, n.max(1));
        if self.scratch.0.len() < threads {
            self.scratch.0.resize_with(threads, Vec::new);
        }
        let cfg = &self.cfg;
        if threads == 1 || range.len() < MIN_PARALLEL {
            let order = self.scratch.0.first_mut().expect("one scratch per thread");
            return match run_shard(
                batch,
                range,
                0,
                &mut self.certifiers,
                &mut self.last,
                cfg,
                order,
            ) {
                Some((_, e)) => Err(e),
                None => Ok(()),
            };
        }
        let chunk = n.div_ceil(threads);
        let first_error = std::thread::scope(|scope| {
            let handles: Vec<_> = self
                .certifiers
                .chunks_mut(chunk)
                .zip(self.last.chunks_mut(chunk))
                .zip(self.scratch.0.iter_mut())
                .enumerate()
                .map(|(s, ((certifiers, last), order))| {
                    let range = range.clone();
                    scope.spawn(move || {
                        run_shard(batch, range, s * chunk, certifiers, last, cfg, order)
                    })
                })
                .collect();
            handles
                .into_iter()
                .filter_map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
                .min_by_key(|&(j, _)| j)
        });
        match first_error {
            Some((_, e)) => Err(e),
            None => Ok(()),
        }
    }
}

/// Per-thread scratch of [`NetworkCertifier::push_batch`]: positions sorted by subsystem. Not
/// part of the state (never serialised, equal to any other).
#[derive(Debug, Clone, Default)]
pub(crate) struct Scratch(pub(crate) Vec<Vec<u32>>);

impl PartialEq for Scratch {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}
