//! [`simulate_g5`]: the paper's five-node benchmark as arrays, the data of `streamcert
//! simulate g5` (and of `cargo xtask reproduce` run `seed`).

use streamcert_dynamics::Coupling;
use streamcert_experiments::{Experiment, G5Dataset};

use crate::Error;

/// One simulated run of G5, column by column (`n` samples).
#[derive(Debug, Clone, PartialEq)]
pub struct G5Run {
    /// Times `t_k` (seconds).
    pub t: Vec<f64>,
    /// Outputs `(y_a, y_b) = (x1, x4)`, row-major `n × 2`.
    pub y: Vec<f64>,
    /// Applied inputs `(u_a, u_b)` (`u = K y + d`), row-major `n × 2`.
    pub u: Vec<f64>,
    /// States `x1 … x5`, row-major `n × 5`.
    pub x: Vec<f64>,
    /// The true observed closed-loop local rates `(β_a, β_b)` at each state, row-major `n × 2`.
    pub beta_true: Vec<f64>,
}

/// Run `seed` of experiment 1 or 2 (the seed rule is `G5Dataset::seeds`), with the
/// reproduction's defaults and optionally another number of steps, coupling structure or
/// coupling gain: the same numbers `streamcert simulate g5` prints.
///
/// # Errors
/// [`Error::Config`] for an experiment other than 1 or 2 or a gain that is not finite and
/// `≥ 0`.
pub fn simulate_g5(
    experiment: u8,
    seed: u64,
    steps: Option<usize>,
    gamma: Option<f64>,
    bidirectional: bool,
) -> Result<G5Run, Error> {
    let experiment = match experiment {
        1 => Experiment::One,
        2 => Experiment::Two,
        e => return Err(Error::Config(format!("experiment must be 1 or 2, got {e}"))),
    };
    if let Some(g) = gamma.filter(|g| !(*g >= 0.0 && g.is_finite())) {
        return Err(Error::Config(format!("gamma must be finite and >= 0, got {g}")));
    }
    let coupling = if bidirectional { Coupling::Bidirectional } else { Coupling::Cascade };
    let ds = G5Dataset { coupling, steps, gamma, ..G5Dataset::defaults(experiment) };
    let bad = |e: streamcert_dynamics::DynamicsError| Error::Config(e.to_string());
    let traj = ds.run_seeded(seed).map_err(bad)?;
    let sys = ds.system().map_err(bad)?;
    let n = traj.len();
    let mut run = G5Run {
        t: Vec::with_capacity(n),
        y: Vec::with_capacity(2 * n),
        u: Vec::with_capacity(2 * n),
        x: Vec::with_capacity(5 * n),
        beta_true: Vec::with_capacity(2 * n),
    };
    for k in 0..n {
        let (x, y, u) = (traj.state(k), traj.output(k), traj.input(k));
        let r = sys.observed_closed_loop_rates(x);
        run.t.push(traj.t[k]);
        run.y.extend_from_slice(&y[..2]);
        run.u.extend_from_slice(&u[..2]);
        run.x.extend_from_slice(&x[..5]);
        run.beta_true.extend_from_slice(&[r.a, r.b]);
    }
    Ok(run)
}
