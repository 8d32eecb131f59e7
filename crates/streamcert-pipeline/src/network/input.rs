//! The input rows of `network`: wide (every subsystem's columns in one row, through
//! `SampleReader`) or long (`t, subsystem, outputs..., inputs...`, through the same
//! `RecordReader`: the csv crate's grammar, physical line numbers).

use std::io::Read;

use super::config::{InputLayout, NetConfig};
use crate::input::{RecordReader, Sample, SampleReader, read_error};
use crate::source::{Next, Source};
use crate::{CliError, RowError};

/// What the input yielded next: a row `(line, t)` (its values and items filled), a gap
/// before the next row (a live source's outage: every subsystem in the rows restarts its
/// windows), or a bad payload (a live source's; skipped).
pub(super) enum Item {
    Row(u64, f64),
    Gap(String),
    Bad(RowError),
    /// A live source has nothing yet ([`Next::Idle`]).
    Idle,
}

/// The input rows of either layout, as `(line, t)` with the values and, per subsystem in
/// the row, `(index, start of its outputs in values, p, m)`.
pub(super) enum Rows<R: Read> {
    /// `ids[k]`: the subsystem of the `k`-th `(p, m)` of `dims`.
    Wide {
        reader: SampleReader<R>,
        sample: Sample,
        dims: Vec<(usize, usize)>,
        ids: Vec<usize>,
    },
    Long(LongReader<R>),
    /// Wide rows from a live source (`streamcert-live`); `ids` as for `Wide`.
    Live {
        source: Box<dyn Source>,
        sample: Sample,
        dims: Vec<(usize, usize)>,
        ids: Vec<usize>,
    },
}

/// The columns, `(p, m)` and indices of the subsystems placed on `process` (wide layout).
#[cfg(feature = "distributed")]
pub(super) fn site(
    cfg: &NetConfig,
    process_of: &[usize],
    process: usize,
) -> (crate::config::Columns, Vec<(usize, usize)>, Vec<usize>) {
    let mut columns = cfg.columns.clone();
    columns.outputs.clear();
    columns.inputs.clear();
    let (mut dims, mut ids) = (Vec::new(), Vec::new());
    let (mut yo, mut uo) = (0, 0);
    for (i, &(p, m)) in cfg.dims.iter().enumerate() {
        if process_of.get(i) == Some(&process) {
            columns.outputs.extend_from_slice(&cfg.columns.outputs[yo..yo + p]);
            columns.inputs.extend_from_slice(&cfg.columns.inputs[uo..uo + m]);
            dims.push((p, m));
            ids.push(i);
        }
        yo += p;
        uo += m;
    }
    (columns, dims, ids)
}

impl<R: Read> Rows<R> {
    /// Wide rows of every subsystem from a live source.
    pub(super) fn live(cfg: &NetConfig, source: Box<dyn Source>) -> Self {
        let ids = (0..cfg.dims.len()).collect();
        Self::Live { source, sample: Sample::default(), dims: cfg.dims.clone(), ids }
    }

    /// Wide rows of one site's subsystems from a live source opened for their columns.
    #[cfg(feature = "distributed")]
    pub(super) fn live_for_site(
        cfg: &NetConfig,
        process_of: &[usize],
        process: usize,
        source: Box<dyn Source>,
    ) -> Self {
        let (_, dims, ids) = site(cfg, process_of, process);
        Self::Live { source, sample: Sample::default(), dims, ids }
    }

    /// The live source, if the rows come from one (for its acknowledgements).
    pub(super) fn source(&mut self) -> Option<&mut dyn Source> {
        match self {
            Self::Live { source, .. } => Some(source.as_mut()),
            _ => None,
        }
    }

    pub(super) fn new(cfg: &NetConfig, input: R, name: &str) -> Result<Self, CliError> {
        Ok(match cfg.layout {
            InputLayout::Wide => Self::Wide {
                reader: SampleReader::new(input, name, &cfg.columns)?,
                sample: Sample::default(),
                dims: cfg.dims.clone(),
                ids: (0..cfg.dims.len()).collect(),
            },
            InputLayout::Long => Self::Long(LongReader::new(cfg, input, name)?),
        })
    }

    /// The rows of one site (`process`): in the wide layout only the columns of the
    /// subsystems placed on it; in the long layout every row names its subsystem (a row of
    /// another site's subsystem is refused by the run).
    #[cfg(feature = "distributed")]
    pub(super) fn for_site(
        cfg: &NetConfig,
        process_of: &[usize],
        process: usize,
        input: R,
        name: &str,
    ) -> Result<Self, CliError> {
        if cfg.layout == InputLayout::Long {
            return Self::new(cfg, input, name);
        }
        let (columns, dims, ids) = site(cfg, process_of, process);
        Ok(Self::Wide {
            reader: SampleReader::new(input, name, &columns)?,
            sample: Sample::default(),
            dims,
            ids,
        })
    }

    pub(super) fn next(
        &mut self,
        values: &mut Vec<f64>,
        items: &mut Vec<(usize, usize, usize, usize)>,
    ) -> Option<Result<Item, CliError>> {
        values.clear();
        items.clear();
        match self {
            Self::Wide { reader, sample, dims, ids } => {
                if let Err(e) = reader.next_into(sample)? {
                    return Some(Err(e));
                }
                split(sample, dims, |k| ids[k], values, items);
                Some(Ok(Item::Row(sample.line, sample.t)))
            }
            Self::Long(reader) => {
                reader.next(values, items).map(|r| r.map(|(l, t)| Item::Row(l, t)))
            }
            Self::Live { source, sample, dims, ids } => Some(match source.next_into(sample)? {
                Ok(Next::Row) => {
                    split(sample, dims, |k| ids[k], values, items);
                    Ok(Item::Row(sample.line, sample.t))
                }
                Ok(Next::Gap(why)) => Ok(Item::Gap(why)),
                Ok(Next::Bad(e)) => Ok(Item::Bad(e)),
                Ok(Next::Idle) => Ok(Item::Idle),
                Err(e) => Err(e),
            }),
        }
    }
}

/// A wide row's values per subsystem: the sample holds all outputs, then all inputs, in
/// subsystem order; `id(k)` is the `k`-th subsystem's index.
fn split(
    sample: &Sample,
    dims: &[(usize, usize)],
    id: impl Fn(usize) -> usize,
    values: &mut Vec<f64>,
    items: &mut Vec<(usize, usize, usize, usize)>,
) {
    let (mut yo, mut uo) = (0, 0);
    for (k, &(p, m)) in dims.iter().enumerate() {
        items.push((id(k), values.len(), p, m));
        values.extend_from_slice(&sample.y[yo..yo + p]);
        values.extend_from_slice(&sample.u[uo..uo + m]);
        yo += p;
        uo += m;
    }
}

/// Long rows: `t, subsystem, outputs..., inputs...`, read with the csv crate's grammar.
pub(super) struct LongReader<R: Read> {
    record: RecordReader<R>,
    file: String,
    index: std::collections::HashMap<String, usize>,
    dims: Vec<(usize, usize)>,
    first: bool,
}

impl<R: Read> LongReader<R> {
    fn new(cfg: &NetConfig, input: R, file: &str) -> Result<Self, CliError> {
        let delimiter = cfg
            .columns
            .delimiter_byte()
            .map_err(|message| CliError::Input { file: file.into(), message })?;
        let index =
            cfg.network.subsystems.iter().enumerate().map(|(i, s)| (s.name.clone(), i)).collect();
        Ok(Self {
            record: RecordReader::new(input, delimiter),
            file: file.into(),
            index,
            dims: cfg.dims.clone(),
            first: true,
        })
    }

    fn next(
        &mut self,
        values: &mut Vec<f64>,
        items: &mut Vec<(usize, usize, usize, usize)>,
    ) -> Option<Result<(u64, f64), CliError>> {
        loop {
            match self.record.read_record() {
                Ok(false) => return None,
                Err(e) => return Some(Err(read_error(&self.file, e))),
                Ok(true) => {}
            }
            let line = self.record.line();
            let err = |message: String| {
                Some(Err(CliError::Row(crate::RowError {
                    file: self.file.clone(),
                    line,
                    column: None,
                    message,
                })))
            };
            let number = |raw: &[u8]| -> Option<f64> {
                fast_float2::parse::<f64, _>(raw.trim_ascii()).ok().filter(|v| v.is_finite())
            };
            let first = std::mem::take(&mut self.first);
            let Some(t) = self.record.get(0).and_then(number) else {
                if first {
                    continue; // a header line
                }
                let raw = String::from_utf8_lossy(self.record.get(0).unwrap_or_default());
                return err(format!("expected a finite time, found `{raw}`"));
            };
            let name = String::from_utf8_lossy(self.record.get(1).unwrap_or_default());
            let Some(&i) = self.index.get(name.trim()) else {
                return err(format!("no subsystem named `{}` in the configuration", name.trim()));
            };
            let (p, m) = self.dims[i];
            if self.record.len() != 2 + p + m {
                return err(format!(
                    "subsystem `{}` needs t, its name, {p} outputs and {m} inputs ({} fields), found {}",
                    name.trim(),
                    2 + p + m,
                    self.record.len()
                ));
            }
            for k in 2..2 + p + m {
                let raw = self.record.get(k).unwrap_or_default();
                match number(raw) {
                    Some(v) => values.push(v),
                    None => {
                        let raw = String::from_utf8_lossy(raw);
                        return err(format!(
                            "field {}: expected a finite number, found `{raw}`",
                            k + 1
                        ));
                    }
                }
            }
            items.push((i, 0, p, m));
            return Some(Ok((line, t)));
        }
    }
}
