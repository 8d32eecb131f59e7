//! The verdict on an MQTT topic, for interlocks: the `[verdict]` section of a `certify` or
//! `network` configuration, and the publisher of the messages `streamcert-serve` builds
//! (schema `streamcert.verdict/1`).
//!
//! ```toml
//! [verdict]
//! servers = ["tcp://127.0.0.1:1883"]   # one broker
//! topic = "plant/loop7/verdict"
//! client_id = "streamcert-verdict-loop7"
//! qos = 1                              # 0, 1 (default) or 2
//! # username = "${MQTT_USER}"  password = "${MQTT_PASSWORD}"  (or password_file)
//! # tls_ca = "ca.pem"  tls_cert = "client.pem"  tls_key = "client.key"
//! ```
//!
//! Every message is published **retained**, so that a subscriber that connects (or an
//! interlock that restarts) reads the current verdict at once. The first message (the gate
//! closed, no sample yet) replaces whatever an earlier run left retained. The connection's
//! **last will** is the first message with the gate closed and the reason `offline`: if the
//! certifier dies or its connection is lost without a word, the broker publishes it,
//! retained, in its place. After a reconnection the current verdict is published again (its
//! `sequence` tells a subscriber it has seen it). Credentials follow the `[source]` rules:
//! `${VAR}` or a file, never a literal password, never logged.

use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use rumqttc::{Client, Event, LastWill, MqttOptions, Packet, QoS};
use serde::Deserialize;
use streamcert_pipeline::CliError;

use crate::config::{Secret, Server, Tls, server, tls_files, user_password};

/// A validated `[verdict]` section.
#[derive(Debug, Clone)]
pub struct VerdictConfig {
    /// The broker.
    pub server: Server,
    /// The topic every message goes to, retained.
    pub topic: String,
    /// The client id.
    pub client_id: String,
    /// The quality of service: 0, 1 (default) or 2.
    pub qos: u8,
    /// Credentials, resolved from the environment or a file.
    pub credentials: Option<(String, Secret)>,
    /// TLS files.
    pub tls: Option<Tls>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    servers: Vec<String>,
    topic: String,
    client_id: Option<String>,
    qos: Option<u8>,
    username: Option<String>,
    password: Option<String>,
    password_file: Option<String>,
    tls_ca: Option<String>,
    tls_cert: Option<String>,
    tls_key: Option<String>,
}

/// Parse and check the `[verdict]` table; `name` (the run's) makes the default client id
/// `streamcert-verdict-<name>`.
///
/// # Errors
/// What is wrong, naming the key (`verdict.topic`, `verdict.servers`, ...).
pub fn parse_verdict(table: &toml::Table, name: &str) -> Result<VerdictConfig, String> {
    let section = |e: String| e.replacen("source", "verdict", 1);
    let raw: Raw = toml::Value::Table(table.clone())
        .try_into()
        .map_err(|e: toml::de::Error| format!("[verdict]: {}", e.message()))?;
    let server = match raw.servers.as_slice() {
        [one] => server(one).map_err(section)?,
        _ => return Err("verdict.servers: give one broker, e.g. [\"tcp://127.0.0.1:1883\"]".into()),
    };
    if raw.topic.is_empty() || raw.topic.contains(['+', '#']) {
        return Err(format!("verdict.topic: `{}` is not a topic to publish to", raw.topic));
    }
    let qos = raw.qos.unwrap_or(1);
    if qos > 2 {
        return Err(format!("verdict.qos: {qos}: use 0, 1 or 2"));
    }
    let credentials = user_password(
        raw.username.as_deref(),
        raw.password.as_deref(),
        raw.password_file.as_deref(),
    )
    .map_err(section)?;
    let tls = tls_files(raw.tls_ca.as_ref(), raw.tls_cert.as_ref(), raw.tls_key.as_ref())
        .map_err(section)?;
    Ok(VerdictConfig {
        server,
        topic: raw.topic,
        client_id: raw.client_id.unwrap_or_else(|| format!("streamcert-verdict-{name}")),
        qos,
        credentials,
        tls,
    })
}

/// A live connection: its client, the latest payload (published again after a
/// reconnection), the thread that drives it and the signal that the thread ended.
struct Connection {
    client: Client,
    latest: Arc<Mutex<Vec<u8>>>,
    driver: JoinHandle<()>,
    done: Receiver<()>,
}

/// Publishes verdict messages to the `[verdict]` topic (module docs). Connects at the first
/// message, whose offline form is the connection's last will.
pub struct VerdictPublisher {
    cfg: VerdictConfig,
    tls: Option<rumqttc::TlsConfiguration>,
    connection: Option<Connection>,
}

impl VerdictPublisher {
    /// A publisher for `cfg`; its TLS files are read now, so that a missing one is a
    /// configuration error before the run starts.
    ///
    /// # Errors
    /// A TLS file that cannot be read.
    pub fn new(cfg: VerdictConfig) -> Result<Self, CliError> {
        let tls = if cfg.server.tls || cfg.tls.is_some() {
            Some(crate::mqtt::connection::tls_from(cfg.tls.as_ref(), "verdict")?)
        } else {
            None
        };
        Ok(Self { cfg, tls, connection: None })
    }

    /// Publish `payload`, retained; the first call connects with `will` as the last will.
    pub fn publish(&mut self, payload: &[u8], will: &[u8]) {
        let qos = qos(self.cfg.qos);
        if self.connection.is_none() {
            self.connection = Some(self.connect(will));
        }
        let Some(Connection { client, latest, .. }) = &self.connection else { return };
        if let Ok(mut l) = latest.lock() {
            l.clear();
            l.extend_from_slice(payload);
        }
        // Queued for the connection's thread; while the broker is away, the message after the
        // reconnection is the latest one.
        let _ = client.try_publish(self.cfg.topic.clone(), qos, true, payload.to_vec());
    }

    fn connect(&self, will: &[u8]) -> Connection {
        let c = &self.cfg;
        let mut o = MqttOptions::new(c.client_id.clone(), c.server.host.clone(), c.server.port);
        o.set_keep_alive(Duration::from_secs(10));
        o.set_last_will(LastWill::new(c.topic.clone(), will.to_vec(), qos(c.qos), true));
        if let Some((user, password)) = &c.credentials {
            o.set_credentials(user.clone(), password.0.clone());
        }
        if let Some(tls) = &self.tls {
            o.set_transport(rumqttc::Transport::Tls(tls.clone()));
        }
        let (client, mut connection) = Client::new(o, 64);
        let latest = Arc::new(Mutex::new(Vec::new()));
        let (topic, q, again, republish) =
            (c.topic.clone(), qos(c.qos), latest.clone(), client.clone());
        let (done_tx, done) = std::sync::mpsc::channel();
        let driver = std::thread::spawn(move || {
            let mut wait = Duration::from_millis(100);
            let mut first = true;
            for event in connection.iter() {
                match event {
                    Ok(Event::Incoming(Packet::ConnAck(_))) => {
                        wait = Duration::from_millis(100);
                        // The first connection publishes what is queued; a later one
                        // publishes the current verdict again.
                        if !first {
                            let payload = again.lock().map(|l| l.clone()).unwrap_or_default();
                            let _ = republish.try_publish(topic.clone(), q, true, payload);
                        }
                        first = false;
                    }
                    Ok(Event::Outgoing(rumqttc::Outgoing::Disconnect)) => break,
                    Ok(_) => {}
                    Err(_) => {
                        std::thread::sleep(wait);
                        wait = (wait * 2).min(Duration::from_secs(10));
                    }
                }
            }
            let _ = done_tx.send(());
        });
        Connection { client, latest, driver, done }
    }
}

impl Drop for VerdictPublisher {
    /// Disconnect after the messages queued (the last one, `ended`, among them), waiting at
    /// most 2 s for a broker that is away.
    fn drop(&mut self) {
        if let Some(Connection { client, driver, done, .. }) = self.connection.take() {
            let _ = client.try_disconnect();
            match done.recv_timeout(Duration::from_secs(2)) {
                Ok(()) | Err(RecvTimeoutError::Disconnected) => {
                    let _ = driver.join();
                }
                Err(RecvTimeoutError::Timeout) => {}
            }
        }
    }
}

fn qos(q: u8) -> QoS {
    match q {
        0 => QoS::AtMostOnce,
        1 => QoS::AtLeastOnce,
        _ => QoS::ExactlyOnce,
    }
}
