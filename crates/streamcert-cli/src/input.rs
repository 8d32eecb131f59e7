//! Streaming CSV input with a header, read line by line so a live feed works, and an error for
//! every malformed row that names the file, the line and the column.

use std::io::BufRead;

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
/// are ignored).
pub struct SampleReader<R> {
    reader: R,
    file: String,
    line: u64,
    header: Vec<String>,
    time: usize,
    outputs: Vec<usize>,
    inputs: Vec<usize>,
    last_time: Option<f64>,
    buf: String,
}

fn split(line: &str) -> Vec<&str> {
    line.trim_end_matches(['\n', '\r']).split(',').map(str::trim).collect()
}

impl<R: BufRead> SampleReader<R> {
    /// Read the header and map the configured columns.
    ///
    /// # Errors
    /// [`CliError::Input`] for an empty input or a header that lacks a configured column;
    /// [`CliError::Io`] for a read error.
    pub fn new(mut reader: R, file: &str, columns: &Columns) -> Result<Self, CliError> {
        let mut buf = String::new();
        let mut line = 0;
        loop {
            buf.clear();
            let n = reader
                .read_line(&mut buf)
                .map_err(|e| CliError::io(format!("reading {file}"), e))?;
            line += 1;
            if n == 0 {
                return Err(CliError::Input {
                    file: file.into(),
                    message: "empty input: expected a header line naming the columns".into(),
                });
            }
            if !buf.trim().is_empty() {
                break;
            }
        }
        let header: Vec<String> = split(&buf).into_iter().map(String::from).collect();
        let find = |name: &str| {
            header.iter().position(|h| h == name).ok_or_else(|| CliError::Input {
                file: file.into(),
                message: format!("line {line}: the header has no column `{name}` (configured in [columns]); found {header:?}"),
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
            buf,
        })
    }

    /// Require the next accepted time to be after `t` (used when resuming).
    pub fn set_last_time(&mut self, t: Option<f64>) {
        self.last_time = t;
    }

    /// The next row into `s`: `None` at the end of the input, `Some(Err)` for a malformed row
    /// (which is then consumed; the reader can continue). Blank lines are ignored.
    ///
    /// # Errors
    /// I/O errors are reported as [`CliError::Io`] inside `Some(Err)`.
    pub fn next_into(&mut self, s: &mut Sample) -> Option<Result<(), CliError>> {
        loop {
            self.buf.clear();
            match self.reader.read_line(&mut self.buf) {
                Ok(0) => return None,
                Ok(_) => {}
                Err(e) => return Some(Err(CliError::io(format!("reading {}", self.file), e))),
            }
            self.line += 1;
            if !self.buf.trim().is_empty() {
                break;
            }
        }
        Some(self.parse(s).map_err(CliError::Row))
    }

    fn parse(&mut self, s: &mut Sample) -> Result<(), RowError> {
        let fields = split(&self.buf);
        let err = |column: Option<&str>, message: String| RowError {
            file: self.file.clone(),
            line: self.line,
            column: column.map(String::from),
            message,
        };
        if fields.len() != self.header.len() {
            return Err(err(
                None,
                format!(
                    "expected {} comma-separated fields as in the header, found {} (missing column or truncated row?)",
                    self.header.len(),
                    fields.len()
                ),
            ));
        }
        let number = |i: usize| -> Result<f64, RowError> {
            let name = self.header[i].as_str();
            let v: f64 = fields[i].parse().map_err(|_| {
                err(Some(name), format!("expected a number, found `{}`", fields[i]))
            })?;
            if !v.is_finite() {
                return Err(err(
                    Some(name),
                    format!(
                        "expected a finite number, found `{}` (NaN and infinity are not accepted)",
                        fields[i]
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
