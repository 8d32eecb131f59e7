//! The certificate of order 2 at its boundary: loops just below the margin, simulated exactly
//! and measured through one output, open the gate in few enough runs (a Clopper–Pearson
//! bound), and a loop at five times the margin is certified.
//!
//! Protocol (fixed before the runs; nothing here is tuned to the result):
//! - the plant `ÿ + a_1 ẏ + a_2 y = u + 0.1` in observable form (`y = x_1`, the input and the
//!   constant entering the unmeasured `x_2`), from rest, simulated exactly (zero-order hold)
//!   at 100 Hz for 40 s;
//! - the loop `u = K y_m + d`, `d` a dither of `±0.1` whose sign is redrawn every second;
//! - either sensor noise (`y_m = y + e`, `e` white, `σ = 0.01`) or process noise on the
//!   unmeasured state (`x_2` receives `σ_p √dt w` per sample, `w` white, `σ_p = 0.05`);
//! - the certificate's defaults at order 2: `h = 50` (`L = 0.5 s`), `M = 2000` rows, the
//!   first look when the window is full, looks every 200 samples, `δ = 0.01`, margin 0.05.
//!
//! Every look counts, the first included: a run opens when any look certifies. With no
//! opening in 200 runs the one-sided 95 % Clopper–Pearson bound is 0.0149, within `2δ`.

use statrs::distribution::{Beta, ContinuousCDF};
use streamcert_certificate::{OrderNCertificate, OrderNCertificateConfig};
use streamcert_regression::{LoopModel, OrderNConfig};

use crate::support::{Loop, par_map};

const MARGIN: f64 = 0.05;
const DELTA: f64 = 0.01;

/// One cell: the loop, and the units the certificate reads `y` and `u` in (`y · scale.0`,
/// `u · scale.1`, the gain in those units).
#[derive(Clone)]
struct Cell {
    plant: Loop,
    scale: (f64, f64),
}

impl Cell {
    /// The plant `s² + a_1 s + a_2` under `gain`, sensor noise `σ = 0.01` or, with
    /// `process`, process noise `σ_p = process` on the unmeasured state and no sensor noise.
    fn new(a: [f64; 2], gain: f64, sensor: f64, process: f64) -> Self {
        Self { plant: Loop { sensor, process, ..Loop::new(&a, gain) }, scale: (1.0, 1.0) }
    }
}

/// One seeded run: at every look, its time and whether it certified, with its margin.
fn looks(cell: &Cell, seed: u64, stop_at_first: bool) -> Vec<(f64, bool, Option<f64>)> {
    let regression = OrderNConfig::new(LoopModel::of_order(2).unwrap(), 1, 2000, 50);
    let gain = cell.plant.gain * cell.scale.1 / cell.scale.0;
    let cfg = OrderNCertificateConfig::new(regression, vec![gain], MARGIN, DELTA);
    let mut cert = OrderNCertificate::new(cfg).unwrap();
    let mut out = Vec::new();
    cell.plant.run(seed, |t, y, u| {
        if let Some(look) = cert.push(t, y * cell.scale.0, &[u * cell.scale.1]).unwrap() {
            let margin = look.outcome.as_ref().ok().and_then(|r| r.margin);
            out.push((t, look.certified(), margin));
            return !(stop_at_first && look.certified());
        }
        true
    });
    out
}

/// Whether one seeded run opens the gate at any look, and the time of its first opening.
fn run(cell: &Cell, seed: u64) -> Option<f64> {
    looks(cell, seed, true).into_iter().find(|l| l.1).map(|l| l.0)
}

/// The runs `seeds` of a cell: the opening times, in seed order.
fn runs(cell: &Cell, seeds: std::ops::Range<u64>) -> Vec<Option<f64>> {
    par_map(seeds, |k| run(cell, k))
}

/// The one-sided 95 % Clopper–Pearson upper bound on a rate seen `k` times in `n`.
fn clopper_pearson_upper(k: usize, n: usize) -> f64 {
    if k == n {
        return 1.0;
    }
    Beta::new(k as f64 + 1.0, (n - k) as f64).unwrap().inverse_cdf(0.95)
}

fn the_cell_opens_rarely(name: &str, cell: &Cell, runs_n: u64, seed: u64) {
    let opened = runs(cell, seed..seed + runs_n).iter().filter(|o| o.is_some()).count();
    let bound = clopper_pearson_upper(opened, runs_n as usize);
    eprintln!("{name}: opened in {opened} of {runs_n} runs; 95 % Clopper–Pearson bound {bound:.4}");
    assert!(bound <= 2.0 * DELTA, "{name}: {opened} of {runs_n}, bound {bound:.4}");
}

#[test]
fn a_real_pair_just_below_the_margin_with_sensor_noise_rarely_opens() {
    // K = 0.948025: the closed loop (s + 0.045)(s + 1.155).
    let cell = Cell::new([1.2, 1.0], 0.948_025, 0.01, 0.0);
    the_cell_opens_rarely("real pair, sensor noise", &cell, 200, 10_000);
}

#[test]
fn a_complex_pair_just_below_the_margin_with_sensor_noise_rarely_opens() {
    // s² + 0.09 s + 1 under K = −1: s² + 0.09 s + 2, poles −0.045 ± 1.41 j.
    let cell = Cell::new([0.09, 1.0], -1.0, 0.01, 0.0);
    the_cell_opens_rarely("complex pair, sensor noise", &cell, 200, 20_000);
}

#[test]
fn a_real_pair_just_below_the_margin_with_process_noise_rarely_opens() {
    let cell = Cell::new([1.2, 1.0], 0.948_025, 0.0, 0.05);
    the_cell_opens_rarely("real pair, process noise", &cell, 200, 30_000);
}

#[test]
fn a_loop_at_five_times_the_margin_is_certified_in_nine_runs_of_ten_or_more() {
    // K = 0.7625: the closed loop (s + 0.25)(s + 0.95).
    let cell = Cell::new([1.2, 1.0], 0.7625, 0.01, 0.0);
    let opened = runs(&cell, 40_000..40_050);
    let mut times: Vec<f64> = opened.iter().flatten().copied().collect();
    times.sort_by(f64::total_cmp);
    let median = times.get(times.len() / 2).copied().unwrap_or(f64::NAN);
    eprintln!(
        "5× the margin: certified in {} of 50 runs, median first opening {median} s",
        times.len()
    );
    assert!(times.len() >= 45, "certified in {} of 50 runs", times.len());
}

#[test]
fn a_real_pair_just_below_the_margin_with_the_input_held_ten_seconds_rarely_opens() {
    // The dither redrawn every 10 s: a window of 20 s may hold one switch, or none.
    let mut cell = Cell::new([1.2, 1.0], 0.948_025, 0.01, 0.0);
    cell.plant.hold = 1000;
    the_cell_opens_rarely("real pair, input held 10 s", &cell, 200, 50_000);
}

#[test]
fn the_verdict_does_not_depend_on_the_units_of_y_and_u() {
    // The same runs read in units ×0.01 and ×100 of y and of u: the same decision at every
    // look, and the same margin to rounding. The boundary loop and the loop at 5×.
    for (cell, seed) in [
        (Cell::new([1.2, 1.0], 0.948_025, 0.01, 0.0), 60_000),
        (Cell::new([1.2, 1.0], 0.7625, 0.01, 0.0), 60_100),
    ] {
        for k in 0..2 {
            let plain = looks(&cell, seed + k, false);
            assert!(plain.len() >= 9);
            for scale in [(0.01, 1.0), (100.0, 1.0), (1.0, 0.01), (1.0, 100.0), (0.01, 100.0)] {
                let scaled = looks(&Cell { scale, ..cell.clone() }, seed + k, false);
                assert_eq!(plain.len(), scaled.len());
                for (a, b) in plain.iter().zip(&scaled) {
                    assert_eq!((a.0, a.1), (b.0, b.1), "units {scale:?}");
                    match (a.2, b.2) {
                        (Some(x), Some(y)) => assert!((x - y).abs() <= 2e-4, "{x} against {y}"),
                        (x, y) => assert_eq!(x.is_some(), y.is_some()),
                    }
                }
            }
        }
    }
}

#[test]
fn after_a_plant_change_the_gate_is_open_past_one_and_a_half_windows_in_few_runs() {
    // 5× the margin for 30 s, then a_2 = 0.814475: the closed loop (s + 0.045)(s + 1.155),
    // just below the margin. A window is 20 s (2000 rows); 1.5 windows after the change is 60 s.
    let mut cell = Cell::new([1.2, 1.0], 0.7625, 0.01, 0.0);
    (cell.plant.change, cell.plant.samples) = (Some((3000, vec![1.2, 0.814_475])), 7000);
    let runs_n = 60u64;
    let seen = par_map(70_000..70_000 + runs_n, |seed| looks(&cell, seed, false));
    let open = |range: std::ops::Range<f64>| {
        seen.iter().filter(|s| s.iter().any(|l| range.contains(&l.0) && l.1)).count()
    };
    let (before, after) = (open(0.0..30.0), open(60.0..f64::INFINITY));
    eprintln!(
        "plant change: open before it in {before} of {runs_n} runs, past 1.5 windows after it in {after}"
    );
    assert!(
        before * 10 >= runs_n as usize * 9,
        "certified before the change in {before} of {runs_n} runs"
    );
    assert!(after * 20 <= runs_n as usize, "open past 1.5 windows in {after} of {runs_n} runs");
}
