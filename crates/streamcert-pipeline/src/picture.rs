//! `--plot FILE` (`.png` or `.svg`): a picture of a run, drawn with the workspace's one
//! plotting crate (`streamcert-plot`, the same that draws `cargo xtask`'s figures).
//!
//! A `certify` run shows, over one time axis: the paper's `β̂` and the calibrated certificate
//! with its band (`β̂_w − ρ_w` to `β̂_w`, the standing window's estimate), the Gaussian
//! certificate and the margin, with the spans where the calibrated gate was open shaded
//! behind them (gaps as vertical lines); why the calibrated gate was closed, as a strip of
//! colours labelled in words; the paper's Gaussian gate as a strip; and `ε(t)`. A `network`
//! run shows the network rate and each subsystem's local certificate with the network gate's
//! open spans shaded, and the number of stale or uncertified subsystems. Every legend sits
//! beside its panel. Rows are kept with a doubling stride so that at most
//! [`Trace::CAPACITY`] points per line are drawn whatever the input's length.
//!
//! [`Trace`] keeps the rows whatever the build; drawing them takes the pipeline's `plot`
//! feature (on by default; the Python package builds without it and links no plotting
//! crate), whose absence makes [`Trace::draw_certify`] and [`Trace::draw_network`] an error
//! that says so.

use streamcert_certificate::{Evidence, NotCertified};

#[cfg(feature = "plot")]
mod draw;

/// Rows kept for a picture: every `stride`-th, at most [`Trace::CAPACITY`] (when full, every
/// other kept row is dropped and the stride doubles). Gaps are all kept.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trace {
    rows: Vec<Row>,
    stride: u64,
    seen: u64,
    gaps: Vec<f64>,
}

/// Values per kept row: `certify` keeps `β̂`, the calibrated certificate, `β̂_w`, the
/// Gaussian certificate, the two gates, `ε`, the calibrated reason's code, the newest
/// window's upper bound when it closes the gate and the standing look's order; `network` its
/// own.
const VALUES: usize = 10;

#[derive(Debug, Clone, Copy, PartialEq)]
struct Row {
    t: f64,
    values: [f64; VALUES],
}

impl Row {
    /// Whether this row is a break ([`Trace::break_lines`]).
    fn is_break(&self) -> bool {
        self.values.iter().all(|v| v.is_nan())
    }
}

impl Trace {
    /// The most rows kept.
    pub const CAPACITY: usize = 8192;

    /// An empty trace.
    #[must_use]
    pub fn new() -> Self {
        Self { rows: Vec::with_capacity(Self::CAPACITY), stride: 1, seen: 0, gaps: Vec::new() }
    }

    fn keep(&mut self, t: f64, values: [f64; VALUES]) {
        self.seen += 1;
        if !(self.seen - 1).is_multiple_of(self.stride) {
            return;
        }
        if self.rows.len() == Self::CAPACITY {
            let mut i = 0;
            self.rows.retain(|r| {
                i += 1;
                i % 2 == 1 || r.is_break()
            });
            self.stride *= 2;
        }
        self.rows.push(Row { t, values });
    }

    /// A break in every line at `t` (a row of NaN, kept through the thinning): drawn before
    /// the first row after a gap, so that no line joins the samples across it (a gate open
    /// before a gap would otherwise be drawn as open through it).
    fn break_lines(&mut self, t: f64) {
        self.rows.push(Row { t, values: [f64::NAN; VALUES] });
    }

    /// One `certify` row.
    pub fn push_evidence(&mut self, ev: &Evidence) {
        let nan = f64::NAN;
        let cal = &ev.calibrated;
        let code = cal.reason.map_or(0.0, |r| f64::from(r.code()));
        if matches!(ev.gaussian.reason, Some(NotCertified::Gap { .. })) {
            self.gaps.push(ev.t);
            self.break_lines(ev.t);
        }
        self.keep(
            ev.t,
            [
                ev.beta_hat().unwrap_or(nan),
                cal.value.unwrap_or(nan),
                cal.value.zip(cal.radius).map_or(nan, |(v, r)| v + r),
                ev.gaussian.value.unwrap_or(nan),
                f64::from(u8::from(cal.open)),
                f64::from(u8::from(ev.gaussian.open)),
                ev.ambiguity.map_or(nan, |a| a.eps),
                code,
                match cal.reason {
                    Some(NotCertified::RateBelowMargin { upper, .. }) => upper,
                    _ => nan,
                },
                ev.calibrated_order.map_or(nan, |n| n as f64),
            ],
        );
    }

    /// One `network` epoch: the network rate, whether certified and open, the number of
    /// subsystems not certified, then up to four local certificates.
    pub fn push_epoch(
        &mut self,
        t: f64,
        rate: Option<f64>,
        open: bool,
        missing: usize,
        local: &[Option<f64>],
    ) {
        let nan = f64::NAN;
        let mut values = [nan; VALUES];
        values[0] = rate.unwrap_or(nan);
        values[1] = f64::from(u8::from(open));
        values[2] = missing as f64;
        for (v, l) in values[3..8].iter_mut().zip(local) {
            *v = l.unwrap_or(nan);
        }
        self.keep(t, values);
    }

    #[cfg(feature = "plot")]
    fn line(&self, k: usize) -> Vec<(f64, f64)> {
        self.rows.iter().map(|r| (r.t, r.values[k])).collect()
    }

    /// The first and last kept times: the one time axis of every panel.
    #[cfg(feature = "plot")]
    fn time_axis(&self) -> Option<(f64, f64)> {
        let first = self.rows.iter().find(|r| r.t.is_finite())?.t;
        let last = self.rows.iter().rev().find(|r| r.t.is_finite())?.t;
        Some((first, last.max(first + f64::EPSILON)))
    }
}

#[cfg(not(feature = "plot"))]
impl Trace {
    /// Without the `plot` feature: an error that says so.
    ///
    /// # Errors
    /// Always: this build draws no pictures.
    pub fn draw_certify(
        &self,
        path: &std::path::Path,
        margin: f64,
        subsystem: &str,
    ) -> Result<(), crate::CliError> {
        let _ = (margin, subsystem);
        Err(no_plot(path))
    }

    /// Without the `plot` feature: an error that says so.
    ///
    /// # Errors
    /// Always: this build draws no pictures.
    pub fn draw_network(
        &self,
        path: &std::path::Path,
        margin: f64,
        names: &[String],
    ) -> Result<(), crate::CliError> {
        let _ = (margin, names);
        Err(no_plot(path))
    }
}

#[cfg(not(feature = "plot"))]
fn no_plot(path: &std::path::Path) -> crate::CliError {
    crate::CliError::Config {
        path: path.display().to_string(),
        message: "this build draws no pictures (the pipeline's `plot` feature is off)".into(),
    }
}
