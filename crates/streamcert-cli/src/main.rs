//! The `streamcert` binary: argument parsing and exit codes; the work is in the library.

use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};
use streamcert_dynamics::Coupling;
use streamcert_experiments::Experiment;
use streamcert_pipeline::{CliError, certify, compose, simulate};

mod commands;
mod ops;
use commands::{run_certify, run_network};

/// Decide from streaming sensor data whether a feedback controller may be deployed, and
/// whether a coupled network of certified subsystems stays contracting.
///
/// Exit codes: 0 success, 2 invalid command line or configuration, 3 malformed input data,
/// 4 I/O failure, 5 checkpoint failure, 6 not certified at the end of the input (only with
/// --require-certified).
/// The exit codes, listed in every `--help`.
const EXIT_CODES: &str = "Exit codes: 0 success, 2 invalid command line or configuration \
     (nothing was read), 3 malformed input data, 4 I/O failure, 5 checkpoint failure, 6 not \
     certified at the end of the input (only with --require-certified).";

#[derive(Parser)]
#[command(
    name = "streamcert",
    version,
    about,
    long_about = None,
    after_help = EXIT_CODES
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Certify a candidate gain K from (t, y, u) samples: one output row per sample.
    ///
    /// Reads CSV with a header (columns named in the configuration), line by line, and writes
    /// t, beta_hat, rho, eps, kurtosis, spike_fraction, cert_gauss, cert_wass, the gates
    /// (0/1) and the reasons when not certified, then the calibrated certificate's columns.
    /// From a live input (a pipe or a terminal on stdin) every row is flushed as it is
    /// written, so `tail -f plant.csv | streamcert certify --config c.toml` works live. With a
    /// [source] section in the configuration it reads an MQTT broker or an OPC UA server
    /// instead (docs/live.md).
    /// A summary goes to stderr (or to --summary FILE as JSON).
    #[command(
        after_help = EXIT_CODES,
        override_usage = "streamcert certify --config <CONFIG> [--input <FILE>] [OPTIONS]\n       \
                          streamcert certify --print-config"
    )]
    Certify {
        #[command(flatten)]
        io: Stream,
        /// Malformed rows: stop (exit 3) or skip and count them.
        #[arg(long, value_enum, default_value_t = certify::BadRows::Stop)]
        on_bad_row: certify::BadRows,
        #[command(flatten)]
        persist: Persist,
        /// Write the summary as JSON to FILE instead of text on stderr.
        #[arg(long)]
        summary: Option<PathBuf>,
        #[command(flatten)]
        require: Require,
        /// Draw a picture of the run into FILE (.png or .svg): the rate with the calibrated
        /// band and the margin, the certificates, the gates, eps, and why the calibrated gate
        /// was closed.
        #[arg(long, value_name = "FILE")]
        plot: Option<PathBuf>,
        #[command(flatten)]
        ops: ops::Ops,
    },
    /// Compose local contraction rates and coupling bounds into a network certificate.
    #[command(after_help = EXIT_CODES)]
    Compose {
        /// Local rates beta_i, one per subsystem (whitespace, comma or newline separated).
        #[arg(long)]
        rates: PathBuf,
        /// Coupling bounds gamma_ij (how subsystem j drives subsystem i).
        #[arg(long)]
        gains: PathBuf,
        /// Layout of the gains file.
        #[arg(long, value_enum, default_value_t = compose::GainsFormat::Dense)]
        gains_format: compose::GainsFormat,
        /// Computation.
        #[arg(long, value_enum, default_value_t = compose::Method::Auto)]
        method: compose::Method,
        /// JSON output.
        #[arg(long)]
        json: bool,
    },
    /// Certify a network live: every subsystem's columns of one wide CSV (as `simulate g5`
    /// writes), one certifier per subsystem, the network composed with the coupling bounds at
    /// every epoch. One output row per epoch: network rate, certified, gate, critical coupling
    /// scale, the limiting subsystem and coupling, the subsystems not certified and why, and
    /// each local certificate. A summary goes to stderr (or to --summary FILE as JSON).
    #[command(
        after_help = EXIT_CODES,
        override_usage = "streamcert network --config <CONFIG> [--input <FILE>] [OPTIONS]\n       \
                          streamcert network --print-config"
    )]
    Network {
        #[command(flatten)]
        io: Stream,
        #[command(flatten)]
        persist: Persist,
        /// Write the summary as JSON to FILE instead of text on stderr (process 0 of a run
        /// over several processes).
        #[arg(long)]
        summary: Option<PathBuf>,
        #[command(flatten)]
        cluster: ClusterArgs,
        #[command(flatten)]
        require: Require,
        /// Draw a picture of the run into FILE (.png or .svg; one-process runs): the network
        /// rate, the local certificates, the network gate and the subsystems not certified.
        #[arg(long, value_name = "FILE")]
        plot: Option<PathBuf>,
        #[command(flatten)]
        ops: ops::Ops,
    },
    /// Simulate a benchmark and write it in the CSV layout certify reads.
    Simulate {
        #[command(subcommand)]
        system: SimSystem,
    },
}

/// Run `network` on timely-dataflow with timely's process configuration: every process reads
/// its own `--input` (the subsystems whose `[[subsystem]] process` is its index) and sends
/// process 0 their epoch snapshots; process 0 composes and writes the output (the rows of a
/// one-process run over the sites' rows merged in time order). Every process is started with
/// the same configuration.
#[derive(clap::Args)]
struct ClusterArgs {
    /// Worker threads per process (timely's -w).
    #[arg(long)]
    workers: Option<usize>,
    /// Number of processes (timely's -n).
    #[arg(long)]
    processes: Option<usize>,
    /// This process's index, 0 to processes - 1 (timely's -p).
    #[arg(long)]
    process: Option<usize>,
    /// A file of one host:port per process, in process order (timely's -h; default
    /// localhost:2101, localhost:2102, ...).
    #[arg(long)]
    hostfile: Option<PathBuf>,
    /// Seconds of wall-clock silence of this process's (live) input after which its clock
    /// advances by the time elapsed since its last row, so that its subsystems turn stale
    /// (`stale_after`) instead of holding every epoch back. Default: wait for the input.
    #[arg(long)]
    silence: Option<f64>,
    /// With --checkpoint: every process checkpoints every N epochs (default 1).
    #[arg(long, value_name = "N")]
    checkpoint_epochs: Option<u64>,
}

/// For scripts: the exit status says whether the verdict at the end is "certified".
#[derive(clap::Args)]
struct Require {
    /// Exit with code 6 (after writing every output) when the gate is not open at the end of
    /// the input: the calibrated gate for `certify` (the Gaussian gate in the paper-only
    /// mode), the network gate for `network`. A commissioning script can stop on it.
    #[arg(long)]
    require_certified: bool,
}

/// The exit code of a run whose verdict at the end is not "certified" under
/// `--require-certified`.
const NOT_CERTIFIED_EXIT: u8 = 6;

/// Checkpoint and resume of the streaming commands.
#[derive(clap::Args)]
struct Persist {
    /// Write the whole streaming state to FILE at the end (and every --checkpoint-every rows).
    #[arg(long)]
    checkpoint: Option<PathBuf>,
    /// Checkpoint period in input rows.
    #[arg(long)]
    checkpoint_every: Option<u64>,
    /// Resume from a checkpoint; rows at the start of the input up to its last time are
    /// passed over and the output has no header, so the two outputs concatenate to the
    /// output of one run.
    #[arg(long)]
    resume: Option<PathBuf>,
}

/// Configuration, input and output of the streaming commands (`certify`, `network`).
#[derive(clap::Args)]
struct Stream {
    /// Required (unless --print-config): the configuration (TOML), with your columns, gain
    /// and margin; --print-config writes the template.
    #[arg(long, required_unless_present = "print_config")]
    config: Option<PathBuf>,
    /// Print the commented configuration template and exit.
    #[arg(long)]
    print_config: bool,
    /// Input CSV file, or - for stdin.
    #[arg(long, default_value = "-")]
    input: String,
    /// Output file, or - for stdout.
    #[arg(long, default_value = "-")]
    output: String,
    /// Output format.
    #[arg(long, value_enum, default_value_t = certify::Format::Csv)]
    format: certify::Format,
    /// Flush every output row as soon as it is written. This is automatic when the input is
    /// live (stdin from a pipe or a terminal); from a file, output is buffered.
    #[arg(long)]
    flush_each_row: bool,
}

impl Stream {
    /// The configuration file's path and text (`--config` is required unless
    /// `--print-config`).
    fn config_text(&self) -> Result<(String, String), CliError> {
        let path = self.config.as_ref().ok_or_else(|| CliError::Config {
            path: "-".into(),
            message: "--config is required".into(),
        })?;
        let text = std::fs::read_to_string(path).map_err(|e| CliError::Config {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        Ok((path.display().to_string(), text))
    }

    /// Flush per row: asked for, or a live input.
    fn flush(&self) -> certify::Flush {
        if self.flush_each_row || input_is_live(&self.input) {
            certify::Flush::EachRow
        } else {
            certify::Flush::Buffered
        }
    }
}

#[derive(Subcommand)]
enum SimSystem {
    /// The paper's five-node network G5 under its candidate gains plus PRBS dither.
    G5 {
        /// Which experiment's data set (1: three disturbance regimes, 30 s; 2: disconnected, 16 s).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=2))]
        experiment: u8,
        /// Run number: the data of `cargo xtask reproduce` run SEED (0-based).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Coupling structure.
        #[arg(long, value_enum, default_value_t = CouplingArg::Cascade)]
        coupling: CouplingArg,
        /// Number of steps instead of the experiment's (for long test files).
        #[arg(long)]
        steps: Option<usize>,
        /// Coupling gain γ instead of the experiment's (1: 0.15, 2: 0).
        #[arg(long)]
        gamma: Option<f64>,
        #[command(flatten)]
        publish: Publish,
    },
}

/// A live plant: the simulated rows published to an MQTT broker, or served by an OPC UA
/// server, instead of written out.
#[derive(clap::Args)]
#[command(group = clap::ArgGroup::new("live").args(["publish", "opcua"]))]
pub(crate) struct Publish {
    /// Publish to mqtt://HOST:PORT/TOPIC (QoS 1): a JSON object per row with every column,
    /// or with --per-signal each column on TOPIC/COLUMN as {"t": ..., "value": ...}.
    #[arg(long, value_name = "URL")]
    publish: Option<String>,
    /// Serve the plant at opc.tcp://HOST:PORT: one variable per column (ns of
    /// urn:streamcert:simulated-plant:signals, string ids: the column names), each sample
    /// written with its source timestamp (the simulation's time, from the Unix epoch); the
    /// run starts when a client first monitors the nodes.
    #[arg(long, value_name = "URL", conflicts_with = "publish")]
    opcua: Option<String>,
    /// The OPC UA server's PKI directory (its certificate and key are created there on first
    /// start; `own/cert.der` is the certificate a client trusts).
    #[arg(long, value_name = "DIR", default_value = "pki-plant", requires = "opcua")]
    pki: PathBuf,
    /// One topic per column instead of one row per message.
    #[arg(long, requires = "publish")]
    per_signal: bool,
    /// Wall-clock seconds per second of data (1: real time; 0: as fast as the broker or the
    /// server takes them).
    #[arg(long, default_value_t = 1.0, requires = "live")]
    pace: f64,
    /// Serve an embedded MQTT broker at the URL's address first (to try a live run without a
    /// broker installed); it keeps serving after the last row until the process is stopped.
    #[arg(long, requires = "publish")]
    broker: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum CouplingArg {
    Cascade,
    Bidirectional,
}

fn open_input(name: &str) -> Result<Box<dyn BufRead + Send>, CliError> {
    if name == "-" {
        Ok(Box::new(BufReader::new(std::io::stdin())))
    } else {
        let f =
            std::fs::File::open(name).map_err(|e| CliError::io(format!("opening {name}"), e))?;
        Ok(Box::new(BufReader::new(f)))
    }
}

/// Whether the input is live: stdin that is not a regular file (a pipe, a terminal, a
/// socket). Rows are then flushed one by one.
fn input_is_live(name: &str) -> bool {
    name == "-" && !std::fs::metadata("/dev/stdin").is_ok_and(|m| m.is_file())
}

fn open_output(name: &str) -> Result<Box<dyn Write>, CliError> {
    if name == "-" {
        Ok(Box::new(std::io::stdout()))
    } else {
        let f =
            std::fs::File::create(name).map_err(|e| CliError::io(format!("creating {name}"), e))?;
        Ok(Box::new(BufWriter::new(f)))
    }
}

fn read(path: &PathBuf) -> Result<String, CliError> {
    std::fs::read_to_string(path)
        .map_err(|e| CliError::io(format!("reading {}", path.display()), e))
}

/// What a successful run says about the verdict at the end.
enum Outcome {
    /// Done (no verdict asked for, or certified).
    Done,
    /// `--require-certified` and the gate is not open at the end.
    NotCertified,
}

fn run(cli: Cli) -> Result<Outcome, CliError> {
    match cli.command {
        Command::Certify { io, on_bad_row, persist, summary, require, plot, ops } => {
            run_certify(io, on_bad_row, persist, summary, require, plot, &ops)
        }
        Command::Network { io, persist, summary, cluster, require, plot, ops } => {
            run_network(io, persist, summary, cluster, require, plot, &ops)
        }
        Command::Compose { rates, gains, gains_format, method, json } => {
            let text = compose::run(
                &read(&rates)?,
                &rates.display().to_string(),
                &read(&gains)?,
                &gains.display().to_string(),
                gains_format,
                method,
                if json { compose::Render::Json } else { compose::Render::Text },
            )?;
            print!("{text}");
            Ok(Outcome::Done)
        }
        Command::Simulate {
            system: SimSystem::G5 { experiment, seed, coupling, steps, gamma, publish },
        } => {
            let experiment = if experiment == 1 { Experiment::One } else { Experiment::Two };
            let coupling = match coupling {
                CouplingArg::Cascade => Coupling::Cascade,
                CouplingArg::Bidirectional => Coupling::Bidirectional,
            };
            if let Some(url) = &publish.publish {
                let mut csv = Vec::new();
                simulate::run(experiment, coupling, seed, steps, gamma, &mut csv)?;
                return commands::publish_csv(&csv, url, &publish);
            }
            if let Some(url) = &publish.opcua {
                let mut csv = Vec::new();
                simulate::run(experiment, coupling, seed, steps, gamma, &mut csv)?;
                return commands::serve_opcua(&csv, url, &publish);
            }
            let stdout = std::io::stdout();
            let mut out = BufWriter::new(stdout.lock());
            simulate::run(experiment, coupling, seed, steps, gamma, &mut out)?;
            Ok(Outcome::Done)
        }
    }
}

/// A picture is a `.png` or an `.svg`: refused before any data is read otherwise.
fn check_plot(plot: Option<&PathBuf>) -> Result<(), CliError> {
    let Some(path) = plot else { return Ok(()) };
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if matches!(ext.as_deref(), Some("png" | "svg")) {
        Ok(())
    } else {
        Err(CliError::Config {
            path: path.display().to_string(),
            message: "--plot writes a .png or an .svg picture: name the file so".into(),
        })
    }
}

fn verdict(required: bool, certified: bool) -> Outcome {
    if required && !certified { Outcome::NotCertified } else { Outcome::Done }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(Outcome::Done) => ExitCode::SUCCESS,
        Ok(Outcome::NotCertified) => {
            eprintln!("streamcert: not certified at the end of the input (--require-certified)");
            ExitCode::from(NOT_CERTIFIED_EXIT)
        }
        // A closed pipe downstream (`streamcert simulate g5 | head`) is not an error.
        Err(CliError::Io { source, .. }) if source.kind() == std::io::ErrorKind::BrokenPipe => {
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("streamcert: error: {e}");
            if matches!(e, CliError::Row(_)) {
                eprintln!(
                    "streamcert: the run stopped at this row (--on-bad-row stop, the default); \
                     --on-bad-row skip counts and skips malformed rows instead (a skipped row \
                     is not certified: every gate closes there and reopens at the `consecutive`-th \
                     sample above the margin after it; the windows keep their data)"
                );
            }
            ExitCode::from(u8::try_from(e.exit_code()).unwrap_or(1))
        }
    }
}
