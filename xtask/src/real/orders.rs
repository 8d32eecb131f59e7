//! The records under `order = "auto"` with only their columns, gain and margin set: the
//! verdict and what decided it (each order's share of open rows, or why it stayed closed),
//! and, where no order opens, how long a window, and so a record of the same noise, its
//! looks would have needed.
//!
//! **The length needed** (an estimate, its assumptions stated in REAL.md). A look of order
//! `n` certifies the margin when every polynomial of its confidence ellipsoid
//! `{β : (β − β̂)ᵀ Σ⁻¹ (β − β̂) <= r²}` has its roots left of `−margin`. With `k` times the rows
//! and the same noise and estimates, `Σ` shrinks as `1/k` (the radius as `1/√k`; the
//! quantile `r²` shrinks too, with more degrees of freedom, which is ignored: the estimate
//! errs long). The factor needed is the smallest `k` whose ellipsoid `r²/k` certifies (found
//! by bisection on the exact test, `robust_margin`); a look whose own estimate `β̂` does not
//! clear the margin has none.

use std::fmt::Write as _;

use anyhow::{Context, Result};
use streamcert_certificate::{Certifier, Ellipsoid, robust_margin};
use streamcert_pipeline::config::parse;

use super::{certify_text, grid::minimal_with};
use crate::common::median;

/// The bisection's tolerance on the margin (the certificate's own, 1/s).
const TOLERANCE: f64 = 1e-4;

/// The factor `k` by which the look's rows would have to grow for its ellipsoid to certify
/// `margin`: `Some(1.0)` when it already does, `None` when its own estimate does not clear
/// the margin (no length suffices) or the factor exceeds `10⁶`.
pub(super) fn factor(beta: &[f64], covariance: &[f64], radius2: f64, margin: f64) -> Option<f64> {
    let clears = |k: f64| {
        let e = Ellipsoid { centre: beta, covariance, radius2: radius2 / k };
        robust_margin(&e, TOLERANCE).is_some_and(|m| m >= margin)
    };
    if clears(1.0) {
        return Some(1.0);
    }
    let point = Ellipsoid { centre: beta, covariance, radius2: 0.0 };
    if !robust_margin(&point, TOLERANCE).is_some_and(|m| m > margin + TOLERANCE) {
        return None;
    }
    let (mut lo, mut hi) = (1.0f64, 2.0f64);
    while !clears(hi) {
        (lo, hi) = (hi, 2.0 * hi);
        if hi > 1e6 {
            return None;
        }
    }
    while hi / lo > 1.01 {
        let mid = (lo * hi).sqrt();
        if clears(mid) { hi = mid } else { lo = mid }
    }
    Some(hi)
}

/// Each order above 1's looks on the record (`order = "auto"`'s rung at risk `δ/3`): their
/// number, those whose estimate clears the margin, and the median window (rows) those
/// would have needed.
fn needed(text: &str, csv: &str, name: &str) -> Result<String> {
    let cfg = parse(text, name)?;
    let margin = cfg.certifier.margin;
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().context("no header")?.split(',').collect();
    let col = |c: &str| header.iter().position(|h| *h == c).context("a column of the record");
    let (t, y, u) =
        (col(&cfg.columns.time)?, col(&cfg.columns.outputs[0])?, col(&cfg.columns.inputs[0])?);
    let rows: Vec<Vec<f64>> =
        lines.map(|l| l.split(',').map(|v| v.parse().unwrap_or(f64::NAN)).collect()).collect();
    let mut out = Vec::new();
    for n in [2, 3] {
        let rung = cfg.certifier.order_rung(n);
        let window = rung.regression.window;
        let mut cert = Certifier::new(rung)?;
        let (mut looks, mut seen, mut factors) = (0, 0, Vec::new());
        for r in &rows {
            cert.push(r[t], &[r[y]], &[r[u]])?;
            if let Some(look) = cert.order_n_look().filter(|l| l.index != seen) {
                seen = look.index;
                looks += 1;
                if let Ok(region) = &look.outcome {
                    let f = factor(&region.beta, &region.covariance, region.radius2, margin);
                    factors.extend(f);
                }
            }
        }
        let dt = rows.get(1).zip(rows.first()).map_or(f64::NAN, |(b, a)| b[t] - a[t]);
        out.push(if factors.is_empty() {
            format!(
                "order {n}: {looks} looks, none whose own estimate clears the margin (no window \
                 of this noise would certify them)"
            )
        } else {
            let k = median(&factors);
            let rows_needed = (k * window as f64).ceil();
            format!(
                "order {n}: {looks} looks, {} whose own estimate clears the margin; their median \
                 needs {k:.1} × the window, {rows_needed} rows ({:.0} s at this sampling) where \
                 it has {window}",
                factors.len(),
                rows_needed * dt
            )
        });
    }
    Ok(out.join("; "))
}

/// The paragraph of REAL.md for one record under `order = "auto"`.
pub(super) fn section(name: &str, config: &str, csv: &str) -> Result<String> {
    let text = minimal_with(config, "\n[regression]\norder = \"auto\"\n")?;
    let c = certify_text(&text, csv, name)?;
    let s = &c.summary;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{name} with `order = \"auto\"` (orders 1, 2 and 3 side by side, each at risk δ/3, the defaults `h = 5`, `M = 150` otherwise): the gate open on {:.1} % of rows ({}). {}\n",
        100.0 * s.share_calibrated(),
        s.first_deploy_calibrated.map_or("never opened".into(), |t| format!("first at t = {t} s")),
        s.horizons_line().unwrap_or_default(),
    );
    if s.first_deploy_calibrated.is_none() {
        let _ = writeln!(
            out,
            "How long a window (and so a record of this noise) the looks of order 2 and 3 would have needed, each look's confidence ellipsoid shrunk as its rows grow (`Σ` as `1/k`; module docs of `xtask/src/real/orders.rs`): {}.\n",
            needed(&text, csv, name)?
        );
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::factor;
    use streamcert_certificate::{Ellipsoid, robust_margin};

    /// Oracle: the factor found is the smallest (to 1 %) whose ellipsoid certifies, checked
    /// by the exact test on both sides; a look already certified needs 1; one whose estimate
    /// is below the margin, none.
    #[test]
    fn the_factor_is_the_smallest_that_certifies() {
        // (s + 0.1)(s + 0.3) = s² + 0.4 s + 0.03, a wide ellipsoid, margin 0.05.
        let (beta, cov) = ([0.4, 0.03], [0.01, 0.0, 0.0, 0.0004]);
        let certifies = |r2: f64| {
            let e = Ellipsoid { centre: &beta, covariance: &cov, radius2: r2 };
            robust_margin(&e, 1e-4).is_some_and(|m| m >= 0.05)
        };
        let k = factor(&beta, &cov, 9.0, 0.05).expect("a factor");
        assert!(k > 1.0 && certifies(9.0 / k) && !certifies(9.0 / (k / 1.011)), "{k}");
        assert_eq!(factor(&beta, &cov, 1e-9, 0.05), Some(1.0));
        assert_eq!(factor(&beta, &cov, 9.0, 0.2), None);
    }
}
