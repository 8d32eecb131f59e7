//! The model guards of the certificate of order `n` (the past-row test, the curvature test):
//! how often they close the gate of a loop the model holds, how often the first refuses a
//! plant with a state beyond the order, and the second a loop whose static term stiffens.
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
    varying: usize,
}

/// How the runs are certified: the order, the window and horizon, and whether the
/// nonlinearity guard is on (the hidden-dynamics guard always is).
#[derive(Debug, Clone, Copy)]
struct Setup {
    order: usize,
    window: usize,
    horizon: usize,
    nonlinearity: bool,
}

impl Setup {
    /// `order` with the defaults: `M = 2000`, `h = 50`, both guards.
    fn of(order: usize) -> Self {
        Self { order, window: 2000, horizon: 50, nonlinearity: true }
    }
}

/// One seeded run of `plant`, certified as `setup` says.
fn run(plant: &Loop, setup: Setup, seed: u64) -> Tally {
    let model = LoopModel::of_order(setup.order).unwrap();
    let regression = OrderNConfig::new(model, 1, setup.window, setup.horizon);
    let mut cfg = OrderNCertificateConfig::new(regression, vec![plant.gain], 0.05, 0.01);
    cfg.nonlinearity = setup.nonlinearity;
    let mut cert = OrderNCertificate::new(cfg).unwrap();
    let mut tally = Tally::default();
    plant.run(seed, |t, y, u| {
        if let Some(look) = cert.push(t, y, &[u]).unwrap() {
            tally.looks += 1;
            tally.certified += usize::from(look.certified());
            tally.hidden +=
                usize::from(matches!(look.outcome, Err(NotCertified::HiddenDynamics { .. })));
            tally.varying +=
                usize::from(matches!(look.outcome, Err(NotCertified::VaryingDynamics { .. })));
        }
        true
    });
    tally
}

/// The tallies of the seeded runs `seeds`, summed, at `order` with both guards.
fn cell(plant: &Loop, order: usize, seeds: std::ops::Range<u64>) -> Tally {
    cell_with(plant, Setup::of(order), seeds)
}

/// The same, certified as `setup` says.
fn cell_with(plant: &Loop, setup: Setup, seeds: std::ops::Range<u64>) -> Tally {
    par_map(seeds, |s| run(plant, setup, s)).into_iter().fold(Tally::default(), |t, r| Tally {
        looks: t.looks + r.looks,
        certified: t.certified + r.certified,
        hidden: t.hidden + r.hidden,
        varying: t.varying + r.varying,
    })
}

#[test]
fn the_guard_rarely_closes_a_loop_the_model_holds() {
    // (s + 0.25)(s + 0.95) closed (K = 0.7625): five times the margin, order 2 holds.
    let t = cell(&Loop::new(&[1.2, 1.0], 0.7625), 2, 1000..1040);
    eprintln!("order 2 holds, 5× the margin: {t:?}");
    assert!(t.hidden * 100 <= 2 * t.looks, "{t:?}");
    assert!(t.varying * 100 <= 2 * t.looks, "{t:?}");
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

/// The loop `ÿ + 1.2 ẏ + y + 2 y³ = u + 0.1` under `u = 0.97 y_m + d`: its static term's slope
/// is `0.03 + 6 y²`, so at `y = 0` (visited whenever the dither pulls the output back) the
/// closed loop's rate is about 0.025, below the margin, and about 0.6 at the far end of the
/// excursion the dither of `±0.1` drives. One linear fit certifies its average slope (the
/// contrast: without the guard the same runs certify at least half their looks); the
/// nonlinearity guard refuses at least half the looks and leaves at most a tenth of those
/// certifications. It lowers the false certifications, it does not remove them: the
/// verdict's risk assumes a loop linear over its region.
#[test]
fn the_nonlinearity_guard_refuses_a_loop_certified_on_its_average_slope() {
    let plant = Loop { cubic: 2.0, ..Loop::new(&[1.2, 1.0], 0.97) };
    assert!(plant.rate() < 0.05, "{}", plant.rate());
    let (on, off) = (
        cell_with(&plant, Setup::of(2), 500..520),
        cell_with(&plant, Setup { nonlinearity: false, ..Setup::of(2) }, 500..520),
    );
    eprintln!("stiffening loop: guard on {on:?}, guard off {off:?}");
    assert!(off.certified * 2 >= off.looks, "without the guard: {off:?}");
    assert!(on.certified * 10 <= off.certified, "with the guard: {on:?}");
    assert!(on.varying * 2 >= on.looks, "with the guard: {on:?}");
}

/// The first hidden-dynamics refusal over the seeded runs `seeds` of `plant` at `order`.
fn first_refusal(
    plant: &Loop,
    (order, horizon): (usize, usize),
    seeds: std::ops::Range<u64>,
) -> Option<NotCertified> {
    let found = par_map(seeds, |seed| {
        let model = LoopModel::of_order(order).unwrap();
        let regression = OrderNConfig::new(model, 1, 2000, horizon);
        let cfg = OrderNCertificateConfig::new(regression, vec![plant.gain], 0.05, 0.01);
        let mut cert = OrderNCertificate::new(cfg).unwrap();
        let mut refusal = None;
        plant.run(seed, |t, y, u| {
            if let Some(look) = cert.push(t, y, &[u]).unwrap()
                && let Err(reason @ NotCertified::HiddenDynamics { .. }) = look.outcome
            {
                refusal = Some(reason);
            }
            refusal.is_none()
        });
        refusal
    });
    found.into_iter().flatten().next()
}

/// The refusal names the order it tried and what would be valid: beyond order 2, a model of
/// order 3; beyond order 3, the largest, no certificate of this certifier, and the
/// unmeasured states logged as outputs. Plants, closed just below the margin under a dither
/// of `±1` (where a misfit shows best): three lags `(s + 1)³` at order 2 (`h = 50`); four lags
/// `(s + 1)⁴` and a lag behind a transport delay of 10 samples at order 3, at `h = 25`
/// (`ν = 14`), for the words only: at `h = 50` a window of 2000 rows holds 12 spans of 151
/// samples after the first, and the guard's larger fit of 11 coefficients leaves its test
/// `ν = 1` degree of freedom (a threshold of about 22 500 at `δ = 0.01`), too few to see
/// either; at `h = 25` it refuses every look, those of loops order 3 holds included
/// (docs/your-data.md), so these refusals say nothing of its power.
#[test]
fn the_hidden_dynamics_refusal_names_the_order_and_what_would_be_valid() {
    let three = Loop { amplitude: 1.0, ..Loop::new(&[3.0, 3.0, 1.0], 0.955f64.powi(3)) };
    let at_two = first_refusal(&three, (2, 50), 700..704).expect("order 2 refuses three lags");
    assert!(matches!(at_two, NotCertified::HiddenDynamics { order: 2, .. }), "{at_two:?}");
    let words = at_two.to_string();
    assert!(words.contains("(order 2, window") && words.contains("order = 3"), "{words}");
    let four = Loop { amplitude: 1.0, ..Loop::new(&[4.0, 6.0, 4.0, 1.0], 0.955f64.powi(4)) };
    let delayed =
        Loop { amplitude: 1.0, delay: 10, ..Loop::new(&[1.0], 0.955 * (-0.0045f64).exp()) };
    for (name, plant, seeds) in [("four lags", four, 710..714), ("delayed", delayed, 720..724)] {
        let at_three = first_refusal(&plant, (3, 25), seeds).expect(name);
        assert!(
            matches!(at_three, NotCertified::HiddenDynamics { order: 3, .. }),
            "{name}: {at_three:?}"
        );
        let words = at_three.to_string();
        assert!(
            words.contains("(order 3, the largest certified;")
                && words.contains("unmeasured states logged as outputs")
                && !words.contains("order = 4"),
            "{name}: {words}"
        );
    }
}

/// What order 3 gives today, the figures docs/your-data.md states (20 seeded runs per cell,
/// the protocol above, sensor noise): at `window = 2000`, `h = 50` three lags closed at 5× the
/// margin (`(s + 1)³ − 0.75³`, rate 0.25) are certified at no look, the hidden-dynamics guard
/// refusing none; with more spans (`h = 25, 30, 35`, or a window of 4000 rows at `h = 50` over
/// 80 s runs) the guard refuses every look of that loop and of three lags just below the
/// margin, loops order 3 holds. A change that gives order 3
/// its power fails here, and the docs' figures with it.
#[test]
fn order_3_at_these_windows_certifies_nothing() {
    let plant = |gain: f64, window: usize| Loop {
        // Runs twice the window's 20 s, as the 40 s runs of a 2000-row window.
        samples: 2 * window,
        ..Loop::new(&[3.0, 3.0, 1.0], gain)
    };
    let (fast, near) = (0.75f64.powi(3), 0.955f64.powi(3));
    let t = order_3(&plant(fast, 2000), 50, 2000, 800..820);
    eprintln!("order 3, 5× the margin, h = 50: {t:?}");
    assert!(t.looks > 0 && t.certified == 0 && t.hidden == 0, "{t:?}");
    for (horizon, window) in [(25, 2000), (30, 2000), (35, 2000), (50, 4000)] {
        for gain in [fast, near] {
            let t = order_3(&plant(gain, window), horizon, window, 800..820);
            eprintln!("order 3, gain {gain}, h = {horizon}, M = {window}: {t:?}");
            assert!(t.looks > 0 && t.hidden == t.looks, "h = {horizon}, M = {window}: {t:?}");
        }
    }
}

/// Where order 3's refusals come from, as docs/your-data.md states it: the noise, not the
/// rows' linear approximation of `y` between samples. Three lags at 5× the margin at
/// `h = 25`, `M = 2000` (10 runs): with a sensor noise of `σ = 10⁻⁶` the guard refuses no
/// look and every look certifies; at 200 Hz with `σ = 0.01` and the same horizon and window
/// in seconds (`h = 50`, `M = 4000`: the approximation's error a quarter of 100 Hz's) the
/// guard still refuses every look (4 runs).
#[test]
fn order_3_refusals_come_from_the_noise_not_the_approximation() {
    let base = Loop { samples: 4000, ..Loop::new(&[3.0, 3.0, 1.0], 0.75f64.powi(3)) };
    let quiet = Loop { sensor: 1e-6, ..base.clone() };
    let t = order_3(&quiet, 25, 2000, 830..840);
    eprintln!("order 3, σ = 1e-6: {t:?}");
    assert!(t.looks > 0 && t.hidden == 0 && t.certified == t.looks, "{t:?}");
    let fine = Loop { samples: 8000, dt: 0.005, hold: 200, ..base };
    let t = order_3(&fine, 50, 4000, 840..844);
    eprintln!("order 3 at 200 Hz: {t:?}");
    assert!(t.looks > 0 && t.hidden == t.looks, "{t:?}");
}

/// The looks of order 3 (`window`, `horizon`, margin 0.05, `δ = 0.01`, both guards) over the
/// seeded runs of `plant`, summed.
fn order_3(plant: &Loop, horizon: usize, window: usize, seeds: std::ops::Range<u64>) -> Tally {
    cell_with(plant, Setup { window, horizon, ..Setup::of(3) }, seeds)
}
