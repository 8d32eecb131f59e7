//! The `[source]` section of a certify configuration: a live plant source. `kind = "mqtt"`
//! takes the names Telegraf's `mqtt_consumer` input uses (`servers`, `topics`, `client_id`, `qos`,
//! `persistent_session`, `username`, `password`, `tls_ca`, `tls_cert`, `tls_key`,
//! `data_format`, `json_time_key`), so that a plant's existing settings carry over.
//!
//! ```toml
//! [source]
//! kind = "mqtt"
//! servers = ["tcp://127.0.0.1:1883"]
//! client_id = "streamcert-loop-7"     # the persistent session's name
//! topics = ["plant/loop7"]            # one whole row per message
//! data_format = "json"                # {"t": 1.5, "y_b": 0.12, "u_b": -0.4}
//! ```
//!
//! One signal per topic instead: `[[source.signal]]` tables (`column`, `topic`,
//! `data_format` `"json"` or `"value"`) and the alignment rule in `[source.align]`
//! (`period`, `max_age`, `reorder_window`; see [`crate::align`]).
//!
//! `kind = "opcua"` takes the names of Telegraf's `opcua_listener` ([`opcua`]).
//!
//! Credentials are never written in the file: `username` and `password` take `"${VAR}"`
//! (read from the environment) or `password_file` a path; a literal password is refused.
//! Neither appears in a log line, the summary or a printed configuration.

use std::fmt;
use std::time::Duration;

use serde::Deserialize;
use streamcert_pipeline::config::Columns;

use crate::align::AlignRule;
use crate::payload::{DEFAULT_MAX_PAYLOAD, RowFormat, SignalFormat};

pub mod opcua;

pub use opcua::{Node, OpcUaConfig, SecurityMode, Timestamp};

/// A validated `[source]` section: which kind of live source, with its settings.
#[derive(Debug, Clone)]
pub enum SourceConfig {
    /// `kind = "mqtt"`: a broker's topics.
    Mqtt(MqttConfig),
    /// `kind = "opcua"`: an OPC UA server's nodes.
    OpcUa(OpcUaConfig),
}

/// Where an MQTT source connects and what it reads.
#[derive(Debug, Clone)]
pub struct MqttConfig {
    /// Brokers, tried in turn at each reconnection: `(host, port, tls)`.
    pub servers: Vec<Server>,
    /// The client id: the persistent session's name at the broker.
    pub client_id: String,
    /// Keep the session at the broker across disconnections (QoS 1 messages published
    /// meanwhile are delivered on reconnection). Default true.
    pub persistent_session: bool,
    /// Credentials, resolved from the environment or a file.
    pub credentials: Option<(String, Secret)>,
    /// TLS files: the CA, and the client's certificate and key.
    pub tls: Option<Tls>,
    /// What the messages hold.
    pub layout: Layout,
    /// Payloads above this size are refused (`oversized`). Default 64 KiB.
    pub max_payload: usize,
    /// The largest MQTT packet the client reads, bytes of its remaining length. Default
    /// [`MAX_PACKET`], MQTT's largest: every message a broker can send is read whole, and
    /// one above `max_payload` is refused (`oversized`), counted and acknowledged. A smaller
    /// value bounds the memory one message takes; a packet above it cannot be read, breaks
    /// the connection, and is passed over as a poison message ([`crate::mqtt`]).
    pub max_packet: usize,
    /// Topics that delivered nothing after this long are reported by name. Default 10 s.
    pub silent_after: Duration,
    /// End the stream after this long without a message, counted from the subscription
    /// (`None`, the default: run until stopped).
    pub idle_timeout: Option<Duration>,
    /// With a checkpoint, the most messages held unacknowledged before one is written.
    /// Default 16 (below Mosquitto's default of 20 in flight).
    pub max_unacked: usize,
    /// The first and the longest wait before reconnecting (doubling in between).
    /// Default 0.1 s and 10 s.
    pub backoff: (Duration, Duration),
}

/// One broker address.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Server {
    /// Host name or address.
    pub host: String,
    /// Port (1883 for `tcp://` and `mqtt://`, 8883 for `ssl://`, `tls://` and `mqtts://`
    /// unless given).
    pub port: u16,
    /// Whether the connection is TLS.
    pub tls: bool,
}

impl fmt::Display for Server {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let scheme = if self.tls { "ssl" } else { "tcp" };
        write!(f, "{scheme}://{}:{}", self.host, self.port)
    }
}

/// A secret: its `Debug` and `Display` never show it.
#[derive(Clone, PartialEq, Eq)]
pub struct Secret(pub(crate) String);

impl fmt::Debug for Secret {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("<redacted>")
    }
}

/// TLS files (PEM).
#[derive(Debug, Clone)]
pub struct Tls {
    /// The CA certificate the broker's certificate is checked against.
    pub ca: std::path::PathBuf,
    /// The client's certificate and key, for brokers that ask for one.
    pub client: Option<(std::path::PathBuf, std::path::PathBuf)>,
}

/// What the messages hold.
#[derive(Debug, Clone)]
pub enum Layout {
    /// A whole row per message on these topics.
    Rows {
        /// The topics (MQTT filters: `+` and `#` allowed).
        topics: Vec<String>,
        /// How a row is written.
        format: RowFormat,
        /// The fields' names.
        fields: crate::payload::RowFields,
    },
    /// One signal per topic, aligned on a grid.
    Signals {
        /// Per column of the row (outputs, then inputs, as in `[columns]`): its topic, format
        /// and JSON keys.
        signals: Vec<Signal>,
        /// The alignment rule.
        rule: AlignRule,
        /// Whether a `value` payload's time is its arrival (the user's explicit choice).
        arrival_time: bool,
    },
}

/// One signal's topic.
#[derive(Debug, Clone, PartialEq)]
pub struct Signal {
    /// The column it fills.
    pub column: String,
    /// Its topic (no wildcard).
    pub topic: String,
    /// How it is written.
    pub format: SignalFormat,
    /// The source timestamp's key (`json`).
    pub time_key: String,
    /// The value's key (`json`).
    pub value_key: String,
}

/// MQTT's largest packet, bytes of its remaining length (the protocol's four-byte variable
/// length): the client's default read limit, so that no message a broker can send breaks the
/// connection.
pub const MAX_PACKET: usize = 268_435_455;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    /// Read by [`parse`] before this table is.
    #[allow(dead_code)]
    kind: String,
    servers: Vec<String>,
    client_id: Option<String>,
    #[serde(default = "yes")]
    persistent_session: bool,
    #[serde(default = "one")]
    qos: u8,
    username: Option<String>,
    password: Option<String>,
    password_file: Option<String>,
    tls_ca: Option<String>,
    tls_cert: Option<String>,
    tls_key: Option<String>,
    #[serde(default)]
    topics: Vec<String>,
    data_format: Option<String>,
    json_time_key: Option<String>,
    csv_columns: Option<Vec<String>>,
    max_payload: Option<usize>,
    max_packet: Option<usize>,
    silent_after: Option<f64>,
    idle_timeout: Option<f64>,
    max_unacked: Option<usize>,
    reconnect_min: Option<f64>,
    reconnect_max: Option<f64>,
    #[serde(default)]
    signal: Vec<RawSignal>,
    align: Option<RawAlign>,
    time: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSignal {
    column: String,
    topic: String,
    data_format: Option<String>,
    json_time_key: Option<String>,
    json_value_key: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawAlign {
    period: f64,
    max_age: Option<f64>,
    pub(crate) reorder_window: Option<f64>,
}

/// The alignment rule of `[source.align]`: `max_age` 2T and `reorder_window` T by default.
pub(crate) fn align_rule(a: Option<&RawAlign>) -> Result<AlignRule, String> {
    let a = a.ok_or("source.align: give the grid's period (seconds)")?;
    let rule = AlignRule {
        period: a.period,
        max_age: a.max_age.unwrap_or(2.0 * a.period),
        reorder_window: a.reorder_window.unwrap_or(a.period),
    };
    rule.validate().map_err(|e| format!("source.align: {e}"))?;
    Ok(rule)
}

/// A duration in seconds, `default` when not given.
pub(crate) fn secs(v: Option<f64>, default: f64, key: &str) -> Result<Duration, String> {
    let v = v.unwrap_or(default);
    Duration::try_from_secs_f64(v)
        .map_err(|_| format!("source.{key}: {v} is not a duration in seconds"))
}

fn yes() -> bool {
    true
}

fn one() -> u8 {
    1
}

/// Parse and check the `[source]` table against the configured columns.
///
/// # Errors
/// What is wrong, naming the key (`source.servers`, `source.signal[1].topic`, ...).
pub fn parse(table: &toml::Table, columns: &Columns) -> Result<SourceConfig, String> {
    match table.get("kind").and_then(toml::Value::as_str) {
        Some("mqtt") => parse_mqtt(table, columns).map(SourceConfig::Mqtt),
        Some("opcua") => opcua::parse(table, columns).map(SourceConfig::OpcUa),
        Some(other) => {
            Err(format!("source.kind: \"{other}\" is not a source; use \"mqtt\" or \"opcua\""))
        }
        None => Err("source.kind: say which source, \"mqtt\" or \"opcua\"".into()),
    }
}

fn parse_mqtt(table: &toml::Table, columns: &Columns) -> Result<MqttConfig, String> {
    let raw: Raw = toml::Value::Table(table.clone())
        .try_into()
        .map_err(|e: toml::de::Error| format!("[source]: {}", e.message()))?;
    if raw.qos != 1 {
        return Err(format!(
            "source.qos: {} is not supported: QoS 1 (at least once, with the persistent \
             session) is what keeps a restart from losing messages",
            raw.qos
        ));
    }
    let servers = raw.servers.iter().map(|s| server(s)).collect::<Result<Vec<_>, _>>()?;
    if servers.is_empty() {
        return Err(
            "source.servers: give at least one broker, e.g. \"tcp://127.0.0.1:1883\"".into()
        );
    }
    let client_id = raw.client_id.clone().unwrap_or_else(|| "streamcert".into());
    let max_payload = raw.max_payload.unwrap_or(DEFAULT_MAX_PAYLOAD);
    let max_packet = raw.max_packet.unwrap_or(MAX_PACKET);
    if max_packet <= max_payload || max_packet > MAX_PACKET {
        return Err(format!(
            "source.max_packet = {max_packet}: it must exceed max_payload ({max_payload}), so \
             that an oversized payload is read, counted and acknowledged, and be at most \
             {MAX_PACKET} (MQTT's largest packet)"
        ));
    }
    let idle_timeout = match raw.idle_timeout {
        Some(_) => Some(secs(raw.idle_timeout, 0.0, "idle_timeout")?),
        None => None,
    };
    Ok(MqttConfig {
        servers,
        client_id,
        persistent_session: raw.persistent_session,
        credentials: credentials(&raw)?,
        tls: tls(&raw)?,
        layout: layout(&raw, columns)?,
        max_payload,
        max_packet,
        silent_after: secs(raw.silent_after, 10.0, "silent_after")?,
        idle_timeout,
        max_unacked: raw.max_unacked.unwrap_or(16).max(1),
        backoff: (
            secs(raw.reconnect_min, 0.1, "reconnect_min")?,
            secs(raw.reconnect_max, 10.0, "reconnect_max")?,
        ),
    })
}

/// `tcp://host:port` (or `mqtt://`, `ssl://`, `tls://`, `mqtts://`; a user name and password
/// in the address are refused: they belong in the environment).
pub(crate) fn server(url: &str) -> Result<Server, String> {
    let bad = |why: &str| format!("source.servers: `{url}`: {why}");
    let (scheme, rest) = url.split_once("://").ok_or_else(|| bad("expected scheme://host:port"))?;
    let tls = match scheme {
        "tcp" | "mqtt" => false,
        "ssl" | "tls" | "mqtts" => true,
        _ => return Err(bad("the scheme must be tcp, mqtt, ssl, tls or mqtts")),
    };
    let rest = rest.trim_end_matches('/');
    if rest.contains('@') {
        return Err(bad("credentials in the address are refused; use username = \"${VAR}\" and \
             password = \"${VAR}\" (or password_file)"));
    }
    let (host, port) = match rest.rsplit_once(':') {
        Some((h, p)) => (h, p.parse::<u16>().map_err(|_| bad("the port is not a number"))?),
        None => (rest, if tls { 8883 } else { 1883 }),
    };
    if host.is_empty() {
        return Err(bad("no host"));
    }
    Ok(Server { host: host.trim_matches(['[', ']']).to_string(), port, tls })
}

/// `${VAR}` from the environment; anything else is refused for a password.
fn from_env(value: &str, key: &str, literal_ok: bool) -> Result<String, String> {
    if let Some(var) = value.strip_prefix("${").and_then(|v| v.strip_suffix('}')) {
        return std::env::var(var)
            .map_err(|_| format!("source.{key}: the environment variable {var} is not set"));
    }
    if literal_ok {
        Ok(value.to_string())
    } else {
        Err(format!(
            "source.{key}: a password is never written in the configuration; use \"${{VAR}}\" \
             (an environment variable) or password_file"
        ))
    }
}

fn credentials(raw: &Raw) -> Result<Option<(String, Secret)>, String> {
    user_password(raw.username.as_deref(), raw.password.as_deref(), raw.password_file.as_deref())
}

/// A user name (literal or `${VAR}`) and its password (`${VAR}` or a file's first line).
pub(crate) fn user_password(
    username: Option<&str>,
    password: Option<&str>,
    password_file: Option<&str>,
) -> Result<Option<(String, Secret)>, String> {
    let password = match (password, password_file) {
        (Some(_), Some(_)) => return Err("source: give password or password_file, not both".into()),
        (Some(p), None) => Some(from_env(p, "password", false)?),
        (None, Some(path)) => Some(
            std::fs::read_to_string(path)
                .map_err(|e| format!("source.password_file: {path}: {e}"))?
                .trim_end_matches(['\r', '\n'])
                .to_string(),
        ),
        (None, None) => None,
    };
    match (username, password) {
        (Some(u), p) => Ok(Some((from_env(u, "username", true)?, Secret(p.unwrap_or_default())))),
        (None, Some(_)) => Err("source: a password needs a username".into()),
        (None, None) => Ok(None),
    }
}

fn tls(raw: &Raw) -> Result<Option<Tls>, String> {
    tls_files(raw.tls_ca.as_ref(), raw.tls_cert.as_ref(), raw.tls_key.as_ref())
}

/// The TLS files: the CA alone, or with the client's certificate and key.
pub(crate) fn tls_files(
    ca: Option<&String>,
    cert: Option<&String>,
    key: Option<&String>,
) -> Result<Option<Tls>, String> {
    match (ca, cert, key) {
        (None, None, None) => Ok(None),
        (Some(ca), None, None) => Ok(Some(Tls { ca: ca.into(), client: None })),
        (Some(ca), Some(c), Some(k)) => {
            Ok(Some(Tls { ca: ca.into(), client: Some((c.into(), k.into())) }))
        }
        (None, _, _) => Err("source.tls_ca: TLS needs the CA certificate".into()),
        _ => Err("source: tls_cert and tls_key go together".into()),
    }
}

fn layout(raw: &Raw, columns: &Columns) -> Result<Layout, String> {
    match (raw.topics.is_empty(), raw.signal.is_empty()) {
        (false, true) => rows(raw, columns),
        (true, false) => signals(raw, columns),
        (false, false) => {
            Err("source: give topics (a row per message) or [[source.signal]], not both".into())
        }
        (true, true) => Err("source.topics: no topic to read (or [[source.signal]] tables)".into()),
    }
}

fn rows(raw: &Raw, columns: &Columns) -> Result<Layout, String> {
    let format = match raw.data_format.as_deref().unwrap_or("json") {
        "json" => RowFormat::Json,
        "csv" => RowFormat::Csv,
        other => return Err(format!("source.data_format: \"{other}\": use \"json\" or \"csv\"")),
    };
    let time = raw.json_time_key.clone().unwrap_or_else(|| columns.time.clone());
    let csv_columns = raw.csv_columns.clone().unwrap_or_else(|| {
        std::iter::once(&time).chain(&columns.outputs).chain(&columns.inputs).cloned().collect()
    });
    if format == RowFormat::Csv {
        for c in std::iter::once(&time).chain(&columns.outputs).chain(&columns.inputs) {
            if !csv_columns.contains(c) {
                return Err(format!("source.csv_columns: no `{c}`"));
            }
        }
    }
    if raw.align.is_some() || raw.time.is_some() {
        return Err("source: align and time are for [[source.signal]] topics".into());
    }
    let fields = crate::payload::RowFields {
        time,
        outputs: columns.outputs.clone(),
        inputs: columns.inputs.clone(),
        csv_columns,
    };
    Ok(Layout::Rows { topics: raw.topics.clone(), format, fields })
}

fn signals(raw: &Raw, columns: &Columns) -> Result<Layout, String> {
    let arrival_time = match raw.time.as_deref().unwrap_or("source") {
        "source" => false,
        "arrival" => true,
        other => return Err(format!("source.time: \"{other}\": use \"source\" or \"arrival\"")),
    };
    let wanted: Vec<&String> = columns.outputs.iter().chain(&columns.inputs).collect();
    let mut signals = Vec::with_capacity(wanted.len());
    for name in &wanted {
        let found: Vec<(usize, &RawSignal)> =
            raw.signal.iter().enumerate().filter(|(_, s)| &&s.column == name).collect();
        let (i, s) = match found.as_slice() {
            [one] => *one,
            [] => return Err(format!("source.signal: no topic for the column `{name}`")),
            _ => return Err(format!("source.signal: the column `{name}` is given twice")),
        };
        let format = match s.data_format.as_deref().unwrap_or("json") {
            "json" => SignalFormat::Json,
            "value" if arrival_time => SignalFormat::Value,
            "value" => {
                return Err(format!(
                    "source.signal[{i}].data_format: a bare value has no source timestamp; \
                     set time = \"arrival\" to align by arrival time (jitter on the network \
                     becomes jitter in the rows), or publish {{\"t\": ..., \"value\": ...}}"
                ));
            }
            other => {
                return Err(format!(
                    "source.signal[{i}].data_format: \"{other}\": use \"json\" or \"value\""
                ));
            }
        };
        if s.topic.contains(['+', '#']) {
            return Err(format!("source.signal[{i}].topic: one topic per signal, no wildcard"));
        }
        signals.push(Signal {
            column: s.column.clone(),
            topic: s.topic.clone(),
            format,
            time_key: s.json_time_key.clone().unwrap_or_else(|| "t".into()),
            value_key: s.json_value_key.clone().unwrap_or_else(|| "value".into()),
        });
    }
    if let Some(extra) = raw.signal.iter().find(|s| !wanted.contains(&&s.column)) {
        return Err(format!("source.signal: `{}` is not a column of [columns]", extra.column));
    }
    let rule = align_rule(raw.align.as_ref())?;
    Ok(Layout::Signals { signals, rule, arrival_time })
}

#[cfg(test)]
mod tests;
