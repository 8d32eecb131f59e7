//! `cargo xtask network`: the live network certificate at fleet scale against the truth
//! (NETWORK.md). `N` scalar linear subsystems `ẏ_i = a_i y_i + u_i + w_i` (explored by
//! `u_i = −2 y_i + PRBS(±1, held 0.1 s)`, Gaussian process noise, `dt = 0.01`), candidate
//! gains `K_i = −β_i − a_i` with known local rates `β_i`, and coupling bounds on a sparse
//! random graph (three incoming couplings per subsystem) scaled so that the true network rate
//! `−α(Γ)` sits at a target: three network margins above the margin (power) or at 0.8 of it
//! (just below: every opening is false). The network certifier composes the calibrated local
//! certificates (the run-level risk `δ` split over the `N` subsystems) with the sparse
//! Collatz–Wielandt bound at every epoch, through `push_batch` over threads.
//!
//! The truth is a Collatz–Wielandt bracket `[lower, upper]` of the true network rate
//! (1e-12 wide); a run counts as below the margin only when `upper < margin`, above it only
//! when `lower >= margin`.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use streamcert_certificate::{CertificateKind, CertifierConfig};
use streamcert_compose::{Network, SparseOptions, certify_sparse};
use streamcert_network::{NetworkCertifier, NetworkConfig, SampleBatch, SubsystemSpec};
use streamcert_regression::{InputIntegral, RegressionConfig};

use crate::common::{markdown, median, progress, seed, write};
use crate::validity::clopper_pearson;

const DELTA: f64 = 0.05;
const MARGIN: f64 = 0.1;
const DT: f64 = 0.01;
const STEPS: usize = 3000;
const SIGMA: f64 = 0.05;
const EPOCH: f64 = 1.0;
/// Steps per `push_batch` call.
const CHUNK: usize = 50;

/// Where a run's true network rate is placed.
#[derive(Clone, Copy)]
struct Target {
    name: &'static str,
    rate: f64,
}

const TARGETS: [Target; 3] = [
    Target { name: "just below the margin (0.8 margin)", rate: 0.8 * MARGIN },
    Target { name: "above the margin (3 margins)", rate: 3.0 * MARGIN },
    Target { name: "well above the margin (8 margins)", rate: 8.0 * MARGIN },
];

/// One run's outcome.
struct Outcome {
    lower: f64,
    upper: f64,
    opened: bool,
    first_open: Option<f64>,
    /// Largest composed rate minus the true rate's upper end, over the epochs (must be <= 0
    /// when every local certificate holds).
    excess: f64,
    epochs: usize,
    certified: usize,
}

/// The true network rate bracket of local rates `beta` and couplings `edges` scaled by `s`.
fn truth(beta: &[f64], edges: &[(usize, usize, f64)], s: f64) -> Result<(f64, f64)> {
    let e: Vec<_> = edges.iter().map(|&(i, j, g)| (i, j, s * g)).collect();
    let net = Network::new(beta.to_vec(), &e)?;
    let opts = SparseOptions { max_iterations: 20_000, tolerance: 1e-12, cholesky_steps: 0 };
    let c = certify_sparse(&net, &opts)?;
    Ok((c.metzler_rate, c.metzler_upper))
}

fn one_run(n: usize, target: Target, run: usize, threads: usize) -> Result<Outcome> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed(run, 7100 + (target.rate * 1000.0) as u64));
    let a: Vec<f64> = (0..n).map(|_| rng.random_range(-0.5..0.5)).collect();
    let beta: Vec<f64> = (0..n).map(|_| rng.random_range(1.0..3.0)).collect();
    let mut edges = Vec::with_capacity(3 * n);
    for i in 0..n {
        for _ in 0..3 {
            let j = rng.random_range(0..n);
            if j != i {
                edges.push((i, j, rng.random_range(0.1..0.5)));
            }
        }
    }
    // Scale the couplings so the true rate is at the target (bisection on the bracket's middle).
    let (mut lo, mut hi) = (0.0, 20.0);
    for _ in 0..50 {
        let mid = 0.5 * (lo + hi);
        let (l, u) = truth(&beta, &edges, mid)?;
        if 0.5 * (l + u) > target.rate { lo = mid } else { hi = mid }
    }
    let (lower, upper) = truth(&beta, &edges, lo)?;
    let couplings: Vec<_> = edges.iter().map(|&(i, j, g)| (i, j, lo * g)).collect();
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(1, 1, 150, 5, 1e-4)
    };
    let specs = (0..n)
        .map(|i| {
            let c = CertifierConfig::new(reg, vec![-beta[i] - a[i]], 0.3, 0.05, 1);
            SubsystemSpec::new(&format!("s{i}"), c)
        })
        .collect();
    let mut cfg = NetworkConfig::new(specs, couplings, EPOCH).split_risk(DELTA);
    cfg.margin = MARGIN;
    assert_eq!(cfg.certificate, CertificateKind::Calibrated);
    let mut net = NetworkCertifier::new(cfg)?;
    let mut y = vec![0.0f64; n];
    let mut d = vec![1.0f64; n];
    let mut batch = SampleBatch::new();
    let mut out = Outcome {
        lower,
        upper,
        opened: false,
        first_open: None,
        excess: f64::NEG_INFINITY,
        epochs: 0,
        certified: 0,
    };
    for chunk in 0..STEPS / CHUNK {
        batch.clear();
        for step in chunk * CHUNK..(chunk + 1) * CHUNK {
            let t = step as f64 * DT;
            for i in 0..n {
                if step % 10 == 0 && rng.random::<bool>() {
                    d[i] = -d[i];
                }
                let u = -2.0 * y[i] + d[i];
                batch.push(i, t, &[y[i]], &[u]);
                let w: f64 = rng.sample(StandardNormal);
                y[i] += DT * (a[i] * y[i] + u) + SIGMA * DT.sqrt() * w;
            }
        }
        net.push_batch(&batch, threads, |r| {
            out.epochs += 1;
            out.certified += usize::from(r.certified);
            if r.open && !out.opened {
                out.opened = true;
                out.first_open = Some(r.t);
            }
            if let Some(rate) = r.rate {
                out.excess = out.excess.max(rate - upper);
            }
        })
        .with_context(|| format!("run {run}"))?;
    }
    Ok(out)
}

/// A target's row of NETWORK.md over its runs, and its false openings.
fn target_row(name: &str, results: &[Outcome]) -> (Vec<String>, usize) {
    let below = results.iter().filter(|o| o.upper < MARGIN).count();
    let above = results.iter().filter(|o| o.lower >= MARGIN).count();
    let false_open = results.iter().filter(|o| o.upper < MARGIN && o.opened).count();
    let true_open = results.iter().filter(|o| o.lower >= MARGIN && o.opened).count();
    let (_, cp_hi) = clopper_pearson(false_open, below.max(1));
    let times: Vec<f64> = results.iter().filter_map(|o| o.first_open).collect();
    let excess = results.iter().map(|o| o.excess).fold(f64::NEG_INFINITY, f64::max);
    let share: Vec<f64> =
        results.iter().map(|o| o.certified as f64 / o.epochs.max(1) as f64).collect();
    let brackets = results.iter().map(|o| o.upper - o.lower).fold(0.0, f64::max);
    let row = vec![
        name.to_string(),
        format!("{}", results.len()),
        format!("{below} / {above}"),
        if below > 0 {
            format!("{false_open} / {below} (CP upper {cp_hi:.3})")
        } else {
            "—".into()
        },
        if above > 0 { format!("{true_open} / {above}") } else { "—".into() },
        if times.is_empty() { "never".into() } else { format!("{:.1}", median(&times)) },
        format!("{:.1} %", 100.0 * median(&share)),
        format!("{excess:.4}"),
        format!("{brackets:.1e}"),
    ];
    (row, false_open)
}

/// Run the study and write NETWORK.md.
pub(crate) fn run(
    n: usize,
    runs: usize,
    coupling_runs: usize,
    threads: usize,
    out: &Path,
) -> Result<()> {
    std::fs::create_dir_all(out)?;
    let bar = progress(TARGETS.len() * runs, "network runs");
    let mut rows = Vec::new();
    let mut notes = String::new();
    for target in TARGETS {
        let mut results = Vec::with_capacity(runs);
        for r in 0..runs {
            results.push(one_run(n, target, r, threads)?);
            bar.inc(1);
        }
        let (row, false_open) = target_row(target.name, &results);
        rows.push(row);
        if false_open > 0 {
            let _ = writeln!(
                notes,
                "- **{}: the gate opened in {false_open} run(s) whose true network rate is below \
                 the margin.**",
                target.name
            );
        }
    }
    bar.finish_and_clear();
    let mut md = String::new();
    let _ = writeln!(md, "# The live network certificate at scale\n");
    let _ = writeln!(
        md,
        "Produced by `cargo xtask network --subsystems {n} --runs {runs} --threads {threads}`. \
         Each run: {n} scalar linear subsystems `ẏ_i = a_i y_i + u_i + w_i` (`a_i` uniform in \
         [−0.5, 0.5], explored by `u_i = −2 y_i + PRBS(±1, held 0.1 s)`, Gaussian process noise \
         σ = {SIGMA}, dt = {DT}, {} s), candidate gains with true local rates `β_i` uniform in \
         [1, 3], coupling bounds on a sparse random graph (three incoming per subsystem, weights \
         uniform in [0.1, 0.5]) scaled by bisection until the true network rate `−α(Γ)` is at \
         the target. Local certificates: calibrated (M = 150, h = 5, defaults), one-sample local \
         gates; the run-level risk δ = {DELTA} is split over the subsystems (δ/N each); the \
         network is composed every {EPOCH} s with the sparse Collatz–Wielandt lower bound \
         (`push_batch` over {threads} threads); network margin {MARGIN}, one-epoch gate.\n",
        STEPS as f64 * DT
    );
    let _ = writeln!(
        md,
        "{}",
        markdown(
            &[
                "true network rate",
                "runs",
                "below / above the margin (truth bracket)",
                "opened while below",
                "opened while above",
                "median first opening [s]",
                "median share of epochs certified",
                "largest composed rate − true rate",
                "widest truth bracket",
            ],
            &rows,
        )
    );
    let _ = writeln!(
        md,
        "Reading: a run is below (above) the margin when the upper (lower) end of the \
         Collatz–Wielandt bracket of its true network rate is below (at least) the margin. \
         Every opening of a run below the margin is false; the union bound over the \
         subsystems' calibrated certificates puts the false-opening probability of a run at most \
         δ = {DELTA}. The composed rate can exceed the true rate only if a local certificate \
         overstates its rate (the composition is monotone in the local rates and the \
         Collatz–Wielandt value is a lower bound), so `largest composed rate − true rate` must \
         be at most 0 (`-inf`: at every composition some subsystem had no certificate).\n\n\
         The local certificates run with their default guards. The network gate needs every \
         subsystem's certificate at once, so a guard that closes each subsystem at a small share \
         of samples (VALIDITY.md's `guard closed`, at δ = 0.01) leaves some subsystem closed at \
         almost every epoch once N is large: for a network of N subsystems to be certified, the \
         guards' false closings per subsystem must fall well below 1/N."
    );
    if !notes.is_empty() {
        let _ = writeln!(md, "\n{notes}");
    }
    let _ = writeln!(md, "\n{}", crate::coupling::study(coupling_runs)?);
    write(&out.join("NETWORK.md"), &md)?;
    println!("wrote {}", out.join("NETWORK.md").display());
    Ok(())
}
