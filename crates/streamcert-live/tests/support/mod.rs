//! What the live tests share: an embedded MQTT broker on loopback, a TCP relay that can cut
//! a connection, the batch oracle of the alignment rule, and G5's rows.
#![allow(dead_code, unreachable_pub)]

use std::io::{Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use streamcert_live::AlignRule;

/// `steps` rows of G5 (experiment 1, seed 3) as `simulate` writes them: the CSV text, its
/// header and its rows.
pub fn g5(steps: usize) -> (String, Vec<String>, Vec<Vec<f64>>) {
    let mut out = Vec::new();
    streamcert_pipeline::simulate::run(
        streamcert_experiments::Experiment::One,
        streamcert_dynamics::Coupling::Cascade,
        3,
        Some(steps),
        None,
        &mut out,
    )
    .unwrap();
    let text = String::from_utf8(out).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines.map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    (text, header, rows)
}

/// Start the embedded broker on a free loopback port (for the rest of the test run); its
/// port.
pub fn broker() -> u16 {
    let addr = streamcert_live::broker::free_loopback().unwrap();
    streamcert_live::broker::serve(addr).unwrap();
    addr.port()
}

/// Publish `payloads` on `topic` of the broker on `port` (QoS 1, client `id`, packets up to
/// 2 MiB), waiting `pause` after the first; returns once the broker acknowledged each.
pub fn publish_acked(port: u16, id: &str, topic: &str, payloads: Vec<Vec<u8>>, pause: Duration) {
    let mut o = rumqttc::MqttOptions::new(id, "127.0.0.1", port);
    o.set_max_packet_size(1 << 21, 1 << 21);
    let (client, mut connection) = rumqttc::Client::new(o, 64);
    let n = payloads.len();
    let topic = topic.to_string();
    let feeder = std::thread::spawn(move || {
        for (k, p) in payloads.into_iter().enumerate() {
            client.publish(topic.as_str(), rumqttc::QoS::AtLeastOnce, false, p).unwrap();
            if k == 0 {
                std::thread::sleep(pause);
            }
        }
        client
    });
    let mut acked = 0;
    for event in connection.iter() {
        if let Ok(rumqttc::Event::Incoming(rumqttc::Packet::PubAck(_))) = event {
            acked += 1;
            if acked == n {
                break;
            }
        }
    }
    drop(feeder.join());
}

/// A TCP relay on loopback to `target`: [`Relay::cut`] closes every connection through it and
/// refuses new ones for a while (a broker that went away, as its clients see it).
pub struct Relay {
    /// The relay's port.
    pub port: u16,
    down: Arc<AtomicBool>,
    streams: Arc<Mutex<Vec<TcpStream>>>,
}

impl Relay {
    pub fn new(target: u16) -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let down = Arc::new(AtomicBool::new(false));
        let streams: Arc<Mutex<Vec<TcpStream>>> = Arc::default();
        let (d, st) = (Arc::clone(&down), Arc::clone(&streams));
        std::thread::spawn(move || {
            for client in listener.incoming() {
                let Ok(client) = client else { continue };
                if d.load(Ordering::SeqCst) {
                    let _ = client.shutdown(Shutdown::Both);
                    continue;
                }
                let Ok(server) = TcpStream::connect(("127.0.0.1", target)) else { continue };
                let mut list = st.lock().unwrap();
                list.push(client.try_clone().unwrap());
                list.push(server.try_clone().unwrap());
                pipe(client.try_clone().unwrap(), server.try_clone().unwrap());
                pipe(server, client);
            }
        });
        Self { port, down, streams }
    }

    /// Close every connection and refuse new ones for `outage`.
    pub fn cut(&self, outage: Duration) {
        self.down.store(true, Ordering::SeqCst);
        for s in self.streams.lock().unwrap().drain(..) {
            let _ = s.shutdown(Shutdown::Both);
        }
        std::thread::sleep(outage);
        self.down.store(false, Ordering::SeqCst);
    }
}

/// Copy `from` into `to` on a thread until either closes.
fn pipe(mut from: TcpStream, mut to: TcpStream) {
    std::thread::spawn(move || {
        let mut buf = [0u8; 16 * 1024];
        loop {
            match from.read(&mut buf) {
                Ok(0) | Err(_) => break,
                Ok(n) => {
                    if to.write_all(&buf[..n]).is_err() {
                        break;
                    }
                }
            }
        }
        let _ = to.shutdown(Shutdown::Both);
    });
}

/// One update in arrival order.
#[derive(Debug, Clone, Copy)]
pub struct Update {
    pub signal: usize,
    pub t: f64,
    pub v: f64,
}

/// What the rule yields, recomputed from all the updates at once.
#[derive(Debug, Clone, PartialEq)]
pub enum Item {
    Row(f64, Vec<f64>),
    Gap,
}

/// The batch oracle: (1) which updates are accepted, from the watermark each one saw on
/// arrival; (2) at every decided grid point, each signal's latest accepted update at or
/// before it (a tie to the later arrival), fresh within `max_age`.
pub fn oracle(n: usize, rule: AlignRule, updates: &[Update]) -> (Vec<Item>, u64, u64) {
    let p = rule.period;
    let Some(first) = updates.first() else { return (Vec::new(), 0, 0) };
    let k0 = ((first.t - rule.reorder_window) / p).ceil() as i64;
    // The last grid index decided once `newest` has been seen: the largest `k` with
    // `newest - R >= k p`, by the same comparison the rule states.
    let decided_after = |newest: f64| -> i64 {
        let w = newest - rule.reorder_window;
        if w == f64::NEG_INFINITY {
            return i64::MIN;
        }
        let mut k = (w / p).floor() as i64;
        while (k + 1) as f64 * p <= w {
            k += 1;
        }
        while k as f64 * p > w {
            k -= 1;
        }
        k
    };
    let mut newest = f64::NEG_INFINITY;
    let mut accepted: Vec<(usize, Update)> = Vec::new();
    let mut late = 0;
    for (i, u) in updates.iter().enumerate() {
        let last = decided_after(newest).max(k0 - 1);
        if u.t <= last as f64 * p {
            late += 1;
            continue;
        }
        accepted.push((i, *u));
        newest = newest.max(u.t);
    }
    let (mut items, mut started, mut gap, mut stale) = (Vec::new(), false, false, 0);
    for k in k0..=decided_after(newest) {
        let g = k as f64 * p;
        let mut row = Vec::with_capacity(n);
        for s in 0..n {
            let latest = accepted
                .iter()
                .filter(|(_, u)| u.signal == s && u.t <= g)
                .max_by(|(i, a), (j, b)| a.t.total_cmp(&b.t).then(i.cmp(j)));
            match latest {
                Some((_, u)) if g - u.t <= rule.max_age => row.push(u.v),
                _ => break,
            }
        }
        if row.len() == n {
            if std::mem::take(&mut gap) {
                items.push(Item::Gap);
            }
            started = true;
            items.push(Item::Row(g, row));
        } else if started {
            stale += 1;
            gap = true;
        }
    }
    (items, late, stale)
}
