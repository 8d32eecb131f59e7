//! The `certify` and `network` commands: the configuration read, the pipeline run, the summary
//! written, and the verdict the exit code reports.

use std::io::Write;
use std::path::PathBuf;

use streamcert_pipeline::watch::{NoWatch, Watch};
use streamcert_pipeline::{CliError, certify, config, network};

use super::ops::Ops;
use super::{
    ClusterArgs, Outcome, Persist, Require, Stream, check_plot, open_input, open_output, verdict,
};

/// `streamcert certify`.
pub(super) fn run_certify(
    io: Stream,
    on_bad_row: certify::BadRows,
    persist: Persist,
    summary: Option<PathBuf>,
    require: Require,
    plot: Option<PathBuf>,
    ops: &Ops,
) -> Result<Outcome, CliError> {
    let Persist { checkpoint, checkpoint_every, resume } = persist;
    if io.print_config {
        print!("{}", config::DEFAULT_CONFIG);
        return Ok(Outcome::Done);
    }
    let (path, text) = io.config_text()?;
    let cfg = config::parse(&text, &path)?;
    check_plot(plot.as_ref())?;
    let operator = ops.start(&path, cfg.verdict.as_ref())?;
    let mut watch: Box<dyn Watch> = match operator.monitor {
        Some(m) => Box::new(m.certify(&cfg.certifier, &cfg.columns.outputs, operator.sinks)),
        None => Box::new(NoWatch),
    };
    let opts = certify::Options {
        format: io.format,
        bad_rows: on_bad_row,
        checkpoint,
        checkpoint_every,
        resume,
        flush: io.flush(),
        plot,
    };
    let mut out = open_output(&io.output)?;
    let s = match &cfg.source {
        Some(table) => {
            one_input(&io.input, &path)?;
            let mut source = streamcert_live::open(table, &cfg.columns, opts.checkpoint.is_some())
                .map_err(|e| match e {
                    CliError::Config { message, .. } => {
                        CliError::Config { path: path.clone(), message }
                    }
                    other => other,
                })?;
            certify::run_source_watched(
                &cfg,
                source.as_mut(),
                "live",
                &mut out,
                &opts,
                &mut *watch,
            )?
        }
        None => {
            let input = open_input(&io.input)?;
            certify::run_watched(&cfg, input, &io.input, &mut out, &opts, &mut *watch)?
        }
    };
    drop(watch);
    out.flush().map_err(|e| CliError::io("writing output", e))?;
    match summary {
        Some(file) => {
            let v = s.json(&cfg.certifier, &cfg.columns.outputs);
            std::fs::write(&file, format!("{v}\n"))
                .map_err(|e| CliError::io(format!("writing {}", file.display()), e))?;
        }
        None => {
            eprintln!("{}", s.text(&cfg.certifier, &cfg.columns.outputs));
            if let Some(w) = s.units_warning(&cfg.certifier) {
                eprintln!("warning: {w}");
            }
        }
    }
    Ok(verdict(require.require_certified, s.certified_at_end(&cfg.certifier)))
}

/// A configuration with a live `[source]` reads no `--input` file.
fn one_input(input: &str, path: &str) -> Result<(), CliError> {
    if input == "-" {
        return Ok(());
    }
    Err(CliError::Config {
        path: path.into(),
        message: format!(
            "the configuration reads a live [source]; --input {input} reads a file: give one \
             or the other"
        ),
    })
}

/// `streamcert network`.
pub(super) fn run_network(
    io: Stream,
    persist: Persist,
    summary: Option<PathBuf>,
    cluster: ClusterArgs,
    require: Require,
    plot: Option<PathBuf>,
    ops: &Ops,
) -> Result<Outcome, CliError> {
    let Persist { checkpoint, checkpoint_every, resume } = persist;
    if io.print_config {
        print!("{}", network::template());
        return Ok(Outcome::Done);
    }
    let (path, text) = io.config_text()?;
    let cfg = network::parse(&text, &path)?;
    check_plot(plot.as_ref())?;
    let mut out = open_output(&io.output)?;
    let opts = network::NetOptions {
        format: io.format,
        flush: io.flush(),
        checkpoint,
        checkpoint_every,
        resume,
        plot,
    };
    let ClusterArgs { workers, processes, process, hostfile, silence, checkpoint_epochs } = cluster;
    let cluster =
        network::Cluster { workers, processes, process, hostfile, silence, checkpoint_epochs };
    if cluster.is_set() && opts.plot.is_some() {
        return Err(CliError::Config {
            path: path.clone(),
            message: "--plot draws a one-process run (drop --plot, or run without \
                      --processes/--workers)"
                .into(),
        });
    }
    if cluster.is_set() && (ops.is_set() || cfg.verdict.is_some()) {
        return Err(CliError::Config {
            path: path.clone(),
            message: "--serve, --metrics and [verdict] watch a one-process run (drop them, or \
                      run without --processes/--workers)"
                .into(),
        });
    }
    let operator = ops.start(&path, cfg.verdict.as_ref())?;
    let mut watch: Box<dyn Watch> = match operator.monitor {
        Some(m) => Box::new(m.network(&cfg.network, operator.sinks)),
        None => Box::new(NoWatch),
    };
    let s = if let (Some(table), false) = (&cfg.source, cluster.is_set()) {
        one_input(&io.input, &path)?;
        let source = streamcert_live::open(table, &cfg.columns, opts.checkpoint.is_some())?;
        network::run_source_watched(&cfg, source, "live", &mut out, &opts, &mut *watch)?
    } else if cluster.is_set() {
        if cfg.source.is_some() {
            one_input(&io.input, &path)?;
        }
        let Some(s) = run_cluster(&cfg, &io.input, &mut out, &opts, &cluster)? else {
            return Ok(Outcome::Done);
        };
        s
    } else {
        network::run_watched(&cfg, open_input(&io.input)?, &io.input, &mut out, &opts, &mut *watch)?
    };
    drop(watch);
    out.flush().map_err(|e| CliError::io("writing output", e))?;
    match summary {
        Some(file) => {
            let v = network::summary_json(&cfg.network, &s);
            std::fs::write(&file, format!("{v}\n"))
                .map_err(|e| CliError::io(format!("writing {}", file.display()), e))?;
        }
        None => eprintln!("{}", network::summary_text(&cfg.network, &s)),
    }
    Ok(verdict(require.require_certified, s.open_at_end))
}

/// `streamcert network` over timely: every process reads its own input (its subsystems'
/// rows) and process 0 writes; the summary on process 0, `None` on the others (which say
/// on standard error what they did).
fn run_cluster(
    cfg: &network::NetConfig,
    input: &str,
    out: &mut dyn Write,
    opts: &network::NetOptions,
    cluster: &network::Cluster,
) -> Result<Option<network::NetSummary>, CliError> {
    let name = input.to_string();
    let opened = std::cell::Cell::new(false);
    let open = move || -> Result<Box<dyn std::io::Read + Send>, CliError> {
        if name == "-" && opened.replace(true) {
            return Err(CliError::Input {
                file: "-".into(),
                message: "standard input cannot be read again after a restart".into(),
            });
        }
        Ok(Box::new(open_input(&name)?))
    };
    // A live [source]: each site subscribes to its own subsystems' signals, under a client id
    // of its own (a persistent session per site); acknowledged on arrival (a site's
    // checkpoints are written on timely's epochs, not held against its messages).
    let process = cluster.index();
    let live = |columns: &streamcert_pipeline::config::Columns| {
        let table = cfg.source.clone().unwrap_or_default();
        let site = streamcert_live::for_site(&table, columns, process);
        streamcert_live::open(&site, columns, false)
    };
    let input_of = if cfg.source.is_some() {
        network::SiteInput::Live(&live)
    } else {
        network::SiteInput::File(&open)
    };
    if process == 0 {
        return Ok(Some(network::run_timely(cfg, input_of, input, out, opts, cluster)?.0));
    }
    let (_, site) = network::run_timely(cfg, input_of, input, std::io::sink(), opts, cluster)?;
    let rejoins =
        if site.rejoins > 0 { format!(", {} rejoins", site.rejoins) } else { String::new() };
    eprintln!(
        "process {}: done, {} rows certified, {} bytes of snapshots sent to process 0{rejoins}",
        cluster.index(),
        site.rows,
        site.bytes_sent,
    );
    Ok(None)
}

/// The CSV text `csv` as a header and rows of numbers.
fn csv_rows(
    csv: &[u8],
    bad: impl Fn(String) -> CliError,
) -> Result<(Vec<String>, Vec<Vec<f64>>), CliError> {
    let text = std::str::from_utf8(csv).map_err(|e| bad(e.to_string()))?;
    let mut lines = text.lines();
    let header: Vec<String> =
        lines.next().unwrap_or_default().split(',').map(String::from).collect();
    let rows =
        lines.map(|l| l.split(',').map(|v| v.parse().unwrap_or(f64::NAN)).collect()).collect();
    Ok((header, rows))
}

/// `streamcert simulate g5 --opcua URL`: the CSV rows `csv` served by an OPC UA server, one
/// variable per column, each sample written at its time (`--pace`) from when a client first
/// monitors its nodes.
pub(super) fn serve_opcua(
    csv: &[u8],
    url: &str,
    args: &super::Publish,
) -> Result<Outcome, CliError> {
    use streamcert_live::opcua::server::PlantServer;
    let bad = |message: String| CliError::Config { path: "--opcua".into(), message };
    let pace = args.pace;
    if !(pace >= 0.0 && pace.is_finite()) {
        return Err(bad(format!("--pace must be finite and >= 0, got {pace}")));
    }
    let hostport = url
        .strip_prefix("opc.tcp://")
        .map(|r| r.trim_end_matches('/'))
        .ok_or_else(|| bad(format!("`{url}`: expected opc.tcp://HOST:PORT")))?;
    let addr = std::net::ToSocketAddrs::to_socket_addrs(hostport)
        .map_err(|e| bad(format!("`{url}`: {e}")))?
        .next()
        .ok_or_else(|| bad(format!("`{url}`: no address")))?;
    let (header, rows) = csv_rows(csv, bad)?;
    let server = PlantServer::start(addr, &header[1..], &args.pki)?;
    eprintln!(
        "opcua: serving {} at {} (nodes {}); certificate {}",
        header[1..].join(", "),
        server.endpoint(),
        server.node_ids().join(" "),
        args.pki.join("own/cert.der").display()
    );
    // The run starts when a client monitors the plant's nodes, so that it sees the first
    // sample however long after the plant it was started.
    if !server.monitored() {
        eprintln!("opcua: the run starts when a client monitors the nodes");
        while !server.monitored() {
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    }
    let start = std::time::Instant::now();
    let t0 = rows.first().map_or(0.0, |r| r[0]);
    for row in &rows {
        let due = std::time::Duration::from_secs_f64(((row[0] - t0) * pace).max(0.0));
        if let Some(wait) = due.checked_sub(start.elapsed()) {
            std::thread::sleep(wait);
        }
        server.publish(row[0], &row[1..])?;
    }
    eprintln!(
        "opcua: served {} samples; the last values stay until the process is stopped",
        rows.len()
    );
    loop {
        std::thread::park();
    }
}

/// `streamcert simulate g5 --publish URL`: the CSV rows `csv` published to the broker.
pub(super) fn publish_csv(
    csv: &[u8],
    url: &str,
    args: &super::Publish,
) -> Result<Outcome, CliError> {
    use streamcert_live::publish::{self, Layout, PublishOptions};
    let (per_signal, pace) = (args.per_signal, args.pace);
    let bad = |message: String| CliError::Config { path: "--publish".into(), message };
    if !(pace >= 0.0 && pace.is_finite()) {
        return Err(bad(format!("--pace must be finite and >= 0, got {pace}")));
    }
    let (server, topic) = publish::parse_url(url).map_err(bad)?;
    if args.broker {
        let addr = std::net::ToSocketAddrs::to_socket_addrs(&(server.host.as_str(), server.port))
            .map_err(|e| bad(format!("{}: {e}", server.host)))?
            .next()
            .ok_or_else(|| bad(format!("{}: no address", server.host)))?;
        streamcert_live::broker::serve(addr)?;
        eprintln!("broker: serving MQTT on {addr}");
    }
    let (header, rows) = csv_rows(csv, bad)?;
    let layout = if per_signal { Layout::Signals } else { Layout::Rows };
    let client_id = format!("streamcert-simulate-{}", std::process::id());
    let opts = PublishOptions { server, topic, client_id, layout, pace };
    let sent = publish::publish(&opts, &header, 0, rows)?;
    eprintln!("published {sent} messages to {url}");
    if args.broker {
        eprintln!("broker: still serving; stop it with Ctrl-C");
        loop {
            std::thread::park();
        }
    }
    Ok(Outcome::Done)
}
