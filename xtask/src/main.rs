//! `cargo xtask`: the reproduction entry point of streamcert.
//!
//! Commands:
//!
//! * `reproduce [--out DIR] [--seed S]`: simulate the G5 benchmark (paper Section II-D) under
//!   Experiment 1's disturbance schedule (both coupling structures) and Experiment 2's
//!   disconnected data collection, and write the trajectories as CSV with a `meta.json`.
//!   The certificate experiments (Tables II and III) are added as their crates land.
//!
//! Without a command it prints this list.

mod simulate_g5;

use anyhow::{Context, Result, bail};
use std::path::PathBuf;

const USAGE: &str = "\
usage: cargo xtask <command> [options]

commands:
  reproduce [--out DIR] [--seed S]   simulate G5 (Experiments 1 and 2 data) and write CSV
                                     trajectories and meta.json (default DIR: target/reproduce)
";

/// Options shared by the commands.
#[derive(Debug)]
struct Options {
    out: PathBuf,
    seed: u64,
}

fn parse(args: &[String]) -> Result<Options> {
    let mut opts = Options { out: PathBuf::from("target/reproduce"), seed: 1 };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--out" => opts.out = PathBuf::from(it.next().context("--out needs a directory")?),
            "--seed" => {
                opts.seed = it.next().context("--seed needs a value")?.parse().context("--seed")?;
            }
            other => bail!("unknown option `{other}`\n{USAGE}"),
        }
    }
    Ok(opts)
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(cmd) = args.first() else {
        print!("{USAGE}");
        return Ok(());
    };
    match cmd.as_str() {
        "reproduce" => simulate_g5::run(&parse(&args[1..])?),
        "help" | "--help" | "-h" => {
            print!("{USAGE}");
            Ok(())
        }
        other => bail!("unknown command `{other}`\n{USAGE}"),
    }
}
