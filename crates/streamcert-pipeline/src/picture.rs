//! `--plot FILE` (`.png` or `.svg`): a picture of a run, drawn with the workspace's one
//! plotting crate (`streamcert-plot`, the same that draws `cargo xtask`'s figures).
//!
//! A `certify` run shows, over time: the paper's `β̂` and the calibrated certificate with its
//! band (`β̂_w − ρ_w` to `β̂_w`, the standing window's estimate), the Gaussian certificate and
//! the margin; the spans where each gate was open; `ε(t)`; and why the calibrated gate was
//! closed (the reason's code, gaps as vertical lines). A `network` run shows the network
//! rate, each subsystem's local certificate, the network gate and the number of stale or
//! uncertified subsystems. Rows are kept with a doubling stride so that at most
//! [`Trace::CAPACITY`] points per line are drawn whatever the input's length.

use std::path::Path;

use streamcert_certificate::{Evidence, NotCertified};
use streamcert_plot::{BLUE, Figure, GREEN, GREY, ORANGE, PURPLE, Panel, RED_, save_as};

use crate::CliError;

/// Rows kept for a picture: every `stride`-th, at most [`Trace::CAPACITY`] (when full, every
/// other kept row is dropped and the stride doubles). Gaps are all kept.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trace {
    rows: Vec<Row>,
    stride: u64,
    seen: u64,
    gaps: Vec<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Row {
    t: f64,
    values: [f64; 8],
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

    fn keep(&mut self, t: f64, values: [f64; 8]) {
        self.seen += 1;
        if (self.seen - 1) % self.stride != 0 {
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
        self.rows.push(Row { t, values: [f64::NAN; 8] });
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
        let mut values = [nan; 8];
        values[0] = rate.unwrap_or(nan);
        values[1] = f64::from(u8::from(open));
        values[2] = missing as f64;
        for (v, l) in values[3..].iter_mut().zip(local) {
            *v = l.unwrap_or(nan);
        }
        self.keep(t, values);
    }

    fn line(&self, k: usize) -> Vec<(f64, f64)> {
        self.rows.iter().map(|r| (r.t, r.values[k])).collect()
    }

    /// Draw a `certify` run into `path`.
    ///
    /// # Errors
    /// [`CliError::Io`] naming the file when it cannot be drawn or written.
    pub fn draw_certify(&self, path: &Path, margin: f64, subsystem: &str) -> Result<(), CliError> {
        let mut rate = Panel::new(&format!("{subsystem}: contraction rate"), "t [s]", "rate [1/s]")
            .line("paper's β̂", self.line(0), GREY)
            .line("calibrated: standing window's β̂_w", self.line(2), PURPLE)
            .line("calibrated certificate β̂_w − ρ_w (risk δ)", self.line(1), BLUE)
            .line("Gaussian certificate (no stated risk)", self.line(3), ORANGE);
        rate.hlines.push((margin, format!("margin {margin}")));
        rate.vlines.clone_from(&self.gaps);
        // The certificates far below the margin would flatten the picture: show the band
        // around it and say in the legend what is clipped.
        let finite =
            |k: usize| self.rows.iter().map(move |r| r.values[k]).filter(|v| v.is_finite());
        let top = finite(2).chain(finite(0)).fold(margin, f64::max);
        let bottom = finite(1).fold(margin, f64::min).max(margin - 2.0 * (top - margin).max(0.1));
        rate.y_range = Some((bottom, top));
        let gates = Panel::new("gates (1 = open)", "t [s]", "open")
            .line("calibrated gate", self.line(4), BLUE)
            .line(
                "Gaussian gate (paper)",
                // Drawn at 0.9 so that both gates stay visible where they agree.
                self.line(5).iter().map(|&(t, v)| (t, v * 0.9)).collect(),
                ORANGE,
            );
        let eps = Panel::new("ambiguity radius ε(t)", "t [s]", "ε").line("ε", self.line(6), GREEN);
        let mut why = Panel::new(
            "why the calibrated gate is closed (reason code; 0 = open)",
            "t [s]",
            "code",
        )
        .line(
            "1 warming up, 4 below margin, 5 accumulating, 10 rate dropped, 11 varying dynamics, 12 hidden dynamics, 13/14 untested, 15 plant changed, 19 not identified",
            self.line(7),
            RED_,
        );
        why.vlines.clone_from(&self.gaps);
        why.y_range = Some((0.0, 19.0));
        let fig =
            Figure { panels: vec![rate, gates, eps, why], rows: 4, cols: 1, size: (1100, 1300) };
        draw(&fig, path)
    }

    /// Draw a `network` run into `path`; `names` are the first local certificates' subsystems.
    ///
    /// # Errors
    /// [`CliError::Io`] naming the file when it cannot be drawn or written.
    pub fn draw_network(&self, path: &Path, margin: f64, names: &[String]) -> Result<(), CliError> {
        let mut rate =
            Panel::new("network: composed rate and local certificates", "t [s]", "rate [1/s]")
                .line("network rate", self.line(0), BLUE);
        for (i, name) in names.iter().take(5).enumerate() {
            let color = [ORANGE, GREEN, PURPLE, RED_, GREY][i];
            rate = rate.line(&format!("local certificate {name}"), self.line(3 + i), color);
        }
        rate.hlines.push((margin, format!("network margin {margin}")));
        let gate = Panel::new("network gate (1 = open)", "t [s]", "open").line(
            "network gate",
            self.line(1),
            BLUE,
        );
        let stale =
            Panel::new("subsystems not certified (stale, warming up, below)", "t [s]", "count")
                .line("not certified", self.line(2), RED_);
        let fig = Figure { panels: vec![rate, gate, stale], rows: 3, cols: 1, size: (1100, 1000) };
        draw(&fig, path)
    }
}

fn draw(fig: &Figure, path: &Path) -> Result<(), CliError> {
    let fail = |e: streamcert_plot::PlotError| {
        CliError::io(format!("drawing {}", path.display()), std::io::Error::other(e.to_string()))
    };
    streamcert_plot::init_fonts().map_err(fail)?;
    save_as(fig, path).map_err(fail)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A gap breaks every line, also after the thinning has halved the rows many times: the
    /// gate open before the gap is never joined to the samples after it.
    #[test]
    fn a_gap_breaks_every_line_through_the_thinning() {
        let mut trace = Trace::new();
        let open = |on: bool| {
            let g = f64::from(u8::from(on));
            [1.0, 0.5, 1.5, 0.2, g, g, 0.01, if on { 0.0 } else { 4.0 }]
        };
        for k in 0..50_000u32 {
            let t = f64::from(k) * 0.01;
            if k == 30_001 {
                trace.break_lines(t + 100.0);
            }
            let t = if k > 30_000 { t + 100.0 } else { t };
            trace.keep(t, open(k <= 30_000));
        }
        assert!(trace.rows.len() <= Trace::CAPACITY + 1, "{}", trace.rows.len());
        assert!(trace.stride > 1, "the thinning ran");
        for k in 0..8 {
            let line = trace.line(k);
            let at = line.iter().position(|&(_, v)| v.is_nan()).expect("a break");
            // The break lies between the last row before the gap and the first after it.
            assert!(line[at - 1].0 <= 300.0 && line[at + 1].0 > 400.0, "line {k}");
            assert_eq!(line.iter().filter(|&&(_, v)| v.is_nan()).count(), 1, "line {k}");
        }
    }
}
