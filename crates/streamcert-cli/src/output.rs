//! [`EvidenceWriter`]: evidence rows ([`EvidenceRow`]) as CSV (the csv crate) or JSON lines,
//! buffered, flushed per row only when asked. The command line and the experiments' traces
//! write through it, so there is one output format.

use std::io::Write;

use streamcert_certificate::{EVIDENCE_COLUMNS, Evidence, EvidenceRow};

/// Output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// Comma-separated values with a header (the evidence columns); an absent number is an
    /// empty field, a reason is quoted when it contains a comma.
    Csv,
    /// One JSON object per line, the same names; an absent number is `null`.
    Jsonl,
}

enum Sink<W: Write> {
    Csv(Box<csv::Writer<W>>),
    Jsonl(std::io::BufWriter<W>),
}

/// Writes one [`EvidenceRow`] per [`Evidence`]. Numbers are written in the shortest form that
/// reads back to the same `f64` (ryu), so a written file round-trips exactly.
pub struct EvidenceWriter<W: Write> {
    sink: Sink<W>,
    flush_each_row: bool,
}

impl<W: Write> EvidenceWriter<W> {
    /// A writer in `format`; with `header`, the CSV header line is written first (JSON lines
    /// have none). With `flush_each_row`, every row is flushed to `out` as soon as it is
    /// written (a live feed); otherwise output is buffered and flushed by
    /// [`flush`](Self::flush).
    ///
    /// # Errors
    /// Writing the header.
    pub fn new(
        out: W,
        format: Format,
        header: bool,
        flush_each_row: bool,
    ) -> std::io::Result<Self> {
        let sink = match format {
            Format::Csv => {
                let mut w = csv::WriterBuilder::new().has_headers(false).from_writer(out);
                if header {
                    w.write_record(EVIDENCE_COLUMNS)?;
                }
                Sink::Csv(Box::new(w))
            }
            Format::Jsonl => Sink::Jsonl(std::io::BufWriter::with_capacity(1 << 16, out)),
        };
        let mut w = Self { sink, flush_each_row };
        if flush_each_row {
            w.flush()?;
        }
        Ok(w)
    }

    /// Write the row of one sample.
    ///
    /// # Errors
    /// Writing to the output.
    pub fn write(&mut self, evidence: &Evidence) -> std::io::Result<()> {
        let row = EvidenceRow::from(evidence);
        match &mut self.sink {
            Sink::Csv(w) => w.serialize(row)?,
            Sink::Jsonl(w) => {
                serde_json::to_writer(&mut *w, &row)?;
                w.write_all(b"\n")?;
            }
        }
        if self.flush_each_row {
            self.flush()?;
        }
        Ok(())
    }

    /// Flush the buffered rows to the output.
    ///
    /// # Errors
    /// Writing to the output.
    pub fn flush(&mut self) -> std::io::Result<()> {
        match &mut self.sink {
            Sink::Csv(w) => w.flush(),
            Sink::Jsonl(w) => w.flush(),
        }
    }
}
