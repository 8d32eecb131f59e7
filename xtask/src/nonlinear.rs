//! `cargo xtask nonlinear`: three certificates side by side on the same runs of scalar
//! nonlinear loops with a known state-dependent rate (the paper's Gaussian certificate, the
//! linear calibrated one and the nonlinear one), against the smallest true rate over the
//! region each certificate speaks for (NONLINEAR.md).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;
use streamcert_certificate::nonlinear::simultaneous_multiplier;
use streamcert_certificate::{
    Calibration, CertificateKind, Certifier, CertifierConfig, FeatureSet, Interval,
    NonlinearConfig, RegionBound, RiskSplit,
};
use streamcert_regression::{InputIntegral, RegressionConfig};

use statrs::distribution::{ContinuousCDF, Normal};

use crate::common::{markdown, median, progress, write};

mod cells;
use crate::validity::clopper_pearson;
use cells::{Cell, cells};

const DELTA: f64 = 0.01;
const MARGIN: f64 = 0.05;
const H: usize = 5;
const WINDOW: usize = 50;
const PAPER_C: f64 = 0.1;
/// The study's certifiers: the default configuration (no `[nonlinear]` section, so its linear
/// calibrated gate is closed by its guards alone), and nonlinear ones by library and region.
#[derive(Clone, Copy, PartialEq)]
enum Lib {
    /// No `[nonlinear]` section.
    Default,
    /// The polynomial library of this degree over the default region, with this bound.
    Poly(usize, RegionBound),
    /// The named library `y, y·tanh y`, the default region, with this bound.
    Tanh(RegionBound),
}

/// The certifiers of one run, each fed every sample once (the rows below read them).
const CERTIFIERS: [Lib; 6] = [
    Lib::Poly(2, RegionBound::Pointwise),
    Lib::Poly(2, RegionBound::Simultaneous),
    Lib::Poly(3, RegionBound::Pointwise),
    Lib::Tanh(RegionBound::Pointwise),
    Lib::Tanh(RegionBound::Simultaneous),
    Lib::Default,
];

/// The certificates of the table: the kind, and the certifier that gives it.
const ROWS: [(CertificateKind, Lib, &str); 8] = [
    (CertificateKind::Gaussian, Lib::Default, "paper (Gaussian, c = 0.1)"),
    (CertificateKind::Calibrated, Lib::Default, "linear calibrated, default configuration"),
    (
        CertificateKind::Calibrated,
        Lib::Poly(2, RegionBound::Pointwise),
        "linear calibrated (with [nonlinear], hidden-dynamics guard only)",
    ),
    (
        CertificateKind::Nonlinear,
        Lib::Poly(2, RegionBound::Pointwise),
        "nonlinear, degree 2 (the default)",
    ),
    (
        CertificateKind::Nonlinear,
        Lib::Poly(2, RegionBound::Simultaneous),
        "nonlinear, degree 2, simultaneous bound",
    ),
    (CertificateKind::Nonlinear, Lib::Poly(3, RegionBound::Pointwise), "nonlinear, degree 3"),
    (
        CertificateKind::Nonlinear,
        Lib::Tanh(RegionBound::Pointwise),
        "nonlinear, features y, y·tanh y",
    ),
    (
        CertificateKind::Nonlinear,
        Lib::Tanh(RegionBound::Simultaneous),
        "nonlinear, features y, y·tanh y, simultaneous bound",
    ),
];

/// The study's certifier for `lib`; `split`: the nonlinear certificates' split of `δ` over
/// the windows (`None`: their default).
fn config(
    k: f64,
    lib: Lib,
    (window, windows): (usize, Option<usize>),
    split: Option<RiskSplit>,
) -> CertifierConfig {
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(1, 1, window, H, 1e-4)
    };
    CertifierConfig {
        // The nonlinear certifiers run their calibration with the hidden-dynamics guard only
        // (on by default, it gives the nonlinear certificate its order test; the nonlinearity
        // and change guards do not gate the nonlinear certificate, and their cost would
        // dominate the study); the default certifier has them all.
        calibration: Some(if lib == Lib::Default {
            Calibration { windows, ..Calibration::new(DELTA) }
        } else {
            Calibration { windows, hidden_dynamics: true, ..Calibration::new(DELTA).unguarded() }
        }),
        nonlinear: match lib {
            Lib::Default => None,
            Lib::Tanh(bound) => Some(NonlinearConfig {
                bound,
                risk_split: split.unwrap_or(NonlinearConfig::default().risk_split),
                ..NonlinearConfig::with_features(
                    FeatureSet::from_names(&["y", "y*tanh(y)"]).expect("a valid library"),
                )
            }),
            Lib::Poly(degree, bound) => Some(NonlinearConfig {
                bound,
                risk_split: split.unwrap_or(NonlinearConfig::default().risk_split),
                ..NonlinearConfig::with_degree(degree)
            }),
        },
        ..CertifierConfig::new(reg, vec![k], PAPER_C, MARGIN, 1)
    }
}

/// The time by which `opened` (first opening times, one per run that opened) covers 90 % of
/// `runs` runs: the `⌈0.9 runs⌉`-th smallest; `–` when fewer runs opened.
fn ninety(opened: &[f64], runs: usize) -> String {
    let need = (9 * runs).div_ceil(10);
    if need == 0 || opened.len() < need {
        return "–".into();
    }
    let mut sorted = opened.to_vec();
    sorted.sort_by(f64::total_cmp);
    format!("{:.1} s", sorted[need - 1])
}

/// Range minimum of the true rate on a fine grid (sparse table, `O(1)` per query), plus the
/// exact endpoints: the smallest true rate over a region.
struct RateTable {
    lo: f64,
    step: f64,
    levels: Vec<Vec<f64>>,
}

impl RateTable {
    fn new(rate: impl Fn(f64) -> f64) -> Self {
        let (lo, hi, step) = (-6.0, 6.0, 5e-4);
        let n = ((hi - lo) / step) as usize + 1;
        let mut levels = vec![(0..n).map(|i| rate(lo + step * i as f64)).collect::<Vec<f64>>()];
        let mut width = 1;
        while 2 * width <= n {
            let prev = &levels[levels.len() - 1];
            let next: Vec<f64> =
                (0..=n - 2 * width).map(|i| prev[i].min(prev[i + width])).collect();
            levels.push(next);
            width *= 2;
        }
        Self { lo, step, levels }
    }

    fn min_over(&self, r: Interval, rate: &impl Fn(f64) -> f64) -> f64 {
        let ends = rate(r.lo).min(rate(r.hi));
        let n = self.levels[0].len();
        let i = ((r.lo - self.lo) / self.step).ceil().max(0.0) as usize;
        let j = (((r.hi - self.lo) / self.step).floor().max(0.0) as usize).min(n - 1);
        if !(r.lo >= self.lo && r.hi <= self.lo + self.step * (n - 1) as f64) {
            // Outside the table (the tanh loop wanders to x = −9): a direct scan at the
            // table's resolution or finer.
            let steps = (((r.hi - r.lo) / self.step).ceil() as usize).clamp(1, 1 << 20);
            return (0..=steps)
                .map(|k| rate(r.lo + (r.hi - r.lo) * k as f64 / steps as f64))
                .fold(ends, f64::min);
        }
        if i > j {
            return ends;
        }
        let level = (usize::BITS - 1 - (j - i + 1).leading_zeros()) as usize;
        let row = &self.levels[level];
        ends.min(row[i].min(row[j + 1 - (1 << level)]))
    }
}

/// One run, per certificate: opened while its region held a state with a rate below the
/// margin; first opening; samples with a value; samples whose value exceeded the smallest true
/// rate over its region.
#[derive(Default, Clone, Copy)]
struct Outcome {
    false_open: bool,
    first_open: Option<f64>,
    valued: usize,
    above_truth: usize,
    /// The nonlinear certificate's latest look of its longest window at the end of the run:
    /// `(β̂_min, β_nl)` (the estimate's minimum over the region, and the certificate).
    last: Option<(f64, f64)>,
    /// That look's edge-slope factor (`NonlinearLook::edge_factor`).
    edge: Option<f64>,
    /// That look's certificate had it spent the whole `δ` (one look at the end): `β̂_min −
    /// c_δ · s`, with `s = (β̂_min − β_nl) / c` the look's own spread at its worst cell and
    /// `c_δ` the simultaneous multiplier at `δ` with the look's `ν`.
    one_look: Option<f64>,
}

fn one_run(
    cell: &Cell,
    seed: u64,
    table: &RateTable,
    split: Option<RiskSplit>,
) -> Result<[Outcome; ROWS.len()]> {
    let (ts, ys, us) = cell.data(seed)?;
    let rate = |x: f64| cell.rate(x);
    let mut certs = Vec::with_capacity(CERTIFIERS.len());
    for lib in CERTIFIERS {
        certs.push(Certifier::new(config(cell.k, lib, (cell.window, cell.windows), split))?);
    }
    let slot = |lib: Lib| CERTIFIERS.iter().position(|&l| l == lib).expect("a certifier per row");
    let mut out = [Outcome::default(); ROWS.len()];
    let mut evs = Vec::with_capacity(CERTIFIERS.len());
    for i in 0..ts.len() {
        evs.clear();
        for c in &mut certs {
            evs.push(c.push(ts[i], &ys[i..=i], &us[i..=i])?);
        }
        for (o, (kind, lib, _)) in out.iter_mut().zip(ROWS) {
            let (ev, cert) = (&evs[slot(lib)], &certs[slot(lib)]);
            let v = ev.verdict(kind);
            let Some(value) = v.value else { continue };
            let region = match kind {
                CertificateKind::Gaussian => cert.region().next(),
                CertificateKind::Calibrated => cert.calibrated_region().next(),
                _ => ev.nonlinear_region,
            };
            let Some(region) = region.filter(Interval::is_proper) else { continue };
            let truth = table.min_over(region, &rate);
            o.valued += 1;
            o.above_truth += usize::from(value > truth);
            if v.open {
                o.first_open.get_or_insert(ts[i]);
                o.false_open |= truth < MARGIN;
            }
        }
    }
    for (o, (kind, lib, _)) in out.iter_mut().zip(ROWS) {
        if matches!(kind, CertificateKind::Nonlinear) {
            let looks = certs[slot(lib)].nonlinear_looks();
            let last = looks.iter().rev().flatten().next();
            o.last = last.map(|l| (l.beta_hat_min, l.certificate));
            o.edge = last.and_then(|l| l.edge_factor);
            let (rank, bound) = match lib {
                Lib::Poly(degree, bound) => (degree, bound),
                Lib::Tanh(bound) => (2, bound),
                Lib::Default => (2, RegionBound::default()),
            };
            o.one_look = last.map(|l| {
                let c_delta = simultaneous_multiplier(bound.directions(rank), l.nu, DELTA);
                l.beta_hat_min - c_delta * (l.beta_hat_min - l.certificate) / l.multiplier
            });
        }
    }
    Ok(out)
}

/// The one-look oracle at the end of the power runs (the efficiency yardstick applied
/// to the nonlinear certificate): `sd` is the spread over runs of the longest window's last
/// `β̂_min`; the oracle opens a run when `β̂_min − z(1 − δ)·sd >= β_margin`. Returns the share
/// of runs it opens and the median of `(β̂_min − β_nl) / (z·sd)`, the certificate's radius over
/// the oracle's.
fn oracle(outs: &[Outcome]) -> Option<(f64, f64)> {
    let last: Vec<(f64, f64)> = outs.iter().filter_map(|o| o.last).collect();
    if last.len() < 2 || last.len() < outs.len() {
        return None;
    }
    let n = last.len() as f64;
    let mean = last.iter().map(|l| l.0).sum::<f64>() / n;
    let sd = (last.iter().map(|l| (l.0 - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let z = -Normal::new(0.0, 1.0).ok()?.inverse_cdf(DELTA);
    let opened = last.iter().filter(|l| l.0 - z * sd >= MARGIN).count();
    let ratios: Vec<f64> = last.iter().map(|l| (l.0 - l.1) / (z * sd)).collect();
    Some((opened as f64 / n, median(&ratios)))
}

/// A certificate's row of NONLINEAR.md's table over a cell's runs.
fn row(cell: &Cell, kind: CertificateKind, label: &str, outs: &[Outcome]) -> Vec<String> {
    let n = outs.len();
    let false_open = outs.iter().filter(|o| o.false_open).count();
    let opened: Vec<f64> = outs.iter().filter_map(|o| o.first_open).collect();
    let valued: usize = outs.iter().map(|o| o.valued).sum();
    let above: usize = outs.iter().map(|o| o.above_truth).sum();
    let (cp_lo, cp_hi) = clopper_pearson(false_open, n);
    let share = |k: usize, n: usize| {
        if n == 0 { "–".to_string() } else { format!("{:.1} %", 100.0 * k as f64 / n as f64) }
    };
    vec![
        cell.name.to_string(),
        if cell.validity { "validity".into() } else { "power".into() },
        label.to_string(),
        n.to_string(),
        if cell.validity {
            format!("{false_open} ({:.4}–{:.4})", cp_lo, cp_hi)
        } else {
            "–".into()
        },
        if cell.validity {
            let pass = matches!(kind, CertificateKind::Gaussian) || cp_hi <= 2.0 * DELTA;
            if matches!(kind, CertificateKind::Gaussian) {
                "no claim".into()
            } else if pass {
                "yes".into()
            } else {
                "NO".into()
            }
        } else {
            "–".into()
        },
        share(above, valued),
        share(opened.len(), n),
        if opened.is_empty() { "–".into() } else { format!("{:.1} s", median(&opened)) },
        if cell.validity { "–".into() } else { ninety(&opened, n) },
        match oracle(outs).filter(|_| !cell.validity) {
            Some((share, ratio)) => format!("{:.0} % / {ratio:.2}", 100.0 * share),
            None => "–".into(),
        },
        if cell.validity || !matches!(kind, CertificateKind::Nonlinear) {
            "–".into()
        } else {
            let opened = outs.iter().filter(|o| o.one_look.is_some_and(|v| v >= MARGIN)).count();
            share(opened, n)
        },
        {
            let edges: Vec<f64> = outs.iter().filter_map(|o| o.edge).collect();
            if cell.validity || edges.is_empty() {
                "–".into()
            } else {
                format!("{:.2}", median(&edges))
            }
        },
    ]
}

/// The study: `runs` per validity cell, the cells whose name contains `only`, the nonlinear
/// certificates with the split `split` (`None`: their default), into `out`.
pub(crate) fn run(
    runs: usize,
    only: Option<&str>,
    split: Option<RiskSplit>,
    out: &Path,
) -> Result<()> {
    // Each cell keeps its index (its seeds) when others are left out.
    let cells: Vec<(usize, Cell)> = cells()
        .into_iter()
        .enumerate()
        .filter(|(_, c)| only.is_none_or(|o| c.name.contains(o)))
        .collect();
    let power_runs = (runs / 5).max(runs.min(20));
    let total: usize = cells.iter().map(|(_, c)| if c.validity { runs } else { power_runs }).sum();
    let bar = progress(total, "nonlinear");
    let mut only_arg = only.map_or(String::new(), |o| format!(" --only \"{o}\""));
    if let Some(split) = split {
        let name = serde_json::to_value(split)?;
        let _ = write!(only_arg, " --split {}", name.as_str().unwrap_or_default());
    }
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# The nonlinear certificate against the true rate over its region\n\nProduced by `cargo xtask nonlinear --runs {runs}{only_arg}` ({power_runs} runs per power cell). Each run: 40 s (the seven cells before the last four: the length stated, with more calibrated windows; G5 cells at dt = 0.02) at dt = 0.01 of a scalar loop `dx = (f(x) + u) dt + 0.1 dW`, `y = x`, explored by `u = K_e y + PRBS` (±1.5 held 1 s unless stated), candidate gain K; the G5 cells run Experiment 2's data (γ = 0, dt = 0.02, 2000 steps, 10 000 in the 200 s cells, `cargo xtask reproduce`'s seed rule) through subsystem A (output x1, input u1) or B (output x4, input u4). Eight certificates on the same runs, each with a one-sample gate (n_s = 1) and margin {MARGIN}: the paper's Gaussian certificate (c = {PAPER_C}, window M = {WINDOW} unless stated, h = {H}), the linear calibrated certificate (δ = {DELTA}, windows doubling from {WINDOW}; twice: from a certifier with the default configuration, no `[nonlinear]` section, whose gate its guards close, and from the default nonlinear certifier with the hidden-dynamics guard only, whose gate the nonlinear certificate's test closes) and the nonlinear certificate (polynomial features of degree 2, the default, over the default region, the 2.5–97.5 % quantiles of the window's outputs with the gate closed while the output is outside them, with the default pointwise multiplier `c = t_ν(1 − δ_{{w,k}})`; degree 2 with the simultaneous multiplier, Hotelling's `T²` over the span of `a(y)`, valid for every region at once; degree 3 and the named library `y, y·tanh y` with the pointwise multiplier, and that library with the simultaneous one; each over the default region, from its own certifier, with the hidden-dynamics guard only; same windows and δ, which each nonlinear certificate splits over the windows by its default rule, `M_w²` each (the linear certificate's: equal shares); each with its lack-of-fit check, `check_terms = 2`: the lowest two powers of `y` it lacks, `y³, y⁴` for degree 2, and its order test: the past increment in a larger fit of its own). The paper's and the calibrated certificates' region is the range of `y` over the samples of their window (the paper's window, the standing calibrated window); the nonlinear certificate's is the region its standing look reports. The truth at a sample is the smallest true rate `−(f'(x) + K)` over that region.\n\n- **false opening**: the gate was open at a sample whose region held a state with a true rate below the margin (validity cells); the 95 % Clopper–Pearson interval is over runs. The nonlinear and calibrated certificates promise at most δ = {DELTA} (the calibrated one only for linear dynamics).\n- **above truth**: share of samples with a value where the certificate exceeded the smallest true rate over its region.\n- **opened / median first opening**: power cells (smallest visited rate at least 3× the margin).\n- **90 % opened by**: the time by which the gate had opened in 90 % of the runs (`–` when fewer than 90 % opened within the run).\n- **one-look oracle at the end** (nonlinear rows of power cells): with `sd` the spread over the cell's runs of the longest window's last `β̂_min` (the estimate's own minimum over its region), the share of runs where `β̂_min − z(1 − δ)·sd >= β_margin` (an oracle that knows the spread and looks once, at the end: roughly the most any valid rule could open on that data), and the median over runs of the certificate's radius `β̂_min − β_nl` over `z·sd` (the efficiency ratio, the spread factor).\n- **one look at the end, whole δ** (nonlinear rows of power cells): the share of runs whose last look of the longest window would have certified had it been the run's only look, spending the whole δ: `β̂_min − c_δ·s ≥ β_margin`, with `s = (β̂_min − β_nl)/c` that look's own spread at its worst cell and `c_δ` the row's multiplier (pointwise or simultaneous) at δ. The most a region-valid bound on the same estimates can open at the end (against the one-look oracle, which knows the spread over runs and bounds one point).\n- **edge-slope factor** (nonlinear rows of power cells): the median over runs of the last look's radius over the radius the same multiplier gives the rate at the region's midpoint, `(β̂_min − β_nl) / (c·s(y_mid))`: how much less the data say of the slope where the certificate is decided, at the region's edge, than at its centre.\n"
    );
    let mut rows = Vec::new();
    for (ci, cell) in &cells {
        let n = if cell.validity { runs } else { power_runs };
        let table = RateTable::new(|x| cell.rate(x));
        let mut results = Vec::with_capacity(n);
        for r in 0..n {
            results.push(one_run(cell, 7_000_000 * (*ci as u64 + 1) + r as u64, &table, split)?);
            bar.inc(1);
        }
        for (ki, (kind, _, label)) in ROWS.iter().enumerate() {
            let outs: Vec<Outcome> = results.iter().map(|o| o[ki]).collect();
            rows.push(row(cell, *kind, label, &outs));
        }
    }
    let _ = writeln!(
        s,
        "{}",
        markdown(
            &[
                "cell",
                "kind",
                "certificate",
                "runs",
                "false openings (95 % CP)",
                "CP upper ≤ 2δ",
                "above truth",
                "opened",
                "median first opening",
                "90 % opened by",
                "one-look oracle at the end: opened / ρ ÷ (z·sd)",
                "one look at the end, whole δ",
                "edge-slope factor",
            ],
            &rows
        )
    );
    let _ = writeln!(
        s,
        "\nThe nonlinear certificate bounds the smallest rate over its region from below. The default multiplier is one direction's (pointwise): the bound at the point where the true rate is smallest is below it with probability `1 − δ_{{w,k}}`, and the minimum of the bounds is below that one; the point is a fixed state or an end of the region the data chose, whose quantile settles as the window grows (see `RegionBound` in streamcert-certificate). The quadratic cells, the two before the last, are the case that argument leans on: a drift the default library holds exactly, whose smallest rate lies at the region's upper end and crosses the margin where the regions' upper quantile falls in about a third of the runs (K = −0.85) or above most of them (K = −0.9). The simultaneous rows (Hotelling's `T²` over the span of `a(y)`) hold at every point of every region at once, with no appeal to the region settling. The paper's and the linear calibrated certificates speak for one averaged Jacobian over their window; the calibrated gate also closes when the nonlinearity test of the same window is significant at δ. The tanh drift is not a polynomial: the cubic fit covers it only as far as the cubic is close over the region.\n\nPower is a matter of data: the seven long cells run the same loops (and G5's subsystems) longer, with calibrated windows doubling up to about the run's length, and show when 90 % of the runs had opened. The oracle column says where 40 s cannot suffice: where the one-look oracle opens in well under 90 % of the 40 s runs, no valid rule can open in 90 % of them on that data. A library that cannot represent the drift (degree 2 or `y, y·tanh y` on a cubic) may open early, but its value then exceeds the true minimum over the region (the `above truth` column): that is not power. The long near-margin cell checks that the longer windows keep the guarantee. Each nonlinear certificate splits δ over the windows by `M_w²` (its default), so the windows longer than a run, which never look, hold most of it: that is the cost of the split in the long cells (`--split equal` or `--split by_length` runs the same cells with the other rules). The last cell runs G5's subsystem B on its 40 s with windows that end at the run's length: the longest looks once, at the end, on every column, so its \"one look at the end, whole δ\" is what any bound on these estimates could open in 40 s.\n\nThe cell after the long ones is a linear loop at 5× the margin (VALIDITY.md's power cell, scaled to this margin): its rate is the same at every state, so the linear calibrated certificate's assumption holds and it is the one to deploy on; the nonlinear rows show what a bound at every state of a data-chosen region costs where the rate does not vary, the slope at the region's edge (the edge-slope factor) known far less well than the average slope.\n"
    );
    write(&out.join("NONLINEAR.md"), &s)?;
    bar.finish_and_clear();
    println!("{s}");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rate_table_equals_a_scan() {
        let rate = |x: f64| (3.0 * x).sin() + 0.1 * x * x;
        let t = RateTable::new(rate);
        for (lo, hi) in [(-1.0, 0.3), (0.2, 0.2001), (-5.9, 5.9), (0.5, 0.5)] {
            let scan = (0..=20000)
                .map(|i| rate(lo + (hi - lo) * f64::from(i) / 20000.0))
                .fold(f64::INFINITY, f64::min);
            let got = t.min_over(Interval { lo, hi }, &rate);
            assert!((got - scan).abs() < 1e-5, "[{lo}, {hi}]: {got} vs {scan}");
        }
        // Beyond the table: a direct scan.
        let far = t.min_over(Interval { lo: -9.0, hi: 0.0 }, &rate);
        let scan = (0..=90000)
            .map(|i| rate(-9.0 + 9.0 * f64::from(i) / 90000.0))
            .fold(f64::INFINITY, f64::min);
        assert!((far - scan).abs() < 1e-5, "{far} vs {scan}");
    }
}
