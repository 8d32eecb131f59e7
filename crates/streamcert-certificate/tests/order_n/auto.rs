//! The order ladder (`order = "auto"`): each rung is the certifier of its order at a third of
//! the risk, bit for bit; the gate is open exactly when one of theirs is; the standing order is
//! reported; a hidden-state plant the first order refuses is certified at order 2, a
//! first-order loop at order 1, a loop below the margin at none; a checkpoint continues the
//! run bit for bit; what the ladder cannot run is refused by name.

use streamcert_certificate::{
    Calibration, Certifier, CertifierConfig, CertifyError, Evidence, HorizonLadder,
    NotCertified::WarmingUp, OrderLadder,
};
use streamcert_regression::{LoopModel, RegressionConfig};

use crate::support::{Loop, par_map};

const DELTA: f64 = 0.01;
const MARGIN: f64 = 0.05;

/// `[regression] window = 2000, horizon = 50` (rows at the orders above 1, columns at the
/// first), `[calibration] delta = 0.01`, margin 0.05, a one-sample gate, for the gain `k`, at
/// `order` or, with `None`, `order = "auto"`.
fn config(k: f64, order: Option<usize>) -> CertifierConfig {
    let regression = RegressionConfig {
        order: LoopModel::of_order(order.unwrap_or(1)).unwrap(),
        ..RegressionConfig::new(1, 1, 2000, 50, 0.0)
    };
    let mut cfg = CertifierConfig::new(regression, vec![k], 1.0, MARGIN, 1);
    cfg.calibration = Some(Calibration::new(DELTA));
    if order.is_none() {
        cfg.orders = Some(OrderLadder::automatic());
    }
    cfg
}

/// The same certifier at `order` alone, at the ladder's risk per rung `δ / 3`.
fn rung_alone(k: f64, order: usize) -> Certifier {
    let mut cfg = config(k, Some(order));
    cfg.calibration = Some(Calibration::new(DELTA / 3.0));
    Certifier::new(cfg).unwrap()
}

fn samples(plant: &Loop, seed: u64) -> Vec<(f64, f64, f64)> {
    let mut out = Vec::with_capacity(plant.samples);
    plant.run(seed, |t, y, u| {
        out.push((t, y, u));
        true
    });
    out
}

/// Oracle: the three certifiers run alone at `δ / 3`. Every rung's verdict is theirs bit for
/// bit, the ladder's gate is open exactly when one of theirs is, the standing rung is the open
/// one with the largest certificate (the lower order on a tie), and where no order has a
/// certificate the highest order past its warm-up gives the reason. Returns the rows open
/// and, per order, the rows that order stood.
fn against_the_rungs_alone(plant: &Loop, seed: u64) -> (usize, [usize; 3]) {
    let k = plant.gain;
    let mut ladder = Certifier::new(config(k, None)).unwrap();
    let mut alone = [rung_alone(k, 1), rung_alone(k, 2), rung_alone(k, 3)];
    let (mut open, mut stood) = (0, [0; 3]);
    for (i, &(t, y, u)) in samples(plant, seed).iter().enumerate() {
        let ev = ladder.push(t, &[y], &[u]).unwrap();
        let each: Vec<Evidence> =
            alone.iter_mut().map(|c| c.push(t, &[y], &[u]).unwrap()).collect();
        let status: Vec<_> = ladder.rungs_status().collect();
        assert_eq!(status.iter().map(|s| s.order).collect::<Vec<_>>(), [1, 2, 3]);
        for (s, e) in status.iter().zip(&each) {
            assert_eq!(format!("{:?}", s.verdict), format!("{:?}", e.calibrated), "row {i}");
        }
        assert_eq!(ev.calibrated.open, each.iter().any(|e| e.calibrated.open), "row {i}");
        let best = (0..3).fold(None::<usize>, |b, j| match b {
            None => Some(j),
            Some(b) => {
                let (x, y) = (&each[j].calibrated, &each[b].calibrated);
                let before = (x.open && !y.open)
                    || (x.open == y.open && x.value.zip(y.value).is_some_and(|(x, y)| x > y))
                    || (x.open == y.open && x.value.is_some() && y.value.is_none());
                Some(if before { j } else { b })
            }
        });
        let best = best.unwrap();
        assert_eq!(ev.calibrated.value, each[best].calibrated.value, "row {i}");
        if ev.calibrated.value.is_none() {
            // No order certifies: the highest order past its warm-up says why.
            let warming = |e: &Evidence| matches!(e.calibrated.reason, Some(WarmingUp { .. }));
            let says = (0..3).rev().find(|&j| !warming(&each[j])).unwrap_or(0);
            assert_eq!(ev.calibrated.reason, each[says].calibrated.reason, "row {i}");
        }
        if ev.calibrated.value.is_some() {
            assert_eq!(ev.calibrated_order, Some(best + 1), "row {i}");
        }
        if ev.calibrated.open {
            open += 1;
            stood[best] += 1;
        }
    }
    (open, stood)
}

#[test]
fn each_rung_is_its_order_alone_at_a_third_of_the_risk_and_the_gate_is_their_union() {
    // (s + 0.25)(s + 0.95): a damped second-order plant at five times the margin, measured by
    // its position; the first order's hidden-dynamics guard refuses it.
    let two = Loop { samples: 4000, ..Loop::new(&[1.2, 1.0], 0.7625) };
    let (open, stood) = against_the_rungs_alone(&two, 7);
    assert!(open > 0 && stood[1] > 0, "certified at order 2: {open} rows, {stood:?}");
    assert_eq!(stood[0], 0, "never at the first order: {stood:?}");
    // A first-order loop ẏ = −y + u + 0.1 under K = 0.75 (rate 0.25, five times the margin).
    let one = Loop { samples: 4000, ..Loop::new(&[1.0], 0.75) };
    let (open, stood) = against_the_rungs_alone(&one, 8);
    assert!(open > 0 && stood[0] > 0, "certified at the first order: {open} rows, {stood:?}");
}

#[test]
fn hidden_state_plants_open_at_their_order_and_loops_below_the_margin_never() {
    let run = |plant: Loop, seeds: std::ops::Range<u64>| {
        par_map(seeds, |seed| {
            let mut cert = Certifier::new(config(plant.gain, None)).unwrap();
            let mut orders = Vec::new();
            plant.run(seed, |t, y, u| {
                let ev = cert.push(t, &[y], &[u]).unwrap();
                if ev.calibrated.open {
                    orders.push(ev.calibrated_order.unwrap());
                }
                true
            });
            orders
        })
    };
    // A tank behind a tank, (s + 0.25)(s + 0.95) closed: certified, at order 2.
    let tanks = run(Loop::new(&[1.2, 1.0], 0.7625), 20..26);
    assert!(tanks.iter().all(|o| o.iter().all(|&n| n == 2)), "{tanks:?}");
    assert!(tanks.iter().filter(|o| !o.is_empty()).count() >= 5, "{tanks:?}");
    // Just below the margin: a lightly damped pair at 0.045 (the loop's rate 0.9 × margin),
    // and four equal lags in series whose closed loop sits at 0.045: never open.
    let light = Loop { amplitude: 1.0, ..Loop::new(&[0.09, 1.0], 0.0) };
    let four = Loop { amplitude: 1.0, ..Loop::new(&[4.0, 6.0, 4.0, 1.0], 0.955f64.powi(4)) };
    for (name, plant) in [("lightly damped", light), ("four lags", four)] {
        assert!(plant.rate() < MARGIN, "{name}: {}", plant.rate());
        let opened = run(plant, 40..46);
        assert!(opened.iter().all(Vec::is_empty), "{name}: {opened:?}");
    }
}

#[test]
fn a_checkpoint_of_the_ladder_continues_bit_for_bit() {
    let plant = Loop { samples: 3000, ..Loop::new(&[1.2, 1.0], 0.7625) };
    let data = samples(&plant, 3);
    let mut cert = Certifier::new(config(plant.gain, None)).unwrap();
    for &(t, y, u) in &data[..2300] {
        cert.push(t, &[y], &[u]).unwrap();
    }
    for bytes in [cert.checkpoint().unwrap(), cert.checkpoint_json().unwrap().into_bytes()] {
        let mut restored = Certifier::restore(&bytes).unwrap();
        let mut original = cert.clone();
        for &(t, y, u) in &data[2300..] {
            let (a, b) =
                (original.push(t, &[y], &[u]).unwrap(), restored.push(t, &[y], &[u]).unwrap());
            assert_eq!(format!("{a:?}"), format!("{b:?}"));
        }
        assert_eq!(format!("{:?}", original.rungs_status().collect::<Vec<_>>()), {
            format!("{:?}", restored.rungs_status().collect::<Vec<_>>())
        });
    }
    // A checkpoint whose rung lost its order is refused, not run.
    let json = cert.checkpoint_json().unwrap();
    let damaged = json.replacen("\"order\":2", "\"order\":3", 1);
    assert_ne!(damaged, json, "the rung's order is in the checkpoint");
    assert!(Certifier::restore(damaged.as_bytes()).is_err());
}

#[test]
fn what_the_ladder_cannot_run_is_refused_by_name() {
    let refused = |cfg: CertifierConfig| match Certifier::new(cfg) {
        Err(CertifyError::InvalidConfig { field, reason }) => (field, reason),
        other => panic!("not refused: {other:?}"),
    };
    let mut two = config(0.7625, None);
    two.regression.outputs = 2;
    two.gain = vec![0.7625, 0.0];
    let (field, why) = refused(two);
    assert_eq!(field, "regression.order");
    assert!(why.contains("one output"), "{why}");
    let mut both = config(0.7625, None);
    both.ladder = Some(HorizonLadder { horizons: vec![25, 50], blocks: None });
    let (field, why) = refused(both);
    assert!(field == "regression.order" && why.contains("horizon = \"auto\""), "{why}");
    let mut bare = config(0.7625, None);
    bare.calibration = None;
    assert_eq!(refused(bare).0, "regression.order");
    let mut unordered = config(0.7625, None);
    unordered.orders = Some(OrderLadder { orders: vec![2, 3] });
    assert_eq!(refused(unordered).0, "regression.order");
    // A window too short for order 3's fits is raised at that rung, not refused: every
    // rung's window holds its guards' spans.
    let mut short = config(0.7625, None);
    short.regression = RegressionConfig::new(1, 1, 1000, 50, 0.0);
    let cert = Certifier::new(short).unwrap();
    let windows: Vec<_> = cert.rungs_status().map(|s| (s.order, s.window)).collect();
    assert_eq!(windows, [(1, 1000), (2, 1010), (3, 1963)]);
}
