//! The `network` configuration: `[network]`, `[[subsystem]]`, `[[coupling]]`, and the
//! `certify` sections every subsystem shares (each subsystem's certifier built by the
//! `certify` parser).

use serde::{Deserialize, Serialize};
use streamcert_certificate::{CertificateKind, CouplingBlock, CouplingConfig};
use streamcert_network::{EstimatedCoupling, NetworkCertifier, NetworkConfig, SubsystemSpec};

use crate::CliError;
use crate::compose::{self, GainsFormat};
use crate::config::REQUIRED_VALUE;
use crate::config::{self, Columns};

/// The commented example printed by `streamcert network --print-config`: G5's two observed
/// subsystems (the columns `streamcert simulate g5` writes) with bidirectional coupling.
pub const EXAMPLE_CONFIG: &str = r#"# streamcert network configuration (TOML). Unknown keys are refused.
# Data: `streamcert simulate g5 --experiment 2 --coupling bidirectional` writes these columns.

[network]
epoch = 0.5             # seconds between compositions (t = k * epoch)
stale_after = 2.5       # a subsystem without a sample for this long is not certified
# Which local certificate composes: "calibrated" (the default: a stated risk over the run);
# "gaussian" or "wasserstein" is the paper-only mode, whose network verdict carries no
# stated risk.
certificate = "calibrated"
margin = 0.0            # the network is certified when its rate is >= margin (contraction)
consecutive = 1         # certified epochs in a row before the network gate opens
risk = 0.01             # run-level risk of the calibrated certificates, split delta/N
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
# process = 0           # over several processes (--processes): the one that reads A's samples

[[subsystem]]
name = "B"
outputs = ["y_b"]
inputs = ["u_b"]
gain = [[-3.0]]

# Coupling bounds: how `from` drives `to` (gamma >= 0). For many subsystems, a file instead:
# `gains = "gains.txt"` and `gains_format = "dense"` (N rows of N, entry (i, j) = how j drives
# i) or "triplets" (lines `i,j,gamma`) in [network], indices in [[subsystem]] order.
# Or measure a coupling: `estimate = true` instead of `gamma` puts `from`'s outputs among
# `to`'s regressors and composes with a calibrated upper bound on the gain (spends part of
# [network] risk; output column gamma_<from>_<to>).
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
    /// A gains file instead of (not beside) `[[coupling]]`: indices are the `[[subsystem]]`
    /// order; a relative path is relative to the configuration file's folder.
    gains: Option<String>,
    #[serde(default)]
    gains_format: GainsFormat,
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
    CertificateKind::Calibrated
}

/// The run-level risk of the calibrated certificates when `[network] risk` is omitted.
const DEFAULT_RISK: f64 = 0.01;

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
    /// The process (site) that reads this subsystem's samples in a run over several
    /// processes (`--processes`); default 0.
    #[serde(default, skip_serializing)]
    process: usize,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CouplingEntry {
    from: String,
    to: String,
    /// A given bound `γ >= 0`.
    gamma: Option<f64>,
    /// Estimate the gain instead: `to`'s regression takes `from`'s outputs as inputs.
    #[serde(default)]
    estimate: bool,
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
    /// The process that reads each subsystem (`[[subsystem]] process`, default 0).
    pub process_of: Vec<usize>,
    /// The `[source]` section as written (a live source of wide rows, read by the
    /// `streamcert-live` crate); `None`: the input is a file or stdin.
    pub source: Option<toml::Table>,
    /// The `[verdict]` section as written (an MQTT topic for the network's verdict messages,
    /// read by the `streamcert-live` crate); `None`: no verdict topic.
    pub verdict: Option<toml::Table>,
}

/// The key paths of `value` (under `at`) set to [`REQUIRED_VALUE`], anywhere in it.
fn placeholders(value: &toml::Value, at: &str, out: &mut Vec<String>) {
    let join = |key: &str| if at.is_empty() { key.to_string() } else { format!("{at}.{key}") };
    match value {
        toml::Value::String(s) if s == REQUIRED_VALUE => out.push(at.to_string()),
        toml::Value::Table(t) => {
            for (k, v) in t {
                placeholders(v, &join(k), out);
            }
        }
        toml::Value::Array(items) => {
            if items.iter().any(|v| matches!(v, toml::Value::String(s) if s == REQUIRED_VALUE)) {
                out.push(at.to_string());
            } else {
                for (i, v) in items.iter().enumerate() {
                    placeholders(v, &format!("{at}[{i}]"), out);
                }
            }
        }
        _ => {}
    }
}

/// What `streamcert network --print-config` writes: [`EXAMPLE_CONFIG`] with the user's
/// choices (the time column, each subsystem's columns and candidate gain, the network's and
/// the local certificates' margins) as [`REQUIRED_VALUE`] placeholders, refused by [`parse`]
/// naming each until they are set.
#[must_use]
pub fn template() -> String {
    EXAMPLE_CONFIG
        .replacen(
            "# Data: `streamcert simulate g5 --experiment 2 --coupling bidirectional` writes these columns.",
            "# Required: every key set to \"REQUIRED\" below (your columns, each subsystem's candidate\n\
             # gain, the margins); a file that leaves one so is refused naming it. The couplings and\n\
             # the rest are an example for two subsystems A and B.",
            1,
        )
        .replacen("margin = 0.0            #", "margin = \"REQUIRED\"    #", 1)
        .replacen("time = \"t\"", "time = \"REQUIRED\"", 1)
        .replace("outputs = [\"y_a\"]", "outputs = [\"REQUIRED\"]")
        .replace("inputs = [\"u_a\"]", "inputs = [\"REQUIRED\"]")
        .replace("outputs = [\"y_b\"]", "outputs = [\"REQUIRED\"]")
        .replace("inputs = [\"u_b\"]", "inputs = [\"REQUIRED\"]")
        .replace("gain = [[-2.5]]", "gain = \"REQUIRED\"")
        .replace("gain = [[-3.0]]", "gain = \"REQUIRED\"")
        .replacen("margin = 0.1\n", "margin = \"REQUIRED\"\n", 1)
}

/// Parse and validate; `path` names the file in errors.
///
/// # Errors
/// [`CliError::Config`].
pub fn parse(text: &str, path: &str) -> Result<NetConfig, CliError> {
    let bad = |message: String| CliError::Config { path: path.to_string(), message };
    let mut table: toml::Table = toml::from_str(text).map_err(|e| bad(e.to_string()))?;
    check_required(&table).map_err(bad)?;
    let mut section_table = |name: &str| match table.remove(name) {
        Some(toml::Value::Table(t)) => Ok(Some(t)),
        Some(_) => Err(bad(format!("[{name}] must be a table"))),
        None => Ok(None),
    };
    let source = section_table("source")?;
    let verdict = section_table("verdict")?;
    let (section, subsystems, couplings) = sections(&mut table).map_err(bad)?;
    let estimated = estimated_pairs(&couplings, &subsystems).map_err(bad)?;
    let calibrated = section.certificate == CertificateKind::Calibrated;
    if !estimated.is_empty() && section.risk.is_none() && !calibrated {
        return Err(bad(
            "estimated couplings spend part of the run-level risk: set [network] risk = δ (or \
             certificate = \"calibrated\", whose default risk is 0.01)"
                .into(),
        ));
    }
    let columns_table = match table.get("columns") {
        Some(toml::Value::Table(t)) => t.clone(),
        _ => return Err(bad("missing [columns] (the time column)".into())),
    };
    let mut specs = Vec::with_capacity(subsystems.len());
    let mut dims = Vec::with_capacity(subsystems.len());
    let mut columns =
        Columns { time: String::new(), outputs: vec![], inputs: vec![], delimiter: ",".into() };
    for i in 0..subsystems.len() {
        let (s, blocks) = with_estimated(&subsystems, i, &estimated);
        let text = subsystem_text(&table, &columns_table, &s).map_err(bad)?;
        let c = config::parse(&text, &format!("{path} (subsystem `{}`)", s.name))?;
        columns.time.clone_from(&c.columns.time);
        columns.delimiter.clone_from(&c.columns.delimiter);
        columns.outputs.extend(c.columns.outputs.iter().cloned());
        columns.inputs.extend(c.columns.inputs.iter().cloned());
        dims.push((c.columns.outputs.len(), c.columns.inputs.len()));
        let mut certifier = c.certifier;
        if !blocks.is_empty() {
            // The risk is set by `split_risk` below. Coupling gains are estimated at one
            // horizon: a subsystem whose gains are estimated runs at the regression's own
            // (`horizon = "auto"`: the paper's h = 5) without a horizon ladder.
            certifier.couplings = Some(CouplingConfig { blocks, delta: 0.5 });
            certifier.ladder = None;
        }
        specs.push(SubsystemSpec::new(&s.name, certifier));
    }
    let edges = coupling_edges(&section, &couplings, &subsystems, path).map_err(bad)?;
    let network = network_config(&section, specs, edges, &estimated).map_err(bad)?;
    // Build once: every check of the network and of each certifier.
    NetworkCertifier::new(network.clone()).map_err(|e| bad(e.to_string()))?;
    let process_of = subsystems.iter().map(|s| s.process).collect();
    Ok(NetConfig { columns, dims, network, layout: section.input, process_of, source, verdict })
}

/// Every key the user must set is set (none is left at the template's placeholder).
fn check_required(table: &toml::Table) -> Result<(), String> {
    let mut unset = Vec::new();
    placeholders(&toml::Value::Table(table.clone()), "", &mut unset);
    if unset.is_empty() {
        return Ok(());
    }
    Err(format!(
        "required {} not set: {} (your plant's columns, each subsystem's candidate gain and \
         the margins have no default; `streamcert network --print-config` marks them \
         \"{REQUIRED_VALUE}\")",
        if unset.len() == 1 { "key" } else { "keys" },
        unset.join(", ")
    ))
}

/// `[network]`, `[[subsystem]]` and `[[coupling]]` taken out of `table` (the rest is the
/// `certify` sections every subsystem shares).
fn sections(
    table: &mut toml::Table,
) -> Result<(NetworkSection, Vec<SubsystemEntry>, Vec<CouplingEntry>), String> {
    let section: NetworkSection = table
        .remove("network")
        .ok_or("missing [network]")?
        .try_into()
        .map_err(|e: toml::de::Error| format!("[network]: {e}"))?;
    let subsystems: Vec<SubsystemEntry> = table
        .remove("subsystem")
        .ok_or("no [[subsystem]]")?
        .try_into()
        .map_err(|e: toml::de::Error| format!("[[subsystem]]: {e}"))?;
    let couplings: Vec<CouplingEntry> = match table.remove("coupling") {
        Some(v) => v.try_into().map_err(|e: toml::de::Error| format!("[[coupling]]: {e}"))?,
        None => Vec::new(),
    };
    Ok((section, subsystems, couplings))
}

/// The index of the subsystem a `[[coupling]]` names.
fn index_of(subsystems: &[SubsystemEntry], name: &str) -> Result<usize, String> {
    subsystems
        .iter()
        .position(|s| s.name == name)
        .ok_or_else(|| format!("[[coupling]] names `{name}`, which is no [[subsystem]]"))
}

/// The estimated couplings `(to, from)` in file order (each coupling gives `gamma` or
/// `estimate = true`, not both).
fn estimated_pairs(
    couplings: &[CouplingEntry],
    subsystems: &[SubsystemEntry],
) -> Result<Vec<(usize, usize)>, String> {
    let mut estimated = Vec::new();
    for c in couplings {
        match (c.gamma, c.estimate) {
            (Some(_), true) => {
                return Err(format!(
                    "[[coupling]] {} -> {}: give `gamma` or `estimate = true`, not both",
                    c.from, c.to
                ));
            }
            (None, false) => {
                return Err(format!(
                    "[[coupling]] {} -> {}: needs `gamma` (a given bound) or `estimate = true`",
                    c.from, c.to
                ));
            }
            (None, true) => {
                estimated.push((index_of(subsystems, &c.to)?, index_of(subsystems, &c.from)?));
            }
            (Some(_), false) => {}
        }
    }
    Ok(estimated)
}

/// Subsystem `i` with the outputs of the subsystems whose couplings into it are estimated
/// among its inputs (a zero row of the gain per channel), and those coupling blocks.
fn with_estimated(
    subsystems: &[SubsystemEntry],
    i: usize,
    estimated: &[(usize, usize)],
) -> (SubsystemEntry, Vec<CouplingBlock>) {
    let s = &subsystems[i];
    let (mut inputs, mut gain) = (s.inputs.clone(), s.gain.clone());
    let p = s.outputs.len();
    let mut blocks = Vec::new();
    for &(_, from) in estimated.iter().filter(|&&(to, _)| to == i) {
        let first = inputs.len();
        inputs.extend(subsystems[from].outputs.iter().cloned());
        gain.extend(subsystems[from].outputs.iter().map(|_| vec![0.0; p]));
        blocks.push(CouplingBlock { first, len: subsystems[from].outputs.len() });
    }
    let entry = SubsystemEntry {
        name: s.name.clone(),
        outputs: s.outputs.clone(),
        inputs,
        gain,
        process: s.process,
    };
    (entry, blocks)
}

/// The subsystem as a `certify` configuration's text: its columns and gain, the shared rest.
fn subsystem_text(
    shared: &toml::Table,
    columns: &toml::Table,
    s: &SubsystemEntry,
) -> Result<String, String> {
    fn value<T: Serialize>(v: &T) -> Result<toml::Value, String> {
        toml::Value::try_from(v).map_err(|e| e.to_string())
    }
    let mut t = shared.clone();
    let mut cols = columns.clone();
    cols.insert("outputs".into(), value(&s.outputs)?);
    cols.insert("inputs".into(), value(&s.inputs)?);
    t.insert("columns".into(), toml::Value::Table(cols));
    let mut controller = toml::Table::new();
    controller.insert("gain".into(), value(&s.gain)?);
    t.insert("controller".into(), toml::Value::Table(controller));
    toml::to_string(&t).map_err(|e| e.to_string())
}

/// The given coupling bounds as edges `(to, from, γ)`: from `[network] gains` (a file beside
/// the configuration) or from the `[[coupling]]` entries, not both.
fn coupling_edges(
    section: &NetworkSection,
    couplings: &[CouplingEntry],
    subsystems: &[SubsystemEntry],
    path: &str,
) -> Result<Vec<(usize, usize, f64)>, String> {
    match &section.gains {
        Some(_) if !couplings.is_empty() => {
            Err("[network] gains and [[coupling]] both give coupling bounds: keep one".into())
        }
        Some(file) => {
            let file = std::path::Path::new(path)
                .parent()
                .filter(|_| std::path::Path::new(file).is_relative())
                .map_or_else(|| std::path::PathBuf::from(file), |dir| dir.join(file));
            let shown = file.display().to_string();
            let text = std::fs::read_to_string(&file)
                .map_err(|e| format!("[network] gains: cannot read {shown}: {e}"))?;
            compose::gain_edges(&text, &shown, subsystems.len(), section.gains_format)
                .map_err(|e| format!("[network] gains: {e}"))
        }
        None => couplings
            .iter()
            .filter_map(|c| {
                let at = |name: &str| index_of(subsystems, name);
                c.gamma.map(|g| Ok((at(&c.to)?, at(&c.from)?, g)))
            })
            .collect(),
    }
}

/// The network of the subsystems' certifiers, its edges and estimated couplings, with
/// `[network]`'s settings and its risk split over the certificates.
fn network_config(
    section: &NetworkSection,
    specs: Vec<SubsystemSpec>,
    edges: Vec<(usize, usize, f64)>,
    estimated: &[(usize, usize)],
) -> Result<NetworkConfig, String> {
    let n = specs.len();
    let mut network = NetworkConfig::new(specs, edges, section.epoch);
    let mut seen = vec![0; n];
    network.estimated = estimated
        .iter()
        .map(|&(to, from)| {
            seen[to] += 1;
            EstimatedCoupling { to, from, block: seen[to] - 1 }
        })
        .collect();
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
    let calibrated = section.certificate == CertificateKind::Calibrated;
    if calibrated && network.subsystems.iter().any(|s| s.certifier.calibration.is_none()) {
        return Err("[network] certificate = \"calibrated\" composes the calibrated \
                    certificates, but [calibration] enabled = false leaves no calibration: \
                    enable it, or choose the paper-only certificate = \"gaussian\" (no stated \
                    risk)"
            .into());
    }
    if let Some(delta) = section.risk.or(calibrated.then_some(DEFAULT_RISK)) {
        if !(delta > 0.0 && delta < 1.0) {
            return Err(format!("[network] risk must be in (0, 1), got {delta}"));
        }
        // `split_risk` selects the calibrated certificate; the paper-only choice stands (its
        // subsystems' calibrations still run at their share, for comparison).
        network = network.split_risk(delta);
        network.certificate = section.certificate;
    }
    Ok(network)
}

#[cfg(test)]
mod tests;
