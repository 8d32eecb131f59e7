//! A block ring left out and rebuilt (`InstrumentedWindows::strip`, `cleared`, `refill_from`):
//! the newest `columns_held` columns pushed into a cleared copy and moved into a stripped
//! copy give the original bit for bit, through resets and the ring's wrap, and a replay of
//! another length is refused.

use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::regression::{InstrumentedWindows, Interval};

/// One column of `p` outputs and `m` inputs: random regressors, increments and a range.
fn column(rng: &mut ChaCha8Rng, p: usize, m: usize) -> (Vec<f64>, Vec<f64>, Vec<Interval>) {
    let z = (0..p + m).map(|_| rng.random::<f64>() - 0.5).collect();
    let dy = (0..p).map(|_| rng.random::<f64>() - 0.5).collect();
    let range = (0..p)
        .map(|_| {
            let lo = rng.random::<f64>();
            Interval { lo, hi: lo + rng.random::<f64>() }
        })
        .collect();
    (z, dy, range)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Oracle: the windows as pushed. Any number of columns (before the instruments' reach
    /// fills, before the longest window fills, past its wrap), a reset anywhere, one or two
    /// outputs, one or two instrument intervals.
    #[test]
    fn a_stripped_ring_refilled_from_its_replay_is_the_original(
        n in 0usize..700,
        reset in proptest::option::of(0usize..700),
        p in 1usize..3,
        intervals in 1usize..3,
        seed in 0u64..1000,
    ) {
        let (m, h) = (1, 5);
        let mut win = InstrumentedWindows::new(p, m, h, 1, intervals, &[60, 120, 240])
            .unwrap()
            .with_ranges(p);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut since_reset = Vec::new();
        for k in 0..n {
            if reset == Some(k) {
                win.reset();
                since_reset.clear();
            }
            let col = column(&mut rng, p, m);
            win.push_column_ranged(&col.0, &col.1, &col.2);
            since_reset.push(col);
        }
        let held = win.columns_held();
        prop_assert!(held <= win.columns_held_max());
        prop_assert!(held <= since_reset.len());
        let mut replayed = win.cleared();
        for (z, dy, range) in &since_reset[since_reset.len() - held..] {
            replayed.push_column_ranged(z, dy, range);
        }
        let mut stripped = win.clone();
        prop_assert!(stripped.strip());
        prop_assert!(!stripped.same_bits(&win));
        prop_assert!(stripped.refill_from(&replayed));
        prop_assert!(stripped.same_bits(&win));
        // A replay one column short (or long) is refused, and leaves the state stripped.
        if held > 0 {
            let mut short = win.cleared();
            for (z, dy, range) in &since_reset[since_reset.len() - held + 1..] {
                short.push_column_ranged(z, dy, range);
            }
            let mut again = win.clone();
            prop_assert!(again.strip());
            prop_assert!(!again.refill_from(&short));
        }
    }
}

/// Windows that keep values are not stripped: a replay of columns does not rebuild them.
#[test]
fn valued_windows_are_not_stripped() {
    let valued = InstrumentedWindows::new(1, 1, 5, 1, 1, &[60, 120]).unwrap().with_values();
    assert!(!valued.clone().strip());
}
