//! The MQTT client's connection: its options from the `[source]` settings, the thread that
//! drives it, and TLS.

use std::sync::mpsc::Receiver;
use std::thread::JoinHandle;
use std::time::Duration;

use rumqttc::{Client, ConnectionError, Event, MqttOptions, Packet};
use streamcert_pipeline::CliError;

use crate::config::MqttConfig;

/// A connection's events, handed over by the thread that drives it.
pub(super) type Events = Receiver<Result<Event, ConnectionError>>;

/// A client for the `i`-th server, the events of its connection and the thread that drives
/// it. The thread polls the connection without pause and hands every event over as it comes,
/// so that acknowledgements go out as soon as they are asked for, whatever the certifier is
/// doing (memory then holds what the broker sends ahead of the certifier, where a bounded
/// hand-over would hold the acknowledgements back and have the broker deliver again, after a
/// crash, messages a checkpoint already holds). After an error the thread waits, doubling
/// from `reconnect_min` to `reconnect_max`, before the client reconnects. It ends when the
/// client disconnects or is dropped.
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
    // Packets up to 16 times the payload limit are read whole, so that an oversized payload
    // is named and counted (a larger packet is the client's protocol error: a reconnection).
    o.set_max_packet_size(cfg.max_payload.saturating_mul(16).max(1 << 20), 64 * 1024);
    if let Some((user, password)) = &cfg.credentials {
        o.set_credentials(user.clone(), password.0.clone());
    }
    if server.tls || cfg.tls.is_some() {
        o.set_transport(rumqttc::Transport::Tls(tls(cfg)?));
    }
    let (client, mut connection) = Client::new(o, cfg.max_unacked.max(16) * 4);
    let (tx, rx) = std::sync::mpsc::channel();
    let backoff = cfg.backoff;
    let driver = std::thread::spawn(move || {
        let mut wait = backoff.0;
        while let Ok(event) = connection.recv() {
            let failed = event.is_err();
            match &event {
                Ok(Event::Incoming(Packet::ConnAck(_))) => wait = backoff.0,
                Ok(Event::Outgoing(rumqttc::Outgoing::Disconnect)) => break,
                _ => {}
            }
            if tx.send(event).is_err() {
                break;
            }
            if failed {
                std::thread::sleep(wait);
                wait = (wait * 2).min(backoff.1);
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
