//! `cargo xtask soak`: the network service across sites under faults, through the
//! `streamcert` binary as operators run it (NETWORK.md, "Soak run"). `N` scalar loops placed
//! round-robin on 3 processes, each reading its own long-layout file; one site's clock steps
//! 30 s ahead halfway (every later row of it is 30 s later), one site's file ends with a burst
//! of malformed rows. The same rows merged in time order go through one process first (the
//! reference). Then the three processes run with checkpoints; process 1 is killed (SIGKILL)
//! and restarted from its checkpoint at about a third of the run, process 2 at about two
//! thirds. Reported: every epoch row of process 0 against the reference, how each run ended,
//! and each process's peak memory (its `VmHWM`, polled).

use std::fmt::Write as _;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::common::{markdown, seed, write};

const DT: f64 = 0.01;
const JUMP_STEPS: usize = 3000;

fn config(n: usize) -> String {
    let mut c = String::from(
        "[network]\nepoch = 1.0\nstale_after = 2.5\ninput = \"long\"\nmargin = 0.1\n\n\
         [columns]\ntime = \"t\"\n\n",
    );
    for i in 0..n {
        let beta = 1.0 + 2.0 * (i as f64 / n as f64);
        let _ = writeln!(
            c,
            "[[subsystem]]\nname = \"s{i}\"\noutputs = [\"y{i}\"]\ninputs = [\"u{i}\"]\n\
             gain = [[{}]]\nprocess = {}\n",
            -beta,
            i % 3
        );
    }
    for i in 0..n {
        let _ =
            writeln!(c, "[[coupling]]\nfrom = \"s{}\"\nto = \"s{i}\"\ngamma = 0.05\n", (i + 1) % n);
    }
    c.push_str(
        "[certificate]\nconservatism = 0.3\nmargin = 0.05\nconsecutive = 1\n\n\
         [regression]\nwindow = 150\nhorizon = 5\nridge = 1e-4\n\
         input_integral = \"zero_order_hold\"\n\n[ambiguity]\nenabled = false\n",
    );
    c
}

/// Write the three sites' files and the merged file; returns the row count.
fn data(n: usize, steps: usize, dir: &Path) -> Result<u64> {
    let open = |name: &str| -> Result<BufWriter<std::fs::File>> {
        Ok(BufWriter::new(std::fs::File::create(dir.join(name))?))
    };
    let mut sites = [open("site-0.csv")?, open("site-1.csv")?, open("site-2.csv")?];
    let mut merged = open("merged.csv")?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed(0, 9500));
    let a: Vec<f64> = (0..n).map(|_| rng.random_range(-0.5..0.5)).collect();
    let (mut y, mut d) = (vec![0.0f64; n], vec![1.0f64; n]);
    // Site 2's rows from step steps/2 on are stamped JUMP_STEPS steps later: held back from
    // the merged file until the other sites reach that time.
    let mut held: std::collections::VecDeque<(usize, String)> = Default::default();
    let mut rows = 0u64;
    let stamp = |step: usize| format!("{}", step as f64 * DT);
    for step in 0..steps + JUMP_STEPS {
        if step < steps {
            for i in 0..n {
                if step % 10 == 0 && rng.random::<bool>() {
                    d[i] = -d[i];
                }
                let u = -2.0 * y[i] + d[i];
                let site = i % 3;
                let jumped = site == 2 && step >= steps / 2;
                let at = if jumped { step + JUMP_STEPS } else { step };
                let row = format!("{},s{i},{},{}\n", stamp(at), y[i], u);
                sites[site].write_all(row.as_bytes())?;
                if jumped {
                    held.push_back((at, row));
                } else {
                    merged.write_all(row.as_bytes())?;
                }
                rows += 1;
                let w: f64 = rng.sample(StandardNormal);
                y[i] += DT * (a[i] * y[i] + u) + 0.05 * DT.sqrt() * w;
            }
        }
        while held.front().is_some_and(|(at, _)| *at <= step) {
            if let Some((_, row)) = held.pop_front() {
                merged.write_all(row.as_bytes())?;
            }
        }
        // The burst of malformed rows at the end of site 0's file (time after its last row).
        if step + 1 == steps {
            for k in 0..20 {
                let row = format!("{},s{},nan,{}\n", stamp(steps), 3 * k % n, k);
                sites[0].write_all(row.as_bytes())?;
                merged.write_all(row.as_bytes())?;
            }
        }
    }
    for mut f in sites.into_iter().chain([merged]) {
        f.flush()?;
    }
    Ok(rows)
}

/// Peak resident memory of a running process, in MiB (`VmHWM`).
fn peak_mib(pid: u32) -> Option<f64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

struct Proc {
    child: Child,
    peak: f64,
    runs: usize,
}

/// The three processes' command lines: the binary, the configuration, the host file, process
/// 0's output and the folder of the sites' files, checkpoints and logs.
struct Sites {
    bin: PathBuf,
    cfg: PathBuf,
    hosts: PathBuf,
    output: PathBuf,
    out: PathBuf,
}

impl Sites {
    /// Start process `i` (from its checkpoint when `resume`), its standard error to a log.
    fn spawn(&self, i: usize, resume: bool) -> Result<Child> {
        let path = |p: &Path| p.display().to_string();
        let ck = self.out.join(format!("site-{i}.ckpt"));
        let mut c = Command::new(&self.bin);
        c.args(["network", "--config", &path(&self.cfg), "--processes", "3"])
            .args(["--process", &i.to_string(), "--hostfile", &path(&self.hosts)])
            .args(["--input", &path(&self.out.join(format!("site-{i}.csv")))])
            .args(["--checkpoint", &path(&ck), "--checkpoint-epochs", "10"]);
        if resume {
            c.args(["--resume", &path(&ck)]);
        }
        if i == 0 {
            c.args(["--output", &path(&self.output)]);
        }
        let name = format!("site-{i}-{}.log", u8::from(resume));
        let log = std::fs::File::create(self.out.join(name))?;
        Ok(c.stdout(Stdio::null()).stderr(log).spawn()?)
    }

    /// Run the three processes to the end, killing process 1 when a third of the `total`
    /// epoch rows are written and process 2 at two thirds (each once its checkpoint exists),
    /// each restarted with `--resume` 2 s later; polls every process's peak memory. The
    /// kills `(process, rows written, seconds)`.
    fn supervise(&self, procs: &mut [Proc], total: usize) -> Result<Vec<(usize, usize, f64)>> {
        let start = Instant::now();
        let written = || std::fs::read_to_string(&self.output).map_or(0, |t| t.lines().count());
        let mut kills: Vec<(usize, usize, f64)> = Vec::new();
        let plan = [(1usize, total / 3), (2usize, 2 * total / 3)];
        loop {
            for p in procs.iter_mut() {
                if let Some(m) = peak_mib(p.child.id()) {
                    p.peak = p.peak.max(m);
                }
            }
            if let Some(&(victim, at)) = plan.get(kills.len()) {
                let done = written();
                if done >= at && self.out.join(format!("site-{victim}.ckpt")).exists() {
                    procs[victim].child.kill()?;
                    procs[victim].child.wait()?;
                    kills.push((victim, done, start.elapsed().as_secs_f64()));
                    std::thread::sleep(Duration::from_secs(2));
                    procs[victim].child = self.spawn(victim, true)?;
                    procs[victim].runs += 1;
                }
            }
            let mut finished = true;
            for p in procs.iter_mut() {
                if p.child.try_wait()?.is_none() {
                    finished = false;
                }
            }
            if finished {
                return Ok(kills);
            }
            if start.elapsed() > Duration::from_secs(3600) {
                for p in procs.iter_mut() {
                    let _ = p.child.kill();
                }
                bail!("the soak run did not finish in an hour");
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

/// The one-process reference over the merged rows: its standard output and error, and its
/// time in seconds.
fn reference(bin: &Path, cfg: &Path, out: &Path) -> Result<(String, String, f64)> {
    let start = Instant::now();
    let reference = Command::new(bin)
        .args(["network", "--config", &cfg.display().to_string(), "--input"])
        .arg(out.join("merged.csv"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .output()?;
    let want = String::from_utf8_lossy(&reference.stdout).into_owned();
    let want_err = String::from_utf8_lossy(&reference.stderr).into_owned();
    Ok((want, want_err, start.elapsed().as_secs_f64()))
}

pub(crate) fn run(n: usize, steps: usize, out: &Path) -> Result<()> {
    std::fs::create_dir_all(out)?;
    let bin = crate::reliability::binary()?;
    eprintln!("soak: writing {n} subsystems x {steps} steps…");
    let rows = data(n, steps, out)?;
    let cfg = out.join("net.toml");
    std::fs::write(&cfg, config(n))?;
    eprintln!("soak: the one-process reference…");
    let (want, want_err, reference_s) = reference(&bin, &cfg, out)?;
    let ports: Vec<u16> = (0..3)
        .map(|_| Ok(std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port()))
        .collect::<Result<_>>()?;
    let hosts = out.join("hosts.txt");
    std::fs::write(&hosts, ports.iter().map(|p| format!("127.0.0.1:{p}\n")).collect::<String>())?;
    let output = out.join("epochs.csv");
    let sites = Sites { bin, cfg, hosts, output: output.clone(), out: out.to_path_buf() };
    for i in 0..3 {
        let _ = std::fs::remove_file(out.join(format!("site-{i}.ckpt")));
    }
    let _ = std::fs::remove_file(&output);
    eprintln!("soak: three processes, two kills…");
    let start = Instant::now();
    let mut procs: Vec<Proc> = (0..3)
        .map(|i| Ok(Proc { child: sites.spawn(i, false)?, peak: 0.0, runs: 1 }))
        .collect::<Result<_>>()?;
    let total = want.lines().count().max(1);
    let kills = sites.supervise(&mut procs, total)?;
    let soak_s = start.elapsed().as_secs_f64();
    let codes: Vec<Option<i32>> =
        procs.iter_mut().map(|p| p.child.wait().ok().and_then(|s| s.code())).collect();
    let got = std::fs::read_to_string(&output).context("process 0's rows")?;
    let (w, g): (Vec<&str>, Vec<&str>) = (want.lines().collect(), got.lines().collect());
    let differ = w.iter().zip(&g).filter(|(a, b)| a != b).count() + w.len().abs_diff(g.len());
    let log0 = std::fs::read_to_string(out.join("site-0-0.log")).unwrap_or_default();
    let last = |t: &str| t.lines().rev().find(|l| l.contains("error")).unwrap_or("").to_string();
    let mut md = String::new();
    writeln!(
        md,
        "Produced by `cargo xtask soak --subsystems {n} --steps {steps}`: {n} scalar loops \
         (dt = {DT} s, {steps} steps each, {rows} samples) on 3 processes of the `streamcert` \
         binary on localhost, each reading its own long-layout file; site 2's clock steps \
         {} s ahead halfway; site 0's file ends with 20 malformed rows (`nan`); checkpoints \
         every 10 epochs of 1 s. The reference is one process over the same rows merged in \
         time order ({reference_s:.0} s). The soak took {soak_s:.0} s.\n",
        JUMP_STEPS as f64 * DT
    )?;
    md.push_str(&tables(&kills, total, &procs, &codes));
    writeln!(
        md,
        "\nOutput lines (the header and the epoch rows): reference {}, soak {}; lines that \
         differ: {differ}. The reference \
         stopped with `{}`; process 0 with `{}`.",
        w.len(),
        g.len(),
        last(&want_err),
        last(&log0)
    )?;
    write(&out.join("SOAK.md"), &md)?;
    println!("{md}");
    if differ > 0 {
        bail!("{differ} epoch rows differ from the uninterrupted run");
    }
    Ok(())
}

/// SOAK.md's two tables: the kills, and how each process ended.
fn tables(
    kills: &[(usize, usize, f64)],
    total: usize,
    procs: &[Proc],
    codes: &[Option<i32>],
) -> String {
    let kill_rows: Vec<Vec<String>> = kills
        .iter()
        .map(|(victim, at, s)| {
            vec![format!("process {victim}"), format!("{at} of {total}"), format!("{s:.1}")]
        })
        .collect();
    let mut md = markdown(
        &["killed (SIGKILL), restarted with --resume", "epoch rows written", "at [s]"],
        &kill_rows,
    );
    md.push('\n');
    let proc_rows: Vec<Vec<String>> = procs
        .iter()
        .enumerate()
        .map(|(i, p)| {
            vec![
                format!("{i}"),
                format!("{}", p.runs),
                codes[i].map_or("killed".into(), |c| c.to_string()),
                format!("{:.0}", p.peak),
            ]
        })
        .collect();
    md.push_str(&markdown(&["process", "starts", "exit code", "peak memory [MiB]"], &proc_rows));
    md
}
