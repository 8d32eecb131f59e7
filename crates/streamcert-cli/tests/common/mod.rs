//! Helpers shared by the binary's end-to-end test files (`cli.rs`, `network.rs`).

#![allow(dead_code)]

pub(crate) mod live;

use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Output, Stdio};

/// The `streamcert` binary under test.
pub(crate) fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_streamcert"))
}

/// Run the binary with `args`, feeding `stdin` from a thread.
pub(crate) fn run(args: &[&str], stdin: &[u8]) -> Output {
    let mut child = bin()
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    // Feed stdin from another thread: the child streams its output while it reads, so
    // writing everything first could fill the output pipe and deadlock.
    let mut pipe = child.stdin.take().expect("stdin");
    let data = stdin.to_vec();
    let feeder = std::thread::spawn(move || {
        // The child may stop reading early (a configuration error): ignore a broken pipe.
        let _ = pipe.write_all(&data);
    });
    let out = child.wait_with_output().expect("wait");
    feeder.join().expect("feeder thread");
    out
}

/// A path in the tests' scratch directory.
pub(crate) fn tmp(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("cli-tests");
    std::fs::create_dir_all(&dir).expect("tmp dir");
    dir.join(name)
}

/// Lossy UTF-8.
pub(crate) fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// `streamcert compose --rates R --gains G <extra>`.
pub(crate) fn compose(rates: &std::path::Path, gains: &std::path::Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "compose",
        "--rates",
        rates.to_str().expect("utf8"),
        "--gains",
        gains.to_str().expect("utf8"),
    ];
    args.extend_from_slice(extra);
    run(&args, b"")
}

/// The printed default configuration with G5 node b's required keys set
/// (`config::g5_node_b`), written to a file private to the calling test (tests run in
/// parallel).
pub(crate) fn config(tag: &str) -> PathBuf {
    let out = run(&["certify", "--print-config"], b"");
    assert!(out.status.success());
    assert_eq!(text(&out.stdout), streamcert_pipeline::config::DEFAULT_CONFIG);
    let path = tmp(&format!("config-{tag}.toml"));
    std::fs::write(&path, streamcert_pipeline::config::g5_node_b()).expect("write config");
    path
}

/// The example network configuration (`network::EXAMPLE_CONFIG`: G5's two subsystems);
/// `network --print-config` writes it with the user's choices as placeholders.
pub(crate) fn network_example() -> String {
    streamcert_pipeline::network::EXAMPLE_CONFIG.to_string()
}

pub(crate) fn simulate(seed: &str) -> Vec<u8> {
    let out = run(&["simulate", "g5", "--experiment", "1", "--seed", seed], b"");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    out.stdout
}

/// Wait for `child` at most `secs` seconds; kill it and fail after that.
pub(crate) fn wait_bounded(
    mut child: std::process::Child,
    secs: u64,
    what: &str,
) -> std::process::Output {
    let start = std::time::Instant::now();
    loop {
        match child.try_wait().expect("try_wait") {
            Some(_) => return child.wait_with_output().expect("output"),
            None if start.elapsed().as_secs() >= secs => {
                let _ = child.kill();
                let out = child.wait_with_output().expect("output");
                panic!("{what} did not finish in {secs} s: {}", text(&out.stderr));
            }
            None => std::thread::sleep(std::time::Duration::from_millis(20)),
        }
    }
}
