//! `cargo xtask reliability`: every bad input the reliability work covers, run through the
//! `streamcert` binary as a user would, with the exit code and the first line the user reads,
//! written to RELIABILITY.md. Nothing in the table is typed by hand.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::{Context, Result, bail};

use crate::common::{markdown, write};

/// The binary, built in release mode by this command.
pub(crate) fn binary() -> Result<PathBuf> {
    let status = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
        .args(["build", "--release", "-q", "-p", "streamcert-cli"])
        .status()
        .context("building streamcert-cli")?;
    if !status.success() {
        bail!("building streamcert-cli failed");
    }
    Ok(PathBuf::from("target/release/streamcert"))
}

/// Run the binary with `args` and `stdin`; (exit code, first stderr line, stdout).
fn run(bin: &Path, args: &[&str], stdin: &[u8]) -> Result<(i32, String, String)> {
    use std::io::Write;
    let mut child = Command::new(bin)
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("running {}", bin.display()))?;
    // Feed stdin from another thread: the child writes its output while it reads, so writing
    // all the input first could fill the output pipe and deadlock.
    let mut pipe = child.stdin.take().context("stdin")?;
    let data = stdin.to_vec();
    let feeder = std::thread::spawn(move || {
        let _ = pipe.write_all(&data);
    });
    let out = child.wait_with_output()?;
    let _ = feeder.join();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let mut first = stderr
        .lines()
        .find(|l| !l.starts_with("summary:") && !l.is_empty())
        .or_else(|| stderr.lines().next())
        .unwrap_or("")
        .to_string();
    // A run that goes on after a message (a skipped row) ends with its verdict: append it.
    if let Some(v) = stderr.lines().find(|l| l.starts_with("verdict"))
        && !first.starts_with("verdict")
    {
        first = format!("{first} / {v}");
    }
    // A TOML error says what is wrong below its excerpt of the file: append those lines.
    if first.contains("TOML parse error") {
        for l in stderr.lines().skip(1).filter(|l| !l.trim().is_empty() && !l.contains('|')) {
            first = format!("{first} / {}", l.trim());
        }
    }
    Ok((out.status.code().unwrap_or(-1), first, String::from_utf8_lossy(&out.stdout).into()))
}

/// One row of the table: the case, the exit code, the message.
fn record(rows: &mut Vec<Vec<String>>, case: &str, (code, message, _): (i32, String, String)) {
    rows.push(vec![case.into(), code.to_string(), format!("`{}`", message.replace('|', "\\|"))]);
}

/// Flip one bit of `bytes` at `at`.
fn flip(mut bytes: Vec<u8>, at: usize) -> Vec<u8> {
    bytes[at] ^= 0x02;
    bytes
}

/// Write the table to `out/RELIABILITY.md`.
pub(crate) fn run_all(out: &Path) -> Result<()> {
    let bin = binary()?;
    std::fs::create_dir_all(out)?;
    // The configuration and data every case starts from.
    let (_, _, template) = run(&bin, &["certify", "--print-config"], b"")?;
    // The printed template with G5 node b's required keys set (what `g5_node_b` writes).
    anyhow::ensure!(template == streamcert_pipeline::config::DEFAULT_CONFIG, "--print-config");
    let config = streamcert_pipeline::config::g5_node_b();
    let cfg_path = out.join("config.toml");
    std::fs::write(&cfg_path, &config)?;
    let cfg = s(&cfg_path)?;
    let (_, _, data) = run(&bin, &["simulate", "g5", "--experiment", "1", "--seed", "1"], b"")?;
    let lines = data.lines().map(str::to_string).collect();
    let cases = Cases { bin, out: out.to_path_buf(), cfg, config, template, lines };
    let mut rows: Vec<Vec<String>> = Vec::new();
    cases.checkpoint_cases(&mut rows)?;
    cases.time_cases(&mut rows)?;
    cases.value_cases(&mut rows)?;
    cases.csv_cases(&mut rows)?;
    cases.config_cases(&mut rows)?;
    let mut text = String::new();
    let _ = writeln!(
        text,
        "# Reliability: bad inputs and what the user sees\n\nProduced by `cargo xtask reliability` (target/reliability/RELIABILITY.md; a copy is committed at the top level). Each case runs the release `streamcert` binary on data from `streamcert simulate g5 --experiment 1 --seed 1` and the printed configuration (`certify --print-config`) with node b's required keys set (time `t`, output `y_b`, input `u_b`, gain [[-4.0]], margin 0.05), edited as the case says. Exit codes: 0 success, 2 configuration, 3 input data, 4 I/O, 5 checkpoint. The message is the first line on standard error (for runs that succeed, the verdict line; for a TOML error, with the lines that say what is wrong)."
    );
    let _ = writeln!(text, "\n{}", markdown(&["case", "exit", "message"], &rows));
    write(&out.join("RELIABILITY.md"), &text)?;
    println!("wrote {}", out.join("RELIABILITY.md").display());
    Ok(())
}

fn replace_field(line: &str, i: usize, value: &str) -> String {
    line.split(',')
        .enumerate()
        .map(|(k, f)| if k == i { value.to_string() } else { f.to_string() })
        .collect::<Vec<_>>()
        .join(",")
}

/// A path as text (the binary's arguments).
fn s(p: &Path) -> Result<String> {
    p.to_str().map(str::to_string).context("utf-8 path")
}

/// What every case starts from: the binary, the output folder, the configuration (its path
/// and text), the printed template and the simulated data's lines.
struct Cases {
    bin: PathBuf,
    out: PathBuf,
    cfg: String,
    config: String,
    template: String,
    lines: Vec<String>,
}

impl Cases {
    /// A file in the output folder.
    fn path(&self, name: &str) -> PathBuf {
        self.out.join(name)
    }

    /// Run the binary.
    fn run(&self, args: &[&str], stdin: &[u8]) -> Result<(i32, String, String)> {
        run(&self.bin, args, stdin)
    }

    /// `certify` with the configuration and `extra` arguments.
    fn certify(&self, extra: &[&str], stdin: &[u8]) -> Result<(i32, String, String)> {
        let mut args = vec!["certify", "--config", self.cfg.as_str()];
        args.extend_from_slice(extra);
        self.run(&args, stdin)
    }

    /// The first 600 lines (the header and 599 rows).
    fn first(&self) -> String {
        format!("{}\n", self.lines[..600].join("\n"))
    }

    /// The header and the rows 600 to 899 (what a resumed run reads).
    fn rest(&self) -> String {
        format!("{}\n{}\n", self.lines[0], self.lines[600..900].join("\n"))
    }

    /// Damaged, foreign and intact checkpoints.
    fn checkpoint_cases(&self, rows: &mut Vec<Vec<String>>) -> Result<()> {
        let first = self.first();
        let rest = self.rest();
        let ckpt = self.path("state.ckpt");
        let ck = s(&ckpt)?;
        self.certify(&["--checkpoint", &ck], first.as_bytes())?;
        let good = std::fs::read(&ckpt)?;
        let resume = |bytes: &[u8]| -> Result<(i32, String, String)> {
            let damaged = self.path("damaged.ckpt");
            std::fs::write(&damaged, bytes)?;
            self.certify(&["--resume", &s(&damaged)?], rest.as_bytes())
        };
        record(rows, "checkpoint: intact (resume)", resume(&good)?);
        record(
            rows,
            "checkpoint: one bit flipped in the payload",
            resume(&flip(good.clone(), good.len() / 2))?,
        );
        record(
            rows,
            "checkpoint: one bit flipped in the checksum",
            resume(&flip(good.clone(), 30))?,
        );
        record(rows, "checkpoint: truncated", resume(&good[..good.len() - 100])?);
        record(rows, "checkpoint: empty file", resume(b"")?);
        record(
            rows,
            "checkpoint: a JSON file that is not a checkpoint",
            resume(b"{\"certifier\": 1}\n")?,
        );
        let (certifier, cert_config) = payload(&good)?;
        let reseal = |edit: &dyn Fn(&mut serde_json::Value)| -> Result<Vec<u8>> {
            let mut v = certifier.clone();
            edit(&mut v);
            reseal(&v, &cert_config)
        };
        record(
            rows,
            "checkpoint: Gram entry set to −5, checksum recomputed",
            resume(&reseal(&|v| v["certifier"]["regression"]["g"][0] = (-5.0).into())?)?,
        );
        record(
            rows,
            "checkpoint: spike count off by one, checksum recomputed",
            resume(&reseal(&|v| {
                let spikes = &mut v["certifier"]["ambiguity"][0]["spikes"];
                *spikes = (spikes.as_u64().unwrap_or(0) + 1).into();
            })?)?,
        );
        record(
            rows,
            "checkpoint: ‖K‖ changed, checksum recomputed",
            resume(&reseal(&|v| v["certifier"]["gain_norm"] = 9.0.into())?)?,
        );
        record(
            rows,
            "checkpoint: a ring buffer one entry short, checksum recomputed",
            resume(&reseal(&|v| {
                if let Some(a) = v["certifier"]["regression"]["col_z"].as_array_mut() {
                    a.pop();
                }
            })?)?,
        );
        record(
            rows,
            "checkpoint: eigenvalue scratch emptied, checksum recomputed",
            resume(&reseal(&|v| v["certifier"]["eig_work"] = serde_json::json!([]))?)?,
        );
        self.calibrated_checkpoint_cases(rows)
    }

    /// A calibrated checkpoint's `T = [I; K]` zeroed, and a checkpoint of another
    /// configuration (the one [`checkpoint_cases`](Self::checkpoint_cases) wrote).
    fn calibrated_checkpoint_cases(&self, rows: &mut Vec<Vec<String>>) -> Result<()> {
        let (first, rest, ck) = (self.first(), self.rest(), s(&self.path("state.ckpt"))?);
        // With the calibrated certificate on: its `T = [I; K]` zeroed.
        let cal_cfg = self.path("calibrated.toml");
        std::fs::write(
            &cal_cfg,
            self.config.replace("enabled = false\ndelta", "enabled = true\ndelta"),
        )?;
        let cal = s(&cal_cfg)?;
        let cal_ckpt = self.path("calibrated.ckpt");
        self.run(&["certify", "--config", &cal, "--checkpoint", &s(&cal_ckpt)?], first.as_bytes())?;
        let (mut cal_state, cal_config) = payload(&std::fs::read(&cal_ckpt)?)?;
        if let Some(t) = cal_state["certifier"]["calibrated"]["tmat"].as_array_mut() {
            t.iter_mut().for_each(|x| *x = 0.0.into());
        }
        let zeroed = reseal(&cal_state, &cal_config)?;
        let damaged = self.path("damaged-calibrated.ckpt");
        std::fs::write(&damaged, zeroed)?;
        record(
            rows,
            "checkpoint: calibrated `T = [I; K]` zeroed, checksum recomputed",
            self.run(&["certify", "--config", &cal, "--resume", &s(&damaged)?], rest.as_bytes())?,
        );
        let other_cfg = self.path("other.toml");
        std::fs::write(&other_cfg, self.config.replace("margin = 0.05", "margin = 0.06"))?;
        record(
            rows,
            "checkpoint: written under another configuration",
            self.run(&["certify", "--config", &s(&other_cfg)?, "--resume", &ck], rest.as_bytes())?,
        );
        Ok(())
    }

    /// The time column: a gap, irregular sampling, duplicated and backward times.
    fn time_cases(&self, rows: &mut Vec<Vec<String>>) -> Result<()> {
        let lines: Vec<&str> = self.lines.iter().map(String::as_str).collect();
        let header = lines[0];
        let body: Vec<&str> = lines[1..900].to_vec();
        let with_gap: String = std::iter::once(header)
            .chain(body.iter().copied().filter(|l| {
                let t: f64 = l.split(',').next().and_then(|v| v.parse().ok()).unwrap_or(0.0);
                !(8.0..10.0).contains(&t)
            }))
            .collect::<Vec<_>>()
            .join("\n");
        let (code, _, out_rows) =
            self.certify(&["--summary", &s(&self.path("gap.json"))?], with_gap.as_bytes())?;
        let gap_row = out_rows.lines().find(|l| l.contains("gap of")).unwrap_or("").to_string();
        let summary = std::fs::read_to_string(self.path("gap.json")).unwrap_or_default();
        rows.push(vec![
            "a 2 s gap in the time column".into(),
            code.to_string(),
            format!(
                "row: `…{}`; summary gaps: {}",
                gap_row.split(',').nth(10).unwrap_or(""),
                serde_json::from_str::<serde_json::Value>(&summary)
                    .map_or(0, |v| v["gaps"].as_u64().unwrap_or(0))
            ),
        ]);
        let jitter: String = std::iter::once(header)
            .chain(
                body.iter()
                    .enumerate()
                    .filter(|(i, _)| (i * 7919) % 10 < 7 || i % 4 == 0)
                    .map(|(_, l)| *l),
            )
            .collect::<Vec<_>>()
            .join("\n");
        record(
            rows,
            "irregular sampling (a fixed 70 % of the rows kept)",
            self.certify(&[], jitter.as_bytes())?,
        );
        let dup = format!("{header}\n{}\n{}\n", body[0], body[0]);
        record(rows, "a duplicated time", self.certify(&[], dup.as_bytes())?);
        let back = format!("{header}\n{}\n{}\n", body[1], body[0]);
        record(rows, "a time before the previous one", self.certify(&[], back.as_bytes())?);
        Ok(())
    }

    /// Bad values and rows.
    fn value_cases(&self, rows: &mut Vec<Vec<String>>) -> Result<()> {
        let lines: Vec<&str> = self.lines.iter().map(String::as_str).collect();
        let header = lines[0];
        let body: Vec<&str> = lines[1..900].to_vec();
        let row =
            |edit: &dyn Fn(&str) -> String| format!("{header}\n{}\n{}\n", body[0], edit(body[1]));
        record(
            rows,
            "NaN in y",
            self.certify(&[], row(&|l| replace_field(l, 3, "NaN")).as_bytes())?,
        );
        record(
            rows,
            "infinity in u",
            self.certify(&[], row(&|l| replace_field(l, 4, "inf")).as_bytes())?,
        );
        record(
            rows,
            "a non-number",
            self.certify(&[], row(&|l| replace_field(l, 3, "abc")).as_bytes())?,
        );
        record(
            rows,
            "a truncated row",
            self.certify(
                &[],
                row(&|l| l.split(',').take(3).collect::<Vec<_>>().join(",")).as_bytes(),
            )?,
        );
        record(
            rows,
            "an unterminated quote",
            self.certify(&[], row(&|l| replace_field(l, 3, "\"0.1")).as_bytes())?,
        );
        record(rows, "an empty file", self.certify(&[], b"")?);
        record(
            rows,
            "a header and no data row",
            self.certify(&[], format!("{header}\n").as_bytes())?,
        );
        record(
            rows,
            "a header without the configured columns",
            self.certify(&[], b"time,a,b\n0,0,0\n")?,
        );
        Ok(())
    }

    /// CSV as other programs write it.
    fn csv_cases(&self, rows: &mut Vec<Vec<String>>) -> Result<()> {
        let lines: Vec<&str> = self.lines.iter().map(String::as_str).collect();
        let bom = format!("\u{feff}{}", lines[..50].join("\n"));
        record(rows, "a UTF-8 byte-order mark", self.certify(&[], bom.as_bytes())?);
        let semicolons = lines[..50].join("\n").replace(',', ";");
        record(rows, "semicolons, default delimiter", self.certify(&[], semicolons.as_bytes())?);
        let semi_cfg = self.path("semicolon.toml");
        std::fs::write(
            &semi_cfg,
            self.config.replacen("time = \"t\"", "time = \"t\"\ndelimiter = \";\"", 1),
        )?;
        record(
            rows,
            "semicolons, `delimiter = \";\"`",
            self.run(&["certify", "--config", &s(&semi_cfg)?], semicolons.as_bytes())?,
        );
        let quoted = lines[..50]
            .iter()
            .map(|l| l.split(',').map(|f| format!("\"{f}\"")).collect::<Vec<_>>().join(","))
            .collect::<Vec<_>>()
            .join("\r\n");
        record(rows, "quoted fields and CRLF line ends", self.certify(&[], quoted.as_bytes())?);
        Ok(())
    }

    /// Configuration files: unknown keys, omitted defaults, required keys, a bad last row.
    fn config_cases(&self, rows: &mut Vec<Vec<String>>) -> Result<()> {
        let lines: Vec<&str> = self.lines.iter().map(String::as_str).collect();
        let bad_cfg = self.path("bad.toml");
        std::fs::write(&bad_cfg, self.config.replace("margin = 0.05", "margin = 0.05\nmargn = 1"))?;
        record(
            rows,
            "an unknown configuration key",
            self.run(&["certify", "--config", &s(&bad_cfg)?], b"")?,
        );
        let start = self.config.find("[ambiguity]").context("ambiguity section")?;
        let end = self.config.find("[calibration]").context("calibration section")?;
        let short = format!(
            "{}[ambiguity]\nenabled = true\n\n{}",
            &self.config[..start],
            &self.config[end..]
        );
        let short_cfg = self.path("short.toml");
        std::fs::write(&short_cfg, short)?;
        record(
            rows,
            "`[ambiguity]` with only `enabled` (documented defaults omitted)",
            self.run(&["certify", "--config", &s(&short_cfg)?], lines[..50].join("\n").as_bytes())?,
        );

        let required = "[columns]\ntime = \"t\"\noutputs = [\"y_b\"]\ninputs = [\"u_b\"]\n\
                        [controller]\ngain = [[-4.0]]\n[certificate]\nmargin = 0.05\n";
        let required_cfg = self.path("required.toml");
        std::fs::write(&required_cfg, required)?;
        record(
            rows,
            "only the required keys (columns, gain, margin)",
            self.run(
                &["certify", "--config", &s(&required_cfg)?],
                lines[..50].join("\n").as_bytes(),
            )?,
        );
        let no_margin_cfg = self.path("no-margin.toml");
        std::fs::write(&no_margin_cfg, required.replace("margin = 0.05\n", ""))?;
        record(
            rows,
            "a required key missing (`margin`)",
            self.run(&["certify", "--config", &s(&no_margin_cfg)?], b"")?,
        );
        let template_cfg = self.path("template.toml");
        std::fs::write(&template_cfg, &self.template)?;
        record(
            rows,
            "the printed template unedited (no gain, margin or columns chosen)",
            self.run(&["certify", "--config", &s(&template_cfg)?], b"")?,
        );
        let bad_last =
            format!("{}\n{}\n", lines[..900].join("\n"), replace_field(lines[900], 3, "NaN"));
        record(
            rows,
            "a bad last row, `--on-bad-row skip` (a skipped row closes the gates)",
            self.certify(&["--on-bad-row", "skip"], bad_last.as_bytes())?,
        );
        Ok(())
    }
}

/// A `certify` checkpoint's payload: the certifier (its block rings unpacked when the
/// binary encoding packed them) and the run's summary.
#[derive(serde::Deserialize)]
struct CertifyCheckpoint {
    certifier: streamcert_certificate::Certifier,
    summary: serde_json::Value,
}

/// A sealed `certify` checkpoint's payload as a JSON value (whatever its encoding; every
/// block ring whole), and the certifier's configuration it holds.
fn payload(sealed: &[u8]) -> Result<(serde_json::Value, streamcert_certificate::CertifierConfig)> {
    let cp: CertifyCheckpoint = streamcert_certificate::unseal::<()>(sealed, None)?.decode()?;
    let state = serde_json::json!({
        "certifier": serde_json::to_value(&cp.certifier)?,
        "summary": cp.summary,
    });
    Ok((state, cp.certifier.config().clone()))
}

/// `state` sealed again for `config` in the binary encoding the command line writes, with a
/// valid checksum: a damage that only the state's own checks can catch.
fn reseal(
    state: &serde_json::Value,
    config: &streamcert_certificate::CertifierConfig,
) -> Result<Vec<u8>> {
    Ok(streamcert_certificate::seal_value(state, streamcert_certificate::Encoding::Binary, config)?)
}
