//! `certify` from a live MQTT source against Mosquitto (Debian's package, started by each
//! test on loopback): killed with SIGKILL and resumed, the rows equal an uninterrupted run's;
//! the broker restarted mid-run, the process goes on, with a gap at the outage. Built with
//! the `mosquitto-tests` feature, which `.ci/run` turns on after installing Mosquitto
//! (`cargo test --workspace` needs nothing installed: the embedded broker's tests are in
//! `live.rs` and in the `streamcert-live` crate).
#![cfg(feature = "mosquitto-tests")]

use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use streamcert_live::publish::{self, PublishOptions};

mod common;
use common::live::{Certify, file_reference, g5, live_config, publisher, rows_of};
use common::tmp;

/// A Mosquitto broker on a loopback port, without persistence (a restart loses sessions),
/// queueing without limit for offline persistent sessions.
struct Mosquitto {
    child: Child,
    port: u16,
}

impl Mosquitto {
    fn start(port: u16) -> Self {
        let conf = format!(
            "listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n\
             max_queued_messages 0\n"
        );
        Self::start_with(port, &conf)
    }

    /// Mosquitto with the configuration `text`, waited for on `port`.
    fn start_with(port: u16, text: &str) -> Self {
        let conf = tmp(&format!("mosquitto-{port}.conf"));
        std::fs::write(&conf, text).unwrap();
        let child = Command::new("mosquitto")
            .args(["-c", conf.to_str().unwrap()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("mosquitto (apt-get install mosquitto)");
        let deadline = Instant::now() + Duration::from_secs(10);
        while TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(Instant::now() < deadline, "mosquitto did not start");
            std::thread::sleep(Duration::from_millis(20));
        }
        Self { child, port }
    }

    fn stop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Mosquitto {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Wait (30 s at most) until the evidence file `path` holds `n` rows; fail saying `what`.
fn wait_rows(path: &std::path::Path, n: usize, what: &str) {
    let deadline = Instant::now() + Duration::from_secs(30);
    while rows_of(path).len() < n {
        assert!(Instant::now() < deadline, "{what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Resume the killed run of `config` from `checkpoint`, writing `outputs.1`, until it ends;
/// the rows of both runs as one run's (and the resumed run's stderr). The rows the first run
/// wrote after its last checkpoint are certified again by the resumed one (their messages
/// were not acknowledged): the first run's rows are kept up to where the second starts.
fn resume(
    config: &std::path::Path,
    persist: &[&str],
    checkpoint: &std::path::Path,
    outputs: (&std::path::Path, &std::path::Path),
) -> (Vec<String>, String) {
    let args = [
        &["--output", outputs.1.to_str().unwrap()],
        persist,
        &["--resume", checkpoint.to_str().unwrap()],
    ]
    .concat();
    let (status, err) = Certify::start(config, &args).finish();
    assert!(status.success(), "{err}");
    let (a, b) = (rows_of(outputs.0), rows_of(outputs.1));
    let start: f64 = b.first().expect("the resumed run wrote rows").0.parse().unwrap();
    let mut got: Vec<String> =
        a.into_iter().filter(|(t, _)| t.parse::<f64>().unwrap() < start).map(|(_, r)| r).collect();
    got.extend(b.into_iter().map(|(_, r)| r));
    (got, err)
}

fn free_port() -> u16 {
    streamcert_live::broker::free_loopback().unwrap().port()
}

#[test]
fn killed_with_sigkill_and_resumed_the_rows_equal_an_uninterrupted_run() {
    let broker = Mosquitto::start(free_port());
    let config = live_config("kill", broker.port, "g5/kill");
    let (csv, header, rows) = g5("3000");
    let want_path = file_reference("kill", &csv);
    let (checkpoint, out1, out2) =
        (tmp("live-kill.ckpt"), tmp("live-kill-1.csv"), tmp("live-kill-2.csv"));
    let _ = std::fs::remove_file(&checkpoint);
    let persist = ["--checkpoint", checkpoint.to_str().unwrap(), "--checkpoint-every", "100"];
    let first =
        Certify::start(&config, &[&["--output", out1.to_str().unwrap()], &persist[..]].concat());
    let (head, tail) = rows.split_at(1500);
    publish::publish(&publisher(broker.port, "g5/kill", "pub-kill-1"), &header, 0, head.to_vec())
        .unwrap();
    // Kill it mid-stream, once it has certified some of what was published.
    wait_rows(&out1, 700, "the first run certified too little");
    first.kill();
    // The plant goes on publishing while streamcert is down; the broker queues it for the
    // persistent session.
    publish::publish(&publisher(broker.port, "g5/kill", "pub-kill-2"), &header, 0, tail.to_vec())
        .unwrap();
    let (got, err) = resume(&config, &persist, &checkpoint, (&out1, &out2));
    let want: Vec<String> = rows_of(&want_path).into_iter().map(|(_, r)| r).collect();
    assert_eq!(got.len(), want.len(), "rows; {err}");
    assert!(got == want, "the resumed run differs from the uninterrupted one");
}

#[test]
fn a_broker_restarted_mid_run_is_a_gap_and_the_process_goes_on() {
    let port = free_port();
    let mut broker = Mosquitto::start(port);
    let config = live_config("restart", port, "g5/restart");
    let (_, header, rows) = g5("2000");
    let out = tmp("live-restart.csv");
    let mut certify = Certify::start(&config, &["--output", out.to_str().unwrap()]);
    let (before, after) = rows.split_at(1000);
    publish::publish(&publisher(port, "g5/restart", "pub-r1"), &header, 0, before.to_vec())
        .unwrap();
    wait_rows(&out, 1000, "the rows before the restart were not certified");
    // The broker goes away and comes back without the session (no persistence).
    broker.stop();
    std::thread::sleep(Duration::from_millis(500));
    let _broker = Mosquitto::start(port);
    certify.wait_line("subscribed to", 2);
    let opts = PublishOptions { ..publisher(port, "g5/restart", "pub-r2") };
    publish::publish(&opts, &header, 0, after.to_vec()).unwrap();
    let (status, err) = certify.finish();
    assert!(status.success(), "{err}");
    let times: Vec<f64> = rows_of(&out).into_iter().map(|(t, _)| t.parse().unwrap()).collect();
    let published: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(times, published, "every row published before and after the outage certified");
    let source = err.lines().find(|l| l.contains(" messages, ")).expect("the source line");
    assert!(source.contains(" 1 gaps") && source.contains(" 1 reconnects"), "{source}");
    assert!(err.contains("did not keep the session"), "{err}");
}

/// Run `program args` in `dir`, failing the test on a non-zero exit.
fn sh(dir: &std::path::Path, program: &str, args: &[&str]) {
    let out = Command::new(program).args(args).current_dir(dir).output().expect(program);
    assert!(out.status.success(), "{program} {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

/// A CA and a server certificate for 127.0.0.1 (openssl, from Debian's packages) in a
/// scratch directory; its path.
fn tls_files() -> std::path::PathBuf {
    let dir = tmp("tls");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("ext.cnf"), "subjectAltName=IP:127.0.0.1\n").unwrap();
    for command in [
        "req -x509 -newkey rsa:2048 -nodes -days 2 -keyout ca.key -out ca.pem -subj /CN=streamcert-test-CA",
        "req -newkey rsa:2048 -nodes -keyout server.key -out server.csr -subj /CN=127.0.0.1",
        "x509 -req -in server.csr -CA ca.pem -CAkey ca.key -CAcreateserial -out server.pem -days 2 -extfile ext.cnf",
    ] {
        sh(&dir, "openssl", &command.split(' ').collect::<Vec<_>>());
    }
    // Mosquitto started as root reads its files as the `mosquitto` user: a test key may be
    // world-readable.
    sh(&dir, "chmod", &["644", "server.key"]);
    dir
}

#[test]
fn tls_with_a_password_from_a_file_certifies_and_never_shows_the_password() {
    let dir = tls_files();
    let secret = "pw-7f3a-never-shown";
    sh(&dir, "mosquitto_passwd", &["-b", "-c", "passwd", "operator", secret]);
    std::fs::write(dir.join("password"), format!("{secret}\n")).unwrap();
    // One plain listener for the plant, one TLS listener with passwords for streamcert.
    let (plain, tls) = (free_port(), free_port());
    let d = dir.display();
    let conf = format!(
        "per_listener_settings true\nlistener {plain} 127.0.0.1\nallow_anonymous true\n\
         listener {tls} 127.0.0.1\nallow_anonymous false\npassword_file {d}/passwd\n\
         cafile {d}/ca.pem\ncertfile {d}/server.pem\nkeyfile {d}/server.key\n"
    );
    let broker = Mosquitto::start_with(plain, &conf);
    let config = tmp("live-tls.toml");
    let source = format!(
        "\n[source]\nkind = \"mqtt\"\nservers = [\"ssl://127.0.0.1:{tls}\"]\n\
         client_id = \"streamcert-tls\"\ntopics = [\"g5/tls\"]\nidle_timeout = 2.0\n\
         tls_ca = \"{d}/ca.pem\"\nusername = \"operator\"\npassword_file = \"{d}/password\"\n"
    );
    std::fs::write(&config, streamcert_pipeline::config::g5_node_b() + &source).unwrap();
    let summary = tmp("live-tls-summary.json");
    let certify =
        Certify::start(&config, &["--output", "/dev/null", "--summary", summary.to_str().unwrap()]);
    let (_, header, rows) = g5("500");
    publish::publish(&publisher(broker.port, "g5/tls", "pub-tls"), &header, 0, rows).unwrap();
    let (status, err) = certify.finish();
    assert!(status.success(), "{err}");
    let json = std::fs::read_to_string(&summary).unwrap();
    assert!(json.contains("\"rows\":501") || json.contains("\"rows\": 501"), "{json}");
    assert!(!err.contains(secret) && !json.contains(secret), "the password was shown");
}

/// G5 node b's configuration reading `y_b` and `u_b` from a topic each, aligned on a 20 ms
/// grid, as client `id` of the broker on `port`.
fn signals_config(tag: &str, port: u16) -> std::path::PathBuf {
    let path = tmp(&format!("live-{tag}.toml"));
    let source = format!(
        "\n[source]\nkind = \"mqtt\"\nservers = [\"tcp://127.0.0.1:{port}\"]\n\
         client_id = \"streamcert-{tag}\"\nidle_timeout = 2.0\n\
         [source.align]\nperiod = 0.02\nmax_age = 0.02\nreorder_window = 0.1\n\
         [[source.signal]]\ncolumn = \"y_b\"\ntopic = \"{tag}/y_b\"\n\
         [[source.signal]]\ncolumn = \"u_b\"\ntopic = \"{tag}/u_b\"\n"
    );
    std::fs::write(&path, streamcert_pipeline::config::g5_node_b() + &source).unwrap();
    path
}

/// The rows `t, y_b, u_b` of G5 on the topics `{tag}/y_b` and `{tag}/u_b`.
fn publish_signals(port: u16, tag: &str, part: &str, rows: &[Vec<f64>]) {
    let opts = PublishOptions {
        layout: streamcert_live::publish::Layout::Signals,
        ..publisher(port, tag, &format!("pub-{tag}-{part}"))
    };
    let columns = ["t", "y_b", "u_b"].map(String::from);
    publish::publish(&opts, &columns, 0, rows.to_vec()).unwrap();
}

#[test]
fn per_signal_topics_killed_and_resumed_form_the_uninterrupted_rows() {
    let broker = Mosquitto::start(free_port());
    let (_, header, rows) = g5("1500");
    let pick = |c: &str| header.iter().position(|h| h == c).unwrap();
    let (t, y, u) = (pick("t"), pick("y_b"), pick("u_b"));
    let rows: Vec<Vec<f64>> = rows.iter().map(|r| vec![r[t], r[y], r[u]]).collect();
    // The uninterrupted run.
    let (whole, reference) = (signals_config("sigref", broker.port), tmp("live-sigref.csv"));
    let run = Certify::start(&whole, &["--output", reference.to_str().unwrap()]);
    publish_signals(broker.port, "sigref", "all", &rows);
    let (status, err) = run.finish();
    assert!(status.success(), "{err}");
    // Killed mid-stream and resumed: the aligner's state comes back from the checkpoint.
    let config = signals_config("sigkill", broker.port);
    let (checkpoint, out1, out2) =
        (tmp("live-sigkill.ckpt"), tmp("live-sigkill-1.csv"), tmp("live-sigkill-2.csv"));
    let _ = std::fs::remove_file(&checkpoint);
    let persist = ["--checkpoint", checkpoint.to_str().unwrap(), "--checkpoint-every", "50"];
    let first =
        Certify::start(&config, &[&["--output", out1.to_str().unwrap()], &persist[..]].concat());
    let (head, tail) = rows.split_at(800);
    publish_signals(broker.port, "sigkill", "1", head);
    wait_rows(&out1, 300, "the first run certified too little");
    first.kill();
    publish_signals(broker.port, "sigkill", "2", tail);
    let (got, err) = resume(&config, &persist, &checkpoint, (&out1, &out2));
    let want: Vec<String> = rows_of(&reference).into_iter().map(|(_, r)| r).collect();
    assert!(want.len() > 1000, "{} reference rows", want.len());
    assert_eq!(got.len(), want.len(), "rows; {err}");
    assert!(got == want, "the resumed aligned rows differ from the uninterrupted ones");
}

/// `mosquitto_pub` (Debian's mosquitto-clients) on `port`, QoS 1, with `args`; `stdin` fed to it.
fn mosquitto_pub(port: u16, args: &[&str], stdin: Option<&std::path::Path>) {
    let port = port.to_string();
    let mut cmd = Command::new("mosquitto_pub");
    cmd.args(["-h", "127.0.0.1", "-p", &port, "-q", "1"]).args(args);
    if let Some(path) = stdin {
        cmd.stdin(std::fs::File::open(path).unwrap());
    }
    let out = cmd.output().expect("mosquitto_pub (apt-get install mosquitto-clients)");
    assert!(out.status.success(), "mosquitto_pub {args:?}: {}", text(&out.stderr));
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A scratch file `foreign-{name}` holding `bytes`.
fn scratch_file(name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = tmp(&format!("foreign-{name}"));
    std::fs::write(&p, bytes).unwrap();
    p
}

/// The bad messages of the matrix, as `mosquitto_pub` arguments: 2 MiB, exactly
/// `max_payload + 1` (of 262 144), 100 000 nested JSON arrays (within the payload limit, so
/// that the JSON parser sees them), invalid UTF-8, and an empty payload.
fn bad_messages() -> Vec<Vec<String>> {
    let nested = [vec![b'['; 100_000], vec![b']'; 100_000]].concat();
    let files = [
        scratch_file("2mib", &vec![b'x'; 2 << 20]),
        scratch_file("limit", &vec![b'x'; 262_145]),
        scratch_file("nested", &nested),
        scratch_file("utf8", &[0xff, 0xfe, 0x7b]),
    ];
    let mut bad: Vec<Vec<String>> =
        files.iter().map(|f| vec!["-f".into(), f.to_str().unwrap().into()]).collect();
    bad.push(vec!["-n".into()]);
    bad
}

/// Publish `bad` (mosquitto_pub arguments) on `topic`.
fn publish_bad(port: u16, topic: &str, bad: &[String]) {
    let args: Vec<&str> = ["-t", topic].into_iter().chain(bad.iter().map(String::as_str)).collect();
    mosquitto_pub(port, &args, None);
}

/// Publish `rows` of `header` on `topic` as JSON lines from a foreign publisher
/// (`mosquitto_pub -l`, a message per line), and append them to the reference `csv`.
fn publish_rows(port: u16, topic: &str, header: &[String], rows: &[Vec<f64>], csv: &mut String) {
    let lines: Vec<String> = rows
        .iter()
        .map(|r| {
            let pairs: Vec<String> =
                header.iter().zip(r).map(|(h, v)| format!("\"{h}\":{v}")).collect();
            format!("{{{}}}", pairs.join(","))
        })
        .collect();
    let t0 = rows.first().map_or(0.0, |r| r[0]);
    let jsonl = scratch_file(&format!("rows-{t0}.jsonl"), (lines.join("\n") + "\n").as_bytes());
    mosquitto_pub(port, &["-t", topic, "-l"], Some(&jsonl));
    for r in rows {
        let v: Vec<String> = r.iter().map(f64::to_string).collect();
        csv.push_str(&(v.join(",") + "\n"));
    }
}

/// G5 node b's live configuration for `topic`, with a payload limit of 256 KiB (so that the
/// nested arrays reach the JSON parser) and `extra` `[source]` keys.
fn foreign_config(tag: &str, port: u16, topic: &str, extra: &str) -> std::path::PathBuf {
    let config = live_config(tag, port, topic);
    let mut toml = std::fs::read_to_string(&config).unwrap();
    toml.push_str(&format!("max_payload = 262144\n{extra}"));
    std::fs::write(&config, toml).unwrap();
    config
}

#[test]
fn no_bad_message_from_a_foreign_publisher_stalls_the_certifier_and_each_is_counted_once() {
    let broker = Mosquitto::start(free_port());
    let (port, topic) = (broker.port, "g5/foreign");
    let config = foreign_config("foreign", port, topic, "");
    let bad = bad_messages();
    // A retained bad message, there before the certifier subscribes.
    mosquitto_pub(port, &["-t", topic, "-r", "-m", "{\"t\": "], None);
    let (_, header, rows) = g5("4999");
    assert_eq!(rows.len(), 5000);
    let metrics_port = free_port();
    let metrics = format!("127.0.0.1:{metrics_port}");
    let out = tmp("live-foreign-out.csv");
    let args = ["--output", out.to_str().unwrap(), "--metrics", &metrics];
    let certify = Certify::start(&config, &args);
    // The reference: the same rows from a file, a bad line where each bad message was.
    let mut csv = format!("{}\nnot a row\n", header.join(","));
    for (k, block) in rows.chunks(1000).enumerate() {
        publish_bad(port, topic, &bad[k]);
        csv.push_str("not a row\n");
        publish_rows(port, topic, &header, block, &mut csv);
    }
    wait_rows(&out, 5000, "the good rows were not all certified");
    // Prometheus' own linter passes the metrics served mid-run.
    let scraped =
        Command::new("curl").args(["-sf", &format!("http://{metrics}/metrics")]).output().unwrap();
    assert!(scraped.status.success(), "curl: {}", text(&scraped.stderr));
    let scraped_path = scratch_file("metrics.txt", &scraped.stdout);
    let lint = Command::new("promtool")
        .args(["check", "metrics"])
        .stdin(std::fs::File::open(&scraped_path).unwrap())
        .output()
        .expect("promtool (apt-get install prometheus)");
    assert!(lint.status.success(), "promtool: {}{}", text(&lint.stdout), text(&lint.stderr));
    let (status, err) = certify.finish();
    assert!(status.success(), "{err}");
    mosquitto_pub(port, &["-t", topic, "-r", "-n"], None);
    let want = file_reference("foreign", &csv);
    assert!(rows_of(&out) == rows_of(&want), "the live rows differ from the file's");
    let source = err.lines().find(|l| l.contains(" messages, ")).expect("the source line");
    for counted in
        ["6 bad (", "not_json 3", "oversized 2", "not_utf8 1", "0 reconnects (0 attempts)"]
    {
        assert!(source.contains(counted), "{counted}: {source}");
    }
}

/// The certifier killed while a bad message is in flight (taken, its row skipped, not yet
/// acknowledged: no checkpoint since) and resumed from its checkpoint: the broker delivers
/// the bad message again, and the rows of both runs are the uninterrupted file's, a skipped
/// row where each bad message was; no reconnection.
#[test]
fn killed_with_a_bad_message_in_flight_and_resumed_loses_nothing() {
    // Mosquitto with no limit on the messages in flight, so that the ones after the last
    // checkpoint stay unacknowledged until the next.
    let port = free_port();
    let conf = format!(
        "listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n\
         max_queued_messages 0\nmax_inflight_messages 0\n"
    );
    let broker = Mosquitto::start_with(port, &conf);
    let topic = "g5/badkill";
    let config = foreign_config("badkill", broker.port, topic, "max_unacked = 100000\n");
    let bad = bad_messages();
    let (_, header, rows) = g5("2999");
    let (checkpoint, out1, out2) =
        (tmp("live-badkill.ckpt"), tmp("live-badkill-1.csv"), tmp("live-badkill-2.csv"));
    let _ = std::fs::remove_file(&checkpoint);
    let persist = ["--checkpoint", checkpoint.to_str().unwrap(), "--checkpoint-every", "1000"];
    let first =
        Certify::start(&config, &[&["--output", out1.to_str().unwrap()], &persist[..]].concat());
    let mut csv = format!("{}\n", header.join(","));
    publish_rows(broker.port, topic, &header, &rows[..1020], &mut csv);
    // After the checkpoint at row 1000: in flight when the process is killed.
    publish_bad(broker.port, topic, &bad[0]);
    csv.push_str("not a row\n");
    publish_rows(broker.port, topic, &header, &rows[1020..1500], &mut csv);
    wait_rows(&out1, 1400, "the first run certified too little");
    first.kill();
    // While it is down: another bad message and the rest of the rows, queued by the broker.
    publish_bad(broker.port, topic, &bad[2]);
    csv.push_str("not a row\n");
    publish_rows(broker.port, topic, &header, &rows[1500..], &mut csv);
    let (got, err) = resume(&config, &persist, &checkpoint, (&out1, &out2));
    let want: Vec<String> =
        rows_of(&file_reference("badkill", &csv)).into_iter().map(|(_, r)| r).collect();
    assert_eq!(got.len(), want.len(), "rows; {err}");
    assert!(got == want, "the resumed run differs from the uninterrupted one");
    let source = err.lines().find(|l| l.contains(" messages, ")).expect("the source line");
    assert!(source.contains("oversized 1") && source.contains("not_json 1"), "{source}");
    assert!(source.contains("0 reconnects (0 attempts)"), "{source}");
    // The resumed process took both bad messages itself: the one in flight when the first
    // was killed came again, the other was queued.
    let skipped = err.lines().filter(|l| l.starts_with("skipped: mqtt topic g5/badkill")).count();
    assert_eq!(skipped, 2, "{err}");
}

/// The matrix on per-signal topics: a bad message of each kind on `y_b`'s topic before each
/// block of 600 samples, and a retained one on `u_b`'s there before the certifier subscribes.
/// Each is counted once, with no reconnection, and every row the samples form is formed and
/// certified at the clean run's times. (A bad message closes the gates for the row being
/// formed when it arrives, which the alignment's timing decides, so the rows' numbers are
/// compared in the row-topic tests above, not here.)
#[test]
fn bad_messages_on_per_signal_topics_are_counted_once_and_every_row_is_formed() {
    let broker = Mosquitto::start(free_port());
    let port = broker.port;
    let (_, header, rows) = g5("2999");
    let pick = |c: &str| header.iter().position(|h| h == c).unwrap();
    let (t, y, u) = (pick("t"), pick("y_b"), pick("u_b"));
    let rows: Vec<Vec<f64>> = rows.iter().map(|r| vec![r[t], r[y], r[u]]).collect();
    let (clean, reference) = (signals_config("sigclean", port), tmp("live-sigclean.csv"));
    let run = Certify::start(&clean, &["--output", reference.to_str().unwrap()]);
    publish_signals(port, "sigclean", "all", &rows);
    let (status, err) = run.finish();
    assert!(status.success(), "{err}");
    let config = signals_config("sigbad", port);
    let toml = std::fs::read_to_string(&config).unwrap();
    let limit = "idle_timeout = 2.0\nmax_payload = 262144\n";
    std::fs::write(&config, toml.replacen("idle_timeout = 2.0\n", limit, 1)).unwrap();
    mosquitto_pub(port, &["-t", "sigbad/u_b", "-r", "-m", "{\"t\": "], None);
    let out = tmp("live-sigbad.csv");
    let run = Certify::start(&config, &["--output", out.to_str().unwrap()]);
    for (k, (block, bad)) in rows.chunks(600).zip(bad_messages()).enumerate() {
        publish_bad(port, "sigbad/y_b", &bad);
        publish_signals(port, "sigbad", &k.to_string(), block);
    }
    let (status, err) = run.finish();
    mosquitto_pub(port, &["-t", "sigbad/u_b", "-r", "-n"], None);
    assert!(status.success(), "{err}");
    let times = |p: &std::path::Path| rows_of(p).into_iter().map(|(t, _)| t).collect::<Vec<_>>();
    let want = times(&reference);
    assert!(want.len() > 2900, "{} reference rows", want.len());
    assert_eq!(times(&out), want, "the rows formed differ from the clean run's");
    let source = err.lines().find(|l| l.contains(" messages, ")).expect("the source line");
    for counted in
        ["6 bad (", "not_json 3", "oversized 2", "not_utf8 1", "0 reconnects (0 attempts)"]
    {
        assert!(source.contains(counted), "{counted}: {source}");
    }
}
