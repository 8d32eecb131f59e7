//! Where the data barely identify the candidate: an input that never moves over a window is
//! refused as not identifying the rate, and step tests with long holds certify no unsafe
//! candidate.

use streamcert::certificate::{Certifier, NotCertified};
use streamcert::dynamics::{LinearScenario, Process};

use crate::calibrated::calibrated;
use crate::support::scalar;

/// An input held over the whole run is a multiple of the intercept's span in every window:
/// the data do not identify the input's gain. Before the calibrated fits' ridge was made
/// relative, the absolute ridge estimated that gain as zero and the gate opened on the drift
/// alone (the identification-and-units study: a candidate of true rate −0.5 deployed in most
/// runs); now every look is refused, the reason says the input has not moved, and a step
/// test with a few moves over 60 s certifies no unsafe candidate (40 runs each; the family is
/// `cargo xtask validity`'s held-input table at 2000 runs per cell).
#[test]
fn an_input_that_never_moves_is_refused_as_not_identifying_the_rate() {
    let plant = |hold: f64| LinearScenario {
        dither_hold: hold,
        dt: 0.02,
        steps: 3000,
        ..scalar(-1.0, 0.0, Process::Gaussian { sigma: 0.1 }, 1.0)
    };
    // K = 1.5: β* = 1 − K = −0.5, far below the margin.
    let cfg = calibrated(1, vec![1.5], 150, 1);
    let data = plant(1e6).run(1).expect("data");
    let mut cert = Certifier::new(cfg.clone()).expect("valid");
    let mut last = None;
    for i in 0..data.len() {
        let v = cert.push(data.t[i], data.output(i), data.input(i)).expect("sample").calibrated;
        assert!(!v.open, "opened at {}", data.t[i]);
        last = v.reason;
    }
    let Some(reason @ NotCertified::WeaklyIdentified { moves, .. }) = last else {
        panic!("reason at the end: {last:?}");
    };
    assert_eq!(moves, 0.0);
    assert!(reason.to_string().contains("has not moved"), "{reason}");
    assert_eq!(reason.kind(), "weakly_identified");
    for hold in [2.0, 10.0, 30.0] {
        for seed in 0..40 {
            let data = plant(hold).run(seed).expect("data");
            let mut cert = Certifier::new(cfg.clone()).expect("valid");
            for i in 0..data.len() {
                let v = cert.push(data.t[i], data.output(i), data.input(i)).expect("sample");
                assert!(!v.calibrated.open, "hold {hold} s, seed {seed}: opened at {}", data.t[i]);
            }
        }
    }
}

/// A closed loop logged with `u = K_e y` and nothing added: the inputs are a fixed function of
/// the outputs in every window, so every look is refused and the reason names the controller
/// and the dither; the same loop with a dither of ±1 never gives that reason, and the held
/// input of the test above keeps its own (20 seeds each).
#[test]
fn a_closed_loop_without_a_dither_is_named_as_such() {
    let plant = |dither: f64| LinearScenario {
        dt: 0.02,
        steps: 3000,
        dither_hold: 0.2,
        ..scalar(0.5, -2.0, Process::Gaussian { sigma: 0.1 }, dither)
    };
    // K = -4: β* = 3.5, far above the margin; only the data's identification decides.
    let cfg = calibrated(1, vec![-4.0], 150, 1);
    for seed in 0..20 {
        let reasons = |dither: f64| {
            let data = plant(dither).run(seed).expect("data");
            let mut cert = Certifier::new(cfg.clone()).expect("valid");
            let mut seen = Vec::new();
            for i in 0..data.len() {
                let v = cert.push(data.t[i], data.output(i), data.input(i)).expect("sample");
                seen.push((v.calibrated.open, v.calibrated.reason));
            }
            seen
        };
        let undithered = reasons(0.0);
        assert!(undithered.iter().all(|(open, _)| !open), "seed {seed}: opened");
        let Some((_, Some(last @ NotCertified::InputFollowsOutputs { .. }))) = undithered.last()
        else {
            panic!("seed {seed}: reason at the end {:?}", undithered.last());
        };
        assert_eq!(last.kind(), "input_follows_outputs");
        assert!(last.to_string().contains("add a dither"), "{last}");
        let dithered = reasons(1.0);
        assert!(
            dithered
                .iter()
                .all(|(_, r)| !matches!(r, Some(NotCertified::InputFollowsOutputs { .. }))),
            "seed {seed}: a dithered loop told to add a dither"
        );
        assert!(dithered.iter().any(|(open, _)| *open), "seed {seed}: the dithered loop certified");
    }
}
