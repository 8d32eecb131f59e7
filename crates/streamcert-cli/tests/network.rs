//! End-to-end tests of `streamcert network`: against two `certify` runs and `compose`, split
//! and resume, and the long input layout.

mod common;

use std::path::PathBuf;

use common::{compose, network_example, run, text, tmp, wait_bounded};

/// `streamcert network` on Experiment 2's data with bidirectional coupling: each epoch's local
/// certificates are the `certify` runs' values at the last row before the epoch, and the
/// network rate is `compose` on those rates and the configured gains, digit for digit.
#[test]
fn network_equals_two_certify_runs_and_compose() {
    let data = run(
        &["simulate", "g5", "--experiment", "2", "--coupling", "bidirectional", "--seed", "1"],
        b"",
    );
    assert!(data.status.success());
    let example = network_example();
    let net_cfg = tmp("network.toml");
    std::fs::write(&net_cfg, &example).expect("write");
    let net = run(&["network", "--config", net_cfg.to_str().expect("utf8")], &data.stdout);
    assert!(net.status.success(), "{}", text(&net.stderr));
    // The same certifier settings as the example's shared sections, one subsystem each: the
    // example composes the calibrated certificates at run-level risk 0.01, δ/2 each.
    let certify_cfg = |tag: &str, y: &str, u: &str, k: f64| {
        let path = tmp(&format!("network-{tag}.toml"));
        let body = format!(
            "[columns]\ntime = \"t\"\noutputs = [\"{y}\"]\ninputs = [\"{u}\"]\n[controller]\ngain = [[{k}]]\n\
             [certificate]\nconservatism = 0.3\nmargin = 0.1\nconsecutive = 10\n\
             [regression]\nwindow = 150\nhorizon = 5\nridge = 1e-4\ninput_integral = \"zero_order_hold\"\n\
             [calibration]\ndelta = 0.005\n[ambiguity]\nenabled = false\n"
        );
        std::fs::write(&path, body).expect("write");
        path
    };
    let local = |cfg: PathBuf| -> Vec<(f64, String)> {
        let out = run(&["certify", "--config", cfg.to_str().expect("utf8")], &data.stdout);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let mut r = csv::Reader::from_reader(out.stdout.as_slice());
        let h = r.headers().expect("header").clone();
        let (t, c) = (
            h.iter().position(|x| x == "t").expect("t"),
            h.iter().position(|x| x == "cert_calibrated").expect("cert"),
        );
        r.records()
            .map(|x| x.expect("row"))
            .map(|x| (x[t].parse().expect("t"), x[c].to_string()))
            .collect()
    };
    let a = local(certify_cfg("a", "y_a", "u_a", -2.5));
    let b = local(certify_cfg("b", "y_b", "u_b", -3.0));
    let mut r = csv::Reader::from_reader(net.stdout.as_slice());
    let h = r.headers().expect("header").clone();
    let col = |name: &str| h.iter().position(|x| x == name).expect("column");
    let (mut epochs, mut composed) = (0, 0);
    for row in r.records().map(|x| x.expect("row")) {
        epochs += 1;
        let t: f64 = row[col("t")].parse().expect("t");
        let before =
            |v: &[(f64, String)]| v.iter().rev().find(|(s, _)| *s < t).map(|(_, c)| c.clone());
        let (ca, cb) = (before(&a).expect("a row before"), before(&b).expect("b row before"));
        assert_eq!(&row[col("cert_A")], ca, "A at t = {t}");
        assert_eq!(&row[col("cert_B")], cb, "B at t = {t}");
        if ca.is_empty() || cb.is_empty() {
            assert!(row[col("rate")].is_empty());
            continue;
        }
        composed += 1;
        assert_eq!(&row[col("sensitivity_converged")], "1", "t = {t}");
        let rates = tmp("network-rates.txt");
        let gains = tmp("network-gains.txt");
        std::fs::write(&rates, format!("{ca} {cb}\n")).expect("write");
        std::fs::write(&gains, "0 0.4\n0.4 0\n").expect("write");
        let c = compose(&rates, &gains, &["--json"]);
        assert!(c.status.success(), "{}", text(&c.stderr));
        let v: serde_json::Value = serde_json::from_slice(&c.stdout).expect("json");
        let rate: f64 = row[col("rate")].parse().expect("rate");
        assert_eq!(v["rate"].as_f64().map(f64::to_bits), Some(rate.to_bits()), "t = {t}");
    }
    assert_eq!(epochs, 32);
    assert!(composed >= 10, "{composed} epochs with a network rate");
}

/// A network run split at a checkpoint and resumed on the whole input (the replayed rows are
/// passed over) writes exactly the output of one run; a damaged checkpoint is refused.
#[test]
fn network_split_and_resume_equals_one_run() {
    let data = run(
        &["simulate", "g5", "--experiment", "2", "--coupling", "bidirectional", "--seed", "2"],
        b"",
    );
    let example = network_example();
    let cfg = tmp("network-resume.toml");
    std::fs::write(&cfg, &example).expect("write");
    let cfg = cfg.to_str().expect("utf8");
    let whole = run(&["network", "--config", cfg], &data.stdout);
    assert!(whole.status.success(), "{}", text(&whole.stderr));
    let lines: Vec<&[u8]> = data.stdout.split_inclusive(|&b| b == b'\n').collect();
    let first: Vec<u8> = lines[..431].concat();
    let cp = tmp("network.checkpoint");
    let cp = cp.to_str().expect("utf8");
    let a =
        run(&["network", "--config", cfg, "--checkpoint", cp, "--checkpoint-every", "100"], &first);
    assert!(a.status.success(), "{}", text(&a.stderr));
    let b = run(&["network", "--config", cfg, "--resume", cp], &data.stdout);
    assert!(b.status.success(), "{}", text(&b.stderr));
    assert!(text(&b.stderr).contains("(430 replayed)"), "{}", text(&b.stderr));
    assert_eq!([a.stdout, b.stdout].concat(), whole.stdout);
    // One flipped byte in the state: refused with exit code 5.
    let mut damaged = std::fs::read(cp).expect("checkpoint");
    let at = damaged.len() / 2;
    damaged[at] ^= 0x01;
    let bad = tmp("network-damaged.checkpoint");
    std::fs::write(&bad, damaged).expect("write");
    let c =
        run(&["network", "--config", cfg, "--resume", bad.to_str().expect("utf8")], &data.stdout);
    assert_eq!(c.status.code(), Some(5), "{}", text(&c.stderr));
}

/// The long layout (`t,subsystem,outputs,inputs`, one subsystem per row) gives the same
/// epochs as the wide file it was cut from; a row naming no subsystem or with the wrong
/// number of fields is a row error (exit 3).
#[test]
fn network_long_rows_equal_the_wide_file() {
    let data = run(
        &["simulate", "g5", "--experiment", "2", "--coupling", "bidirectional", "--seed", "3"],
        b"",
    );
    let example = network_example();
    let wide_cfg = tmp("network-wide.toml");
    std::fs::write(&wide_cfg, &example).expect("write");
    let long_cfg = tmp("network-long.toml");
    std::fs::write(&long_cfg, example.replace("# input = \"wide\"", "input = \"long\""))
        .expect("write");
    let wide = run(&["network", "--config", wide_cfg.to_str().expect("utf8")], &data.stdout);
    assert!(wide.status.success(), "{}", text(&wide.stderr));
    let mut r = csv::Reader::from_reader(data.stdout.as_slice());
    let h = r.headers().expect("header").clone();
    let col = |n: &str| h.iter().position(|x| x == n).expect("column");
    let mut long = String::from("t,subsystem,values\n");
    for row in r.records().map(|x| x.expect("row")) {
        for (name, y, u) in [("A", "y_a", "u_a"), ("B", "y_b", "u_b")] {
            long.push_str(&format!(
                "{},{name},{},{}\n",
                &row[col("t")],
                &row[col(y)],
                &row[col(u)]
            ));
        }
    }
    let long_cfg = long_cfg.to_str().expect("utf8");
    let out = run(&["network", "--config", long_cfg], long.as_bytes());
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(text(&out.stdout), text(&wide.stdout));
    let unknown = run(&["network", "--config", long_cfg], b"0,A,0,0\n0,C,0,0\n");
    assert_eq!(unknown.status.code(), Some(3));
    assert!(text(&unknown.stderr).contains("no subsystem named `C`"), "{}", text(&unknown.stderr));
    // Other people's CSV: CRLF line ends, a blank line, a quoted name; the error names the
    // physical line of the bad row (line 4 here).
    let crlf =
        run(&["network", "--config", long_cfg], b"0,\"A\",0,0\r\n\r\n0.02,A,0,0\r\n0.04,C,0,0\r\n");
    assert_eq!(crlf.status.code(), Some(3));
    let stderr = text(&crlf.stderr);
    assert!(stderr.contains(":4:") && stderr.contains("no subsystem named `C`"), "{stderr}");
    // A corrupted time far ahead (found by fuzzing: it made the network compose 10¹³ epochs).
    let jump = run(&["network", "--config", long_cfg], b"0,A,0,0\n1e12,A,0,0\n");
    assert_eq!(jump.status.code(), Some(3));
    assert!(text(&jump.stderr).contains("max_epoch_jump"), "{}", text(&jump.stderr));
    let short = run(&["network", "--config", long_cfg], b"0,A,0\n");
    assert_eq!(short.status.code(), Some(3));
    assert!(
        text(&short.stderr).contains("needs t, its name, 1 outputs and 1 inputs"),
        "{}",
        text(&short.stderr)
    );
}

/// `simulate g5` for Experiment 2 with bidirectional coupling `γ = 0.3`, run `seed`, `steps`
/// steps.
fn g5_bidirectional(seed: u32, steps: u32) -> std::process::Output {
    let (seed, steps) = (seed.to_string(), steps.to_string());
    let args = ["simulate", "g5", "--experiment", "2", "--coupling", "bidirectional"];
    let data =
        run(&[&args[..], &["--seed", &seed, "--gamma", "0.3", "--steps", &steps]].concat(), b"");
    assert!(data.status.success(), "{}", text(&data.stderr));
    data
}

/// `streamcert network` with both couplings of bidirectional G5 (γ = 0.3) estimated: the
/// local calibrated certificates are those of `certify` runs whose inputs include the other
/// subsystem's output (risk δ/(N + E) each), every estimated upper bound contains the true γ,
/// and the network rate is `compose` on the local rates and the bounds.
#[test]
fn network_estimates_the_couplings_of_bidirectional_g5() {
    let data = g5_bidirectional(2, 3000);
    let example = network_example();
    let body =
        example.replace("gamma = 0.4", "estimate = true").replace("risk = 0.01 ", "risk = 0.04 ");
    let net_cfg = tmp("network-estimated.toml");
    std::fs::write(&net_cfg, body).expect("write");
    let net = run(&["network", "--config", net_cfg.to_str().expect("utf8")], &data.stdout);
    assert!(net.status.success(), "{}", text(&net.stderr));
    let certify = |tag: &str, y: &str, u: &str, other: &str, k: f64| -> Vec<(f64, String)> {
        let path = tmp(&format!("network-estimated-{tag}.toml"));
        let body = format!(
            "[columns]\ntime = \"t\"\noutputs = [\"{y}\"]\ninputs = [\"{u}\", \"{other}\"]\n\
             [controller]\ngain = [[{k}], [0.0]]\n\
             [certificate]\nconservatism = 0.3\nmargin = 0.1\nconsecutive = 10\n\
             [regression]\nwindow = 150\nhorizon = 5\nridge = 1e-4\ninput_integral = \"zero_order_hold\"\n\
             [calibration]\nenabled = true\ndelta = 0.01\n[ambiguity]\nenabled = false\n"
        );
        std::fs::write(&path, body).expect("write");
        let out = run(&["certify", "--config", path.to_str().expect("utf8")], &data.stdout);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let mut r = csv::Reader::from_reader(out.stdout.as_slice());
        let h = r.headers().expect("header").clone();
        let col = |name: &str| h.iter().position(|x| x == name).expect("column");
        let (t, c) = (col("t"), col("cert_calibrated"));
        r.records()
            .map(|x| x.expect("row"))
            .map(|x| (x[t].parse().expect("t"), x[c].to_string()))
            .collect()
    };
    let a = certify("a", "y_a", "u_a", "y_b", -2.5);
    let b = certify("b", "y_b", "u_b", "y_a", -3.0);
    let mut r = csv::Reader::from_reader(net.stdout.as_slice());
    let h = r.headers().expect("header").clone();
    let col = |name: &str| h.iter().position(|x| x == name).expect("column");
    let (mut bounded, mut composed) = (0, 0);
    for row in r.records().map(|x| x.expect("row")) {
        let t: f64 = row[col("t")].parse().expect("t");
        let before =
            |v: &[(f64, String)]| v.iter().rev().find(|(s, _)| *s < t).map(|(_, c)| c.clone());
        let (ca, cb) = (before(&a).expect("a row"), before(&b).expect("b row"));
        assert_eq!(&row[col("cert_A")], ca, "A at t = {t}");
        assert_eq!(&row[col("cert_B")], cb, "B at t = {t}");
        let (gba, gab) = (&row[col("gamma_B_A")], &row[col("gamma_A_B")]);
        for g in [gba, gab].into_iter().filter(|g| !g.is_empty()) {
            bounded += 1;
            let g: f64 = g.parse().expect("gamma");
            assert!(g >= 0.3, "an upper bound {g} below the true γ = 0.3 at t = {t}");
        }
        if row[col("rate")].is_empty() {
            continue;
        }
        composed += 1;
        let rates = tmp("network-estimated-rates.txt");
        let gains = tmp("network-estimated-gains.txt");
        std::fs::write(&rates, format!("{ca} {cb}\n")).expect("write");
        std::fs::write(&gains, format!("0 {gba}\n{gab} 0\n")).expect("write");
        let c = compose(&rates, &gains, &["--json"]);
        assert!(c.status.success(), "{}", text(&c.stderr));
        let v: serde_json::Value = serde_json::from_slice(&c.stdout).expect("json");
        let rate: f64 = row[col("rate")].parse().expect("rate");
        assert_eq!(v["rate"].as_f64().map(f64::to_bits), Some(rate.to_bits()), "t = {t}");
    }
    assert!(bounded >= 100 && composed >= 30, "{bounded} bounds, {composed} rates");
}

/// Two free ports on localhost (bound, read and released; a race with another program
/// taking them in between is possible but unlikely).
fn free_ports() -> [u16; 2] {
    let a = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let b = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    [a.local_addr().expect("addr").port(), b.local_addr().expect("addr").port()]
}

/// `streamcert network` over two timely processes on localhost (one worker each, the two
/// subsystems on different processes) writes the rows of the one-process run byte for byte,
/// with given and with estimated couplings; and a run on two worker threads of one process too.
#[test]
fn two_timely_processes_write_the_one_process_rows() {
    let data = g5_bidirectional(3, 1500);
    let input = tmp("timely-g5.csv");
    std::fs::write(&input, &data.stdout).expect("write");
    let example = network_example();
    let estimated = example
        .replacen("gamma = 0.4", "estimate = true", 1)
        .replace("# risk = 0.01", "risk = 0.04")
        .replace("[ambiguity]", "[calibration]\nenabled = true\n\n[ambiguity]");
    for (tag, body) in [("given", example.clone()), ("estimated", estimated)] {
        // B is read by process 1.
        let body = body.replace("gain = [[-3.0]]", "gain = [[-3.0]]\nprocess = 1");
        let cfg = tmp(&format!("timely-{tag}.toml"));
        std::fs::write(&cfg, body).expect("write");
        let cfg = cfg.to_str().expect("utf8");
        let one = run(&["network", "--config", cfg, "--input", input.to_str().expect("utf8")], b"");
        assert!(one.status.success(), "{}", text(&one.stderr));
        assert!(one.stdout.len() > 1000, "{tag}: {} bytes", one.stdout.len());
        // Two worker threads in one process.
        let threads = run(
            &[
                "network",
                "--config",
                cfg,
                "--input",
                input.to_str().expect("utf8"),
                "--workers",
                "2",
            ],
            b"",
        );
        assert!(threads.status.success(), "{}", text(&threads.stderr));
        assert_eq!(text(&threads.stdout), text(&one.stdout), "{tag}: two threads");
        // Two processes.
        let [p0, p1] = free_ports();
        let hosts = tmp(&format!("timely-hosts-{tag}.txt"));
        std::fs::write(&hosts, format!("127.0.0.1:{p0}\n127.0.0.1:{p1}\n")).expect("write");
        let output = tmp(&format!("timely-out-{tag}.csv"));
        let _ = std::fs::remove_file(&output);
        let process = |index: &str, extra: &[&str]| {
            common::bin()
                .args(["network", "--config", cfg, "--processes", "2", "--process", index])
                .args(["--hostfile", hosts.to_str().expect("utf8")])
                .args(extra)
                .stdin(std::process::Stdio::null())
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .expect("spawn")
        };
        // Each process reads its own file: the wide file's columns of its subsystem (and, for
        // an estimated coupling, of the driving output it measures).
        let second = process("1", &["--input", input.to_str().expect("utf8")]);
        let first = process(
            "0",
            &["--input", input.to_str().expect("utf8"), "--output", output.to_str().expect("utf8")],
        );
        let first = wait_bounded(first, 120, "process 0");
        let second = wait_bounded(second, 120, "process 1");
        assert!(first.status.success(), "process 0: {}", text(&first.stderr));
        assert!(second.status.success(), "process 1: {}", text(&second.stderr));
        let got = std::fs::read(&output).expect("process 0's output");
        assert_eq!(text(&got), text(&one.stdout), "{tag}: two processes");
    }
}

/// The timely path checkpoints at every epoch boundary: a row period is refused with a
/// configuration error.
#[test]
fn timely_runs_refuse_a_checkpoint_period() {
    let example = network_example();
    let cfg = tmp("timely-checkpoint.toml");
    std::fs::write(&cfg, &example).expect("write");
    let ckpt = tmp("timely-checkpoint.ckpt");
    let out = run(
        &[
            "network",
            "--config",
            cfg.to_str().expect("utf8"),
            "--workers",
            "2",
            "--checkpoint",
            ckpt.to_str().expect("utf8"),
            "--checkpoint-every",
            "10",
        ],
        b"t,y_a,u_a,y_b,u_b\n0,0,0,0,0\n",
    );
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("every epoch boundary"), "{}", text(&out.stderr));
}

/// `network --print-config` writes the template: run as it is, it is refused (exit 2) naming
/// each subsystem's gain and the margins; the example with them set runs.
#[test]
fn the_printed_network_template_needs_the_users_choices() {
    let out = run(&["network", "--print-config"], b"");
    assert!(out.status.success());
    assert_eq!(text(&out.stdout), streamcert_pipeline::network::template());
    let path = tmp("network-template.toml");
    std::fs::write(&path, &out.stdout).expect("write");
    let refused = run(&["network", "--config", path.to_str().expect("utf8")], b"");
    assert_eq!(refused.status.code(), Some(2));
    let err = text(&refused.stderr);
    for key in ["subsystem[0].gain", "subsystem[1].gain", "network.margin", "certificate.margin"] {
        assert!(err.contains(key), "{key}: {err}");
    }
}
