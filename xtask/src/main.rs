//! `cargo xtask`: the reproduction entry point of streamcert.
//!
//! Commands:
//!
//! * `reproduce`: both experiments of the paper (Tables II and III, six figures), the
//!   validity table and a sensitivity study, written with `REPORT.md` and `meta.json` to
//!   `target/reproduce` (or `--out DIR`).
//! * `exp1`, `exp2`: one experiment.
//! * `validity`: the calibrated certificate at the boundary (VALIDITY.md).
//! * `nonlinear`: the paper's, the linear calibrated and the nonlinear certificates against
//!   the true rate over their regions on scalar nonlinear loops (NONLINEAR.md).
//! * `network`: the live network certificate of up to 10⁴ subsystems against the true
//!   network rate (NETWORK.md).
//! * `sites`: the network service across timely processes: bytes that cross per epoch against
//!   the raw-sample path, and throughput against one-process `push_batch` (NETWORK.md,
//!   BENCHMARKS.md).
//! * `soak`: three `streamcert` processes under faults (two kills and restarts, a clock step,
//!   a burst of malformed rows) against the one-process run (NETWORK.md).
//! * `reliability`: bad inputs through the binary (RELIABILITY.md).
//!
//! The command line is clap's: `cargo xtask --help`, `cargo xtask reproduce --help`. Every
//! choice the paper leaves open is a flag whose default is `Params::default()`, the one
//! place it is set. Without a command it prints the help.

mod common;
mod coupling;
mod dither;
mod exp1;
mod exp2;
mod network;
mod nonlinear;
use streamcert_plot as plot;
mod real;
mod reliability;
mod report;
mod sensitivity;
mod sites;
mod soak;
mod validity;

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};

use crate::common::Params;

/// `cargo xtask`: reproduce the paper's experiments, measure the calibrated certificate's
/// validity, and tabulate the command line's answers to bad input.
#[derive(Parser)]
#[command(name = "cargo xtask", bin_name = "cargo xtask", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Both experiments, the sensitivity study, REPORT.md and meta.json.
    Reproduce(Run),
    /// Experiment 1 only (Table II, validity, Figs. 3-5).
    Exp1(Run),
    /// Experiment 2 only (Table III, coupled simulations, Figs. 6-8).
    Exp2(Run),
    /// The calibrated certificate's false-opening rate at the boundary, its power and its
    /// reaction to a plant change, with the paper's certificate on the same runs
    /// (VALIDITY.md).
    Validity {
        /// Runs per near-margin cell (a fifth of them, at least 50, per power cell).
        #[arg(long, default_value_t = 200)]
        runs: usize,
        /// Output folder.
        #[arg(long, default_value = "target/validity")]
        out: PathBuf,
        /// Only the plant-change table (steps and slow drifts), with this many runs per
        /// cell, written to CHANGE.md.
        #[arg(long)]
        only_change: Option<usize>,
        /// Only the held-input and units families, with this many runs per unsafe cell (a
        /// fifth, at least 50, per contracting one), written to HELD.md.
        #[arg(long)]
        only_held: Option<usize>,
        /// Only the power table (contracting candidates), with this many runs per cell,
        /// written to POWER.md.
        #[arg(long)]
        only_power: Option<usize>,
        /// Only the certificate of order n (`[regression] order = 2 | 3`): loops measured
        /// through one output with hidden states, with this many runs per near-margin cell
        /// (at most 200 per cell beyond the order, a fifth, 20 to 400, per power cell, a
        /// tenth, 20 to 200, after a plant change), written to ORDER.md.
        #[arg(long)]
        only_order: Option<usize>,
        /// The calibrated certificate's horizon in the default cells: `fixed` (h = 5, the
        /// default) or `auto` (the horizon ladder of `horizon = "auto"`: h = 1, 2, 5, 10,
        /// `M / 5` blocks of h columns per base window, δ/4 each), on the same seeds.
        #[arg(long, default_value = "fixed", value_parser = ["fixed", "auto"])]
        horizon: String,
    },
    /// The two public plant records of examples/real/ (the heat exchanger and the cascaded
    /// tanks), checked by SHA-256, converted, certified, and the exchanger compared in °C
    /// and in K (REAL.md).
    Real {
        /// Folder holding the originals `exchanger.csv` and `tanque.csv` (see
        /// examples/real/README.md): check their hashes and that converting them gives the
        /// committed records.
        #[arg(long)]
        from: Option<PathBuf>,
        /// Output folder.
        #[arg(long, default_value = "target/real")]
        out: PathBuf,
    },
    /// The paper's, the linear calibrated and the nonlinear certificates on the same runs of
    /// scalar nonlinear loops, against the smallest true rate over each one's region
    /// (NONLINEAR.md).
    Nonlinear {
        /// Runs per validity cell (a fifth of them, at least min(runs, 20), per power cell).
        #[arg(long, default_value_t = 500)]
        runs: usize,
        /// Only the cells whose name contains this text (for example `G5`); each cell keeps
        /// its seeds, so its rows equal the full study's.
        #[arg(long)]
        only: Option<String>,
        /// The nonlinear certificates' split of δ over the windows: `equal`, `by_length` or
        /// `by_length_squared` (default: the certificate's own, `by_length_squared`).
        #[arg(long, value_parser = parse_split)]
        split: Option<streamcert_certificate::RiskSplit>,
        /// Output folder.
        #[arg(long, default_value = "target/nonlinear")]
        out: PathBuf,
    },
    /// The live network certificate of many scalar subsystems on a sparse random graph
    /// against the true network rate, just below and well above the margin (NETWORK.md).
    Network {
        /// Subsystems per run.
        #[arg(long, default_value_t = 10_000)]
        subsystems: usize,
        /// Runs per target.
        #[arg(long, default_value_t = 10)]
        runs: usize,
        /// Runs per cell of the coupling-bound coverage study.
        #[arg(long, default_value_t = 1000)]
        coupling_runs: usize,
        /// Threads of `push_batch`.
        #[arg(long, default_value_t = 2)]
        threads: usize,
        /// Output folder.
        #[arg(long, default_value = "target/network")]
        out: PathBuf,
    },
    /// The network service across timely processes (threads here, TCP on localhost): bytes
    /// across process boundaries per epoch against the raw-sample path, and samples per
    /// second against one-process `push_batch` (NETWORK.md, BENCHMARKS.md).
    Sites(sites::Options),
    /// Three `streamcert network` processes on localhost under faults (SIGKILL and restart of
    /// two processes, a clock step at one site, malformed rows at another) against the
    /// one-process run over the same rows; peak memory per process (NETWORK.md).
    Soak {
        /// Subsystems (placed round-robin on the 3 processes).
        #[arg(long, default_value_t = 1000)]
        subsystems: usize,
        /// Steps of 10 ms per subsystem.
        #[arg(long, default_value_t = 10_000)]
        steps: usize,
        /// Output folder.
        #[arg(long, default_value = "target/soak")]
        out: PathBuf,
    },
    /// Every bad input through the streamcert binary: exit code and message per case
    /// (RELIABILITY.md).
    Reliability {
        /// Output folder.
        #[arg(long, default_value = "target/reliability")]
        out: PathBuf,
    },
}

/// The serde name of a unit enum variant (`sde`, `cascade`, …), the spelling of its flag.
fn name<T: serde::Serialize>(v: &T) -> String {
    serde_json::to_value(v).ok().and_then(|v| v.as_str().map(str::to_string)).unwrap_or_default()
}

/// Every choice the paper leaves open; the defaults are `Params::default()` (see REPORT.md
/// for why).
#[derive(Args)]
struct Run {
    /// Output folder.
    #[arg(long, default_value = "target/reproduce")]
    out: PathBuf,
    /// Seeds.
    #[arg(long, default_value_t = Params::default().seeds)]
    seeds: usize,
    /// Conservatism c of eq. rho.
    #[arg(long, default_value_t = Params::default().c)]
    c: f64,
    /// Regression window M in columns.
    #[arg(long, default_value_t = Params::default().window)]
    window: usize,
    /// Integration horizon h in samples.
    #[arg(long, default_value_t = Params::default().horizon)]
    horizon: usize,
    /// Gate length n_s.
    #[arg(long, default_value_t = Params::default().consecutive)]
    consecutive: usize,
    /// alpha_kappa of eq. eps_est.
    #[arg(long, default_value_t = Params::default().alpha_kurtosis)]
    alpha_kurtosis: f64,
    /// alpha_s of eq. eps_est.
    #[arg(long, default_value_t = Params::default().alpha_spike)]
    alpha_spike: f64,
    /// PRBS dither amplitude.
    #[arg(long, default_value_t = Params::default().dither)]
    dither: f64,
    /// PRBS hold time in seconds.
    #[arg(long, default_value_t = Params::default().dither_hold)]
    dither_hold: f64,
    /// Noise scaling with dt: sde | held_input | state_increment.
    #[arg(long, default_value_t = name(&Params::default().noise_scaling))]
    noise_scaling: String,
    /// Experiment 1 G5 coupling: cascade | bidirectional.
    #[arg(long, default_value_t = name(&Params::default().coupling))]
    coupling: String,
    /// Residuals for eps: one_step | horizon.
    #[arg(long, default_value_t = name(&Params::default().residuals))]
    residuals: String,
    /// Estimator: ordinary | instrumented.
    #[arg(long, default_value_t = name(&Params::default().estimator))]
    estimator: String,
    /// Input integral: trapezoidal | zero_order_hold.
    #[arg(long, default_value_t = name(&Params::default().input_integral))]
    input_integral: String,
    /// Regression model: through_origin (the paper's eq. regressor) | affine (an intercept
    /// beside the dynamics, the library's and the command line's default).
    #[arg(long, default_value_t = name(&Params::default().model))]
    model: String,
    /// Experiment 2: noise also into x1.
    #[arg(long, default_value_t = Params::default().exp2_noise_on_a, action = clap::ArgAction::Set)]
    exp2_noise_on_a: bool,
    /// Skip the sensitivity study.
    #[arg(long)]
    no_sensitivity: bool,
}

struct Options {
    out: PathBuf,
    params: Params,
    sensitivity: bool,
}

fn enum_arg<T: serde::de::DeserializeOwned>(flag: &str, v: &str) -> Result<T> {
    serde_json::from_value(serde_json::Value::String(v.to_string()))
        .with_context(|| format!("--{flag}: unknown value `{v}` (see --help)"))
}

impl Run {
    fn options(self) -> Result<Options> {
        if self.seeds == 0 {
            bail!("--seeds must be at least 1");
        }
        let params = Params {
            seeds: self.seeds,
            c: self.c,
            window: self.window,
            horizon: self.horizon,
            consecutive: self.consecutive,
            alpha_kurtosis: self.alpha_kurtosis,
            alpha_spike: self.alpha_spike,
            dither: self.dither,
            dither_hold: self.dither_hold,
            noise_scaling: enum_arg("noise-scaling", &self.noise_scaling)?,
            coupling: enum_arg("coupling", &self.coupling)?,
            residuals: enum_arg("residuals", &self.residuals)?,
            estimator: enum_arg("estimator", &self.estimator)?,
            input_integral: enum_arg("input-integral", &self.input_integral)?,
            model: enum_arg("model", &self.model)?,
            exp2_noise_on_a: self.exp2_noise_on_a,
            ..Params::default()
        };
        Ok(Options { out: self.out, params, sensitivity: !self.no_sensitivity })
    }
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    let Some(command) = cli.command else {
        use clap::CommandFactory;
        Cli::command().print_help()?;
        return Ok(());
    };
    plot::init_fonts()?;
    if let Command::Validity { horizon, .. } = &command {
        validity::set_horizon_auto(horizon == "auto");
    }
    match command {
        Command::Reproduce(run) => report::reproduce(&run.options()?, true, true),
        Command::Exp1(run) => report::reproduce(&run.options()?, true, false),
        Command::Exp2(run) => report::reproduce(&run.options()?, false, true),
        Command::Validity { out, only_order: Some(runs), .. } => validity::order_only(runs, &out),
        Command::Validity { out, only_held: Some(runs), .. } => validity::held_only(runs, &out),
        Command::Validity { out, only_power: Some(runs), .. } => validity::power_only(runs, &out),
        Command::Validity { runs, out, only_change: None, .. } => validity::run(runs, &out),
        Command::Validity { out, only_change: Some(runs), .. } => validity::change_only(runs, &out),
        Command::Real { from, out } => real::run(from.as_deref(), &out),
        Command::Nonlinear { runs, only, split, out } => {
            nonlinear::run(runs, only.as_deref(), split, &out)
        }
        Command::Network { subsystems, runs, coupling_runs, threads, out } => {
            network::run(subsystems, runs, coupling_runs, threads, &out)
        }
        Command::Sites(options) => sites::run(&options),
        Command::Soak { subsystems, steps, out } => soak::run(subsystems, steps, &out),
        Command::Reliability { out } => reliability::run_all(&out),
    }
}

/// A risk split by its configuration name (`equal`, `by_length`, `by_length_squared`).
fn parse_split(name: &str) -> Result<streamcert_certificate::RiskSplit, String> {
    serde_json::from_value(serde_json::Value::String(name.into()))
        .map_err(|_| format!("`{name}`: use equal, by_length or by_length_squared"))
}
