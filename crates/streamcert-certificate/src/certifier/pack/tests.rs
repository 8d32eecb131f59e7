//! The packing's source map against an oracle, and its round trip over shapes.

use super::*;

fn shape(p: usize, m: usize, intervals: usize) -> Shape {
    Shape {
        p,
        d: p + m,
        intervals,
        horizon: 5,
        lag: 1,
        head: 2,
        len: 3,
        coarse: 1,
        lengths: vec![4, 8],
    }
}

/// Oracle: the shared entries named by index arithmetic against the same entries named by
/// their regressor and instrument, for one and two outputs and one and two intervals.
#[test]
fn a_guards_shared_entries_are_the_linear_rings_same_products() {
    for (p, m, extra, j) in [(1, 2, 1, 1), (1, 2, 2, 1), (2, 1, 2, 2), (1, 1, 3, 2)] {
        let (lin, big) = (shape(p, m, j), shape(p, m + extra, j));
        let (ld, d) = (lin.d, big.d);
        let (lk, k) = (lin.k(), big.k());
        let src = big.sources(Some(&lin));
        assert_eq!(src.len(), big.stride());
        // Name each entry: (block part, row, instrument as (interval, regressor)).
        let name =
            |idx: usize, d: usize, k: usize| -> (u8, usize, (usize, usize), (usize, usize)) {
                let (n, cw) = (d * k, p * k);
                if idx < n {
                    (0, idx / k, ((idx % k) / d, (idx % k) % d), (0, 0))
                } else if idx < n + cw {
                    let i = idx - n;
                    (1, i / k, ((i % k) / d, (i % k) % d), (0, 0))
                } else {
                    let i = idx - n - cw;
                    (2, 0, ((i / k) / d, (i / k) % d), ((i % k) / d, (i % k) % d))
                }
            };
        for (idx, s) in src.iter().enumerate() {
            let (part, row, a, b) = name(idx, d, k);
            let extra_term = |x: (usize, usize)| x.1 >= ld;
            let shared = match part {
                0 => row < ld && !extra_term(a),
                1 => !extra_term(a),
                _ => !extra_term(a) && !extra_term(b),
            };
            match *s {
                Source::Linear(li) => {
                    assert!(shared, "{idx}");
                    assert_eq!(name(li, ld, lk), (part, row, a, b), "{p} {m} {extra} {j}: {idx}");
                }
                Source::Mirror(mi) => {
                    assert!(!shared && part == 2 && a > b);
                    assert_eq!(name(mi, d, k), (2, 0, b, a));
                }
                Source::Stored => assert!(!(shared || part == 2 && a > b)),
            }
        }
    }
}

/// Block records as the rings form them: for each block, sums over `cols` columns of the
/// outer products of the regressors `z` (`d`), the increments (`p`) and the instruments (the
/// regressors of `intervals` earlier columns), the linear ring's from the first `ld` of each.
fn rings(
    (p, ld, d, intervals): (usize, usize, usize, usize),
    cap: usize,
    values: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let mut at = 0;
    let mut next = || {
        at += 1;
        values[at % values.len()] * (1.0 + at as f64 / 7.0)
    };
    let (mut lin, mut big) = (Vec::new(), Vec::new());
    for _ in 0..cap {
        let (k, lk) = (intervals * d, intervals * ld);
        let (mut rl, mut rb) = (vec![0.0; (ld + p) * lk + lk * lk], vec![0.0; (d + p) * k + k * k]);
        for _ in 0..3 {
            let z: Vec<f64> = (0..d).map(|_| next()).collect();
            let dy: Vec<f64> = (0..p).map(|_| next()).collect();
            let w: Vec<f64> = (0..k).map(|_| next()).collect();
            let lw: Vec<f64> = (0..lk).map(|c| w[(c / ld) * d + c % ld]).collect();
            for (r, z, w, dd) in [(&mut rb, &z[..], &w[..], d), (&mut rl, &z[..ld], &lw[..], ld)] {
                let k = w.len();
                let rows = z.iter().chain(&dy).copied().collect::<Vec<_>>();
                for (a, &za) in rows.iter().enumerate() {
                    for (b, &wb) in w.iter().enumerate() {
                        r[a * k + b] += za * wb;
                    }
                }
                for a in 0..k {
                    for b in 0..k {
                        r[(dd + p) * k + a * k + b] += w[a] * w[b];
                    }
                }
            }
        }
        lin.extend(rl);
        big.extend(rb);
    }
    (lin, big)
}

proptest::proptest! {
    /// Over shapes (outputs, inputs, extra terms, instrument intervals, blocks): both rings
    /// pack and unpack to the same bits; one bit flipped in any derived entry keeps a ring
    /// whole; a byte more or less is refused.
    #[test]
    fn packing_round_trips_and_refuses_what_does_not_derive(
        (p, m, extra, intervals) in (1usize..3, 1usize..3, 1usize..4, 1usize..3),
        cap in 1usize..5,
        values in proptest::collection::vec(-1e3f64..1e3, 1..40),
        flip in 0usize..10_000,
    ) {
        let mut lin = shape(p, m, intervals);
        lin.lengths = vec![cap];
        let big = Shape { d: lin.d + extra, ..lin.clone() };
        let (lring, gring) = rings((p, lin.d, big.d, intervals), cap, &values);
        for (ring, sources, base) in [
            (&lring, lin.sources(None), &[][..]),
            (&gring, big.sources(Some(&lin)), &lring[..]),
        ] {
            let bytes = pack_ring(ring, &sources, base).expect("packs");
            let back = unpack_ring(&bytes, &sources, cap, base).expect("fits");
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            proptest::prop_assert_eq!(bits(&back), bits(ring));
            let derived: Vec<usize> = (0..ring.len())
                .filter(|i| sources[i % sources.len()] != Source::Stored)
                .collect();
            if !derived.is_empty() {
                let i = derived[flip % derived.len()];
                let mut bent = ring.clone();
                bent[i] = f64::from_bits(bent[i].to_bits() ^ 1);
                proptest::prop_assert!(pack_ring(&bent, &sources, base).is_none());
            }
            proptest::prop_assert!(unpack_ring(&bytes[8..], &sources, cap, base).is_none());
            let mut longer = bytes.clone();
            longer.extend_from_slice(&[0; 8]);
            proptest::prop_assert!(unpack_ring(&longer, &sources, cap, base).is_none());
        }
    }
}

/// The default shape's counts (`p = 1`, `y`, `u`, `τ`; the guards' one and two extra terms):
/// 18, 12 and 27 values written per block of 21, 36 and 55.
#[test]
fn the_default_rings_write_18_12_and_27_values_per_block() {
    let lin = shape(1, 2, 1);
    let stored = |s: &[Source]| s.iter().filter(|s| **s == Source::Stored).count();
    assert_eq!((lin.stride(), stored(&lin.sources(None))), (21, 18));
    for (extra, want) in [(1, (36, 12)), (2, (55, 27))] {
        let big = Shape { d: lin.d + extra, ..lin.clone() };
        assert_eq!((big.stride(), stored(&big.sources(Some(&lin)))), want);
    }
}
