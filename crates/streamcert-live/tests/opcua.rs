//! The OPC UA source against a real server (async-opcua's own, serving a simulated G5 node on
//! loopback): the rows a live run certifies are those of the same samples written to a CSV
//! file, to the bit, with security None and with Basic256Sha256 SignAndEncrypt; every bad
//! value is counted and named and never reaches the certifier; a server restarted mid-run is
//! a gap, and the run goes on.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use opcua::types::{DataValue, DateTime, StatusCode, Variant};
use streamcert_live::SourceConfig;
use streamcert_live::opcua::server::PlantServer;
use streamcert_live::opcua::{self as live_opcua, OpcUaSource};
use streamcert_pipeline::certify::{self, Options, Summary};
use streamcert_pipeline::config::{self, Config};

mod support;

const G5_B: &str = include_str!("../../../examples/data/g5_node_b.toml");
/// The simulation's step (and the grid's period).
const T: f64 = 0.02;
/// The reorder window, seconds of source time: the tests write a sample per millisecond
/// (20 times real time), so a publication (every 20 ms) spans about 0.4 s of source time,
/// which a server may split over messages.
const WINDOW: f64 = 2.0;

/// `steps + 1` samples `(t, y_b, u_b)` of G5 (experiment 1, seed 3).
fn g5(steps: usize) -> Vec<[f64; 3]> {
    let (_, header, rows) = support::g5(steps);
    let at = |name: &str| header.iter().position(|h| h == name).unwrap();
    let (t, y, u) = (at("t"), at("y_b"), at("u_b"));
    rows.iter().map(|v| [v[t], v[y], v[u]]).collect()
}

/// The samples as a CSV file whose times are the grid's, `k·T` (the rows a live run forms).
fn csv(samples: &[[f64; 3]]) -> String {
    let mut text = String::from("t,y_b,u_b\n");
    for (k, s) in samples.iter().enumerate() {
        text.push_str(&format!("{},{},{}\n", k as f64 * T, s[1], s[2]));
    }
    text
}

/// A fresh directory under the target's temporary space.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("streamcert-opcua-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn loopback() -> SocketAddr {
    "127.0.0.1:0".parse().unwrap()
}

/// The node-b configuration reading `server`'s nodes with these extra `[source]` keys.
fn config(server: &PlantServer, extra: &str) -> Config {
    config_with(server, extra, 0.02, WINDOW)
}

/// [`config`] with this publishing interval (seconds) and reorder window (of source time).
/// The client's PKI directory is a scratch one of the server's port unless `extra` names one.
fn config_with(server: &PlantServer, extra: &str, publishing: f64, window: f64) -> Config {
    let ids = server.node_ids();
    let endpoint = server.endpoint();
    let port = endpoint.trim_end_matches('/').rsplit(':').next().unwrap_or_default();
    let pki = scratch(&format!("client-pki-{port}")).display().to_string();
    let extra = if extra.contains("pki_dir") {
        extra.to_string()
    } else {
        format!("pki_dir = {pki:?}\n{extra}")
    };
    let text = format!(
        "{G5_B}\n[source]\nkind = \"opcua\"\nendpoint = \"{}\"\nqueue_size = 100000\n\
         publishing_interval = {publishing}\n{extra}\n\
         [[source.node]]\ncolumn = \"y_b\"\nnode_id = \"{}\"\n\
         [[source.node]]\ncolumn = \"u_b\"\nnode_id = \"{}\"\n\
         [source.align]\nperiod = {T}\nmax_age = {}\nreorder_window = {window}\n",
        server.endpoint(),
        ids[0],
        ids[1],
        2.0 * T,
    );
    config::parse(&text, "opcua.toml").unwrap()
}

/// A subscribed source for `cfg`'s `[source]`.
fn source(cfg: &Config) -> OpcUaSource {
    let parsed = streamcert_live::parse(cfg.source.as_ref().unwrap(), &cfg.columns).unwrap();
    let SourceConfig::OpcUa(c) = parsed else { panic!("an OPC UA source") };
    let mut s = OpcUaSource::new(c, 1).unwrap();
    assert!(s.wait_subscribed(Duration::from_secs(20)).unwrap(), "not subscribed");
    s
}

fn file_run(cfg: &Config, csv: &str) -> (String, Summary) {
    let mut out = Vec::new();
    let s = certify::run(cfg, csv.as_bytes(), "g5.csv", &mut out, &Options::default()).unwrap();
    (String::from_utf8(out).unwrap(), s)
}

fn live_run(cfg: &Config, source: &mut OpcUaSource) -> (String, Summary) {
    let mut out = Vec::new();
    let s = certify::run_source(cfg, source, "opcua", &mut out, &Options::default()).unwrap();
    (String::from_utf8(out).unwrap(), s)
}

/// Write `samples` to the server, one per millisecond (the server's queues hold them between
/// two publications).
fn publish(server: &PlantServer, samples: &[[f64; 3]]) {
    publish_every(server, samples, Duration::from_millis(1));
}

/// Write `samples` to the server, one per `pace`.
fn publish_every(server: &PlantServer, samples: &[[f64; 3]], pace: Duration) {
    for s in samples {
        server.publish(s[0], &s[1..]).unwrap();
        std::thread::sleep(pace);
    }
}

/// Publish `samples`, one per `pace`, and compare the live run with the file's: every row
/// decided (all but the last reorder window's, which wait for later samples) is the file's,
/// to the bit.
fn bit_for_bit(server: &PlantServer, cfg: &Config, samples: &[[f64; 3]], pace: Duration) {
    assert!(!server.monitored(), "monitored before any client subscribed");
    let mut src = source(cfg);
    assert!(server.monitored(), "the client subscribed, yet no node is monitored");
    let (got, summary) = std::thread::scope(|scope| {
        scope.spawn(|| publish_every(server, samples, pace));
        live_run(cfg, &mut src)
    });
    let decided = usize::try_from(summary.rows).unwrap();
    let undecided = (WINDOW / T) as usize + 1;
    assert!(
        decided + undecided >= samples.len(),
        "{decided} of {} rows: {:?}",
        samples.len(),
        summary.source.as_ref().map(|r| (r.messages, r.late, r.stale_rows, r.gaps))
    );
    let (want, want_summary) = file_run(cfg, &csv(&samples[..decided]));
    assert_eq!(got, want);
    assert_eq!(summary.rows, want_summary.rows);
    assert_eq!(summary.first_deploy_calibrated, want_summary.first_deploy_calibrated);
    let report = summary.source.unwrap();
    assert_eq!((report.bad_total(), report.gaps, report.late), (0, 0, 0), "{report:?}");
}

#[test]
fn nodes_certify_the_files_samples_bit_for_bit() {
    let server =
        PlantServer::start(loopback(), &["y_b".into(), "u_b".into()], &scratch("none")).unwrap();
    let cfg = config(&server, "idle_timeout = 2.0");
    bit_for_bit(&server, &cfg, &g5(2500), Duration::from_millis(1));
}

#[test]
fn a_publication_reaches_the_rows_in_order_of_source_time() {
    let server =
        PlantServer::start(loopback(), &["y_b".into(), "u_b".into()], &scratch("order")).unwrap();
    // A sample a millisecond, a publication every 0.2 s: about 200 samples (4 s of source
    // time) a publication, listed node by node, against a reorder window of 0.2 s of source
    // time. Handed on as listed, most of u_b's values would be late; in time order none is.
    let cfg = config_with(&server, "idle_timeout = 2.0", 0.2, 0.2);
    bit_for_bit(&server, &cfg, &g5(1500), Duration::from_millis(1));
}

#[test]
fn sign_and_encrypt_with_certificate_files_certifies_the_same_rows() {
    let dir = scratch("secure");
    let server_pki = dir.join("server-pki");
    let server =
        PlantServer::start(loopback(), &["y_b".into(), "u_b".into()], &server_pki).unwrap();
    let (cert, key) = (dir.join("client.der"), dir.join("client.pem"));
    live_opcua::create_client_certificate(&cert, &key).unwrap();
    let client_pki = dir.join("client-pki");
    let secure = format!(
        "security_policy = \"Basic256Sha256\"\nsecurity_mode = \"SignAndEncrypt\"\n\
         certificate = {:?}\nprivate_key = {:?}\npki_dir = {:?}\n",
        cert.display().to_string(),
        key.display().to_string(),
        client_pki.display().to_string()
    );
    let cfg = config(&server, &format!("{secure}idle_timeout = 2.0"));
    // Without the server's certificate in the client's trusted/ directory: refused, said.
    let parsed = streamcert_live::parse(cfg.source.as_ref().unwrap(), &cfg.columns).unwrap();
    let SourceConfig::OpcUa(c) = parsed else { panic!("an OPC UA source") };
    let mut untrusted = OpcUaSource::new(c, 1).unwrap();
    let e = untrusted.wait_subscribed(Duration::from_secs(20)).unwrap_err().to_string();
    assert!(e.contains("trusted"), "{e}");
    drop(untrusted);
    live_opcua::trust_server_certificate(&client_pki, &server_pki.join("own/cert.der")).unwrap();
    // Four milliseconds a sample (5 times real time): the reorder window, 2 s of source
    // time, then spans 400 ms of wall time, so that the encryption's latency on a loaded
    // machine (five servers and clients on two cores) does not make a publication late (at
    // one millisecond a sample, 7 of 1 604 messages arrived late in about one run of eight,
    // and were counted late, not certified, as the source's rules say).
    bit_for_bit(&server, &cfg, &g5(800), Duration::from_millis(4));
}

#[test]
fn every_bad_value_is_counted_named_and_never_certified() {
    let server =
        PlantServer::start(loopback(), &["y_b".into(), "u_b".into()], &scratch("bad")).unwrap();
    let cfg = config(&server, "idle_timeout = 2.0");
    let samples = g5(400);
    let mut src = source(&cfg);
    let stamp = |t: f64| Some(DateTime::from(live_opcua::ticks(t)));
    let good = |t: f64, v: f64| DataValue {
        value: Some(Variant::Double(v)),
        status: Some(StatusCode::Good),
        source_timestamp: stamp(t),
        ..DataValue::null()
    };
    // Between samples 200 and 201, each kind of bad value on y_b (u_b's value good).
    let bad = [
        (
            "bad_status",
            DataValue { status: Some(StatusCode::BadSensorFailure), ..good(4.001, 1.0) },
        ),
        ("not_a_number", DataValue { value: Some(Variant::from("1.0")), ..good(4.002, 0.0) }),
        ("not_finite", good(4.003, f64::NAN)),
        ("not_finite", good(4.004, f64::INFINITY)),
        ("missing_field", DataValue { source_timestamp: None, ..good(4.005, 1.0) }),
        ("missing_field", DataValue { value: None, ..good(4.006, 1.0) }),
    ];
    let (got, summary) = std::thread::scope(|scope| {
        scope.spawn(|| {
            publish(&server, &samples[..=200]);
            for (j, (_, dv)) in bad.iter().enumerate() {
                let t = 4.001 + j as f64 * 0.001;
                server.write([dv.clone(), good(t, 0.5)].into_iter()).unwrap();
            }
            publish(&server, &samples[201..]);
        });
        live_run(&cfg, &mut src)
    });
    let report = summary.source.clone().unwrap();
    for (kind, _) in &bad {
        let n = report.bad.iter().find(|(k, _)| k == kind).map_or(0, |(_, n)| *n);
        assert_eq!(n, bad.iter().filter(|(k, _)| k == kind).count() as u64, "{kind}: {report:?}");
    }
    assert_eq!(report.bad_total(), bad.len() as u64);
    // Never a number the certifier sees: no bad value in any row, and every sample's row
    // formed (u_b's good values at 4.00x are held over by the next grid point, 4.02).
    assert_eq!(summary.skipped, bad.len() as u64);
    assert!(!got.contains("NaN") && !got.contains("inf"), "a bad value reached a row");
    let times: Vec<f64> =
        got.lines().skip(1).map(|l| l.split(',').next().unwrap().parse().unwrap()).collect();
    let expected: Vec<f64> = (0..times.len()).map(|k| k as f64 * T).collect();
    assert_eq!(times, expected);
    assert!(times.len() + (WINDOW / T) as usize + 1 >= samples.len(), "{} rows", times.len());
}

#[test]
fn a_server_restarted_mid_run_is_a_gap_and_the_run_goes_on() {
    let pki = scratch("restart");
    let columns = ["y_b".to_string(), "u_b".to_string()];
    let server = PlantServer::start(loopback(), &columns, &pki).unwrap();
    let addr: SocketAddr =
        server.endpoint()["opc.tcp://".len()..].trim_end_matches('/').parse().unwrap();
    let cfg = config(&server, "reconnect_min = 0.05\nreconnect_max = 0.2\nidle_timeout = 4.0\n");
    let samples = g5(2000);
    let mut src = source(&cfg);
    let (samples, columns, pki) = (&samples, &columns, &pki);
    let (got, summary) = std::thread::scope(|scope| {
        let plant = scope.spawn(move || {
            publish(&server, &samples[..1000]);
            std::thread::sleep(Duration::from_millis(300));
            server.stop();
            std::thread::sleep(Duration::from_millis(500));
            let again = PlantServer::start(addr, columns, pki).unwrap();
            // The client reconnects and subscribes again before the plant goes on.
            std::thread::sleep(Duration::from_millis(2500));
            publish(&again, &samples[1000..]);
            again
        });
        let run = live_run(&cfg, &mut src);
        // The restarted server serves until the run has ended.
        drop(plant.join().unwrap());
        run
    });
    let report = summary.source.clone().unwrap();
    assert!(report.reconnects >= 1 && report.gaps >= 1, "{report:?}");
    assert!(summary.gaps >= 1, "{} rows, {report:?}", summary.rows);
    // Every sample published before and after the outage is certified (the last of each
    // stretch waits for a next sample on the grid, so it may be absent).
    let times: Vec<f64> =
        got.lines().skip(1).map(|l| l.split(',').next().unwrap().parse().unwrap()).collect();
    let last = 2000 - (WINDOW / T) as usize - 1;
    for k in (0..999).chain(1000..last) {
        let t = k as f64 * T;
        assert!(times.contains(&t), "row {t} missing");
    }
}

#[test]
fn a_node_that_delivers_nothing_is_named() {
    let server =
        PlantServer::start(loopback(), &["y_b".into(), "u_b".into()], &scratch("silent")).unwrap();
    let cfg = config(&server, "silent_after = 0.5\nidle_timeout = 1.5\n");
    let mut src = source(&cfg);
    let (_, summary) = std::thread::scope(|scope| {
        scope.spawn(|| {
            // Only y_b's node is written: u_b's says it is waiting for its first value.
            for k in 0..50 {
                let t = k as f64 * T;
                let dv = DataValue {
                    value: Some(Variant::Double(1.0)),
                    status: Some(StatusCode::Good),
                    source_timestamp: Some(DateTime::from(live_opcua::ticks(t))),
                    ..DataValue::null()
                };
                server.write([dv].into_iter()).unwrap();
            }
        });
        live_run(&cfg, &mut src)
    });
    let report = summary.source.unwrap();
    assert_eq!(report.rows, 0);
    assert_eq!(report.silent, vec![server.node_ids()[1].clone()]);
}

/// A server's source timestamps are Unix seconds: the verdict line reads the gate's opening
/// as an instant in ISO 8601 UTC to the millisecond (the summary's JSON keeps the seconds),
/// never as `t = 1.79648e+9`.
#[test]
fn a_verdict_on_unix_source_times_reads_its_opening_in_utc() {
    // 2026-12-05T14:13:20Z.
    const START: f64 = 1_796_480_000.0;
    let server =
        PlantServer::start(loopback(), &["y_b".into(), "u_b".into()], &scratch("utc")).unwrap();
    let cfg = config(&server, "idle_timeout = 2.0");
    let samples: Vec<[f64; 3]> = g5(1500).into_iter().map(|s| [START + s[0], s[1], s[2]]).collect();
    let mut src = source(&cfg);
    let (_, summary) = std::thread::scope(|scope| {
        scope.spawn(|| publish(&server, &samples));
        live_run(&cfg, &mut src)
    });
    let since = summary.calibrated_since.expect("G5's node b certifies within 30 s");
    let verdict = summary.verdict_line(&cfg.certifier, &cfg.columns.outputs);
    // The instant by hand: the run's 30 s fall within the hour that starts 13 min 20 s before.
    let ms = ((since - START) * 1000.0).round() as u64 + 20_000;
    assert!(ms < 46 * 60_000, "opened {} s into the run", since - START);
    let instant =
        format!("2026-12-05T14:{:02}:{:02}.{:03}Z", 13 + ms / 60_000, ms / 1000 % 60, ms % 1000);
    assert!(verdict.contains(&format!("from {instant} to the end")), "{instant}: {verdict}");
    assert!(!verdict.contains("e+9") && !verdict.contains("t = 1"), "{verdict}");
    let json = summary.json(&cfg.certifier, &cfg.columns.outputs);
    let seconds = json["calibrated_since"].as_f64().or_else(|| json["since"].as_f64());
    assert_eq!(seconds, Some(since), "the JSON keeps the seconds: {json}");
}
