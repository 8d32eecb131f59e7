//! `cargo xtask real`: the two public plant records of `examples/real/` (streamcert's CSV,
//! checked by hash), certified with their configurations, and the heat exchanger's verdict
//! compared in °C and in K (it must be the same: the affine model); and for each record the
//! calibrated gate's share of open rows at fixed horizons and base windows (`real/grid.rs`).
//!
//! The committed files are conversions of `exchanger.csv` and `tanque.csv` of the public
//! repository `Rafa7046/Non_Linear_Identification` at commit
//! `e5c9b006b0a2ec1650bc018a5fb38d2f4363d4c7` (`src/data/`), themselves copies of the DaISy
//! heat exchanger (97-002) and the cascaded tanks benchmark (see `examples/real/README.md`).
//! With `--from DIR` (a folder holding those two files) the command checks the originals'
//! hashes and that converting them gives the committed files byte for byte.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Cursor;
use std::path::Path;

use anyhow::{Context, Result, bail};
use sha2::{Digest, Sha256};
use streamcert_pipeline::certify::{Options, Summary, run as certify};
use streamcert_pipeline::config::parse;

use crate::common::{markdown, median, write};

mod grid;
mod orders;

/// One record: the original's file name under `DIR` and its SHA-256, the committed
/// conversion and its SHA-256, its configuration and the conversion.
struct Record {
    name: &'static str,
    file: &'static str,
    sha256: &'static str,
    converted: &'static str,
    converted_sha256: &'static str,
    config: &'static str,
    convert: fn(&str) -> Result<String>,
}

const RECORDS: [Record; 2] = [
    Record {
        name: "exchanger",
        file: "exchanger.csv",
        sha256: "3dfbb1e1c2f789a3593b460373c5c0a649647ab5548478ed0992c68d5b2c5f34",
        converted: "examples/real/exchanger.csv",
        converted_sha256: "827b8fb3c724da60fb02eed30f08a6f77c86522a08302d2cc86d985baff1a754",
        config: "examples/real/exchanger.toml",
        convert: exchanger,
    },
    Record {
        name: "tanks",
        file: "tanque.csv",
        sha256: "ef2388ed822f3aef4aa80d6b0f2b466dd80b361786b3eafc7a2957c31ea323a7",
        converted: "examples/real/tanks.csv",
        converted_sha256: "2413320a0796a740ea94eb76e214bdf171f6b1a129765b42c5424cf4cce08de5",
        config: "examples/real/tanks.toml",
        convert: tanks,
    },
];

/// `ts,q,th` (s, flow, °C) to `t,flow,temp` (the temperature in °C).
fn exchanger(text: &str) -> Result<String> {
    add_to_third_column(text, 0.0, "exchanger.csv").map(|s| s.replacen("ts,q,th", "t,flow,temp", 1))
}

/// The same three-column record with `offset` added to its third column (0: the values as
/// recorded; 273.15: °C to K), the header kept.
fn add_to_third_column(text: &str, offset: f64, name: &str) -> Result<String> {
    map_third_column(text, |th| th + offset, name)
}

/// `text` (`t,q,temperature`) with `f` applied to the third column.
fn map_third_column(text: &str, f: impl Fn(f64) -> f64, name: &str) -> Result<String> {
    let mut lines = text.lines();
    let mut out = format!("{}\n", lines.next().context("no header")?);
    for (i, line) in lines.enumerate() {
        let fields: Vec<&str> = line.split(',').collect();
        let [t, q, th] = fields[..] else { bail!("{name} line {}: 3 fields expected", i + 2) };
        let th: f64 = th.trim().parse().with_context(|| format!("line {}", i + 2))?;
        let _ = writeln!(out, "{},{},{}", t.trim(), q.trim(), f(th));
    }
    Ok(out)
}

/// The same record in mK: the calibrated gate at every row (the fits' ridge is in the units
/// as logged, so certificates agree to about 10⁻⁶ only; the instruments' strength is
/// measured equilibrated, so the unit refuses no fit): `(rows whose certificate is present in
/// one run only, the largest relative difference where both are)`, or an error naming the
/// first row whose gate differs.
fn millikelvin_check(config: &str, csv: &str, celsius: &Certified) -> Result<(usize, f64)> {
    let mk = map_third_column(csv, |th| (th + 273.15) * 1000.0, "exchanger")?;
    let mk = certify_text(config, &mk, "exchanger (mK)")?;
    let (mut presence, mut worst) = (0usize, 0.0f64);
    for (c, k) in celsius.rows.iter().zip(&mk.rows) {
        if c.get("calibrated_open") != k.get("calibrated_open") {
            bail!("°C and mK differ at t = {:?}: calibrated_open", c.get("t"));
        }
        match (number(c, "cert_calibrated"), number(k, "cert_calibrated")) {
            (Some(a), Some(b)) => worst = worst.max((a - b).abs() / (1.0 + a.abs())),
            (None, None) => {}
            _ => presence += 1,
        }
    }
    Ok((presence, worst))
}

/// `"uEst","uVal","yEst","yVal","Ts"` (the estimation record: pump and level voltages,
/// sampled every `Ts` = 4 s) to `t,pump,level`.
fn tanks(text: &str) -> Result<String> {
    let mut out = String::from("t,pump,level\n");
    let mut ts = None;
    for (i, line) in text.lines().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split(',').collect();
        if f.len() < 4 {
            bail!("tanque.csv line {}: at least 4 fields expected", i + 1);
        }
        if ts.is_none() {
            ts = Some(f.get(4).and_then(|v| v.trim().parse::<f64>().ok()).context("Ts")?);
        }
        let t = (i - 1) as f64 * ts.unwrap_or(4.0);
        let _ = writeln!(out, "{t},{},{}", f[0].trim(), f[2].trim());
    }
    Ok(out)
}

/// One certified run: its summary and its evidence rows (column name to text).
struct Certified {
    summary: Summary,
    rows: Vec<BTreeMap<String, String>>,
}

fn certify_text(config: &str, csv: &str, name: &str) -> Result<Certified> {
    let cfg = parse(config, name)?;
    let opts = Options::default();
    let mut out = Vec::new();
    let summary = certify(&cfg, Cursor::new(csv.as_bytes().to_vec()), name, &mut out, &opts)?;
    let text = String::from_utf8(out)?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().context("no header")?.split(',').collect();
    let rows = lines
        .map(|l| header.iter().map(|h| h.to_string()).zip(l.split(',').map(String::from)).collect())
        .collect();
    Ok(Certified { summary, rows })
}

fn number(row: &BTreeMap<String, String>, col: &str) -> Option<f64> {
    row.get(col).and_then(|v| v.parse().ok())
}

/// The most frequent reasons the calibrated gate was closed, with their shares.
fn reasons(c: &Certified) -> String {
    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    for r in &c.rows {
        let why = r.get("reason_calibrated").map_or("", String::as_str).trim_matches('"');
        // "window 600: the rate is at most …" names its window first.
        let why = match why.split_once(": ") {
            Some((w, rest)) if w.starts_with("window") => rest,
            _ => why,
        };
        // The reason's kind: its text up to the first number or parenthesis.
        let kind: String =
            why.chars().take_while(|ch| !ch.is_ascii_digit() && *ch != '(' && *ch != '-').collect();
        let kind = if kind.trim().is_empty() { "open".into() } else { kind.trim().to_string() };
        *counts.entry(kind).or_default() += 1;
    }
    let mut v: Vec<(String, usize)> = counts.into_iter().collect();
    v.sort_by_key(|e| std::cmp::Reverse(e.1));
    let n = c.rows.len().max(1) as f64;
    v.iter()
        .take(4)
        .map(|(k, c)| format!("{k} {:.0} %", 100.0 * *c as f64 / n))
        .collect::<Vec<_>>()
        .join("; ")
}

/// The file at `path`, refused unless its SHA-256 is `sha256`.
fn checked(path: &Path, sha256: &str) -> Result<String> {
    let bytes = std::fs::read(path)
        .with_context(|| format!("reading {} (run from the repository root)", path.display()))?;
    let digest: String = Sha256::digest(&bytes).iter().map(|b| format!("{b:02x}")).collect();
    if digest != sha256 {
        bail!("{}: SHA-256 {digest}, expected {sha256} (another file?)", path.display());
    }
    Ok(String::from_utf8(bytes)?)
}

/// The heat exchanger's record in K and in mK against °C (`affine`, its certification): the
/// same gates at every row and the certificates within 10⁻⁹ relative, else an error; the
/// paragraph of REAL.md that says so.
fn units_check(config: &str, csv: &str, affine: &Certified) -> Result<String> {
    let mut units = String::new();
    // The same record in K: the same verdict at every row, the same certificates
    // within 10⁻⁹ relative (the working origin makes both runs integrate the same
    // excursions; only the rounding of forming them differs).
    let kelvin =
        certify_text(config, &add_to_third_column(csv, 273.15, "exchanger")?, "exchanger (K)")?;
    let mut worst = 0.0f64;
    for (c, k) in affine.rows.iter().zip(&kelvin.rows) {
        for col in ["calibrated_open", "gauss_open"] {
            if c.get(col) != k.get(col) {
                bail!("°C and K differ at t = {:?}: {col}", c.get("t"));
            }
        }
        for col in ["beta_hat", "rho", "cert_calibrated", "rho_calibrated"] {
            if let (Some(a), Some(b)) = (number(c, col), number(k, col)) {
                worst = worst.max((a - b).abs() / (1.0 + a.abs()));
            } else if number(c, col).is_some() != number(k, col).is_some() {
                bail!("°C and K differ at t = {:?}: {col} present in one", c.get("t"));
            }
        }
    }
    if !(worst <= 1e-9) {
        bail!("°C and K certificates differ by {worst:e} relative");
    }
    let _ = writeln!(
        units,
        "The heat exchanger in °C and in K (the temperature plus 273.15): the same gates at every one of {} rows, certificates equal to {worst:.1e} relative (the check fails above 1e-9).\n",
        affine.rows.len()
    );
    let (presence, mk_worst) = millikelvin_check(config, csv, affine)?;
    let _ = writeln!(
        units,
        "In mK ((the temperature plus 273.15) × 1000, excursions of about 7000): the same calibrated gate at every row (the check fails otherwise); certificates equal to {mk_worst:.1e} relative where both runs have one, and present in one run only at {presence} rows (every calibrated fit is in no unit: its ridge is relative to each diagonal entry and its refusals are judged equilibrated).\n"
    );
    Ok(units)
}

/// Check and certify every committed record (and, with `from`, check the originals and their
/// conversion); write `REAL.md` under `out`.
pub(crate) fn run(from: Option<&Path>, out: &Path) -> Result<()> {
    std::fs::create_dir_all(out)?;
    let mut rows = Vec::new();
    let (mut units, mut grids) = (String::new(), String::new());
    for rec in &RECORDS {
        let csv = checked(Path::new(rec.converted), rec.converted_sha256)?;
        if let Some(from) = from {
            let original = checked(&from.join(rec.file), rec.sha256)?;
            if (rec.convert)(&original)? != csv {
                bail!("converting {} does not give {}", rec.file, rec.converted);
            }
            println!("{}: the original's hash and its conversion agree", rec.converted);
        }
        let config = std::fs::read_to_string(rec.config)
            .with_context(|| format!("reading {} (run from the repository root)", rec.config))?;
        let affine = certify_text(&config, &csv, rec.name)?;
        let origin = certify_text(
            &config.replace("model = \"affine\"", "model = \"through_origin\""),
            &csv,
            rec.name,
        )?;
        for (model, c) in [("affine (default)", &affine), ("through the origin", &origin)] {
            let betas: Vec<f64> = c.rows.iter().filter_map(|r| number(r, "beta_hat")).collect();
            let certs: Vec<f64> =
                c.rows.iter().filter_map(|r| number(r, "cert_calibrated")).collect();
            let s = &c.summary;
            rows.push(vec![
                rec.name.to_string(),
                model.to_string(),
                s.rows.to_string(),
                format!("{:.1} %", 100.0 * s.share_calibrated()),
                s.first_deploy_calibrated.map_or("never".into(), |t| format!("{t} s")),
                if betas.is_empty() { "–".into() } else { format!("{:.4}", median(&betas)) },
                if certs.is_empty() { "–".into() } else { format!("{:.4}", median(&certs)) },
                reasons(c),
            ]);
        }
        if rec.name == "exchanger" {
            units.push_str(&units_check(&config, &csv, &affine)?);
            // The automatic horizons, with only the columns, gain and margin set: the same
            // verdict in K.
            let auto = grid::minimal(&config, None)?;
            let _ = writeln!(
                units,
                "With only the columns, gain and margin set and `horizon`, `window` \"auto\":\n"
            );
            units.push_str(&units_check(&auto, &csv, &certify_text(&auto, &csv, rec.name)?)?);
        }
        grids.push_str(&grid::grid(rec.name, &config, &csv)?);
        grids.push_str(&orders::section(rec.name, &config, &csv)?);
    }
    let mut s = String::from(
        "# Real plant records\n\nProduced by `cargo xtask real` (the records' sources, hashes and configurations: examples/real/README.md).\n\n",
    );
    let _ = writeln!(
        s,
        "{}",
        markdown(
            &[
                "record",
                "model",
                "rows",
                "calibrated gate open",
                "first opened",
                "median β̂",
                "median calibrated certificate",
                "calibrated gate's state (share of rows)"
            ],
            &rows
        )
    );
    s.push_str(&units);
    s.push_str(&grids);
    write(&out.join("REAL.md"), &s)?;
    println!("wrote {}", out.join("REAL.md").display());
    Ok(())
}
