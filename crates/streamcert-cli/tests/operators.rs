//! The verdict where operators look, end to end through the binary: the verdict topic on a
//! real broker (the embedded one) and the status page's server.

mod common;

use std::process::Stdio;
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use common::{bin, tmp, wait_bounded};
use rumqttc::{Client, Event, MqttOptions, Packet, QoS};

/// A subscriber to `topic` on the broker at `port`: every message's payload and retain flag,
/// once it is subscribed.
fn subscriber(port: u16, topic: &str, id: &str) -> Receiver<(serde_json::Value, bool)> {
    let (client, mut connection) = Client::new(MqttOptions::new(id, "127.0.0.1", port), 16);
    client.subscribe(topic, QoS::AtLeastOnce).unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let (ready_tx, ready) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _client = client;
        for event in connection.iter() {
            match event {
                Ok(Event::Incoming(Packet::SubAck(_))) => {
                    let _ = ready_tx.send(());
                }
                Ok(Event::Incoming(Packet::Publish(p))) => {
                    let v = serde_json::from_slice(&p.payload).unwrap();
                    if tx.send((v, p.retain)).is_err() {
                        break;
                    }
                }
                Ok(_) => {}
                Err(_) => std::thread::sleep(Duration::from_millis(50)),
            }
        }
    });
    ready.recv_timeout(Duration::from_secs(10)).expect("subscribed");
    rx
}

/// An embedded broker on a free port, and a subscriber `id` to `topic` on it.
fn broker_with_subscriber(
    topic: &str,
    id: &str,
) -> (std::net::SocketAddr, Receiver<(serde_json::Value, bool)>) {
    let port = streamcert_live::broker::free_loopback().unwrap();
    streamcert_live::broker::serve(port).unwrap();
    (port, subscriber(port.port(), topic, id))
}

/// Messages from `rx` until one has `ended` (or `stop` says so), 30 s at most.
fn until(
    rx: &Receiver<(serde_json::Value, bool)>,
    stop: impl Fn(&serde_json::Value) -> bool,
) -> Vec<serde_json::Value> {
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut got = Vec::new();
    while let Ok((m, _)) = rx.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
        let done = stop(&m);
        got.push(m);
        if done {
            return got;
        }
    }
    panic!("no last message: {got:?}");
}

/// G5 Experiment 2, seed 1, with the rows of t in [10, 11) left out (a gap that closes the
/// gate), written to a file.
fn g5_with_gap(tag: &str) -> std::path::PathBuf {
    let out = bin().args(["simulate", "g5", "--experiment", "2", "--seed", "1"]).output().unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    let kept: Vec<&str> = text
        .lines()
        .enumerate()
        .filter(|(i, l)| {
            let t: f64 = l.split(',').next().unwrap().parse().unwrap_or(0.0);
            *i == 0 || !(10.0..11.0).contains(&t)
        })
        .map(|(_, l)| l)
        .collect();
    let path = tmp(&format!("g5-gap-{tag}.csv"));
    std::fs::write(&path, kept.join("\n") + "\n").unwrap();
    path
}

/// G5 node b's configuration with a `[verdict]` topic on the broker at `port`, its
/// credentials from the environment.
fn verdict_config(tag: &str, port: u16, topic: &str) -> std::path::PathBuf {
    let path = tmp(&format!("verdict-{tag}.toml"));
    let verdict = format!(
        "\n[verdict]\nservers = [\"tcp://127.0.0.1:{port}\"]\ntopic = \"{topic}\"\n\
         username = \"${{STREAMCERT_TEST_USER}}\"\npassword = \"${{STREAMCERT_TEST_PASSWORD}}\"\n"
    );
    std::fs::write(&path, streamcert_pipeline::config::g5_node_b() + &verdict).unwrap();
    path
}

const SECRET: &str = "s3cret-never-shown";

#[test]
fn the_verdict_topic_carries_each_gate_change_in_order_and_retains_the_last() {
    let topic = "plant/node_b/verdict";
    let (port, rx) = broker_with_subscriber(topic, "interlock");
    let (config, data, ev) = (
        verdict_config("changes", port.port(), topic),
        g5_with_gap("changes"),
        tmp("verdict-ev.csv"),
    );
    let child = bin()
        .args(["certify", "--config", config.to_str().unwrap(), "--input", data.to_str().unwrap()])
        .args(["--output", ev.to_str().unwrap(), "--name", "node_b"])
        .env("STREAMCERT_TEST_USER", "operator")
        .env("STREAMCERT_TEST_PASSWORD", SECRET)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let out = wait_bounded(child, 60, "certify");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(!String::from_utf8_lossy(&out.stderr).contains(SECRET));
    let messages = until(&rx, |m| m["ended"] == true);
    // The evidence rows' changes of the calibrated gate.
    let text = std::fs::read_to_string(&ev).unwrap();
    let mut rows = csv::Reader::from_reader(text.as_bytes());
    let header = rows.headers().unwrap().clone();
    let (ti, gi) = (
        header.iter().position(|h| h == "t").unwrap(),
        header.iter().position(|h| h == "calibrated_open").unwrap(),
    );
    let mut changes = Vec::new();
    let mut was = false;
    for r in rows.records() {
        let r = r.unwrap();
        let open = &r[gi] == "1";
        if open != was {
            changes.push((r[ti].parse::<f64>().unwrap(), open));
        }
        was = open;
    }
    assert!(changes.len() >= 2, "{changes:?}");
    let n = messages.len();
    assert_eq!(messages[0]["sequence"], 0);
    assert_eq!(messages[0]["reason"]["kind"], "starting");
    let middle: Vec<(f64, bool)> = messages[1..n - 1]
        .iter()
        .map(|m| (m["t"].as_f64().unwrap(), m["open"].as_bool().unwrap()))
        .collect();
    assert_eq!(middle, changes);
    for (i, m) in messages.iter().enumerate() {
        assert_eq!(m["schema"], "streamcert.verdict/1");
        assert_eq!(m["sequence"], i);
        assert_eq!(m["name"], "node_b");
        assert!(!m.to_string().contains(SECRET));
    }
    assert_eq!(messages[n - 1]["reason"]["kind"], "stopped");
    // A subscriber that connects afterwards reads the last verdict, retained.
    let late = subscriber(port.port(), topic, "late-interlock");
    let (retained, flag) = late.recv_timeout(Duration::from_secs(10)).unwrap();
    assert!(flag);
    assert_eq!(retained, messages[n - 1]);
}

#[test]
fn a_certifier_killed_leaves_its_offline_will_retained() {
    let topic = "plant/node_b/will";
    let (port, rx) = broker_with_subscriber(topic, "interlock-will");
    let config = verdict_config("will", port.port(), topic);
    let mut child = bin()
        .args(["certify", "--config", config.to_str().unwrap(), "--name", "node_b"])
        .env("STREAMCERT_TEST_USER", "operator")
        .env("STREAMCERT_TEST_PASSWORD", SECRET)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let first = until(&rx, |m| m["sequence"] == 0);
    assert_eq!(first[0]["open"], false);
    child.kill().unwrap();
    child.wait().unwrap();
    let will = until(&rx, |m| m["reason"]["kind"] == "offline");
    let last = will.last().unwrap();
    assert_eq!((last["open"].as_bool(), last["ended"].as_bool()), (Some(false), Some(true)));
    let late = subscriber(port.port(), topic, "late-will");
    let (retained, flag) = late.recv_timeout(Duration::from_secs(10)).unwrap();
    assert!(flag);
    assert_eq!(retained["reason"]["kind"], "offline");
}

#[test]
fn servers_bind_localhost_unless_told_and_a_cluster_refuses_them() {
    let data = bin().args(["simulate", "g5", "--experiment", "2", "--seed", "1"]).output().unwrap();
    let input = tmp("operators-g5.csv");
    std::fs::write(&input, &data.stdout).unwrap();
    let config = tmp("operators-node-b.toml");
    std::fs::write(&config, streamcert_pipeline::config::g5_node_b()).unwrap();
    let out = bin()
        .args(["certify", "--config", config.to_str().unwrap(), "--input", input.to_str().unwrap()])
        .args(["--output", "/dev/null", "--serve", "0", "--metrics", "0"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.lines().any(|l| l.starts_with("status page: http://127.0.0.1:")), "{err}");
    assert!(err.lines().any(|l| l.starts_with("metrics: http://127.0.0.1:")), "{err}");
    let bad = bin()
        .args(["certify", "--config", config.to_str().unwrap(), "--input", input.to_str().unwrap()])
        .args(["--serve", "not-an-address"])
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2), "{}", String::from_utf8_lossy(&bad.stderr));
    let net = tmp("operators-net.toml");
    let example = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/data/g5_network.toml");
    std::fs::copy(example, &net).unwrap();
    let cluster = bin()
        .args(["network", "--config", net.to_str().unwrap(), "--input", input.to_str().unwrap()])
        .args(["--processes", "2", "--process", "0", "--serve", "0"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&cluster.stderr);
    assert_eq!(cluster.status.code(), Some(2), "{err}");
    assert!(err.contains("watch a one-process run"), "{err}");
}
