//! Streaming CSV input with a header, read line by line so a live feed works, and an error for
//! every malformed row that names the file, the line and the column.

use std::io::Read;

mod record;
pub(crate) use record::RecordReader;

use crate::config::Columns;
use crate::{CliError, RowError};

/// One parsed row.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Sample {
    /// 1-based line number in the input.
    pub line: u64,
    /// Time.
    pub t: f64,
    /// Outputs, in the configured order.
    pub y: Vec<f64>,
    /// Inputs, in the configured order.
    pub u: Vec<f64>,
}

/// Reads samples from a CSV stream whose header names the configured columns (other columns
/// are ignored), with the csv crate's grammar: a configurable delimiter, quoted fields, a
/// UTF-8 byte-order mark before the header (as spreadsheets write it), surrounding spaces
/// trimmed, blank lines skipped, `\n`, `\r\n` or `\r` line ends. Plain lines are split in
/// place, others go through `csv-core` (see `record.rs`); a row is parsed as soon as its line
/// is complete, so a live feed works. Line numbers in errors are physical lines.
pub struct SampleReader<R> {
    reader: RecordReader<R>,
    file: String,
    line: u64,
    header: Vec<String>,
    time: usize,
    outputs: Vec<usize>,
    inputs: Vec<usize>,
    last_time: Option<f64>,
    /// Data rows read after the header, well formed or not.
    records: u64,
}

/// A read error of the input as the CLI's error.
pub(crate) fn read_error(file: &str, e: std::io::Error) -> CliError {
    CliError::io(format!("reading {file}"), e)
}

impl<R: Read> SampleReader<R> {
    /// Read the header and map the configured columns.
    ///
    /// # Errors
    /// [`CliError::Input`] for an empty input, an unreadable header, a header that lacks a
    /// configured column or an invalid delimiter; [`CliError::Io`] for a read error.
    pub fn new(reader: R, file: &str, columns: &Columns) -> Result<Self, CliError> {
        let input = |message: String| CliError::Input { file: file.into(), message };
        let delimiter = columns.delimiter_byte().map_err(input)?;
        let mut reader = RecordReader::new(reader, delimiter);
        let read = reader.read_record().map_err(|e| read_error(file, e))?;
        if !read {
            return Err(input("empty input: expected a header line naming the columns".into()));
        }
        let line = reader.line();
        let mut header = Vec::with_capacity(reader.len());
        for i in 0..reader.len() {
            let field = reader.get(i).unwrap_or_default();
            let name = std::str::from_utf8(field)
                .map_err(|_| input(format!("line {line}: the header is not valid UTF-8")))?;
            header.push(name.trim_start_matches('\u{feff}').trim().to_string());
        }
        // A header read as one field that holds another delimiter: say which setting to
        // change.
        let hint = match header.as_slice() {
            [one] => [(';', ";"), ('\t', "tab"), (',', ",")]
                .into_iter()
                .find(|(c, _)| one.contains(*c) && columns.delimiter_byte() != Ok(*c as u8))
                .map(|(_, name)| {
                    format!(
                        ": the header is one field that holds {name:?}; set `delimiter = \
                         \"{name}\"` in [columns]"
                    )
                }),
            _ => None,
        }
        .unwrap_or_default();
        let find = |name: &str| {
            header.iter().position(|h| h == name).ok_or_else(|| CliError::Input {
                file: file.into(),
                message: format!(
                    "line {line}: the header has no column `{name}` (configured in [columns]); \
                     found {header:?} (delimiter {:?}){hint}",
                    columns.delimiter
                ),
            })
        };
        let time = find(&columns.time)?;
        let outputs = columns.outputs.iter().map(|c| find(c)).collect::<Result<Vec<_>, _>>()?;
        let inputs = columns.inputs.iter().map(|c| find(c)).collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            reader,
            file: file.into(),
            line,
            header,
            time,
            outputs,
            inputs,
            last_time: None,
            records: 0,
        })
    }

    /// Data rows read so far after the header, well formed or not (blank lines are not rows).
    #[must_use]
    pub fn records(&self) -> u64 {
        self.records
    }

    /// The next row into `s`: `None` at the end of the input, `Some(Err)` for a malformed row
    /// (which is then consumed; the reader can continue). Blank lines are ignored. An
    /// unterminated quote runs to the end of the input, as in the csv crate, so its row has
    /// too few fields.
    ///
    /// # Errors
    /// I/O errors are reported as [`CliError::Io`] inside `Some(Err)`.
    pub fn next_into(&mut self, s: &mut Sample) -> Option<Result<(), CliError>> {
        match self.reader.read_record() {
            Ok(false) => None,
            Ok(true) => {
                self.records += 1;
                self.line = self.reader.line();
                Some(self.parse(s).map_err(CliError::Row))
            }
            Err(e) => {
                self.line = self.reader.position_line();
                Some(Err(read_error(&self.file, e)))
            }
        }
    }

    fn parse(&mut self, s: &mut Sample) -> Result<(), RowError> {
        let record = &self.reader;
        let err = |column: Option<&str>, message: String| RowError {
            file: self.file.clone(),
            line: self.line,
            column: column.map(String::from),
            message,
        };
        if record.len() != self.header.len() {
            return Err(err(
                None,
                format!(
                    "expected {} fields as in the header, found {} (missing column or truncated row?)",
                    self.header.len(),
                    record.len()
                ),
            ));
        }
        let number = |i: usize| -> Result<f64, RowError> {
            let name = self.header[i].as_str();
            // Surrounding spaces are trimmed here, for the used fields only (the csv crate's
            // own trimming would trim every field, read or not).
            let raw = record.get(i).unwrap_or_default().trim_ascii();
            // fast-float2 parses the bytes (no UTF-8 pass), correctly rounded like
            // `str::parse`; its extra spellings (`inf`, `nan`) are refused below.
            let v: f64 = fast_float2::parse(raw).map_err(|_| {
                let text = String::from_utf8_lossy(raw);
                err(Some(name), format!("expected a number, found `{text}`"))
            })?;
            if !v.is_finite() {
                let text = String::from_utf8_lossy(raw);
                return Err(err(
                    Some(name),
                    format!(
                        "expected a finite number, found `{text}` (NaN and infinity are not accepted)"
                    ),
                ));
            }
            Ok(v)
        };
        let t = number(self.time)?;
        if let Some(prev) = self.last_time {
            if t == prev {
                return Err(err(
                    Some(&self.header[self.time]),
                    format!("duplicated time {t}: times must be strictly increasing"),
                ));
            }
            if t < prev {
                return Err(err(
                    Some(&self.header[self.time]),
                    format!(
                        "time {t} is before the previous time {prev}: times must be strictly increasing"
                    ),
                ));
            }
        }
        s.y.clear();
        for &i in &self.outputs {
            s.y.push(number(i)?);
        }
        s.u.clear();
        for &i in &self.inputs {
            s.u.push(number(i)?);
        }
        s.t = t;
        s.line = self.line;
        self.last_time = Some(t);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    /// The two parsers agree on whether a field is a number, and on its value.
    fn agree(text: &str) {
        let std: Option<f64> = text.parse().ok();
        let fast: Option<f64> = fast_float2::parse(text.as_bytes()).ok();
        assert_eq!(std.map(f64::to_bits), fast.map(f64::to_bits), "`{text}`");
    }

    #[test]
    fn fast_float_reads_what_str_parse_reads() {
        for text in [
            "0",
            "-0",
            "+1",
            ".5",
            "1.",
            "1e5",
            "1E-5",
            "-1.5e+300",
            "1e-400",
            "1e400",
            "",
            " ",
            "-",
            "+",
            ".",
            "e5",
            "1e",
            "1e+",
            "0x10",
            "1_0",
            "1,5",
            "inf",
            "-inf",
            "Infinity",
            "NaN",
            "nan",
            "1.0.0",
            "1e5e5",
            "١",
            "0.1 ",
            "00012",
            "4.9e-324",
            "2.2250738585072014e-308",
        ] {
            agree(text);
        }
    }

    proptest! {
        #[test]
        fn fast_float_agrees_on_formatted_numbers(bits in any::<u64>(), digits in 0usize..20) {
            let v = f64::from_bits(bits);
            agree(&format!("{v}"));
            agree(&format!("{v:e}"));
            agree(&format!("{v:.digits$}"));
            agree(&format!("{v:.digits$e}"));
        }
    }
}
