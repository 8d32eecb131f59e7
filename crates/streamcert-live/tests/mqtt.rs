//! The MQTT source against a real broker (rumqttd, embedded, on loopback): the rows a live
//! run certifies are the CSV file's to the bit; per-signal topics are aligned as the batch
//! oracle says; every bad payload is counted and named and never reaches the certifier; a
//! broker that goes away is reconnected and the run goes on.

use std::time::Duration;

use streamcert_live::publish::{self, Layout, PublishOptions};
use streamcert_live::{AlignRule, MqttSource, SourceConfig};
use streamcert_pipeline::certify::{self, Options, Summary};
use streamcert_pipeline::config::{self, Config};
use streamcert_pipeline::source::Source;

mod support;
use support::{Item, Relay, Update, broker, g5, oracle};

const G5_B: &str = include_str!("../../../examples/data/g5_node_b.toml");

/// The node-b configuration with this `[source]` section.
fn config(source: &str) -> Config {
    config::parse(&format!("{G5_B}\n[source]\n{source}"), "test.toml").unwrap()
}

/// The certify output and summary of a CSV text.
fn file_run(cfg: &Config, csv: &str) -> (Vec<u8>, Summary) {
    let mut out = Vec::new();
    let s = certify::run(cfg, csv.as_bytes(), "g5.csv", &mut out, &Options::default()).unwrap();
    (out, s)
}

/// A subscribed source for `cfg`'s `[source]`.
fn source(cfg: &Config) -> MqttSource {
    let parsed = streamcert_live::parse(cfg.source.as_ref().unwrap(), &cfg.columns).unwrap();
    let SourceConfig::Mqtt(mqtt) = parsed else { panic!("an MQTT source") };
    let mut s = MqttSource::new(mqtt, cfg.columns.outputs.len(), false).unwrap();
    assert!(s.wait_subscribed(Duration::from_secs(10)), "not subscribed");
    s
}

/// Certify what `source` yields until it is idle.
fn live_run(cfg: &Config, source: &mut dyn Source) -> (Vec<u8>, Summary) {
    let mut out = Vec::new();
    let s = certify::run_source(cfg, source, "mqtt", &mut out, &Options::default()).unwrap();
    (out, s)
}

fn publisher(port: u16, topic: &str, id: &str, layout: Layout) -> PublishOptions {
    let server = streamcert_live::config::Server { host: "127.0.0.1".into(), port, tls: false };
    PublishOptions { server, topic: topic.into(), client_id: id.into(), layout, pace: 0.0 }
}

#[test]
fn a_row_per_message_certifies_the_files_rows_bit_for_bit() {
    let port = broker();
    let (csv, header, rows) = g5(3000);
    let source_text = format!(
        "kind = \"mqtt\"\nservers = [\"tcp://127.0.0.1:{port}\"]\nclient_id = \"rows\"\n\
         topics = [\"g5/rows\"]\nidle_timeout = 2.0\n"
    );
    let cfg = config(&source_text);
    let (want, want_summary) = file_run(&cfg, &csv);
    let mut src = source(&cfg);
    let opts = publisher(port, "g5/rows", "pub-rows", Layout::Rows);
    let sender = std::thread::spawn(move || publish::publish(&opts, &header, 0, rows).unwrap());
    let (got, summary) = live_run(&cfg, &mut src);
    assert_eq!(sender.join().unwrap(), 3001);
    assert_eq!(String::from_utf8(got).unwrap(), String::from_utf8(want).unwrap());
    assert_eq!(summary.rows, want_summary.rows);
    assert_eq!(summary.first_deploy_calibrated, want_summary.first_deploy_calibrated);
    let report = summary.source.unwrap();
    assert_eq!((report.messages, report.rows, report.bad_total()), (3001, 3001, 0));
}

/// Good rows with every kind of bad payload between them, in `format`.
fn bad_payload_run(format: &str, bad: &[(&str, Vec<u8>)]) {
    let port = broker();
    let (csv, header, rows) = g5(400);
    let source_text = format!(
        "kind = \"mqtt\"\nservers = [\"tcp://127.0.0.1:{port}\"]\nclient_id = \"bad-{format}\"\n\
         topics = [\"g5/rows\"]\nidle_timeout = 1.5\ndata_format = \"{format}\"\n\
         csv_columns = {header:?}\n"
    );
    let cfg = config(&source_text);
    let (_, want) = file_run(&cfg, &csv);
    let mut src = source(&cfg);
    // Row k as the format writes it.
    let encode = |row: &[f64]| -> Vec<u8> {
        let fields: Vec<String> = row.iter().map(f64::to_string).collect();
        if format == "csv" {
            fields.join(",").into_bytes()
        } else {
            let pairs: Vec<String> =
                header.iter().zip(&fields).map(|(h, v)| format!("\"{h}\":{v}")).collect();
            format!("{{{}}}", pairs.join(",")).into_bytes()
        }
    };
    let mut payloads: Vec<Vec<u8>> = rows.iter().map(|r| encode(r)).collect();
    // Every bad payload after row 200, in order.
    for (i, (_, p)) in bad.iter().enumerate() {
        payloads.insert(201 + i, p.clone());
    }
    let client = rumqttc_client(port);
    let sender = std::thread::spawn(move || client(payloads));
    let (out, summary) = live_run(&cfg, &mut src);
    sender.join().unwrap();
    let report = summary.source.clone().unwrap();
    for (kind, _) in bad {
        let n = report.bad.iter().find(|(k, _)| k == kind).map_or(0, |(_, n)| *n);
        assert_eq!(n, bad.iter().filter(|(k, _)| k == kind).count() as u64, "{kind}: {report:?}");
    }
    assert_eq!(report.bad_total(), bad.len() as u64);
    // Never a number the certifier sees: every good row, and only they, certified.
    assert_eq!((summary.rows, summary.skipped), (want.rows, bad.len() as u64));
    let times: Vec<f64> = String::from_utf8(out)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    let expected: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(times, expected);
}

/// A publisher of raw payloads on `g5/rows` (QoS 1, all acknowledged before it returns).
fn rumqttc_client(port: u16) -> impl FnOnce(Vec<Vec<u8>>) + Send {
    move |payloads| support::publish_acked(port, "raw", "g5/rows", payloads, Duration::ZERO)
}

#[test]
fn every_bad_json_payload_is_counted_named_and_never_certified() {
    let bad = [
        ("oversized", format!("{{\"pad\":\"{}\"}}", "x".repeat(70_000)).into_bytes()),
        ("not_utf8", vec![0xff, 0xfe, 0x00]),
        ("not_json", b"{\"t\": 1,".to_vec()),
        ("not_json", b"[1, 2, 3]".to_vec()),
        ("missing_field", br#"{"t": 99.0, "y_b": 1.0}"#.to_vec()),
        ("not_a_number", br#"{"t": 99.0, "y_b": "1.0", "u_b": 0.0}"#.to_vec()),
        ("not_a_number", br#"{"t": 99.0, "y_b": null, "u_b": 0.0}"#.to_vec()),
        ("time_backwards", br#"{"t": 0.5, "y_b": 1.0, "u_b": 0.0}"#.to_vec()),
    ];
    bad_payload_run("json", &bad);
}

#[test]
fn every_bad_csv_payload_is_counted_named_and_never_certified() {
    let twelve = |v: &str| {
        let mut f = ["99"; 12];
        f[3] = v;
        f.join(",").into_bytes()
    };
    let bad = [
        ("wrong_field_count", b"1.0,2.0".to_vec()),
        ("not_a_number", twelve("abc")),
        ("not_finite", twelve("NaN")),
        ("not_finite", twelve("-inf")),
        ("time_backwards", {
            let mut f = ["0.5"; 12];
            f[0] = "0.25";
            f.join(",").into_bytes()
        }),
    ];
    bad_payload_run("csv", &bad);
}

#[test]
fn signals_on_their_own_topics_are_aligned_as_the_oracle_says() {
    let port = broker();
    let (_, header, rows) = g5(2500);
    // Node b's output and input on a topic each, every 20 ms of data, on a grid of 20 ms.
    // A broker orders messages within a topic, not across topics (rumqttd hands a subscriber
    // each topic's backlog in turn): published at a quarter of real time, the two topics
    // stay well within the reorder window of 0.3 s.
    let rule = AlignRule { period: 0.02, max_age: 0.02, reorder_window: 0.3 };
    let source_text = format!(
        "kind = \"mqtt\"\nservers = [\"tcp://127.0.0.1:{port}\"]\nclient_id = \"signals\"\n\
         idle_timeout = 2.0\n[source.align]\nperiod = {}\nmax_age = {}\nreorder_window = {}\n\
         [[source.signal]]\ncolumn = \"y_b\"\ntopic = \"g5/sig/y_b\"\n\
         [[source.signal]]\ncolumn = \"u_b\"\ntopic = \"g5/sig/u_b\"\n",
        rule.period, rule.max_age, rule.reorder_window
    );
    let cfg = config(&source_text);
    let mut src = source(&cfg);
    // Only t, y_b and u_b are published (on g5/sig/y_b and g5/sig/u_b).
    let cols = ["t", "y_b", "u_b"].map(String::from).to_vec();
    let idx: Vec<usize> =
        cols.iter().map(|c| header.iter().position(|h| h == c).unwrap()).collect();
    let picked: Vec<Vec<f64>> = rows.iter().map(|r| idx.iter().map(|&i| r[i]).collect()).collect();
    let updates: Vec<Update> = picked
        .iter()
        .flat_map(|r| {
            [Update { signal: 0, t: r[0], v: r[1] }, Update { signal: 1, t: r[0], v: r[2] }]
        })
        .collect();
    let opts =
        PublishOptions { pace: 0.25, ..publisher(port, "g5/sig", "pub-signals", Layout::Signals) };
    let sender = std::thread::spawn(move || publish::publish(&opts, &cols, 0, picked).unwrap());
    let (got, summary) = live_run(&cfg, &mut src);
    sender.join().unwrap();
    let report = summary.source.clone().unwrap();
    // Within the reorder window nothing is late, so the oracle's order is immaterial.
    assert_eq!(report.late, 0);
    let (items, _, stale) = oracle(2, rule, &updates);
    assert_eq!(report.stale_rows, stale);
    let mut csv = String::from("t,y_b,u_b\n");
    let mut formed = 0;
    for item in &items {
        if let Item::Row(t, v) = item {
            csv.push_str(&format!("{t},{},{}\n", v[0], v[1]));
            formed += 1;
        }
    }
    assert!(formed > 1000, "{formed} rows");
    assert_eq!(report.rows, formed);
    let (want, _) = file_run(&cfg, &csv);
    assert_eq!(String::from_utf8(got).unwrap(), String::from_utf8(want).unwrap());
}

#[test]
fn a_broker_that_goes_away_is_reconnected_and_the_run_goes_on() {
    let port = broker();
    let relay = Relay::new(port);
    let (csv, header, rows) = g5(3000);
    let source_text = format!(
        "kind = \"mqtt\"\nservers = [\"tcp://127.0.0.1:{}\"]\nclient_id = \"outage\"\n\
         topics = [\"g5/rows\"]\nidle_timeout = 3.0\nreconnect_min = 0.05\nreconnect_max = 0.2\n",
        relay.port
    );
    let cfg = config(&source_text);
    let (want, _) = file_run(&cfg, &csv);
    let mut src = source(&cfg);
    let opts = publisher(port, "g5/rows", "pub-outage", Layout::Rows);
    let sender = std::thread::spawn(move || {
        let (a, rest) = rows.split_at(1000);
        let (b, c) = rest.split_at(1000);
        let part =
            |id: &str| PublishOptions { client_id: format!("pub-outage-{id}"), ..opts.clone() };
        publish::publish(&part("a"), &header, 0, a.to_vec()).unwrap();
        std::thread::sleep(Duration::from_millis(500));
        // The outage: the relay refuses connections while the plant keeps publishing.
        let cut = std::thread::spawn(move || relay.cut(Duration::from_secs(1)));
        std::thread::sleep(Duration::from_millis(100));
        publish::publish(&part("b"), &header, 0, b.to_vec()).unwrap();
        cut.join().unwrap();
        publish::publish(&part("c"), &header, 0, c.to_vec()).unwrap();
    });
    let (got, summary) = live_run(&cfg, &mut src);
    sender.join().unwrap();
    let report = summary.source.clone().unwrap();
    eprintln!("{}", report.line());
    assert!(report.reconnects >= 1, "{report:?}");
    let got = String::from_utf8(got).unwrap();
    let want = String::from_utf8(want).unwrap();
    if report.gaps == 0 {
        // The broker kept the session: what was published during the outage was delivered
        // on reconnection, and the run is the file's.
        assert_eq!(got, want);
    } else {
        // It did not: a gap, and every row published before and after the outage certified.
        let times: Vec<&str> = got.lines().skip(1).map(|l| l.split(',').next().unwrap()).collect();
        let wanted: Vec<&str> =
            want.lines().skip(1).map(|l| l.split(',').next().unwrap()).collect();
        for t in wanted[..1000].iter().chain(&wanted[2000..]) {
            assert!(times.contains(t), "row {t} missing");
        }
        assert!(summary.gaps >= 1);
    }
}

#[test]
fn a_topic_that_delivers_nothing_is_named() {
    let port = broker();
    let (_, header, rows) = g5(200);
    let source_text = format!(
        "kind = \"mqtt\"\nservers = [\"tcp://127.0.0.1:{port}\"]\nclient_id = \"silent\"\n\
         topics = [\"g5/live\", \"g5/dead\"]\nidle_timeout = 1.5\nsilent_after = 0.5\n"
    );
    let cfg = config(&source_text);
    let mut src = source(&cfg);
    let opts = publisher(port, "g5/live", "pub-silent", Layout::Rows);
    publish::publish(&opts, &header, 0, rows).unwrap();
    let (_, summary) = live_run(&cfg, &mut src);
    let report = summary.source.unwrap();
    assert_eq!(report.rows, 201);
    assert_eq!(report.silent, vec!["g5/dead".to_string()]);
    assert!(report.line().contains("silent: g5/dead"), "{}", report.line());
}

#[test]
fn the_idle_timeout_counts_from_the_subscription_not_from_the_opening() {
    let port = broker();
    let (_, header, rows) = g5(100);
    let cfg = config(&format!(
        "kind = \"mqtt\"\nservers = [\"tcp://127.0.0.1:{port}\"]\nclient_id = \"late-start\"\n\
         topics = [\"g5/late\"]\nidle_timeout = 0.5\n"
    ));
    let parsed = streamcert_live::parse(cfg.source.as_ref().unwrap(), &cfg.columns).unwrap();
    let SourceConfig::Mqtt(mqtt) = parsed else { panic!("an MQTT source") };
    let mut src = MqttSource::new(mqtt, 1, false).unwrap();
    // Opened, then left longer than the idle timeout before it is read (a site's source
    // waits for its peers): it still subscribes and takes what is published next.
    std::thread::sleep(Duration::from_millis(1000));
    let opts = publisher(port, "g5/late", "pub-late", Layout::Rows);
    let sender = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(300));
        publish::publish(&opts, &header, 0, rows).unwrap()
    });
    let (_, summary) = live_run(&cfg, &mut src);
    assert_eq!(sender.join().unwrap(), 101);
    assert_eq!(summary.rows, 101);
}
