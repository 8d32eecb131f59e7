//! The golden record: every committed example configuration run on its committed data, its
//! evidence pinned byte for byte (length and FNV-1a 64 of the file) and its summary word for
//! word, against `tests/golden/examples.txt`. A change that moves one number of one row, or
//! one word of one verdict, fails here; a change meant to do so rewrites the record with
//! `STREAMCERT_BLESS=1 cargo test -p streamcert-cli --test golden` and shows the difference
//! in its commit. The live examples (`g5_live.toml`, `g5_opcua.toml`) read from a broker or a
//! server: their certificate is the file configuration's, pinned by `g5_node_b.toml`.

use std::path::{Path, PathBuf};

mod common;
use common::{bin, text, tmp};

/// The repository's root.
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The committed examples: `(name, command, configuration, data)`, paths from the root.
const CASES: [(&str, &str, &str, &str); 5] = [
    ("certify_b", "certify", "examples/data/certify_b.toml", "examples/data/g5_exp2_seed1.csv"),
    ("g5_node_b", "certify", "examples/data/g5_node_b.toml", "examples/data/g5_exp2_seed1.csv"),
    ("g5_network", "network", "examples/data/g5_network.toml", "examples/data/g5_exp2_seed1.csv"),
    ("exchanger", "certify", "examples/real/exchanger.toml", "examples/real/exchanger.csv"),
    ("tanks", "certify", "examples/real/tanks.toml", "examples/real/tanks.csv"),
];

/// FNV-1a, 64 bits.
fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes
        .iter()
        .fold(0xcbf2_9ce4_8422_2325, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
}

/// One case's record: a header line with the evidence's rows, bytes and hash, then the
/// summary (standard error) line by line, each behind `| `.
fn record(name: &str, command: &str, config: &str, data: &str) -> String {
    let out = tmp(&format!("golden-{name}.csv"));
    let run = bin()
        .current_dir(root())
        .args([command, "--config", config, "--input", data, "--output"])
        .arg(&out)
        .output()
        .expect("the command line");
    let err = text(&run.stderr);
    assert!(run.status.success(), "{name}: {err}");
    let evidence = std::fs::read(&out).expect("the evidence");
    let rows = evidence.iter().filter(|&&b| b == b'\n').count();
    let mut rec = format!(
        "== {name}: {command} {config} {data}: evidence {rows} lines, {} bytes, fnv1a64 {:016x}\n",
        evidence.len(),
        fnv1a64(&evidence)
    );
    for line in err.lines() {
        rec.push_str(&format!("| {line}\n"));
    }
    rec
}

#[test]
fn every_committed_example_gives_its_recorded_evidence_and_summary() {
    let got: String = CASES.iter().map(|&(n, c, cfg, data)| record(n, c, cfg, data)).collect();
    let path = root().join("tests/golden/examples.txt");
    if std::env::var_os("STREAMCERT_BLESS").is_some() {
        std::fs::write(&path, &got).expect("the record");
    }
    let want = std::fs::read_to_string(&path).expect("tests/golden/examples.txt");
    for (g, w) in got.lines().zip(want.lines()) {
        assert_eq!(g, w, "the first line that differs from tests/golden/examples.txt");
    }
    assert_eq!(got.lines().count(), want.lines().count(), "lines of the record");
}
