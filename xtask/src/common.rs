//! Parameters, seeds and small helpers shared by the experiments.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use serde::Serialize;
use streamcert_ambiguity::{AmbiguityConfig, SpikeScale};
use streamcert_certificate::{CertifierConfig, Evidence, ResidualSource};
use streamcert_dynamics::{Coupling, NoiseScaling};
use streamcert_experiments::{Experiment, G5Dataset};
use streamcert_regression::{Estimator, InputIntegral, Model, RegressionConfig};

/// Every choice the paper leaves open, with its default; each is a command-line flag.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Params {
    /// Step (Table I).
    pub(crate) dt: f64,
    /// Regression window `M` in columns (not in the paper).
    pub(crate) window: usize,
    /// Horizon `h` in samples (not in the paper).
    pub(crate) horizon: usize,
    /// Ridge `λ` (Table I).
    pub(crate) ridge: f64,
    /// Conservatism `c` of eq. rho (not in the paper).
    pub(crate) c: f64,
    /// Gate length `n_s` (not in the paper).
    pub(crate) consecutive: usize,
    /// `α_κ` (not in the paper).
    pub(crate) alpha_kurtosis: f64,
    /// `α_s` (not in the paper).
    pub(crate) alpha_spike: f64,
    /// `N_tail` (Section V-A).
    pub(crate) tail_window: usize,
    /// PRBS dither amplitude on every input during data collection (not in the paper).
    pub(crate) dither: f64,
    /// PRBS hold time in seconds.
    pub(crate) dither_hold: f64,
    /// Noise scaling with `dt` (not in the paper).
    pub(crate) noise_scaling: NoiseScaling,
    /// G5 coupling structure for Experiment 1.
    pub(crate) coupling: Coupling,
    /// Residuals that feed `ε` (not in the paper).
    pub(crate) residuals: ResidualSource,
    /// Estimator (the paper's ridge by default).
    pub(crate) estimator: Estimator,
    /// Input integral rule (the paper's trapezoid by default).
    pub(crate) input_integral: InputIntegral,
    /// Regression model: the paper's through the origin by default (the reproduction is of
    /// the paper's model; `--model affine` gives the library's default).
    pub(crate) model: Model,
    /// Experiment 2: also put the `σ` noise on subsystem A (`x1`); the paper's G5 has noise
    /// only in `x4`, and a noise-free A gives a residual of pure discretisation error.
    pub(crate) exp2_noise_on_a: bool,
    /// Number of seeds.
    pub(crate) seeds: usize,
}

impl Default for Params {
    fn default() -> Self {
        // The data-set choices are `G5Dataset::defaults`, the one place `simulate g5` reads too.
        let data = G5Dataset::defaults(Experiment::One);
        Self {
            dt: data.dt,
            window: 150,
            horizon: 5,
            ridge: 1e-4,
            c: 0.3,
            consecutive: 10,
            alpha_kurtosis: 0.03,
            alpha_spike: 2.0,
            tail_window: 150,
            dither: data.dither,
            dither_hold: data.dither_hold,
            noise_scaling: data.noise_scaling,
            coupling: data.coupling,
            residuals: ResidualSource::OneStep,
            estimator: Estimator::Ordinary,
            input_integral: InputIntegral::ZeroOrderHold,
            model: Model::ThroughOrigin,
            exp2_noise_on_a: data.noise_on_a,
            seeds: 20,
        }
    }
}

impl Params {
    /// The G5 data set of an experiment with these choices.
    pub(crate) fn dataset(&self, experiment: Experiment) -> G5Dataset {
        G5Dataset {
            experiment,
            coupling: self.coupling,
            dt: self.dt,
            dither: self.dither,
            dither_hold: self.dither_hold,
            noise_scaling: self.noise_scaling,
            noise_on_a: self.exp2_noise_on_a,
            steps: None,
            gamma: None,
        }
    }

    /// The certifier of one scalar subsystem for candidate gain `k`.
    pub(crate) fn certifier(&self, k: f64, margin: f64) -> CertifierConfig {
        let reg = RegressionConfig {
            input_integral: self.input_integral,
            estimator: self.estimator,
            model: self.model,
            ..RegressionConfig::new(1, 1, self.window, self.horizon, self.ridge)
        };
        let mut cfg = CertifierConfig::new(reg, vec![k], self.c, margin, self.consecutive);
        cfg.ambiguity = Some(AmbiguityConfig {
            alpha_kurtosis: self.alpha_kurtosis,
            alpha_spike: self.alpha_spike,
            spike_scale: SpikeScale::Calibrated { samples: self.tail_window },
            ..AmbiguityConfig::paper(self.tail_window)
        });
        cfg.residuals = self.residuals;
        cfg
    }
}

/// Seeds of one run: every random stream derives from the run seed.
pub(crate) fn seed(run: usize, stream: u64) -> u64 {
    (run as u64 + 1) * 1_000_003 + stream
}

/// Mean and sample standard deviation over the finite values.
pub(crate) fn mean_std(v: &[f64]) -> (f64, f64) {
    let f: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if f.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = f.len() as f64;
    let m = f.iter().sum::<f64>() / n;
    let s = if f.len() > 1 {
        (f.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    } else {
        0.0
    };
    (m, s)
}

/// `mean ± std` with `digits` decimals.
pub(crate) fn pm(v: &[f64], digits: usize) -> String {
    let (m, s) = mean_std(v);
    if m.is_finite() { format!("{m:.digits$} ± {s:.digits$}") } else { "n/a".into() }
}

/// Percent `mean ± std` of fractions.
pub(crate) fn pct(v: &[f64]) -> String {
    let (m, s) = mean_std(v);
    if m.is_finite() { format!("{:.0} % ± {:.0}", 100.0 * m, 100.0 * s) } else { "n/a".into() }
}

/// Median of the finite values (NaN if none).
pub(crate) fn median(v: &[f64]) -> f64 {
    let mut f: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if f.is_empty() {
        return f64::NAN;
    }
    f.sort_by(f64::total_cmp);
    let n = f.len();
    if n % 2 == 1 { f[n / 2] } else { 0.5 * (f[n / 2 - 1] + f[n / 2]) }
}

/// A Markdown table.
pub(crate) fn markdown(header: &[&str], rows: &[Vec<String>]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "| {} |", header.join(" | "));
    let _ = writeln!(s, "|{}", "---|".repeat(header.len()));
    for r in rows {
        let _ = writeln!(s, "| {} |", r.join(" | "));
    }
    s
}

/// The same table as CSV (cells quoted when they contain a comma).
pub(crate) fn csv(header: &[&str], rows: &[Vec<String>]) -> String {
    let q = |c: &str| if c.contains(',') { format!("\"{c}\"") } else { c.to_string() };
    let mut s = header.iter().map(|h| q(h)).collect::<Vec<_>>().join(",");
    s.push('\n');
    for r in rows {
        s.push_str(&r.iter().map(|c| q(c)).collect::<Vec<_>>().join(","));
        s.push('\n');
    }
    s
}

/// Write a text file, creating its directory.
pub(crate) fn write(path: &Path, text: &str) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// Write one subsystem's evidence through the command line's writer
/// ([`EvidenceWriter`](streamcert_pipeline::output::EvidenceWriter)): the columns and number format
/// of `streamcert certify`.
pub(crate) fn write_evidence(path: &Path, evidence: &[Evidence]) -> Result<()> {
    use streamcert_pipeline::output::{EvidenceWriter, Flush, Format, Header};
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let file =
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut w = EvidenceWriter::new(file, Format::Csv, Header::Write, Flush::Buffered, Vec::new())?;
    for e in evidence {
        w.write(e)?;
    }
    w.flush().with_context(|| format!("writing {}", path.display()))
}

/// A progress bar on stderr (hidden when stderr is not a terminal).
pub(crate) fn progress(len: usize, what: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len as u64);
    if let Ok(style) = indicatif::ProgressStyle::with_template("{msg:>14} [{bar:30}] {pos}/{len}") {
        bar.set_style(style);
    }
    bar.set_message(what.to_string());
    bar
}
