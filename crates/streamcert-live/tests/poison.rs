//! Messages that must not stall the MQTT source, against a real broker (rumqttd, embedded, on
//! loopback) on a persistent session: a payload far above `max_payload` is read, counted once
//! and acknowledged, with no reconnection; a packet above the client's `max_packet` (which
//! cannot be read, so cannot be acknowledged, and is delivered again at every reconnection)
//! is passed over as a poison message after `POISON_TRIES` failures, with a gap, and every
//! row published after it is certified as the file's.

use std::time::Duration;

use streamcert_live::mqtt::POISON_TRIES;
use streamcert_live::{MqttSource, SourceConfig};
use streamcert_pipeline::certify::{self, Options, Summary};
use streamcert_pipeline::config::{self, Config};

mod support;
use support::{broker, g5};

const G5_B: &str = include_str!("../../../examples/data/g5_node_b.toml");

fn config(source: &str) -> Config {
    config::parse(&format!("{G5_B}\n[source]\n{source}"), "test.toml").unwrap()
}

/// A subscribed source for `cfg`'s `[source]`.
fn source(cfg: &Config) -> MqttSource {
    let parsed = streamcert_live::parse(cfg.source.as_ref().unwrap(), &cfg.columns).unwrap();
    let SourceConfig::Mqtt(mqtt) = parsed else { panic!("an MQTT source") };
    let mut s = MqttSource::new(mqtt, cfg.columns.outputs.len(), false).unwrap();
    assert!(s.wait_subscribed(Duration::from_secs(10)), "not subscribed");
    s
}

/// Publish `first` on `topic` (QoS 1), wait `pause`, then every row of `rows` as JSON; each
/// acknowledged by the broker before this returns.
fn publish(port: u16, topic: &'static str, first: Vec<u8>, pause: Duration, rows: Vec<Vec<u8>>) {
    let payloads = std::iter::once(first).chain(rows).collect();
    support::publish_acked(port, "poison-publisher", topic, payloads, pause);
}

/// The G5 rows as JSON payloads, the file's certify output and summary.
fn rows_and_reference(cfg: &Config, steps: usize) -> (Vec<Vec<u8>>, Vec<u8>, Summary) {
    let (csv, header, rows) = g5(steps);
    let mut want = Vec::new();
    let s = certify::run(cfg, csv.as_bytes(), "g5.csv", &mut want, &Options::default()).unwrap();
    let json = rows
        .iter()
        .map(|r| {
            let pairs: Vec<String> =
                header.iter().zip(r).map(|(h, v)| format!("\"{h}\":{v}")).collect();
            format!("{{{}}}", pairs.join(",")).into_bytes()
        })
        .collect();
    (json, want, s)
}

/// Certify what the source yields until it is idle.
fn live(cfg: &Config, src: &mut MqttSource) -> (Vec<u8>, Summary) {
    let mut out = Vec::new();
    let s = certify::run_source(cfg, src, "mqtt", &mut out, &Options::default()).unwrap();
    (out, s)
}

#[test]
fn a_payload_far_above_max_payload_is_counted_once_and_never_reconnects() {
    let port = broker();
    let cfg = config(&format!(
        "kind = \"mqtt\"\nservers = [\"tcp://127.0.0.1:{port}\"]\nclient_id = \"big\"\n\
         topics = [\"g5/big\"]\nidle_timeout = 2.0\nreconnect_min = 0.05\nreconnect_max = 0.2\n"
    ));
    let (rows, want, want_summary) = rows_and_reference(&cfg, 400);
    let mut src = source(&cfg);
    // 900 KiB: fourteen times max_payload, within the embedded broker's 1 MiB.
    let big = vec![b'['; 900 * 1024];
    let sender = std::thread::spawn(move || publish(port, "g5/big", big, Duration::ZERO, rows));
    let (out, summary) = live(&cfg, &mut src);
    sender.join().unwrap();
    let report = summary.source.clone().unwrap();
    assert_eq!(report.bad, vec![("oversized".to_string(), 1)], "{report:?}");
    assert_eq!((report.reconnect_attempts, report.reconnects), (0, 0), "{report:?}");
    assert_eq!(summary.rows, want_summary.rows);
    assert_eq!(String::from_utf8(out).unwrap(), String::from_utf8(want).unwrap());
}

#[test]
fn a_packet_above_max_packet_is_passed_over_as_poison_and_the_run_goes_on() {
    let port = broker();
    let cfg = config(&format!(
        "kind = \"mqtt\"\nservers = [\"tcp://127.0.0.1:{port}\"]\nclient_id = \"poison\"\n\
         topics = [\"g5/poison\"]\nidle_timeout = 4.0\nmax_payload = 50000\n\
         max_packet = 100000\nreconnect_min = 0.05\nreconnect_max = 0.2\n"
    ));
    let (rows, want, want_summary) = rows_and_reference(&cfg, 400);
    let mut src = source(&cfg);
    // 300 KB: above max_packet, the client cannot read it; the broker delivers it again at
    // every reconnection of the persistent session until the session is discarded.
    let poison = vec![b'x'; 300_000];
    let pause = Duration::from_millis(2500);
    let sender = std::thread::spawn(move || publish(port, "g5/poison", poison, pause, rows));
    let (out, summary) = live(&cfg, &mut src);
    sender.join().unwrap();
    let report = summary.source.clone().unwrap();
    assert_eq!(report.bad, vec![("poison".to_string(), 1)], "{report:?}");
    // One failure per delivery of the poison message, no more.
    assert_eq!(report.reconnect_attempts, u64::from(POISON_TRIES), "{report:?}");
    assert_eq!(report.reconnects, u64::from(POISON_TRIES), "{report:?}");
    assert_eq!(report.gaps, 1, "{report:?}");
    // Every row published after it certified, as the file's.
    assert_eq!(summary.rows, want_summary.rows);
    assert_eq!(String::from_utf8(out).unwrap(), String::from_utf8(want).unwrap());
}
