//! The nonlinear certificate's trimmed region: the quantiles of the window's outputs, inside
//! the bounding box of the same window; the gate closed while the output lies outside the
//! standing look's region; the edge-slope factor (1 where the slope does not vary); a
//! checkpoint that resumes bit for bit with the region's values. The loop: `nonlinear.rs`'s
//! cubic at 40× the margin.

use streamcert::certificate::{
    Certifier, CertifierConfig, Interval, NonlinearConfig, NotCertified,
};
use streamcert::dynamics::Trajectory;

use crate::nonlinear::{config, cubic_40x};

/// The degree-2 certifier with the region trimmed by `trim` (0: the bounding box).
fn trimmed(trim: f64) -> CertifierConfig {
    let mut cfg = config(-1.0, 0.05, 50, 2);
    cfg.nonlinear = Some(NonlinearConfig { region_trim: trim, ..NonlinearConfig::with_degree(2) });
    cfg
}

fn run(cfg: &CertifierConfig, traj: &Trajectory) -> Certifier {
    let mut cert = Certifier::new(cfg.clone()).expect("valid");
    for i in 0..traj.t.len() {
        cert.push(traj.t[i], &traj.y[i..=i], &traj.u[i..=i]).expect("finite data");
    }
    cert
}

/// The default is degree 2 over the 2.5–97.5 % quantiles.
#[test]
fn the_default_is_degree_2_over_the_quantiles() {
    let d = NonlinearConfig::default();
    assert_eq!((d.degree, d.region_trim, d.check_terms), (2, 0.025, 2));
    let extra: Vec<String> = d.check_features().into_iter().map(|f| f.name()).collect();
    assert_eq!(extra, ["y^3", "y^4"]);
}

/// Every window's trimmed region lies inside its bounding box on the same data, is strictly
/// inside it on the longest window, and leaves out about `2 q` of the window's outputs: at
/// most `2 q` of the column starts, with the window's last samples and the open block as
/// slack.
#[test]
fn the_trimmed_region_is_inside_the_bounding_box_and_leaves_out_the_tails() {
    let traj = cubic_40x().run(3).expect("valid scenario");
    let (cut, full) = (run(&trimmed(0.025), &traj), run(&trimmed(0.0), &traj));
    let (looks, boxes) = (cut.nonlinear_looks(), full.nonlinear_looks());
    let mut compared = 0;
    for (a, b) in looks.iter().zip(boxes).filter_map(|(a, b)| a.zip(*b)) {
        assert_eq!((a.window, a.look), (b.window, b.look));
        let (r, hull) = (a.region, b.region);
        assert!(hull.lo <= r.lo && r.hi <= hull.hi, "window {}: {r:?} in {hull:?}", a.window);
        // The window's samples up to its look, with one block and one column's samples of
        // slack.
        let n = traj.t.iter().position(|&t| t == a.t).expect("a sample time") + 1;
        let span = a.window + 2 * 5;
        let outside =
            traj.y[n - span..n].iter().filter(|&&y| !(r.lo <= y && y <= r.hi)).count() as f64;
        assert!(outside / span as f64 <= 0.05 + 12.0 / span as f64, "window {}", a.window);
        compared += 1;
    }
    assert!(compared >= 3, "{compared} windows compared");
    let longest = looks.iter().rev().flatten().next().expect("a look");
    let hull = boxes.iter().rev().flatten().next().expect("a look").region;
    assert!(longest.region.lo > hull.lo && longest.region.hi < hull.hi);
}

/// Wherever the nonlinear gate is open the output lies in the standing look's region; where
/// the output has left it, the gate is closed with that reason, naming the output and the
/// region; and the gate still opens (the loop is 40× the margin).
#[test]
fn the_gate_is_closed_while_the_output_is_outside_the_region() {
    let mut outside = 0;
    let mut opened = 0;
    for seed in 0..4 {
        let traj = cubic_40x().run(seed).expect("valid scenario");
        let mut cert = Certifier::new(trimmed(0.025)).expect("valid");
        for i in 0..traj.t.len() {
            let ev = cert.push(traj.t[i], &traj.y[i..=i], &traj.u[i..=i]).expect("finite");
            let y = traj.y[i];
            let nl = ev.nonlinear;
            if nl.open {
                let r = ev.nonlinear_region.expect("an open gate has a region");
                assert!(r.lo <= y && y <= r.hi, "open at y = {y} outside {r:?}");
                opened += 1;
            }
            if let Some(NotCertified::OutsideRegion { y: at, lo, hi }) = nl.reason {
                assert_eq!(at, y);
                assert_eq!(ev.nonlinear_region, Some(Interval { lo, hi }));
                assert!(!(lo <= y && y <= hi));
                outside += 1;
            }
        }
    }
    assert!(opened > 0 && outside > 0, "opened at {opened}, outside at {outside} samples");
}

/// With degree 1 the slope does not vary over the region: the radius is `c · s` everywhere,
/// so the edge-slope factor is 1; with degree 2 it is above 1.
#[test]
fn the_edge_slope_factor_is_one_where_the_slope_is_constant() {
    let traj = cubic_40x().run(1).expect("valid scenario");
    let mut linear = trimmed(0.025);
    linear.nonlinear = Some(NonlinearConfig::with_degree(1));
    let cert = run(&linear, &traj);
    let mut seen = 0;
    for look in cert.nonlinear_looks().iter().flatten() {
        let e = look.edge_factor.expect("a spread");
        assert!((e - 1.0).abs() < 1e-9, "window {}: {e}", look.window);
        seen += 1;
    }
    assert!(seen > 0);
    let quadratic = run(&trimmed(0.025), &traj);
    let look = quadratic.nonlinear_looks().iter().rev().flatten().next().expect("a look");
    assert!(look.edge_factor.expect("a spread") > 1.0);
}

/// A checkpoint mid-run, with the trimmed region's values, resumes bit for bit; a damaged
/// value count is refused.
#[test]
fn a_checkpoint_with_the_region_values_resumes_bit_for_bit() {
    let traj = cubic_40x().run(2).expect("valid scenario");
    let cfg = trimmed(0.025);
    let split = 2500;
    let mut first = Certifier::new(cfg.clone()).expect("valid");
    let mut all = Vec::new();
    let (mut sealed, mut text) = (Vec::new(), String::new());
    for i in 0..traj.t.len() {
        all.push(first.push(traj.t[i], &traj.y[i..=i], &traj.u[i..=i]).expect("finite"));
        if i + 1 == split {
            sealed = first.checkpoint().expect("serialises");
            text = first.checkpoint_json().expect("serialises");
        }
    }
    assert!(text.contains("block_values"));
    let mut second = Certifier::restore(&sealed).expect("restores");
    assert_eq!(Certifier::restore(&text).expect("the export restores"), second);
    for (k, want) in all.iter().enumerate().skip(split) {
        let ev = second.push(traj.t[k], &traj.y[k..=k], &traj.u[k..=k]).expect("finite");
        assert_eq!(&ev, want, "row {k}");
    }
    // One value dropped from a block ring: refused, not a panic at the next look.
    let at = text.find("\"block_values\":[").expect("values") + "\"block_values\":[".len();
    let comma = at + text[at..].find(',').expect("two values");
    let mut damaged = text.clone();
    damaged.replace_range(at..=comma, "");
    let resealed = crate::support::reseal_json(crate::support::json_payload(&damaged), &cfg);
    let err = Certifier::restore(&resealed).unwrap_err();
    assert!(err.to_string().contains("wrong size"), "{err}");
}
