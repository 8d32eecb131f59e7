//! `InstrumentedWindows::window_range` against the hull of the window's complete blocks,
//! formed from the columns' ranges in the test.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::regression::{InstrumentedWindows, Interval};

/// Every column of every window, before and after the block ring wraps, two channels: the
/// region is the hull of the last `min(blocks of w, complete blocks)` blocks' column ranges,
/// a block being `h` consecutive usable columns (`seen()` counts them).
#[test]
fn each_windows_region_is_the_hull_of_its_newest_complete_blocks() {
    let (h, windows) = (3usize, [9usize, 15, 24]);
    let mut win = InstrumentedWindows::new(1, 1, h, 1, 2, &windows).unwrap().with_ranges(2);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    // Complete blocks' hulls, oldest first, and the open block's.
    let (mut blocks, mut open) = (Vec::<[Interval; 2]>::new(), [Interval::EMPTY; 2]);
    for column in 0..200 {
        let z = [rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5];
        let dy = [0.3 * z[0] - 0.2 * z[1] + 0.01 * rng.random::<f64>()];
        let mut range = [Interval::EMPTY; 2];
        for r in &mut range {
            let (a, b) = (rng.random::<f64>() * 4.0 - 2.0, rng.random::<f64>() * 4.0 - 2.0);
            *r = Interval { lo: a.min(b), hi: a.max(b) };
        }
        let seen = win.seen();
        let done = win.push_column_ranged(&z, &dy, &range);
        if win.seen() > seen {
            for (o, r) in open.iter_mut().zip(range) {
                *o = o.hull(r);
            }
            if done {
                blocks.push(open);
                open = [Interval::EMPTY; 2];
            }
        }
        for (w, &len) in windows.iter().enumerate() {
            let take = (len / h).min(blocks.len());
            let mut want = [Interval::EMPTY; 2];
            for b in &blocks[blocks.len() - take..] {
                for (o, r) in want.iter_mut().zip(b) {
                    *o = o.hull(*r);
                }
            }
            let mut got = [Interval { lo: f64::NAN, hi: f64::NAN }; 2];
            win.window_range(w, &mut got);
            assert_eq!(got, want, "column {column}, window {w}");
        }
    }
    assert!(blocks.len() > 2 * windows[2] / h, "the block ring wrapped more than once");
}
