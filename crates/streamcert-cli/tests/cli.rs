//! End-to-end tests of the `streamcert` binary: simulate | certify, split and resume, every
//! kind of bad input with its message and exit code, and compose against Lemma 1.

mod common;

use std::process::Stdio;

use common::{bin, compose, config, run, simulate, text, tmp};

#[test]
fn simulate_pipes_into_certify() {
    let cfg = config("pipe");
    let data = simulate("4");
    let out = run(&["certify", "--config", cfg.to_str().expect("utf8")], &data);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let lines: Vec<String> = text(&out.stdout).lines().map(String::from).collect();
    assert_eq!(lines.len(), 1 + 1501, "header plus one row per sample");
    assert!(
        lines[0].starts_with("t,beta_hat,rho,eps,kurtosis,spike_fraction,cert_gauss,cert_wass")
    );
    assert!(lines.iter().any(|l| l.contains(",1,1,")), "some row has both gates open");
    assert!(text(&out.stderr).contains("summary: 1501 rows, 0 skipped"));
    // JSON lines carry the same numbers.
    let json =
        run(&["certify", "--config", cfg.to_str().expect("utf8"), "--format", "jsonl"], &data);
    let last: serde_json::Value =
        serde_json::from_str(text(&json.stdout).lines().last().expect("rows")).expect("json");
    let csv: Vec<f64> = lines
        .last()
        .expect("rows")
        .split(',')
        .take(2)
        .map(|v| v.parse().expect("number"))
        .collect();
    assert_eq!(
        csv,
        vec![last["t"].as_f64().expect("t"), last["beta_hat"].as_f64().expect("beta_hat")]
    );
}

#[test]
fn the_calibrated_certificate_is_the_default_verdict() {
    let cfg = config("calibrated");
    let out = run(&["certify", "--config", cfg.to_str().expect("utf8")], &simulate("6"));
    assert!(out.status.success(), "{}", text(&out.stderr));
    let lines: Vec<String> = text(&out.stdout).lines().map(String::from).collect();
    assert!(lines[0].contains(
        ",rho_calibrated,cert_calibrated,calibrated_window,calibrated_horizon,calibrated_order,\
         calibrated_open,reason_calibrated,"
    ));
    assert!(lines[0].ends_with(",region_lo_calibrated_y_b,region_hi_calibrated_y_b"));
    let last: Vec<&str> = lines.last().expect("rows").split(',').collect();
    assert_eq!(last.len(), 25 + 6);
    let rho_cal: f64 = last[12].parse().expect("rho_calibrated");
    let cert_cal: f64 = last[13].parse().expect("cert_calibrated");
    let window: usize = last[14].parse().expect("calibrated_window");
    let h: usize = last[15].parse().expect("calibrated_horizon");
    let order: usize = last[16].parse().expect("calibrated_order");
    // The default horizon, h = 5, the first order, and one of its windows (M = 150 doubling
    // to 16 M).
    assert_eq!((h, order), (5, 1), "{last:?}");
    assert!(rho_cal > 0.0 && cert_cal.is_finite() && [150, 300, 600, 1200, 2400].contains(&window));
    // The gate is open exactly when no reason is given.
    assert_eq!(last[17] == "1", last[18].is_empty(), "{last:?}");
    // The summary's first line is the calibrated verdict, with its risk.
    let stderr = text(&out.stderr);
    let first = stderr.lines().next().expect("a summary");
    assert!(first.starts_with("verdict: ") && first.contains("delta = 0.01"), "{stderr}");
    assert!(stderr.contains("calibrated gate (risk delta over the run)"));
    assert!(stderr.contains("paper's gates (no stated risk)"));
    // The paper-only mode is a named choice, and says it has no stated risk.
    let paper = tmp("config-paper-only.toml");
    let text_cfg = std::fs::read_to_string(&cfg)
        .expect("config")
        .replace("enabled = true\ndelta = 0.01", "enabled = false\ndelta = 0.01");
    std::fs::write(&paper, text_cfg).expect("write config");
    let plain = run(&["certify", "--config", paper.to_str().expect("utf8")], &simulate("6"));
    let row = text(&plain.stdout).lines().last().expect("rows").to_string();
    assert!(row.contains(",,,,0,no calibration configured,"), "{row}");
    let stderr = text(&plain.stderr);
    assert!(stderr.lines().next().expect("summary").contains("NO STATED RISK"), "{stderr}");
}

#[test]
fn nonlinear_section_adds_the_nonlinear_certificate_and_its_region() {
    let cfg = config("nonlinear");
    let on = std::fs::read_to_string(&cfg)
        .expect("config")
        .replace("enabled = false\nfeatures", "enabled = true\nfeatures");
    std::fs::write(&cfg, on).expect("write config");
    let out = run(&["certify", "--config", cfg.to_str().expect("utf8")], &simulate("6"));
    assert!(out.status.success(), "{}", text(&out.stderr));
    let lines: Vec<String> = text(&out.stdout).lines().map(String::from).collect();
    let header: Vec<&str> = lines[0].split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let last: Vec<&str> = lines.last().expect("rows").split(',').collect();
    assert_eq!(last.len(), header.len());
    // A nonlinear certificate with its region, inside the paper window's region or wider.
    let (lo, hi): (f64, f64) = (
        last[col("nonlinear_y_lo")].parse().expect("lo"),
        last[col("nonlinear_y_hi")].parse().expect("hi"),
    );
    assert!(lo <= hi && last[col("cert_nonlinear")].parse::<f64>().is_ok(), "{last:?}");
    let (plo, phi): (f64, f64) = (
        last[col("region_lo_y_b")].parse().expect("lo"),
        last[col("region_hi_y_b")].parse().expect("hi"),
    );
    assert!(plo <= phi);
    assert_eq!(last[col("nonlinear_open")] == "1", last[col("reason_nonlinear")].is_empty());
    assert!(text(&out.stderr).contains("nonlinear gate (risk delta over the run"));
}

#[test]
fn split_and_resume_equals_one_run() {
    let cfg = config("resume");
    let c = cfg.to_str().expect("utf8");
    let data = text(&simulate("5"));
    let lines: Vec<&str> = data.lines().collect();
    let (head, rest) = lines.split_at(700);
    let first = format!("{}\n", head.join("\n"));
    let second = format!("{}\n{}\n", lines[0], rest.join("\n"));
    let whole = run(&["certify", "--config", c], data.as_bytes());
    let cp = tmp("state.json");
    let cps = cp.to_str().expect("utf8");
    let a = run(
        &["certify", "--config", c, "--checkpoint", cps, "--checkpoint-every", "100"],
        first.as_bytes(),
    );
    let b = run(&["certify", "--config", c, "--resume", cps], second.as_bytes());
    assert!(a.status.success() && b.status.success(), "{}{}", text(&a.stderr), text(&b.stderr));
    assert_eq!(format!("{}{}", text(&a.stdout), text(&b.stdout)), text(&whole.stdout));
    // Resuming with another configuration is refused.
    let other = tmp("other.toml");
    std::fs::write(
        &other,
        std::fs::read_to_string(&cfg).expect("cfg").replace("margin = 0.05", "margin = 0.06"),
    )
    .expect("write");
    let bad = run(
        &["certify", "--config", other.to_str().expect("utf8"), "--resume", cps],
        second.as_bytes(),
    );
    assert_eq!(bad.status.code(), Some(5), "{}", text(&bad.stderr));
    // The refusal names the setting that differs, with both values.
    let said = text(&bad.stderr);
    assert!(said.contains("margin: 0.05 in the checkpoint, 0.06 now"), "{said}");
    assert!(!said.contains("checkpoint: checkpoint"), "{said}");
    // A damaged checkpoint (one flipped bit in the payload or the header, truncated, empty,
    // or another file altogether) is refused with exit 5 and a message, never a panic.
    let good = std::fs::read(&cp).expect("checkpoint");
    let mut flipped = good.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0x04;
    let mut header = good.clone();
    header[30] ^= 0x01;
    // A flipped header byte reads as a wrong checksum or as a malformed header, depending on
    // which hex digit it hits.
    let header_message = if header[30].is_ascii_hexdigit() && !header[30].is_ascii_uppercase() {
        "corrupted"
    } else {
        "header is damaged"
    };
    let damaged: [(&str, Vec<u8>); 5] = [
        ("corrupted", flipped),
        (header_message, header),
        ("checkpoint", good[..good.len() - 7].to_vec()),
        ("not a streamcert checkpoint", Vec::new()),
        ("not a streamcert checkpoint", b"{\"certifier\": 1}\n".to_vec()),
    ];
    for (message, bytes) in damaged {
        let path = tmp("damaged.json");
        std::fs::write(&path, &bytes).expect("write");
        let out = run(
            &["certify", "--config", c, "--resume", path.to_str().expect("utf8")],
            second.as_bytes(),
        );
        assert_eq!(out.status.code(), Some(5), "{}", text(&out.stderr));
        assert!(text(&out.stderr).contains(message), "{message}: {}", text(&out.stderr));
    }
}

/// A live feed under faults: the input arrives through a pipe in bursts cut in the middle of
/// lines, with pauses; the process is killed mid-stream; a new process resumes from the last
/// checkpoint with the same input replayed from the start. The output kept up to the
/// checkpoint's last time, followed by the resumed output, equals the unsplit run.
#[test]
fn killed_live_run_resumes_to_the_unsplit_output() {
    use std::io::{Read, Write};
    let cfg = config("live");
    let c = cfg.to_str().expect("utf8");
    let data = simulate("9");
    let whole = run(&["certify", "--config", c], &data);
    assert!(whole.status.success());
    let cp = tmp("live.ckpt");
    let _ = std::fs::remove_file(&cp);
    let cps = cp.to_str().expect("utf8");
    let mut child = bin()
        .args(["certify", "--config", c, "--checkpoint", cps, "--checkpoint-every", "50"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn");
    let mut stdout = child.stdout.take().expect("stdout");
    let collector = std::thread::spawn(move || {
        let mut out = Vec::new();
        let _ = stdout.read_to_end(&mut out);
        out
    });
    // 60 % of the input in 37 bursts of uneven length (cut inside lines), 2 ms apart.
    let mut pipe = child.stdin.take().expect("stdin");
    let part = data.len() * 3 / 5;
    let mut at = 0;
    for k in 0..37 {
        let end = if k == 36 { part } else { (at + part / 37 + (k * 7919) % 97).min(part) };
        pipe.write_all(&data[at..end]).expect("feed");
        pipe.flush().expect("flush");
        at = end;
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    // Wait (bounded) for a checkpoint, then kill without closing the input.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    while !cp.exists() && std::time::Instant::now() < deadline {
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    std::thread::sleep(std::time::Duration::from_millis(100));
    child.kill().expect("kill");
    let _ = child.wait();
    drop(pipe);
    let partial = text(&collector.join().expect("collector"));
    // The checkpoint's last time: the header line, then the state with the summary.
    let saved = std::fs::read(&cp).expect("a checkpoint was written before the kill");
    // Only the summary's last time is read (the rest skipped, packed rings included).
    #[derive(serde::Deserialize)]
    struct Saved {
        summary: SavedSummary,
    }
    #[derive(serde::Deserialize)]
    struct SavedSummary {
        last_time: f64,
    }
    let state: Saved = streamcert_certificate::unseal::<()>(&saved, None)
        .expect("sealed")
        .decode()
        .expect("a state");
    let last = state.summary.last_time;
    let kept: Vec<&str> = partial
        .lines()
        .take_while(|l| {
            l.starts_with('t')
                || l.split(',')
                    .next()
                    .and_then(|v| v.parse::<f64>().ok())
                    .is_some_and(|t| t <= last)
        })
        .collect();
    assert!(kept.len() > 50, "only {} rows before the checkpoint", kept.len());
    let resumed = run(&["certify", "--config", c, "--resume", cps], &data);
    assert!(resumed.status.success(), "{}", text(&resumed.stderr));
    assert_eq!(format!("{}\n{}", kept.join("\n"), text(&resumed.stdout)), text(&whole.stdout));
}

/// Run certify on `body` (after a valid header) and return (exit code, stderr).
fn certify_rows(body: &str, extra: &[&str]) -> (Option<i32>, String) {
    let cfg = config("rows");
    let header = "t,y_a,u_a,y_b,u_b\n";
    let mut args = vec!["certify", "--config", cfg.to_str().expect("utf8")];
    args.extend_from_slice(extra);
    let out = run(&args, format!("{header}{body}").as_bytes());
    (out.status.code(), text(&out.stderr))
}

/// The rows of `body` under `header`, certified with the `[columns]` delimiter set to
/// `delimiter`; returns (exit code, stdout, stderr).
fn certify_foreign(header: &str, body: &str, delimiter: &str) -> (Option<i32>, String, String) {
    let cfg = config(&format!("foreign-{}", delimiter.len()));
    let text_cfg = std::fs::read_to_string(&cfg).expect("cfg");
    let with_delimiter =
        text_cfg.replacen("time = \"t\"", &format!("time = \"t\"\ndelimiter = \"{delimiter}\""), 1);
    std::fs::write(&cfg, with_delimiter).expect("write");
    let out = run(
        &["certify", "--config", cfg.to_str().expect("utf8")],
        format!("{header}{body}").as_bytes(),
    );
    (out.status.code(), text(&out.stdout), text(&out.stderr))
}

#[test]
fn csv_from_spreadsheets_and_other_programs_is_read() {
    // The same three rows written five ways give the same certificate rows.
    let plain = certify_foreign("t,y_b,u_b\n", "0,0,0\n0.02,0.1,0.5\n0.04,0.2,0.4\n", ",");
    assert_eq!(plain.0, Some(0), "{}", plain.2);
    let variants = [
        ("\u{feff}t,y_b,u_b\n", "0,0,0\n0.02,0.1,0.5\n0.04,0.2,0.4\n", ","),
        ("t;y_b;u_b\n", "0;0;0\n0.02;0.1;0.5\n0.04;0.2;0.4\n", ";"),
        ("t\ty_b\tu_b\n", "0\t0\t0\n0.02\t0.1\t0.5\n0.04\t0.2\t0.4\n", "tab"),
        (
            "\"t\",\"y_b\",\"u_b\"\r\n",
            "\"0\",\"0\",\"0\"\r\n\"0.02\", 0.1 ,\"0.5\"\r\n\r\n0.04,0.2,0.4\r\n",
            ",",
        ),
    ];
    for (header, body, delimiter) in variants {
        let out = certify_foreign(header, body, delimiter);
        assert_eq!(out.0, Some(0), "{header:?}: {}", out.2);
        assert_eq!(out.1, plain.1, "{header:?}");
    }
    // An unterminated quote or an unknown delimiter is an error with a message, not a panic.
    let (code, _, stderr) = certify_foreign("t,y_b,u_b\n", "0,0,0\n0.02,\"0.1,0.5\n", ",");
    assert_eq!(code, Some(3), "{stderr}");
    let (code, _, stderr) = certify_foreign("t|y_b|u_b\n", "0|0|0\n", "|");
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("delimiter"), "{stderr}");
}

#[test]
fn each_bad_input_has_its_message_and_exit_code() {
    let good = "0,0,0,0,0\n0.02,0,0,0.1,0.5\n";
    let cases = [
        (format!("{good}0.04,0,0,abc,0.5\n"), "-:4: column `y_b`: expected a number, found `abc`"),
        (format!("{good}0.04,0,0,NaN,0.5\n"), "-:4: column `y_b`: expected a finite number"),
        (format!("{good}0.04,0,0,0.1,inf\n"), "-:4: column `u_b`: expected a finite number"),
        (
            format!("{good}0.01,0,0,0.1,0.5\n"),
            "-:4: column `t`: time 0.01 is before the previous time 0.02",
        ),
        (format!("{good}0.02,0,0,0.1,0.5\n"), "-:4: column `t`: duplicated time 0.02"),
        (format!("{good}0.04,0,0\n"), "-:4: expected 5 fields as in the header, found 3"),
    ];
    for (body, message) in &cases {
        let (code, stderr) = certify_rows(body, &[]);
        assert_eq!(code, Some(3), "{stderr}");
        assert!(stderr.contains(message), "expected `{message}` in `{stderr}`");
        // The way on past a bad row is named where the run stopped.
        assert!(stderr.contains("--on-bad-row skip"), "{stderr}");
    }
    // Skip policy: every bad row counted, the run succeeds.
    let all_bad: String =
        cases.iter().map(|(b, _)| b.lines().nth(2).expect("bad row").to_string() + "\n").collect();
    let summary = tmp("summary.json");
    let (code, stderr) = certify_rows(
        &format!("{good}{all_bad}0.06,0,0,0.1,0.5\n"),
        &["--on-bad-row", "skip", "--summary", summary.to_str().expect("utf8")],
    );
    assert_eq!(code, Some(0), "{stderr}");
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).expect("summary")).expect("json");
    assert_eq!(s["skipped"], 6);
    assert_eq!(s["rows"], 3);
    // Empty input and a header without the configured columns.
    let cfg = config("rows");
    let empty = run(&["certify", "--config", cfg.to_str().expect("utf8")], b"");
    assert_eq!(empty.status.code(), Some(3));
    assert!(text(&empty.stderr).contains("empty input"));
    let header = run(&["certify", "--config", cfg.to_str().expect("utf8")], b"t,y,u\n0,0,0\n");
    assert_eq!(header.status.code(), Some(3));
    assert!(text(&header.stderr).contains("no column `y_b`"));
}

#[test]
fn invalid_configurations_are_refused_before_reading() {
    let base = std::fs::read_to_string(config("invalid")).expect("cfg");
    for (edit, message) in [
        (base.replace("margin = 0.05", "margin = 0.05\nmargn = 1"), "unknown field"),
        (base.replace("gain = [[-4.0]]", "gain = [[-4.0, 2.0]]"), "m × p"),
        (base.replace("conservatism = 0.1", "conservatism = 0.0"), "conservatism"),
        (base.replace("eps_floor = 0.015", "eps_floor = 0.5"), "eps_floor"),
    ] {
        let path = tmp("bad.toml");
        std::fs::write(&path, edit).expect("write");
        // The input would fail too, but the configuration error comes first (exit 2).
        let out = run(&["certify", "--config", path.to_str().expect("utf8")], b"garbage");
        assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
        assert!(
            text(&out.stderr).contains(message),
            "expected `{message}` in {}",
            text(&out.stderr)
        );
    }
}

#[test]
fn compose_two_subsystems_equals_lemma_1() {
    let (rates, gains) = (tmp("compose-rates.txt"), tmp("compose-gains.txt"));
    std::fs::write(&rates, "0.8\n1.2\n").expect("write");
    std::fs::write(&gains, "0 0.5\n0.5 0\n").expect("write");
    let out = compose(&rates, &gains, &["--json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(&text(&out.stdout)).expect("json");
    let lemma = streamcert_compose::lemma1_rate(0.8, 1.2, 0.5).expect("valid");
    assert!((v["rate"].as_f64().expect("rate") - lemma).abs() < 1e-12);
    let warn = streamcert_compose::warning_gain(0.8, 1.2).expect("valid");
    assert!((v["critical_scale"].as_f64().expect("scale") * 0.5 - warn).abs() < 1e-9);
    // Sparse triplets give a certified rate no larger than the exact one.
    std::fs::write(&gains, "i,j,gamma\n0,1,0.5\n1,0,0.5\n").expect("write");
    let out =
        compose(&rates, &gains, &["--gains-format", "triplets", "--method", "sparse", "--json"]);
    let v: serde_json::Value = serde_json::from_str(&text(&out.stdout)).expect("json");
    let r = v["rate"].as_f64().expect("rate");
    assert!(r <= lemma + 1e-12 && r > lemma - 1e-3, "{r} vs {lemma}");
    // The text form: the JSON's numbers to six significant digits, as a person writes them.
    std::fs::write(&gains, "0 0.5\n0.5 0\n").expect("write");
    let said = text(&compose(&rates, &gains, &[]).stdout);
    let rate = format!("network rate: {}\n", streamcert_certificate::Sig(lemma));
    assert!(said.contains(&rate), "{said}");
    // A negative gain is an input error of the gains file; a rate that is not finite, of
    // the rates file.
    std::fs::write(&gains, "0 -0.5\n0.5 0\n").expect("write");
    let out = compose(&rates, &gains, &[]);
    assert_eq!(out.status.code(), Some(3));
    assert!(text(&out.stderr).contains(">= 0"));
    assert!(text(&out.stderr).contains("compose-gains.txt"), "{}", text(&out.stderr));
    std::fs::write(&gains, "0 0.5\n0.5 0\n").expect("write");
    std::fs::write(&rates, "0.8\nNaN\n").expect("write");
    let out = compose(&rates, &gains, &[]);
    assert_eq!(out.status.code(), Some(3));
    let said = text(&out.stderr);
    assert!(said.contains("compose-rates.txt") && said.contains("rate 2"), "{said}");
}

/// `simulate g5 --experiment E --seed s` writes the data of `cargo xtask reproduce` run `s`:
/// the same `G5Dataset::run_seeded(s)` with the reproduction's defaults.
#[test]
fn simulate_seed_is_the_reproduction_run() {
    use streamcert_experiments::{Experiment, G5Dataset};
    for (experiment, flag) in [(Experiment::One, "1"), (Experiment::Two, "2")] {
        let out = run(&["simulate", "g5", "--experiment", flag, "--seed", "3"], b"");
        assert!(out.status.success());
        let traj = G5Dataset::defaults(experiment).run_seeded(3).expect("valid");
        let csv = text(&out.stdout);
        let rows: Vec<&str> = csv.lines().skip(1).collect();
        assert_eq!(rows.len(), traj.len());
        for k in [0, 1, traj.len() / 2, traj.len() - 1] {
            let fields: Vec<f64> =
                rows[k].split(',').take(5).map(|v| v.parse().expect("number")).collect();
            let (y, u) = (traj.output(k), traj.input(k));
            assert_eq!(fields, vec![traj.t[k], y[0], u[0], y[1], u[1]], "row {k}");
        }
    }
}

/// `--help` of the streaming commands shows `--config` as required in the usage and lists
/// the exit codes.
#[test]
fn help_shows_the_required_configuration_and_the_exit_codes() {
    for command in ["certify", "network"] {
        let out = run(&[command, "--help"], b"");
        assert!(out.status.success());
        let help = text(&out.stdout);
        assert!(help.contains(&format!("streamcert {command} --config <CONFIG>")), "{help}");
        assert!(help.contains("Exit codes: 0 success, 2 invalid"), "{help}");
        assert!(help.contains("6 not certified at the end"), "{help}");
    }
}
