//! A file's run in three stages on three threads, in batches: one reads and parses, one
//! certifies, the calling one formats and writes, each while the others do. Rows, errors,
//! checkpoints and output stay in input order, so the output is the live path's (tested).

use std::io::{Read, Write};
use std::sync::mpsc::{Receiver, Sender, SyncSender, channel, sync_channel};

use streamcert_certificate::{Evidence, Interval};

use super::{Step, write_checkpoint};
use crate::CliError;
use crate::input::{Sample, SampleReader};
use crate::output::EvidenceWriter;

/// Rows a stage hands over at a time.
const BATCH: usize = 1024;

/// Batches in flight between two stages (beyond it the faster stage waits).
const IN_FLIGHT: usize = 4;

/// Parsed rows on their way from the reading thread to the certifying one: each row's
/// outcome and sample (the samples' buffers reused when the batch comes back).
struct Parsed {
    outcomes: Vec<Result<(), CliError>>,
    samples: Vec<Sample>,
}

impl Parsed {
    fn new() -> Self {
        Self { outcomes: Vec::with_capacity(BATCH), samples: Vec::with_capacity(BATCH) }
    }

    /// Read up to [`BATCH`] rows; `true` at the end of the input.
    fn fill<R: Read>(&mut self, reader: &mut SampleReader<R>) -> bool {
        self.outcomes.clear();
        while self.outcomes.len() < BATCH {
            let i = self.outcomes.len();
            if self.samples.len() == i {
                self.samples.push(Sample::default());
            }
            let Some(next) = reader.next_into(&mut self.samples[i]) else { return true };
            self.outcomes.push(next);
        }
        false
    }
}

/// Certified rows on their way from the certifying thread to the writing one. Batches travel
/// back to be refilled, so their buffers are reused.
struct Batch {
    evidence: Vec<Evidence>,
    /// The rows' region values, concatenated; row `i` ends at `region_ends[i]`.
    regions: Vec<Interval>,
    region_ends: Vec<usize>,
    /// Checkpoints due: the sealed bytes, written once the first `n` rows are out.
    checkpoints: Vec<(usize, Vec<u8>)>,
    /// The error that stopped the run, after the rows before it.
    error: Option<CliError>,
}

impl Batch {
    fn new() -> Self {
        Self {
            evidence: Vec::with_capacity(BATCH),
            regions: Vec::with_capacity(BATCH * 6),
            region_ends: Vec::with_capacity(BATCH),
            checkpoints: Vec::new(),
            error: None,
        }
    }

    fn clear(&mut self) {
        self.evidence.clear();
        self.regions.clear();
        self.region_ends.clear();
        self.checkpoints.clear();
        self.error = None;
    }
}

/// A batch from `spent`, or a new one.
fn reuse<T>(spent: &Receiver<T>, new: fn() -> T) -> T {
    spent.try_recv().unwrap_or_else(|_| new())
}

/// Run `step` over `reader`'s rows into `writer` (module docs).
pub(super) fn run<R: Read + Send, W: Write>(
    mut step: Step<'_>,
    reader: &mut SampleReader<R>,
    writer: &mut EvidenceWriter<W>,
) -> Result<(), CliError> {
    let io = |e| CliError::io("writing output", e);
    let opts = step.opts;
    std::thread::scope(|scope| -> Result<(), CliError> {
        let (parsed_tx, parsed_rx) = sync_channel::<Parsed>(IN_FLIGHT);
        let (spent_tx, spent_rx) = channel::<Parsed>();
        let (full_tx, full_rx) = sync_channel::<Batch>(IN_FLIGHT);
        let (empty_tx, empty_rx) = channel::<Batch>();
        scope.spawn(move || read(reader, &parsed_tx, &spent_rx));
        scope.spawn(move || certify(&mut step, &parsed_rx, &spent_tx, (&full_tx, &empty_rx)));
        for mut batch in full_rx {
            let mut from = 0;
            let mut checkpoints = batch.checkpoints.drain(..).peekable();
            for (i, ev) in batch.evidence.iter().enumerate() {
                let to = batch.region_ends[i];
                writer.write_with_region(ev, &batch.regions[from..to]).map_err(io)?;
                from = to;
                while let Some((_, sealed)) = checkpoints.next_if(|(n, _)| *n == i + 1) {
                    writer.flush().map_err(io)?;
                    write_checkpoint(opts, &sealed)?;
                }
            }
            drop(checkpoints);
            if let Some(e) = batch.error.take() {
                return Err(e);
            }
            // The certifying thread may have finished: a failed return is harmless.
            let _ = empty_tx.send(batch);
        }
        Ok(())
    })
}

/// The reading stage: parsed batches until the end of the input, or until the certifying
/// stage stops taking them (it met an error).
fn read<R: Read>(reader: &mut SampleReader<R>, out: &SyncSender<Parsed>, spent: &Receiver<Parsed>) {
    loop {
        let mut parsed = reuse(spent, Parsed::new);
        let end = parsed.fill(reader);
        if out.send(parsed).is_err() || end {
            return;
        }
    }
}

/// The certifying stage: each parsed batch into a certified one, until the rows end or a row
/// stops the run (its error then in the batch, after the rows before it).
fn certify(
    step: &mut Step<'_>,
    parsed: &Receiver<Parsed>,
    spent: &Sender<Parsed>,
    (out, empty): (&SyncSender<Batch>, &Receiver<Batch>),
) {
    for mut rows in parsed {
        let mut batch = reuse(empty, Batch::new);
        batch.clear();
        let stop = step.fill(&mut rows, &mut batch);
        // A closed channel means the writing side stopped (an error): stop too.
        if out.send(batch).is_err() || stop {
            return;
        }
        // The reading thread may have finished: a failed return is harmless.
        let _ = spent.send(rows);
    }
}

impl Step<'_> {
    /// Certify the parsed `rows` into `batch`; `true` when the run ends here (an error, then
    /// in `batch.error`).
    fn fill(&mut self, rows: &mut Parsed, batch: &mut Batch) -> bool {
        for (next, s) in rows.outcomes.drain(..).zip(&rows.samples) {
            let ev = match self.row(next, s, &mut batch.regions) {
                Ok(Some(ev)) => ev,
                Ok(None) => continue,
                Err(e) => {
                    batch.error = Some(e);
                    return true;
                }
            };
            batch.evidence.push(ev);
            batch.region_ends.push(batch.regions.len());
            match self.due_checkpoint() {
                Ok(None) => {}
                Ok(Some(sealed)) => batch.checkpoints.push((batch.evidence.len(), sealed)),
                Err(e) => {
                    batch.error = Some(e);
                    return true;
                }
            }
        }
        false
    }
}
