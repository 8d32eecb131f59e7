//! `certify` from a live MQTT source, as a process, against the embedded broker (rumqttd) on
//! loopback: the simulated plant that serves its own broker, certified live.
//! (`mosquitto.rs` runs the process against Mosquitto: killed and resumed, broker restarted.)

use std::io::{BufRead, BufReader};
use std::process::Stdio;

mod common;
use common::bin;
use common::live::{Certify, live_config};

#[test]
fn the_simulated_plant_with_its_own_broker_is_certified_live() {
    let port = streamcert_live::broker::free_loopback().unwrap().port();
    let config = live_config("sim", port, "plant/g5");
    // The plant serves its broker and publishes at 20 times real time once started.
    let url = format!("mqtt://127.0.0.1:{port}/plant/g5");
    let mut plant = bin()
        .args(["simulate", "g5", "--seed", "3", "--publish", &url, "--broker", "--pace", "0.05"])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut plant_err = BufReader::new(plant.stderr.take().unwrap()).lines();
    let line = plant_err.next().unwrap().unwrap();
    assert!(line.starts_with("broker: serving MQTT on"), "{line}");
    let certify = Certify::start(&config, &["--output", "/dev/null"]);
    let (status, err) = certify.finish();
    plant.kill().unwrap();
    plant.wait().unwrap();
    assert!(status.success(), "{err}");
    assert!(err.contains("verdict: "), "{err}");
    assert!(err.contains("source: mqtt tcp://127.0.0.1"), "{err}");
    assert!(err.contains(" 0 bad"), "{err}");
}
