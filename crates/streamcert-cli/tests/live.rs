//! `certify` from a live source, as a process: against the embedded broker (rumqttd) on
//! loopback, the simulated plant that serves its own broker, certified live; and the plant
//! served by an OPC UA server (async-opcua's), certified from its nodes.
//! (`mosquitto.rs` runs the process against Mosquitto: killed and resumed, broker restarted.)

use std::io::{BufRead, BufReader};
use std::process::Stdio;

mod common;
use common::bin;
use common::live::{Certify, live_config};

#[test]
fn the_simulated_plant_with_its_own_broker_is_certified_live() {
    let ports = common::live::port_lock();
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
    drop(ports);
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

/// The command of docs/live.md's code block whose first line is `# terminal N`, split into
/// words, with `streamcert` dropped (the binary under test runs it).
fn terminal(doc: &str, n: u8) -> Vec<String> {
    let marker = format!("# terminal {n}:");
    let mut lines = doc.lines().skip_while(|l| !l.starts_with(&marker));
    lines.next().expect("the terminal's block");
    let command = lines.next().expect("its command");
    let words: Vec<String> = command.split_whitespace().map(String::from).collect();
    assert_eq!(words[0], "streamcert");
    words[1..].to_vec()
}

/// What a walk-through of docs/live.md printed: the plant's first stderr line, and the
/// certify run's stderr and evidence rows.
struct WalkThrough {
    plant_says: String,
    stderr: String,
    rows: usize,
}

/// docs/live.md's terminals `plant` and `certify` (`certify` reading `config`, under
/// examples/data), as written but on a free port instead of `port` (tests run in parallel,
/// and a machine may run a broker or a server of its own there), in the commands and in the
/// configuration; `extra` appended to the plant's command.
fn walk_through(plant: u8, certify: u8, port: &str, config: &str, extra: &[String]) -> WalkThrough {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let doc = std::fs::read_to_string(root.join("docs/live.md")).unwrap();
    let ports = common::live::port_lock();
    let free = streamcert_live::broker::free_loopback().unwrap().port().to_string();
    let on_port = |w: &String| w.replace(port, &free);
    let mut plant_args: Vec<String> = terminal(&doc, plant).iter().map(on_port).collect();
    plant_args.extend_from_slice(extra);
    let mut certify_args: Vec<String> = terminal(&doc, certify).iter().map(on_port).collect();
    let text = std::fs::read_to_string(root.join("examples/data").join(config)).unwrap();
    let local = common::tmp(&format!("docs-{config}"));
    std::fs::write(&local, text.replace(port, &free)).unwrap();
    let evidence = common::tmp(&format!("docs-{config}-evidence.csv"));
    for w in &mut certify_args {
        if *w == format!("examples/data/{config}") {
            *w = local.display().to_string();
        } else if w.as_str() == "evidence.csv" {
            *w = evidence.display().to_string();
        }
    }
    let mut plant = bin().args(&plant_args).stderr(Stdio::piped()).spawn().unwrap();
    let mut plant_err = BufReader::new(plant.stderr.take().unwrap()).lines();
    let plant_says = plant_err.next().unwrap().unwrap();
    drop(ports);
    let args: Vec<&str> = certify_args.iter().map(String::as_str).collect();
    let (status, stderr) = Certify::start_args(&args).finish();
    plant.kill().unwrap();
    plant.wait().unwrap();
    assert!(status.success(), "{stderr}");
    assert!(stderr.lines().any(|l| l.starts_with("verdict: ")), "{stderr}");
    let rows = std::fs::read_to_string(&evidence).unwrap().lines().count();
    WalkThrough { plant_says, stderr, rows }
}

#[test]
fn the_two_terminal_walk_through_of_docs_live_md_runs_as_written() {
    let w = walk_through(1, 2, "1883", "g5_live.toml", &[]);
    assert!(w.plant_says.starts_with("broker: serving MQTT on"), "{}", w.plant_says);
    let source = w.stderr.lines().find(|l| l.contains(" messages, ")).expect("the source line");
    assert!(source.contains(" 0 bad, 0 late") && source.contains(" 0 gaps"), "{source}");
    assert!(w.rows > 1000, "{} evidence rows", w.rows);
}

#[test]
fn the_opcua_walk_through_of_docs_live_md_runs_as_written() {
    // The plant's PKI in a scratch directory.
    let pki = common::tmp("opcua-docs-pki").display().to_string();
    let w = walk_through(3, 4, "4840", "g5_opcua.toml", &["--pki".into(), pki]);
    let line = &w.plant_says;
    assert!(line.starts_with("opcua: serving") && line.contains("ns=2;s=y_b"), "{line}");
    assert!(w.stderr.contains("subscribed to 2 nodes"), "{}", w.stderr);
    let source = w.stderr.lines().find(|l| l.contains(" messages, ")).expect("the source line");
    assert!(source.starts_with("source: opcua") && source.contains(" 0 bad"), "{source}");
    assert!(source.contains(" 0 late") && source.contains(" 0 gaps"), "{source}");
    // The plant starts when the certifier monitors its nodes: every sample reaches it, and
    // all but the last reorder window's (0.5 s of 0.02 s rows, waiting for a later sample
    // when the run ends) are certified.
    let sim = bin().args(["simulate", "g5"]).output().unwrap();
    let samples = common::text(&sim.stdout).lines().count() - 1;
    let undecided = 26;
    assert!(w.rows - 1 + undecided >= samples, "{} evidence rows of {samples}: {source}", w.rows);
}

/// A network read from the embedded broker: its port, G5's wide rows (experiment 2,
/// bidirectional, seed 1), the one-process run of those rows from a file, and the
/// configuration `example` reading topic `g5/{tag}` under client id `streamcert-{tag}`.
struct NetworkCase {
    port: u16,
    csv: String,
    want: std::path::PathBuf,
    live_cfg: std::path::PathBuf,
}

fn network_case(tag: &str, example: &str) -> NetworkCase {
    let ports = common::live::port_lock();
    let port = streamcert_live::broker::free_loopback().unwrap();
    streamcert_live::broker::serve(port).unwrap();
    drop(ports);
    let sim = bin()
        .args(["simulate", "g5", "--experiment", "2", "--coupling", "bidirectional", "--seed", "1"])
        .output()
        .unwrap();
    assert!(sim.status.success());
    let csv = common::text(&sim.stdout);
    let (file_cfg, data, want) = (
        common::tmp(&format!("{tag}-file.toml")),
        common::tmp(&format!("{tag}.csv")),
        common::tmp(&format!("{tag}-want.csv")),
    );
    std::fs::write(&file_cfg, example).unwrap();
    std::fs::write(&data, &csv).unwrap();
    let status = bin()
        .args(["network", "--config", &path(&file_cfg), "--input", &path(&data)])
        .args(["--output", &path(&want)])
        .status()
        .unwrap();
    assert!(status.success());
    let live_cfg = common::tmp(&format!("{tag}-live.toml"));
    let source = format!(
        "\n[source]\nkind = \"mqtt\"\nservers = [\"tcp://127.0.0.1:{}\"]\n\
         client_id = \"streamcert-{tag}\"\ntopics = [\"g5/{tag}\"]\nidle_timeout = 2.0\n",
        port.port()
    );
    std::fs::write(&live_cfg, example.to_string() + &source).unwrap();
    NetworkCase { port: port.port(), csv, want, live_cfg }
}

impl NetworkCase {
    /// Publish the rows, a JSON object per message, on `g5/{tag}`.
    fn publish(&self, tag: &str) {
        let mut lines = self.csv.lines();
        let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
        let rows: Vec<Vec<f64>> =
            lines.map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
        let opts = common::live::publisher(self.port, &format!("g5/{tag}"), &format!("pub-{tag}"));
        streamcert_live::publish::publish(&opts, &header, 0, rows).unwrap();
    }

    /// The live run's epoch rows (at `got`) equal the file's.
    fn assert_same(&self, got: &std::path::Path) {
        let got = std::fs::read_to_string(got).unwrap();
        let want = std::fs::read_to_string(&self.want).unwrap();
        assert!(want.lines().count() > 10, "{want}");
        assert!(got == want, "the live network's epochs differ from the file's");
    }
}

fn path(p: &std::path::Path) -> String {
    p.display().to_string()
}

#[test]
fn a_network_read_from_a_broker_writes_the_files_epochs_bit_for_bit() {
    let case = network_case("net", &common::network_example());
    let got = common::tmp("net-got.csv");
    let run = Certify::start_args(&[
        "network",
        "--config",
        &path(&case.live_cfg),
        "--output",
        &path(&got),
    ]);
    case.publish("net");
    let (status, err) = run.finish();
    assert!(status.success(), "{err}");
    assert!(err.lines().any(|l| l.contains(" messages, ") && l.contains(" 0 bad")), "{err}");
    case.assert_same(&got);
}

#[test]
fn two_sites_read_their_subsystems_from_a_broker_and_write_the_files_epochs() {
    // A on process 0, B on process 1.
    let example = common::network_example()
        .replace("# process = 0           #", "process = 0           #")
        .replace("gain = [[-3.0]]\n", "gain = [[-3.0]]\nprocess = 1\n");
    assert!(example.contains("process = 1"), "{example}");
    // Two sites, each subscribed to the wide rows for its own subsystem's columns.
    let case = network_case("sites", &example);
    let hosts = common::tmp("sites-live-hosts.txt");
    let ports: Vec<u16> = (0..2)
        .map(|_| std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port())
        .collect();
    std::fs::write(&hosts, format!("127.0.0.1:{}\n127.0.0.1:{}\n", ports[0], ports[1])).unwrap();
    let got = common::tmp("sites-got.csv");
    let _ = std::fs::remove_file(&got);
    // Both start together (timely waits for every process), and say they are subscribed.
    let sites: Vec<_> = (0..2)
        .map(|i| {
            let (cfg, hosts, got) = (path(&case.live_cfg), path(&hosts), path(&got));
            std::thread::spawn(move || {
                let index = i.to_string();
                let mut args = vec!["network", "--config", &cfg, "--processes", "2"];
                args.extend(["--process", &index, "--hostfile", &hosts, "--silence", "30"]);
                if i == 0 {
                    args.extend(["--output", &got]);
                }
                Certify::start_args(&args)
            })
        })
        .collect();
    let sites: Vec<Certify> = sites.into_iter().map(|h| h.join().unwrap()).collect();
    case.publish("sites");
    for (i, site) in sites.into_iter().enumerate() {
        let (status, err) = site.finish();
        assert!(status.success(), "process {i}: {err}");
        // Each site's session is its own: the configured client id, suffixed.
        assert!(err.contains(&format!("client streamcert-sites-site{i}")), "{err}");
    }
    case.assert_same(&got);
}

/// `[regression] order = 2` live: the rows a live run certifies from the embedded broker are,
/// bit for bit, those of `certify --input` on the same samples with the same configuration,
/// and they are the certificate of order 2's (not the first order's).
#[test]
fn a_live_loop_at_order_two_writes_the_files_rows_bit_for_bit() {
    let ports = common::live::port_lock();
    let port = streamcert_live::broker::free_loopback().unwrap();
    streamcert_live::broker::serve(port).unwrap();
    drop(ports);
    let (csv, header, rows) = common::live::g5("1500");
    let template = streamcert_pipeline::config::g5_node_b();
    assert!(template.contains("\norder = 1\n"));
    let order_two = template.replace("\norder = 1\n", "\norder = 2\n");
    let data = common::tmp("order2-live.csv");
    std::fs::write(&data, &csv).unwrap();
    let file_run = |tag: &str, cfg_text: &str| {
        let (cfg, out) = (common::tmp(&format!("{tag}.toml")), common::tmp(&format!("{tag}.csv")));
        std::fs::write(&cfg, cfg_text).unwrap();
        let status = bin()
            .args(["certify", "--config", &path(&cfg), "--input", &path(&data)])
            .args(["--output", &path(&out)])
            .status()
            .unwrap();
        assert!(status.success());
        common::live::rows_of(&out)
    };
    let want = file_run("order2-file", &order_two);
    assert_ne!(want, file_run("order1-file", &template), "order 2 changes the rows");
    assert_eq!(want.len(), rows.len());
    let source = format!(
        "\n[source]\nkind = \"mqtt\"\nservers = [\"tcp://127.0.0.1:{}\"]\n\
         client_id = \"streamcert-order2\"\ntopics = [\"g5/order2\"]\nidle_timeout = 2.0\n",
        port.port()
    );
    let live_cfg = common::tmp("order2-live.toml");
    std::fs::write(&live_cfg, order_two + &source).unwrap();
    let got = common::tmp("order2-got.csv");
    let run = Certify::start(&live_cfg, &["--output", &path(&got)]);
    let opts = common::live::publisher(port.port(), "g5/order2", "pub-order2");
    streamcert_live::publish::publish(&opts, &header, 0, rows).unwrap();
    let (status, err) = run.finish();
    assert!(status.success(), "{err}");
    assert!(common::live::rows_of(&got) == want, "the live rows differ from the file's: {err}");
}
