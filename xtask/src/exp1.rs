//! Experiment 1 (paper Section V-B): the Wasserstein certificate across three disturbance
//! regimes on G5, Table II, the validity table, and Figs. 3 to 5.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;
use streamcert_certificate::{CertificateKind, Certifier, Evidence};
use streamcert_dynamics::{
    Disturbance, DisturbanceConfig, G5, Impulse, Integrator, SimConfig, Trajectory, simulate,
};
use streamcert_experiments::{Experiment, Setting, regime_schedule};

mod figures;

use crate::common::{
    Params, csv, markdown, mean_std, pct, pm, progress, seed, write, write_evidence,
};

const SETTING: Setting = Experiment::One.setting();
pub(crate) const K1: f64 = SETTING.k1;
pub(crate) const K4: f64 = SETTING.k4;
const GAMMA: f64 = SETTING.gamma;
pub(crate) const MARGIN: f64 = SETTING.margin;
const IMPULSE: f64 = SETTING.impulse;

/// Regime index of time `t` (`None` at or after 30 s).
pub(crate) fn regime(t: f64) -> Option<usize> {
    (t < 30.0 - 1e-9).then(|| ((t / 10.0 + 1e-9).floor() as usize).min(2))
}

pub(crate) fn g5(p: &Params) -> Result<G5> {
    Ok(p.dataset(Experiment::One).system()?)
}

/// The data run (see `G5Dataset`): candidate gains plus PRBS dither, Experiment 1's schedule.
pub(crate) fn data_run(p: &Params, run: usize) -> Result<Trajectory> {
    Ok(p.dataset(Experiment::One).run_seeded(run as u64)?)
}

/// Certify one measured channel (`0` = A: `x1`, `u1`; `1` = B: `x4`, `u4`).
pub(crate) fn certify(
    p: &Params,
    traj: &Trajectory,
    channel: usize,
    k: f64,
    margin: f64,
) -> Result<Vec<Evidence>> {
    let mut cert = Certifier::new(p.certifier(k, margin))?;
    (0..traj.len())
        .map(|i| {
            Ok(cert.push(
                traj.t[i],
                &traj.output(i)[channel..=channel],
                &traj.input(i)[channel..=channel],
            )?)
        })
        .collect()
}

/// One seed's results.
pub(crate) struct SeedResult {
    /// `[subsystem][certificate: 0 Gauss, 1 Wass][regime]` share of steps with `β_cert > margin`.
    share: [[[f64; 3]; 2]; 2],
    /// Same, over the steps that have an estimate.
    share_est: [[[f64; 3]; 2]; 2],
    /// Share of steps with the gate open.
    gate: [[[f64; 3]; 2]; 2],
    /// Share of steps with a certificate above the true rate.
    false_cert: [[[f64; 3]; 2]; 2],
    /// Mean `ε` per regime, subsystem B.
    eps_b: [f64; 3],
    /// Mean excess kurtosis per regime, subsystem B.
    kurt_b: [f64; 3],
    decision: Decision,
}

/// The Regime-3 decision experiment (Fig. 5).
pub(crate) struct Decision {
    t_decide: f64,
    how: &'static str,
    gauss_b: f64,
    wass_b: f64,
    eps_b: f64,
    deploy: [[Option<f64>; 2]; 2],
    cost: [f64; 2],
    response: [Vec<(f64, f64)>; 2],
    cumulative: [Vec<(f64, f64)>; 2],
}

/// The paper's two certificates, in the order of the tables' `[certificate]` index.
const PAPER: [CertificateKind; 2] = [CertificateKind::Gaussian, CertificateKind::Wasserstein];

fn cert_of(e: &Evidence, which: usize) -> Option<f64> {
    e.verdict(PAPER[which]).value
}

fn open_of(e: &Evidence, which: usize) -> bool {
    e.verdict(PAPER[which]).open
}

fn decide(
    p: &Params,
    sys: &G5,
    traj: &Trajectory,
    ev: &[Vec<Evidence>; 2],
    run: usize,
) -> Result<Decision> {
    let r3: Vec<usize> = (0..traj.len()).filter(|&k| regime(traj.t[k]) == Some(2)).collect();
    let disagree = r3.iter().copied().find(|&k| {
        let (g, w) = (ev[1][k].gaussian.value, ev[1][k].wasserstein.value);
        matches!((g, w), (Some(g), Some(w)) if (g > MARGIN) != (w > MARGIN))
    });
    let (k0, how) = match disagree {
        Some(k) => {
            (k, "first Regime-3 step where the two certificates of B disagree about the margin")
        }
        None => {
            match r3.iter().copied().find(|&k| ev[1][k].gaussian.open || ev[1][k].wasserstein.open)
            {
                Some(k) => {
                    (k, "no disagreement in Regime 3; first Regime-3 step with a gate of B open")
                }
                None => (r3[0], "no certificate of B opened in Regime 3; start of Regime 3"),
            }
        }
    };
    let t0 = traj.t[k0];
    // Deployment time of subsystem i under policy P: first time >= t0 with P's gate open.
    let mut deploy = [[None; 2]; 2];
    for (pol, row) in deploy.iter_mut().enumerate() {
        for (i, d) in row.iter_mut().enumerate() {
            *d = (k0..traj.len()).find(|&k| open_of(&ev[i][k], pol)).map(|k| traj.t[k]);
        }
    }
    let steps = ((30.0 - t0) / p.dt).round() as usize;
    let mut cost = [0.0; 2];
    let mut response: [Vec<(f64, f64)>; 2] = [Vec::new(), Vec::new()];
    let mut cumulative: [Vec<(f64, f64)>; 2] = [Vec::new(), Vec::new()];
    for pol in 0..2 {
        let cfg = SimConfig {
            dt: p.dt,
            steps,
            t0,
            x0: traj.state(k0).to_vec(),
            integrator: Integrator::EulerMaruyama,
            noise_scaling: p.noise_scaling,
        };
        let eta = DisturbanceConfig {
            impulses: vec![Impulse { time: t0 + 0.1, magnitude: IMPULSE }],
            ..regime_schedule()
        };
        // Same noise realisation for both policies.
        let mut dist = [
            Disturbance::new(DisturbanceConfig::none(), seed(run, 5))?,
            Disturbance::new(eta, seed(run, 6))?,
        ];
        let [ta, tb] = deploy[pol];
        let on = |d: Option<f64>, t: f64| d.is_some_and(|d| t >= d - 1e-9);
        let out = simulate(sys, &cfg, &mut dist, |t, y, u| {
            u[0] = if on(ta, t) { K1 * y[0] } else { 0.0 };
            u[1] = if on(tb, t) { K4 * y[1] } else { 0.0 };
        })?;
        let mut acc = 0.0;
        for k in 0..out.len() {
            let sq: f64 = out.state(k).iter().map(|v| v * v).sum();
            if k + 1 < out.len() {
                acc += sq * p.dt;
            }
            response[pol].push((out.t[k], sq.sqrt()));
            cumulative[pol].push((out.t[k], acc));
        }
        cost[pol] = acc;
    }
    let e = &ev[1][k0];
    Ok(Decision {
        t_decide: t0,
        how,
        gauss_b: e.gaussian.value.unwrap_or(f64::NAN),
        wass_b: e.wasserstein.value.unwrap_or(f64::NAN),
        eps_b: e.eps().unwrap_or(f64::NAN),
        deploy,
        cost,
        response,
        cumulative,
    })
}

/// One seed: summary, data trajectory, evidence of A and B, true rates per step.
type SeedRun = (SeedResult, Trajectory, [Vec<Evidence>; 2], Vec<[f64; 2]>);

fn run_seed(p: &Params, run: usize) -> Result<SeedRun> {
    let sys = g5(p)?;
    let traj = data_run(p, run)?;
    let ev = [certify(p, &traj, 0, K1, MARGIN)?, certify(p, &traj, 1, K4, MARGIN)?];
    let truth: Vec<[f64; 2]> = (0..traj.len())
        .map(|k| {
            let r = sys.observed_closed_loop_rates(traj.state(k));
            [r.a, r.b]
        })
        .collect();
    let mut share = [[[0.0; 3]; 2]; 2];
    let mut share_est = share;
    let mut gate = share;
    let mut false_cert = share;
    let (mut eps_b, mut kurt_b) = ([0.0; 3], [0.0; 3]);
    for r in 0..3 {
        let ks: Vec<usize> = (0..traj.len()).filter(|&k| regime(traj.t[k]) == Some(r)).collect();
        let n = ks.len() as f64;
        for i in 0..2 {
            for w in 0..2 {
                let certs: Vec<(usize, f64)> =
                    ks.iter().filter_map(|&k| cert_of(&ev[i][k], w).map(|c| (k, c))).collect();
                let above = certs.iter().filter(|(_, c)| *c > MARGIN).count() as f64;
                share[i][w][r] = above / n;
                share_est[i][w][r] =
                    if certs.is_empty() { f64::NAN } else { above / certs.len() as f64 };
                gate[i][w][r] = ks.iter().filter(|&&k| open_of(&ev[i][k], w)).count() as f64 / n;
                false_cert[i][w][r] = if certs.is_empty() {
                    f64::NAN
                } else {
                    certs.iter().filter(|(k, c)| *c > truth[*k][i]).count() as f64
                        / certs.len() as f64
                };
            }
        }
        let eps: Vec<f64> = ks.iter().filter_map(|&k| ev[1][k].eps()).collect();
        eps_b[r] = mean_std(&eps).0;
        let kurt: Vec<f64> =
            ks.iter().filter_map(|&k| ev[1][k].ambiguity.and_then(|a| a.kurtosis)).collect();
        kurt_b[r] = mean_std(&kurt).0;
    }
    let decision = decide(p, &sys, &traj, &ev, run)?;
    Ok((
        SeedResult { share, share_est, gate, false_cert, eps_b, kurt_b, decision },
        traj,
        ev,
        truth,
    ))
}

/// Table II shares of all seeds: `f(seed) -> value`.
fn collect(results: &[SeedResult], f: impl Fn(&SeedResult) -> f64) -> Vec<f64> {
    results.iter().map(f).collect()
}

/// The states, the regime and the true rates per step (the evidence is in
/// `evidence_{a,b}_seed0.csv`, written by [`write_evidence`]).
fn trace_csv(traj: &Trajectory, truth: &[[f64; 2]]) -> String {
    let mut s = String::from("t,regime,x1,x2,x3,x4,x5,beta_true_a,beta_true_b\n");
    for k in 0..traj.len() {
        let x = traj.state(k);
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{}",
            traj.t[k],
            regime(traj.t[k]).map_or(String::new(), |r| (r + 1).to_string()),
            x[0],
            x[1],
            x[2],
            x[3],
            x[4],
            truth[k][0],
            truth[k][1]
        );
    }
    s
}

/// Run Experiment 1 over `p.seeds` seeds; write traces, tables and figures under `out`;
/// return the REPORT.md section.
pub(crate) fn run(p: &Params, out: &Path) -> Result<String> {
    let dir = out.join("exp1");
    let bar = progress(p.seeds, "experiment 1");
    let mut results = Vec::with_capacity(p.seeds);
    for run in 0..p.seeds {
        let (res, traj, ev, truth) = run_seed(p, run)?;
        if run == 0 {
            write(&dir.join("trace_seed0.csv"), &trace_csv(&traj, &truth))?;
            write_evidence(&dir.join("evidence_a_seed0.csv"), &ev[0])?;
            write_evidence(&dir.join("evidence_b_seed0.csv"), &ev[1])?;
            figures::figures(out, &traj, &ev, &res.decision)?;
        }
        results.push(res);
        bar.inc(1);
    }
    bar.finish_and_clear();

    let t = tables(&results);
    write(&dir.join("table2.md"), &markdown(&TABLE2_HEADER, &t.table2))?;
    write(&dir.join("table2.csv"), &csv(&TABLE2_HEADER, &t.table2))?;
    write(&dir.join("validity.md"), &markdown(&VALIDITY_HEADER, &t.validity))?;
    write(&dir.join("validity.csv"), &csv(&VALIDITY_HEADER, &t.validity))?;
    write(&dir.join("decision.md"), &markdown(&DECISION_HEADER, &t.decision))?;
    Ok(report(p, &results, &t))
}

/// Table II's header: the paper's shares beside ours for both subsystems.
const TABLE2_HEADER: [&str; 8] = [
    "Regime",
    "Noise",
    "paper Gauss",
    "paper Wass",
    "ours B Gauss",
    "ours B Wass",
    "ours A Gauss",
    "ours A Wass",
];

/// Subsystem B's shares over the steps that have an estimate, with the gates and the radius.
const ESTIMATE_HEADER: [&str; 7] = [
    "Regime",
    "B Gauss (steps with an estimate)",
    "B Wass (steps with an estimate)",
    "B Gauss gate open",
    "B Wass gate open",
    "mean ε (B)",
    "mean κ_e (B)",
];

/// The validity table's header (the share of certified steps above the true rate).
const VALIDITY_HEADER: [&str; 5] = ["Regime", "A Gauss", "A Wass", "B Gauss", "B Wass"];

/// The Regime-3 decision's header.
const DECISION_HEADER: [&str; 3] = ["Quantity", "paper", "ours (mean ± std over seeds)"];

/// Experiment 1's tables over the seeds, rows under the headers above.
struct Tables {
    table2: Vec<Vec<String>>,
    estimate: Vec<Vec<String>>,
    validity: Vec<Vec<String>>,
    decision: Vec<Vec<String>>,
}

/// The tables from every seed's result.
fn tables(results: &[SeedResult]) -> Tables {
    let paper = [
        ("Regime 1", "Gaussian (σ0 = 0.08)", "94 %", "100 %"),
        ("Regime 2", "Laplace (κ ≈ 3)", "78 %", "83 %"),
        ("Regime 3", "Spikes (5.5 %, 4.5–7.5 σ0)", "33 %", "73 %"),
    ];
    let rows: Vec<Vec<String>> = (0..3)
        .map(|r| {
            let (name, noise, pg, pw) = paper[r];
            vec![
                name.into(),
                noise.into(),
                pg.into(),
                pw.into(),
                pct(&collect(results, |s| s.share[1][0][r])),
                pct(&collect(results, |s| s.share[1][1][r])),
                pct(&collect(results, |s| s.share[0][0][r])),
                pct(&collect(results, |s| s.share[0][1][r])),
            ]
        })
        .collect();

    let est_rows: Vec<Vec<String>> = (0..3)
        .map(|r| {
            vec![
                paper[r].0.into(),
                pct(&collect(results, |s| s.share_est[1][0][r])),
                pct(&collect(results, |s| s.share_est[1][1][r])),
                pct(&collect(results, |s| s.gate[1][0][r])),
                pct(&collect(results, |s| s.gate[1][1][r])),
                pm(&collect(results, |s| s.eps_b[r]), 3),
                pm(&collect(results, |s| s.kurt_b[r]), 2),
            ]
        })
        .collect();

    let validity_rows: Vec<Vec<String>> = (0..3)
        .map(|r| {
            vec![
                paper[r].0.into(),
                pct(&collect(results, |s| s.false_cert[0][0][r])),
                pct(&collect(results, |s| s.false_cert[0][1][r])),
                pct(&collect(results, |s| s.false_cert[1][0][r])),
                pct(&collect(results, |s| s.false_cert[1][1][r])),
            ]
        })
        .collect();

    let dec = |f: &dyn Fn(&Decision) -> f64| collect(results, |s| f(&s.decision));
    let ratio = dec(&|d| d.cost[0] / d.cost[1]);
    let disagreements =
        results.iter().filter(|s| s.decision.how.starts_with("first Regime-3 step where")).count();
    let dec_rows = vec![
        vec!["decision time t_decide [s]".into(), "24.32".into(), pm(&dec(&|d| d.t_decide), 2)],
        vec![
            "Gaussian certificate of B at t_decide".into(),
            "−1.61".into(),
            pm(&dec(&|d| d.gauss_b), 3),
        ],
        vec![
            "Wasserstein certificate of B at t_decide".into(),
            "0.22".into(),
            pm(&dec(&|d| d.wass_b), 3),
        ],
        vec!["ε of B at t_decide".into(), "0.13".into(), pm(&dec(&|d| d.eps_b), 3)],
        vec!["cost ratio Gaussian / Wasserstein policy".into(), "3.2×".into(), pm(&ratio, 3)],
        vec![
            "seeds where the certificates disagreed in Regime 3".into(),
            "(all, implied)".into(),
            format!("{disagreements} of {}", results.len()),
        ],
    ];

    Tables { table2: rows, estimate: est_rows, validity: validity_rows, decision: dec_rows }
}

/// The REPORT.md section of Experiment 1.
fn report(p: &Params, results: &[SeedResult], t: &Tables) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "## Experiment 1: Wasserstein certificate across three regimes (Section V-B)\n"
    );
    let _ = writeln!(
        s,
        "G5 ({:?} coupling), γ = {GAMMA}, K = diag({K1}, {K4}), 30 s at dt = {}, β_margin = {MARGIN}, {} seeds. Data are collected under the candidate K plus PRBS dither (in open loop G5's node 2 escapes in finite time); the certificates evaluate K. Subsystem B (x4) is where the disturbance η enters; the paper does not say which subsystem Table II is about, so both are shown.\n",
        p.coupling, p.dt, p.seeds
    );
    let _ = writeln!(
        s,
        "### Table II: share of steps with β_cert > β_margin (all steps of the regime, including the warm-up)\n\n{}",
        markdown(&TABLE2_HEADER, &t.table2)
    );
    let _ = writeln!(
        s,
        "Same regimes, subsystem B, over the steps that have an estimate, with the gates and the radius:\n\n{}",
        markdown(&ESTIMATE_HEADER, &t.estimate)
    );
    let _ = writeln!(
        s,
        "### Regime-3 decision and cost (Fig. 5)\n\nDecision point: {} (seed 0: t = {:.2} s). From there the plant is simulated twice with the same noise and an impulse of {IMPULSE} into x4 0.1 s later; each subsystem's controller is switched on when that policy's gate of that subsystem is open in the data run.\n\n{}",
        results[0].decision.how,
        results[0].decision.t_decide,
        markdown(&DECISION_HEADER, &t.decision)
    );
    let _ = writeln!(
        s,
        "### Validity (not reported by the paper): share of certified steps with β_cert above the true rate β*(x(t))\n\nTrue rates: β*_A = tanh x1 + x1 sech² x1 − k1 along the trajectory, β*_B = 1 − k4 = 5.\n\n{}",
        markdown(&VALIDITY_HEADER, &t.validity)
    );
    let _ = writeln!(
        s,
        "Figures: `fig3_exp1_certificates.png`, `fig4_exp1_surface.png`, `fig5_exp1_response.png` (seed 0; SVG beside each).\n"
    );
    let _ = writeln!(
        s,
        "![certificates](fig3_exp1_certificates.png)\n\n![surface](fig4_exp1_surface.png)\n\n![response](fig5_exp1_response.png)\n"
    );
    s
}

/// Subsystem B's Table II shares in one seed, `[certificate: 0 Gauss, 1 Wass][regime]`: over
/// all the regime's steps, and over its steps that have an estimate.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SharesB {
    pub(crate) all: [[f64; 3]; 2],
    pub(crate) with_estimate: [[f64; 3]; 2],
}

/// Subsystem B's Table II shares for every seed (the sensitivity study).
pub(crate) fn shares_per_seed(p: &Params) -> Result<Vec<SharesB>> {
    (0..p.seeds)
        .map(|run| {
            let (res, ..) = run_seed(p, run)?;
            Ok(SharesB { all: res.share[1], with_estimate: res.share_est[1] })
        })
        .collect()
}
