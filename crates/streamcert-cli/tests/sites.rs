//! `streamcert network` over three timely processes on localhost, each reading only its own
//! subsystem's long-layout file: process 0's epoch rows are those of the one-process run over
//! the merged file, byte for byte, with given and estimated couplings; after one process is
//! killed (SIGKILL) mid-stream and restarted from its checkpoint, still; a damaged or
//! another process's checkpoint is refused (exit 5) and the others wait undisturbed.

mod common;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{bin, run, text, tmp, wait_bounded};

const CONFIG: &str = r#"
[network]
epoch = 0.5
stale_after = 2.5
input = "long"

[columns]
time = "t"

[[subsystem]]
name = "A"
outputs = ["y_a"]
inputs = ["u_a"]
gain = [[-2.0]]
process = 0

[[subsystem]]
name = "B"
outputs = ["y_b"]
inputs = ["u_b"]
gain = [[-2.5]]
process = 1

[[subsystem]]
name = "C"
outputs = ["y_c"]
inputs = ["u_c"]
gain = [[-3.0]]
process = 2

[[coupling]]
from = "B"
to = "A"
gamma = 0.3

[[coupling]]
from = "C"
to = "B"
gamma = 0.3

# Measured at C's site: its rows carry y_a (the driving output) as an input.
[[coupling]]
from = "A"
to = "C"
estimate = true

[certificate]
conservatism = 0.3
margin = 0.1
consecutive = 10

[regression]
window = 150
horizon = 5
ridge = 1e-4
input_integral = "zero_order_hold"

[ambiguity]
enabled = false
"#;

/// A portable seeded generator (xorshift64*), uniform in [-1, 1).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11;
        x as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// Three coupled scalar loops (`ẏ_i = a_i y_i + u_i + 0.2 y_j + w`, `u_i = k_i y_i + PRBS`),
/// Euler steps of 10 ms; the long rows of each site (C's at a 5 ms offset, carrying `y_a`
/// when `carry`) and all of them merged in time order.
/// With `jump > 0`, C's clock steps `jump` steps ahead halfway (its later rows are stamped
/// that much later).
fn data(steps: usize, carry: bool, jump: usize) -> ([String; 3], String) {
    let mut rng = Rng(0x5eed_0003);
    let (a, k) = ([0.4, 0.3, 0.2], [-2.0, -2.5, -3.0]);
    let (mut y, mut d) = ([0.0f64; 3], [1.0f64; 3]);
    let mut sites = [String::new(), String::new(), String::new()];
    // (half-steps of 5 ms, row): the merged file is every row in time order.
    let mut merged: Vec<(usize, String)> = Vec::new();
    for step in 0..steps {
        let t = step as f64 * 0.01;
        let c_step = if step >= steps / 2 { step + jump } else { step };
        for i in 0..3 {
            if step % 20 == 0 && rng.next() > 0.0 {
                d[i] = -d[i];
            }
        }
        let u: Vec<f64> = (0..3).map(|i| k[i] * y[i] + d[i]).collect();
        let tc = c_step as f64 * 0.01 + 0.005;
        let rows = [
            format!("{t},A,{},{}\n", y[0], u[0]),
            format!("{t},B,{},{}\n", y[1], u[1]),
            if carry {
                format!("{tc},C,{},{},{}\n", y[2], u[2], y[0])
            } else {
                format!("{tc},C,{},{}\n", y[2], u[2])
            },
        ];
        for ((site, row), key) in
            sites.iter_mut().zip(&rows).zip([2 * step, 2 * step, 2 * c_step + 1])
        {
            site.push_str(row);
            merged.push((key, row.clone()));
        }
        let next: Vec<f64> = (0..3)
            .map(|i| {
                let drive = 0.2 * y[(i + 1) % 3];
                y[i] + 0.01 * (a[i] * y[i] + u[i] + drive) + 0.02 * rng.next()
            })
            .collect();
        y.copy_from_slice(&next);
    }
    merged.sort_by_key(|(key, _)| *key);
    (sites, merged.into_iter().map(|(_, row)| row).collect())
}

fn hostfile(tag: &str) -> PathBuf {
    let ports: Vec<u16> = (0..3)
        .map(|_| {
            let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
            l.local_addr().expect("addr").port()
        })
        .collect();
    let hosts = tmp(&format!("sites-hosts-{tag}.txt"));
    let body: String = ports.iter().map(|p| format!("127.0.0.1:{p}\n")).collect();
    std::fs::write(&hosts, body).expect("write");
    hosts
}

fn process(cfg: &Path, hosts: &Path, index: usize, extra: &[&str], stdin: Stdio) -> Child {
    let mut c: Command = bin();
    c.args(["network", "--config", cfg.to_str().expect("utf8"), "--processes", "3"])
        .args(["--process", &index.to_string(), "--hostfile", hosts.to_str().expect("utf8")])
        .args(extra)
        .stdin(stdin)
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    c.spawn().expect("spawn")
}

struct Setup {
    cfg: PathBuf,
    files: Vec<PathBuf>,
    want: Vec<u8>,
    site2: String,
}

fn setup(tag: &str, config: &str, steps: usize, jump: usize) -> Setup {
    let (sites, merged) = data(steps, config.contains("estimate = true"), jump);
    let cfg = tmp(&format!("sites-{tag}.toml"));
    std::fs::write(&cfg, config).expect("write");
    let merged_path = tmp(&format!("sites-{tag}-merged.csv"));
    std::fs::write(&merged_path, &merged).expect("write");
    let files: Vec<PathBuf> = sites
        .iter()
        .enumerate()
        .map(|(i, body)| {
            let p = tmp(&format!("sites-{tag}-{i}.csv"));
            std::fs::write(&p, body).expect("write");
            p
        })
        .collect();
    let one = run(
        &[
            "network",
            "--config",
            cfg.to_str().expect("utf8"),
            "--input",
            merged_path.to_str().expect("utf8"),
        ],
        b"",
    );
    assert!(one.status.success(), "{}", text(&one.stderr));
    let site2 = sites[2].clone();
    Setup { cfg, files, want: one.stdout, site2 }
}

fn path(p: &Path) -> &str {
    p.to_str().expect("utf8")
}

#[test]
fn three_sites_write_the_one_process_rows() {
    let given = CONFIG.replace("estimate = true", "gamma = 0.3");
    // The third run: C's clock steps 5 s ahead halfway (a site whose clock is off): the epochs
    // up to its time are composed, the other sites' subsystems stale there, as in one process.
    for (tag, config, jump) in
        [("given", given.clone(), 0), ("estimated", CONFIG.to_string(), 0), ("jump", given, 500)]
    {
        let s = setup(tag, &config, 3000, jump);
        let rows = text(&s.want).lines().count();
        assert!(rows >= 55, "{tag}: {rows} epoch rows");
        if tag == "estimated" {
            assert!(text(&s.want).lines().next().is_some_and(|h| h.contains("gamma_A_C")));
        }
        if tag == "jump" {
            let want = text(&s.want);
            assert!(want.lines().any(|l| l.contains("A: stale")), "{want}");
            assert!(want.lines().any(|l| l.contains("C: stale")), "{want}");
        }
        let hosts = hostfile(tag);
        let out = tmp(&format!("sites-{tag}-out.csv"));
        let _ = std::fs::remove_file(&out);
        let children: Vec<Child> = (0..3)
            .map(|i| {
                let mut extra = vec!["--input", path(&s.files[i])];
                if i == 0 {
                    extra.extend(["--output", path(&out)]);
                }
                process(&s.cfg, &hosts, i, &extra, Stdio::null())
            })
            .collect();
        for (i, c) in children.into_iter().enumerate() {
            let o = wait_bounded(c, 120, &format!("{tag}: process {i}"));
            assert!(o.status.success(), "{tag}: process {i}: {}", text(&o.stderr));
            if i > 0 {
                // Only snapshots crossed: far fewer bytes than the site's raw rows.
                let err = text(&o.stderr);
                let bytes: u64 = err
                    .split(" bytes of snapshots")
                    .next()
                    .and_then(|h| h.rsplit(", ").next())
                    .and_then(|b| b.trim().parse().ok())
                    .unwrap_or_else(|| panic!("{tag}: no byte count in: {err}"));
                let raw = std::fs::metadata(&s.files[i]).expect("size").len();
                assert!(bytes > 0 && bytes * 5 < raw, "{tag}: process {i} sent {bytes} of {raw}");
            }
        }
        let got = std::fs::read(&out).expect("process 0's output");
        assert_eq!(text(&got), text(&s.want), "{tag}: three processes");
    }
}

#[test]
fn a_killed_process_resumes_from_its_checkpoint_and_nothing_differs() {
    let s = setup("fault", CONFIG, 3000, 0);
    let hosts = hostfile("fault");
    let out = tmp("sites-fault-out.csv");
    let ck: Vec<PathBuf> = (0..3).map(|i| tmp(&format!("sites-fault-{i}.ckpt"))).collect();
    for c in &ck {
        let _ = std::fs::remove_file(c);
    }
    let _ = std::fs::remove_file(&out);
    let site = |i: usize, input: &str, extra: &[&str], stdin: Stdio| {
        // Checkpoints every 4 epochs: a site's may be newer than the composer's.
        let mut args = vec!["--input", input, "--checkpoint", path(&ck[i])];
        args.extend(["--checkpoint-epochs", "4"]);
        args.extend_from_slice(extra);
        if i == 0 {
            args.extend(["--output", path(&out)]);
        }
        process(&s.cfg, &hosts, i, &args, stdin)
    };
    let p0 = site(0, path(&s.files[0]), &[], Stdio::null());
    let p1 = site(1, path(&s.files[1]), &[], Stdio::null());
    // Process 2 reads its standard input: the first 40 % of its rows, then nothing.
    let mut p2 = site(2, "-", &[], Stdio::piped());
    let lines: Vec<&str> = s.site2.lines().collect();
    let head: String = lines[..lines.len() * 2 / 5].iter().map(|l| format!("{l}\n")).collect();
    let mut pipe = p2.stdin.take().expect("stdin");
    pipe.write_all(head.as_bytes()).expect("feed");
    // Mid-stream: epochs written and process 2's checkpoint there; then SIGKILL.
    let start = Instant::now();
    while !(ck[2].exists() && std::fs::read(&out).is_ok_and(|o| text(&o).lines().count() > 10)) {
        assert!(start.elapsed() < Duration::from_secs(60), "no progress before the kill");
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(300));
    let before = text(&std::fs::read(&out).expect("out")).lines().count();
    // Processes 0 and 1 have their whole files, yet wait for process 2 (epoch 24 of its rows):
    // their newest checkpoints (every 4 epochs) are at most one period past it.
    // Only the site's first valid epoch is read (the rest skipped, packed rings included).
    #[derive(serde::Deserialize)]
    struct SiteFile {
        site: Site,
    }
    #[derive(serde::Deserialize)]
    struct Site {
        valid_from: u64,
    }
    for c in &ck[..2] {
        let sealed = std::fs::read(c).expect("checkpoint");
        let v: SiteFile = streamcert_certificate::unseal::<()>(&sealed, None)
            .expect("sealed")
            .decode()
            .expect("a state");
        let from = v.site.valid_from;
        assert!(from <= 24 + 4, "{}: a site ran ahead to epoch {from}", c.display());
    }
    p2.kill().expect("SIGKILL");
    let _ = p2.wait();
    drop(pipe);
    // While it is down no epoch is composed (held back).
    std::thread::sleep(Duration::from_millis(1500));
    let during = text(&std::fs::read(&out).expect("out")).lines().count();
    // Process 2 had read 40 % of its rows: no epoch after them was composed.
    let total = text(&s.want).lines().count();
    assert!(before <= during && during <= total * 2 / 5 + 2, "{during} of {total} rows");
    // A damaged checkpoint, then process 1's, are refused (exit 5); the others wait.
    let damaged = tmp("sites-fault-damaged.ckpt");
    let mut bytes = std::fs::read(&ck[2]).expect("checkpoint");
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x01;
    std::fs::write(&damaged, &bytes).expect("write");
    let foreign = tmp("sites-fault-foreign.ckpt");
    std::fs::copy(&ck[1], &foreign).expect("copy");
    for (what, bad) in [("damaged", &damaged), ("foreign", &foreign)] {
        let args = ["--resume", path(bad)];
        let refused = wait_bounded(site(2, path(&s.files[2]), &args, Stdio::null()), 60, what);
        assert_eq!(refused.status.code(), Some(5), "{what}: {}", text(&refused.stderr));
    }
    // Restarted from its own checkpoint, reading its whole file.
    let p2 = site(2, path(&s.files[2]), &["--resume", path(&ck[2])], Stdio::null());
    let o2 = wait_bounded(p2, 120, "restarted process 2");
    let o0 = wait_bounded(p0, 120, "process 0");
    let o1 = wait_bounded(p1, 120, "process 1");
    for (i, o) in [(0, &o0), (1, &o1), (2, &o2)] {
        assert!(o.status.success(), "process {i}: {}", text(&o.stderr));
    }
    // Process 0 said a peer was lost, then named the process that had been down.
    let log = text(&o0.stderr);
    assert!(log.contains("a peer process was lost"), "{log}");
    assert!(log.contains("process 2 started again from its checkpoint"), "{log}");
    let got = std::fs::read(&out).expect("process 0's output");
    assert_eq!(text(&got), text(&s.want), "the run with a crash and a restart");
}

/// A site whose live input falls silent does not hold the network back: with `--silence`, its
/// clock advances with the wall clock, its subsystem turns stale under `stale_after`, and the
/// other sites' epochs are composed and written (not certified, naming the stale subsystem).
#[test]
fn a_silent_site_turns_stale_instead_of_holding_the_run() {
    let config = CONFIG.replace("estimate = true", "gamma = 0.3");
    let s = setup("silent", &config, 1000, 0);
    let hosts = hostfile("silent");
    let out = tmp("sites-silent-out.csv");
    let _ = std::fs::remove_file(&out);
    let p0 = process(
        &s.cfg,
        &hosts,
        0,
        &["--input", path(&s.files[0]), "--output", path(&out), "--flush-each-row"],
        Stdio::null(),
    );
    let p1 = process(&s.cfg, &hosts, 1, &["--input", path(&s.files[1])], Stdio::null());
    let mut p2 = process(&s.cfg, &hosts, 2, &["--input", "-", "--silence", "0.2"], Stdio::piped());
    let head: String = s.site2.lines().take(200).map(|l| format!("{l}\n")).collect();
    let mut pipe = p2.stdin.take().expect("stdin");
    pipe.write_all(head.as_bytes()).expect("feed");
    // Its rows end at t = 2 s; the epochs go on to the others' end (t = 10 s).
    let start = Instant::now();
    let rows = || text(&std::fs::read(&out).unwrap_or_default()).lines().count();
    while rows() < 20 {
        assert!(start.elapsed() < Duration::from_secs(60), "{} rows after 60 s", rows());
        std::thread::sleep(Duration::from_millis(50));
    }
    drop(pipe);
    for (i, c) in [p0, p1, p2].into_iter().enumerate() {
        let o = wait_bounded(c, 60, &format!("process {i}"));
        assert!(o.status.success(), "process {i}: {}", text(&o.stderr));
    }
    let got = text(&std::fs::read(&out).expect("output"));
    let stale: Vec<&str> = got.lines().filter(|l| l.contains("C: stale")).collect();
    assert!(stale.len() >= 8, "{got}");
    for line in &stale {
        // Not certified while C is stale: `t,epoch,rate,certified,...`.
        assert_eq!(line.split(',').nth(3), Some("0"), "{line}");
    }
    // Before C fell silent the rows are the one-process run's.
    let want = text(&s.want);
    let early: Vec<&str> = want.lines().take(5).collect();
    assert_eq!(got.lines().take(5).collect::<Vec<_>>(), early);
}

/// A malformed row at one site stops the run where the one-process run over the merged rows
/// stops: the same epoch rows, exit 3 on that site and on process 0 (naming the site and its
/// line); the other site reads to its end.
#[test]
fn a_malformed_row_at_one_site_stops_where_one_process_stops() {
    let config = CONFIG.replace("estimate = true", "gamma = 0.3");
    let s = setup("malformed", &config, 2000, 0);
    // Site 1's row 1203 (t = 12.03 s) is malformed, in its file and in the merged one. (At a
    // time exactly on an epoch boundary the one-process run would also compose that epoch when
    // another site's row at the same time comes first in the merged file: README.)
    let mut site1: Vec<String> =
        std::fs::read_to_string(&s.files[1]).expect("site 1").lines().map(str::to_string).collect();
    let bad = site1[1203].clone();
    let broken = bad.replacen(",B,", ",B,oops", 1);
    site1[1203].clone_from(&broken);
    std::fs::write(&s.files[1], site1.join("\n") + "\n").expect("write");
    let merged_path = tmp("sites-malformed-merged.csv");
    let merged = std::fs::read_to_string(&merged_path).expect("merged").replacen(&bad, &broken, 1);
    std::fs::write(&merged_path, merged).expect("write");
    let one = run(&["network", "--config", path(&s.cfg), "--input", path(&merged_path)], b"");
    assert_eq!(one.status.code(), Some(3), "{}", text(&one.stderr));
    let hosts = hostfile("malformed");
    let out = tmp("sites-malformed-out.csv");
    let _ = std::fs::remove_file(&out);
    let children: Vec<Child> = (0..3)
        .map(|i| {
            let mut extra = vec!["--input", path(&s.files[i])];
            if i == 0 {
                extra.extend(["--output", path(&out)]);
            }
            process(&s.cfg, &hosts, i, &extra, Stdio::null())
        })
        .collect();
    let outs: Vec<_> = children
        .into_iter()
        .enumerate()
        .map(|(i, c)| wait_bounded(c, 120, &format!("process {i}")))
        .collect();
    assert_eq!(outs[1].status.code(), Some(3), "{}", text(&outs[1].stderr));
    assert!(text(&outs[1].stderr).contains(":1204:"), "{}", text(&outs[1].stderr));
    assert_eq!(outs[0].status.code(), Some(3), "{}", text(&outs[0].stderr));
    let zero = text(&outs[0].stderr);
    assert!(zero.contains("process 1: ") && zero.contains(":1204: field 3"), "{zero}");
    assert_eq!(outs[2].status.code(), Some(0), "{}", text(&outs[2].stderr));
    let got = std::fs::read(&out).expect("process 0's output");
    assert_eq!(text(&got), text(&one.stdout));
}
