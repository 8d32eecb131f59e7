//! Simulate G5 with the paper's parameters and write the trajectories.

use std::fmt::Write as _;
use std::fs;

use anyhow::{Context, Result};
use streamcert_dynamics::{
    Coupling, Disturbance, DisturbanceConfig, Dither, DitherConfig, Dynamics, G5, G5Config,
    Integrator, NoiseScaling, Process, SimConfig, Trajectory, simulate,
};

use crate::Options;

/// Dither used for excitation (the paper gives none; see `Dither`).
const DITHER: DitherConfig = DitherConfig::Prbs { amplitude: 0.3, hold: 0.1 };

fn write_csv(path: &std::path::Path, g5: &G5, traj: &Trajectory) -> Result<()> {
    let mut s =
        String::from("t,x1,x2,x3,x4,x5,y_a,y_b,u1,u4,eta_a,eta_b,beta_true_a,beta_true_b\n");
    for k in 0..traj.len() {
        let x = traj.state(k);
        let (y, u) = (traj.output(k), traj.input(k));
        let eta = if k + 1 < traj.len() { traj.disturbance(k).to_vec() } else { vec![0.0; 2] };
        let rates = g5.observed_closed_loop_rates(x);
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            traj.t[k],
            x[0],
            x[1],
            x[2],
            x[3],
            x[4],
            y[0],
            y[1],
            u[0],
            u[1],
            eta[0],
            eta[1],
            rates.a,
            rates.b
        );
    }
    fs::write(path, s).with_context(|| format!("writing {}", path.display()))
}

fn run_one(g5: &G5, steps: usize, dist: [DisturbanceConfig; 2], seed: u64) -> Result<Trajectory> {
    let cfg = SimConfig {
        dt: 0.02,
        steps,
        t0: 0.0,
        x0: vec![0.0; g5.state_dim()],
        integrator: Integrator::EulerMaruyama,
        noise_scaling: NoiseScaling::Sde,
    };
    let [da, db] = dist;
    let mut d = [Disturbance::new(da, seed)?, Disturbance::new(db, seed.wrapping_add(1))?];
    let mut dith_a = Dither::new(DITHER, seed.wrapping_add(2))?;
    let mut dith_b = Dither::new(DITHER, seed.wrapping_add(3))?;
    let (k1, k4) = (g5.config().k1, g5.config().k4);
    Ok(simulate(g5, &cfg, &mut d, |t, y, u| {
        u[0] = k1 * y[0] + dith_a.value(t);
        u[1] = k4 * y[1] + dith_b.value(t);
    })?)
}

/// `cargo xtask reproduce`: trajectories for both experiments.
pub(crate) fn run(opts: &Options) -> Result<()> {
    fs::create_dir_all(&opts.out).with_context(|| format!("creating {}", opts.out.display()))?;
    for coupling in [Coupling::Cascade, Coupling::Bidirectional] {
        let name = match coupling {
            Coupling::Cascade => "cascade",
            Coupling::Bidirectional => "bidirectional",
        };
        // Experiment 1: γ = 0.15, K = diag(−3.5, −4.0), 30 s, three regimes on η.
        let g5 =
            G5::new(G5Config { gamma: 0.15, k1: -3.5, k4: -4.0, ..G5Config::paper(coupling) })?;
        let traj = run_one(
            &g5,
            1500,
            [DisturbanceConfig::none(), DisturbanceConfig::experiment1()],
            opts.seed,
        )?;
        write_csv(&opts.out.join(format!("exp1_g5_{name}.csv")), &g5, &traj)?;
    }
    // Experiment 2 data: γ = 0, K = diag(−2.5, −3.0), σ = 0.10 on both subsystems, 16 s.
    let g5 = G5::new(G5Config::paper(Coupling::Cascade))?;
    let noise = DisturbanceConfig::stationary(Process::Gaussian { sigma: 0.10 });
    let traj = run_one(&g5, 800, [noise.clone(), noise], opts.seed)?;
    write_csv(&opts.out.join("exp2_g5_disconnected.csv"), &g5, &traj)?;

    let meta = serde_json::json!({
        "seed": opts.seed,
        "dt": 0.02,
        "integrator": "euler_maruyama",
        "noise_scaling": "sde",
        "dither": serde_json::to_value(DITHER)?,
        "exp1": { "gamma": 0.15, "k": [-3.5, -4.0], "steps": 1500,
                  "disturbance_b": serde_json::to_value(DisturbanceConfig::experiment1())? },
        "exp2": { "gamma": 0.0, "k": [-2.5, -3.0], "steps": 800, "sigma": 0.10 },
        "note": "Trajectories only: the certificate experiments land with their crates."
    });
    fs::write(opts.out.join("meta.json"), serde_json::to_string_pretty(&meta)?)?;
    println!("wrote trajectories and meta.json to {}", opts.out.display());
    Ok(())
}
