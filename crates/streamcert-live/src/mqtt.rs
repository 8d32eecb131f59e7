//! An MQTT subscription as a [`Source`]: rumqttc's client, its connection driven on a thread
//! of its own, the messages taken on the calling thread.
//!
//! - **Delivery**: QoS 1 on a persistent session (`clean_session = false`, a stable client id),
//!   so the broker queues what is published while streamcert is away. Without a checkpoint,
//!   each message is acknowledged as it arrives. With one, acknowledgements wait until the
//!   rows they carried are in a written checkpoint ([`Source::committed`]); at most
//!   `max_unacked` wait ([`Source::commit_due`] asks for a checkpoint then), so a process
//!   killed at any instant is redelivered every message its last checkpoint lacks (and, of
//!   what it holds, at most the acknowledgements not yet sent), and `--resume` passes over
//!   what it already holds by time.
//! - **Outages**: a lost connection is retried with a doubling wait (`reconnect_min` to
//!   `reconnect_max`), the next broker of `servers` each time; the process keeps running. On
//!   reconnection the broker says whether it kept the session: if it did, what was published
//!   meanwhile arrives and the stream goes on; if not, messages may be lost, so a gap is
//!   yielded ([`Next::Gap`]) and the certifier restarts its windows.
//! - **Bad payloads**: counted by kind, reported with the topic and an excerpt, yielded as
//!   [`Next::Bad`] (every gate closes for that sample, as a skipped row in a file), and
//!   acknowledged as any message is. That holds for a payload of any size: the client reads
//!   every packet up to `max_packet` (by default MQTT's largest), and one above
//!   `max_payload` is refused unread (`oversized`).
//! - **Poison messages**: a packet above `max_packet` cannot be read, so it cannot be
//!   acknowledged, and breaks the connection; after [`POISON_TRIES`] such failures in a row
//!   the session is discarded (the broker drops its queue with it), counted as `poison`,
//!   named, and a gap is yielded; the run goes on. A retained message the client cannot read
//!   comes back at every subscription: a second poison with no message read since the first
//!   ends the source with an error that says so, rather than reconnect without end.
//! - **Retained messages** come again at every subscription: one already taken (the same
//!   payload on the same topic, also across a checkpoint) is passed over as `redelivered`.
//! - **Counts**: every reconnection attempt and every reconnection is counted as it happens,
//!   and the source yields [`Next::Idle`] while it waits, so that a watcher's counts are
//!   current while no row comes.
//! - **Silence**: a topic that delivered nothing within `silent_after` is named on stderr
//!   and in the summary.

use std::collections::HashMap;
use std::sync::mpsc::RecvTimeoutError;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

pub use connection::POISON_TRIES;
use rumqttc::{Client, ConnectionError, Event, Packet, Publish, QoS};
use streamcert_pipeline::CliError;
use streamcert_pipeline::input::Sample;
use streamcert_pipeline::source::{Next, Source, SourceReport};

use crate::config::{Layout, MqttConfig, Server};
use crate::rows::{SignalRows, Silence};

pub(crate) mod connection;
mod messages;
use connection::{Driven, Events, connect};

/// How long one wait for the broker lasts before the source checks its clocks (silence,
/// idle timeout).
const POLL: Duration = Duration::from_millis(50);

/// A live MQTT source (see the module docs).
pub struct MqttSource {
    client: Client,
    /// The connection's events, from the thread that drives it, and that thread.
    events: Events,
    driver: Option<JoinHandle<()>>,
    /// Acknowledgements the client's queue had no room for yet, in order.
    to_ack: std::collections::VecDeque<Publish>,
    cfg: MqttConfig,
    report: SourceReport,
    /// With a checkpoint: messages not yet acknowledged, in order of arrival.
    unacked: Vec<Publish>,
    manual_acks: bool,
    /// The last row's time (whole-row topics).
    last_t: Option<f64>,
    /// Per-signal topics: the rows they form, and each topic's signal.
    rows: Option<SignalRows>,
    signal_of: HashMap<String, usize>,
    /// Topics (or filters) and whether each has delivered.
    topics: Vec<(String, bool)>,
    silence: Silence,
    last_message: Instant,
    /// Connection state: ever connected, connected now, the server in use.
    ever_connected: bool,
    connected: bool,
    server: usize,
    /// A gap to yield before anything else.
    gap: Option<String>,
    /// Subscriptions acknowledged since the last request.
    subacks: usize,
    /// Messages received while waiting for the subscriptions.
    early: std::collections::VecDeque<Publish>,
    /// A poison message was passed over and no message has been read since.
    poisoned: bool,
    /// The session was just discarded: the next connection's new session is no surprise.
    purged: bool,
}

impl MqttSource {
    /// Connect (lazily: the first [`next_into`](Source::next_into) does) and subscribe.
    /// `outputs` is the number of outputs (the signals' first columns); `checkpointing`
    /// holds acknowledgements for the checkpoints.
    ///
    /// # Errors
    /// A TLS file that cannot be read.
    pub fn new(cfg: MqttConfig, outputs: usize, checkpointing: bool) -> Result<Self, CliError> {
        let (client, events, driver) = connect(&cfg, 0, checkpointing)?;
        let (rows, signal_of, topics) = match &cfg.layout {
            Layout::Rows { topics, .. } => {
                (None, HashMap::new(), topics.iter().map(|t| (t.clone(), false)).collect())
            }
            Layout::Signals { signals, rule, .. } => {
                let rows = SignalRows::new(signals.len(), outputs, *rule)?;
                let of = signals.iter().enumerate().map(|(i, s)| (s.topic.clone(), i)).collect();
                let topics = signals.iter().map(|s| (s.topic.clone(), false)).collect();
                (Some(rows), of, topics)
            }
        };
        let report = SourceReport { name: describe(&cfg), ..SourceReport::default() };
        let silence = Silence::new(cfg.silent_after);
        let source = Self {
            client,
            events,
            driver: Some(driver),
            to_ack: std::collections::VecDeque::new(),
            cfg,
            report,
            unacked: Vec::new(),
            manual_acks: checkpointing,
            last_t: None,
            rows,
            signal_of,
            topics,
            silence,
            last_message: Instant::now(),
            ever_connected: false,
            connected: false,
            server: 0,
            gap: None,
            early: std::collections::VecDeque::new(),
            subacks: 0,
            poisoned: false,
            purged: false,
        };
        // The subscriptions are asked for once the broker answers ([`Self::event`]): on every
        // connection whose session the broker did not keep.
        Ok(source)
    }

    /// Connect and wait until every topic's subscription is acknowledged, for at most
    /// `timeout`: `true` once subscribed. Messages that arrive meanwhile (a persistent
    /// session's queue) are kept for [`next_into`](Source::next_into). Without this, the first
    /// `next_into` connects; a caller that must not miss messages published from now on
    /// (a test, a script that starts its publisher next) calls it first.
    pub fn wait_subscribed(&mut self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        let mut acked = 0;
        while acked < self.topics.len() && Instant::now() < deadline {
            match self.events.recv_timeout(POLL) {
                Ok(Driven::Event(Event::Incoming(Packet::SubAck(_)))) => {
                    acked += 1;
                    self.subscribed();
                }
                Ok(Driven::Event(Event::Incoming(Packet::Publish(p)))) => self.early.push_back(p),
                Ok(Driven::Event(Event::Incoming(Packet::ConnAck(ack)))) => {
                    if self.connack(ack.session_present).is_err() {
                        return false;
                    }
                }
                Ok(Driven::Lost(e)) => {
                    if self.lost(&e).is_err() {
                        return false;
                    }
                }
                Ok(Driven::Poison(why)) => {
                    if self.poison(why).is_err() {
                        return false;
                    }
                }
                Ok(Driven::Event(_)) | Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return false,
            }
        }
        acked >= self.topics.len()
    }

    /// A subscription acknowledged: once all are, say so on stderr (an operator, or a script,
    /// knows from then on that nothing published is missed).
    fn subscribed(&mut self) {
        self.subacks += 1;
        if self.subacks == self.topics.len() {
            // The idle and silence clocks start once the source can receive (a site's source
            // is opened before its peers are all up).
            self.last_message = Instant::now();
            self.silence.restart();
            let topics: Vec<&str> = self.topics.iter().map(|(t, _)| t.as_str()).collect();
            eprintln!("source: {}: subscribed to {}", self.report.name, topics.join(", "));
        }
    }

    /// Ask for the topics (queued until the connection is up).
    fn subscribe(&mut self) -> Result<(), CliError> {
        self.subacks = 0;
        for (topic, _) in &self.topics {
            self.client.subscribe(topic.clone(), QoS::AtLeastOnce).map_err(client_error)?;
        }
        Ok(())
    }

    /// The broker accepted a connection. After an outage, a broker that did not keep the
    /// session may have lost messages: a gap. The topics are asked for on every connection
    /// (asking again for a kept subscription changes nothing; a changed configuration's
    /// topics are taken).
    fn connack(&mut self, session_present: bool) -> Result<(), CliError> {
        if self.ever_connected {
            self.report.reconnects += 1;
        }
        if std::mem::take(&mut self.purged) {
            // The gap was declared when the session was discarded.
        } else if self.ever_connected && !session_present {
            self.gap = Some(format!(
                "the broker {} did not keep the session: messages published during the \
                 outage may be lost",
                self.cfg.servers[self.server]
            ));
        }
        self.ever_connected = true;
        self.connected = true;
        self.subscribe()
    }

    /// A connection event: `Some` to yield.
    fn event(&mut self, event: Event, s: &mut Sample) -> Result<Option<Next>, CliError> {
        match event {
            Event::Incoming(Packet::ConnAck(ack)) => {
                self.connack(ack.session_present)?;
                Ok(None)
            }
            Event::Incoming(Packet::Publish(p)) => Ok(self.message(p, s)),
            Event::Incoming(Packet::SubAck(_)) => {
                self.subscribed();
                Ok(None)
            }
            _ => Ok(None),
        }
    }

    /// A lost or refused connection: counted as a reconnection attempt and reported (the
    /// connection's thread waits before trying again); with several brokers, the next is
    /// tried.
    fn lost(&mut self, e: &ConnectionError) -> Result<(), CliError> {
        self.report.reconnect_attempts += 1;
        self.connected = false;
        // Unacknowledged messages belong to the session: redelivered if the broker keeps it.
        self.unacked.clear();
        self.to_ack.clear();
        let server = &self.cfg.servers[self.server];
        eprintln!("source: {server}: {e}; reconnecting");
        if self.cfg.servers.len() > 1 {
            self.server = (self.server + 1) % self.cfg.servers.len();
            let (client, events, driver) = connect(&self.cfg, self.server, self.manual_acks)?;
            self.client = client;
            self.events = events;
            self.driver = Some(driver);
            self.subscribe()?;
        }
        Ok(())
    }

    /// A poison message passed over ([`POISON_TRIES`] failures to read a packet in a row):
    /// counted as `poison`, named, and a gap declared (the session and its queue are
    /// discarded). A second one with no message read since the first is a retained message
    /// that comes back at every subscription: the source ends with an error saying so.
    fn poison(&mut self, why: String) -> Result<(), CliError> {
        let server = self.cfg.servers[self.server].to_string();
        if self.poisoned {
            return Err(CliError::io(
                format!("mqtt {server}"),
                std::io::Error::other(format!(
                    "{why}, again after the session was discarded: a retained message above \
                     max_packet ({} bytes) comes back at every subscription; raise max_packet \
                     or clear the retained message",
                    self.cfg.max_packet
                )),
            ));
        }
        self.poisoned = true;
        self.report.count_bad("poison");
        let what = if self.cfg.persistent_session {
            self.purged = true;
            "the session is discarded so that the broker drops it: messages queued with it are \
             lost"
        } else {
            "the clean session dropped it: messages in flight with it are lost"
        };
        eprintln!("source: {server}: poison message: {why}; {what}");
        self.gap = Some(format!("poison message passed over ({why}): {what}"));
        Ok(())
    }

    /// Send the acknowledgements waiting for room in the client's queue, in order.
    fn flush_acks(&mut self) -> Result<(), CliError> {
        while let Some(p) = self.to_ack.front() {
            match self.client.try_ack(p) {
                Ok(()) => {
                    self.to_ack.pop_front();
                }
                Err(rumqttc::ClientError::TryRequest(_)) => return Ok(()),
                Err(e) => return Err(client_error(e)),
            }
        }
        Ok(())
    }
}

impl Source for MqttSource {
    fn next_into(&mut self, s: &mut Sample) -> Option<Result<Next, CliError>> {
        loop {
            if let Some(why) = self.gap.take() {
                self.report.gaps += 1;
                return Some(Ok(Next::Gap(why)));
            }
            if let Some(next) = self.rows.as_mut().and_then(|r| r.next(s, &mut self.report)) {
                return Some(Ok(next));
            }
            if let Some(p) = self.early.pop_front() {
                match self.message(p, s) {
                    Some(next) => return Some(Ok(next)),
                    None => continue,
                }
            }
            self.silence.check(&self.topics, &mut self.report);
            // Idle only once subscribed: a site's source waits for its peers first.
            let ready = self.subacks >= self.topics.len();
            if ready && self.cfg.idle_timeout.is_some_and(|d| self.last_message.elapsed() >= d) {
                return None;
            }
            if let Err(e) = self.flush_acks() {
                return Some(Err(e));
            }
            match self.events.recv_timeout(POLL) {
                Ok(Driven::Event(event)) => match self.event(event, s) {
                    Ok(Some(next)) => return Some(Ok(next)),
                    Ok(None) => {}
                    Err(e) => return Some(Err(e)),
                },
                Ok(Driven::Lost(e)) => {
                    return Some(self.lost(&e).map(|()| Next::Idle));
                }
                Ok(Driven::Poison(why)) => {
                    if let Err(e) = self.poison(why) {
                        return Some(Err(e));
                    }
                }
                // Nothing within the poll: the run looks at the counts.
                Err(RecvTimeoutError::Timeout) => return Some(Ok(Next::Idle)),
                Err(RecvTimeoutError::Disconnected) => return None,
            }
        }
    }

    fn committed(&mut self) -> Result<(), CliError> {
        // Never blocking: the connection's thread may be busy handing over messages; what
        // finds no room is sent at the next call, still in order.
        self.to_ack.extend(self.unacked.drain(..));
        self.flush_acks()
    }

    fn commit_due(&self) -> bool {
        self.manual_acks && self.unacked.len() >= self.cfg.max_unacked
    }

    fn report(&self) -> Option<SourceReport> {
        let mut report = self.report.clone();
        report.state = self.rows.as_ref().and_then(SignalRows::state);
        Some(report)
    }

    fn restore(&mut self, report: &SourceReport) -> Result<(), CliError> {
        if let (Some(rows), Some(state)) = (&mut self.rows, &report.state) {
            rows.restore(state)?;
        }
        // The run's counts go on from the checkpoint's (what the broker delivers again that
        // the checkpoint lacks is counted again, as the killed process's counts are lost).
        self.report.continue_from(report);
        Ok(())
    }
}

/// A source that ends says goodbye: the broker sees a clean disconnection (the session, if
/// persistent, is kept for the next run) rather than a dropped connection.
impl Drop for MqttSource {
    fn drop(&mut self) {
        // The acknowledgements queued before the disconnection go out first; the connection's
        // thread ends once it is sent (waited for at most 2 s).
        let _ = self.flush_acks();
        let _ = self.client.try_disconnect();
        let deadline = Instant::now() + Duration::from_secs(2);
        while self.driver.as_ref().is_some_and(|d| !d.is_finished()) && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

fn client_error(e: rumqttc::ClientError) -> CliError {
    CliError::io("mqtt", std::io::Error::other(e.to_string()))
}

/// The source in words, without credentials.
fn describe(cfg: &MqttConfig) -> String {
    let servers: Vec<String> = cfg.servers.iter().map(Server::to_string).collect();
    let what = match &cfg.layout {
        Layout::Rows { topics, .. } => format!("{} row topic(s)", topics.len()),
        Layout::Signals { signals, .. } => format!("{} signal topics", signals.len()),
    };
    format!("mqtt {} (client {}), {what}", servers.join(" "), cfg.client_id)
}
