//! `cargo xtask sites`: the network service across sites (NETWORK.md, "Across sites";
//! BENCHMARKS.md). `N` scalar loops `ẏ_i = a_i y_i + u_i + w_i` (explored by
//! `u_i = −2 y_i + PRBS(±1)`, Gaussian process noise) sampled at `rate` Hz, placed round-robin
//! on `P` timely processes (threads of this process, talking over localhost TCP exactly as
//! separate machines do), each process generating and certifying only its own subsystems'
//! rows; worker 0 composes every 1 s epoch.
//!
//! * **Bytes.** What crossed process boundaries (the bincode size of every message a process
//!   other than 0 sent to the composer, as timely serialises it), per epoch, against what the
//!   raw-sample path (the one sites replaced) sent for the same rows: process 0 read every row and
//!   shipped each sample of a subsystem owned by another process as `Sample { row, line,
//!   index, t, values }` (its bincode size, measured here on a struct of the same fields).
//! * **Throughput.** Samples per second over 2 processes against the one-process
//!   `NetworkCertifier::push_batch` over 2 threads on the same samples (the ceiling).

use std::fmt::Write as _;
use std::path::Path;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, anyhow};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::Serialize;
use streamcert_certificate::CertifierConfig;
use streamcert_network::{NetworkCertifier, NetworkConfig, SampleBatch, SubsystemSpec};
use streamcert_regression::{InputIntegral, RegressionConfig};
use streamcert_timely::{Output, Placement, Row};

use crate::common::{markdown, seed, write};

mod cli;

const SIGMA: f64 = 0.05;
const EPOCH: f64 = 1.0;

/// The raw-sample message of the path sites replaced, field for field.
#[derive(Serialize)]
struct OldSample {
    row: u64,
    line: u64,
    index: u32,
    t: f64,
    values: Vec<f64>,
}

fn network(n: usize) -> NetworkConfig {
    let mut rng = ChaCha8Rng::seed_from_u64(seed(0, 9300));
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(1, 1, 150, 5, 1e-4)
    };
    let specs = (0..n)
        .map(|i| {
            let beta: f64 = rng.random_range(1.0..3.0);
            let c = CertifierConfig::new(reg, vec![-beta], 0.3, 0.05, 1);
            SubsystemSpec::new(&format!("s{i}"), c)
        })
        .collect();
    let edges = (0..n)
        .flat_map(|i| [((i + 1) % n, i, 0.05), ((i + 7) % n, i, 0.05)])
        .filter(|&(a, b, _)| a != b)
        .collect();
    let mut cfg = NetworkConfig::new(specs, edges, EPOCH).split_risk(0.05);
    cfg.margin = 0.1;
    cfg
}

/// The rows of subsystems `ids` (one sample per row, in time order), `steps` steps of `dt`.
pub(super) struct Rows {
    pub(super) ids: Vec<usize>,
    y: Vec<f64>,
    d: Vec<f64>,
    a: Vec<f64>,
    rng: ChaCha8Rng,
    step: usize,
    k: usize,
    steps: usize,
    dt: f64,
}

impl Rows {
    pub(super) fn new(ids: Vec<usize>, steps: usize, dt: f64, stream: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed(0, 9400 + stream));
        let a = ids.iter().map(|_| rng.random_range(-0.5..0.5)).collect();
        Self {
            y: vec![0.0; ids.len()],
            d: vec![1.0; ids.len()],
            a,
            ids,
            rng,
            step: 0,
            k: 0,
            steps,
            dt,
        }
    }
}

impl Iterator for Rows {
    type Item = Result<Row, std::io::Error>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.step >= self.steps || self.ids.is_empty() {
            return None;
        }
        let (k, dt) = (self.k, self.dt);
        if self.step.is_multiple_of(50) && self.rng.random::<bool>() {
            self.d[k] = -self.d[k];
        }
        let u = -2.0 * self.y[k] + self.d[k];
        let t = self.step as f64 * dt;
        let row = Row { line: 0, t, samples: vec![(self.ids[k], vec![self.y[k], u])], gap: false };
        let w: f64 = self.rng.sample(StandardNormal);
        self.y[k] += dt * (self.a[k] * self.y[k] + u) + SIGMA * dt.sqrt() * w;
        self.k += 1;
        if self.k == self.ids.len() {
            self.k = 0;
            self.step += 1;
        }
        Some(Ok(row))
    }
}

/// What a run over `p` processes measured.
struct Measured {
    seconds: f64,
    epochs: u64,
    samples: u64,
    bytes: u64,
    messages: u64,
}

/// `n` subsystems round-robin over `p` processes (threads here, TCP on localhost).
fn over_processes(n: usize, p: usize, steps: usize, dt: f64, out: &Path) -> Result<Measured> {
    let cfg = network(n);
    let ports: Vec<u16> = (0..p)
        .map(|_| {
            let l = std::net::TcpListener::bind("127.0.0.1:0")?;
            Ok(l.local_addr()?.port())
        })
        .collect::<Result<_>>()?;
    let hosts = out.join(format!("hosts-{p}.txt"));
    let text: String = ports.iter().map(|port| format!("127.0.0.1:{port}\n")).collect();
    std::fs::write(&hosts, text)?;
    let process_of: Vec<usize> = (0..n).map(|i| i % p).collect();
    let start = Instant::now();
    let handles: Vec<_> = (0..p)
        .map(|process| {
            let place = Placement {
                process_of: process_of.clone(),
                processes: p,
                process,
                workers: 1,
                hosts: Some(hosts.clone()),
                silence: None,
            };
            let cfg = cfg.clone();
            let ids: Vec<usize> = (0..n).filter(|i| i % p == process).collect();
            std::thread::spawn(move || {
                let mut epochs = 0u64;
                let source = move || Rows::new(ids, steps, dt, process as u64);
                let outcome = streamcert_timely::run(cfg, &place, None, None, source, |o| {
                    if let Output::Epoch(_) = o {
                        epochs += 1;
                    }
                    Ok(())
                });
                outcome.map(|o| (o, epochs)).map_err(|e| anyhow!("process {process}: {e}"))
            })
        })
        .collect();
    let mut m = Measured { seconds: 0.0, epochs: 0, samples: 0, bytes: 0, messages: 0 };
    for h in handles {
        let (o, epochs) = h.join().map_err(|_| anyhow!("a process thread panicked"))??;
        m.epochs += epochs;
        m.samples += o.rows;
        m.bytes += o.bytes_sent;
        if o.bytes_sent > 0 {
            m.messages += o.messages;
        }
    }
    m.seconds = start.elapsed().as_secs_f64();
    Ok(m)
}

/// The same rows through one `NetworkCertifier::push_batch` over 2 threads.
fn push_batch(n: usize, steps: usize, dt: f64) -> Result<(f64, u64)> {
    let cfg = network(n);
    let mut net = NetworkCertifier::new(cfg)?;
    // The rows of the two-process run, merged in time order (process 0's, then 1's, per step).
    let mut sites: Vec<Rows> = (0..2)
        .map(|p| Rows::new((0..n).filter(|i| i % 2 == p).collect(), steps, dt, p as u64))
        .collect();
    let mut batch = SampleBatch::new();
    let mut epochs = 0u64;
    let start = Instant::now();
    for chunk in 0..steps.div_ceil(100) {
        batch.clear();
        for _ in chunk * 100..((chunk + 1) * 100).min(steps) {
            for site in &mut sites {
                for _ in 0..site.ids.len() {
                    if let Some(Ok(r)) = site.next() {
                        let (i, v) = &r.samples[0];
                        batch.push(*i, r.t, &v[..1], &v[1..]);
                    }
                }
            }
        }
        net.push_batch(&batch, 2, |_| epochs += 1)?;
    }
    Ok((start.elapsed().as_secs_f64(), epochs))
}

/// A table row: the path, its seconds, samples per second, and the ratio of the baseline's
/// seconds to its own (`None`: it is the baseline).
fn timing(path: &str, secs: f64, samples: f64, baseline: Option<f64>) -> Vec<String> {
    vec![
        path.into(),
        format!("{secs:.2}"),
        format!("{:.3e}", samples / secs),
        baseline.map_or_else(|| "1".into(), |b| format!("{:.2}", b / secs)),
    ]
}

/// The command line of `cargo xtask sites`.
#[derive(clap::Args)]
pub(crate) struct Options {
    /// Subsystems of the bytes study.
    #[arg(long, default_value_t = 10_000)]
    subsystems: usize,
    /// Processes of the bytes study.
    #[arg(long, default_value_t = 4)]
    processes: usize,
    /// Sampling rate [Hz].
    #[arg(long, default_value_t = 1000.0)]
    rate: f64,
    /// Seconds of data.
    #[arg(long, default_value_t = 3.0)]
    seconds: f64,
    /// Subsystems of the throughput study (2 processes against push_batch).
    #[arg(long, default_value_t = 100)]
    throughput_subsystems: usize,
    /// Seconds of data of the throughput study.
    #[arg(long, default_value_t = 30.0)]
    throughput_seconds: f64,
    /// A `streamcert` binary of the raw-sample path (process 0 reads and ships every sample,
    /// as before sites; built from the project's history): also compare the two
    /// binaries on the throughput study's samples written as CSV.
    #[arg(long)]
    old_binary: Option<PathBuf>,
    /// Output folder.
    #[arg(long, default_value = "target/sites")]
    out: PathBuf,
}

/// Run both studies and write `SITES.md` into `out`.
pub(crate) fn run(o: &Options) -> Result<()> {
    let Options {
        subsystems,
        processes,
        rate,
        seconds,
        throughput_subsystems,
        throughput_seconds,
        ref old_binary,
        ref out,
    } = *o;
    let out = out.as_path();
    let old_binary = old_binary.as_deref();
    std::fs::create_dir_all(out)?;
    let dt = 1.0 / rate;
    let steps = (seconds * rate).round() as usize;
    eprintln!("bytes: {subsystems} subsystems over {processes} processes, {steps} steps…");
    let m = over_processes(subsystems, processes, steps, dt, out).context("bytes study")?;
    // The old path: every sample of a subsystem on another process crossed as one message.
    let crossing = (0..subsystems).filter(|i| i % processes != 0).count() as u64 * steps as u64;
    let one = OldSample { row: 1, line: 1, index: 1, t: 0.0, values: vec![0.0, 0.0] };
    let old_bytes = crossing * bincode::serialized_size(&one)?;
    let mut md = String::new();
    writeln!(
        md,
        "Produced by `cargo xtask sites --subsystems {subsystems} --processes {processes} \
         --rate {rate} --seconds {seconds} --throughput-subsystems {throughput_subsystems} \
         --throughput-seconds {throughput_seconds}{}`.\n",
        if old_binary.is_some() { " --old-binary <the raw-sample binary>" } else { "" }
    )?;
    writeln!(md, "### Bytes across process boundaries\n")?;
    writeln!(
        md,
        "{subsystems} scalar subsystems sampled at {rate} Hz for {seconds} s ({} samples), \
         placed round-robin on {processes} timely processes (threads of one process, TCP on \
         localhost), epochs of {EPOCH} s, calibrated local certificates; {} epochs composed, \
         {:.1} s wall.\n",
        m.samples, m.epochs, m.seconds
    )?;
    md.push_str(&bytes_table(&m, crossing, old_bytes));
    eprintln!("throughput: {throughput_subsystems} subsystems, 2 processes vs push_batch…");
    let tsteps = (throughput_seconds * rate).round() as usize;
    let two = over_processes(throughput_subsystems, 2, tsteps, dt, out).context("throughput")?;
    let (batch_s, _) = push_batch(throughput_subsystems, tsteps, dt)?;
    let samples = (throughput_subsystems * tsteps) as f64;
    writeln!(md, "\n### Throughput\n")?;
    writeln!(
        md,
        "{throughput_subsystems} subsystems at {rate} Hz for {throughput_seconds} s \
         ({samples:.0} samples) on this machine (2 cores), in one program (timely processes as \
         threads, TCP on localhost; rows generated in memory).\n"
    )?;
    md.push_str(&markdown(
        &["path", "seconds", "samples per second", "ratio to push_batch"],
        &[
            timing("one process, `push_batch` over 2 threads (ceiling)", batch_s, samples, None),
            timing("2 timely processes, each its own rows", two.seconds, samples, Some(batch_s)),
        ],
    ));
    if let Some(old) = old_binary {
        md.push_str(&binaries(old, (throughput_subsystems, tsteps, dt), samples, out)?);
    }
    write(&out.join("SITES.md"), &md)?;
    println!("{md}");
    Ok(())
}

/// The throughput study through the binaries (`old`: the raw-sample one) on `n` subsystems,
/// `steps` steps of `dt`: SITES.md's paragraph and table.
fn binaries(
    old: &Path,
    (n, steps, dt): (usize, usize, f64),
    samples: f64,
    out: &Path,
) -> Result<String> {
    let mut md = String::new();
    eprintln!("throughput through the binaries (the old one: {})…", old.display());
    let ([old_s, new_s, one_s, workers_s], same) = cli::throughput(old, n, steps, dt, out)?;
    writeln!(
        md,
        "\nThrough the `streamcert` binaries on the same samples written as CSV (2 \
         processes on localhost, or one; this build's runs wrote the same epoch rows, \
         {}):\n",
        if same {
            "and so did the raw-sample binary's"
        } else {
            "the raw-sample binary's differ: its calibrated local certificates predate \
             later changes of the default (see VALIDITY.md)"
        }
    )?;
    md.push_str(&markdown(
        &["path", "seconds", "samples per second", "ratio to the raw-sample binary"],
        &[
            timing(
                "the raw-sample binary: process 0 reads the wide file and ships the samples",
                old_s,
                samples,
                None,
            ),
            timing("sites: each process reads its own columns", new_s, samples, Some(old_s)),
            timing("sites, one process (no timely)", one_s, samples, Some(old_s)),
            timing(
                "sites, one process on 2 timely workers (`--workers 2`)",
                workers_s,
                samples,
                Some(old_s),
            ),
        ],
    ));
    Ok(md)
}

/// The bytes study's table: messages and bytes per epoch of the raw-sample path (`crossing`
/// samples, `old_bytes` bytes) and of the sites' path (`m`).
fn bytes_table(m: &Measured, crossing: u64, old_bytes: u64) -> String {
    let epochs = m.epochs.max(1);
    let per = |b: u64| format!("{:.0}", b as f64 / epochs as f64);
    markdown(
        &["path", "messages per epoch", "bytes per epoch", "ratio to raw samples"],
        &[
            vec![
                "raw samples (process 0 reads and ships every sample)".into(),
                per(crossing),
                per(old_bytes),
                "1".into(),
            ],
            vec![
                "sites (only snapshots and marks cross)".into(),
                per(m.messages),
                per(m.bytes),
                format!("1/{:.0}", old_bytes as f64 / m.bytes.max(1) as f64),
            ],
        ],
    )
}
