//! The streaming aligner against a batch oracle of the sample-and-hold rule, on updates
//! delivered late, reordered, stale and duplicated.

use proptest::prelude::*;
use streamcert_live::{AlignRule, Aligned, Aligner};

mod support;
use support::{Item, Update, oracle};

/// The streaming aligner over the same updates, popping after each.
fn stream(n: usize, rule: AlignRule, updates: &[Update]) -> (Vec<Item>, u64, u64) {
    let mut a = Aligner::new(n, rule).unwrap();
    let mut row = vec![0.0; n];
    let mut items = Vec::new();
    for u in updates {
        let _ = a.push(u.signal, u.t, u.v);
        while let Some(next) = a.pop(&mut row) {
            items.push(match next {
                Aligned::Row(t) => Item::Row(t, row.clone()),
                Aligned::Gap => Item::Gap,
            });
        }
    }
    (items, a.late(), a.stale())
}

/// Updates of `n` signals each sampled every `step` with jitter, delivered with random
/// delays (so reordered and sometimes late), some signals dropping out for a while, some
/// updates duplicated.
fn updates(n: usize, seeds: &[u64], step: f64, delay: f64) -> Vec<Update> {
    let mut out: Vec<(f64, Update)> = Vec::new();
    let mut state =
        seeds.iter().fold(0x2545_f491_4f6c_dd1du64, |s, &x| s ^ x.wrapping_mul(0x9e37_79b9));
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for s in 0..n {
        let mut t = next() * step;
        let mut k = 0;
        while t < 40.0 * step {
            let outage = (12.0 * step..16.0 * step).contains(&t) && s == 1;
            if !outage {
                let u = Update { signal: s, t, v: f64::from(k) + s as f64 / 10.0 };
                let arrival = t + next() * delay;
                out.push((arrival, u));
                if next() < 0.05 {
                    out.push((arrival + next() * delay, u));
                }
            }
            t += step * (0.5 + next());
            k += 1;
        }
    }
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    out.into_iter().map(|(_, u)| u).collect()
}

proptest! {
    #[test]
    fn the_stream_forms_the_oracles_rows(
        n in 1usize..4,
        seeds in proptest::collection::vec(any::<u64>(), 1..3),
        period in prop::sample::select(vec![0.05, 0.1, 0.25]),
        age in 0.0f64..3.0,
        window in 0.0f64..2.0,
        delay in 0.0f64..0.4,
    ) {
        let rule = AlignRule { period, max_age: age * period, reorder_window: window * period };
        let ups = updates(n, &seeds, 0.1, delay);
        let (want, late, stale) = oracle(n, rule, &ups);
        let (got, got_late, got_stale) = stream(n, rule, &ups);
        prop_assert_eq!(&got, &want);
        prop_assert_eq!((got_late, got_stale), (late, stale));
    }
}

#[test]
fn late_reordered_and_stale_updates_by_hand() {
    let rule = AlignRule { period: 1.0, max_age: 1.5, reorder_window: 1.0 };
    let mut a = Aligner::new(2, rule).unwrap();
    let mut row = [0.0; 2];
    let mut pop = |a: &mut Aligner| a.pop(&mut row).map(|x| (x, row));
    // Signal 0 at 0.5 and 1.2, signal 1 at 0.9; 1.2 arrives before 0.5 (reordered).
    a.push(0, 1.2, 12.0).unwrap();
    a.push(1, 0.9, 9.0).unwrap();
    a.push(0, 0.5, 5.0).unwrap();
    assert_eq!(pop(&mut a), None, "grid 1 needs the watermark at 2");
    a.push(1, 2.1, 21.0).unwrap();
    // Grid 1.0: signal 0's latest at or before it is 0.5 (1.2 is later), signal 1's 0.9.
    assert_eq!(pop(&mut a), Some((Aligned::Row(1.0), [5.0, 9.0])));
    assert_eq!(pop(&mut a), None);
    // Too late for grid 1.0.
    assert!(a.push(0, 0.95, 0.0).is_err());
    assert_eq!(a.late(), 1);
    // Signal 0 goes quiet: at grid 3 its 1.2 is 1.8 old (> 1.5): stale, then a gap.
    a.push(1, 3.0, 30.0).unwrap();
    a.push(1, 4.5, 45.0).unwrap();
    // Grid 2.0: signal 1's 2.1 is after it, so its 0.9 (1.1 old) still holds.
    assert_eq!(pop(&mut a), Some((Aligned::Row(2.0), [12.0, 9.0])));
    assert_eq!(pop(&mut a), None, "grid 3 is stale");
    assert_eq!(a.stale(), 1);
    a.push(0, 3.6, 36.0).unwrap();
    a.push(1, 5.5, 55.0).unwrap();
    assert_eq!(pop(&mut a), Some((Aligned::Gap, [12.0, 9.0])));
    assert_eq!(pop(&mut a), Some((Aligned::Row(4.0), [36.0, 30.0])));
}

#[test]
fn a_resumed_aligner_continues_as_the_uninterrupted_one() {
    let rule = AlignRule { period: 0.1, max_age: 0.2, reorder_window: 0.15 };
    let ups = updates(3, &[7, 11], 0.1, 0.3);
    let (want, _, _) = stream(3, rule, &ups);
    let cut = ups.len() / 2;
    let (mut got, _, _) = stream(3, rule, &ups[..cut]);
    // Save at the cut (as a checkpoint does, through JSON), restore, go on.
    let mut a = Aligner::new(3, rule).unwrap();
    let mut row = vec![0.0; 3];
    for u in &ups[..cut] {
        let _ = a.push(u.signal, u.t, u.v);
        while a.pop(&mut row).is_some() {}
    }
    let text = serde_json::to_string(&a).unwrap();
    let mut b: Aligner = serde_json::from_str(&text).unwrap();
    assert_eq!(a, b);
    assert!(b.is_consistent());
    // A state whose buffers do not fit its signals is refused before it is used.
    let mut value: serde_json::Value = serde_json::from_str(&text).unwrap();
    value["out"] = serde_json::json!([1.0]);
    let damaged: Aligner = serde_json::from_value(value).unwrap();
    assert!(!damaged.is_consistent());
    for u in &ups[cut..] {
        let _ = b.push(u.signal, u.t, u.v);
        while let Some(next) = b.pop(&mut row) {
            got.push(match next {
                Aligned::Row(t) => Item::Row(t, row.clone()),
                Aligned::Gap => Item::Gap,
            });
        }
    }
    assert_eq!(got, want);
}
