//! The calibrated certificate's anchored window (`Calibration::anchored_share`): its looks
//! against a recompute from every column since the start, at the sizes and risks of its
//! rule; its certificate beyond the longest sliding window; a new epoch after a plant change.

use nalgebra::{DMatrix, DVector};
use streamcert::certificate::{
    Calibration, Certifier, anchored_look_risk, calibrated_radius, look_risk,
};
use streamcert::dynamics::{LinearScenario, Process};
use streamcert::regression::Model;

use crate::calibrated::{calibrated, short_window_plant};
use crate::support::{resume_matches, run as run_scenario, scalar};

const H: usize = 5;

/// At every anchored look of a 40 s run (`M = 150`, every default): the look holds the
/// anchored size `⌈30 · √2^(j−1)⌉` blocks of `h` columns (less the open record's newest
/// blocks once the records merge); its `β̂` is the instrumental-variables estimate on every
/// instrumented column since the start up to its length (nalgebra, `10⁻⁸` relative); its
/// radius is the Student-t radius of its `sd` and `ν` at the risk of
/// `anchored_look_risk(δ, a, 1, j, K)` (the first radius's part or the batched one's).
#[test]
fn every_anchored_look_matches_its_formula() {
    let cfg = calibrated(1, vec![-1.2], 150, 10);
    let cal = cfg.calibration.expect("calibrated");
    assert_eq!(cfg.regression.model, Model::Affine);
    let traj = run_scenario(&short_window_plant(), 5);
    let mut cert = Certifier::new(cfg).expect("valid");
    let mut cols: Vec<(DVector<f64>, f64)> = Vec::new();
    let (mut checked, mut merged, mut last) = (0, 0, 0);
    for i in 0..traj.len() {
        cert.push(traj.t[i], traj.output(i), traj.input(i)).expect("valid");
        if cert.regression().columns_built() as usize > cols.len() {
            let (z, dy) = cert.regression().newest_column().expect("column");
            let mut z = z.to_vec();
            z.push(cert.regression().newest_column_span().expect("column"));
            cols.push((DVector::from_vec(z), dy[0]));
        }
        let (Some(look), epoch) = cert.anchored_look() else { continue };
        assert_eq!(epoch, 1, "no gap, no change");
        if look.look == last {
            continue;
        }
        last = look.look;
        assert!(look.anchored);
        let size = cal.anchored_size(30, look.look) as usize;
        let blocks = look.window / H;
        assert_eq!(look.window % H, 0);
        if size < 256 {
            assert_eq!(blocks, size, "look {}", look.look);
        } else {
            // Records of `c` blocks: at most `c − 1` newest blocks wait in the open record.
            assert!(blocks <= size && blocks + size / 128 >= size, "{blocks} of {size}");
            merged += 1;
        }
        // Columns `q >= h + 1` are instrumented by column `q − h − 1` (instrument lag 1).
        let first = H + 1;
        let (mut nm, mut cw) = (DMatrix::<f64>::zeros(3, 3), DMatrix::<f64>::zeros(1, 3));
        for q in first..first + look.window {
            let w = &cols[q - H - 1].0;
            nm += &cols[q].0 * w.transpose();
            cw += DMatrix::from_element(1, 1, cols[q].1) * w.transpose();
        }
        let theta = &cw * nm.try_inverse().expect("invertible");
        let beta = -(theta[(0, 0)] + theta[(0, 1)] * -1.2);
        assert!(
            (look.beta_hat - beta).abs() < 1e-8 * (1.0 + beta.abs()),
            "look {}: {} vs {beta}",
            look.look,
            look.beta_hat
        );
        let risk = anchored_look_risk(0.01, cal.anchored_share, 1, look.look, 11);
        let share = cal.auto_batch_risk;
        let radius = |r: f64| calibrated_radius(look.sd * look.sd, look.nu, r);
        let matches = [risk, risk * (1.0 - share), risk * share]
            .iter()
            .any(|&r| (look.radius - radius(r)).abs() <= 1e-12 * look.radius);
        assert!(matches, "look {}: radius {} at risk {risk}", look.look, look.radius);
        checked += 1;
    }
    // Looks at 30, 43, 60, 85, 120, 170, 240, 340, 480 and 679 blocks (the last at 34 s).
    assert_eq!(checked, 10, "anchored looks in 40 s");
    assert_eq!(merged, 3, "looks after the records merged");
}

/// A loop at 5× the margin, 40 s, `n_s = 10`, 20 seeds: where the longest sliding window
/// (2400 columns) and the anchored window both hold a look at the end, the anchored one,
/// on about 3395 columns at a larger share of δ, has the larger certificate in most runs; its
/// certificate overstates the true rate in at most one run (the union bound allows about
/// `0.9 δ` of runs over all looks; the just-identified estimate's tails are heavier than the
/// Student-t's, measured in VALIDITY.md: one of these 20 seeds does).
#[test]
fn the_anchored_window_certifies_beyond_the_longest_sliding_window() {
    // ẏ = −y + u + w explored by u = −0.5 y + PRBS; the candidate K = 0.75 has β* = 0.25.
    let scenario = LinearScenario {
        dither_hold: 0.2,
        steps: 4000,
        ..scalar(-1.0, -0.5, Process::Gaussian { sigma: 0.1 }, 1.0)
    };
    let cfg = calibrated(1, vec![0.75], 150, 10);
    let (mut larger, mut compared, mut over) = (0, 0, 0);
    for seed in 0..20 {
        let traj = run_scenario(&scenario, 900 + seed);
        let mut cert = Certifier::new(cfg.clone()).expect("valid");
        for i in 0..traj.len() {
            cert.push(traj.t[i], traj.output(i), traj.input(i)).expect("valid");
        }
        let (Some(anchored), 1) = cert.anchored_look() else { continue };
        over += usize::from(anchored.certificate() >= 0.25);
        let Some(longest) = cert.calibrated_looks().last().copied().flatten() else { continue };
        assert!(anchored.window > longest.window, "{} columns", anchored.window);
        larger += usize::from(anchored.certificate() > longest.certificate());
        compared += 1;
    }
    assert!(compared >= 18, "{compared} runs with both looks");
    assert!(over <= 1, "the anchored certificate above β* in {over} of 20 runs");
    assert!(larger * 4 >= compared * 3, "the anchored look larger in {larger} of {compared}");
}

/// A plant change from β* = 3 to −0.2 at 20 s (dt = 0.01, 10 seeds): the anchored window
/// starts a new epoch within 1.5 shortest-window spans after the change in every run, the
/// looks of the new epoch hold no column from before it, and none of them certifies the new
/// plant.
#[test]
fn a_plant_change_starts_a_new_anchored_epoch() {
    use streamcert::dynamics::PlantSwitch;
    let k = -1.5;
    // ẏ = a y + u + w, β* = −(a + K): a = −1.5 before (β* = 3), 1.7 after (β* = −0.2).
    let scenario = LinearScenario {
        dither_hold: 0.2,
        steps: 4000,
        switch: Some(PlantSwitch { at: 20.0, a: vec![1.7], ramp: 0.0 }),
        ..scalar(-1.5, -2.0, Process::Gaussian { sigma: 0.1 }, 1.0)
    };
    let cfg = calibrated(1, vec![k], 150, 10);
    let mut delays = Vec::new();
    for seed in 0..10 {
        let traj = run_scenario(&scenario, 300 + seed);
        let mut cert = Certifier::new(cfg.clone()).expect("valid");
        let mut restarted = None;
        for i in 0..traj.len() {
            cert.push(traj.t[i], traj.output(i), traj.input(i)).expect("valid");
            let (look, epoch) = cert.anchored_look();
            if epoch >= 2 && restarted.is_none() {
                restarted = Some(traj.t[i]);
            }
            let (Some(look), Some(at)) = (look, restarted) else { continue };
            if epoch < 2 {
                continue;
            }
            assert!(at > 20.0, "seed {seed}: restarted at {at}");
            // The look's columns (one per sample) all after the restart.
            assert!(look.t - look.window as f64 * 0.01 >= at - 0.1, "seed {seed}: {look:?}");
            assert!(look.certificate() < 0.05, "seed {seed}: {look:?} certifies the new plant");
        }
        let at = restarted.unwrap_or_else(|| panic!("seed {seed}: no new epoch"));
        delays.push(at - 20.0);
    }
    // Within 1.5 shortest-window spans (2.3 s) of the change; measured 0.7 to 1.1 s.
    assert!(delays.iter().all(|&d| d < 1.5 * 1.54), "{delays:?}");
    // An anchored look's risk never exceeds the first look's of one window holding all of δ
    // (both are parts of one union bound).
    let cal = Calibration::new(0.01);
    assert!(anchored_look_risk(0.01, cal.anchored_share, 1, 1, 11) <= look_risk(0.01, 1.0, 1));
}

/// A checkpoint taken mid-run (after the anchored records merged, with blocks waiting in
/// the open record) and restored continues bit for bit: every later evidence row and the
/// anchored look equal the uninterrupted run's; a re-sealed state whose anchored epoch start
/// lies after the columns seen, or whose record size is not a power of two, is refused.
#[test]
fn the_anchored_window_checkpoints_and_is_checked() {
    let traj = run_scenario(&short_window_plant(), 21);
    let cfg = calibrated(1, vec![-1.2], 150, 10);
    let mut whole = Certifier::new(cfg.clone()).expect("valid");
    let all: Vec<_> = (0..traj.len())
        .map(|k| whole.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid"))
        .collect();
    for split in [1777, 3003] {
        let (text, second) = resume_matches(&cfg, &traj, &all, split);
        assert_eq!(second.anchored_look(), whole.anchored_look());
        let payload = crate::support::json_payload(&text);
        // Records of 2 blocks at 1777 samples (354 blocks), of 4 at 3003 (598).
        let coarse = if split < 2000 { "\"coarse\":2" } else { "\"coarse\":4" };
        assert!(payload.contains(coarse), "merged records at {split}");
        let reseal = |edited: String| crate::support::reseal_json(&edited, &cfg);
        let bad = payload.replace(coarse, "\"coarse\":3");
        assert!(Certifier::restore(reseal(bad)).is_err(), "a record of 3 blocks");
        let at = payload.find("\"start\":").expect("epoch start") + "\"start\":".len();
        let digits = payload[at..].chars().take_while(char::is_ascii_digit).count();
        let bad = format!("{}{}{}", &payload[..at], 10_000_000, &payload[at + digits..]);
        assert!(Certifier::restore(reseal(bad)).is_err(), "an epoch after the columns seen");
    }
    assert!(whole.anchored_look().0.is_some(), "the anchored window looked");
}

/// With `max_window = 1200` the anchored window looks at sizes up to 1200 columns only (30,
/// 43, …, 240 blocks: seven looks), and from the block past the cap on no anchored look
/// stands; the sliding windows above the cap are dropped as before.
#[test]
fn max_window_caps_the_anchored_window() {
    let traj = run_scenario(&short_window_plant(), 8);
    let mut cfg = calibrated(1, vec![-1.2], 150, 10);
    cfg.calibration = cfg.calibration.map(|c| Calibration { max_window: Some(1200), ..c });
    let mut cert = Certifier::new(cfg).expect("valid");
    assert_eq!(cert.calibrated_looks().len(), 4, "150 to 1200 columns");
    let (mut looks, mut last, mut after) = (0, 0, 0);
    for i in 0..traj.len() {
        cert.push(traj.t[i], traj.output(i), traj.input(i)).expect("valid");
        let columns = cert.regression().columns_built() as usize;
        match cert.anchored_look().0 {
            Some(look) => {
                assert!(look.window <= 1200, "{look:?}");
                // Columns are instrumented from the seventh on (h + lag + 1).
                assert!(columns <= 1200 + 2 * H + 1, "a look stands at {columns} columns");
                if look.look != last {
                    (last, looks) = (look.look, looks + 1);
                }
            }
            None => after += usize::from(columns > 1300),
        }
    }
    assert_eq!(looks, 7, "anchored looks up to the cap");
    assert!(after > 2000, "no anchored look past the cap ({after} samples)");
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

    /// The anchored looks' risks over any number of epochs and looks never sum above
    /// `δ · share` (the union bound's part), for any design count; the sizes increase
    /// strictly from the shortest window's blocks for any growth.
    #[test]
    fn anchored_risks_sum_within_the_share_and_sizes_increase(
        delta in 1e-4f64..0.2, share in 0.01f64..0.99, design in 1u64..64,
        growth in 1.0001f64..4.0, base in 2usize..500,
    ) {
        let mut total = 0.0;
        for e in 1..=40u64 {
            for j in 1..=300u64 {
                total += anchored_look_risk(delta, share, e, j, design);
            }
        }
        proptest::prop_assert!(total <= delta * share * (1.0 + 1e-12), "{total}");
        proptest::prop_assert!(total >= 0.9 * delta * share, "{total}");
        let cal = Calibration { anchored_growth: growth, ..Calibration::new(delta) };
        let mut before = 0;
        for j in 1..=40u64 {
            let size = cal.anchored_size(base, j);
            proptest::prop_assert!(size > before, "look {j}: {size} after {before}");
            before = size;
        }
        proptest::prop_assert_eq!(cal.anchored_size(base, 1), base as u64);
    }
}
