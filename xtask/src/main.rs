//! `cargo xtask`: the reproduction entry point of streamcert.
//!
//! Commands:
//!
//! * `reproduce`: both experiments of the paper (Tables II and III, six figures), the
//!   validity table and a sensitivity study, written with `REPORT.md` and `meta.json` to
//!   `target/reproduce` (or `--out DIR`).
//! * `exp1`, `exp2`: one experiment.
//!
//! Every choice the paper leaves open is a flag (see `USAGE`). Without a command it prints
//! the command list.

mod common;
mod exp1;
mod exp2;
mod plot;
mod reliability;
mod report;
mod validity;

use std::path::PathBuf;

use anyhow::{Context, Result, bail};

use crate::common::Params;

const USAGE: &str = "\
usage: cargo xtask <command> [options]

commands:
  reproduce      both experiments, sensitivity study, REPORT.md, meta.json
  exp1           Experiment 1 only (Table II, validity, Figs. 3-5)
  exp2           Experiment 2 only (Table III, coupled simulations, Figs. 6-8)
  validity [--runs N] [--out DIR]
                 gate-opening rates of the calibrated and the paper's certificates on
                 linear systems with known rates (VALIDITY.md, default 200 runs,
                 default DIR target/validity)

  reliability [--out DIR]
                 every bad input (damaged checkpoints, gaps, jitter, foreign CSV, bad rows
                 and values, configuration) through the streamcert binary: exit code and
                 message per case (RELIABILITY.md, default DIR target/reliability)

options (defaults in brackets; see REPORT.md for why):
  --out DIR                     output folder [target/reproduce]
  --seeds N                     seeds [20]
  --c X                         conservatism c of eq. rho [0.1]
  --window M                    regression window in columns [150]
  --horizon H                   integration horizon in samples [5]
  --consecutive N               gate length n_s [10]
  --alpha-kurtosis X            alpha_kappa of eq. eps_est [0.03]
  --alpha-spike X               alpha_s of eq. eps_est [2.0]
  --dither X                    PRBS dither amplitude [0.5]
  --dither-hold S               PRBS hold time in seconds [0.1]
  --noise-scaling S             sde | held_input | state_increment [sde]
  --coupling S                  Experiment 1 G5 coupling: cascade | bidirectional [cascade]
  --residuals S                 residuals for eps: one_step | horizon [one_step]
  --estimator S                 ordinary | instrumented [ordinary]
  --input-integral S            trapezoidal | zero_order_hold [trapezoidal]
  --exp2-noise-on-a B           Experiment 2 noise also into x1: true | false [true]
  --no-sensitivity              skip the sensitivity study
";

struct Options {
    out: PathBuf,
    params: Params,
    sensitivity: bool,
}

fn enum_arg<T: serde::de::DeserializeOwned>(flag: &str, v: &str) -> Result<T> {
    serde_json::from_value(serde_json::Value::String(v.to_string()))
        .with_context(|| format!("{flag}: unknown value `{v}`\n{USAGE}"))
}

fn parse(args: &[String]) -> Result<Options> {
    let mut o = Options {
        out: PathBuf::from("target/reproduce"),
        params: Params::default(),
        sensitivity: true,
    };
    let mut it = args.iter();
    while let Some(flag) = it.next() {
        if flag == "--no-sensitivity" {
            o.sensitivity = false;
            continue;
        }
        let v = it.next().with_context(|| format!("{flag} needs a value\n{USAGE}"))?;
        let num =
            |v: &str| v.parse::<f64>().with_context(|| format!("{flag}: not a number: `{v}`"));
        let int =
            |v: &str| v.parse::<usize>().with_context(|| format!("{flag}: not a count: `{v}`"));
        let p = &mut o.params;
        match flag.as_str() {
            "--out" => o.out = PathBuf::from(v),
            "--seeds" => p.seeds = int(v)?,
            "--c" => p.c = num(v)?,
            "--window" => p.window = int(v)?,
            "--horizon" => p.horizon = int(v)?,
            "--consecutive" => p.consecutive = int(v)?,
            "--alpha-kurtosis" => p.alpha_kurtosis = num(v)?,
            "--alpha-spike" => p.alpha_spike = num(v)?,
            "--dither" => p.dither = num(v)?,
            "--dither-hold" => p.dither_hold = num(v)?,
            "--noise-scaling" => p.noise_scaling = enum_arg(flag, v)?,
            "--coupling" => p.coupling = enum_arg(flag, v)?,
            "--residuals" => p.residuals = enum_arg(flag, v)?,
            "--estimator" => p.estimator = enum_arg(flag, v)?,
            "--input-integral" => p.input_integral = enum_arg(flag, v)?,
            "--exp2-noise-on-a" => {
                p.exp2_noise_on_a = v.parse().with_context(|| format!("{flag}: true or false"))?
            }
            other => bail!("unknown option `{other}`\n{USAGE}"),
        }
    }
    if o.params.seeds == 0 {
        bail!("--seeds must be at least 1");
    }
    Ok(o)
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(cmd) = args.first() else {
        print!("{USAGE}");
        return Ok(());
    };
    plot::init_fonts()?;
    match cmd.as_str() {
        "reproduce" => report::reproduce(&parse(&args[1..])?, true, true),
        "exp1" => report::reproduce(&parse(&args[1..])?, true, false),
        "exp2" => report::reproduce(&parse(&args[1..])?, false, true),
        "validity" => {
            let mut runs = 200;
            let mut out = PathBuf::from("target/validity");
            let mut it = args[1..].iter();
            while let Some(flag) = it.next() {
                let v = it.next().with_context(|| format!("{flag} needs a value"))?;
                match flag.as_str() {
                    "--runs" => runs = v.parse().context("--runs")?,
                    "--out" => out = PathBuf::from(v),
                    other => bail!("unknown option `{other}`\n{USAGE}"),
                }
            }
            validity::run(runs, &out)
        }
        "reliability" => {
            let out = match args.get(1).map(String::as_str) {
                Some("--out") => PathBuf::from(args.get(2).context("--out needs a value")?),
                Some(other) => bail!("unknown option `{other}`\n{USAGE}"),
                None => PathBuf::from("target/reliability"),
            };
            reliability::run_all(&out)
        }
        "help" | "--help" | "-h" => {
            print!("{USAGE}");
            Ok(())
        }
        other => bail!("unknown command `{other}`\n{USAGE}"),
    }
}
