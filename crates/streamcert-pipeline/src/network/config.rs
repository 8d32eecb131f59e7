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
    let mut unset = Vec::new();
    placeholders(&toml::Value::Table(table.clone()), "", &mut unset);
    if !unset.is_empty() {
        return Err(bad(format!(
            "required {} not set: {} (your plant's columns, each subsystem's candidate gain and \
             the margins have no default; `streamcert network --print-config` marks them \
             \"{REQUIRED_VALUE}\")",
            if unset.len() == 1 { "key" } else { "keys" },
            unset.join(", ")
        )));
    }
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
    let index = |name: &str| {
        subsystems
            .iter()
            .position(|s| s.name == name)
            .ok_or_else(|| bad(format!("[[coupling]] names `{name}`, which is no [[subsystem]]")))
    };
    // Estimated couplings: (to, from) in file order; each adds `from`'s outputs to `to`'s
    // inputs (one coupling block, a zero row of the gain per channel).
    let mut estimated = Vec::new();
    for c in &couplings {
        match (c.gamma, c.estimate) {
            (Some(_), true) => {
                return Err(bad(format!(
                    "[[coupling]] {} -> {}: give `gamma` or `estimate = true`, not both",
                    c.from, c.to
                )));
            }
            (None, false) => {
                return Err(bad(format!(
                    "[[coupling]] {} -> {}: needs `gamma` (a given bound) or `estimate = true`",
                    c.from, c.to
                )));
            }
            (None, true) => estimated.push((index(&c.to)?, index(&c.from)?)),
            (Some(_), false) => {}
        }
    }
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
    let (mut outputs, mut inputs) = (Vec::new(), Vec::new());
    let mut time = String::new();
    let mut delimiter = ",".to_string();
    let mut blocks = Vec::new();
    for (i, s) in subsystems.iter().enumerate() {
        // The subsystem as a `certify` configuration: its columns and gain, the shared rest;
        // the outputs of the subsystems whose couplings into it are estimated join its inputs.
        let (mut s_inputs, mut s_gain) = (s.inputs.clone(), s.gain.clone());
        let p = s.outputs.len();
        let mut own = Vec::new();
        for &(_, from) in estimated.iter().filter(|&&(to, _)| to == i) {
            let first = s_inputs.len();
            s_inputs.extend(subsystems[from].outputs.iter().cloned());
            s_gain.extend(subsystems[from].outputs.iter().map(|_| vec![0.0; p]));
            own.push(CouplingBlock { first, len: subsystems[from].outputs.len() });
        }
        blocks.push(own);
        let s = &SubsystemEntry {
            name: s.name.clone(),
            outputs: s.outputs.clone(),
            inputs: s_inputs,
            gain: s_gain,
            process: s.process,
        };
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
        let mut certifier = c.certifier;
        if !blocks[i].is_empty() {
            // The risk is set by `split_risk` below.
            let blocks = std::mem::take(&mut blocks[i]);
            certifier.couplings = Some(CouplingConfig { blocks, delta: 0.5 });
        }
        specs.push(SubsystemSpec::new(&s.name, certifier));
    }
    let edges = match &section.gains {
        Some(_) if !couplings.is_empty() => {
            return Err(bad(
                "[network] gains and [[coupling]] both give coupling bounds: keep one".into(),
            ));
        }
        Some(file) => {
            let file = std::path::Path::new(path)
                .parent()
                .filter(|_| std::path::Path::new(file).is_relative())
                .map_or_else(|| std::path::PathBuf::from(file), |dir| dir.join(file));
            let shown = file.display().to_string();
            let text = std::fs::read_to_string(&file)
                .map_err(|e| bad(format!("[network] gains: cannot read {shown}: {e}")))?;
            compose::gain_edges(&text, &shown, subsystems.len(), section.gains_format)
                .map_err(|e| bad(format!("[network] gains: {e}")))?
        }
        None => couplings
            .iter()
            .filter_map(|c| c.gamma.map(|g| Ok((index(&c.to)?, index(&c.from)?, g))))
            .collect::<Result<Vec<_>, CliError>>()?,
    };
    let mut network = NetworkConfig::new(specs, edges, section.epoch);
    let mut seen = vec![0; subsystems.len()];
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
    if calibrated && network.subsystems.iter().any(|s| s.certifier.calibration.is_none()) {
        return Err(bad(
            "[network] certificate = \"calibrated\" composes the calibrated certificates, but \
             [calibration] enabled = false leaves no calibration: enable it, or choose the \
             paper-only certificate = \"gaussian\" (no stated risk)"
                .into(),
        ));
    }
    if let Some(delta) = section.risk.or(calibrated.then_some(DEFAULT_RISK)) {
        if !(delta > 0.0 && delta < 1.0) {
            return Err(bad(format!("[network] risk must be in (0, 1), got {delta}")));
        }
        // `split_risk` selects the calibrated certificate; the paper-only choice stands (its
        // subsystems' calibrations still run at their share, for comparison).
        network = network.split_risk(delta);
        network.certificate = section.certificate;
    }
    // Build once: every check of the network and of each certifier.
    NetworkCertifier::new(network.clone()).map_err(|e| bad(e.to_string()))?;
    let columns = Columns { time, outputs, inputs, delimiter };
    let process_of = subsystems.iter().map(|s| s.process).collect();
    Ok(NetConfig { columns, dims, network, layout: section.input, process_of })
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

    /// The committed example the docs run is [`EXAMPLE_CONFIG`], byte for byte.
    #[test]
    fn the_committed_example_is_the_example() {
        let committed = include_str!("../../../../examples/data/g5_network.toml");
        assert_eq!(committed, EXAMPLE_CONFIG);
    }

    /// `network --print-config`'s template is refused naming every choice it leaves to the
    /// user, and the example (the template with G5's choices) parses.
    #[test]
    fn the_template_names_every_required_key() {
        let err = parse(&template(), "net.toml").unwrap_err().to_string();
        for path in [
            "network.margin",
            "columns.time",
            "subsystem[0].outputs",
            "subsystem[0].inputs",
            "subsystem[0].gain",
            "subsystem[1].gain",
            "certificate.margin",
        ] {
            assert!(err.contains(path), "`{path}` not in: {err}");
        }
        assert!(!err.contains("gamma") && !err.contains("epoch"), "{err}");
        let one = EXAMPLE_CONFIG.replace("gain = [[-3.0]]", "gain = \"REQUIRED\"");
        let err = parse(&one, "net.toml").unwrap_err().to_string();
        assert!(err.contains("required key not set: subsystem[1].gain"), "{err}");
    }

    #[test]
    fn the_example_parses_and_bad_networks_are_refused() {
        let cfg = parse(EXAMPLE_CONFIG, "example").expect("the example is valid");
        assert_eq!(cfg.dims, vec![(1, 1), (1, 1)]);
        assert_eq!(cfg.columns.outputs, ["y_a", "y_b"]);
        assert_eq!(cfg.network.couplings, vec![(0, 1, 0.4), (1, 0, 0.4)]);
        refused(&EXAMPLE_CONFIG.replace("from = \"B\"", "from = \"C\""), "`C`");
        refused(&EXAMPLE_CONFIG.replace("risk = 0.01 ", "risk = 1.5 "), "risk");
        refused(
            &EXAMPLE_CONFIG.replace("[ambiguity]", "[calibration]\nenabled = false\n\n[ambiguity]"),
            "no calibration",
        );
        // The default is the calibrated certificate at risk 0.01, δ/N per subsystem.
        assert_eq!(cfg.network.certificate, CertificateKind::Calibrated);
        for s in &cfg.network.subsystems {
            assert_eq!(s.certifier.calibration.map(|c| c.delta), Some(0.005));
        }
        let paper = EXAMPLE_CONFIG
            .replace("certificate = \"calibrated\"", "certificate = \"gaussian\"")
            .replace("risk = 0.01 ", "# risk = 0.01 ");
        let cfg = parse(&paper, "paper").expect("the paper-only mode is valid");
        assert_eq!(cfg.network.certificate, CertificateKind::Gaussian);
        refused(
            &EXAMPLE_CONFIG.replace("gamma = 0.4", "gamma = -0.4"),
            "γ must be finite and >= 0",
        );
        refused(
            &EXAMPLE_CONFIG.replace("gain = [[-3.0]]", "gain = [[-3.0, 1.0]]"),
            "subsystem `B`",
        );
        refused(&EXAMPLE_CONFIG.replace("epoch = 0.5", "epoch = 0.0"), "epoch");
        // Estimated couplings: one of gamma and estimate, and a run-level risk.
        refused(&paper.replace("gamma = 0.4", "estimate = true"), "[network] risk");
        refused(&EXAMPLE_CONFIG.replace("gamma = 0.4", "gamma = 0.4\nestimate = true"), "not both");
        refused(&EXAMPLE_CONFIG.replace("gamma = 0.4", ""), "needs `gamma`");
        let text = EXAMPLE_CONFIG
            .replacen("gamma = 0.4", "estimate = true", 1)
            .replace("risk = 0.01 ", "risk = 0.03 ");
        let cfg = parse(&text, "estimated").expect("valid");
        // B -> A estimated: A's inputs gain B's output, a zero gain row and one block.
        assert_eq!(cfg.dims, vec![(1, 2), (1, 1)]);
        assert_eq!(cfg.columns.inputs, ["u_a", "y_b", "u_b"]);
        let a = &cfg.network.subsystems[0].certifier;
        assert_eq!(a.gain, vec![-2.5, 0.0]);
        let blocks = a.couplings.as_ref().map(|c| (c.blocks.clone(), c.delta));
        assert_eq!(blocks, Some((vec![CouplingBlock { first: 1, len: 1 }], 0.01)));
        assert_eq!(cfg.network.estimated, vec![EstimatedCoupling { to: 0, from: 1, block: 0 }]);
        assert_eq!(cfg.network.couplings, vec![(1, 0, 0.4)]);
        // A run-level risk with the paper's certificate named: the named certificate composes
        // (the explicit paper-only choice, labelled as such), and the calibrations beside it
        // run at their share.
        let text = paper.replace("# risk = 0.01 ", "risk = 0.02 ");
        let cfg = parse(&text, "risk").expect("valid");
        assert_eq!(cfg.network.certificate, CertificateKind::Gaussian);
        for s in &cfg.network.subsystems {
            assert_eq!(s.certifier.calibration.map(|c| c.delta), Some(0.01));
        }
        assert_eq!(cfg.network.total_risk(), None, "the paper-only verdict states no risk");
    }

    #[test]
    fn coupling_bounds_from_a_gains_file_in_either_layout() {
        let dir = std::env::temp_dir().join(format!("streamcert-gains-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let cfg_path = dir.join("net.toml");
        let without = |text: &str| {
            let start = text.find("[[coupling]]").expect("couplings");
            let end = text.find("# Every subsystem's certifier").expect("end");
            format!("{}{}", &text[..start], &text[end..])
        };
        let base = without(EXAMPLE_CONFIG);
        let want = parse(EXAMPLE_CONFIG, "example").expect("valid").network.couplings;
        for (file, layout, body) in [
            ("dense.txt", "dense", "0 0.4\n0.4 0\n"),
            ("triplets.txt", "triplets", "i,j,gamma\n0,1,0.4\n1,0,0.4\n"),
        ] {
            std::fs::write(dir.join(file), body).expect("write");
            let text = base.replacen(
                "[network]",
                &format!("[network]\ngains = \"{file}\"\ngains_format = \"{layout}\""),
                1,
            );
            // A relative path is read next to the configuration file.
            let cfg = parse(&text, cfg_path.to_str().expect("utf8")).expect(layout);
            let mut got = cfg.network.couplings.clone();
            got.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
            let mut expected = want.clone();
            expected.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
            assert_eq!(got, expected, "{layout}");
        }
        let path = cfg_path.to_str().expect("utf8");
        let with =
            |extra: &str| EXAMPLE_CONFIG.replacen("[network]", &format!("[network]\n{extra}"), 1);
        let message = |text: &str| parse(text, path).expect_err("refused").to_string();
        assert!(message(&with("gains = \"dense.txt\"")).contains("keep one"));
        let missing = base.replacen("[network]", "[network]\ngains = \"nowhere.txt\"", 1);
        assert!(message(&missing).contains("cannot read"));
        std::fs::write(dir.join("bad.txt"), "0 0.4 1\n0.4 0\n").expect("write");
        let shape = base.replacen("[network]", "[network]\ngains = \"bad.txt\"", 1);
        assert!(message(&shape).contains("2 rows of 2"));
        std::fs::write(dir.join("neg.txt"), "0,1,-0.4\n").expect("write");
        let negative = base.replacen(
            "[network]",
            "[network]\ngains = \"neg.txt\"\ngains_format = \"triplets\"",
            1,
        );
        assert!(message(&negative).contains("γ must be finite and >= 0"));
        std::fs::write(dir.join("far.txt"), "0,7,0.4\n").expect("write");
        let far = base.replacen(
            "[network]",
            "[network]\ngains = \"far.txt\"\ngains_format = \"triplets\"",
            1,
        );
        assert!(parse(&far, path).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
