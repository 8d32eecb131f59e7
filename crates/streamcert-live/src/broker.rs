//! An embedded MQTT broker (rumqttd, MQTT 3.1.1) in this process: to try a live run without
//! installing a broker (`streamcert simulate g5 --publish mqtt://127.0.0.1:1883/plant
//! --broker`), and the real peer of the tests. It accepts anonymous clients on the address
//! given (loopback unless told otherwise), keeps persistent sessions and takes payloads up
//! to 1 MiB. For a plant, use the site's broker (Mosquitto, EMQX, HiveMQ, ...).

use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use streamcert_pipeline::CliError;

/// Start the broker on `addr` on a thread of its own and wait (at most 10 s) until it accepts
/// connections. It runs until the process ends.
///
/// # Errors
/// [`CliError::Io`] when it does not accept connections within 10 s (the address is taken,
/// or not this machine's).
pub fn serve(addr: SocketAddr) -> Result<(), CliError> {
    let server = rumqttd::ServerSettings {
        name: "v4".into(),
        listen: addr,
        tls: None,
        next_connection_delay_ms: 1,
        connections: rumqttd::ConnectionSettings {
            connection_timeout_ms: 60_000,
            max_payload_size: 1 << 20,
            max_inflight_count: 100,
            auth: None,
            external_auth: None,
            dynamic_filters: true,
        },
    };
    let config = rumqttd::Config {
        id: 0,
        router: rumqttd::RouterConfig {
            max_connections: 1000,
            max_outgoing_packet_count: 200,
            max_segment_size: 100 << 20,
            max_segment_count: 10,
            custom_segment: None,
            initialized_filters: None,
            shared_subscriptions_strategy: rumqttd::Strategy::default(),
        },
        v4: Some([("v4".to_string(), server)].into_iter().collect()),
        ..rumqttd::Config::default()
    };
    std::thread::spawn(move || {
        if let Err(e) = rumqttd::Broker::new(config).start() {
            eprintln!("broker: {e}");
        }
    });
    let deadline = Instant::now() + Duration::from_secs(10);
    while TcpStream::connect(addr).is_err() {
        if Instant::now() >= deadline {
            let e = std::io::Error::other("not accepting connections after 10 s");
            return Err(CliError::io(format!("starting the broker on {addr}"), e));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(())
}

/// A free loopback address for [`serve`] (for tests and examples).
///
/// # Errors
/// [`CliError::Io`] when no port can be had.
pub fn free_loopback() -> Result<SocketAddr, CliError> {
    let l = std::net::TcpListener::bind("127.0.0.1:0")
        .map_err(|e| CliError::io("finding a free port", e))?;
    l.local_addr().map_err(|e| CliError::io("finding a free port", e))
}
