//! The `certify` configuration file (TOML), validated before any data is read.

use serde::Deserialize;
use streamcert_ambiguity::{AmbiguityConfig, SpikeScale};
use streamcert_certificate::{
    Calibration, Certifier, CertifierConfig, FeatureSet, NonlinearConfig, ResidualSource, RiskSplit,
};
use streamcert_regression::{Estimator, InputIntegral, Model, RegressionConfig};

use crate::CliError;

/// The commented default configuration printed by `streamcert certify --print-config`.
pub const DEFAULT_CONFIG: &str = r#"# streamcert certify configuration (TOML). Unknown keys are refused.

[columns]
# Name of the time column (seconds, strictly increasing).
time = "t"
# Measured outputs y (p columns) and applied inputs u (m columns), by header name.
outputs = ["y_b"]       # (the names `streamcert simulate g5` writes for node b)
inputs = ["u_b"]        # (the applied input of node b)
# delimiter = ","       # or ";" or "tab"; quoted fields and a byte-order mark are accepted

[controller]
# Candidate gain K (m rows of p values): the controller u = K y to be certified (-4 is G5's).
gain = [[-4.0]]

[certificate]
# Conservatism c of the paper's radius rho = c (1 + ||K||) RMS(R) / sqrt(lambda_min(Z Z^T / M)
# + lambda), for the paper's two certificates only (they carry no stated risk; the verdict is
# the calibrated one below). The paper gives no value; 0.1 is the reproduction's.
conservatism = 0.1
# Deploy once the certificate is >= margin for `consecutive` samples (the paper's gate rule;
# 0.05 and 10 are its experiments' values, and a margin > 0 is what "contracts" means).
margin = 0.05
consecutive = 10        # n_s
# A step above gap_factor times the median of the last 32 steps is a gap: the window
# restarts there and the gates close (the row's reason says so).
# gap_factor = 5.0
# With two or more outputs, the metric the rate is measured in: one weight per output
# (the rate of w1 y1, w2 y2, ...). Without it the units as logged decide (an output in mm
# instead of m changes the verdict); the summary warns when the outputs' ranges differ by
# more than 100x. For example the inverse of each output's typical range:
# metric = [1.0, 0.01]

[regression]
# The model: "affine" fits an intercept beside the dynamics (dY = Theta Z + c tau), so the
# verdict does not depend on the operating point or the sensor's units offset (°C or K);
# "through_origin" is the paper's dY = Theta Z, valid only for a loop that runs about zero.
model = "affine"
window = 150            # M: columns in the sliding window (the paper's experiments)
horizon = 5             # h: samples per integration interval (the paper's experiments)
ridge = 1e-4            # lambda (far below the excitation of a dithered loop)
# min_columns = 150     # warm-up (default: window)
# Inputs held between samples by a digital controller (the common case) integrate exactly by
# the zero-order hold; "trapezoidal" leaves a 10-15 % downward bias of beta_hat on them
# (cargo xtask dither). Use "trapezoidal" for inputs that vary continuously between samples.
input_integral = "zero_order_hold"
estimator = "ordinary"  # the paper's; the calibrated certificate always uses its own
                        # instrumented estimate ("instrumented" here changes the paper's)

[ambiguity]
# The paper's Wasserstein certificate and its radius eps(t) (Section III); the values are the
# paper's. Like the Gaussian one it carries no stated risk.
enabled = true          # also compute the Wasserstein certificate
tail_window = 150       # residuals in the kurtosis and spike window (the paper's)
eps_floor = 0.015       # eps_0 (the paper's)
eps_cap = 0.32          # eps_max (the paper's)
alpha_kurtosis = 0.03   # alpha_1 (the paper's)
alpha_spike = 2.0       # alpha_2 (the paper's)
# sigma0 for the 3 sigma0 spike test: a number, or omit to calibrate it as
# 1.4826 * MAD of the first `tail_window` residuals.
# sigma0 = 0.08
residuals = "one_step"  # keeps the tail shape eps detects (the paper is silent); or "horizon"

[calibration]
# The verdict: an instrumented regression on several windows (M, 2M, 4M, ...) with a radius
# from its own uncertainty (no c); its gate opens for a controller whose true rate is below
# the margin with probability at most delta over the whole run (see the README for the
# assumptions), and its guards close it where the data contradict its model. Needs margin > 0
# and window >= h (u + 2), u = p + m + 1 (intercept) + 2p (the nonlinearity guard's fit):
# 35 for p = m = 1, h = 5. `enabled = false` is the paper-only mode: the
# paper's two certificates alone, which carry no stated risk (the summary says so).
enabled = true
delta = 0.01            # the risk of a false deployment over the whole run
# windows = 5            # M, 2M, ..., 16M (default: at least five, doubling until the
                         # longest holds 200 h: a long window makes up for the intercept)
# risk_split = "equal"   # delta / windows each, every time scale alike ("by_length": the
                         # longer windows more, the shortest less: a fast loop waits longer)
# max_window = 1200      # drop windows longer than this (default: none)
# look_spacing = 0.5     # a window looks every look_spacing * M_w columns once full
# instrument_lag = 1     # samples between the instrument's interval and the column's
# instrument_intervals = 1  # earlier intervals stacked into the instrument (>= 2: 2SLS)
# batch_blocks = 1       # blocks of h per batch of the first variance (1: every block is
                         # one; the automatic batches below take care of sensor noise)
# auto_batches = 30      # beside it, on windows long enough, the variance in about 30
                         # batches, the smaller radius standing: sensor noise needs batches,
                         # and the user need not know it (0: off)
# auto_batch_risk = 0.2  # the share of the risk the batched radius spends (the first radius
                         # the rest: quick on process noise, which is the common case)
# The guards (each on by default; closing never costs validity, only power; turning one off
# certifies plants the certificate's risk does not cover):
# hidden_dynamics = true # a window whose output's past increment predicts its next one (a
                         # hidden state: a mass measured by its position) does not stand
# nonlinearity = true    # a window whose outputs' squares and cubes predict the increment (a
                         # slope that varies over the explored region) does not stand
# guard_risk = 0.002     # risk of each of these two tests (default: delta / windows); larger
                         # closes more often, never less: fewer false openings on a nonlinear
                         # loop (it does not make them rare: use [nonlinear]), less power
# plant_change = true    # a window's look stands only while a fresh estimate on the newest
                         # data is not significantly below it (the plant changed)
# change_risk = 0.01     # risk of each such comparison (default: delta); a false one closes
                         # the gate for an eighth of the shortest window, larger closes sooner

[nonlinear]
# The calibrated certificate above assumes one Jacobian over its window. For a nonlinear
# loop (one output), enable this: a fourth certificate, the smallest rate over the region of
# outputs the window explored, for a drift polynomial in y up to `degree` (calibrated, same
# windows and delta), and a test that closes the linear calibrated gate when the dynamics
# vary over the region ("dynamics vary over the explored region"). Needs [calibration].
enabled = false
features = "polynomial"  # y, y^2, ..., y^degree; or a list such as ["y", "y*tanh(y)"]
                         # (known: y, y^2 .. y^5, tanh(y), y*tanh(y); starts with "y")
degree = 3              # cubic: the lowest odd degree whose slope varies
region = "bounding_box"  # the range of y over the window's samples (the rule built so far)
# cells = 32             # grid cells on which the minimum over the region is bounded
# test_risk = 0.01       # risk of the nonlinearity and lack-of-fit tests (default: delta)
# check_terms = 2        # lack-of-fit check: extra powers of y the library lacks (0: off);
                         # where they are significant the nonlinear gate stays closed
"#;

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
}

/// The feature library of `[nonlinear]`: `"polynomial"` (with `degree`) or a list of named
/// features starting with `"y"`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(untagged)]
enum Features {
    /// `"polynomial"`.
    Library(String),
    /// Named features, for example `["y", "y*tanh(y)"]`.
    Named(Vec<String>),
}

impl Default for Features {
    fn default() -> Self {
        Self::Library("polynomial".into())
    }
}

/// The region rules of `[nonlinear]` (one so far).
#[derive(Debug, Default, Clone, Copy, Deserialize, PartialEq)]
#[serde(rename_all = "snake_case")]
enum RegionRule {
    #[default]
    BoundingBox,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct NonlinearSection {
    #[serde(default)]
    enabled: bool,
    #[serde(default)]
    features: Features,
    #[serde(default)]
    degree: Option<usize>,
    #[serde(default)]
    #[allow(dead_code)]
    region: RegionRule,
    #[serde(default)]
    cells: Option<usize>,
    #[serde(default)]
    check_terms: Option<usize>,
    #[serde(default)]
    test_risk: Option<f64>,
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

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Certificate {
    conservatism: f64,
    margin: f64,
    consecutive: usize,
    #[serde(default)]
    gap_factor: Option<f64>,
    #[serde(default)]
    metric: Option<Vec<f64>>,
}

/// Every key may be omitted: the defaults are the ones `--print-config` shows.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct Regression {
    model: Model,
    window: usize,
    horizon: usize,
    ridge: f64,
    min_columns: Option<usize>,
    input_integral: InputIntegral,
    estimator: Estimator,
}

impl Default for Regression {
    fn default() -> Self {
        Self {
            model: Model::Affine,
            window: 150,
            horizon: 5,
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
}

/// Parse and validate a configuration text; `path` names it in errors.
///
/// # Errors
/// [`CliError::Config`] for a TOML error, an unknown key, a wrong `K` shape or an invalid
/// parameter.
pub fn parse(text: &str, path: &str) -> Result<Config, CliError> {
    let bad = |message: String| CliError::Config { path: path.to_string(), message };
    let f: File = toml::from_str(text).map_err(|e| bad(e.to_string()))?;
    let (p, m) = (f.columns.outputs.len(), f.columns.inputs.len());
    if p == 0 || m == 0 {
        return Err(bad(
            "columns.outputs and columns.inputs must each name at least one column".into()
        ));
    }
    let mut names: Vec<&String> = f.columns.outputs.iter().chain(&f.columns.inputs).collect();
    names.push(&f.columns.time);
    names.sort();
    if names.windows(2).any(|w| w[0] == w[1]) {
        return Err(bad("a column is named twice in [columns]".into()));
    }
    if f.controller.gain.len() != m || f.controller.gain.iter().any(|r| r.len() != p) {
        return Err(bad(format!(
            "controller.gain must be m × p = {m} × {p} (one row per input, one value per output), got {} rows of lengths {:?}",
            f.controller.gain.len(),
            f.controller.gain.iter().map(Vec::len).collect::<Vec<_>>()
        )));
    }
    let r = &f.regression;
    let reg = RegressionConfig {
        min_columns: r.min_columns.unwrap_or(r.window),
        input_integral: r.input_integral,
        estimator: r.estimator,
        model: r.model,
        ..RegressionConfig::new(p, m, r.window, r.horizon, r.ridge)
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
    if a.enabled {
        certifier.ambiguity = Some(AmbiguityConfig {
            tail_window: a.tail_window,
            eps_floor: a.eps_floor,
            eps_cap: a.eps_cap,
            alpha_kurtosis: a.alpha_kurtosis,
            alpha_spike: a.alpha_spike,
            spike_scale: match a.sigma0 {
                Some(sigma0) => SpikeScale::Fixed { sigma0 },
                None => SpikeScale::Calibrated { samples: a.tail_window },
            },
        });
    }
    certifier.residuals = a.residuals;
    if f.calibration.enabled {
        certifier.calibration = Some(f.calibration.calibration());
    }
    let nl = &f.nonlinear;
    if nl.enabled {
        let d = NonlinearConfig::default();
        let features = match &nl.features {
            Features::Library(name) if name == "polynomial" => None,
            Features::Library(name) => {
                return Err(bad(format!(
                    "[nonlinear] features: `{name}` is no library: use \"polynomial\" (with \
                     degree) or a list of features such as [\"y\", \"y*tanh(y)\"]"
                )));
            }
            Features::Named(names) => Some(
                FeatureSet::from_names(names)
                    .map_err(|e| bad(format!("[nonlinear] features: {e}")))?,
            ),
        };
        certifier.nonlinear = Some(NonlinearConfig {
            degree: nl.degree.unwrap_or(d.degree),
            features,
            cells: nl.cells.unwrap_or(d.cells),
            test_risk: nl.test_risk,
            check_terms: nl.check_terms.unwrap_or(d.check_terms),
        });
    }
    f.columns.delimiter_byte().map_err(&bad)?;
    // Validate everything by building a certifier once.
    Certifier::new(certifier.clone()).map_err(|e| bad(e.to_string()))?;
    Ok(Config { columns: f.columns, certifier })
}

#[cfg(test)]
mod tests;
