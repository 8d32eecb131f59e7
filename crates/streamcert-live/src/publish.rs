//! A plant's rows published to an MQTT broker, at real-time pace or faster: the live plant
//! of `streamcert simulate g5 --publish`, and the publisher of the tests.
//!
//! Two layouts, the two a [`crate::config`] source reads: a whole row per message (a JSON
//! object with every column, on one topic), or one signal per topic
//! (`{topic}/{column}`, each `{"t": ..., "value": ...}`). Numbers are written in the
//! shortest form that reads back to the same bits, as the CSV of `simulate` is, so the rows a
//! live run certifies are the file's to the bit. QoS 1: every message is acknowledged by the
//! broker before [`publish`] returns.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use rumqttc::{Client, Event, MqttOptions, Packet, QoS};
use streamcert_pipeline::CliError;

use crate::config::Server;

/// How rows are published.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// One JSON object per row, on the topic.
    Rows,
    /// One `{"t", "value"}` object per column and row, on `{topic}/{column}`.
    Signals,
}

/// What [`publish`] is told.
#[derive(Debug, Clone)]
pub struct PublishOptions {
    /// The broker.
    pub server: Server,
    /// The topic (the prefix of each signal's topic with [`Layout::Signals`]).
    pub topic: String,
    /// The client id.
    pub client_id: String,
    /// The layout.
    pub layout: Layout,
    /// Seconds of wall-clock time per second of data: 1 is real time, 0 as fast as the
    /// broker takes them.
    pub pace: f64,
}

/// Parse `mqtt://host:port/topic` (or `tcp://`): the broker and the topic.
///
/// # Errors
/// An address without a scheme, host or topic.
pub fn parse_url(url: &str) -> Result<(Server, String), String> {
    let (scheme, rest) =
        url.split_once("://").ok_or_else(|| format!("`{url}`: expected mqtt://host:port/topic"))?;
    if !matches!(scheme, "mqtt" | "tcp") {
        return Err(format!("`{url}`: the scheme must be mqtt or tcp"));
    }
    let (addr, topic) =
        rest.split_once('/').ok_or_else(|| format!("`{url}`: no topic after the address"))?;
    let (host, port) = match addr.rsplit_once(':') {
        Some((h, p)) => (h, p.parse().map_err(|_| format!("`{url}`: the port is not a number"))?),
        None => (addr, 1883),
    };
    if host.is_empty() || topic.is_empty() {
        return Err(format!("`{url}`: expected mqtt://host:port/topic"));
    }
    Ok((Server { host: host.into(), port, tls: false }, topic.into()))
}

/// Publish `rows` (each `values[i]` the column `columns[i]`; `columns[time]` the time) and
/// wait until the broker has acknowledged every message. Returns the number of messages.
///
/// # Errors
/// A connection that fails before every message is acknowledged (after retries for 30 s).
pub fn publish<I>(
    opts: &PublishOptions,
    columns: &[String],
    time: usize,
    rows: I,
) -> Result<u64, CliError>
where
    I: IntoIterator<Item = Vec<f64>>,
{
    let mut o =
        MqttOptions::new(opts.client_id.clone(), opts.server.host.clone(), opts.server.port);
    o.set_keep_alive(Duration::from_secs(10));
    let (client, mut connection) = Client::new(o, 256);
    // The connection is driven on its own thread; it counts the broker's acknowledgements.
    let acked = Arc::new(AtomicU64::new(0));
    let counter = Arc::clone(&acked);
    let driver = std::thread::spawn(move || {
        let mut failing_since = None::<Instant>;
        for event in connection.iter() {
            match event {
                Ok(Event::Incoming(Packet::PubAck(_))) => {
                    counter.fetch_add(1, Ordering::Relaxed);
                }
                Ok(Event::Outgoing(rumqttc::Outgoing::Disconnect)) => break,
                Ok(_) => failing_since = None,
                Err(e) => {
                    let since = *failing_since.get_or_insert_with(Instant::now);
                    if since.elapsed() > Duration::from_secs(30) {
                        return Err(format!("the broker did not answer for 30 s: {e}"));
                    }
                    std::thread::sleep(Duration::from_millis(100));
                }
            }
        }
        Ok(())
    });
    let io = |e: rumqttc::ClientError| CliError::io("publishing", std::io::Error::other(e));
    let start = Instant::now();
    let mut first: Option<f64> = None;
    let mut sent = 0u64;
    let mut text = String::new();
    for row in rows {
        let t = row[time];
        let t0 = *first.get_or_insert(t);
        if opts.pace > 0.0 {
            let due = Duration::from_secs_f64(((t - t0) * opts.pace).max(0.0));
            if let Some(wait) = due.checked_sub(start.elapsed()) {
                std::thread::sleep(wait);
            }
        }
        match opts.layout {
            Layout::Rows => {
                text.clear();
                json_row(&mut text, columns, &row);
                client
                    .publish(opts.topic.clone(), QoS::AtLeastOnce, false, text.clone())
                    .map_err(io)?;
                sent += 1;
            }
            Layout::Signals => {
                for (i, (name, v)) in columns.iter().zip(&row).enumerate() {
                    if i == time {
                        continue;
                    }
                    let payload = format!("{{\"t\":{},\"value\":{}}}", Num(t), Num(*v));
                    let topic = format!("{}/{name}", opts.topic);
                    client.publish(topic, QoS::AtLeastOnce, false, payload).map_err(io)?;
                    sent += 1;
                }
            }
        }
    }
    wait_for_acks(client, driver, &acked, sent)
}

/// Wait until the broker has acknowledged `sent` messages, then disconnect.
fn wait_for_acks(
    client: Client,
    driver: std::thread::JoinHandle<Result<(), String>>,
    acked: &AtomicU64,
    sent: u64,
) -> Result<u64, CliError> {
    let fail = |m: String| CliError::io("publishing", std::io::Error::other(m));
    while acked.load(Ordering::Relaxed) < sent && !driver.is_finished() {
        std::thread::sleep(Duration::from_millis(5));
    }
    let _ = client.disconnect();
    // Without a client the connection's iterator ends, whatever the broker does.
    drop(client);
    driver.join().map_err(|_| fail("the connection thread failed".into()))?.map_err(fail)?;
    let acked = acked.load(Ordering::Relaxed);
    if acked < sent {
        return Err(fail(format!("{acked} of {sent} messages acknowledged")));
    }
    Ok(sent)
}
/// A row as a JSON object, numbers in their shortest round-trip form.
fn json_row(out: &mut String, columns: &[String], row: &[f64]) {
    use std::fmt::Write;
    out.push('{');
    for (i, (name, v)) in columns.iter().zip(row).enumerate() {
        if i > 0 {
            out.push(',');
        }
        let _ = write!(out, "\"{name}\":{}", Num(*v));
    }
    out.push('}');
}

/// A finite number in the shortest form that reads back to the same bits (Rust's `{}` of
/// `f64`, as the CSV of `simulate` writes it); JSON has no spelling for the rest, so they are
/// written `null` (a reader refuses them).
struct Num(f64);

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.0.is_finite() { write!(f, "{}", self.0) } else { f.write_str("null") }
    }
}
