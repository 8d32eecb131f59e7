//! [`Run`]: the command line's `certify` over arrays, one sample or one block at a time.

use streamcert_certificate::{Certifier, Evidence, Interval};
use streamcert_pipeline::certify::{self, Summary};
use streamcert_pipeline::config::Config;
use streamcert_pipeline::output::region_columns;

use crate::{Error, EvidenceColumns};

/// Blocks at least this long are certified and stored on two threads.
const PIPELINE_MIN: usize = 1 << 15;
/// Samples per chunk between the two threads.
const CHUNK: usize = 2048;

/// Certified samples on their way to the columns.
struct Chunk {
    evidence: Vec<Evidence>,
    regions: Vec<Interval>,
    region_ends: Vec<usize>,
}

impl Chunk {
    fn new() -> Self {
        Self {
            evidence: Vec::with_capacity(CHUNK),
            regions: Vec::with_capacity(CHUNK * 8),
            region_ends: Vec::with_capacity(CHUNK),
        }
    }

    fn clear(&mut self) {
        self.evidence.clear();
        self.regions.clear();
        self.region_ends.clear();
    }
}

/// A `certify` run fed from arrays: the same certifier, the same per-sample summary
/// ([`certify::record`]) and the same checkpoints ([`certify::seal_checkpoint`]) as the
/// command line, so its numbers equal the command line's on the same data bit for bit.
///
/// Samples are checked as the command line checks a CSV row (finite values, strictly
/// increasing time), with the row's index and column name in the error; a block is checked
/// whole before any of it is absorbed, so a refused block leaves the run as it was.
#[derive(Debug, Clone)]
pub struct Run {
    cfg: Config,
    cert: Certifier,
    summary: Summary,
    region: Vec<Interval>,
    region_names: Vec<String>,
}

impl Run {
    /// A run of `cfg` from an empty window.
    ///
    /// # Errors
    /// [`Error::Config`] when the certifier refuses the configuration.
    pub fn new(cfg: Config) -> Result<Self, Error> {
        let cert = Certifier::new(cfg.certifier.clone())
            .map_err(|e| Error::Config(format!("configuration: invalid configuration: {e}")))?;
        Ok(Self::from_parts(cfg, cert, Summary::default()))
    }

    fn from_parts(cfg: Config, cert: Certifier, summary: Summary) -> Self {
        let mut channels: Vec<String> =
            cfg.columns.outputs.iter().chain(&cfg.columns.inputs).cloned().collect();
        if cfg.certifier.calibration.is_some() {
            channels.extend(cfg.columns.outputs.iter().map(|o| format!("calibrated_{o}")));
        }
        let region_names = region_columns(&channels);
        Self { cfg, cert, summary, region: Vec::new(), region_names }
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// The certifier.
    #[must_use]
    pub fn certifier(&self) -> &Certifier {
        &self.cert
    }

    /// The summary so far (its calibrated region is the one standing now).
    #[must_use]
    pub fn summary(&self) -> Summary {
        let mut s = self.summary.clone();
        certify::finish(&self.cert, &mut s);
        s
    }

    /// The region columns' names, as in the command line's CSV header.
    #[must_use]
    pub fn region_names(&self) -> &[String] {
        &self.region_names
    }

    /// The region values of the last sample (one interval per region channel).
    #[must_use]
    pub fn last_region(&self) -> &[Interval] {
        &self.region
    }

    /// Outputs `p` and inputs `m`.
    #[must_use]
    pub fn dims(&self) -> (usize, usize) {
        (self.cfg.columns.outputs.len(), self.cfg.columns.inputs.len())
    }

    /// Check the samples `t[k]`, `y[k·p..(k+1)·p]`, `u[k·m..(k+1)·m]` as the command line
    /// checks CSV rows, against the last time absorbed.
    ///
    /// # Errors
    /// [`Error::Shape`] for lengths that do not match `p`, `m` or each other;
    /// [`Error::Data`] for the first non-finite value or non-increasing time.
    pub fn check(&self, t: &[f64], y: &[f64], u: &[f64]) -> Result<(), Error> {
        let (p, m) = self.dims();
        let n = t.len();
        if y.len() != n * p || u.len() != n * m {
            return Err(Error::Shape(format!(
                "{n} times need {n} × {p} outputs and {n} × {m} inputs, got {} and {} values",
                y.len(),
                u.len()
            )));
        }
        let cols = &self.cfg.columns;
        let data = |row: usize, column: &str, message: String| Error::Data {
            row,
            column: Some(column.to_string()),
            message,
        };
        let finite = |row: usize, column: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(data(
                    row,
                    column,
                    format!(
                        "expected a finite number, found `{v}` (NaN and infinity are not accepted)"
                    ),
                ))
            }
        };
        let mut prev = self.summary.last_time;
        for k in 0..n {
            finite(k, &cols.time, t[k])?;
            if let Some(prev) = prev {
                if t[k] == prev {
                    let msg =
                        format!("duplicated time {}: times must be strictly increasing", t[k]);
                    return Err(data(k, &cols.time, msg));
                }
                if t[k] < prev {
                    let msg = format!(
                        "time {} is before the previous time {prev}: times must be strictly increasing",
                        t[k]
                    );
                    return Err(data(k, &cols.time, msg));
                }
            }
            prev = Some(t[k]);
            for (name, &v) in cols.outputs.iter().zip(&y[k * p..(k + 1) * p]) {
                finite(k, name, v)?;
            }
            for (name, &v) in cols.inputs.iter().zip(&u[k * m..(k + 1) * m]) {
                finite(k, name, v)?;
            }
        }
        Ok(())
    }

    /// Certify one sample (checked first): its evidence; the region values are then in
    /// [`last_region`](Self::last_region).
    ///
    /// # Errors
    /// As [`check`](Self::check), with row 0.
    pub fn push(&mut self, t: f64, y: &[f64], u: &[f64]) -> Result<Evidence, Error> {
        self.check(&[t], y, u)?;
        self.absorb(0, t, y, u)
    }

    fn absorb(&mut self, row: usize, t: f64, y: &[f64], u: &[f64]) -> Result<Evidence, Error> {
        let ev = self.cert.push(t, y, u).map_err(|e| Error::Data {
            row,
            column: None,
            message: e.to_string(),
        })?;
        self.region.clear();
        certify::record(&self.cert, &mut self.summary, t, y, &ev, &mut self.region);
        Ok(ev)
    }

    /// Certify a block of `n = t.len()` samples (`y` row-major `n × p`, `u` row-major
    /// `n × m`), appending every sample's evidence to `out`. The block is checked whole
    /// first: a refused block absorbs nothing. A block of 32 768 samples or more is
    /// certified on this thread while a second one stores the columns (the same values in
    /// the same order).
    ///
    /// # Errors
    /// As [`check`](Self::check); a sample the certifier itself refuses after the check
    /// (none is known) stops the block there, the samples before it absorbed.
    pub fn push_block(
        &mut self,
        t: &[f64],
        y: &[f64],
        u: &[f64],
        out: &mut EvidenceColumns,
    ) -> Result<(), Error> {
        self.check(t, y, u)?;
        let (p, m) = self.dims();
        if t.len() < PIPELINE_MIN {
            for k in 0..t.len() {
                let ev = self.absorb(k, t[k], &y[k * p..(k + 1) * p], &u[k * m..(k + 1) * m])?;
                out.push(&ev, &self.region);
            }
            return Ok(());
        }
        // A long block: this thread certifies, a second one stores the columns (for a million
        // samples the result's fresh pages cost as much as the arithmetic), in chunks that
        // travel back to be refilled. Order and values are those of the loop above.
        std::thread::scope(|scope| {
            let (full_tx, full_rx) = std::sync::mpsc::sync_channel::<Chunk>(4);
            let (empty_tx, empty_rx) = std::sync::mpsc::channel::<Chunk>();
            scope.spawn(move || {
                for chunk in full_rx {
                    let mut from = 0;
                    for (ev, &to) in chunk.evidence.iter().zip(&chunk.region_ends) {
                        out.push(ev, &chunk.regions[from..to]);
                        from = to;
                    }
                    // The certifying side may have finished: a failed return is harmless.
                    let _ = empty_tx.send(chunk);
                }
            });
            for start in (0..t.len()).step_by(CHUNK) {
                let mut chunk = empty_rx.try_recv().unwrap_or_else(|_| Chunk::new());
                chunk.clear();
                let mut failed = None;
                for k in start..t.len().min(start + CHUNK) {
                    let (yk, uk) = (&y[k * p..(k + 1) * p], &u[k * m..(k + 1) * m]);
                    match self.absorb(k, t[k], yk, uk) {
                        Ok(ev) => {
                            chunk.evidence.push(ev);
                            chunk.regions.extend_from_slice(&self.region);
                            chunk.region_ends.push(chunk.regions.len());
                        }
                        Err(e) => {
                            failed = Some(e);
                            break;
                        }
                    }
                }
                // The storing side ends only when this side drops its sender: it is alive.
                let _ = full_tx.send(chunk);
                if let Some(e) = failed {
                    return Err(e);
                }
            }
            Ok(())
        })
    }

    /// Empty evidence columns for `n` samples of this run.
    #[must_use]
    pub fn columns(&self, n: usize) -> EvidenceColumns {
        EvidenceColumns::with_capacity(n, self.region_names.clone())
    }

    /// The sealed checkpoint's bytes: the command line's `--checkpoint` format (binary), so
    /// either restores the other's.
    ///
    /// # Errors
    /// [`Error::Checkpoint`] when the state cannot be encoded.
    pub fn checkpoint(&self) -> Result<Vec<u8>, Error> {
        Ok(certify::seal_checkpoint("checkpoint", &self.cert, &self.summary)?)
    }

    /// A run resumed from a checkpoint for `cfg`, refused exactly as the command line's
    /// `--resume` refuses it (damaged, foreign, another configuration).
    ///
    /// # Errors
    /// [`Error::Checkpoint`].
    pub fn restore(bytes: &[u8], cfg: Config) -> Result<Self, Error> {
        let (cert, summary) = certify::open_checkpoint(bytes, &cfg, "checkpoint")?;
        Ok(Self::from_parts(cfg, cert, summary))
    }
}
