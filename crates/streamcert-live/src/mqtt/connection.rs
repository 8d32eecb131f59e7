//! The MQTT client's connection: its options from the `[source]` settings, the thread that
//! drives it, and TLS.

use std::sync::mpsc::Receiver;
use std::thread::JoinHandle;
use std::time::Duration;

use rumqttc::{Client, ConnectionError, Event, MqttOptions, Packet, StateError};
use streamcert_pipeline::CliError;

use crate::config::MqttConfig;

/// Failures to read a packet in a row, with no message taken between them, after which the
/// packet is a poison message and the session is discarded.
pub const POISON_TRIES: u32 = 3;

/// What the thread that drives a connection hands over.
pub(super) enum Driven {
    /// An event of the connection.
    Event(Event),
    /// The connection was lost or refused; the thread waits, then tries again.
    Lost(ConnectionError),
    /// A packet the client cannot read broke the connection [`POISON_TRIES`] times: the next
    /// connection discards the session (why, in words).
    Poison(String),
}

/// A connection's events, handed over by the thread that drives it.
pub(super) type Events = Receiver<Driven>;

/// A client for the `i`-th server, the events of its connection and the thread that drives
/// it. The thread polls the connection without pause and hands every event over as it comes,
/// so that acknowledgements go out as soon as they are asked for, whatever the certifier is
/// doing (memory then holds what the broker sends ahead of the certifier, where a bounded
/// hand-over would hold the acknowledgements back and have the broker deliver again, after a
/// crash, messages a checkpoint already holds). After an error the thread waits, doubling
/// from `reconnect_min` to `reconnect_max`, before the client reconnects. It ends when the
/// client disconnects or is dropped.
///
/// **Poison messages.** A packet the client cannot read (one above `max_packet`) breaks the
/// connection before its packet id is known, so it cannot be acknowledged, and a persistent
/// session has the broker deliver it again at every reconnection. After [`POISON_TRIES`] such
/// failures in a row with no message read between them, the thread connects once with a
/// clean session, which has the broker discard the session and its queue (the poison message
/// with it), then connects again with a persistent session: a new one, so messages queued
/// with the poison message are lost, and the source declares a gap.
pub(super) fn connect(
    cfg: &MqttConfig,
    i: usize,
    manual_acks: bool,
) -> Result<(Client, Events, JoinHandle<()>), CliError> {
    let server = &cfg.servers[i];
    let mut o = MqttOptions::new(cfg.client_id.clone(), server.host.clone(), server.port);
    o.set_clean_session(!cfg.persistent_session);
    o.set_keep_alive(Duration::from_secs(10));
    o.set_manual_acks(manual_acks);
    // Packets up to `max_packet` (by default MQTT's largest) are read whole, so that an
    // oversized payload is named, counted and acknowledged; a larger one is a poison message.
    o.set_max_packet_size(cfg.max_packet, 64 * 1024);
    if let Some((user, password)) = &cfg.credentials {
        o.set_credentials(user.clone(), password.0.clone());
    }
    if server.tls || cfg.tls.is_some() {
        o.set_transport(rumqttc::Transport::Tls(tls(cfg)?));
    }
    let (client, mut connection) = Client::new(o, cfg.max_unacked.max(16) * 4);
    let (tx, rx) = std::sync::mpsc::channel();
    let backoff = cfg.backoff;
    let persistent = cfg.persistent_session;
    let driver = std::thread::spawn(move || {
        let mut wait = backoff.0;
        // Unreadable packets in a row, and whether the connection being made discards the
        // session to pass over one.
        let (mut unreadable, mut purging) = (0u32, false);
        while let Ok(event) = connection.recv() {
            let driven = match event {
                Ok(Event::Incoming(Packet::ConnAck(_))) if purging => {
                    // The clean session discarded the old one: drop this connection (the
                    // broker forgets a clean session with it) and connect again, persistent.
                    purging = false;
                    connection.eventloop.mqtt_options.set_clean_session(!persistent);
                    connection.eventloop.clean();
                    continue;
                }
                Ok(event) => {
                    match &event {
                        Event::Incoming(Packet::ConnAck(_)) => wait = backoff.0,
                        Event::Incoming(Packet::Publish(_)) => unreadable = 0,
                        Event::Outgoing(rumqttc::Outgoing::Disconnect) => break,
                        _ => {}
                    }
                    Driven::Event(event)
                }
                Err(e) => {
                    let poison =
                        matches!(e, ConnectionError::MqttState(StateError::Deserialization(_)));
                    unreadable = if poison { unreadable + 1 } else { 0 };
                    let what = e.to_string();
                    if tx.send(Driven::Lost(e)).is_err() {
                        break;
                    }
                    if unreadable >= POISON_TRIES {
                        unreadable = 0;
                        // A clean session's queue goes with its connection: only a
                        // persistent one is discarded.
                        if persistent {
                            purging = true;
                            connection.eventloop.mqtt_options.set_clean_session(true);
                        }
                        let why = format!(
                            "a packet the client cannot read broke the connection \
                             {POISON_TRIES} times in a row ({what})"
                        );
                        if tx.send(Driven::Poison(why)).is_err() {
                            break;
                        }
                    }
                    std::thread::sleep(wait);
                    wait = (wait * 2).min(backoff.1);
                    continue;
                }
            };
            if tx.send(driven).is_err() {
                break;
            }
        }
    });
    Ok((client, rx, driver))
}

/// The TLS configuration from the PEM files (rustls with the ring provider).
fn tls(cfg: &MqttConfig) -> Result<rumqttc::TlsConfiguration, CliError> {
    tls_from(cfg.tls.as_ref(), "source")
}

/// The TLS configuration from the PEM files of the `section` (`source`, `verdict`).
pub(crate) fn tls_from(
    files: Option<&crate::config::Tls>,
    section: &str,
) -> Result<rumqttc::TlsConfiguration, CliError> {
    let files = files.ok_or_else(|| CliError::Config {
        path: format!("[{section}]"),
        message: format!("{section}.tls_ca: a TLS broker needs the CA certificate"),
    })?;
    let read = |p: &std::path::Path| {
        std::fs::read(p).map_err(|e| CliError::io(format!("reading {}", p.display()), e))
    };
    // Installing the process's crypto provider a second time is refused, harmlessly.
    let _ = rustls::crypto::ring::default_provider().install_default();
    let client_auth = match &files.client {
        Some((cert, key)) => Some((read(cert)?, read(key)?)),
        None => None,
    };
    Ok(rumqttc::TlsConfiguration::Simple { ca: read(&files.ca)?, alpn: None, client_auth })
}
