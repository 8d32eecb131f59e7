//! `cargo xtask sites --old-binary`: the throughput study through the `streamcert` binaries.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Result;

use super::Rows;

/// The same study through binaries: a raw-sample `streamcert` (`old`: process 0 reads the
/// wide file and ships the samples) against this build's (each process reads its own
/// columns), 2 processes each, and this build's one-process run; seconds of wall clock,
/// and whether the old binary wrote this build's epoch rows.
pub(super) fn throughput(
    old: &Path,
    n: usize,
    steps: usize,
    dt: f64,
    out: &Path,
) -> Result<([f64; 4], bool)> {
    let new = crate::reliability::binary()?;
    write_configs(n, out)?;
    write_inputs(n, steps, dt, out)?;
    let two =
        |bin: &Path, cfg: &str, inputs: [Option<PathBuf>; 2]| two_processes(bin, cfg, inputs, out);
    let old_s = two(old, "old.toml", [Some(out.join("wide.csv")), None])?;
    let new_s =
        two(&new, "new.toml", [Some(out.join("site-0.csv")), Some(out.join("site-1.csv"))])?;
    // One process of the new binary over the wide file, with `extra` arguments: its seconds.
    let one = |extra: &[&std::ffi::OsStr], what: &str| -> Result<f64> {
        let start = Instant::now();
        let status = std::process::Command::new(&new)
            .args(["network", "--config"])
            .arg(out.join("new.toml"))
            .arg("--input")
            .arg(out.join("wide.csv"))
            .args(extra)
            .stdout(std::process::Stdio::null())
            .status()?;
        anyhow::ensure!(status.success(), "{what}: {status}");
        Ok(start.elapsed().as_secs_f64())
    };
    let one_s = one(&[], "one process")?;
    let workers = out.join("workers.out.csv");
    let workers_s = one(
        &["--workers".as_ref(), "2".as_ref(), "--output".as_ref(), workers.as_os_str()],
        "one process on 2 workers",
    )?;
    // This build's two processes and its one process on 2 workers must agree; the old
    // binary's rows agree only while the local certificates are the old binary's.
    let a = std::fs::read(out.join("old.toml.out.csv"))?;
    let b = std::fs::read(out.join("new.toml.out.csv"))?;
    let c = std::fs::read(out.join("workers.out.csv"))?;
    anyhow::ensure!(b == c, "2 workers wrote other epoch rows than 2 processes");
    Ok(([old_s, new_s, one_s, workers_s], a == b))
}

/// The configurations of the two binaries: `old.toml` (no placement: process 0 reads every
/// column) and `new.toml` (the subsystems placed round-robin on two processes).
fn write_configs(n: usize, out: &Path) -> Result<()> {
    let mut cfg =
        String::from("[network]\nepoch = 1.0\nmargin = 0.1\n\n[columns]\ntime = \"t\"\n\n");
    for i in 0..n {
        writeln!(
            cfg,
            "[[subsystem]]\nname = \"s{i}\"\noutputs = [\"y{i}\"]\ninputs = [\"u{i}\"]\n\
             gain = [[-2.0]]\nPLACE{i}\n"
        )?;
    }
    cfg.push_str(
        "[certificate]\nconservatism = 0.3\nmargin = 0.05\nconsecutive = 1\n\n[regression]\n\
         window = 150\nhorizon = 5\nridge = 1e-4\ninput_integral = \"zero_order_hold\"\n\n\
         [ambiguity]\nenabled = false\n",
    );
    let mut old_cfg = cfg.clone();
    let mut new_cfg = cfg;
    for i in (0..n).rev() {
        old_cfg = old_cfg.replace(&format!("PLACE{i}\n"), "");
        new_cfg = new_cfg.replace(&format!("PLACE{i}\n"), &format!("process = {}\n", i % 2));
    }
    std::fs::write(out.join("old.toml"), old_cfg)?;
    std::fs::write(out.join("new.toml"), new_cfg)?;
    Ok(())
}

/// The wide file (every subsystem's columns) and each site's file (its own columns).
fn write_inputs(n: usize, steps: usize, dt: f64, out: &Path) -> Result<()> {
    use std::io::Write as _;
    // The wide file, and each site's columns.
    let mut sites: Vec<Rows> = (0..2)
        .map(|p| Rows::new((0..n).filter(|i| i % 2 == p).collect(), steps, dt, p as u64))
        .collect();
    let mut wide = std::io::BufWriter::new(std::fs::File::create(out.join("wide.csv"))?);
    let mut files: Vec<_> = (0..2)
        .map(|p| {
            Ok(std::io::BufWriter::new(std::fs::File::create(out.join(format!("site-{p}.csv")))?))
        })
        .collect::<Result<_>>()?;
    let header = |ids: &mut dyn Iterator<Item = usize>| {
        let mut h = String::from("t");
        for i in ids {
            let _ = write!(h, ",y{i},u{i}");
        }
        h
    };
    writeln!(wide, "{}", header(&mut (0..n)))?;
    for (p, f) in files.iter_mut().enumerate() {
        writeln!(f, "{}", header(&mut (0..n).filter(|i| i % 2 == p)))?;
    }
    let mut values = vec![(0.0, 0.0); n];
    for step in 0..steps {
        for (p, site) in sites.iter_mut().enumerate() {
            let mut line = format!("{}", step as f64 * dt);
            for _ in 0..site.ids.len() {
                if let Some(Ok(r)) = site.next() {
                    let (i, v) = &r.samples[0];
                    values[*i] = (v[0], v[1]);
                    let _ = write!(line, ",{},{}", v[0], v[1]);
                }
            }
            writeln!(files[p], "{line}")?;
        }
        let mut line = format!("{}", step as f64 * dt);
        for v in &values {
            let _ = write!(line, ",{},{}", v.0, v.1);
        }
        writeln!(wide, "{line}")?;
    }
    wide.flush()?;
    for f in &mut files {
        f.flush()?;
    }
    Ok(())
}

/// Two processes of `bin` on `cfg` (in `out`), each with its input if given: their seconds of
/// wall clock.
fn two_processes(bin: &Path, cfg: &str, inputs: [Option<PathBuf>; 2], out: &Path) -> Result<f64> {
    let hosts = out.join("cli-hosts.txt");
    let ports: Vec<u16> = (0..2)
        .map(|_| Ok(std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port()))
        .collect::<Result<_>>()?;
    std::fs::write(&hosts, ports.iter().map(|p| format!("127.0.0.1:{p}\n")).collect::<String>())?;
    let start = Instant::now();
    let children: Vec<_> = (0..2)
        .map(|p| {
            let mut c = std::process::Command::new(bin);
            c.args(["network", "--config"]).arg(out.join(cfg));
            c.args(["--processes", "2", "--process", &p.to_string(), "--hostfile"]).arg(&hosts);
            if let Some(input) = &inputs[p] {
                c.arg("--input").arg(input);
            }
            if p == 0 {
                c.arg("--output").arg(out.join(format!("{cfg}.out.csv")));
            }
            c.stdin(std::process::Stdio::null())
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .spawn()
        })
        .collect::<std::io::Result<_>>()?;
    for mut c in children {
        let status = c.wait()?;
        anyhow::ensure!(status.success(), "{} {cfg}: {status}", bin.display());
    }
    Ok(start.elapsed().as_secs_f64())
}
