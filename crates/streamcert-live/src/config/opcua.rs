//! `kind = "opcua"`: an OPC UA server's nodes, one per column, with the names Telegraf's
//! `opcua_listener` input uses (`endpoint`, `security_policy`, `security_mode`,
//! `certificate`, `private_key`, `auth_method`, `username`, `password`, `timestamp`, and per
//! node `name`, `namespace`, `identifier_type`, `identifier`), so that a plant's existing
//! settings carry over.
//!
//! ```toml
//! [source]
//! kind = "opcua"
//! endpoint = "opc.tcp://127.0.0.1:4840"
//! security_policy = "None"            # or Basic256Sha256, Aes128_Sha256_RsaOaep, ...
//! security_mode = "None"              # or Sign, SignAndEncrypt (certificate files then)
//! sampling_interval = 0.01            # seconds, asked of the server per node
//!
//! [[source.node]]
//! column = "y_b"                      # Telegraf's `name`
//! namespace = 1
//! identifier_type = "s"               # s, i, g or b
//! identifier = "g5.y_b"
//!
//! [source.align]
//! period = 0.01                       # the grid (see the align module)
//! ```
//!
//! Every node is a signal aligned on the grid by its **source timestamp** (the time the
//! server says the value was sampled), not by arrival. `timestamp = "server"` takes the
//! server's timestamp instead: an explicit choice, for servers that stamp no source time.

use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;
use streamcert_pipeline::config::Columns;

use super::{RawAlign, Secret, align_rule, secs, user_password};
use crate::align::AlignRule;

/// Where an OPC UA source connects and what it reads.
#[derive(Debug, Clone)]
pub struct OpcUaConfig {
    /// The server's endpoint URL, `opc.tcp://host:port[/path]`.
    pub endpoint: String,
    /// The security policy's name as OPC UA writes it (`None`, `Basic256Sha256`, ...).
    pub security_policy: String,
    /// The message security mode.
    pub security_mode: SecurityMode,
    /// The client's certificate and private key (needed unless the policy is `None`).
    pub certificate: Option<(PathBuf, PathBuf)>,
    /// The client's PKI directory: `trusted/` holds the server certificates it trusts,
    /// `rejected/` those it refused. Default `pki`.
    pub pki_dir: PathBuf,
    /// Trust any server certificate on first contact (written to `trusted/`). Default false:
    /// the server's certificate must be in `trusted/` already.
    pub trust_server_certs: bool,
    /// A user name and password (`auth_method = "UserName"`); anonymous otherwise.
    pub credentials: Option<(String, Secret)>,
    /// Per column of the row (outputs, then inputs, as in `[columns]`): its node.
    pub nodes: Vec<Node>,
    /// The alignment rule.
    pub rule: AlignRule,
    /// Which timestamp is a value's time.
    pub timestamp: Timestamp,
    /// The sampling interval asked of the server for each node (0: every change).
    pub sampling_interval: Duration,
    /// The subscription's publishing interval. Default 0.1 s.
    pub publishing_interval: Duration,
    /// How many values the server queues per node between two publications. Default 1000.
    pub queue_size: u32,
    /// Nodes that delivered nothing after this long are reported by name. Default 10 s.
    pub silent_after: Duration,
    /// End the stream after this long without a value, counted from the subscription
    /// (`None`, the default: run until stopped).
    pub idle_timeout: Option<Duration>,
    /// The first and the longest wait before reconnecting (doubling in between).
    /// Default 0.1 s and 10 s.
    pub backoff: (Duration, Duration),
}

/// OPC UA's message security modes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SecurityMode {
    /// No signature, no encryption.
    None,
    /// Messages signed.
    Sign,
    /// Messages signed and encrypted.
    SignAndEncrypt,
}

/// Which of a value's timestamps is its time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Timestamp {
    /// The source timestamp: when the value was sampled (the default).
    Source,
    /// The server's timestamp: when the server received it.
    Server,
}

/// One node: the column it fills and its id.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Node {
    /// The column it fills.
    pub column: String,
    /// Its node id in OPC UA's text form, `ns=1;s=g5.y_b`.
    pub id: String,
}

/// The policies the client speaks, as OPC UA names them.
pub(crate) const POLICIES: [&str; 6] = [
    "None",
    "Basic128Rsa15",
    "Basic256",
    "Basic256Sha256",
    "Aes128_Sha256_RsaOaep",
    "Aes256_Sha256_RsaPss",
];

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    #[allow(dead_code)]
    kind: String,
    endpoint: String,
    security_policy: Option<String>,
    security_mode: Option<String>,
    certificate: Option<String>,
    private_key: Option<String>,
    pki_dir: Option<String>,
    #[serde(default)]
    trust_server_certs: bool,
    auth_method: Option<String>,
    username: Option<String>,
    password: Option<String>,
    password_file: Option<String>,
    timestamp: Option<String>,
    sampling_interval: Option<f64>,
    publishing_interval: Option<f64>,
    queue_size: Option<u32>,
    silent_after: Option<f64>,
    idle_timeout: Option<f64>,
    reconnect_min: Option<f64>,
    reconnect_max: Option<f64>,
    #[serde(default)]
    node: Vec<RawNode>,
    align: Option<RawAlign>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawNode {
    column: Option<String>,
    name: Option<String>,
    node_id: Option<String>,
    namespace: Option<u16>,
    identifier_type: Option<String>,
    identifier: Option<String>,
}

/// Parse and check a `kind = "opcua"` table against the configured columns.
///
/// # Errors
/// What is wrong, naming the key (`source.security_mode`, `source.node[1].identifier`, ...).
pub fn parse(table: &toml::Table, columns: &Columns) -> Result<OpcUaConfig, String> {
    let raw: Raw = toml::Value::Table(table.clone())
        .try_into()
        .map_err(|e: toml::de::Error| format!("[source]: {}", e.message()))?;
    if !raw.endpoint.starts_with("opc.tcp://") || raw.endpoint.len() <= "opc.tcp://".len() {
        return Err(format!("source.endpoint: `{}`: expected opc.tcp://host:port", raw.endpoint));
    }
    if raw.endpoint.contains('@') {
        return Err("source.endpoint: credentials in the address are refused; use auth_method \
                    = \"UserName\" with username and password = \"${VAR}\" (or password_file)"
            .into());
    }
    let (security_policy, security_mode, certificate) = security(&raw)?;
    let publishing_interval = secs(raw.publishing_interval, 0.1, "publishing_interval")?;
    let rule = rule(&raw, publishing_interval.as_secs_f64())?;
    let idle_timeout = match raw.idle_timeout {
        Some(v) => Some(secs(Some(v), 0.0, "idle_timeout")?),
        None => None,
    };
    Ok(OpcUaConfig {
        endpoint: raw.endpoint.clone(),
        security_policy,
        security_mode,
        certificate,
        pki_dir: raw.pki_dir.clone().unwrap_or_else(|| "pki".into()).into(),
        trust_server_certs: raw.trust_server_certs,
        credentials: credentials(&raw)?,
        nodes: nodes(&raw.node, columns)?,
        rule,
        timestamp: match raw.timestamp.as_deref().unwrap_or("source") {
            "source" => Timestamp::Source,
            "server" => Timestamp::Server,
            other => {
                return Err(format!(
                    "source.timestamp: \"{other}\": use \"source\" (when the value was sampled) \
                     or \"server\"; the arrival time (Telegraf's \"gather\") is not a sample's \
                     time"
                ));
            }
        },
        sampling_interval: secs(raw.sampling_interval, 0.0, "sampling_interval")?,
        publishing_interval,
        queue_size: raw.queue_size.unwrap_or(1000).max(1),
        silent_after: secs(raw.silent_after, 10.0, "silent_after")?,
        idle_timeout,
        backoff: (
            secs(raw.reconnect_min, 0.1, "reconnect_min")?,
            secs(raw.reconnect_max, 10.0, "reconnect_max")?,
        ),
    })
}

/// The alignment rule, its reorder window spanning a publication: a server lists a
/// publication's values node by node and may split it over several messages (the client
/// sorts a message's values by time, not across messages), so one node's values can arrive
/// up to a publishing interval of source time after another's. Default: the publishing
/// interval plus one period; a window shorter than the publishing interval is refused (its
/// rows would drop many values as late).
fn rule(raw: &Raw, publishing: f64) -> Result<AlignRule, String> {
    let mut rule = align_rule(raw.align.as_ref())?;
    match raw.align.as_ref().and_then(|a| a.reorder_window) {
        None => rule.reorder_window = publishing + rule.period,
        Some(r) if r < publishing => {
            return Err(format!(
                "source.align.reorder_window: {r} s is shorter than the publishing interval \
                 ({publishing} s): a server may split a publication, its values node by \
                 node, over several messages, so many would arrive late; give at least \
                 {publishing} s (the default is the publishing interval plus one period)"
            ));
        }
        Some(_) => {}
    }
    Ok(rule)
}

type Security = (String, SecurityMode, Option<(PathBuf, PathBuf)>);

/// The policy and mode, stated (no `auto`: a server could offer `None` first), consistent,
/// with the certificate files a signing policy needs.
fn security(raw: &Raw) -> Result<Security, String> {
    let policy = raw.security_policy.clone().unwrap_or_else(|| "None".into());
    if !POLICIES.contains(&policy.as_str()) {
        return Err(format!(
            "source.security_policy: \"{policy}\": use one of {} (\"auto\" is refused: say which)",
            POLICIES.join(", ")
        ));
    }
    let mode = match raw.security_mode.as_deref().unwrap_or("None") {
        "None" => SecurityMode::None,
        "Sign" => SecurityMode::Sign,
        "SignAndEncrypt" => SecurityMode::SignAndEncrypt,
        other => {
            return Err(format!(
                "source.security_mode: \"{other}\": use None, Sign or SignAndEncrypt (\"auto\" \
                 is refused: say which)"
            ));
        }
    };
    if (policy == "None") != (mode == SecurityMode::None) {
        return Err(format!(
            "source.security_mode: {mode:?} does not go with security_policy \"{policy}\": \
             the policy None goes with the mode None, a signing policy with Sign or \
             SignAndEncrypt"
        ));
    }
    let files = match (&raw.certificate, &raw.private_key) {
        (Some(c), Some(k)) => Some((PathBuf::from(c), PathBuf::from(k))),
        (None, None) => None,
        _ => return Err("source: certificate and private_key go together".into()),
    };
    if mode != SecurityMode::None && files.is_none() {
        return Err(format!(
            "source.certificate: security_mode {mode:?} needs the client's certificate and \
             private_key (DER or PEM files)"
        ));
    }
    Ok((policy, mode, files))
}

fn credentials(raw: &Raw) -> Result<Option<(String, Secret)>, String> {
    match raw.auth_method.as_deref().unwrap_or("Anonymous") {
        "Anonymous" => {
            if raw.username.is_some() || raw.password.is_some() || raw.password_file.is_some() {
                return Err("source.auth_method: a username or password is given; set \
                            auth_method = \"UserName\""
                    .into());
            }
            Ok(None)
        }
        "UserName" => {
            let c = user_password(
                raw.username.as_deref(),
                raw.password.as_deref(),
                raw.password_file.as_deref(),
            )?;
            if c.is_none() {
                return Err("source.username: auth_method \"UserName\" needs a username".into());
            }
            Ok(c)
        }
        other => Err(format!("source.auth_method: \"{other}\": use Anonymous or UserName")),
    }
}

/// One node per column, in the row's order.
fn nodes(raw: &[RawNode], columns: &Columns) -> Result<Vec<Node>, String> {
    let mut given = Vec::with_capacity(raw.len());
    for (i, n) in raw.iter().enumerate() {
        let column = match (&n.column, &n.name) {
            (Some(c), None) | (None, Some(c)) => c.clone(),
            _ => return Err(format!("source.node[{i}]: give its column (or Telegraf's name)")),
        };
        given.push((i, column, node_id(i, n)?));
    }
    let wanted: Vec<&String> = columns.outputs.iter().chain(&columns.inputs).collect();
    let mut nodes = Vec::with_capacity(wanted.len());
    for name in &wanted {
        let found: Vec<&(usize, String, String)> =
            given.iter().filter(|(_, c, _)| &c == name).collect();
        match found.as_slice() {
            [(_, column, id)] => nodes.push(Node { column: column.clone(), id: id.clone() }),
            [] => return Err(format!("source.node: no node for the column `{name}`")),
            _ => return Err(format!("source.node: the column `{name}` is given twice")),
        }
    }
    if let Some((i, c, _)) = given.iter().find(|(_, c, _)| !wanted.contains(&c)) {
        return Err(format!("source.node[{i}]: `{c}` is not a column of [columns]"));
    }
    Ok(nodes)
}

/// A node's id in text form, from `node_id` or Telegraf's four keys.
fn node_id(i: usize, n: &RawNode) -> Result<String, String> {
    match (&n.node_id, n.namespace, &n.identifier_type, &n.identifier) {
        (Some(id), None, None, None) => {
            if !id.contains(['s', 'i', 'g', 'b']) || !id.contains('=') {
                return Err(format!("source.node[{i}].node_id: `{id}` is not ns=N;s=NAME"));
            }
            Ok(id.clone())
        }
        (None, Some(ns), Some(kind), Some(ident)) => {
            if !matches!(kind.as_str(), "s" | "i" | "g" | "b") {
                return Err(format!(
                    "source.node[{i}].identifier_type: \"{kind}\": use s, i, g or b"
                ));
            }
            if kind == "i" && ident.parse::<u32>().is_err() {
                return Err(format!("source.node[{i}].identifier: `{ident}` is not a number"));
            }
            Ok(format!("ns={ns};{kind}={ident}"))
        }
        _ => Err(format!(
            "source.node[{i}]: give node_id = \"ns=1;s=NAME\", or namespace, identifier_type \
             and identifier"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn columns() -> Columns {
        toml::from_str("time = \"t\"\noutputs = [\"y\"]\ninputs = [\"u\"]").unwrap()
    }

    const NODES: &str = "[[node]]\ncolumn = \"y\"\nnamespace = 1\nidentifier_type = \"s\"\n\
        identifier = \"p.y\"\n[[node]]\nname = \"u\"\nnode_id = \"ns=1;s=p.u\"\n\
        [align]\nperiod = 0.01\n";

    fn parse_text(head: &str) -> Result<OpcUaConfig, String> {
        let text = format!("kind = \"opcua\"\nendpoint = \"opc.tcp://h:4840\"\n{head}{NODES}");
        parse(&toml::from_str(&text).unwrap(), &columns())
    }

    #[test]
    fn nodes_follow_the_columns_in_either_form() {
        let c = parse_text("").unwrap();
        let ids: Vec<&str> = c.nodes.iter().map(|n| n.id.as_str()).collect();
        assert_eq!(ids, ["ns=1;s=p.y", "ns=1;s=p.u"]);
        assert_eq!((c.security_mode, c.timestamp), (SecurityMode::None, Timestamp::Source));
        assert_eq!((c.rule.max_age, c.rule.reorder_window), (0.02, 0.1 + 0.01));
        let e = parse_text("publishing_interval = 0.5\n").map(|c| c.rule.reorder_window);
        assert_eq!(e, Ok(0.5 + 0.01));
    }

    #[test]
    fn a_reorder_window_shorter_than_a_publication_is_refused() {
        let text = format!(
            "kind = \"opcua\"\nendpoint = \"opc.tcp://h:4840\"\npublishing_interval = 0.2\n{}",
            NODES.replace("period = 0.01", "period = 0.01\nreorder_window = 0.1")
        );
        let e = parse(&toml::from_str(&text).unwrap(), &columns()).unwrap_err();
        assert!(e.contains("shorter than the publishing interval"), "{e}");
    }

    #[test]
    fn security_is_stated_consistent_and_has_its_files() {
        let e = parse_text("security_policy = \"auto\"\n").unwrap_err();
        assert!(e.contains("auto"), "{e}");
        let e = parse_text("security_policy = \"Basic256Sha256\"\n").unwrap_err();
        assert!(e.contains("does not go with"), "{e}");
        let sae = "security_policy = \"Basic256Sha256\"\nsecurity_mode = \"SignAndEncrypt\"\n";
        let e = parse_text(sae).unwrap_err();
        assert!(e.contains("certificate"), "{e}");
        let ok = parse_text(&format!("{sae}certificate = \"c.der\"\nprivate_key = \"k.pem\"\n"));
        assert_eq!(ok.unwrap().security_mode, SecurityMode::SignAndEncrypt);
    }

    #[test]
    fn a_password_is_never_literal_and_gather_time_is_refused() {
        let e = parse_text("auth_method = \"UserName\"\nusername = \"op\"\npassword = \"pw1\"\n")
            .unwrap_err();
        assert!(e.contains("${VAR}") && !e.contains("pw1"), "{e}");
        let e = parse_text("username = \"op\"\n").unwrap_err();
        assert!(e.contains("UserName"), "{e}");
        let e = parse_text("timestamp = \"gather\"\n").unwrap_err();
        assert!(e.contains("not a sample's time"), "{e}");
        let e = parse(
            &toml::from_str("kind = \"opcua\"\nendpoint = \"opc.tcp://a:b@h:1\"\n").unwrap(),
            &columns(),
        )
        .unwrap_err();
        assert!(e.contains("refused"), "{e}");
    }
}
