//! The array-level core against the command line: the same numbers bit for bit, checkpoints
//! that resume at every sample, blocks refused whole.

use streamcert_pipeline::certify::{self, Options};
use streamcert_python::config::from_json_over_defaults;
use streamcert_python::simulate::{G5Run, simulate_g5};
use streamcert_python::{Error, EvidenceColumns, FLOAT_COLUMNS, GATES, Run};

fn g5(steps: usize) -> G5Run {
    simulate_g5(1, 0, Some(steps), None, false).unwrap()
}

/// Node b's columns: `t`, `y_b`, `u_b`.
fn node_b(d: &G5Run) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let y = d.y.chunks(2).map(|r| r[1]).collect();
    let u = d.u.chunks(2).map(|r| r[1]).collect();
    (d.t.clone(), y, u)
}

/// Node b's required keys (columns `t`, `y_b`, `u_b`, the gain `[[-4.0]]`, `margin`) with
/// `window` columns in the regression (`None`: the default).
fn node_b_config(window: Option<usize>, margin: f64) -> streamcert_python::config::ConfigText {
    let regression =
        window.map_or(String::new(), |w| format!(r#", "regression": {{"window": {w}}}"#));
    from_json_over_defaults(&format!(
        r#"{{"columns": {{"time": "t", "outputs": ["y_b"], "inputs": ["u_b"]}},
            "controller": {{"gain": [[-4.0]]}}, "certificate": {{"margin": {margin}}}{regression}}}"#
    ))
    .unwrap()
}

fn csv_of(t: &[f64], y: &[f64], u: &[f64]) -> String {
    let mut s = String::from("t,y_b,u_b\n");
    for k in 0..t.len() {
        s += &format!("{},{},{}\n", t[k], y[k], u[k]);
    }
    s
}

fn opts() -> Options {
    Options::default()
}

#[test]
fn columns_equal_the_command_lines_csv_bit_for_bit() {
    let (t, y, u) = node_b(&g5(900));
    let cfg = node_b_config(Some(100), 0.05);
    let mut out = Vec::new();
    let summary =
        certify::run(&cfg.config, csv_of(&t, &y, &u).as_bytes(), "g5", &mut out, &opts()).unwrap();
    let mut run = Run::new(cfg.config.clone()).unwrap();
    let mut cols = run.columns(t.len());
    run.push_block(&t, &y, &u, &mut cols).unwrap();
    let text = String::from_utf8(out).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let rows: Vec<Vec<&str>> = lines.map(|l| split_csv(l)).collect();
    assert_eq!(rows.len(), t.len());
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let number = |s: &str| if s.is_empty() { f64::NAN } else { s.parse::<f64>().unwrap() };
    let same = |a: f64, b: f64| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
    for (name, v) in FLOAT_COLUMNS.iter().zip(&cols.floats) {
        let c = col(name);
        for k in 0..t.len() {
            assert!(same(number(rows[k][c]), v[k]), "{name} row {k}: {} vs {}", rows[k][c], v[k]);
        }
    }
    for (g, gate) in GATES.iter().enumerate() {
        let (o, r) = (col(&format!("{gate}_open")), col(&format!("reason_{gate}")));
        let texts = cols.reason_texts(g);
        for k in 0..t.len() {
            assert_eq!(rows[k][o] == "1", cols.open[g][k], "{gate} row {k}");
            assert_eq!(rows[k][r].trim_matches('"'), texts[k], "{gate} reason row {k}");
        }
    }
    for (name, v) in cols.region_names.iter().zip(&cols.regions) {
        let c = col(name);
        for k in 0..t.len() {
            assert!(same(number(rows[k][c]), v[k]), "{name} row {k}");
        }
    }
    // The same summary (the calibrated region of the end included).
    assert_eq!(run.summary(), summary);
    assert!(cols.open[2].iter().any(|&o| o), "the calibrated gate opens on G5's node b");
}

/// Fields of a CSV line (the reasons may be quoted and hold commas).
fn split_csv(line: &str) -> Vec<&str> {
    let (mut out, mut start, mut quoted) = (Vec::new(), 0, false);
    for (i, c) in line.char_indices() {
        match c {
            '"' => quoted = !quoted,
            ',' if !quoted => {
                out.push(&line[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    out.push(&line[start..]);
    out
}

#[test]
fn a_checkpoint_after_any_sample_resumes_to_the_uninterrupted_run() {
    let (t, y, u) = node_b(&g5(400));
    let cfg = node_b_config(Some(60), 0.05).config;
    let mut whole = Run::new(cfg.clone()).unwrap();
    let mut expected = whole.columns(t.len());
    whole.push_block(&t, &y, &u, &mut expected).unwrap();
    // Every one of the first samples (the states right after the first sample hold NaN
    // references), then every 37th.
    for cut in (1..12).chain((12..t.len()).step_by(37)) {
        let mut a = Run::new(cfg.clone()).unwrap();
        let mut got = a.columns(t.len());
        a.push_block(&t[..cut], &y[..cut], &u[..cut], &mut got).unwrap();
        let text = a.checkpoint().unwrap();
        let mut b = Run::restore(&text, cfg.clone()).unwrap();
        b.push_block(&t[cut..], &y[cut..], &u[cut..], &mut got).unwrap();
        let (g, e) = (format!("{got:?}"), format!("{expected:?}"));
        if g != e {
            let at = g.bytes().zip(e.bytes()).position(|(a, b)| a != b).unwrap_or(0);
            panic!(
                "cut at {cut}: {} vs {}",
                &g[at.saturating_sub(300)..at + 80],
                &e[at.saturating_sub(300)..at + 80]
            );
        }
        assert_eq!(b.summary(), whole.summary(), "cut at {cut}");
    }
}

#[test]
fn a_refused_block_absorbs_nothing_and_names_row_and_column() {
    let (t, y, mut u) = node_b(&g5(50));
    let cfg = node_b_config(None, 0.05).config;
    let mut run = Run::new(cfg).unwrap();
    let mut cols = run.columns(0);
    run.push_block(&t[..10], &y[..10], &u[..10], &mut cols).unwrap();
    let before = run.checkpoint().unwrap();
    u[30] = f64::NAN;
    let err = run.push_block(&t[10..], &y[10..], &u[10..], &mut cols).unwrap_err();
    assert_eq!(
        err,
        Error::Data {
            row: 20,
            column: Some("u_b".into()),
            message: "expected a finite number, found `NaN` (NaN and infinity are not accepted)"
                .into()
        }
    );
    assert_eq!(run.checkpoint().unwrap(), before);
    assert_eq!(cols.len(), 10);
    // A time that does not increase, against the last time absorbed.
    let err = run.push_block(&[t[9]], &[0.0], &[0.0], &mut cols).unwrap_err();
    assert!(
        matches!(err, Error::Data { row: 0, ref column, .. } if column.as_deref() == Some("t"))
    );
    // Lengths that do not match p and m.
    assert!(matches!(
        run.push_block(&t[10..12], &y[10..11], &u[10..12], &mut cols),
        Err(Error::Shape(_))
    ));
    let _ = EvidenceColumns::default();
}

#[test]
fn a_checkpoint_of_another_configuration_or_damaged_is_refused() {
    let (t, y, u) = node_b(&g5(30));
    let cfg = node_b_config(None, 0.05).config;
    let other = node_b_config(None, 0.1).config;
    let mut run = Run::new(cfg.clone()).unwrap();
    let mut cols = run.columns(0);
    run.push_block(&t, &y, &u, &mut cols).unwrap();
    let text = run.checkpoint().unwrap();
    assert!(matches!(Run::restore(&text, other), Err(Error::Checkpoint(_))));
    let mut damaged = text;
    let at = damaged.len() / 2;
    damaged[at] = if damaged[at] == b'1' { b'2' } else { b'1' };
    assert!(matches!(Run::restore(&damaged, cfg.clone()), Err(Error::Checkpoint(_))));
    assert!(matches!(Run::restore(b"\xff\xfe", cfg), Err(Error::Checkpoint(_))));
}

#[test]
fn a_long_block_on_two_threads_equals_the_samples_one_by_one() {
    let (t, y, u) = node_b(&g5(40_000));
    let cfg = node_b_config(None, 0.05).config;
    let mut whole = Run::new(cfg.clone()).unwrap();
    let mut got = whole.columns(t.len());
    whole.push_block(&t, &y, &u, &mut got).unwrap();
    let mut single = Run::new(cfg).unwrap();
    let mut expected = single.columns(t.len());
    for k in 0..t.len() {
        let ev = single.push(t[k], &y[k..=k], &u[k..=k]).unwrap();
        expected.push(&ev, single.last_region());
    }
    assert_eq!(format!("{got:?}"), format!("{expected:?}"));
    assert_eq!(whole.summary(), single.summary());
}

/// A mapping without the gain or the margin is refused naming them; a misspelt key is named
/// by its path, not by a line of a TOML text the caller never saw.
#[test]
fn mappings_are_refused_by_key_path() {
    let err = from_json_over_defaults("{}").unwrap_err().to_string();
    assert!(err.contains("controller.gain") && err.contains("certificate.margin"), "{err}");
    let err = from_json_over_defaults(
        r#"{"columns": {"time": "t", "outputs": ["y"], "inputs": ["u"]},
            "controller": {"gain": [[-4.0]]}, "certificate": {"margin": 0.05, "margn": 1}}"#,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("`certificate.margn`") && err.contains("unknown field"), "{err}");
    assert!(!err.contains("line"), "{err}");
    let err = from_json_over_defaults(
        r#"{"columns": {"time": "t", "outputs": ["y"], "inputs": ["u"]},
            "controller": {"gain": [[-4.0]]}, "certificate": {"margin": 0.05},
            "regression": {"window": "long"}}"#,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("`regression.window`"), "{err}");
}

/// `{"regression": {"order": 2, ...}}` from Python runs the certificate of order 2: the
/// configuration reads as the command line's, G5's node b (a first-order loop at its
/// horizon) gives rows whose paper verdicts are not computed and whose calibrated column is
/// the order-2 certificate's, and what order 2 does not support is refused by its key.
#[test]
fn order_two_from_a_mapping_runs_the_certificate_of_order_two() {
    let json = |order: u8, window: usize, horizon: usize| {
        from_json_over_defaults(&format!(
            r#"{{"columns": {{"time": "t", "outputs": ["y_b"], "inputs": ["u_b"]}},
                "controller": {{"gain": [[-4.0]]}}, "certificate": {{"margin": 0.05}},
                "regression": {{"order": {order}, "window": {window}, "horizon": {horizon}}}}}"#
        ))
    };
    let cfg = json(2, 600, 5).unwrap();
    let on = cfg.config.certifier.order_n().expect("order 2");
    assert_eq!((on.regression.model.order(), on.regression.window), (2, 600));
    let mut run = Run::new(cfg.config).unwrap();
    let (t, y, u) = node_b(&g5(1000));
    let mut last = None;
    for k in 0..t.len() {
        let ev = run.push(t[k], &[y[k]], &[u[k]]).unwrap();
        assert_eq!(ev.gaussian.reason, Some(streamcert_certificate::NotCertified::FirstOrderOnly));
        last = Some(ev);
    }
    // 1000 samples, 990 rows of order 2: the window (600 rows) has looked.
    let last = last.unwrap();
    assert_eq!(last.columns, 600);
    assert!(last.calibrated_window == Some(600), "{last:?}");
    // Too small a window for the horizon is refused, naming the bound.
    let err = json(2, 100, 50).unwrap_err().to_string();
    assert!(err.contains("min_rows"), "{err}");
    assert!(json(4, 600, 5).is_err());
}
