//! The server during a run: the metrics and the status document scraped between two rows
//! equal the evidence rows written so far; the verdict messages are the evidence's gate
//! changes; bad requests get their status codes and the run goes on; a hundred clients are
//! served while it runs.

mod support;

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use streamcert_serve::{Monitor, MonitorOptions, Server, VerdictMessage};

use support::{evidence, g5_rows, get, node_b, parse, raw, request, run_paused, started, value};

/// G5 node b's configuration, a monitor named `name` serving on a free port, and its
/// certify watcher (no verdict sink).
fn served(
    name: &str,
) -> (streamcert_pipeline::config::Config, Monitor, Server, streamcert_serve::CertifyWatch) {
    let cfg = node_b();
    let (monitor, server) = started(name);
    let watch = monitor.certify(&cfg.certifier, &cfg.columns.outputs, Vec::new());
    (cfg, monitor, server, watch)
}

/// The series docs/operations.md documents for runs of `kind` (`certify` or `network`).
fn documented(kind: &str) -> Vec<String> {
    let doc = std::fs::read_to_string(support::example("../../docs/operations.md")).unwrap();
    let rows: Vec<String> = doc
        .lines()
        .filter(|l| l.starts_with("| `streamcert_"))
        .filter(|l| l.split('|').nth(4).is_some_and(|r| r.contains(kind) || r.contains("both")))
        .map(|l| l.split('`').nth(1).unwrap().to_string())
        .collect();
    assert!(rows.len() >= 10, "the metrics table of docs/operations.md: {rows:?}");
    rows
}

fn field(row: &HashMap<String, String>, c: &str) -> f64 {
    row[c].parse().unwrap_or(f64::NAN)
}

/// Where the gate `column` of `rows` changed: `(t, open)`, from a closed start.
fn gate_changes(rows: &[HashMap<String, String>], column: &str) -> Vec<(f64, bool)> {
    let mut was = false;
    let mut changes = Vec::new();
    for row in rows {
        let open = field(row, column) == 1.0;
        if open != was {
            changes.push((field(row, "t"), open));
        }
        was = open;
    }
    changes
}

#[test]
fn metrics_scraped_between_rows_equal_the_evidence_rows_so_far() {
    let (cfg, _monitor, server, mut watch) = served("node_b");
    let addr = server.addr();
    let mut scrapes = Vec::new();
    let out = run_paused(&cfg, &g5_rows(None), &mut watch, |k| {
        if k > 0 && k % 37 == 0 {
            scrapes.push((k, get(addr, "/metrics")));
        }
    });
    let ev = evidence(&out);
    let names = documented("certify");
    let mut opened = 0;
    for (k, r) in &scrapes {
        assert_eq!(r.status, 200);
        // The text format 0.0.4, as promtool reads it: a counter family by its `_total` name.
        assert!(r.headers.contains("content-type: text/plain; version=0.0.4"), "{}", r.headers);
        assert!(!r.body.contains("# EOF"));
        for family in r.body.lines().filter_map(|l| l.strip_prefix("# TYPE ")) {
            let (name, kind) = family.split_once(' ').unwrap();
            assert!(kind != "counter" || name.ends_with("_total"), "{family}");
            let help = format!("# HELP {name} ");
            assert!(r.body.contains(&help), "no help text for {name}");
        }
        let seen: Vec<&str> = r.body.lines().filter(|l| !l.starts_with('#')).collect();
        for name in &names {
            assert!(seen.iter().any(|l| l.starts_with(name.as_str())), "no {name} in\n{}", r.body);
        }
        let m = parse(&r.body);
        let row = &ev[*k as usize - 1];
        let lp = [("loop", "node_b")];
        assert_eq!(value(&m, "streamcert_samples_total", &lp), *k as f64);
        for (kind, gate, cert) in [
            ("calibrated", "calibrated_open", "cert_calibrated"),
            ("gaussian", "gauss_open", "cert_gauss"),
            ("wasserstein", "wass_open", "cert_wass"),
        ] {
            let l = [("loop", "node_b"), ("certificate", kind)];
            assert_eq!(value(&m, "streamcert_gate_open", &l), field(row, gate), "row {k} {kind}");
            let (got, want) =
                (value(&m, "streamcert_certificate_per_second", &l), field(row, cert));
            assert!(got == want || (got.is_nan() && want.is_nan()), "row {k} {kind}: {got} {want}");
            // The state set: exactly one reason at 1, `none` exactly when the gate is open.
            let states: Vec<(String, f64)> = m
                .iter()
                .filter(|((n, ls), _)| {
                    n == "streamcert_gate_reason"
                        && ls.contains(&("certificate".into(), kind.into()))
                })
                .map(|((_, ls), v)| (ls.iter().find(|(k, _)| k == "reason").unwrap().1.clone(), *v))
                .collect();
            assert!(states.len() > 10);
            let on: Vec<&String> =
                states.iter().filter(|(_, v)| *v == 1.0).map(|(r, _)| r).collect();
            assert_eq!(on.len(), 1, "{states:?}");
            assert_eq!(on[0] == "none", field(row, gate) == 1.0);
        }
        assert_eq!(value(&m, "streamcert_last_sample_time_seconds", &lp), field(row, "t"));
        assert_eq!(value(&m, "streamcert_margin_per_second", &lp), cfg.certifier.margin);
        opened += usize::from(field(row, "calibrated_open") == 1.0);
    }
    assert!(scrapes.len() > 15 && opened > 3, "{} scrapes, {opened} open", scrapes.len());
}

#[test]
fn the_status_document_between_rows_is_the_evidence_so_far() {
    let (cfg, monitor, server, mut watch) = served("node_b");
    let addr = server.addr();
    let mut docs = Vec::new();
    let out = run_paused(&cfg, &g5_rows(Some((10.0, 11.0))), &mut watch, |k| {
        if k > 0 && k % 23 == 0 {
            docs.push((k, get(addr, "/api/status")));
        }
    });
    let ev = evidence(&out);
    for (k, r) in &docs {
        assert_eq!(r.status, 200);
        let doc: serde_json::Value = serde_json::from_str(&r.body).unwrap();
        let row = &ev[*k as usize - 1];
        let open = field(row, "calibrated_open") == 1.0;
        assert_eq!(doc["schema"], "streamcert.status/1");
        assert_eq!(doc["open"], open, "row {k}");
        assert_eq!(doc["t"].as_f64().unwrap(), field(row, "t"));
        assert_eq!(doc["counters"]["samples"], *k);
        // Since when: the first row of the current stretch of equal gates.
        let i = *k as usize - 1;
        let start = (0..=i)
            .rev()
            .take_while(|&j| (field(&ev[j], "calibrated_open") == 1.0) == open)
            .last()
            .unwrap();
        assert_eq!(doc["since"].as_f64().unwrap(), field(&ev[start], "t"), "row {k}");
        match open {
            true => assert!(doc["reason"].is_null()),
            false => assert_eq!(doc["reason"]["detail"], row["reason_calibrated"].as_str()),
        }
    }
    let end = monitor.status();
    assert_eq!(end.ended.as_deref(), Some("the input ended"));
    assert!(!end.open && end.verdict.starts_with("verdict: "));
}

#[test]
fn verdict_messages_are_the_evidence_rows_gate_changes() {
    let cfg = node_b();
    let monitor = Monitor::new(MonitorOptions::named("node_b"));
    let (tx, rx) = std::sync::mpsc::channel::<VerdictMessage>();
    let sink = move |m: &VerdictMessage| tx.send(m.clone()).unwrap();
    let mut watch = monitor.certify(&cfg.certifier, &cfg.columns.outputs, vec![Box::new(sink)]);
    let out = run_paused(&cfg, &g5_rows(Some((10.0, 11.0))), &mut watch, |_| {});
    drop(watch);
    let messages: Vec<VerdictMessage> = rx.try_iter().collect();
    let changes = gate_changes(&evidence(&out), "calibrated_open");
    assert!(changes.len() >= 2, "the gap closes the gate that opened: {changes:?}");
    let (first, last) = (&messages[0], &messages[messages.len() - 1]);
    assert_eq!((first.sequence, first.open), (0, false));
    assert_eq!(first.reason.as_ref().unwrap().kind, "starting");
    assert!(last.ended && !last.open);
    let middle: Vec<(f64, bool)> =
        messages[1..messages.len() - 1].iter().map(|m| (m.t.unwrap(), m.open)).collect();
    assert_eq!(middle, changes);
    for (i, m) in messages.iter().enumerate() {
        assert_eq!(m.sequence, i as u64);
        assert_eq!(m.open, m.reason.is_none());
        assert_eq!(m.risk.unwrap().delta, cfg.certifier.calibration.as_ref().unwrap().delta);
        assert_eq!(m.candidate.margin, cfg.certifier.margin);
    }
    let closed = messages.iter().find(|m| m.sequence > 1 && !m.open && !m.ended).unwrap();
    assert_eq!(closed.reason.as_ref().unwrap().kind, "gap");
}

#[test]
fn bad_requests_get_their_status_codes_and_the_run_goes_on() {
    let (cfg, monitor, server, mut watch) = served("node_b");
    let addr = server.addr();
    let mut answers = Vec::new();
    let rows = g5_rows(None);
    let out = run_paused(&cfg, &rows, &mut watch, |k| {
        if k != 300 {
            return;
        }
        answers.push(("unknown path", get(addr, "/etc/passwd").status, 404));
        answers.push(("POST", request(addr, "POST", "/metrics").status, 405));
        answers.push(("PUT", request(addr, "PUT", "/api/status").status, 405));
        answers.push(("DELETE", request(addr, "DELETE", "/").status, 405));
        let big = format!(
            "GET / HTTP/1.1\r\nHost: localhost\r\nX-Big: {}\r\nConnection: close\r\n\r\n",
            "a".repeat(1 << 20)
        );
        answers.push(("1 MB header", raw(addr, big.as_bytes()).status, 431));
        answers.push(("garbage", raw(addr, b"\x00\x01 nonsense\r\n\r\n").status, 400));
        answers.push(("metrics after", get(addr, "/metrics").status, 200));
        answers.push(("page after", get(addr, "/").status, 200));
    });
    for (what, got, want) in &answers {
        assert_eq!(got, want, "{what}");
    }
    assert_eq!(answers.len(), 8);
    // Every row was certified and written.
    assert_eq!(evidence(&out).len(), rows.lines().count() - 1);
    assert_eq!(monitor.status().counters.samples, rows.lines().count() as u64 - 1);
}

#[test]
fn the_page_its_assets_and_no_credential_are_served() {
    let (_monitor, server) = started("node_b");
    let addr = server.addr();
    let page = get(addr, "/");
    assert_eq!(page.status, 200);
    assert!(page.headers.contains("content-type: text/html"));
    assert!(page.headers.contains("content-security-policy: default-src 'self'"));
    // Embedded: nothing is loaded from another host.
    for asset in ["/", "/app.js", "/style.css"] {
        let body = get(addr, asset).body;
        assert!(!body.contains("http://") && !body.contains("https://"), "{asset}");
    }
    assert!(page.body.contains("src=\"/app.js\""));
    assert_eq!(get(addr, "/healthz").body, "ok");
}

#[test]
fn a_hundred_clients_polling_are_served_while_the_run_goes_on() {
    let (cfg, _monitor, server, mut watch) = served("node_b");
    let addr = server.addr();
    let stop = Arc::new(AtomicBool::new(false));
    let mut clients = Vec::new();
    let rows = g5_rows(None);
    let out = run_paused(&cfg, &rows, &mut watch, |k| match k {
        100 => {
            for i in 0..100 {
                let stop = Arc::clone(&stop);
                clients.push(std::thread::spawn(move || {
                    let mut codes = Vec::new();
                    while !stop.load(Ordering::Relaxed) || codes.len() < 2 {
                        let path = if i % 2 == 0 { "/api/status" } else { "/metrics" };
                        codes.push(get(addr, path).status);
                        std::thread::sleep(std::time::Duration::from_millis(20));
                    }
                    codes
                }));
            }
        }
        101..=600 => std::thread::sleep(std::time::Duration::from_millis(2)),
        601 => stop.store(true, Ordering::Relaxed),
        _ => {}
    });
    let codes: Vec<u16> = clients.into_iter().flat_map(|c| c.join().unwrap()).collect();
    assert!(codes.len() >= 200, "{} answers", codes.len());
    assert!(codes.iter().all(|&c| c == 200), "{:?}", codes.iter().filter(|&&c| c != 200).count());
    assert_eq!(evidence(&out).len(), rows.lines().count() - 1);
}

#[test]
fn a_network_run_s_metrics_and_messages_are_its_epoch_rows() {
    let text = std::fs::read_to_string(support::example("g5_network.toml")).unwrap();
    let cfg = streamcert_pipeline::network::parse(&text, "g5_network.toml").unwrap();
    let mut data = Vec::new();
    streamcert_pipeline::simulate::run(
        streamcert_experiments::Experiment::Two,
        streamcert_dynamics::Coupling::Bidirectional,
        0,
        None,
        None,
        &mut data,
    )
    .unwrap();
    let monitor = Monitor::new(MonitorOptions::named("g5"));
    let (tx, rx) = std::sync::mpsc::channel::<VerdictMessage>();
    let sink = move |m: &VerdictMessage| tx.send(m.clone()).unwrap();
    let mut watch = monitor.network(&cfg.network, vec![Box::new(sink)]);
    let opts = streamcert_pipeline::network::NetOptions {
        format: streamcert_pipeline::output::Format::Csv,
        flush: streamcert_pipeline::output::Flush::Buffered,
        checkpoint: None,
        checkpoint_every: None,
        resume: None,
        plot: None,
    };
    let mut out = Vec::new();
    let s = streamcert_pipeline::network::run_watched(
        &cfg,
        &data[..],
        "g5",
        &mut out,
        &opts,
        &mut watch,
    )
    .unwrap();
    drop(watch);
    let epochs = evidence(&String::from_utf8(out).unwrap());
    let changes = gate_changes(&epochs, "open");
    assert!(!changes.is_empty(), "the network gate opens on these data");
    let messages: Vec<VerdictMessage> = rx.try_iter().collect();
    let n = messages.len();
    let middle: Vec<(f64, bool)> =
        messages[1..n - 1].iter().map(|m| (m.t.unwrap(), m.open)).collect();
    assert_eq!(middle, changes);
    assert!(messages.iter().all(|m| m.kind == "network" && m.certificate == "network"));
    assert_eq!(messages[0].risk.map(|r| r.delta), cfg.network.total_risk());
    let m = parse(&monitor.metrics_text());
    let last = epochs.last().unwrap();
    let lp = [("loop", "g5")];
    assert_eq!(value(&m, "streamcert_network_gate_open", &lp), field(last, "open"));
    assert_eq!(value(&m, "streamcert_network_rate_per_second", &lp), field(last, "rate"));
    assert_eq!(value(&m, "streamcert_epochs_total", &lp), epochs.len() as f64);
    assert_eq!(value(&m, "streamcert_samples_total", &lp), s.rows as f64);
    for sub in &cfg.network.subsystems {
        let l = [("loop", "g5"), ("subsystem", sub.name.as_str())];
        let cert = field(last, &format!("cert_{}", sub.name));
        let got = value(&m, "streamcert_subsystem_certificate_per_second", &l);
        assert!(got == cert || (got.is_nan() && cert.is_nan()), "{}: {got} {cert}", sub.name);
    }
    for name in documented("network") {
        assert!(monitor.metrics_text().contains(&format!("\n{name}{{")), "no {name}");
    }
    let status = monitor.status();
    assert_eq!(status.subsystems.len(), cfg.network.subsystems.len());
    assert_eq!(status.counters.epochs, epochs.len() as u64);
}

#[test]
fn the_grafana_dashboard_queries_only_documented_series() {
    let dash = std::fs::read_to_string(support::example("../grafana/streamcert.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&dash).unwrap();
    let mut names = documented("certify");
    names.extend(documented("network"));
    let mut queried = 0;
    for panel in v["panels"].as_array().unwrap() {
        for target in panel["targets"].as_array().unwrap() {
            let expr = target["expr"].as_str().unwrap();
            for (i, _) in expr.match_indices("streamcert_") {
                let name: String = expr[i..]
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                assert!(names.contains(&name), "{name} in `{expr}` is not documented");
                queried += 1;
            }
        }
    }
    assert!(queried >= 12);
}

#[test]
fn the_lag_and_the_age_of_the_last_sample_are_measured_on_the_wall_clock() {
    let cfg = node_b();
    let monitor = Monitor::new(MonitorOptions::named("node_b"));
    let mut watch = monitor.certify(&cfg.certifier, &cfg.columns.outputs, Vec::new());
    // The same rows with Unix times ending now (a live source's source timestamps).
    let rows = g5_rows(None);
    let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap();
    let shift = now.as_secs_f64() - 16.0;
    let shifted: String = rows
        .lines()
        .enumerate()
        .map(|(i, l)| match (i, l.split_once(',')) {
            (0, _) | (_, None) => format!("{l}\n"),
            (_, Some((t, rest))) => format!("{},{rest}\n", t.parse::<f64>().unwrap() + shift),
        })
        .collect();
    let mut lags = Vec::new();
    run_paused(&cfg, &shifted, &mut watch, |k| {
        if k == 500 {
            let m = parse(&monitor.metrics_text());
            lags.push(value(&m, "streamcert_evidence_lag_seconds", &[("loop", "node_b")]));
        }
    });
    // Row 499 is at t = 4.98 s of 16: its sample time is about 11 s before now.
    assert!((lags[0] - 11.0).abs() < 5.0, "lag {}", lags[0]);
    std::thread::sleep(std::time::Duration::from_millis(300));
    let m = parse(&monitor.metrics_text());
    let age = value(&m, "streamcert_last_sample_age_seconds", &[("loop", "node_b")]);
    assert!((0.3..30.0).contains(&age), "age {age}");
    // A file's own clock has no lag.
    let (monitor, _server) = started("file");
    let mut watch = monitor.certify(&cfg.certifier, &cfg.columns.outputs, Vec::new());
    run_paused(&cfg, &rows, &mut watch, |_| {});
    let m = parse(&monitor.metrics_text());
    assert!(value(&m, "streamcert_evidence_lag_seconds", &[("loop", "file")]).is_nan());
}

/// The loop model's order is shown wherever the verdict is: the verdict message's candidate,
/// the status document and the metrics say 2 for `[regression] order = 2` and 1 for the
/// template's first order.
#[test]
fn the_loop_models_order_is_in_the_message_the_status_and_the_metrics() {
    let text = streamcert_pipeline::config::g5_node_b();
    assert!(text.contains("\norder = 1\n"));
    for order in [1usize, 2] {
        let cfg = streamcert_pipeline::config::parse(
            &text.replace("\norder = 1\n", &format!("\norder = {order}\n")),
            "g5_node_b",
        )
        .unwrap();
        let (monitor, server) = started("node_b");
        let (tx, rx) = std::sync::mpsc::channel::<VerdictMessage>();
        let sink = move |m: &VerdictMessage| tx.send(m.clone()).unwrap();
        let mut watch = monitor.certify(&cfg.certifier, &cfg.columns.outputs, vec![Box::new(sink)]);
        let mut seen = None;
        run_paused(&cfg, &g5_rows(None), &mut watch, |k| {
            if k == 400 {
                seen = Some((get(server.addr(), "/api/status"), get(server.addr(), "/metrics")));
            }
        });
        drop(watch);
        let messages: Vec<VerdictMessage> = rx.try_iter().collect();
        assert!(!messages.is_empty());
        assert!(messages.iter().all(|m| m.candidate.order == Some(order)));
        let (status, metrics) = seen.unwrap();
        let doc: serde_json::Value = serde_json::from_str(&status.body).unwrap();
        assert_eq!(doc["order"], order, "{}", status.body);
        let m = parse(&metrics.body);
        assert_eq!(value(&m, "streamcert_model_order", &[("loop", "node_b")]), order as f64);
        assert_eq!(monitor.status().order, Some(order));
    }
}

/// With `order = "auto"` the candidate names the orders run side by side instead of one, and
/// the message, the status document and the metrics follow the order of the standing look:
/// the evidence's own `calibrated_order` at every sample.
#[test]
fn with_order_auto_the_standing_order_is_shown() {
    let text =
        streamcert_pipeline::config::g5_node_b().replace("\norder = 1\n", "\norder = \"auto\"\n");
    let cfg = streamcert_pipeline::config::parse(&text, "g5_node_b").unwrap();
    let (monitor, server) = started("node_b");
    let (tx, rx) = std::sync::mpsc::channel::<VerdictMessage>();
    let sink = move |m: &VerdictMessage| tx.send(m.clone()).unwrap();
    let mut watch = monitor.certify(&cfg.certifier, &cfg.columns.outputs, vec![Box::new(sink)]);
    let mut seen = None;
    let out = run_paused(&cfg, &g5_rows(None), &mut watch, |k| {
        if k == 400 {
            seen = Some((get(server.addr(), "/api/status"), get(server.addr(), "/metrics")));
        }
    });
    drop(watch);
    let messages: Vec<VerdictMessage> = rx.try_iter().collect();
    assert!(
        messages.iter().all(|m| m.candidate.order.is_none() && m.candidate.orders == [1, 2, 3])
    );
    // Every message sent while the gate was open names the order it stood at.
    assert!(messages.iter().any(|m| m.open), "the gate opened");
    assert!(messages.iter().filter(|m| m.open).all(|m| matches!(m.look_order, Some(1..=3))));
    let (status, metrics) = seen.unwrap();
    let doc: serde_json::Value = serde_json::from_str(&status.body).unwrap();
    assert_eq!(doc["orders"], serde_json::json!([1, 2, 3]), "{}", status.body);
    assert!(doc["order"].is_null(), "{}", status.body);
    let look = doc["look_order"].as_u64().map_or(0.0, |n| n as f64);
    let m = parse(&metrics.body);
    assert_eq!(value(&m, "streamcert_model_order", &[("loop", "node_b")]), look);
    // The evidence's standing order is what was shown: row 400's, the last before the look.
    let rows = evidence(&out);
    let want = rows[399]["calibrated_order"].parse::<usize>().ok();
    assert_eq!(doc["look_order"].as_u64().map(|n| n as usize), want, "{}", status.body);
}
