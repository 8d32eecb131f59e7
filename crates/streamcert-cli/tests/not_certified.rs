//! A NOT CERTIFIED that explains itself: a candidate the data refuse is explained by the bound
//! the data give (in the row's words), its picture keeps the estimate and the bounds inside
//! the axis, a header-only file exits 3 as an empty file does, a time column in milliseconds gets a
//! hint, and the gates a skipped row closes reopen at the `consecutive`-th sample after it,
//! as the command line's text says.

mod common;

use common::{run, text, tmp};
use rand::{Rng, SeedableRng};

/// A scalar plant `dx = (a x + u) dt + noise`, `y = x + noise`, sampled every 0.1 s for
/// 300 s under a ±1 input that may switch every second (seeded): the CSV, its time scaled
/// by `time_scale`.
fn scalar_loop(a: f64, time_scale: f64) -> Vec<u8> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut normal = move || {
        let (u1, u2): (f64, f64) = (rng.random::<f64>().max(1e-300), rng.random());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    let (dt, mut x, mut u) = (0.1, 0.0, 1.0);
    let mut out = String::from("t,y,u\n");
    for k in 0..3000u32 {
        if k % 10 == 0 {
            u = if normal() > 0.0 { 1.0 } else { -1.0 };
        }
        let y = x + 0.01 * normal();
        out.push_str(&format!("{},{y},{u}\n", f64::from(k) * dt * time_scale));
        x += dt * (a * x + u) + dt.sqrt() * 0.02 * normal();
    }
    out.into_bytes()
}

/// The template with the scalar loop's columns, candidate `gain` and margin 0.05 /s.
fn config(tag: &str, gain: f64) -> std::path::PathBuf {
    let out = run(&["certify", "--print-config"], b"");
    let template = text(&out.stdout)
        .replace("time = \"REQUIRED\"", "time = \"t\"")
        .replace("outputs = [\"REQUIRED\"]", "outputs = [\"y\"]")
        .replace("inputs = [\"REQUIRED\"]", "inputs = [\"u\"]")
        .replace("gain = \"REQUIRED\"", &format!("gain = [[{gain}]]"))
        .replace("margin = \"REQUIRED\"", "margin = 0.05");
    let path = tmp(&format!("not-certified-{tag}.toml"));
    std::fs::write(&path, template).unwrap();
    path
}

fn certify(config: &std::path::Path, data: &[u8], extra: &[&str]) -> (Option<i32>, String, String) {
    let mut args = vec!["certify", "--config", config.to_str().unwrap()];
    args.extend_from_slice(extra);
    let out = run(&args, data);
    (out.status.code(), text(&out.stdout), text(&out.stderr))
}

#[test]
fn a_refused_candidate_is_explained_by_the_bound_the_data_give() {
    // a = -0.3: K = +0.5 gives a closed-loop rate of -0.2 /s; K = -0.5 one of 0.8 /s.
    let data = scalar_loop(-0.3, 1.0);
    let (code, _, err) = certify(&config("good", -0.5), &data, &[]);
    assert_eq!(code, Some(0));
    assert!(err.starts_with("verdict: CERTIFIED"), "{err}");
    let svg = tmp("refused.svg");
    let (code, _, err) =
        certify(&config("refused", 0.5), &data, &["--plot", svg.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{err}");
    let verdict = err.lines().next().unwrap();
    assert!(verdict.starts_with("verdict: NOT CERTIFIED for K = [[0.5]]"), "{verdict}");
    assert!(
        verdict.contains("the newest data bound the rate below the margin [rate_below_margin] in"),
        "{verdict}"
    );
    // The row's own words with the bound, and the bound near the true rate, -0.2.
    let at_most = verdict.split("the rate is at most ").nth(1).expect("the bound quoted");
    let bound: f64 = at_most.split(',').next().unwrap().parse().unwrap();
    assert!((-0.3..0.0).contains(&bound), "{bound} in {verdict}");
    assert!(!verdict.contains("dropped") && !verdict.contains("newer window"), "{verdict}");
    // The picture: the bound's line in the legend, nothing clipped.
    let picture = std::fs::read_to_string(&svg).unwrap();
    assert!(picture.contains("the newest window"), "the upper bound's line");
    assert!(!picture.contains("clipped"));
}

#[test]
fn a_header_only_file_has_no_data_as_an_empty_file_and_exits_3() {
    let cfg = config("header", -0.5);
    // From a file (buffered output) and from a pipe (each row flushed), as from a live feed.
    let file = tmp("header-only.csv");
    std::fs::write(&file, b"t,y,u\n").unwrap();
    let from_file = ["--input", file.to_str().unwrap()];
    let (code, _, err) = certify(&cfg, b"", &from_file);
    assert_eq!(code, Some(3), "{err}");
    assert!(err.contains("no data row"), "{err}");
    for flags in [&[][..], &["--require-certified"]] {
        let (code, _, err) = certify(&cfg, b"t,y,u\n", flags);
        assert_eq!(code, Some(3), "{flags:?}: {err}");
        assert!(err.contains("no data row") && err.contains("header"), "{err}");
        assert!(!err.contains("CERTIFIED"), "no verdict without data: {err}");
        // Blank lines after the header are no rows either; an empty file exits 3 as well.
        let (code, _, _) = certify(&cfg, b"t,y,u\n\n\n", flags);
        assert_eq!(code, Some(3), "{flags:?}");
        let (code, _, err) = certify(&cfg, b"", flags);
        assert_eq!(code, Some(3), "{flags:?}");
        assert!(err.contains("empty input"), "{err}");
    }
    // One malformed row skipped is a row: the run ends with its verdict, as before.
    let (code, _, err) = certify(&cfg, b"t,y,u\n0,x,1\n", &["--on-bad-row", "skip"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(err.contains("NOT CERTIFIED") && err.contains("[skipped_sample]"), "{err}");
}

#[test]
fn a_time_column_in_milliseconds_gets_a_hint() {
    let cfg = config("ms", -0.5);
    let (_, _, seconds) = certify(&cfg, &scalar_loop(-0.3, 1.0), &[]);
    assert!(!seconds.contains("hint:"), "{seconds}");
    let (_, _, ms) = certify(&cfg, &scalar_loop(-0.3, 1000.0), &[]);
    let hint = ms.lines().find(|l| l.starts_with("hint:")).expect("a hint");
    assert!(hint.contains("median step is 100") && hint.contains("divide them by 1000"), "{hint}");
    let json = tmp("ms-summary.json");
    let _ = certify(&cfg, &scalar_loop(-0.3, 1000.0), &["--summary", json.to_str().unwrap()]);
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
    assert!(v["hint"].as_str().unwrap().contains("milliseconds"));
}

#[test]
fn a_skipped_row_closes_the_gates_for_consecutive_samples_as_the_text_says() {
    let cfg = config("skip", -0.5);
    let data = String::from_utf8(scalar_loop(-0.3, 1.0)).unwrap();
    let mut lines: Vec<&str> = data.lines().collect();
    lines.insert(2001, "200.05,not-a-number,1");
    let bad = lines.join("\n") + "\n";
    let (code, _, err) = certify(&cfg, bad.as_bytes(), &[]);
    assert_eq!(code, Some(3));
    assert!(err.contains("every gate closes there and reopens at the `consecutive`-th"), "{err}");
    let (code, out, err) = certify(&cfg, bad.as_bytes(), &["--on-bad-row", "skip"]);
    assert_eq!(code, Some(0), "{err}");
    let mut rows = csv::Reader::from_reader(out.as_bytes());
    let header = rows.headers().unwrap().clone();
    let gi = header.iter().position(|h| h == "calibrated_open").unwrap();
    let open: Vec<bool> = rows.records().map(|r| &r.unwrap()[gi] == "1").collect();
    // Row 1999 (0-based, the last before the bad one) is open; the gate reopens at the
    // `consecutive`-th row after the skipped one (the template's 10), not before, not later.
    assert!(open[1999], "open before the skipped row");
    let closed = open[2000..].iter().take_while(|o| !**o).count();
    assert_eq!(closed + 1, 10, "reopens at the `consecutive`-th row after the skipped one");
}
