//! The verdict a script and a person get from the binary: `--require-certified` sets the
//! exit status, `--plot` draws the run, a header read as one field names the delimiter
//! setting to change, a real plant's verdict does not depend on its sensor's units, and a
//! skipped last row leaves the run not certified.

mod common;

use common::{config, network_example, run, simulate, text, tmp};

/// `--require-certified`: exit 6 exactly when the verdict at the end is not "certified", after
/// every output is written; without the flag the same run exits 0.
#[test]
fn require_certified_sets_the_exit_status_from_the_verdict() {
    let cfg = config("require");
    let path = cfg.to_str().expect("utf8");
    let mut seen = [false, false];
    for (seed, summary) in [("6", "require-6.json"), ("1", "require-1.json")] {
        let data = simulate(seed);
        let json = tmp(summary);
        let args = ["certify", "--config", path, "--require-certified", "--summary"];
        let mut args: Vec<&str> = args.to_vec();
        args.push(json.to_str().expect("utf8"));
        let out = run(&args, &data);
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).expect("summary")).expect("json");
        let certified = v["certified_at_end"].as_bool().expect("bool");
        let verdict = v["verdict"].as_str().expect("verdict");
        assert_eq!(verdict.starts_with("verdict: CERTIFIED"), certified, "{verdict}");
        // Either way it names the candidate it judged: the gain and the margin.
        assert!(verdict.contains("for K = [[-4]] at the margin 0.05 /s"), "{verdict}");
        // A certified verdict states the assumption its risk rests on.
        assert_eq!(verdict.contains("the risk assumes dynamics linear"), certified, "{verdict}");
        assert_eq!(out.status.code(), Some(if certified { 0 } else { 6 }), "{verdict}");
        assert_eq!(text(&out.stdout).lines().count(), 1 + 1501, "every row is written first");
        seen[usize::from(certified)] = true;
        let free = run(&["certify", "--config", path], &data);
        assert_eq!(free.status.code(), Some(0));
    }
    // The paper-only mode's verdict is its Gaussian gate.
    let paper = tmp("config-require-paper.toml");
    let text_cfg = std::fs::read_to_string(&cfg)
        .expect("config")
        .replace("enabled = true\ndelta = 0.01", "enabled = false\ndelta = 0.01");
    std::fs::write(&paper, text_cfg).expect("write config");
    let out = run(
        &["certify", "--config", paper.to_str().expect("utf8"), "--require-certified"],
        &simulate("6"),
    );
    let open_at_end =
        text(&out.stdout).lines().last().expect("rows").split(',').nth(8) == Some("1");
    let verdict = text(&out.stderr);
    assert!(verdict.contains("NO STATED RISK) for K = [[-4]] at the margin 0.05 /s"), "{verdict}");
    assert_eq!(out.status.code(), Some(if open_at_end { 0 } else { 6 }));
    seen[usize::from(open_at_end)] = true;
    assert!(seen[0] && seen[1], "both outcomes exercised: {seen:?}");
}

/// `--plot` writes a picture of a `certify` run and of a `network` run, as PNG and as SVG;
/// another extension is refused before any data is read (exit 2).
#[test]
fn plot_draws_a_picture_of_certify_and_network_runs() {
    let cfg = config("plot");
    let data = simulate("2");
    for ext in ["png", "svg"] {
        let picture = tmp(&format!("run.{ext}"));
        let _ = std::fs::remove_file(&picture);
        let out = run(
            &[
                "certify",
                "--config",
                cfg.to_str().expect("utf8"),
                "--plot",
                picture.to_str().expect("utf8"),
            ],
            &data,
        );
        assert!(out.status.success(), "{}", text(&out.stderr));
        let bytes = std::fs::read(&picture).expect("the picture is written");
        match ext {
            "png" => assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n"),
            _ => {
                let svg = String::from_utf8(bytes).expect("utf8");
                assert!(svg.starts_with("<svg") && svg.contains("calibrated certificate"));
            }
        }
    }
    let net_data =
        run(&["simulate", "g5", "--experiment", "2", "--coupling", "bidirectional"], b"");
    let example = network_example();
    let net_cfg = tmp("network-plot.toml");
    std::fs::write(&net_cfg, &example).expect("write");
    for ext in ["png", "svg"] {
        let picture = tmp(&format!("network.{ext}"));
        let _ = std::fs::remove_file(&picture);
        let out = run(
            &[
                "network",
                "--config",
                net_cfg.to_str().expect("utf8"),
                "--plot",
                picture.to_str().expect("utf8"),
            ],
            &net_data.stdout,
        );
        assert!(out.status.success(), "{}", text(&out.stderr));
        let bytes = std::fs::read(&picture).expect("the picture is written");
        assert!(bytes.len() > 1000);
        if ext == "svg" {
            assert!(String::from_utf8(bytes).expect("utf8").contains("network rate"));
        }
    }
    let bad =
        run(&["certify", "--config", cfg.to_str().expect("utf8"), "--plot", "run.pdf"], &data);
    assert_eq!(bad.status.code(), Some(2), "{}", text(&bad.stderr));
    assert!(text(&bad.stderr).contains(".png or an .svg"));
}

/// A file whose header is one field because it uses another delimiter: the message names the
/// setting to change.
#[test]
fn a_foreign_delimiter_names_the_setting_to_change() {
    let cfg = config("semicolon");
    let out = run(&["certify", "--config", cfg.to_str().expect("utf8")], b"t;y_b;u_b\n0;0;0\n");
    assert_eq!(out.status.code(), Some(3));
    let err = text(&out.stderr);
    assert!(err.contains("set `delimiter = \";\"` in [columns]"), "{err}");
}

/// The committed heat-exchanger record (examples/real/, DaISy 97-002, about 98 °C) certified
/// with its configuration, as logged in °C and with the temperature in K (plus 273.15): the
/// same gates at every row, and `β̂`, `ρ` and the calibrated certificate equal to 10⁻⁹
/// relative (the working origin makes both runs integrate the same excursions; only the
/// rounding of the offset differs, about 10⁻¹⁴ relative per sample). The paper's model
/// through the origin, on the same two files, is shown to depend on the units, so the
/// comparison can fail.
#[test]
fn the_heat_exchanger_gets_the_same_verdict_in_celsius_and_kelvin() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/real");
    let celsius = std::fs::read_to_string(root.join("exchanger.csv")).expect("record");
    let mut lines = celsius.lines();
    let mut kelvin = format!("{}\n", lines.next().expect("header"));
    for line in lines {
        let (head, temp) = line.rsplit_once(',').expect("three fields");
        let temp: f64 = temp.parse().expect("a temperature");
        kelvin.push_str(&format!("{head},{}\n", temp + 273.15));
    }
    let config = std::fs::read_to_string(root.join("exchanger.toml")).expect("config");
    let origin = config.replace("model = \"affine\"", "model = \"through_origin\"");
    assert_ne!(origin, config, "the configuration names its model");
    let rows = |cfg: &str, tag: &str, data: &str| -> Vec<Vec<String>> {
        let path = tmp(&format!("config-exchanger-{tag}.toml"));
        std::fs::write(&path, cfg).expect("write config");
        let out = run(&["certify", "--config", path.to_str().expect("utf8")], data.as_bytes());
        assert!(out.status.success(), "{}", text(&out.stderr));
        text(&out.stdout).lines().map(|l| l.split(',').map(String::from).collect()).collect()
    };
    let (c, k) = (rows(&config, "c", &celsius), rows(&config, "k", &kelvin));
    assert_eq!(c.len(), 4001, "every sample has its row");
    assert_eq!(c.len(), k.len());
    let col = |name: &str| c[0].iter().position(|h| h == name).expect(name);
    let open = col("calibrated_open");
    assert!(c.iter().skip(1).any(|r| r[open] == "1"), "the record is certified somewhere");
    let mut compared = 0;
    for (a, b) in c.iter().zip(&k).skip(1) {
        for name in ["calibrated_open", "gauss_open", "wass_open", "reason_calibrated"] {
            assert_eq!(a[col(name)], b[col(name)], "{name} at t = {}", a[0]);
        }
        for name in ["beta_hat", "rho", "cert_calibrated", "rho_calibrated"] {
            let (x, y) = (&a[col(name)], &b[col(name)]);
            assert_eq!(x.is_empty(), y.is_empty(), "{name} at t = {}", a[0]);
            if let (Ok(x), Ok(y)) = (x.parse::<f64>(), y.parse::<f64>()) {
                assert!((x - y).abs() <= 1e-9 * (1.0 + x.abs()), "{name} at t = {}: {x} {y}", a[0]);
                compared += 1;
            }
        }
    }
    assert!(compared > 10_000, "{compared} values compared");
    let (oc, ok) = (rows(&origin, "oc", &celsius), rows(&origin, "ok", &kelvin));
    let beta = col("beta_hat");
    let differs = oc.iter().zip(&ok).skip(1).filter(|(a, b)| {
        matches!((a[beta].parse::<f64>(), b[beta].parse::<f64>()), (Ok(x), Ok(y)) if (x - y).abs() > 1e-3)
    });
    assert!(differs.count() > 1000, "through the origin the units change beta_hat");
}

/// A skipped row closes every gate (`--on-bad-row skip`, the library's `Certifier::skip`), so
/// a run whose last row is bad is not certified at its end: the verdict, `certified_at_end`
/// and `--require-certified` agree with the closed gate. The same rows without the bad one
/// end certified, so the check can fail.
#[test]
fn a_skipped_last_row_leaves_the_run_not_certified_at_its_end() {
    let cfg = config("skip-last");
    let path = cfg.to_str().expect("utf8");
    let data = simulate("1");
    // The last row again, one step later, with a NaN where the configuration's output is.
    let lines = text(&data);
    let header: Vec<&str> = lines.lines().next().expect("header").split(',').collect();
    let mut row: Vec<String> =
        lines.lines().last().expect("rows").split(',').map(String::from).collect();
    row[0] = format!("{}", row[0].parse::<f64>().expect("time") + 0.02);
    row[header.iter().position(|&h| h == "y_b").expect("y_b")] = "NaN".into();
    let mut bad = data.clone();
    bad.extend_from_slice(format!("{}\n", row.join(",")).as_bytes());
    let mut verdicts = Vec::new();
    for (tag, input) in [("good", &data), ("bad", &bad)] {
        let json = tmp(&format!("skip-last-{tag}.json"));
        let args = ["certify", "--config", path, "--on-bad-row", "skip", "--require-certified"];
        let mut args = args.to_vec();
        args.extend(["--summary", json.to_str().expect("utf8")]);
        let out = run(&args, input);
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).expect("summary")).expect("json");
        let verdict = v["verdict"].as_str().expect("verdict").to_string();
        let certified = v["certified_at_end"].as_bool().expect("bool");
        assert_eq!(out.status.code(), Some(if certified { 0 } else { 6 }), "{verdict}");
        verdicts.push((certified, verdict, v["skipped"].as_u64()));
    }
    assert!(verdicts[0].0, "the good rows end certified: {}", verdicts[0].1);
    assert!(!verdicts[1].0, "{}", verdicts[1].1);
    assert!(verdicts[1].1.contains("at the end: "), "{}", verdicts[1].1);
    assert!(verdicts[1].1.contains("skipped"), "{}", verdicts[1].1);
    assert_eq!((verdicts[0].2, verdicts[1].2), (Some(0), Some(1)));
}

/// `network`'s summary starts with its verdict: "CERTIFIED" exactly when the network gate is
/// open at the last epoch (the last row's `open`, and `--require-certified`'s exit status),
/// with the run-level risk; otherwise the reason that held longest and the one at the end.
/// The paper-only certificate, named with the example's `risk` kept, composes (its local
/// certificates differ from the calibrated ones) and its verdict says it has no stated risk.
#[test]
fn the_network_verdict_agrees_with_the_gate_at_the_last_epoch() {
    let data = run(
        &[
            "simulate",
            "g5",
            "--experiment",
            "2",
            "--coupling",
            "bidirectional",
            "--seed",
            "1",
            "--steps",
            "3000",
        ],
        b"",
    );
    assert!(data.status.success());
    let example = network_example();
    let write = |tag: &str, body: &str| {
        let path = tmp(&format!("network-verdict-{tag}.toml"));
        std::fs::write(&path, body).expect("write");
        path
    };
    let calibrated = write("calibrated", &example);
    let all = text(&data.stdout);
    let half: String = all.lines().take(1500).map(|l| format!("{l}\n")).collect();
    let mut seen = [false, false];
    let mut local_b = Vec::new();
    for input in [all.as_str(), half.as_str()] {
        let path = calibrated.to_str().expect("utf8");
        let out = run(&["network", "--config", path, "--require-certified"], input.as_bytes());
        let stderr = text(&out.stderr);
        let verdict = stderr.lines().next().expect("a verdict line");
        // `--summary FILE`: the same verdict, and whether the gate is open at the end.
        let json = tmp("network-verdict.json");
        let quiet = run(
            &["network", "--config", path, "--summary", json.to_str().expect("utf8")],
            input.as_bytes(),
        );
        assert!(quiet.status.success() && quiet.stderr.is_empty(), "{}", text(&quiet.stderr));
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).expect("summary")).expect("json");
        assert_eq!(v["verdict"].as_str(), Some(verdict));
        let rows = text(&out.stdout);
        let header: Vec<&str> = rows.lines().next().expect("header").split(',').collect();
        let last: Vec<&str> = rows.lines().last().expect("rows").split(',').collect();
        let open = last[header.iter().position(|&h| h == "open").expect("open")] == "1";
        assert_eq!(verdict.starts_with("verdict: network CERTIFIED"), open, "{verdict}");
        assert_eq!(v["certified_at_end"].as_bool(), Some(open), "{v}");
        assert_eq!(v["risk"].as_f64(), Some(0.01), "{v}");
        assert!(verdict.contains("risk delta = 0.01"), "{verdict}");
        assert_eq!(verdict.contains("the reason that held longest"), !open, "{verdict}");
        assert_eq!(out.status.code(), Some(if open { 0 } else { 6 }), "{verdict}");
        seen[usize::from(open)] = true;
        if input.len() == all.len() {
            let b = header.iter().position(|&h| h == "cert_B").expect("cert_B");
            local_b = rows.lines().skip(1).map(|l| l.split(',').nth(b).map(String::from)).collect();
        }
    }
    assert!(seen[0] && seen[1], "both outcomes exercised: {seen:?}");
    let paper = write(
        "paper",
        &example.replace("certificate = \"calibrated\"", "certificate = \"gaussian\""),
    );
    let out = run(&["network", "--config", paper.to_str().expect("utf8")], &data.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stderr = text(&out.stderr);
    assert!(stderr.starts_with("verdict (paper-only mode, NO STATED RISK)"), "{stderr}");
    let rows = text(&out.stdout);
    let b = rows.lines().next().expect("header").split(',').position(|h| h == "cert_B");
    let paper_b: Vec<Option<String>> = rows
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(b.expect("cert_B")).map(String::from))
        .collect();
    assert_eq!(paper_b.len(), local_b.len());
    assert_ne!(paper_b, local_b, "the Gaussian certificates compose, not the calibrated ones");
}

/// A step test whose input never moves (held at one level for the whole record): the verdict
/// is "not certified" and names why, in words and by kind, with the default configuration.
#[test]
fn an_input_that_never_moves_is_named_in_the_verdict() {
    let cfg = config("held");
    let mut csv = String::from("t,y_b,u_b\n");
    let (mut y, dt) = (0.0f64, 0.02);
    for i in 0..3000u32 {
        let t = f64::from(i) * dt;
        csv.push_str(&format!("{t},{y},1\n"));
        // ẏ = −y + u + w with a deterministic, irregular disturbance.
        let w = (f64::from(i.wrapping_mul(2_654_435_761) % 1000) / 1000.0 - 0.5) * 0.4;
        y += dt * (-y + 1.0) + w * dt.sqrt();
    }
    let out = run(&["certify", "--config", cfg.to_str().expect("utf8")], csv.as_bytes());
    assert!(out.status.success(), "{}", text(&out.stderr));
    let err = text(&out.stderr);
    let verdict = err.lines().find(|l| l.starts_with("verdict:")).expect("verdict line");
    assert!(verdict.starts_with("verdict: NOT CERTIFIED"), "{verdict}");
    assert!(verdict.contains("[weakly_identified]"), "{verdict}");
    assert!(verdict.contains("the input moved too rarely"), "{verdict}");
}

/// `ẏ = −y + u + w` under `u = −2 y + dither`, 3000 rows at dt = 0.02, as a CSV of `t,y_b,u_b`
/// (a deterministic, irregular disturbance; the dither a ±`dither` square wave switching on
/// the disturbance's sign pattern, held 0.2 s).
fn closed_loop_csv(dither: f64) -> String {
    let mut csv = String::from("t,y_b,u_b\n");
    let (mut y, dt) = (0.5f64, 0.02);
    let mut level = 1.0;
    for i in 0..3000u32 {
        let t = f64::from(i) * dt;
        if i % 10 == 0 && i.wrapping_mul(2_246_822_519) % 7 < 3 {
            level = -level;
        }
        let u = -2.0 * y + dither * level;
        csv.push_str(&format!("{t},{y},{u}\n"));
        let w = (f64::from(i.wrapping_mul(2_654_435_761) % 1000) / 1000.0 - 0.5) * 0.4;
        y += dt * (-y + u) + w * dt.sqrt();
    }
    csv
}

/// A closed loop logged with `u = K y` and nothing added: no data separate the plant from the
/// controller, and the verdict says so and names the dither; the same loop with a dither gets
/// no such words.
#[test]
fn a_closed_loop_without_a_dither_is_told_to_add_one() {
    let cfg = config("no-dither");
    let certify = |csv: &str| {
        let out = run(&["certify", "--config", cfg.to_str().expect("utf8")], csv.as_bytes());
        assert!(out.status.success(), "{}", text(&out.stderr));
        let err = text(&out.stderr);
        err.lines().find(|l| l.starts_with("verdict:")).expect("verdict line").to_string()
    };
    let verdict = certify(&closed_loop_csv(0.0));
    assert!(verdict.starts_with("verdict: NOT CERTIFIED"), "{verdict}");
    assert!(verdict.contains("[input_follows_outputs]"), "{verdict}");
    assert!(verdict.contains("cannot separate the plant from the controller"), "{verdict}");
    assert!(verdict.contains("add a dither"), "{verdict}");
    assert!(!verdict.contains("has not moved"), "{verdict}");
    let dithered = certify(&closed_loop_csv(1.0));
    assert!(!dithered.contains("dither") && !dithered.contains("input_follows"), "{dithered}");
}
