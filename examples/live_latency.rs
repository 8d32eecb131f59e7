//! The latency from publishing a row to an MQTT broker to its evidence row being written:
//! the embedded broker on loopback, the default configuration (G5 node b), 5 000 rows
//! published at 500 rows per second (below the path's throughput, so the latency is not
//! queueing), one JSON row per message, QoS 1.
//!
//! Run: `cargo run --release --example live_latency` (prints the median, the 99th percentile
//! and the largest latency, in microseconds).

use std::io::Write;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use streamcert_live::MqttSource;
use streamcert_pipeline::certify::{self, Options};
use streamcert_pipeline::config;

const ROWS: usize = 5_000;
const PERIOD: Duration = Duration::from_millis(2);

/// A sink that notes when each line (evidence row) was written.
struct Stamps {
    at: Arc<Mutex<Vec<Instant>>>,
}

impl Write for Stamps {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let lines = buf.iter().filter(|&&b| b == b'\n').count();
        if lines > 0 {
            let now = Instant::now();
            self.at.lock().expect("stamps").extend(std::iter::repeat_n(now, lines));
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

type Result<T> = std::result::Result<T, Box<dyn std::error::Error + Send + Sync>>;

fn main() -> Result<()> {
    let addr = streamcert_live::broker::free_loopback()?;
    streamcert_live::broker::serve(addr)?;
    let port = addr.port();
    let text = format!(
        "{}\n[source]\nkind = \"mqtt\"\nservers = [\"tcp://127.0.0.1:{port}\"]\n\
         client_id = \"latency\"\ntopics = [\"latency/g5\"]\nidle_timeout = 1.0\n",
        config::g5_node_b()
    );
    let cfg = config::parse(&text, "latency")?;
    let parsed = streamcert_live::parse(cfg.source.as_ref().expect("source"), &cfg.columns)?;
    let streamcert_live::SourceConfig::Mqtt(live) = parsed else {
        return Err("an MQTT source".into());
    };
    let mut source = MqttSource::new(live, 1, false)?;
    if !source.wait_subscribed(Duration::from_secs(10)) {
        return Err("not subscribed".into());
    }
    let publisher = std::thread::spawn(move || -> Result<Vec<Instant>> {
        let mut o = rumqttc::MqttOptions::new("latency-pub", "127.0.0.1", port);
        o.set_keep_alive(Duration::from_secs(10));
        let (client, mut connection) = rumqttc::Client::new(o, 64);
        std::thread::spawn(move || for _ in connection.iter() {});
        let (mut sent, start) = (Vec::with_capacity(ROWS), Instant::now());
        let mut y = 0.1f64;
        for k in 0..ROWS {
            let due = start + PERIOD * u32::try_from(k)?;
            std::thread::sleep(due.saturating_duration_since(Instant::now()));
            let t = k as f64 * 0.02;
            let u = -4.0 * y + if (k / 7) % 2 == 0 { 0.3 } else { -0.3 };
            y += 0.02 * (-0.5 * y + u);
            let payload = format!("{{\"t\":{t},\"y_b\":{y},\"u_b\":{u}}}");
            sent.push(Instant::now());
            client.publish("latency/g5", rumqttc::QoS::AtLeastOnce, false, payload)?;
        }
        std::thread::sleep(Duration::from_millis(200));
        client.disconnect()?;
        Ok(sent)
    });
    let at = Arc::new(Mutex::new(Vec::with_capacity(ROWS + 1)));
    let mut sink = Stamps { at: Arc::clone(&at) };
    certify::run_source(&cfg, &mut source, "mqtt", &mut sink, &Options::default())?;
    let sent = publisher.join().map_err(|_| "the publisher failed")??;
    let written = at.lock().expect("stamps");
    // The first line is the header.
    if written.len() != ROWS + 1 {
        return Err(format!("{} rows written of {ROWS}", written.len().saturating_sub(1)).into());
    }
    let lat: Vec<f64> = sent
        .iter()
        .zip(&written[1..])
        .map(|(s, w)| w.saturating_duration_since(*s).as_secs_f64() * 1e6)
        .collect();
    let worst = (0..lat.len()).max_by(|&a, &b| lat[a].total_cmp(&lat[b])).unwrap_or(0);
    let mut micros = lat.clone();
    micros.sort_by(f64::total_cmp);
    let q = |p: f64| micros[((micros.len() - 1) as f64 * p).round() as usize];
    println!(
        "publish to evidence row over {ROWS} rows at 500 rows/s: median {:.0} us, 99th percentile {:.0} us, max {:.0} us (row {worst})",
        q(0.5),
        q(0.99),
        micros[micros.len() - 1]
    );
    Ok(())
}
