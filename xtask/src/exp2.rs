//! Experiment 2 (paper Section V-C): local certificates from disconnected data, the warning
//! gain, the network margin over the coupling sweep, and coupled simulations, for both G5
//! coupling structures.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;
use streamcert_certificate::Evidence;
use streamcert_compose::{Network, lemma1_rate, network_rate};
use streamcert_dynamics::{
    Coupling, Disturbance, DisturbanceConfig, G5, G5Config, Impulse, Integrator, Process,
    SimConfig, Trajectory, simulate,
};
use streamcert_experiments::{Experiment, Setting};

use crate::common::{Params, csv, markdown, median, pm, progress, seed, write, write_evidence};
use crate::exp1::certify;
use crate::plot::{self, BLUE, Figure, GREEN, ORANGE, PURPLE, Panel, RED_};

const SETTING: Setting = Experiment::Two.setting();
const K1: f64 = SETTING.k1;
const K4: f64 = SETTING.k4;
const SIGMA: f64 = match SETTING.sigma {
    Some(s) => s,
    None => 0.0,
};
const MARGIN: f64 = SETTING.margin;
const DATA_STEPS: usize = SETTING.steps;
pub(crate) const SIM_STEPS: usize = 700;
const IMPULSE: f64 = SETTING.impulse;
pub(crate) const IMPULSE_TIME: f64 = 3.0;
pub(crate) const SWEEP_MAX: f64 = 4.2;
/// The safe simulation coupling is this factor times `γ_warn`.
pub(crate) const SAFE_FACTOR: f64 = 0.55;
/// The unsafe simulation coupling is this factor times the true critical `γ`.
pub(crate) const UNSAFE_FACTOR: f64 = 1.08;
/// A run counts as diverged when ‖x‖ exceeds this or stops being finite.
const DIVERGED: f64 = 1e3;

fn noise(on: bool) -> DisturbanceConfig {
    if on {
        DisturbanceConfig::stationary(Process::Gaussian { sigma: SIGMA })
    } else {
        DisturbanceConfig::none()
    }
}

fn data_run(p: &Params, run: usize) -> Result<Trajectory> {
    Ok(p.dataset(Experiment::Two).run_seeded(run as u64)?)
}

/// Closed-loop coupled response: `u = K y`, impulse into x4 at 3 s.
fn coupled(p: &Params, coupling: Coupling, gamma: f64, run: usize) -> Result<Vec<(f64, f64)>> {
    let sys = G5::new(G5Config { gamma, k1: K1, k4: K4, ..G5Config::paper(coupling) })?;
    let cfg = SimConfig {
        dt: p.dt,
        steps: SIM_STEPS,
        t0: 0.0,
        x0: vec![0.0; 5],
        integrator: Integrator::EulerMaruyama,
        noise_scaling: p.noise_scaling,
    };
    let eta = DisturbanceConfig {
        impulses: vec![Impulse { time: IMPULSE_TIME, magnitude: IMPULSE }],
        ..noise(true)
    };
    let mut dist = [
        Disturbance::new(noise(p.exp2_noise_on_a), seed(run, 15))?,
        Disturbance::new(eta, seed(run, 16))?,
    ];
    let out = simulate(&sys, &cfg, &mut dist, |_t, y, u| {
        u[0] = K1 * y[0];
        u[1] = K4 * y[1];
    })?;
    Ok((0..out.len())
        .map(|k| (out.t[k], out.state(k).iter().map(|v| v * v).sum::<f64>().sqrt()))
        .collect())
}

struct Outcome {
    peak: f64,
    end: f64,
    diverged: bool,
}

fn outcome(norms: &[(f64, f64)]) -> Outcome {
    let diverged = norms.iter().any(|(_, n)| !(n.is_finite() && *n < DIVERGED));
    let after: Vec<f64> =
        norms.iter().filter(|(t, _)| *t >= IMPULSE_TIME).map(|(_, n)| *n).collect();
    let peak = after.iter().copied().filter(|v| v.is_finite()).fold(0.0, f64::max);
    let end = norms.last().map_or(f64::NAN, |(_, n)| *n);
    Outcome { peak, end, diverged }
}

struct SeedResult {
    cert: [f64; 2],
    nominal: [f64; 2],
    t_star: [Option<f64>; 2],
    gammas: Option<[f64; 3]>,
    warn: f64,
    /// `[coupling][level]`.
    outcomes: Vec<Vec<Outcome>>,
    lemma_vs_network: f64,
}

fn run_seed(
    p: &Params,
    run: usize,
    true_rates: [f64; 2],
) -> Result<(SeedResult, Trajectory, [Vec<Evidence>; 2])> {
    let traj = data_run(p, run)?;
    let ev = [certify(p, &traj, 0, K1, MARGIN)?, certify(p, &traj, 1, K4, MARGIN)?];
    let t_end = traj.t[traj.len() - 1];
    let last = |i: usize, f: &dyn Fn(&Evidence) -> Option<f64>| -> f64 {
        let v: Vec<f64> = (0..traj.len())
            .filter(|&k| traj.t[k] > t_end - 3.0 + 1e-9)
            .filter_map(|k| f(&ev[i][k]))
            .collect();
        median(&v)
    };
    let cert = [last(0, &|e| e.gaussian.value), last(1, &|e| e.gaussian.value)];
    let nominal = [last(0, &|e| e.beta_hat()), last(1, &|e| e.beta_hat())];
    let t_star = [0, 1].map(|i| ev[i].iter().find(|e| e.gaussian.open).map(|e| e.t));
    let gamma_true = (true_rates[0] * true_rates[1]).sqrt();
    let warn = if cert[0] > 0.0 && cert[1] > 0.0 { (cert[0] * cert[1]).sqrt() } else { f64::NAN };
    let gammas = warn.is_finite().then_some([
        SAFE_FACTOR * warn,
        0.5 * (warn + gamma_true),
        UNSAFE_FACTOR * gamma_true,
    ]);
    // Lemma 1 against the N-subsystem machinery over the sweep.
    let mut lemma_vs_network = 0.0f64;
    if cert[0] > 0.0 && cert[1] > 0.0 {
        for j in 0..=210 {
            let g = SWEEP_MAX * f64::from(j) / 210.0;
            let lemma = lemma1_rate(cert[0], cert[1], g)?;
            let net = network_rate(&Network::from_dense(&cert, &[0.0, g, g, 0.0])?)?;
            lemma_vs_network = lemma_vs_network.max((lemma - net.rate).abs());
        }
    }
    let mut outcomes = Vec::new();
    if let Some(levels) = gammas {
        for coupling in [Coupling::Bidirectional, Coupling::Cascade] {
            let mut row = Vec::new();
            for g in levels {
                row.push(outcome(&coupled(p, coupling, g, run)?));
            }
            outcomes.push(row);
        }
    }
    Ok((SeedResult { cert, nominal, t_star, gammas, warn, outcomes, lemma_vs_network }, traj, ev))
}

fn figures(
    p: &Params,
    dir: &Path,
    traj: &Trajectory,
    ev: &[Vec<Evidence>; 2],
    res: &SeedResult,
    true_rates: [f64; 2],
) -> Result<()> {
    let series = |i: usize, f: &dyn Fn(&Evidence) -> Option<f64>| -> Vec<(f64, f64)> {
        (0..traj.len()).map(|k| (traj.t[k], f(&ev[i][k]).unwrap_or(f64::NAN))).collect()
    };
    let mut top = Panel::new(
        "Local certificates from disconnected data (γ = 0)",
        "t [s]",
        "β_cert = β_hat − ρ",
    )
    .line("Σ_A", series(0, &|e| e.gaussian.value), BLUE)
    .line("Σ_B", series(1, &|e| e.gaussian.value), ORANGE);
    top.hlines.push((MARGIN, "β_margin".into()));
    top.vlines = res.t_star.iter().flatten().copied().collect();
    let inv = |i: usize| series(i, &|e| e.gaussian.value.filter(|c| *c > 0.0).map(|c| 1.0 / c));
    let mut bottom =
        Panel::new("Incremental gain bound 1/β_cert (where β_cert > 0)", "t [s]", "1/β_cert")
            .line("Σ_A", inv(0), BLUE)
            .line("Σ_B", inv(1), ORANGE);
    bottom.y_range = Some((0.0, 5.0));
    plot::save(
        &Figure { panels: vec![top, bottom], rows: 2, cols: 1, size: (1000, 750) },
        dir,
        "fig6_exp2_local",
    )?;

    let sweep: Vec<f64> = (0..=210).map(|j| SWEEP_MAX * f64::from(j) / 210.0).collect();
    let net = |b: [f64; 2]| -> Vec<(f64, f64)> {
        sweep.iter().map(|&g| (g, lemma1_rate(b[0], b[1], g).unwrap_or(f64::NAN))).collect()
    };
    let mut margin = Panel::new("Network margin β_net(γ) (Lemma 1)", "coupling γ", "β_net")
        .line("from local certificates", net(res.cert), GREEN)
        .line("from point estimates β_hat", net(res.nominal), RED_)
        .line("from true local rates", net(true_rates), PURPLE);
    margin.hlines.push((0.0, "0".into()));
    margin.vlines = vec![res.warn, (true_rates[0] * true_rates[1]).sqrt()];
    let ratio: Vec<(f64, f64)> =
        sweep.iter().map(|&g| (g, g * g / (res.cert[0] * res.cert[1]))).collect();
    let mut small_gain = Panel::new("Small-gain ratio γ²/(β_A β_B)", "coupling γ", "ratio").line(
        "certified rates",
        ratio,
        GREEN,
    );
    small_gain.hlines.push((1.0, "1".into()));
    small_gain.y_range = Some((0.0, 4.0));
    plot::save(
        &Figure { panels: vec![margin, small_gain], rows: 1, cols: 2, size: (1200, 450) },
        dir,
        "fig7_exp2_margin",
    )?;

    if let Some(levels) = res.gammas {
        response_figure(p, dir, levels)?;
    }
    Ok(())
}

/// Fig. 8: the coupled responses at the three coupling levels, and the bidirectional cost.
fn response_figure(p: &Params, dir: &Path, levels: [f64; 3]) -> Result<()> {
    let names = ["γ_safe", "γ_warned", "γ_unsafe"];
    let colors = [GREEN, ORANGE, RED_];
    let mut panels = Vec::new();
    let mut cost_panel = Panel::new("Bidirectional: cumulative cost ∫‖x‖² dt", "t [s]", "cost");
    cost_panel.y_range = Some((0.0, 20.0));
    for (c, coupling) in [(0, Coupling::Bidirectional), (1, Coupling::Cascade)] {
        let mut panel = Panel::new(
            &format!("{coupling:?} G5: ‖x(t)‖, impulse {IMPULSE} at {IMPULSE_TIME} s"),
            "t [s]",
            "‖x‖",
        );
        panel.y_range = Some((0.0, 6.0));
        for (l, g) in levels.iter().enumerate() {
            let norms = coupled(p, coupling, *g, 0)?;
            if c == 0 {
                let mut acc = 0.0;
                let cum = norms.iter().map(|(t, n)| {
                    acc += n * n * p.dt;
                    (*t, acc)
                });
                cost_panel =
                    cost_panel.line(&format!("{} = {g:.2}", names[l]), cum.collect(), colors[l]);
            }
            panel = panel.line(&format!("{} = {g:.2}", names[l]), norms, colors[l]);
        }
        panels.push(panel);
    }
    panels.push(cost_panel);
    plot::save(&Figure { panels, rows: 1, cols: 3, size: (1500, 450) }, dir, "fig8_exp2_response")?;
    Ok(())
}

/// The measured states per step (the evidence is in `evidence_{a,b}_seed0.csv`, written by
/// [`write_evidence`]).
fn trace_csv(traj: &Trajectory) -> String {
    let mut s = String::from("t,x1,x4\n");
    for k in 0..traj.len() {
        let x = traj.state(k);
        let _ = writeln!(s, "{},{},{}", traj.t[k], x[0], x[3]);
    }
    s
}

/// The true local rates of the two observed closed loops at the origin (`β*_A`, `β*_B`).
pub(crate) fn true_rates() -> Result<[f64; 2]> {
    let truth_sys =
        G5::new(G5Config { gamma: 0.0, k1: K1, k4: K4, ..G5Config::paper(Coupling::Cascade) })?;
    let r = truth_sys.rates_at_origin();
    Ok([r.a, r.b])
}

/// Table III's header.
const TABLE3_HEADER: [&str; 4] = ["Quantity", "Symbol", "paper", "ours (mean ± std)"];

/// Table III over the seeds, beside the paper's values.
fn table3(results: &[SeedResult], true_rates: [f64; 2]) -> Vec<Vec<String>> {
    let gamma_true = (true_rates[0] * true_rates[1]).sqrt();
    let col = |f: &dyn Fn(&SeedResult) -> f64| results.iter().map(f).collect::<Vec<f64>>();
    let level = |l: usize| col(&|s| s.gammas.map_or(f64::NAN, |g| g[l]));
    vec![
        vec![
            "Subsystem A local cert. rate".into(),
            "β_A_cert".into(),
            "≈ 0.80".into(),
            pm(&col(&|s| s.cert[0]), 3),
        ],
        vec![
            "Subsystem B local cert. rate".into(),
            "β_B_cert".into(),
            "≈ 1.20".into(),
            pm(&col(&|s| s.cert[1]), 3),
        ],
        vec![
            "Point estimates β̂_A, β̂_B".into(),
            "β̂".into(),
            "(not given)".into(),
            format!("{}, {}", pm(&col(&|s| s.nominal[0]), 3), pm(&col(&|s| s.nominal[1]), 3)),
        ],
        vec![
            "True local rates at the origin".into(),
            "β*_A, β*_B".into(),
            "(not given)".into(),
            format!("{}, {} (−k1, 1 − k4)", true_rates[0], true_rates[1]),
        ],
        vec![
            "Certified warning threshold".into(),
            "γ_warn".into(),
            "≈ 0.98".into(),
            pm(&col(&|s| s.warn), 3),
        ],
        vec![
            "True loss of contraction (bidirectional)".into(),
            "γ_true".into(),
            "> γ_warn".into(),
            format!("{gamma_true:.3}"),
        ],
        vec![
            "Safe simulation coupling".into(),
            format!("γ_safe = {SAFE_FACTOR} γ_warn"),
            "≈ 0.54".into(),
            pm(&level(0), 3),
        ],
        vec![
            "Warning-zone coupling".into(),
            "γ_warned (midpoint)".into(),
            "≈ 1.10".into(),
            pm(&level(1), 3),
        ],
        vec![
            "Unsafe coupling".into(),
            format!("γ_unsafe = {UNSAFE_FACTOR} γ_true"),
            "1.08 γ_true".into(),
            pm(&level(2), 3),
        ],
        vec![
            "First gate opening A, B [s]".into(),
            "t*_A, t*_B".into(),
            "(not given)".into(),
            format!(
                "{}, {}",
                pm(&col(&|s| s.t_star[0].unwrap_or(f64::NAN)), 2),
                pm(&col(&|s| s.t_star[1].unwrap_or(f64::NAN)), 2)
            ),
        ],
        vec![
            "max |Lemma 1 − N-subsystem rate| over the sweep".into(),
            "".into(),
            "".into(),
            format!("{:.1e}", col(&|s| s.lemma_vs_network).iter().fold(0.0f64, |a, b| a.max(*b))),
        ],
    ]
}

/// The coupled simulations' header.
const COUPLED_HEADER: [&str; 6] = [
    "Coupling",
    "level",
    "paper prediction",
    "diverged (seeds)",
    "peak ‖x‖ after impulse",
    "final ‖x‖ at 14 s",
];

/// The coupled simulations per coupling and level over the seeds.
fn coupled_rows(results: &[SeedResult]) -> Vec<Vec<String>> {
    let mut out_rows = Vec::new();
    let prediction =
        ["returns near the origin", "slower recovery, higher peak", "grows without bound"];
    for (c, name) in ["Bidirectional", "Cascade"].iter().enumerate() {
        for (l, lname) in ["γ_safe", "γ_warned", "γ_unsafe"].iter().enumerate() {
            let sel: Vec<&Outcome> =
                results.iter().filter_map(|s| s.outcomes.get(c).map(|o| &o[l])).collect();
            let div = sel.iter().filter(|o| o.diverged).count();
            let peaks: Vec<f64> = sel.iter().map(|o| o.peak).collect();
            let ends: Vec<f64> = sel.iter().filter(|o| !o.diverged).map(|o| o.end).collect();
            out_rows.push(vec![
                (*name).into(),
                (*lname).into(),
                prediction[l].into(),
                format!("{div} of {}", sel.len()),
                pm(&peaks, 2),
                pm(&ends, 3),
            ]);
        }
    }
    out_rows
}

/// Run Experiment 2; return the REPORT.md section.
pub(crate) fn run(p: &Params, out: &Path) -> Result<String> {
    let dir = out.join("exp2");
    let true_rates = true_rates()?;
    let bar = progress(p.seeds, "experiment 2");
    let mut results = Vec::with_capacity(p.seeds);
    for run in 0..p.seeds {
        let (res, traj, ev) = run_seed(p, run, true_rates)?;
        if run == 0 {
            write(&dir.join("trace_seed0.csv"), &trace_csv(&traj))?;
            write_evidence(&dir.join("evidence_a_seed0.csv"), &ev[0])?;
            write_evidence(&dir.join("evidence_b_seed0.csv"), &ev[1])?;
            figures(p, out, &traj, &ev, &res, true_rates)?;
        }
        results.push(res);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let (header, rows) = (TABLE3_HEADER, table3(&results, true_rates));
    write(&dir.join("table3.md"), &markdown(&header, &rows))?;
    write(&dir.join("table3.csv"), &csv(&header, &rows))?;

    let (out_header, out_rows) = (COUPLED_HEADER, coupled_rows(&results));
    write(&dir.join("coupled.md"), &markdown(&out_header, &out_rows))?;

    let mut s = String::new();
    let _ = writeln!(s, "## Experiment 2: compositional certification (Section V-C)\n");
    let _ = writeln!(
        s,
        "K = diag({K1}, {K4}), σ = {SIGMA} (Gaussian, into x4{}), β_margin = {MARGIN}, {} s of disconnected data (γ = 0) per subsystem under K plus PRBS dither, local certificates = median of β̂ − ρ over the last 3 s, {} seeds. Network rates use the N-subsystem machinery (`network_rate` with two nodes), checked against Lemma 1 over the sweep γ ∈ [0, {SWEEP_MAX}].\n",
        if p.exp2_noise_on_a { " and x1" } else { "" },
        DATA_STEPS as f64 * p.dt,
        p.seeds
    );
    let _ = writeln!(s, "### Table III\n\n{}", markdown(&header, &rows));
    let _ = writeln!(
        s,
        "### Coupled simulations (14 s, impulse {IMPULSE} into x4 at {IMPULSE_TIME} s, u = K y)\n\n{}",
        markdown(&out_header, &out_rows)
    );
    let _ = writeln!(
        s,
        "Figures: `fig6_exp2_local.png`, `fig7_exp2_margin.png`, `fig8_exp2_response.png` (seed 0).\n\n![local](fig6_exp2_local.png)\n\n![margin](fig7_exp2_margin.png)\n\n![response](fig8_exp2_response.png)\n"
    );
    Ok(s)
}

/// Each seed's local certificates `(β_A_cert, β_B_cert)`, the median Gaussian certificate
/// over the last 3 s (as Table III), for the sensitivity study.
pub(crate) fn local_rates_per_seed(p: &Params) -> Result<Vec<[f64; 2]>> {
    let mut out = Vec::with_capacity(p.seeds);
    for run in 0..p.seeds {
        let traj = data_run(p, run)?;
        let mut rates = [f64::NAN; 2];
        for (i, k) in [(0usize, K1), (1, K4)] {
            let ev = certify(p, &traj, i, k, MARGIN)?;
            let t_end = traj.t[traj.len() - 1];
            let last: Vec<f64> = (0..traj.len())
                .filter(|&j| traj.t[j] > t_end - 3.0 + 1e-9)
                .filter_map(|j| ev[j].gaussian.value)
                .collect();
            rates[i] = median(&last);
        }
        out.push(rates);
    }
    Ok(out)
}
