//! [`EvidenceWriter`]: evidence rows ([`EvidenceRow`]) as CSV (the csv crate) or JSON lines,
//! buffered, flushed per row only when asked. The command line and the experiments' traces
//! write through it, so there is one output format.

use std::io::Write;

use serde::Serialize;
use serde::ser::SerializeMap;
use streamcert_certificate::{EVIDENCE_COLUMNS, Evidence, EvidenceRow, Interval};

mod csv_row;
use csv_row::CsvRows;

/// Output format.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Format {
    /// Comma-separated values with a header (the evidence columns); an absent number is an
    /// empty field, a reason is quoted when it contains a comma. Default.
    #[default]
    Csv,
    /// One JSON object per line, the same names; an absent number is `null`.
    Jsonl,
}

/// When written rows reach the output.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Flush {
    /// Buffered, flushed at the end and at each checkpoint (a file). Default.
    #[default]
    Buffered,
    /// Every row as soon as it is written (a live input: a pipe or a terminal).
    EachRow,
}

/// Whether a CSV output starts with its header line.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Header {
    /// Write the header first. Default.
    #[default]
    Write,
    /// No header: the output continues one that has it (a resumed run).
    Omit,
}

impl Header {
    /// [`Header::Write`] for a fresh run, [`Header::Omit`] when it resumes (its output
    /// continues one that has the header).
    #[must_use]
    pub fn when_fresh<T>(resume: Option<&T>) -> Self {
        if resume.is_none() { Self::Write } else { Self::Omit }
    }
}

/// Encoded CSV rows are handed to `out` once this many bytes are buffered.
const CSV_BUFFER: usize = 1 << 16;

enum Sink<W: Write> {
    Csv { out: W, rows: Box<CsvRows> },
    Jsonl(std::io::BufWriter<W>),
}

/// Writes one [`EvidenceRow`] per [`Evidence`]. Numbers are written in the shortest form that
/// reads back to the same `f64`, so a written file round-trips exactly. The CSV bytes are
/// those of the csv crate's serde writer (`csv::Writer::serialize`), tested byte for byte;
/// they are encoded by a specialised encoder that skips the quoting scan of numbers and
/// reuses the text of values that did not change since the previous row.
pub struct EvidenceWriter<W: Write> {
    sink: Sink<W>,
    flush_each_row: bool,
    /// Names of the region columns after the evidence columns (`region_lo_<channel>`,
    /// `region_hi_<channel>` per channel), and one row's values (reused).
    region_names: Vec<String>,
    region_values: Vec<Option<f64>>,
}

/// The region columns of one JSON line (a map, flattened into the row).
struct RegionMap<'a> {
    names: &'a [String],
    values: &'a [Option<f64>],
}

impl Serialize for RegionMap<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(self.names.len()))?;
        for (k, v) in self.names.iter().zip(self.values) {
            map.serialize_entry(k, v)?;
        }
        map.end()
    }
}

#[derive(Serialize)]
struct JsonRow<'a> {
    #[serde(flatten)]
    row: EvidenceRow,
    #[serde(flatten)]
    region: RegionMap<'a>,
}

/// The region column names for channels named `channels` (outputs, then inputs): per
/// channel `region_lo_<name>`, `region_hi_<name>`.
#[must_use]
pub fn region_columns(channels: &[String]) -> Vec<String> {
    channels.iter().flat_map(|c| [format!("region_lo_{c}"), format!("region_hi_{c}")]).collect()
}

impl<W: Write> EvidenceWriter<W> {
    /// A writer in `format`; with [`Header::Write`], the CSV header line is written first
    /// (JSON lines have none). With [`Flush::EachRow`], every row is flushed to `out` as soon
    /// as it is written (a live feed); otherwise output is buffered and flushed by
    /// [`flush`](Self::flush).
    ///
    /// # Errors
    /// Writing the header.
    ///
    /// `region_names` ([`region_columns`]) are written after the evidence columns, with the
    /// values passed to [`write_with_region`](Self::write_with_region); empty for none.
    pub fn new(
        out: W,
        format: Format,
        header: Header,
        flush: Flush,
        region_names: Vec<String>,
    ) -> std::io::Result<Self> {
        let flush_each_row = flush == Flush::EachRow;
        let sink = match format {
            Format::Csv => {
                let mut rows = Box::new(CsvRows::new(region_names.len()));
                if header == Header::Write {
                    rows.header(
                        EVIDENCE_COLUMNS
                            .iter()
                            .copied()
                            .chain(region_names.iter().map(String::as_str)),
                    );
                }
                Sink::Csv { out, rows }
            }
            Format::Jsonl => Sink::Jsonl(std::io::BufWriter::with_capacity(1 << 16, out)),
        };
        let region_values = vec![None; region_names.len()];
        let mut w = Self { sink, flush_each_row, region_names, region_values };
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
        self.write_with_region(evidence, &[])
    }

    /// Write the row of one sample with the region columns: `region` holds one
    /// [`Interval`] per region channel (half the region names); missing or empty intervals
    /// are written as absent values.
    ///
    /// # Errors
    /// Writing to the output.
    pub fn write_with_region(
        &mut self,
        evidence: &Evidence,
        region: &[Interval],
    ) -> std::io::Result<()> {
        let row = EvidenceRow::from(evidence);
        for (i, pair) in self.region_values.chunks_exact_mut(2).enumerate() {
            let r = region.get(i).copied().filter(Interval::is_proper);
            pair[0] = r.map(|r| r.lo);
            pair[1] = r.map(|r| r.hi);
        }
        match &mut self.sink {
            Sink::Csv { out, rows } => {
                rows.row(&row, &self.region_values);
                if rows.bytes().len() >= CSV_BUFFER {
                    out.write_all(rows.bytes())?;
                    rows.clear();
                }
            }
            Sink::Jsonl(w) => {
                if self.region_values.is_empty() {
                    serde_json::to_writer(&mut *w, &row)?;
                } else {
                    let region =
                        RegionMap { names: &self.region_names, values: &self.region_values };
                    serde_json::to_writer(&mut *w, &JsonRow { row, region })?;
                }
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
            Sink::Csv { out, rows } => {
                out.write_all(rows.bytes())?;
                rows.clear();
                out.flush()
            }
            Sink::Jsonl(w) => w.flush(),
        }
    }
}

/// Rows encoded but not yet handed to the output are written when the writer is dropped (as
/// the csv crate's writer does), so an early return after an error keeps the rows before it.
impl<W: Write> Drop for EvidenceWriter<W> {
    fn drop(&mut self) {
        // Best effort: an error here has no caller to go to.
        let _ = self.flush();
    }
}
