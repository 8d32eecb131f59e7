//! The `certify` configuration file (TOML), validated before any data is read.

use serde::Deserialize;
use streamcert_ambiguity::{AmbiguityConfig, SpikeScale};
use streamcert_certificate::{
    Calibration, Certifier, CertifierConfig, FeatureSet, NonlinearConfig, ResidualSource,
};
use streamcert_regression::{Estimator, InputIntegral, Model, RegressionConfig};

use crate::CliError;

/// The commented default configuration printed by `streamcert certify --print-config`.
pub const DEFAULT_CONFIG: &str = r#"# streamcert certify configuration (TOML). Unknown keys are refused.

[columns]
# Name of the time column (seconds, strictly increasing).
time = "t"
# Measured outputs y (p columns) and applied inputs u (m columns), by header name.
outputs = ["y_b"]
inputs = ["u_b"]
# delimiter = ","       # or ";" or "tab"; quoted fields and a byte-order mark are accepted

[controller]
# Candidate gain K (m rows of p values): the controller u = K y to be certified.
gain = [[-4.0]]

[certificate]
# Conservatism c of rho = c (1 + ||K||) RMS(R) / sqrt(lambda_min(Z Z^T / M) + lambda).
# The paper gives no value; this is a required, deliberate choice.
conservatism = 0.1
# Deploy once the certificate is >= margin for `consecutive` samples.
margin = 0.05
consecutive = 10
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
window = 150            # M: columns in the sliding window
horizon = 5             # h: samples per integration interval
ridge = 1e-4            # lambda
# min_columns = 150     # warm-up (default: window)
input_integral = "trapezoidal"   # or "zero_order_hold" (exact for held inputs)
estimator = "ordinary"           # or "instrumented" (removes the process-noise bias)

[ambiguity]
enabled = true          # also compute the Wasserstein certificate
tail_window = 150
eps_floor = 0.015
eps_cap = 0.32
alpha_kurtosis = 0.03
alpha_spike = 2.0
# sigma0 for the 3 sigma0 spike test: a number, or omit to calibrate it as
# 1.4826 * MAD of the first `tail_window` residuals.
# sigma0 = 0.08
residuals = "one_step"  # or "horizon"

[calibration]
# A third certificate beside the paper's two: an instrumented regression on several windows
# (M, 2M, 4M, ...) with a radius from its own uncertainty (no c); its gate opens for a
# controller whose true rate is below the margin with probability at most delta over the whole
# run (see the README for the assumptions). Needs margin > 0 and window >= h (p + m + 3)
# (h (p + m + 2) with model = "through_origin").
enabled = false
delta = 0.01
# windows = 4            # M, 2M, 4M, 8M (default: doubling until the longest holds 200 h)
# max_window = 1200      # drop windows longer than this (default: none)
# look_spacing = 0.5     # a window looks every look_spacing * M_w columns once full
# instrument_lag = 1     # samples between the instrument's interval and the column's
# instrument_intervals = 1  # earlier intervals stacked into the instrument (>= 2: 2SLS)
# batch_blocks = 1       # blocks of h per batch of the variance (4 or 8 with sensor noise)
# hidden_dynamics = true # the model-order guard: a window whose output's past increment
                         # predicts its next one (a hidden state: a mass measured by its
                         # position) does not stand; false certifies on the first-order
                         # model without checking it

[nonlinear]
# The calibrated certificate above assumes one Jacobian over its window. For a nonlinear
# loop (one output), enable this: a fourth certificate, the smallest rate over the region of
# outputs the window explored, for a drift polynomial in y up to `degree` (calibrated, same
# windows and delta), and a test that closes the linear calibrated gate when the dynamics
# vary over the region ("dynamics vary over the explored region"). Needs [calibration].
enabled = false
features = "polynomial"  # y, y^2, ..., y^degree; or a list such as ["y", "y*tanh(y)"]
                         # (known: y, y^2 .. y^5, tanh(y), y*tanh(y); starts with "y")
degree = 3
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
    hidden_dynamics: Option<bool>,
}

fn default_delta() -> f64 {
    0.01
}

impl Default for CalibrationSection {
    fn default() -> Self {
        Self {
            enabled: false,
            delta: default_delta(),
            windows: None,
            max_window: None,
            look_spacing: None,
            instrument_lag: None,
            instrument_intervals: None,
            batch_blocks: None,
            hidden_dynamics: None,
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
            hidden_dynamics: self.hidden_dynamics.unwrap_or(d.hidden_dynamics),
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
            input_integral: InputIntegral::Trapezoidal,
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
mod tests {
    use super::*;

    #[test]
    fn default_config_parses() {
        let c = parse(DEFAULT_CONFIG, "default").unwrap();
        assert_eq!(c.certifier.gain, vec![-4.0]);
        assert!(c.certifier.ambiguity.is_some());
    }

    #[test]
    fn bad_configs_are_refused() {
        let unknown = DEFAULT_CONFIG.replace("margin = 0.05", "margin = 0.05\nmargn = 1");
        assert!(parse(&unknown, "x").unwrap_err().to_string().contains("margn"));
        let shape = DEFAULT_CONFIG.replace("gain = [[-4.0]]", "gain = [[-4.0, 1.0]]");
        assert!(parse(&shape, "x").unwrap_err().to_string().contains("m × p"));
        let invalid = DEFAULT_CONFIG.replace("conservatism = 0.1", "conservatism = -1.0");
        assert!(parse(&invalid, "x").unwrap_err().to_string().contains("conservatism"));
        let risk =
            DEFAULT_CONFIG.replace("enabled = false\ndelta = 0.01", "enabled = true\ndelta = 1.5");
        assert!(parse(&risk, "x").unwrap_err().to_string().contains("delta"));
    }

    #[test]
    fn keys_with_documented_defaults_may_be_omitted() {
        let full = parse(DEFAULT_CONFIG, "default").unwrap();
        let start = DEFAULT_CONFIG.find("[ambiguity]").unwrap();
        let end = DEFAULT_CONFIG.find("[calibration]").unwrap();
        let short = format!(
            "{}[ambiguity]\nenabled = true\n\n{}",
            &DEFAULT_CONFIG[..start],
            &DEFAULT_CONFIG[end..]
        );
        let short = short.replace("window = 150 ", "# window = 150 ");
        let parsed = parse(&short, "short").unwrap();
        assert_eq!(parsed.certifier, full.certifier);
    }

    #[test]
    fn calibration_section_selects_the_calibrated_certificate() {
        assert_eq!(parse(DEFAULT_CONFIG, "default").unwrap().certifier.calibration, None);
        let on =
            DEFAULT_CONFIG.replace("enabled = false\ndelta = 0.01", "enabled = true\ndelta = 0.05");
        let c = parse(&on, "x").unwrap();
        assert_eq!(c.certifier.calibration, Some(Calibration::new(0.05)));
        let tuned = on.replace("# windows = 4 ", "windows = 2 ");
        let c = parse(&tuned, "x").unwrap();
        assert_eq!(c.certifier.calibration.map(|c| c.windows), Some(Some(2)));
        let batched = on.replace("# batch_blocks = 1 ", "batch_blocks = 4 ");
        let c = parse(&batched, "x").unwrap().certifier.calibration.unwrap();
        assert_eq!(c.batch_blocks, 4);
        // A window below h (p + m + 3) (the affine model's intercept is one more unknown) has
        // no calibrated bound: refused, naming the smallest; h (p + m + 2) through the origin.
        let short = on.replace("window = 150 ", "window = 10 ");
        assert!(
            parse(&short, "x").unwrap_err().to_string().contains("smallest valid window is 25")
        );
        let origin = short.replace("model = \"affine\"", "model = \"through_origin\"");
        let err = parse(&origin, "x").unwrap_err().to_string();
        assert!(err.contains("smallest valid window is 20"), "{err}");
        let zero_margin = on.replace("margin = 0.05", "margin = 0.0");
        assert!(parse(&zero_margin, "x").unwrap_err().to_string().contains("margin"));
    }

    #[test]
    fn nonlinear_section_selects_the_nonlinear_certificate() {
        let nl = "enabled = false\nfeatures";
        let on = DEFAULT_CONFIG.replace(nl, "enabled = true\nfeatures");
        // Without a calibration the nonlinear certificate is refused, saying what to set.
        let err = parse(&on, "x").unwrap_err().to_string();
        assert!(err.contains("needs a calibration"), "{err}");
        let both = on.replace("enabled = false\ndelta = 0.01", "enabled = true\ndelta = 0.01");
        let c = parse(&both, "x").unwrap();
        assert_eq!(c.certifier.nonlinear, Some(NonlinearConfig::default()));
        let deg = both.replace("degree = 3", "degree = 2").replace("# cells = 32 ", "cells = 8 ");
        let c = parse(&deg, "x").unwrap().certifier.nonlinear.unwrap();
        assert_eq!((c.degree, c.cells, c.check_terms), (2, 8, 2));
        let off = both.replace("# check_terms = 2 ", "check_terms = 0 ");
        assert_eq!(parse(&off, "x").unwrap().certifier.nonlinear.unwrap().check_terms, 0);
        let many = both.replace("# check_terms = 2 ", "check_terms = 9 ");
        assert!(parse(&many, "x").unwrap_err().to_string().contains("check_terms"));
        let unknown = both.replace("features = \"polynomial\"", "features = \"splines\"");
        assert!(parse(&unknown, "x").unwrap_err().to_string().contains("splines"));
        let named = both.replace("features = \"polynomial\"", "features = [\"y\", \"y*tanh(y)\"]");
        let c = parse(&named, "x").unwrap().certifier.nonlinear.unwrap();
        assert_eq!(c.library(), FeatureSet::from_names(&["y", "y*tanh(y)"]).unwrap());
        let first = both.replace("features = \"polynomial\"", "features = [\"tanh(y)\"]");
        assert!(parse(&first, "x").unwrap_err().to_string().contains("start with `y`"));
    }
}
