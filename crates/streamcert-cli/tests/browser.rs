//! The status page in a real browser: headless Chromium (Debian's package; `.ci/run`
//! installs it and turns on the `browser-tests` feature) loads the page of a live
//! `certify --serve` run, driven over the DevTools protocol. The page shows the gate open
//! within 2 s of the evidence row that opened it, the reason in words when a gap closes it,
//! and that data stopped when the input stalls; its screenshot is written to the test's
//! scratch directory (`status-page.png`, the picture in docs/operations.md and the README).

#![cfg(feature = "browser-tests")]

mod common;

use std::io::{BufRead, BufReader, Write};
use std::net::TcpStream;
use std::process::{Child, Stdio};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use common::{bin, tmp};
use tungstenite::stream::MaybeTlsStream;
use tungstenite::{Message, WebSocket};

/// A headless Chromium and its page's DevTools connection.
struct Browser {
    child: Child,
    page: WebSocket<MaybeTlsStream<TcpStream>>,
    id: u64,
}

impl Browser {
    fn start() -> Self {
        let profile = tmp("chromium-profile");
        let _ = std::fs::remove_dir_all(&profile);
        let mut child = std::process::Command::new("chromium")
            .args(["--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run"])
            .args(["--remote-debugging-port=0", "--window-size=1000,1400"])
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg("about:blank")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("chromium (apt-get install chromium)");
        let stderr = BufReader::new(child.stderr.take().unwrap());
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in stderr.lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
        let url = line_with(&rx, "DevTools listening on ", 30);
        let port = url.split(':').nth(2).unwrap().split('/').next().unwrap().to_string();
        let list = http_get(&format!("127.0.0.1:{port}"), "/json/list");
        let targets: serde_json::Value = serde_json::from_str(&list).unwrap();
        let ws = targets
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["type"] == "page")
            .and_then(|t| t["webSocketDebuggerUrl"].as_str())
            .unwrap()
            .to_string();
        let (page, _) = tungstenite::connect(ws).unwrap();
        Self { child, page, id: 0 }
    }

    /// Call `method` and return its result.
    fn call(&mut self, method: &str, params: serde_json::Value) -> serde_json::Value {
        self.id += 1;
        let msg = serde_json::json!({"id": self.id, "method": method, "params": params});
        self.page.send(Message::text(msg.to_string())).unwrap();
        loop {
            let Message::Text(text) = self.page.read().unwrap() else { continue };
            let v: serde_json::Value = serde_json::from_str(text.as_str()).unwrap();
            if v["id"] == self.id {
                return v["result"].clone();
            }
        }
    }

    /// What the page shows: the body's `data-gate` and `data-stalled`, the reason, the stall
    /// banner.
    fn shows(&mut self) -> serde_json::Value {
        let js = "JSON.stringify({gate: document.body.dataset.gate, stalled: \
                  document.body.dataset.stalled, gateText: document.getElementById('gate').textContent, \
                  reason: document.getElementById('reason').textContent, stall: \
                  document.getElementById('stall-words').textContent, t: \
                  document.getElementById('counters').textContent})";
        let r = self
            .call("Runtime.evaluate", serde_json::json!({"expression": js, "returnByValue": true}));
        serde_json::from_str(r["result"]["value"].as_str().unwrap_or("{}")).unwrap()
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `GET path` on `host`; the body by its Content-Length (DevTools keeps the connection open).
fn http_get(host: &str, path: &str) -> String {
    let mut s = TcpStream::connect(host).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(s, "GET {path} HTTP/1.1\r\nHost: {host}\r\n\r\n").unwrap();
    let mut r = BufReader::new(s);
    let mut length = 0;
    loop {
        let mut line = String::new();
        r.read_line(&mut line).unwrap();
        if line.trim().is_empty() {
            break;
        }
        if let Some((k, v)) = line.split_once(':') {
            if k.eq_ignore_ascii_case("content-length") {
                length = v.trim().parse().unwrap();
            }
        }
    }
    let mut body = vec![0; length];
    std::io::Read::read_exact(&mut r, &mut body).unwrap();
    String::from_utf8(body).unwrap()
}

/// The first line of `rx` containing `pattern`, from it on; `secs` at most.
fn line_with(rx: &Receiver<String>, pattern: &str, secs: u64) -> String {
    let deadline = Instant::now() + Duration::from_secs(secs);
    loop {
        let line = rx.recv_timeout(deadline.saturating_duration_since(Instant::now())).unwrap();
        if let Some(i) = line.find(pattern) {
            return line[i + pattern.len()..].to_string();
        }
    }
}

/// Standard base64 (a screenshot).
fn base64(text: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        _ => 63,
    };
    let clean: Vec<u8> = text.bytes().filter(|&c| c != b'=' && !c.is_ascii_whitespace()).collect();
    let mut out = Vec::with_capacity(clean.len() * 3 / 4);
    for chunk in clean.chunks(4) {
        let v: Vec<u32> = chunk.iter().map(|&c| u32::from(value(c))).collect();
        let n = v.iter().enumerate().fold(0u32, |acc, (i, x)| acc | (x << (18 - 6 * i)));
        out.extend(n.to_be_bytes()[1..chunk.len()].iter());
    }
    out
}

#[test]
fn the_status_page_shows_the_gate_the_reason_and_a_stall_in_chromium() {
    let data = bin().args(["simulate", "g5", "--experiment", "2", "--seed", "1"]).output().unwrap();
    let rows: Vec<String> =
        String::from_utf8(data.stdout).unwrap().lines().map(String::from).collect();
    let config = tmp("browser-node-b.toml");
    std::fs::write(&config, streamcert_pipeline::config::g5_node_b()).unwrap();
    let mut certify = bin()
        .args(["certify", "--config", config.to_str().unwrap(), "--serve", "127.0.0.1:0"])
        .args(["--name", "node_b", "--stale-after", "2"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = BufReader::new(certify.stderr.take().unwrap());
    let (tx, err) = std::sync::mpsc::channel();
    std::thread::spawn(move || stderr.lines().map_while(Result::ok).for_each(|l| drop(tx.send(l))));
    let page = line_with(&err, "status page: ", 20);
    // The evidence rows as they arrive: when the calibrated gate changed, by the wall clock.
    let stdout = BufReader::new(certify.stdout.take().unwrap());
    let (tx, changes) = std::sync::mpsc::channel::<(Instant, bool)>();
    std::thread::spawn(move || {
        let mut lines = stdout.lines().map_while(Result::ok);
        let header = lines.next().unwrap();
        let gi = header.split(',').position(|h| h == "calibrated_open").unwrap();
        let mut was = false;
        for line in lines {
            let open = line.split(',').nth(gi) == Some("1");
            if open != was {
                let _ = tx.send((Instant::now(), open));
            }
            was = open;
        }
    });
    let mut browser = Browser::start();
    browser.call("Page.navigate", serde_json::json!({"url": page}));
    let mut stdin = certify.stdin.take().unwrap();
    let mut feed = |from: f64, to: f64| {
        for line in &rows {
            let t: f64 = line.split(',').next().unwrap().parse().unwrap_or(f64::NAN);
            if t.is_nan() && from == 0.0 || (t >= from && t < to) {
                writeln!(stdin, "{line}").unwrap();
                stdin.flush().unwrap();
                std::thread::sleep(Duration::from_millis(2));
            }
        }
    };
    // Until t = 8 s: the gate opens (at t = 6.38 on these data).
    feed(0.0, 8.0);
    let (opened, open) = changes.recv_timeout(Duration::from_secs(20)).unwrap();
    assert!(open);
    let shown = wait_for(&mut browser, opened + Duration::from_secs(2), |s| s["gate"] == "open");
    assert!(shown.is_some(), "the page did not show the gate open within 2 s of its row");
    let shot = browser.call("Page.captureScreenshot", serde_json::json!({"format": "png"}));
    let png = base64(shot["data"].as_str().unwrap());
    assert_eq!(&png[1..4], b"PNG");
    std::fs::write(tmp("status-page.png"), png).unwrap();
    // The rows of t in [10, 11) never come: the row at 11 s shows the gap, which closes the
    // gate; nothing comes after it for a while.
    feed(8.0, 10.0);
    feed(11.0, 11.005);
    let (closed, open) = changes.recv_timeout(Duration::from_secs(20)).unwrap();
    assert!(!open);
    let s = wait_for(&mut browser, closed + Duration::from_secs(2), |s| s["gate"] == "closed");
    let s = s.expect("the page did not show the gate closed within 2 s of its row");
    assert!(s["reason"].as_str().unwrap().contains("a gap in the time column"), "{s}");
    assert_eq!(s["gateText"], "closed");
    // The input has stalled since: no row for longer than --stale-after.
    let stalled = Instant::now();
    let s = wait_for(&mut browser, stalled + Duration::from_secs(5), |s| s["stalled"] == "true");
    let s = s.expect("the page did not say that data stopped");
    assert!(s["stall"].as_str().unwrap().contains("the source has stalled"), "{s}");
    // Data again: the banner goes.
    feed(11.005, 13.0);
    let s = wait_for(&mut browser, Instant::now() + Duration::from_secs(3), |s| {
        s["stalled"] == "false"
    });
    assert!(s.is_some(), "the stall banner stayed after data came back");
    drop(stdin);
    let out = common::wait_bounded(certify, 30, "certify");
    assert!(out.status.success());
}

/// Poll what the page shows every 100 ms until `ok` or `deadline`.
fn wait_for(
    browser: &mut Browser,
    deadline: Instant,
    ok: impl Fn(&serde_json::Value) -> bool,
) -> Option<serde_json::Value> {
    loop {
        let s = browser.shows();
        if ok(&s) {
            return Some(s);
        }
        if Instant::now() >= deadline {
            eprintln!("the page showed: {s}");
            return None;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}
