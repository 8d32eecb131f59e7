//! `streamcert network`: every subsystem's columns of one wide CSV, one certifier per
//! subsystem, the network composed at every epoch; one output row per epoch and a summary.
//!
//! The configuration is the `certify` configuration with the subsystems and couplings added:
//! `[network]`, `[[subsystem]]` (name, outputs, inputs, gain) and `[[coupling]]` (`from`
//! drives `to` with bound `gamma`); `[columns]` gives the time column and the delimiter;
//! `[certificate]`, `[regression]`, `[ambiguity]` and `[calibration]` apply to every
//! subsystem. Each subsystem's certifier configuration is built by the `certify` parser, so
//! the two commands read the same keys the same way.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use streamcert_certificate::CertificateKind;
use streamcert_network::{EpochReport, NetworkCertifier, NetworkConfig, SubsystemSpec};

use crate::CliError;
use crate::config::{self, Columns};
use crate::input::{Sample, SampleReader};
use crate::output::Format;

/// The commented example printed by `streamcert network --print-config`: G5's two observed
/// subsystems (the columns `streamcert simulate g5` writes) with bidirectional coupling.
pub const EXAMPLE_CONFIG: &str = r#"# streamcert network configuration (TOML). Unknown keys are refused.
# Data: `streamcert simulate g5 --experiment 2 --coupling bidirectional` writes these columns.

[network]
epoch = 0.5             # seconds between compositions (t = k * epoch)
stale_after = 2.5       # a subsystem without a sample for this long is not certified
certificate = "gaussian"  # which local certificate composes: gaussian | wasserstein | calibrated
margin = 0.0            # the network is certified when its rate is >= margin
consecutive = 1         # certified epochs in a row before the network gate opens
# risk = 0.01           # calibrated: run-level risk, split delta/N over the subsystems
# dense_limit = 64      # up to this many subsystems the exact dense composition
# input = "wide"        # or "long": rows `t,subsystem,outputs...,inputs...`, one subsystem each
# max_epoch_jump = 100000  # a row more epochs ahead than this is refused (corrupted time)

[columns]
time = "t"
# delimiter = ","

[[subsystem]]
name = "A"
outputs = ["y_a"]
inputs = ["u_a"]
gain = [[-2.5]]

[[subsystem]]
name = "B"
outputs = ["y_b"]
inputs = ["u_b"]
gain = [[-3.0]]

# Coupling bounds: how `from` drives `to` (gamma >= 0).
[[coupling]]
from = "B"
to = "A"
gamma = 0.4

[[coupling]]
from = "A"
to = "B"
gamma = 0.4

# Every subsystem's certifier: the keys of `streamcert certify --print-config`.
[certificate]
conservatism = 0.3
margin = 0.1
consecutive = 10

[regression]
window = 150
horizon = 5
ridge = 1e-4
input_integral = "zero_order_hold"

[ambiguity]
enabled = false
"#;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct NetworkSection {
    epoch: f64,
    stale_after: Option<f64>,
    #[serde(default = "default_certificate")]
    certificate: CertificateKind,
    #[serde(default)]
    margin: f64,
    #[serde(default = "one")]
    consecutive: usize,
    risk: Option<f64>,
    dense_limit: Option<usize>,
    max_epoch_jump: Option<u64>,
    #[serde(default)]
    input: InputLayout,
}

/// How the input rows carry the subsystems' samples.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InputLayout {
    /// One row per time with every subsystem's columns, named in `[columns]` and
    /// `[[subsystem]]` (as `streamcert simulate g5` writes). Default.
    #[default]
    Wide,
    /// One row per sample of one subsystem: `t, subsystem name, its outputs, its inputs`
    /// (no column names; a first line whose time is not a number is a header and skipped).
    /// Subsystems may report at their own times.
    Long,
}

fn default_certificate() -> CertificateKind {
    CertificateKind::Gaussian
}

fn one() -> usize {
    1
}

#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct SubsystemEntry {
    name: String,
    outputs: Vec<String>,
    inputs: Vec<String>,
    gain: Vec<Vec<f64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CouplingEntry {
    from: String,
    to: String,
    gamma: f64,
}

/// A validated network configuration: the combined input columns and the network.
#[derive(Debug, Clone)]
pub struct NetConfig {
    /// The time column, every subsystem's outputs then every subsystem's inputs (in
    /// subsystem order), and the delimiter.
    pub columns: Columns,
    /// `(outputs, inputs)` of each subsystem.
    pub dims: Vec<(usize, usize)>,
    /// The network.
    pub network: NetworkConfig,
    /// Wide or long input rows.
    pub layout: InputLayout,
}

/// Parse and validate; `path` names the file in errors.
///
/// # Errors
/// [`CliError::Config`].
pub fn parse(text: &str, path: &str) -> Result<NetConfig, CliError> {
    let bad = |message: String| CliError::Config { path: path.to_string(), message };
    let mut table: toml::Table = toml::from_str(text).map_err(|e| bad(e.to_string()))?;
    let take = |table: &mut toml::Table, key: &str| table.remove(key);
    let section: NetworkSection = take(&mut table, "network")
        .ok_or_else(|| bad("missing [network]".into()))?
        .try_into()
        .map_err(|e: toml::de::Error| bad(format!("[network]: {e}")))?;
    let subsystems: Vec<SubsystemEntry> = take(&mut table, "subsystem")
        .ok_or_else(|| bad("no [[subsystem]]".into()))?
        .try_into()
        .map_err(|e: toml::de::Error| bad(format!("[[subsystem]]: {e}")))?;
    let couplings: Vec<CouplingEntry> = match take(&mut table, "coupling") {
        Some(v) => v.try_into().map_err(|e: toml::de::Error| bad(format!("[[coupling]]: {e}")))?,
        None => Vec::new(),
    };
    let columns_table = match table.get("columns") {
        Some(toml::Value::Table(t)) => t.clone(),
        _ => return Err(bad("missing [columns] (the time column)".into())),
    };
    let mut specs = Vec::with_capacity(subsystems.len());
    let mut dims = Vec::with_capacity(subsystems.len());
    let (mut outputs, mut inputs) = (Vec::new(), Vec::new());
    let mut time = String::new();
    let mut delimiter = ",".to_string();
    for s in &subsystems {
        // The subsystem as a `certify` configuration: its columns and gain, the shared rest.
        let mut t = table.clone();
        let mut cols = columns_table.clone();
        cols.insert(
            "outputs".into(),
            toml::Value::try_from(&s.outputs).map_err(|e| bad(e.to_string()))?,
        );
        cols.insert(
            "inputs".into(),
            toml::Value::try_from(&s.inputs).map_err(|e| bad(e.to_string()))?,
        );
        t.insert("columns".into(), toml::Value::Table(cols));
        let mut controller = toml::Table::new();
        controller
            .insert("gain".into(), toml::Value::try_from(&s.gain).map_err(|e| bad(e.to_string()))?);
        t.insert("controller".into(), toml::Value::Table(controller));
        let text = toml::to_string(&t).map_err(|e| bad(e.to_string()))?;
        let c = config::parse(&text, &format!("{path} (subsystem `{}`)", s.name))?;
        time.clone_from(&c.columns.time);
        delimiter.clone_from(&c.columns.delimiter);
        outputs.extend(c.columns.outputs.iter().cloned());
        inputs.extend(c.columns.inputs.iter().cloned());
        dims.push((c.columns.outputs.len(), c.columns.inputs.len()));
        specs.push(SubsystemSpec::new(&s.name, c.certifier));
    }
    let index = |name: &str| {
        subsystems
            .iter()
            .position(|s| s.name == name)
            .ok_or_else(|| bad(format!("[[coupling]] names `{name}`, which is no [[subsystem]]")))
    };
    let edges = couplings
        .iter()
        .map(|c| Ok((index(&c.to)?, index(&c.from)?, c.gamma)))
        .collect::<Result<Vec<_>, CliError>>()?;
    let mut network = NetworkConfig::new(specs, edges, section.epoch);
    network.certificate = section.certificate;
    network.margin = section.margin;
    network.consecutive = section.consecutive;
    if let Some(s) = section.stale_after {
        network.stale_after = s;
    }
    if let Some(d) = section.dense_limit {
        network.dense_limit = d;
    }
    if let Some(m) = section.max_epoch_jump {
        network.max_epoch_jump = m;
    }
    if let Some(delta) = section.risk {
        if !(delta > 0.0 && delta < 1.0) {
            return Err(bad(format!("[network] risk must be in (0, 1), got {delta}")));
        }
        network = network.split_risk(delta);
    }
    // Build once: every check of the network and of each certifier.
    NetworkCertifier::new(network.clone()).map_err(|e| bad(e.to_string()))?;
    let columns = Columns { time, outputs, inputs, delimiter };
    Ok(NetConfig { columns, dims, network, layout: section.input })
}

/// One output row per epoch (JSON lines; the CSV has the same fields, `local` as one column
/// `cert_<name>` per subsystem).
#[derive(Debug, Serialize)]
struct EpochRow<'a> {
    t: f64,
    epoch: u64,
    rate: Option<f64>,
    certified: u8,
    open: u8,
    critical_scale: Option<f64>,
    limiting_subsystem: Option<&'a str>,
    limiting_coupling: Option<String>,
    not_certified: String,
    local: std::collections::BTreeMap<&'a str, Option<f64>>,
}

/// Counts over a run (continued across checkpoint and resume).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct NetSummary {
    /// Input rows.
    pub rows: u64,
    /// Rows passed over at the start of a resumed input (the checkpoint holds them).
    pub replayed: u64,
    /// Time of the last input row.
    pub last_time: Option<f64>,
    /// Epochs composed.
    pub epochs: u64,
    /// Epochs certified.
    pub certified: u64,
    /// Epochs with the network gate open.
    pub open: u64,
    /// First time the network gate opened.
    pub first_open: Option<f64>,
}

/// Options of a `network` run.
#[derive(Debug, Clone)]
pub struct NetOptions {
    /// Output format.
    pub format: Format,
    /// Flush every epoch row (a live input).
    pub flush_each_row: bool,
    /// Write the whole network's state here at the end (and every `checkpoint_every` rows).
    pub checkpoint: Option<PathBuf>,
    /// Checkpoint period in input rows.
    pub checkpoint_every: Option<u64>,
    /// Continue from this checkpoint: rows up to its last time are passed over, no header is
    /// written, so the outputs of a split run concatenate to the output of the whole run.
    pub resume: Option<PathBuf>,
}

#[derive(Serialize, Deserialize)]
struct Checkpoint {
    network: NetworkCertifier,
    summary: NetSummary,
}

fn save(path: &Path, net: &NetworkCertifier, summary: &NetSummary) -> Result<(), CliError> {
    let bad = |message: String| CliError::Checkpoint { path: path.display().to_string(), message };
    let cp = Checkpoint { network: net.clone(), summary: summary.clone() };
    let json = serde_json::to_string(&cp).map_err(|e| bad(e.to_string()))?;
    let text = streamcert_certificate::seal(&json, net.config()).map_err(|e| bad(e.to_string()))?;
    crate::certify::write_atomic(path, &text)
}

fn load(path: &Path, cfg: &NetConfig) -> Result<(NetworkCertifier, NetSummary), CliError> {
    let bad = |message: String| CliError::Checkpoint { path: path.display().to_string(), message };
    let bytes = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|_| bad("not a streamcert checkpoint (not UTF-8 text)".into()))?;
    let json =
        streamcert_certificate::unseal(text, Some(&cfg.network)).map_err(|e| bad(e.to_string()))?;
    let cp: Checkpoint = serde_json::from_str(json).map_err(|e| bad(e.to_string()))?;
    let net = cp.network.verify().map_err(|e| bad(e.to_string()))?;
    if net.config() != &cfg.network {
        return Err(bad("the checkpoint was written with a different configuration".into()));
    }
    Ok((net, cp.summary))
}

/// Run the network over a wide CSV stream.
///
/// # Errors
/// Configuration, input rows (the first malformed row stops the run), output, composition
/// and checkpoint errors.
pub fn run<R: Read, W: Write>(
    cfg: &NetConfig,
    input: R,
    input_name: &str,
    out: W,
    opts: &NetOptions,
) -> Result<NetSummary, CliError> {
    let (mut net, mut summary) = match &opts.resume {
        Some(path) => load(path, cfg)?,
        None => (
            NetworkCertifier::new(cfg.network.clone()).map_err(|e| CliError::Config {
                path: "configuration".into(),
                message: e.to_string(),
            })?,
            NetSummary::default(),
        ),
    };
    let names: Vec<String> = cfg.network.subsystems.iter().map(|s| s.name.clone()).collect();
    let mut rows = Rows::new(cfg, input, input_name)?;
    let io = |e: std::io::Error| CliError::io("writing output", e);
    let mut writer = EpochWriter::new(out, opts.format, opts.flush_each_row, opts.resume.is_none());
    // Resuming: rows at the start of the input whose samples every subsystem in them already
    // holds (time not after its newest) are a replay and are passed over, counted.
    let mut replaying = opts.resume.is_some();
    let mut failed: Option<CliError> = None;
    let (mut values, mut items) = (Vec::new(), Vec::new());
    while let Some(next) = rows.next(&mut values, &mut items) {
        let (line, t) = next?;
        if replaying {
            let held = |i: usize| {
                net.subsystem(i).and_then(|c| c.regression().last_time()).is_some_and(|l| t <= l)
            };
            if items.iter().all(|&(i, ..)| held(i)) {
                summary.replayed += 1;
                continue;
            }
            replaying = false;
        }
        summary.rows += 1;
        summary.last_time = Some(t);
        for &(i, start, p, m) in &items {
            let (y, u) = (&values[start..start + p], &values[start + p..start + p + m]);
            let pushed = net.push(i, t, y, u, |r| {
                if failed.is_none() {
                    if let Err(e) = writer.write(r, &names, &mut summary) {
                        failed = Some(io(e));
                    }
                }
            });
            if let Err(e) = pushed {
                return Err(CliError::Row(crate::RowError {
                    file: input_name.into(),
                    line,
                    column: None,
                    message: e.to_string(),
                }));
            }
            if let Some(e) = failed.take() {
                return Err(e);
            }
        }
        if let (Some(path), Some(every)) = (&opts.checkpoint, opts.checkpoint_every) {
            if every > 0 && summary.rows % every == 0 {
                writer.flush().map_err(io)?;
                save(path, &net, &summary)?;
            }
        }
    }
    writer.flush().map_err(io)?;
    if let Some(path) = &opts.checkpoint {
        save(path, &net, &summary)?;
    }
    Ok(summary)
}

/// The input rows of either layout, as `(line, t)` with the values and, per subsystem in
/// the row, `(index, start of its outputs in values, p, m)`.
enum Rows<R: Read> {
    Wide { reader: SampleReader<R>, sample: Sample, dims: Vec<(usize, usize)> },
    Long(LongReader<R>),
}

impl<R: Read> Rows<R> {
    fn new(cfg: &NetConfig, input: R, name: &str) -> Result<Self, CliError> {
        Ok(match cfg.layout {
            InputLayout::Wide => Self::Wide {
                reader: SampleReader::new(input, name, &cfg.columns)?,
                sample: Sample::default(),
                dims: cfg.dims.clone(),
            },
            InputLayout::Long => Self::Long(LongReader::new(cfg, input, name)?),
        })
    }

    fn next(
        &mut self,
        values: &mut Vec<f64>,
        items: &mut Vec<(usize, usize, usize, usize)>,
    ) -> Option<Result<(u64, f64), CliError>> {
        values.clear();
        items.clear();
        match self {
            Self::Wide { reader, sample, dims } => {
                if let Err(e) = reader.next_into(sample)? {
                    return Some(Err(e));
                }
                // The reader gives all outputs, then all inputs, in subsystem order.
                let (mut yo, mut uo) = (0, 0);
                for (i, &(p, m)) in dims.iter().enumerate() {
                    items.push((i, values.len(), p, m));
                    values.extend_from_slice(&sample.y[yo..yo + p]);
                    values.extend_from_slice(&sample.u[uo..uo + m]);
                    yo += p;
                    uo += m;
                }
                Some(Ok((sample.line, sample.t)))
            }
            Self::Long(reader) => reader.next(values, items),
        }
    }
}

/// Long rows: `t, subsystem, outputs..., inputs...`, read with the csv crate.
struct LongReader<R: Read> {
    reader: csv::Reader<R>,
    record: csv::ByteRecord,
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
        let reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .delimiter(delimiter)
            .from_reader(input);
        let index =
            cfg.network.subsystems.iter().enumerate().map(|(i, s)| (s.name.clone(), i)).collect();
        Ok(Self {
            reader,
            record: csv::ByteRecord::new(),
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
            match self.reader.read_byte_record(&mut self.record) {
                Ok(false) => return None,
                Err(e) => {
                    return Some(Err(CliError::Input {
                        file: self.file.clone(),
                        message: format!("unreadable CSV: {e}"),
                    }));
                }
                Ok(true) => {}
            }
            let line = self.record.position().map_or(0, csv::Position::line);
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

/// Epoch rows as CSV (csv crate) or JSON lines.
struct EpochWriter<W: Write> {
    csv: Option<csv::Writer<W>>,
    json: Option<std::io::BufWriter<W>>,
    flush_each_row: bool,
    header: bool,
}

/// The fixed CSV columns before the per-subsystem `cert_<name>` columns.
const CSV_COLUMNS: [&str; 9] = [
    "t",
    "epoch",
    "rate",
    "certified",
    "open",
    "critical_scale",
    "limiting_subsystem",
    "limiting_coupling",
    "not_certified",
];

impl<W: Write> EpochWriter<W> {
    fn new(out: W, format: Format, flush_each_row: bool, header: bool) -> Self {
        let (csv, json) = match format {
            Format::Csv => (Some(csv::Writer::from_writer(out)), None),
            Format::Jsonl => (None, Some(std::io::BufWriter::new(out))),
        };
        Self { csv, json, flush_each_row, header }
    }

    fn write(
        &mut self,
        r: &EpochReport,
        names: &[String],
        summary: &mut NetSummary,
    ) -> std::io::Result<()> {
        summary.epochs += 1;
        summary.certified += u64::from(r.certified);
        summary.open += u64::from(r.open);
        if r.open && summary.first_open.is_none() {
            summary.first_open = Some(r.t);
        }
        let not_certified = r
            .not_certified
            .iter()
            .map(|(i, why)| format!("{}: {why}", names[*i]))
            .collect::<Vec<_>>()
            .join("; ");
        let row = EpochRow {
            t: r.t,
            epoch: r.epoch,
            rate: r.rate,
            certified: u8::from(r.certified),
            open: u8::from(r.open),
            critical_scale: r.critical_scale,
            limiting_subsystem: r.limiting_subsystem.map(|i| names[i].as_str()),
            limiting_coupling: r
                .limiting_coupling
                .map(|(i, j)| format!("{}->{}", names[j], names[i])),
            not_certified,
            local: names.iter().map(String::as_str).zip(r.local.iter().copied()).collect(),
        };
        if let Some(w) = &mut self.csv {
            if std::mem::take(&mut self.header) {
                let mut header: Vec<String> =
                    CSV_COLUMNS.iter().map(|c| (*c).to_string()).collect();
                header.extend(names.iter().map(|n| format!("cert_{n}")));
                w.write_record(&header)?;
            }
            let num = |v: Option<f64>| {
                v.map_or(String::new(), |x| ryu::Buffer::new().format(x).to_string())
            };
            let mut record = vec![
                num(Some(row.t)),
                row.epoch.to_string(),
                num(row.rate),
                row.certified.to_string(),
                row.open.to_string(),
                num(row.critical_scale),
                row.limiting_subsystem.unwrap_or_default().to_string(),
                row.limiting_coupling.clone().unwrap_or_default(),
                row.not_certified.clone(),
            ];
            record.extend(r.local.iter().map(|v| num(*v)));
            w.write_record(&record)?;
        }
        if let Some(w) = &mut self.json {
            serde_json::to_writer(&mut *w, &row)?;
            w.write_all(b"\n")?;
        }
        if self.flush_each_row {
            self.flush()?;
        }
        Ok(())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if let Some(w) = &mut self.csv {
            w.flush()?;
        }
        if let Some(w) = &mut self.json {
            w.flush()?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refused(text: &str, needle: &str) {
        match parse(text, "net.toml") {
            Err(e @ CliError::Config { .. }) => {
                let message = e.to_string();
                assert!(message.contains(needle), "`{needle}` not in: {message}");
            }
            other => panic!("expected a configuration error with `{needle}`, got {other:?}"),
        }
    }

    #[test]
    fn the_example_parses_and_bad_networks_are_refused() {
        let cfg = parse(EXAMPLE_CONFIG, "example").expect("the example is valid");
        assert_eq!(cfg.dims, vec![(1, 1), (1, 1)]);
        assert_eq!(cfg.columns.outputs, ["y_a", "y_b"]);
        assert_eq!(cfg.network.couplings, vec![(0, 1, 0.4), (1, 0, 0.4)]);
        refused(&EXAMPLE_CONFIG.replace("from = \"B\"", "from = \"C\""), "`C`");
        refused(&EXAMPLE_CONFIG.replace("# risk = 0.01", "risk = 1.5"), "risk");
        refused(
            &EXAMPLE_CONFIG.replace("certificate = \"gaussian\"", "certificate = \"calibrated\""),
            "no calibration",
        );
        refused(
            &EXAMPLE_CONFIG.replace("gamma = 0.4", "gamma = -0.4"),
            "γ must be finite and >= 0",
        );
        refused(
            &EXAMPLE_CONFIG.replace("gain = [[-3.0]]", "gain = [[-3.0, 1.0]]"),
            "subsystem `B`",
        );
        refused(&EXAMPLE_CONFIG.replace("epoch = 0.5", "epoch = 0.0"), "epoch");
        // With a run-level risk the calibrated certificate composes, delta/N per subsystem.
        let text = EXAMPLE_CONFIG
            .replace("# risk = 0.01", "risk = 0.01")
            .replace("[ambiguity]", "[calibration]\nenabled = true\n\n[ambiguity]");
        let cfg = parse(&text, "risk").expect("valid");
        assert_eq!(cfg.network.certificate, CertificateKind::Calibrated);
        for s in &cfg.network.subsystems {
            assert_eq!(s.certifier.calibration.map(|c| c.delta), Some(0.005));
        }
    }
}
