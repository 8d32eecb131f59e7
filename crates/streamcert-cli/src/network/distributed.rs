//! `streamcert network` on timely-dataflow (`--workers`, `--processes`, `--process`,
//! `--hostfile`: timely's own `-w`, `-n`, `-p`, `-h`): the subsystems sharded over the
//! workers of every process, process 0 reading the input and writing the epoch rows. The
//! rows are those of the one-process run, byte for byte (tested with two processes).

use std::io::{Read, Write};
use std::path::PathBuf;

use streamcert_timely::{Row, TimelyError};

use super::config::NetConfig;
use super::input::Rows;
use super::output::EpochWriter;
use super::{NetOptions, NetSummary, estimated_columns};
use crate::{CliError, RowError};

/// Timely's process configuration.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Cluster {
    /// Worker threads per process (`-w`, default 1).
    pub workers: Option<usize>,
    /// Number of processes (`-n`, default 1).
    pub processes: Option<usize>,
    /// This process's index (`-p`, default 0).
    pub process: Option<usize>,
    /// One `host:port` per process, in process order (`-h`; default `localhost:2101` and up).
    pub hostfile: Option<PathBuf>,
}

impl Cluster {
    /// Whether any option is set (the run then goes through timely).
    #[must_use]
    pub fn is_set(&self) -> bool {
        *self != Self::default()
    }

    /// This process's index.
    #[must_use]
    pub fn index(&self) -> usize {
        self.process.unwrap_or(0)
    }

    /// Timely's arguments.
    fn args(&self) -> Vec<String> {
        let mut args = Vec::new();
        let mut put = |flag: &str, v: Option<String>| {
            if let Some(v) = v {
                args.push(flag.to_string());
                args.push(v);
            }
        };
        put("-w", self.workers.map(|w| w.to_string()));
        put("-n", self.processes.map(|n| n.to_string()));
        put("-p", self.process.map(|p| p.to_string()));
        put("-h", self.hostfile.as_ref().map(|h| h.display().to_string()));
        args
    }
}

/// The rows of `input` as timely rows.
struct RowIter<R: Read> {
    rows: Option<Rows<R>>,
    first: Option<CliError>,
    values: Vec<f64>,
    items: Vec<(usize, usize, usize, usize)>,
}

impl<R: Read> Iterator for RowIter<R> {
    type Item = Result<Row, CliError>;

    fn next(&mut self) -> Option<Self::Item> {
        if let Some(e) = self.first.take() {
            return Some(Err(e));
        }
        let next = self.rows.as_mut()?.next(&mut self.values, &mut self.items)?;
        Some(next.map(|(line, t)| {
            Row {
                line,
                t,
                samples: self
                    .items
                    .iter()
                    .map(|&(i, start, p, m)| (i, self.values[start..start + p + m].to_vec()))
                    .collect(),
            }
        }))
    }
}

/// Run the network on timely. Process 0 reads `input` and writes the epoch rows to `out`;
/// the other processes certify their shards and write nothing.
///
/// # Errors
/// Checkpoints are refused (`--checkpoint`, `--resume`: one-process runs only); timely's
/// configuration; the input, row and output errors of the one-process run.
pub fn run_timely<W: Write>(
    cfg: &NetConfig,
    input: Box<dyn Read + Send>,
    input_name: &str,
    out: W,
    opts: &NetOptions,
    cluster: &Cluster,
) -> Result<NetSummary, CliError> {
    let bad = |message: String| CliError::Config { path: "timely".into(), message };
    if opts.checkpoint.is_some() || opts.resume.is_some() {
        return Err(bad(
            "--checkpoint and --resume need a one-process run (no timely options)".into()
        ));
    }
    let names: Vec<String> = cfg.network.subsystems.iter().map(|s| s.name.clone()).collect();
    let mut writer = EpochWriter::new(
        out,
        opts.format,
        opts.flush_each_row,
        true,
        estimated_columns(&cfg.network, &names),
    );
    let mut summary = NetSummary::default();
    let mut failed: Option<std::io::Error> = None;
    let (rows_cfg, name) = (cfg.clone(), input_name.to_string());
    let source = move || {
        let (rows, first) = match Rows::new(&rows_cfg, input, &name) {
            Ok(rows) => (Some(rows), None),
            Err(e) => (None, Some(e)),
        };
        RowIter { rows, first, values: Vec::new(), items: Vec::new() }
    };
    let result = streamcert_timely::run(cfg.network.clone(), &cluster.args(), source, |r| {
        if failed.is_none() {
            if let Err(e) = writer.write(r, &names, &mut summary) {
                failed = Some(e);
            }
        }
    });
    let io = |e: std::io::Error| CliError::io("writing output", e);
    if let Some(e) = failed {
        return Err(io(e));
    }
    writer.flush().map_err(io)?;
    let row = |line: u64, message: String| {
        CliError::Row(RowError { file: input_name.into(), line, column: None, message })
    };
    match result {
        Ok(outcome) => {
            summary.rows = outcome.rows;
            summary.last_time = outcome.last_time;
            Ok(summary)
        }
        Err(TimelyError::Source { source, .. }) => Err(source),
        Err(TimelyError::Network { line, source }) => Err(row(line, source.to_string())),
        Err(TimelyError::Subsystem { line, index, name, message }) => {
            Err(row(line, format!("subsystem {index} (`{name}`): {message}")))
        }
        Err(e @ (TimelyError::Config(_) | TimelyError::Worker(_))) => Err(bad(e.to_string())),
    }
}
