//! The hidden-dynamics guard of the certificate of order `n` (the past-row test): how often it
//! closes the gate of a loop the model holds, and how often it refuses a plant with a state
//! beyond the order.
//!
//! Protocol (fixed before the runs): plants in observable form (`y = x_1`, the input and the
//! constant 0.1 entering the last state), simulated exactly (zero-order hold) at 100 Hz for
//! 40 s from rest, optionally with the input delayed by a whole number of samples; the loop
//! `u = K y_m + d`, `d` a dither of `±0.1` redrawn every second; sensor noise `σ = 0.01`;
//! the certificate's defaults (`h = 50`, `M = 2000`, looks every 200 samples, `δ = 0.01`,
//! margin 0.05, the guard at risk `δ` per look).

use streamcert_certificate::{NotCertified, OrderNCertificate, OrderNCertificateConfig};
use streamcert_regression::{LoopModel, OrderNConfig};

use crate::support::{Loop, par_map};

/// What one run's looks said: certified, refused by the guard, other.
#[derive(Debug, Default, Clone, Copy)]
struct Tally {
    looks: usize,
    certified: usize,
    hidden: usize,
}

/// One seeded run of `plant`, certified at `order`.
fn run(plant: &Loop, order: usize, seed: u64) -> Tally {
    let regression = OrderNConfig::new(LoopModel::of_order(order).unwrap(), 1, 2000, 50);
    let cfg = OrderNCertificateConfig::new(regression, vec![plant.gain], 0.05, 0.01);
    let mut cert = OrderNCertificate::new(cfg).unwrap();
    let mut tally = Tally::default();
    plant.run(seed, |t, y, u| {
        if let Some(look) = cert.push(t, y, &[u]).unwrap() {
            tally.looks += 1;
            tally.certified += usize::from(look.certified());
            tally.hidden +=
                usize::from(matches!(look.outcome, Err(NotCertified::HiddenDynamics { .. })));
        }
        true
    });
    tally
}

/// The tallies of the seeded runs `seeds`, summed.
fn cell(plant: &Loop, order: usize, seeds: std::ops::Range<u64>) -> Tally {
    par_map(seeds, |s| run(plant, order, s)).into_iter().fold(Tally::default(), |t, r| Tally {
        looks: t.looks + r.looks,
        certified: t.certified + r.certified,
        hidden: t.hidden + r.hidden,
    })
}

#[test]
fn the_guard_rarely_closes_a_loop_the_model_holds() {
    // (s + 0.25)(s + 0.95) closed (K = 0.7625): five times the margin, order 2 holds.
    let t = cell(&Loop::new(&[1.2, 1.0], 0.7625), 2, 1000..1040);
    eprintln!("order 2 holds, 5× the margin: {t:?}");
    assert!(t.hidden * 100 <= 2 * t.looks, "{t:?}");
    assert!(t.certified * 100 >= 95 * t.looks, "{t:?}");
}

#[test]
fn beyond_the_order_the_guard_refuses_two_looks_in_three_or_more() {
    // A slow state behind a fast one read through a sensor lag: (s + 0.045)(s + 2)(s + 5)
    // open loop, margin 0.045, below the margin; order 2 cannot hold it.
    let lagged = Loop { amplitude: 1.0, ..Loop::new(&[7.045, 10.315, 0.45], 0.0) };
    // A complex pair −0.045 ± 1.41 j behind a transport delay of 10 samples.
    let delayed = Loop { amplitude: 1.0, delay: 10, ..Loop::new(&[0.09, 1.0], -1.0) };
    for (name, plant, seeds) in [("lagged", lagged, 100..120), ("delayed", delayed, 300..320)] {
        let t = cell(&plant, 2, seeds);
        eprintln!("{name}, order 2: {t:?}");
        assert_eq!(t.certified, 0, "{name}: {t:?}");
        assert!(t.hidden * 3 >= 2 * t.looks, "{name}: {t:?}");
    }
}
