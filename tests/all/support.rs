//! Shared helpers for the known-answer tests.

use streamcert::certificate::{Certifier, CertifierConfig, Evidence};
use streamcert::dynamics::{LinearScenario, Process, Trajectory};

/// Run a scenario that is valid by construction.
pub(crate) fn run(scenario: &LinearScenario, seed: u64) -> Trajectory {
    scenario.run(seed).expect("valid scenario")
}

/// Run `cfg` on `traj` up to row `split`, checkpoint, restore, and check that every later
/// row's evidence equals `all`'s (the uninterrupted run's), bit for bit, and that the JSON
/// export restores the same state as the binary checkpoint; the export's text (for edits)
/// and the restored certifier at the end.
pub(crate) fn resume_matches(
    cfg: &CertifierConfig,
    traj: &Trajectory,
    all: &[Evidence],
    split: usize,
) -> (String, Certifier) {
    let mut first = Certifier::new(cfg.clone()).expect("valid");
    for k in 0..split {
        first.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid");
    }
    let binary = first.checkpoint().expect("serialises");
    let text = first.checkpoint_json().expect("serialises");
    let mut second = Certifier::restore(&binary).expect("restores");
    // The JSON export restores the same state.
    assert_eq!(Certifier::restore(&text).expect("restores"), second);
    for k in split..traj.len() {
        let ev = second.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid");
        assert_eq!(ev, all[k], "row {k} after a restore at {split}");
    }
    (text, second)
}

/// The JSON payload of a sealed JSON checkpoint ([`Certifier::checkpoint_json`]).
pub(crate) fn json_payload(text: &str) -> &str {
    text.split_once('\n').expect("a header line").1
}

/// A JSON payload sealed again for `cfg` with a valid checksum: past the checksum, so only
/// the state's own checks can refuse it.
pub(crate) fn reseal_json(payload: &str, cfg: &CertifierConfig) -> Vec<u8> {
    streamcert::certificate::seal(payload.as_bytes(), streamcert::certificate::Encoding::Json, cfg)
        .expect("seals")
}

/// True closed-loop rate `−λ_max(sym(A + B K))` with nalgebra's dense eigensolver (the oracle).
pub(crate) fn true_rate(a: &[f64], b: &[f64], k: &[f64], n: usize, m: usize) -> f64 {
    let a = nalgebra::DMatrix::from_row_slice(n, n, a);
    let b = nalgebra::DMatrix::from_row_slice(n, m, b);
    let k = nalgebra::DMatrix::from_row_slice(m, n, k);
    let j = a + b * k;
    let s = (&j + j.transpose()) * 0.5;
    -s.symmetric_eigen().eigenvalues.max()
}

/// `ẏ = a y + u + noise` explored by `u = k_explore y + PRBS(±dither, held 0.1 s)`, dt = 0.01,
/// 1000 steps; adjust other fields with struct update syntax.
pub(crate) fn scalar(a: f64, k_explore: f64, noise: Process, dither: f64) -> LinearScenario {
    LinearScenario {
        n: 1,
        m: 1,
        a: vec![a],
        b: vec![1.0],
        noise,
        k_explore: vec![k_explore],
        dither,
        dither_hold: 0.1,
        dt: 0.01,
        steps: 1000,
        noise_gain: None,
        sensor_noise: 0.0,
        switch: None,
    }
}

/// `base` as the coupled two-output plant of the multi-output tests: `A = [0.5 0.3; −0.2 0.2]`,
/// `B = I`, explored by `u = −y + PRBS`, for `steps` steps.
pub(crate) fn coupled_pair(base: LinearScenario, steps: usize) -> LinearScenario {
    LinearScenario {
        n: 2,
        m: 2,
        a: vec![0.5, 0.3, -0.2, 0.2],
        b: vec![1.0, 0.0, 0.0, 1.0],
        k_explore: vec![-1.0, 0.0, 0.0, -1.0],
        steps,
        ..base
    }
}
