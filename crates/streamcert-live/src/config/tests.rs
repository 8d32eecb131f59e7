//! The `[source]` section's parsing, key by key.

use super::*;

fn mqtt(c: SourceConfig) -> MqttConfig {
    match c {
        SourceConfig::Mqtt(m) => m,
        SourceConfig::OpcUa(_) => panic!("an MQTT source"),
    }
}

fn columns() -> Columns {
    toml::from_str("time = \"t\"\noutputs = [\"y\"]\ninputs = [\"u\"]").unwrap()
}

fn parse_text(text: &str) -> Result<SourceConfig, String> {
    parse(&toml::from_str(text).unwrap(), &columns())
}

#[test]
fn servers_are_parsed_and_credentials_in_them_refused() {
    assert_eq!(
        server("tcp://127.0.0.1:1884").unwrap(),
        Server { host: "127.0.0.1".into(), port: 1884, tls: false }
    );
    assert_eq!(server("mqtts://broker").unwrap().port, 8883);
    assert!(server("tcp://user:pw@host:1883").unwrap_err().contains("refused"));
    assert!(server("http://host").is_err());
}

#[test]
fn a_literal_password_is_refused_and_never_shown() {
    let base = "kind = \"mqtt\"\nservers = [\"tcp://h\"]\ntopics = [\"a\"]\nusername = \"op\"\n";
    let e = parse_text(&format!("{base}password = \"hunter2\"")).unwrap_err();
    assert!(!e.contains("hunter2") && e.contains("${VAR}"), "{e}");
    let file = std::env::temp_dir().join(format!("streamcert-pw-{}", std::process::id()));
    std::fs::write(&file, "s3cret-from-a-file\n").unwrap();
    let with_file = format!("{base}password_file = {:?}", file.display().to_string());
    let ok = parse_text(&with_file).unwrap();
    std::fs::remove_file(&file).unwrap();
    let Some((_, secret)) = &mqtt(ok.clone()).credentials else { panic!("credentials") };
    assert_eq!(secret.0, "s3cret-from-a-file");
    let shown = format!("{ok:?}");
    assert!(!shown.contains("s3cret") && shown.contains("<redacted>"), "{shown}");
    // From the environment (PATH is set wherever tests run).
    let path = std::env::var("PATH").unwrap();
    let ok = parse_text(&format!("{base}password = \"${{PATH}}\"")).unwrap();
    assert!(!format!("{ok:?}").contains(&path));
    let e = parse_text(&format!("{base}password = \"${{STREAMCERT_NO_SUCH_VAR}}\"")).unwrap_err();
    assert!(e.contains("STREAMCERT_NO_SUCH_VAR is not set"), "{e}");
}

#[test]
fn signals_need_every_column_a_period_and_a_timestamp() {
    let base = "kind = \"mqtt\"\nservers = [\"tcp://h\"]\n";
    let y = "[[signal]]\ncolumn = \"y\"\ntopic = \"p/y\"\n";
    let u = "[[signal]]\ncolumn = \"u\"\ntopic = \"p/u\"\n";
    let e = parse_text(&format!("{base}{y}")).unwrap_err();
    assert!(e.contains("no topic for the column `u`"), "{e}");
    let e = parse_text(&format!("{base}{y}{u}")).unwrap_err();
    assert!(e.contains("period"), "{e}");
    let ok = parse_text(&format!("{base}{y}{u}[align]\nperiod = 0.1\n")).unwrap();
    let Layout::Signals { rule, .. } = mqtt(ok).layout else { panic!("signals") };
    assert_eq!((rule.max_age, rule.reorder_window), (0.2, 0.1));
    let bare = "[[signal]]\ncolumn = \"u\"\ntopic = \"p/u\"\ndata_format = \"value\"\n";
    let e = parse_text(&format!("{base}{y}{bare}[align]\nperiod = 0.1\n")).unwrap_err();
    assert!(e.contains("time = \\\"arrival\\\"") || e.contains("arrival"), "{e}");
}

#[test]
fn a_site_keeps_its_own_signals_and_session() {
    let table: toml::Table = toml::from_str(
        "kind = \"mqtt\"\nservers = [\"tcp://h\"]\nclient_id = \"net\"\n\
         [[signal]]\ncolumn = \"y\"\ntopic = \"p/y\"\n[[signal]]\ncolumn = \"u\"\ntopic = \"p/u\"\n\
         [[signal]]\ncolumn = \"y_other\"\ntopic = \"q/y\"\n[[signal]]\ncolumn = \"u_other\"\n\
         topic = \"q/u\"\n[align]\nperiod = 0.1\n",
    )
    .unwrap();
    // The whole table is refused for the site's columns (other subsystems' topics); the
    // site's own is accepted, under a client id of its own.
    assert!(parse(&table, &columns()).unwrap_err().contains("y_other"));
    let site = crate::for_site(&table, &columns(), 1);
    let m = mqtt(parse(&site, &columns()).unwrap());
    assert_eq!(m.client_id, "net-site1");
    let Layout::Signals { signals, .. } = m.layout else { panic!("signals") };
    let topics: Vec<&str> = signals.iter().map(|s| s.topic.as_str()).collect();
    assert_eq!(topics, ["p/y", "p/u"]);
}
