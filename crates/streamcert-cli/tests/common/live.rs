//! Helpers of the live-source tests (`live.rs`, `mosquitto.rs`): the configuration, a certify
//! process whose stderr is watched line by line, the G5 rows, a publisher.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use streamcert_live::publish::{Layout, PublishOptions};

use super::{bin, text, tmp};

/// Held from taking a free loopback port until a broker or server listens on it: a port is
/// free only until someone binds it, and the tests of one binary run in parallel, so without
/// it a test's broker could take the port another test's plant is about to serve on.
pub(crate) static PORT: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// The lock of [`PORT`] (a test that failed while holding it does not stop the others).
pub(crate) fn port_lock() -> std::sync::MutexGuard<'static, ()> {
    PORT.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// G5 node b's configuration reading the rows of `topic` from the broker on `port`, ending
/// after 3 s without a message.
pub(crate) fn live_config(tag: &str, port: u16, topic: &str) -> PathBuf {
    let path = tmp(&format!("live-{tag}.toml"));
    let source = format!(
        "\n[source]\nkind = \"mqtt\"\nservers = [\"tcp://127.0.0.1:{port}\"]\n\
         client_id = \"streamcert-{tag}\"\ntopics = [\"{topic}\"]\nidle_timeout = 3.0\n\
         reconnect_min = 0.05\nreconnect_max = 0.2\n"
    );
    std::fs::write(&path, streamcert_pipeline::config::g5_node_b() + &source).unwrap();
    path
}

/// A running `certify` and its stderr, line by line.
pub(crate) struct Certify {
    child: Option<Child>,
    pub(crate) lines: Receiver<String>,
    pub(crate) seen: Vec<String>,
}

impl Certify {
    /// Start `certify --config config <args>` and wait until it says it is subscribed.
    pub(crate) fn start(config: &Path, args: &[&str]) -> Self {
        let mut all = vec!["certify", "--config", config.to_str().unwrap()];
        all.extend_from_slice(args);
        Self::start_args(&all)
    }

    /// Start `streamcert <args>` (a certify on a live source) and wait until it says it is
    /// subscribed.
    pub(crate) fn start_args(args: &[&str]) -> Self {
        let mut child =
            bin().args(args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
        let stderr = BufReader::new(child.stderr.take().unwrap());
        let (tx, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in stderr.lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let mut c = Self { child: Some(child), lines, seen: Vec::new() };
        c.wait_line("subscribed to", 1);
        c
    }

    /// Wait (20 s at most) until `n` lines containing `pattern` have been seen.
    pub(crate) fn wait_line(&mut self, pattern: &str, n: usize) {
        let deadline = Instant::now() + Duration::from_secs(20);
        while self.seen.iter().filter(|l| l.contains(pattern)).count() < n {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => self.seen.push(line),
                Err(RecvTimeoutError::Timeout | RecvTimeoutError::Disconnected) => {
                    panic!("no `{pattern}` ({n}) on stderr: {}", self.seen.join("\n"))
                }
            }
        }
    }

    /// Wait (60 s at most) for the end; its exit status and whole stderr (the reader's last
    /// lines included: it sends until the process's stderr closes, 5 s at most after the
    /// exit).
    pub(crate) fn finish(mut self) -> (std::process::ExitStatus, String) {
        let child = self.child.take().expect("running");
        let out = super::wait_bounded(child, 60, "certify");
        let deadline = Instant::now() + Duration::from_secs(5);
        while let Ok(line) =
            self.lines.recv_timeout(deadline.saturating_duration_since(Instant::now()))
        {
            self.seen.push(line);
        }
        (out.status, self.seen.join("\n"))
    }

    /// SIGKILL.
    pub(crate) fn kill(mut self) {
        if let Some(mut c) = self.child.take() {
            c.kill().unwrap();
            c.wait().unwrap();
        }
    }
}

/// A test that fails leaves no process behind.
impl Drop for Certify {
    fn drop(&mut self) {
        if let Some(c) = &mut self.child {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// G5 experiment 1, seed 3, `steps` rows: the CSV text, its header and its rows.
pub(crate) fn g5(steps: &str) -> (String, Vec<String>, Vec<Vec<f64>>) {
    let out = bin().args(["simulate", "g5", "--seed", "3", "--steps", steps]).output().unwrap();
    assert!(out.status.success());
    let csv = text(&out.stdout);
    let mut lines = csv.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines.map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    (csv, header, rows)
}

/// A publisher of whole rows on `topic` (client id `id`).
pub(crate) fn publisher(port: u16, topic: &str, id: &str) -> PublishOptions {
    let server = streamcert_live::config::Server { host: "127.0.0.1".into(), port, tls: false };
    PublishOptions {
        server,
        topic: topic.into(),
        client_id: id.into(),
        layout: Layout::Rows,
        pace: 0.0,
    }
}

/// The data rows of a certify CSV output (no header), each with its time's text.
pub(crate) fn rows_of(path: &Path) -> Vec<(String, String)> {
    let out = std::fs::read_to_string(path).unwrap_or_default();
    out.lines()
        .filter(|l| !l.starts_with('t'))
        .map(|l| (l.split(',').next().unwrap().to_string(), l.to_string()))
        .collect()
}

/// `certify --input` of `csv` with G5 node b's configuration, a line that is not a row
/// skipped (`--on-bad-row skip`, where a live source's bad message was): the reference
/// output's path.
pub(crate) fn file_reference(tag: &str, csv: &str) -> PathBuf {
    let csv_path = tmp(&format!("live-{tag}.csv"));
    std::fs::write(&csv_path, csv).unwrap();
    let cfg = tmp(&format!("live-{tag}-file.toml"));
    std::fs::write(&cfg, streamcert_pipeline::config::g5_node_b()).unwrap();
    let want = tmp(&format!("live-{tag}-want.csv"));
    let status = bin()
        .args(["certify", "--config", cfg.to_str().unwrap(), "--on-bad-row", "skip", "--input"])
        .args([csv_path.to_str().unwrap(), "--output", want.to_str().unwrap()])
        .status()
        .unwrap();
    assert!(status.success());
    want
}
