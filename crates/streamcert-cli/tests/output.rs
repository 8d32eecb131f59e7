//! The output rows against the library: every number of a `certify` CSV or JSON-lines row
//! reads back to the bit-identical value of the library's `Evidence` for the same sample, an
//! absent value is an empty field (`null`), gates are 0/1 and reasons are their text.

use streamcert_certificate::{CertificateKind, Certifier, Evidence, Interval, NotCertified};
use streamcert_pipeline::certify::{self, BadRows, Options};
use streamcert_pipeline::config;
use streamcert_pipeline::output::Format;

/// A scalar loop `ẏ = 0.5 y + u + w` under `u = −4 y + square-wave dither`, with a
/// deterministic pseudo-random disturbance, as CSV with the default configuration's columns.
fn plant_csv(rows: usize) -> String {
    let (dt, mut y, mut state) = (0.01_f64, 0.0_f64, 12345_u64);
    let mut csv = String::from("t,y_b,u_b\n");
    for k in 0..rows {
        let dither = if (k / 20) % 3 == 0 { 1.0 } else { -1.0 };
        let u = -4.0 * y + dither;
        csv.push_str(&format!("{},{y},{u}\n", k as f64 * dt));
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let w = ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.2;
        y += dt * (0.5 * y + u) + dt.sqrt() * w;
    }
    csv
}

fn options(format: Format) -> Options {
    Options { format, ..Options::default() }
}

/// The library's evidence for the same rows (the CSV's text parses to the same floats).
fn library(cfg: &config::Config, input: &str) -> Vec<Evidence> {
    library_with_regions(cfg, input).into_iter().map(|(e, _)| e).collect()
}

/// The library's evidence and, per sample, the region columns' intervals (the paper window's
/// output and input, then the calibrated window's output when calibrated).
fn library_with_regions(cfg: &config::Config, input: &str) -> Vec<(Evidence, Vec<Interval>)> {
    let mut cert = Certifier::new(cfg.certifier.clone()).expect("valid configuration");
    input
        .lines()
        .skip(1)
        .map(|line| {
            let v: Vec<f64> = line.split(',').map(|f| f.parse().expect("number")).collect();
            let e = cert.push(v[0], &v[1..2], &v[2..3]).expect("sample");
            let mut region: Vec<Interval> = cert.region().collect();
            if cfg.certifier.calibration.is_some() {
                region.push(cert.calibrated_region().next().unwrap_or(Interval::EMPTY));
            }
            (e, region)
        })
        .collect()
}

fn numbers(e: &Evidence) -> [(&'static str, Option<f64>); 11] {
    let amb = e.ambiguity;
    [
        ("beta_hat", e.beta_hat()),
        ("rho", e.rho()),
        ("eps", amb.map(|a| a.eps)),
        ("kurtosis", amb.and_then(|a| a.kurtosis)),
        ("spike_fraction", amb.map(|a| a.spike_fraction)),
        ("cert_gauss", e.gaussian.value),
        ("cert_wass", e.wasserstein.value),
        ("cert_calibrated", e.calibrated.value),
        ("cert_nonlinear", e.nonlinear.value),
        ("nonlinear_y_lo", e.nonlinear_region.map(|r| r.lo)),
        ("nonlinear_y_hi", e.nonlinear_region.map(|r| r.hi)),
    ]
}

fn reason(r: Option<NotCertified>) -> String {
    r.map_or(String::new(), |r| r.to_string())
}

#[test]
fn csv_rows_read_back_to_the_library_evidence() {
    // With the calibrated and nonlinear certificates, so their columns carry numbers too.
    let text = config::g5_node_b().replace("enabled = false", "enabled = true");
    let cfg = config::parse(&text, "calibrated").expect("configuration");
    assert!(cfg.certifier.nonlinear.is_some());
    let input = plant_csv(6000);
    let with_regions = library_with_regions(&cfg, &input);
    let want: Vec<Evidence> = with_regions.iter().map(|(e, _)| *e).collect();
    let mut out = Vec::new();
    certify::run(&cfg, input.as_bytes(), "plant", &mut out, &options(Format::Csv)).expect("run");
    let mut reader = csv::Reader::from_reader(out.as_slice());
    let header = reader.headers().expect("header").clone();
    let regions = [
        "region_lo_y_b",
        "region_hi_y_b",
        "region_lo_u_b",
        "region_hi_u_b",
        "region_lo_calibrated_y_b",
        "region_hi_calibrated_y_b",
    ];
    let names: Vec<&str> =
        streamcert_certificate::EVIDENCE_COLUMNS.iter().copied().chain(regions).collect();
    assert_eq!(header.iter().collect::<Vec<_>>(), names);
    let col = |name: &str| header.iter().position(|h| h == name).expect("column");
    let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.expect("row")).collect();
    assert_eq!(rows.len(), want.len());
    let (mut open, mut reasons) = (0, 0);
    for (row, (e, region)) in rows.iter().zip(&with_regions) {
        assert_eq!(row[col("t")].parse::<f64>().expect("t").to_bits(), e.t.to_bits());
        for (i, r) in region.iter().enumerate() {
            let (lo, hi) = (&row[col(regions[2 * i])], &row[col(regions[2 * i + 1])]);
            if r.is_proper() {
                assert_eq!(lo.parse::<f64>().expect("lo").to_bits(), r.lo.to_bits());
                assert_eq!(hi.parse::<f64>().expect("hi").to_bits(), r.hi.to_bits());
            } else {
                assert!(lo.is_empty() && hi.is_empty());
            }
        }
        for (name, value) in numbers(e) {
            let field = &row[col(name)];
            match value {
                Some(v) => assert_eq!(
                    field.parse::<f64>().expect("number").to_bits(),
                    v.to_bits(),
                    "{name} at t = {}",
                    e.t
                ),
                None => assert!(field.is_empty(), "{name} at t = {}: `{field}`", e.t),
            }
        }
        for (kind, open_col, reason_col) in [
            (CertificateKind::Gaussian, "gauss_open", "reason_gauss"),
            (CertificateKind::Wasserstein, "wass_open", "reason_wass"),
            (CertificateKind::Calibrated, "calibrated_open", "reason_calibrated"),
            (CertificateKind::Nonlinear, "nonlinear_open", "reason_nonlinear"),
        ] {
            let v = e.verdict(kind);
            assert_eq!(&row[col(open_col)], if v.open { "1" } else { "0" });
            assert_eq!(row[col(reason_col)], reason(v.reason));
            open += usize::from(v.open);
            reasons += usize::from(v.reason.is_some());
        }
    }
    // The stream exercises open gates, closed ones with reasons, and calibrated numbers.
    assert!(open > 0 && reasons > 0, "open {open}, reasons {reasons}");
    assert!(want.iter().any(|e| e.calibrated.open), "the calibrated gate opens");
    assert!(want.iter().any(|e| e.nonlinear.value.is_some()), "a nonlinear certificate");
}

#[test]
fn json_lines_read_back_to_the_library_evidence() {
    let cfg = config::parse(&config::g5_node_b(), "g5 node b").expect("default configuration");
    let input = plant_csv(1500);
    let want = library(&cfg, &input);
    let mut out = Vec::new();
    certify::run(&cfg, input.as_bytes(), "plant", &mut out, &options(Format::Jsonl)).expect("run");
    let text = String::from_utf8(out).expect("UTF-8");
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), want.len());
    for (line, e) in lines.iter().zip(&want) {
        let v: serde_json::Value = serde_json::from_str(line).expect("JSON");
        for (name, value) in numbers(e) {
            assert_eq!(v[name].as_f64().map(f64::to_bits), value.map(f64::to_bits), "{name}");
        }
        assert_eq!(v["gauss_open"], u8::from(e.gaussian.open));
        assert_eq!(
            v["reason_calibrated"].as_str().map(String::from),
            e.calibrated.reason.map(|r| r.to_string())
        );
    }
}

#[test]
fn the_reader_thread_changes_nothing_but_speed() {
    // A file input is read and parsed by one thread and certified by another, in batches of
    // 1024 rows; a live one on the writing thread. Bad rows spread over several batches,
    // under both policies.
    let cfg = config::parse(&config::g5_node_b(), "g5 node b").expect("default configuration");
    let mut lines: Vec<String> = plant_csv(5000).lines().map(String::from).collect();
    for (k, bad) in [(700, "x"), (1024, "nan"), (1025, ""), (2049, "1e999"), (4000, "-inf")] {
        let mut f: Vec<String> = lines[k].split(',').map(String::from).collect();
        f[1] = bad.into();
        lines[k] = f.join(",");
    }
    let input = lines.join("\n") + "\n";
    // Checkpoints every 300 accepted rows (across batch boundaries): each path its own file.
    let dir = std::env::temp_dir().join(format!("streamcert-output-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory");
    for bad_rows in [BadRows::Skip, BadRows::Stop] {
        let outcome = |flush: certify::Flush| {
            let checkpoint = dir.join(format!("{bad_rows:?}-{flush:?}.ckpt"));
            let _ = std::fs::remove_file(&checkpoint);
            let opts = Options {
                bad_rows,
                flush,
                checkpoint: Some(checkpoint.clone()),
                checkpoint_every: Some(300),
                ..options(Format::Csv)
            };
            let mut out = Vec::new();
            let r = certify::run(&cfg, input.as_bytes(), "plant", &mut out, &opts);
            let saved = std::fs::read(&checkpoint).expect("a checkpoint was written");
            (r.map_err(|e| e.to_string()), out, saved)
        };
        let (threaded, live) =
            (outcome(certify::Flush::Buffered), outcome(certify::Flush::EachRow));
        assert_eq!(threaded.0, live.0, "{bad_rows:?}");
        assert_eq!(threaded.1, live.1, "{bad_rows:?}");
        // The last checkpoint written (at the end, or the last periodic one before the error)
        // is the same state.
        assert_eq!(threaded.2, live.2, "{bad_rows:?}");
        match (bad_rows, &threaded.0) {
            (BadRows::Skip, Ok(summary)) => assert_eq!(summary.skipped, 5),
            (BadRows::Stop, Err(message)) => assert!(message.contains("plant:701:"), "{message}"),
            (_, other) => panic!("{bad_rows:?}: {other:?}"),
        }
    }
}
