//! The coverage of the estimated coupling bounds (a section of NETWORK.md): two scalar linear
//! subsystems coupled both ways with known gains,
//!
//! ```text
//! ẏ_a = a_a y_a + u_a + γ_ab y_b + w_a,    ẏ_b = a_b y_b + u_b + γ_ba y_a + w_b
//! ```
//!
//! explored by `u = −2 y + PRBS(±1, held 0.2 s)`, Gaussian process noise, `dt = 0.01`, 40 s.
//! Each subsystem's calibrated certifier takes the other's output as a coupling input (a zero
//! row of the gain) and reports an upper bound on `|γ|` with risk `δ_c` over the run. A run
//! *understates* when any reported bound, at any sample, is below the true gain: the bounds'
//! promise is that this happens in at most a fraction `δ_c` of runs.

use std::fmt::Write as _;

use anyhow::Result;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use streamcert_certificate::{
    Calibration, Certifier, CertifierConfig, CouplingBlock, CouplingConfig,
};
use streamcert_regression::{InputIntegral, RegressionConfig};

use crate::common::{markdown, median, progress, seed};
use crate::validity::clopper_pearson;

const DELTA_C: f64 = 0.05;
const DT: f64 = 0.01;
const STEPS: usize = 4000;

/// One cell: the local drifts and the two coupling gains.
struct Cell {
    name: &'static str,
    a: [f64; 2],
    gamma: [f64; 2],
    sigma: f64,
}

const CELLS: [Cell; 3] = [
    Cell { name: "symmetric, γ = 0.3", a: [0.2, -0.3], gamma: [0.3, 0.3], sigma: 0.1 },
    Cell {
        name: "asymmetric, γ_ab = 0.8, γ_ba = 0.2",
        a: [0.2, -0.3],
        gamma: [0.8, 0.2],
        sigma: 0.1,
    },
    Cell {
        name: "symmetric, γ = 0.3, heavy noise σ = 0.5",
        a: [0.2, -0.3],
        gamma: [0.3, 0.3],
        sigma: 0.5,
    },
];

/// Per run: whether any bound understated, and each block's last bound and estimate.
struct Run {
    understated: bool,
    last: [Option<(f64, f64)>; 2],
}

fn certifier(k: f64) -> Result<Certifier> {
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(1, 2, 150, 5, 1e-4)
    };
    let cfg = CertifierConfig {
        calibration: Some(Calibration::new(0.01)),
        couplings: Some(CouplingConfig {
            blocks: vec![CouplingBlock { first: 1, len: 1 }],
            delta: DELTA_C / 2.0,
        }),
        ..CertifierConfig::new(reg, vec![k, 0.0], 0.3, 0.05, 1)
    };
    Ok(Certifier::new(cfg)?)
}

fn one_run(cell: &Cell, run: usize, stream: u64) -> Result<Run> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed(run, stream));
    let mut certs = [certifier(-1.0)?, certifier(-1.0)?];
    let (mut y, mut d) = ([0.0f64; 2], [1.0f64; 2]);
    let mut out = Run { understated: false, last: [None, None] };
    for step in 0..STEPS {
        let t = step as f64 * DT;
        let mut u = [0.0; 2];
        for i in 0..2 {
            if step % 20 == 0 && rng.random::<bool>() {
                d[i] = -d[i];
            }
            u[i] = -2.0 * y[i] + d[i];
        }
        for i in 0..2 {
            certs[i].push(t, &[y[i]], &[u[i], y[1 - i]])?;
            if let Some(Some(b)) = certs[i].coupling_bounds().first() {
                out.understated |= b.upper < cell.gamma[i];
                out.last[i] = Some((b.upper, b.estimate));
            }
        }
        let w: [f64; 2] = [rng.sample(StandardNormal), rng.sample(StandardNormal)];
        let next = [
            y[0] + DT * (cell.a[0] * y[0] + u[0] + cell.gamma[0] * y[1])
                + cell.sigma * DT.sqrt() * w[0],
            y[1] + DT * (cell.a[1] * y[1] + u[1] + cell.gamma[1] * y[0])
                + cell.sigma * DT.sqrt() * w[1],
        ];
        y = next;
    }
    Ok(out)
}

/// The section of NETWORK.md: `runs` runs per cell.
pub(crate) fn study(runs: usize) -> Result<String> {
    let bar = progress(CELLS.len() * runs, "coupling runs");
    let mut rows = Vec::new();
    for (c, cell) in CELLS.iter().enumerate() {
        let mut results = Vec::with_capacity(runs);
        for r in 0..runs {
            results.push(one_run(cell, r, 7300 + c as u64)?);
            bar.inc(1);
        }
        let bad = results.iter().filter(|r| r.understated).count();
        let (_, hi) = clopper_pearson(bad, runs);
        let ratio = |i: usize, which: usize| {
            let v: Vec<f64> = results
                .iter()
                .filter_map(|r| r.last[i].map(|(u, e)| if which == 0 { u } else { e }))
                .collect();
            median(&v)
        };
        rows.push(vec![
            cell.name.to_string(),
            format!("{runs}"),
            format!("{bad} / {runs}"),
            format!("{hi:.4}"),
            if hi <= 2.0 * DELTA_C { "yes".into() } else { "**no**".into() },
            format!("{:.3} / {:.3} (γ {})", ratio(0, 1), ratio(0, 0), cell.gamma[0]),
            format!("{:.3} / {:.3} (γ {})", ratio(1, 1), ratio(1, 0), cell.gamma[1]),
        ]);
    }
    bar.finish_and_clear();
    let mut md = String::new();
    let _ = writeln!(md, "## Estimated coupling bounds: coverage\n");
    let _ = writeln!(
        md,
        "Two scalar subsystems coupled both ways with known gains (`ẏ_a = a_a y_a + u_a + γ_ab \
         y_b + w_a`, and the same for b), explored by `u = −2 y + PRBS(±1, held 0.2 s)`, \
         dt = {DT}, {} s; each subsystem's calibrated certifier takes the other's output as a \
         coupling input and reports an upper bound on the gain with risk δ_c = {DELTA_C} for the \
         two bounds together over the run (`CouplingConfig`, δ_c/2 each). A run understates when \
         any reported bound, at any sample, is below the true gain; the promise is at most δ_c \
         of runs.\n",
        STEPS as f64 * DT
    );
    let _ = writeln!(
        md,
        "{}",
        markdown(
            &[
                "cell",
                "runs",
                "runs understating",
                "95 % CP upper",
                "≤ 2 δ_c",
                "median last estimate / bound, a ← b",
                "median last estimate / bound, b ← a",
            ],
            &rows,
        )
    );
    Ok(md)
}
