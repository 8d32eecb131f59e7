//! The `certify` configuration file (TOML), validated before any data is read.

use serde::Deserialize;
use streamcert_ambiguity::{AmbiguityConfig, SpikeScale};
use streamcert_certificate::{
    Calibration, Certifier, CertifierConfig, GuardVariance, ResidualSource, RiskSplit,
};
use streamcert_regression::{Estimator, InputIntegral, Model, RegressionConfig};

use crate::CliError;

mod choice;
mod nonlinear;
mod required;

use choice::{Choice, OrderChoice};
use nonlinear::NonlinearSection;
use required::required_message;
pub use required::{REQUIRED_KEYS, REQUIRED_VALUE, g5_node_b, unset_required};

/// The commented default configuration printed by `streamcert certify --print-config`.
pub const DEFAULT_CONFIG: &str = include_str!("config/default.toml");

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    columns: Columns,
    controller: Controller,
    certificate: Certificate,
    #[serde(default)]
    regression: Regression,
    #[serde(default)]
    ambiguity: Ambiguity,
    #[serde(default)]
    calibration: CalibrationSection,
    #[serde(default)]
    nonlinear: NonlinearSection,
    #[serde(default)]
    source: Option<toml::Table>,
    #[serde(default)]
    verdict: Option<toml::Table>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CalibrationSection {
    #[serde(default = "default_true")]
    enabled: bool,
    #[serde(default = "default_delta")]
    delta: f64,
    #[serde(default)]
    windows: Option<usize>,
    #[serde(default)]
    max_window: Option<usize>,
    #[serde(default)]
    look_spacing: Option<f64>,
    #[serde(default)]
    instrument_lag: Option<usize>,
    #[serde(default)]
    instrument_intervals: Option<usize>,
    #[serde(default)]
    batch_blocks: Option<usize>,
    #[serde(default)]
    auto_batches: Option<usize>,
    #[serde(default)]
    auto_batch_risk: Option<f64>,
    #[serde(default)]
    hidden_dynamics: Option<bool>,
    #[serde(default)]
    nonlinearity: Option<bool>,
    #[serde(default)]
    plant_change: Option<bool>,
    #[serde(default)]
    change_risk: Option<f64>,
    #[serde(default)]
    guard_risk: Option<f64>,
    #[serde(default)]
    risk_split: Option<RiskSplit>,
    #[serde(default)]
    relative_ridge: Option<f64>,
    #[serde(default)]
    guard_variance: Option<GuardVariance>,
    #[serde(default)]
    anchored_share: Option<f64>,
    #[serde(default)]
    anchored_growth: Option<f64>,
    #[serde(default)]
    anchored_looks: Option<usize>,
}

fn default_true() -> bool {
    true
}

fn default_delta() -> f64 {
    0.01
}

impl Default for CalibrationSection {
    fn default() -> Self {
        Self {
            enabled: true,
            delta: default_delta(),
            windows: None,
            max_window: None,
            look_spacing: None,
            instrument_lag: None,
            instrument_intervals: None,
            batch_blocks: None,
            auto_batches: None,
            auto_batch_risk: None,
            hidden_dynamics: None,
            nonlinearity: None,
            plant_change: None,
            change_risk: None,
            guard_risk: None,
            risk_split: None,
            relative_ridge: None,
            guard_variance: None,
            anchored_share: None,
            anchored_growth: None,
            anchored_looks: None,
        }
    }
}

impl CalibrationSection {
    /// The library's settings: every omitted key takes the library's default.
    fn calibration(&self) -> Calibration {
        let d = Calibration::new(self.delta);
        Calibration {
            windows: self.windows.or(d.windows),
            max_window: self.max_window.or(d.max_window),
            look_spacing: self.look_spacing.unwrap_or(d.look_spacing),
            instrument_lag: self.instrument_lag.unwrap_or(d.instrument_lag),
            instrument_intervals: self.instrument_intervals.unwrap_or(d.instrument_intervals),
            batch_blocks: self.batch_blocks.unwrap_or(d.batch_blocks),
            auto_batches: self.auto_batches.unwrap_or(d.auto_batches),
            auto_batch_risk: self.auto_batch_risk.unwrap_or(d.auto_batch_risk),
            hidden_dynamics: self.hidden_dynamics.unwrap_or(d.hidden_dynamics),
            nonlinearity: self.nonlinearity.unwrap_or(d.nonlinearity),
            plant_change: self.plant_change.unwrap_or(d.plant_change),
            change_risk: self.change_risk.or(d.change_risk),
            guard_risk: self.guard_risk.or(d.guard_risk),
            risk_split: self.risk_split.unwrap_or(d.risk_split),
            relative_ridge: self.relative_ridge.unwrap_or(d.relative_ridge),
            guard_variance: self.guard_variance.unwrap_or(d.guard_variance),
            anchored_share: self.anchored_share.unwrap_or(d.anchored_share),
            anchored_growth: self.anchored_growth.unwrap_or(d.anchored_growth),
            anchored_looks: self.anchored_looks.unwrap_or(d.anchored_looks),
            ..d
        }
    }
}

/// Input column names and the field delimiter.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Columns {
    /// Time column.
    pub time: String,
    /// Output columns.
    pub outputs: Vec<String>,
    /// Input columns.
    pub inputs: Vec<String>,
    /// Field delimiter: `","` (default), `";"`, or `"\t"` / `"tab"`.
    #[serde(default = "default_delimiter")]
    pub delimiter: String,
}

fn default_delimiter() -> String {
    ",".into()
}

impl Columns {
    /// The delimiter as one byte.
    ///
    /// # Errors
    /// A message naming the accepted delimiters.
    pub fn delimiter_byte(&self) -> Result<u8, String> {
        match self.delimiter.as_str() {
            "," => Ok(b','),
            ";" => Ok(b';'),
            "\t" | "\\t" | "tab" => Ok(b'\t'),
            other => Err(format!(
                "`delimiter` must be \",\", \";\" or \"tab\" (or \"\\t\"), got {other:?}"
            )),
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Controller {
    gain: Vec<Vec<f64>>,
}

/// `conservatism` and `consecutive` may be omitted (0.1, the reproduction's `c`, and 10, the
/// paper's `n_s`); `margin`, what "contracts" means for the user's plant, may not.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Certificate {
    #[serde(default = "default_conservatism")]
    conservatism: f64,
    margin: f64,
    #[serde(default = "default_consecutive")]
    consecutive: usize,
    #[serde(default)]
    gap_factor: Option<f64>,
    #[serde(default)]
    metric: Option<Vec<f64>>,
}

fn default_conservatism() -> f64 {
    0.1
}

fn default_consecutive() -> usize {
    10
}

/// Every key may be omitted: the defaults are the ones `--print-config` shows.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct Regression {
    order: OrderChoice,
    model: Model,
    window: Choice,
    horizon: Choice,
    ridge: f64,
    min_columns: Option<usize>,
    input_integral: InputIntegral,
    estimator: Estimator,
}

impl Default for Regression {
    fn default() -> Self {
        Self {
            order: OrderChoice::default(),
            model: Model::Affine,
            window: Choice::Fixed(150),
            horizon: Choice::Fixed(5),
            ridge: 1e-4,
            min_columns: None,
            input_integral: InputIntegral::ZeroOrderHold,
            estimator: Estimator::Ordinary,
        }
    }
}

/// Every key may be omitted: the defaults are the ones `--print-config` shows (the paper's).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct Ambiguity {
    enabled: bool,
    tail_window: usize,
    eps_floor: f64,
    eps_cap: f64,
    alpha_kurtosis: f64,
    alpha_spike: f64,
    sigma0: Option<f64>,
    residuals: ResidualSource,
}

impl Default for Ambiguity {
    fn default() -> Self {
        let a = AmbiguityConfig::paper(150);
        Self {
            enabled: true,
            tail_window: a.tail_window,
            eps_floor: a.eps_floor,
            eps_cap: a.eps_cap,
            alpha_kurtosis: a.alpha_kurtosis,
            alpha_spike: a.alpha_spike,
            sigma0: None,
            residuals: ResidualSource::OneStep,
        }
    }
}

/// A validated configuration.
#[derive(Debug, Clone)]
pub struct Config {
    /// Column names.
    pub columns: Columns,
    /// The certifier configuration.
    pub certifier: CertifierConfig,
    /// The `[source]` section as written (a live plant source, read by the `streamcert-live`
    /// crate, which validates it); `None` when the file has none (the input is a file or
    /// stdin). It never enters the certifier's configuration, so a checkpoint resumes under
    /// another source.
    pub source: Option<toml::Table>,
    /// The `[verdict]` section as written (an MQTT topic for the verdict messages, read by
    /// the `streamcert-live` crate, which validates it); `None`: no verdict topic.
    pub verdict: Option<toml::Table>,
}

/// How a TOML error names where it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorPlace {
    /// The file's line and column with the line quoted: for a file the user wrote.
    Lines,
    /// The key's path (`certificate.margn`): for a text built from the user's mapping (a
    /// Python dict), whose lines the user never saw.
    KeyPaths,
}

/// The dotted path of the key whose value or name starts at byte `at` of `text` (the last
/// `[section]` header before it, then the key on that line).
fn key_path_at(text: &str, at: usize) -> Option<String> {
    let before = text.get(..at)?;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let line = text[line_start..].lines().next()?;
    let key = line.split('=').next()?.trim();
    let section = before[..line_start]
        .lines()
        .rev()
        .map(str::trim)
        .find(|l| l.starts_with('[') && l.ends_with(']'))
        .map(|l| l.trim_matches(|c| c == '[' || c == ']').trim().to_string());
    Some(match section {
        Some(s) if !key.is_empty() && !key.starts_with('[') => format!("{s}.{key}"),
        Some(s) => s,
        None => key.to_string(),
    })
}

/// `e` as a message placed by `place`.
fn toml_message(e: &toml::de::Error, text: &str, place: ErrorPlace) -> String {
    match (place, e.span().and_then(|span| key_path_at(text, span.start))) {
        (ErrorPlace::KeyPaths, Some(path)) => format!("`{path}`: {}", e.message().trim_end()),
        (ErrorPlace::KeyPaths, None) => e.message().trim_end().to_string(),
        (ErrorPlace::Lines, _) => e.to_string(),
    }
}

/// Parse and validate a configuration text; `path` names it in errors.
///
/// # Errors
/// [`CliError::Config`] for a TOML error, a required key unset ([`REQUIRED_KEYS`], named in
/// the message), an unknown key, a wrong `K` shape or an invalid parameter.
pub fn parse(text: &str, path: &str) -> Result<Config, CliError> {
    parse_placed(text, path, ErrorPlace::Lines)
}

/// [`parse`], with TOML errors placed by `place`.
///
/// # Errors
/// As [`parse`].
pub fn parse_placed(text: &str, path: &str, place: ErrorPlace) -> Result<Config, CliError> {
    let bad = |message: String| CliError::Config { path: path.to_string(), message };
    let table: toml::Table =
        toml::from_str(text).map_err(|e| bad(toml_message(&e, text, place)))?;
    let unset = unset_required(&table);
    if !unset.is_empty() {
        return Err(bad(required_message(&unset)));
    }
    let f: File = toml::from_str(text).map_err(|e| bad(toml_message(&e, text, place)))?;
    let (p, m) = check_shape(&f).map_err(&bad)?;
    let r = &f.regression;
    let (window, horizon, ladder) = choice::resolve(r.window, r.horizon, f.calibration.enabled);
    let (order, orders) = choice::resolve_order(r.order, f.calibration.enabled);
    let reg = RegressionConfig {
        min_columns: r.min_columns.unwrap_or(window),
        input_integral: r.input_integral,
        estimator: r.estimator,
        model: r.model,
        order,
        ..RegressionConfig::new(p, m, window, horizon, r.ridge)
    };
    let mut certifier = CertifierConfig::new(
        reg,
        f.controller.gain.concat(),
        f.certificate.conservatism,
        f.certificate.margin,
        f.certificate.consecutive,
    );
    if let Some(g) = f.certificate.gap_factor {
        certifier.gap_factor = g;
    }
    certifier.metric.clone_from(&f.certificate.metric);
    let a = &f.ambiguity;
    certifier.ambiguity = a.config();
    certifier.residuals = a.residuals;
    if f.calibration.enabled {
        certifier.calibration = Some(f.calibration.calibration());
    }
    certifier.ladder = ladder;
    certifier.orders = orders;
    certifier.nonlinear = f.nonlinear.config().map_err(&bad)?;
    f.columns.delimiter_byte().map_err(&bad)?;
    // Validate everything by building a certifier once.
    Certifier::new(certifier.clone()).map_err(|e| bad(e.to_string()))?;
    Ok(Config { columns: f.columns, certifier, source: f.source, verdict: f.verdict })
}

/// The columns named once each, at least one output and one input, and a gain of `m × p`:
/// `(p, m)`, or what is wrong.
fn check_shape(f: &File) -> Result<(usize, usize), String> {
    let (p, m) = (f.columns.outputs.len(), f.columns.inputs.len());
    if p == 0 || m == 0 {
        return Err("columns.outputs and columns.inputs must each name at least one column".into());
    }
    let mut names: Vec<&String> = f.columns.outputs.iter().chain(&f.columns.inputs).collect();
    names.push(&f.columns.time);
    names.sort();
    if names.windows(2).any(|w| w[0] == w[1]) {
        return Err("a column is named twice in [columns]".into());
    }
    if f.controller.gain.len() != m || f.controller.gain.iter().any(|r| r.len() != p) {
        return Err(format!(
            "controller.gain must be m × p = {m} × {p} (one row per input, one value per output), got {} rows of lengths {:?}",
            f.controller.gain.len(),
            f.controller.gain.iter().map(Vec::len).collect::<Vec<_>>()
        ));
    }
    Ok((p, m))
}

impl Ambiguity {
    /// The ambiguity model this section configures, if enabled.
    fn config(&self) -> Option<AmbiguityConfig> {
        self.enabled.then_some(AmbiguityConfig {
            tail_window: self.tail_window,
            eps_floor: self.eps_floor,
            eps_cap: self.eps_cap,
            alpha_kurtosis: self.alpha_kurtosis,
            alpha_spike: self.alpha_spike,
            spike_scale: match self.sigma0 {
                Some(sigma0) => SpikeScale::Fixed { sigma0 },
                None => SpikeScale::Calibrated { samples: self.tail_window },
            },
        })
    }
}

#[cfg(test)]
mod tests;
