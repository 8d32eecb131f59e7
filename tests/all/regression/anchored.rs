//! The anchored window (`AnchoredWindow`) against a recompute from the columns: its records
//! are sums of `c` consecutive blocks since the reset, and its estimate is the delete-a-record
//! jackknife of those records with the overlap factor of `c` blocks.

use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::regression::{
    AnchoredWindow, InstrumentedWindows, RateMap, RegressionError, Solve, WindowEstimate,
};

/// `c_{b,h} = 3bh² / (3bh² − h² + 1)`.
fn overlap(b: usize, h: usize) -> f64 {
    let (b, h) = (b as f64, h as f64);
    3.0 * b * h * h / (3.0 * b * h * h - h * h + 1.0)
}

/// At every block of a stream that merges the records five times (and after a reset), the
/// anchored estimate equals the recompute from the columns: `Θ̂ = Cw Q A⁻¹` on every closed
/// record, `Ω̂ = c_{c,h} Σ_r S_r²` with `S_r = (Θ̂ − Θ̂_(r)) T` and
/// `Θ̂_(r) = (Cw − Cw_r) Q (A − N_r Q)⁻¹` (`10⁻⁹` relative), and the counts of records,
/// columns and blocks.
#[test]
fn the_anchored_estimate_is_the_delete_a_record_jackknife_of_every_block_since_the_reset() {
    let (p, m, h, lag) = (1usize, 2usize, 3usize, 1usize);
    let d = p + m;
    let records = 10;
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut win = InstrumentedWindows::new(p, m, h, lag, 1, &[24]).expect("valid");
    let mut anchored = AnchoredWindow::new(&win, records).expect("valid");
    let t = [1.0, -0.7, 0.4];
    let t_vec = DVector::from_column_slice(&t);
    let mut est = WindowEstimate::new(p, m, 1);
    // Columns since the reset: (z, dy).
    let mut cols: Vec<(DVector<f64>, f64)> = Vec::new();
    let (mut state, mut input) = (0.0f64, [0.0f64; 2]);
    let (mut compared, mut merged_seen) = (0, 1);
    for step in 0..4000 {
        if step == 2500 {
            win.reset();
            anchored.reset();
            cols.clear();
        }
        for v in &mut input {
            *v = 0.9 * *v + rng.random::<f64>() - 0.5;
        }
        let z = [state + 2.0, input[0], input[1]];
        let dy = -0.3 * state + 0.4 * input[0] - 0.2 * input[1] + 0.1 * (rng.random::<f64>() - 0.5);
        state += dy;
        cols.push((DVector::from_column_slice(&z), dy));
        if !win.push_column(&z, &[dy]) {
            continue;
        }
        anchored.push_newest(&win);
        // Column i is instrumented once the ring holds `h + lag + 1` columns, by column
        // `i − h − lag`.
        let first = h + lag;
        let usable = cols.len() - first;
        assert_eq!(usable % h, 0);
        assert_eq!(anchored.blocks() as usize, usable / h);
        let c = anchored.coarse();
        merged_seen = merged_seen.max(c);
        let recs = anchored.records();
        assert!(recs < records && (c == 1 || recs >= records / 2), "{recs} records of {c}");
        assert_eq!(recs * c + (anchored.blocks() as usize) % c, anchored.blocks() as usize);
        assert_eq!(anchored.columns(), recs * c * h);
        if recs <= d {
            continue;
        }
        let (theta, omega) = delete_a_record(&cols, (c, h, lag), recs, &t_vec);
        anchored.estimate(
            Solve { ridge: 0.0, rate: RateMap::SymmetricPart(&t), min_pivot_ratio: 0.0 },
            &mut est,
        );
        assert!(est.ready, "step {step}");
        assert_eq!((est.batches, est.columns), (recs, recs * c * h));
        let rel = |x: f64, y: f64| (x - y).abs() / x.abs().max(y.abs()).max(1e-300);
        for (x, y) in est.theta.iter().zip(theta.iter()) {
            assert!(rel(*x, *y) < 1e-9, "step {step}: {x} {y}");
        }
        assert!(rel(est.score_cov[0], omega) < 1e-9, "step {step}: {} {omega}", est.score_cov[0]);
        compared += 1;
    }
    // 2500 columns hold 832 blocks: records of 1, 2, …, 128 blocks.
    assert!(merged_seen >= 64, "records of {merged_seen} blocks at most");
    assert!(compared > 1000, "{compared}");
}

/// A record count that is odd, or too small to keep more records than regressors after a
/// merge, is refused with the field named; a serde round trip checks and reads back the same
/// state.
#[test]
fn anchored_windows_refuse_bad_record_counts_and_round_trip() {
    let mut win = InstrumentedWindows::new(1, 1, 5, 1, 1, &[150]).expect("valid");
    for bad in [0, 5, 6] {
        let err = AnchoredWindow::new(&win, bad).unwrap_err();
        assert!(matches!(err, RegressionError::InvalidConfig { field: "records", .. }), "{bad}");
    }
    let mut anchored = AnchoredWindow::new(&win, 8).expect("valid");
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for _ in 0..400 {
        let z = [rng.random::<f64>(), rng.random::<f64>()];
        if win.push_column(&z, &[rng.random::<f64>()]) {
            anchored.push_newest(&win);
        }
    }
    assert!(anchored.coarse() >= 4);
    let text = serde_json::to_string(&anchored).expect("serialises");
    let back: AnchoredWindow = serde_json::from_str(&text).expect("reads back");
    back.check_state(&win, 8).expect("consistent");
    assert_eq!(back, anchored);
    assert!(back.check_state(&win, 12).is_err(), "a different record count is refused");
}

/// The delete-a-record jackknife by nalgebra over `recs` records of `c` blocks of `h` columns
/// of `cols` (from the first instrumented column, `h + lag`, each instrumented by the column
/// `h + lag` before it): `(Θ̂, Ω̂)`.
fn delete_a_record(
    cols: &[(DVector<f64>, f64)],
    (c, h, lag): (usize, usize, usize),
    recs: usize,
    t_vec: &DVector<f64>,
) -> (DMatrix<f64>, f64) {
    let (d, first) = (t_vec.len(), h + lag);
    // The sums of record r (columns of its c blocks).
    let sums = |r: usize| {
        let (mut nm, mut cw, mut hm) =
            (DMatrix::zeros(d, d), DMatrix::zeros(1, d), DMatrix::zeros(d, d));
        for j in r * c * h..(r + 1) * c * h {
            let (zq, dyq) = &cols[first + j];
            let wv = &cols[first + j - h - lag].0;
            nm += zq * wv.transpose();
            cw += DMatrix::from_element(1, 1, *dyq) * wv.transpose();
            hm += wv * wv.transpose();
        }
        (nm, cw, hm)
    };
    let parts: Vec<_> = (0..recs).map(sums).collect();
    let (mut nm, mut cw, mut hm) =
        (DMatrix::zeros(d, d), DMatrix::zeros(1, d), DMatrix::zeros(d, d));
    for (a, b, e) in &parts {
        nm += a;
        cw += b;
        hm += e;
    }
    let q = hm.try_inverse().expect("invertible") * nm.transpose();
    let a = &nm * &q;
    let theta = &cw * &q * a.clone().try_inverse().expect("invertible");
    let mut omega = 0.0;
    for (nr, cr, _) in &parts {
        let deleted = (&cw - cr) * &q * (&a - nr * &q).try_inverse().expect("invertible");
        let s = ((&theta - deleted) * t_vec)[(0, 0)];
        omega += s * s;
    }
    omega *= overlap(c, h);
    (theta, omega)
}
