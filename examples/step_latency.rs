//! What the default certifier's slowest steps are made of: every step of a long run timed
//! once, the steps at which windows look grouped by how many windows look together.
//!
//! The default calibrated certificate (`p = m = 1`, `h = 5`, δ = 0.01, every guard), on the
//! stream of `benches/regression.rs`, base window `M` (argument, default 150). Window `i`
//! (`2^i M` columns) looks every `2^(i−1) M` samples once full, so the shortest window looks
//! every `M/2` samples and, every `2^(W−2) M` samples, all `W` windows look in the same step.
//! The phase of the looks is found from the timings (the residue modulo `M/2` with the
//! slowest median step). Wall-clock times on a shared machine: medians are stable, maxima
//! carry the machine's noise (the criterion bench `certifier_worst_step` measures the slowest
//! step on clones of its state).
//!
//! Run: `cargo run --release --example step_latency -- 600` (prints one row per number of
//! windows looking: the steps' count, median and largest time in microseconds, then the
//! median step and the 99th and 99.9th percentiles of all steps).

use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::certificate::{Calibration, Certifier, CertifierConfig};
use streamcert::regression::RegressionConfig;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let base: usize = std::env::args().nth(1).map_or(Ok(150), |s| s.parse())?;
    if base < 10 || !base.is_multiple_of(10) {
        return Err("the base window must be a positive multiple of 10".into());
    }
    let horizon = 5;
    let calibration = Calibration::new(0.01);
    let windows = calibration.window_lengths(base, horizon).len();
    let len = 40 * (base << windows.saturating_sub(2)).max(1_000);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut state = [0.0f64; 2];
    let mut cfg = CertifierConfig::new(
        RegressionConfig::new(1, 1, base, horizon, 1e-4),
        vec![-1.0],
        0.2,
        0.05,
        10,
    );
    cfg.calibration = Some(calibration);
    let mut cert = Certifier::new(cfg)?;
    // Every window full: the longest spans 2^(W−1) M columns.
    let settle = (base << windows) + 200;
    let mut times = Vec::with_capacity(len);
    for k in 0..len {
        for v in &mut state {
            *v = 0.95 * *v + rng.random::<f64>() - 0.5;
        }
        let start = Instant::now();
        cert.push(0.01 * (k + 1) as f64, &state[..1], &state[1..])?;
        times.push(start.elapsed().as_secs_f64() * 1e6);
    }
    let steady = &times[settle..];
    let spacing = base / 2;
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let medians: Vec<f64> = (0..spacing)
        .map(|r| median(&mut steady.iter().skip(r).step_by(spacing).copied().collect()))
        .collect();
    let phase =
        (0..spacing).max_by(|&a, &b| medians[a].total_cmp(&medians[b])).ok_or("no steps")?;
    // The look at sample `k` is the `(k − r)/spacing`-th, `r = k mod spacing`; window `i`
    // looks at every `2^i`-th, so `1 + (trailing zeros)` windows look (at most `W`).
    let first = settle + phase;
    let mut groups = vec![Vec::new(); windows];
    for (j, &t) in steady.iter().skip(phase).step_by(spacing).enumerate() {
        let index = first / spacing + j;
        let looking = 1 + (index.trailing_zeros() as usize).min(windows - 1);
        groups[looking - 1].push(t);
    }
    println!(
        "M = {base}, {windows} windows, {} steps timed after the windows filled",
        steady.len()
    );
    println!("windows looking | steps | median µs | largest µs");
    for (i, g) in groups.iter_mut().enumerate() {
        if g.is_empty() {
            continue;
        }
        let largest = g.iter().copied().fold(0.0, f64::max);
        println!("{} | {} | {:.1} | {:.1}", i + 1, g.len(), median(g), largest);
    }
    let mut all = steady.to_vec();
    all.sort_by(f64::total_cmp);
    let n = all.len();
    println!(
        "every step: median {:.2} µs, 99th percentile {:.1} µs, 99.9th {:.1} µs",
        all[n / 2],
        all[n * 99 / 100],
        all[n * 999 / 1000]
    );
    Ok(())
}
