//! `streamcert simulate g5`: a G5 data set in the CSV layout `certify` reads.

use std::io::Write;

use streamcert_dynamics::Coupling;
use streamcert_experiments::{Experiment, G5Dataset};

use crate::CliError;

/// Write `t,y_a,u_a,y_b,u_b` (and the states and the true local rates) for run `seed` of the
/// experiment, exactly the data of `cargo xtask reproduce` run `seed` (the seed rule is
/// `G5Dataset::seeds`), optionally with another number of steps or another coupling gain.
///
/// # Errors
/// [`CliError::Io`] on a write error.
pub fn run<W: Write>(
    experiment: Experiment,
    coupling: Coupling,
    seed: u64,
    steps: Option<usize>,
    gamma: Option<f64>,
    out: &mut W,
) -> Result<(), CliError> {
    if let Some(g) = gamma.filter(|g| !(*g >= 0.0 && g.is_finite())) {
        return Err(CliError::Input {
            file: "simulate".into(),
            message: format!("--gamma must be finite and >= 0, got {g}"),
        });
    }
    let ds = G5Dataset { coupling, steps, gamma, ..G5Dataset::defaults(experiment) };
    let traj = ds
        .run_seeded(seed)
        .map_err(|e| CliError::Input { file: "simulate".into(), message: e.to_string() })?;
    let sys = ds
        .system()
        .map_err(|e| CliError::Input { file: "simulate".into(), message: e.to_string() })?;
    let io = |e| CliError::io("writing the data set", e);
    writeln!(out, "t,y_a,u_a,y_b,u_b,x1,x2,x3,x4,x5,beta_true_a,beta_true_b").map_err(io)?;
    for k in 0..traj.len() {
        let (x, y, u) = (traj.state(k), traj.output(k), traj.input(k));
        let r = sys.observed_closed_loop_rates(x);
        writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{},{}",
            traj.t[k], y[0], u[0], y[1], u[1], x[0], x[1], x[2], x[3], x[4], r.a, r.b
        )
        .map_err(io)?;
    }
    out.flush().map_err(io)
}
