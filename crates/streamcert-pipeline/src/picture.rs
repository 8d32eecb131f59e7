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

use std::path::Path;

use streamcert_certificate::{Evidence, NotCertified};
use streamcert_plot::{
    BLUE, Figure, GREEN, GREY, ORANGE, PURPLE, Panel, RED_, RGBColor, Span, save_as,
};

use crate::CliError;
use crate::certify::reason_phrase;

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

    /// The first and last kept times: the one time axis of every panel.
    fn time_axis(&self) -> Option<(f64, f64)> {
        let first = self.rows.iter().find(|r| r.t.is_finite())?.t;
        let last = self.rows.iter().rev().find(|r| r.t.is_finite())?.t;
        Some((first, last.max(first + f64::EPSILON)))
    }

    /// Spans of the kept rows where `class` gives a label: consecutive rows of the same label
    /// make one span, from the first row's time to the next row's (a break ends a span).
    fn spans(&self, class: impl Fn(&Row) -> Option<(String, RGBColor)>) -> Vec<Span> {
        let mut out: Vec<Span> = Vec::new();
        let mut open: Option<(f64, String, RGBColor)> = None;
        for r in &self.rows {
            let now = if r.is_break() { None } else { class(r) };
            let same = matches!((&open, &now), (Some((_, a, _)), Some((b, _))) if a == b);
            if !same {
                if let Some((x0, label, color)) = open.take() {
                    out.push(Span { x0, x1: r.t, label, color });
                }
                open = now.map(|(label, color)| (r.t, label, color));
            }
        }
        if let (Some((x0, label, color)), Some(last)) = (open, self.rows.last()) {
            out.push(Span { x0, x1: last.t, label, color });
        }
        out
    }

    /// Draw a `certify` run into `path`: the rates with the calibrated gate's open spans
    /// shaded behind them; why the calibrated gate was closed, as a strip of labelled colours;
    /// the paper's Gaussian gate as a strip; `ε(t)`. Every panel shares one time axis.
    ///
    /// # Errors
    /// [`CliError::Io`] naming the file when it cannot be drawn or written.
    pub fn draw_certify(&self, path: &Path, margin: f64, subsystem: &str) -> Result<(), CliError> {
        draw(&self.certify_figure(margin, subsystem), path)
    }

    /// The figure [`draw_certify`](Self::draw_certify) draws.
    fn certify_figure(&self, margin: f64, subsystem: &str) -> Figure {
        let mut rate = Panel::new(&format!("{subsystem}: contraction rate"), "t [s]", "rate [1/s]")
            .line("paper's β̂", self.line(0), GREY)
            .line("calibrated: standing window's β̂_w", self.line(2), PURPLE)
            .line("calibrated certificate β̂_w − ρ_w (risk δ)", self.line(1), BLUE)
            .line("Gaussian certificate (no stated risk)", self.line(3), ORANGE);
        rate.hlines.push((margin, format!("margin {margin}")));
        rate.vlines.clone_from(&self.gaps);
        rate.spans = self.spans(|r| {
            (r.values[4] > 0.5).then(|| ("calibrated gate open (the verdict)".into(), BLUE))
        });
        // The certificates far below the margin would flatten the picture: show the band
        // around it and say in the legend what is clipped.
        let finite =
            |k: usize| self.rows.iter().map(move |r| r.values[k]).filter(|v| v.is_finite());
        let top = finite(2).chain(finite(0)).fold(margin, f64::max);
        let bottom = finite(1).fold(margin, f64::min).max(margin - 2.0 * (top - margin).max(0.1));
        rate.y_range = Some((bottom, top));
        let why = Panel::strip(
            "why the calibrated gate was closed",
            "t [s]",
            self.spans(|r| {
                let code = r.values[7];
                if !(code >= 1.0) {
                    return None;
                }
                let kind = NotCertified::KINDS.get(code as usize - 1).copied().unwrap_or("unknown");
                Some((reason_phrase(kind).to_string(), reason_color(kind)))
            }),
        );
        let gauss = Panel::strip(
            "the paper's Gaussian gate (no stated risk)",
            "t [s]",
            self.spans(|r| (r.values[5] > 0.5).then(|| ("Gaussian gate open".into(), ORANGE))),
        );
        let mut eps =
            Panel::new("ambiguity radius ε(t)", "t [s]", "ε").line("ε", self.line(6), GREEN);
        eps.weight = 2;
        let mut panels = vec![rate, why, gauss, eps];
        if let Some(axis) = self.time_axis() {
            for p in &mut panels {
                p.x_range = Some(axis);
            }
        }
        Figure { panels, rows: 4, cols: 1, size: (1300, 1050) }
    }

    /// Draw a `network` run into `path`; `names` are the first local certificates' subsystems.
    /// The network gate's open spans are shaded behind the rates.
    ///
    /// # Errors
    /// [`CliError::Io`] naming the file when it cannot be drawn or written.
    pub fn draw_network(&self, path: &Path, margin: f64, names: &[String]) -> Result<(), CliError> {
        draw(&self.network_figure(margin, names), path)
    }

    /// The figure [`draw_network`](Self::draw_network) draws.
    fn network_figure(&self, margin: f64, names: &[String]) -> Figure {
        let mut rate =
            Panel::new("network: composed rate and local certificates", "t [s]", "rate [1/s]")
                .line("network rate", self.line(0), BLUE);
        for (i, name) in names.iter().take(5).enumerate() {
            let color = [ORANGE, GREEN, PURPLE, RED_, GREY][i];
            rate = rate.line(&format!("local certificate {name}"), self.line(3 + i), color);
        }
        rate.hlines.push((margin, format!("network margin {margin}")));
        rate.spans =
            self.spans(|r| (r.values[1] > 0.5).then(|| ("network gate open".into(), BLUE)));
        let stale =
            Panel::new("subsystems not certified (stale, warming up, below)", "t [s]", "count")
                .line("not certified", self.line(2), RED_);
        let mut panels = vec![rate, stale];
        if let Some(axis) = self.time_axis() {
            for p in &mut panels {
                p.x_range = Some(axis);
            }
        }
        Figure { panels, rows: 2, cols: 1, size: (1300, 800) }
    }
}

/// The colour of a reason in the strip (none is a series' colour; one kind, one colour).
fn reason_color(kind: &str) -> RGBColor {
    match kind {
        "warming_up" => RGBColor(170, 170, 170),
        "below_margin" => RGBColor(214, 39, 40),
        "accumulating" => RGBColor(140, 86, 75),
        "rate_dropped" => RGBColor(120, 20, 20),
        "varying_dynamics" => RGBColor(227, 119, 194),
        "hidden_dynamics" => RGBColor(23, 190, 207),
        "order_untested" | "linearity_untested" => RGBColor(210, 210, 150),
        "plant_changed" => RGBColor(90, 60, 160),
        "weakly_identified" => RGBColor(188, 189, 34),
        "outside_region" => RGBColor(31, 119, 180),
        "insufficient_excitation" | "weak_instruments" => RGBColor(255, 200, 60),
        "gap" | "skipped_sample" => RGBColor(40, 40, 40),
        _ => RGBColor(100, 100, 100),
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

    /// The certify picture: every panel on one time axis (the first to the last kept time);
    /// the calibrated gate's open spans shaded behind the rates exactly where it was open;
    /// why it was closed in words, one span per run of the same reason.
    #[test]
    fn the_certify_picture_shades_the_gate_and_names_the_reasons() {
        let mut trace = Trace::new();
        // Closed warming up to 1 s, open to 2 s, below the margin (code 4) to 3 s, open after.
        for k in 0..400u32 {
            let t = f64::from(k) * 0.01;
            let (open, code) = match k {
                0..100 => (false, 1.0),
                100..200 => (true, 0.0),
                200..300 => (false, 4.0),
                _ => (true, 0.0),
            };
            let g = f64::from(u8::from(open));
            trace.keep(t, [1.0, 0.5, 1.5, 0.2, g, 0.0, 0.01, code]);
        }
        let fig = trace.certify_figure(0.05, "level");
        let axis = Some((0.0, 3.99));
        assert!(fig.panels.iter().all(|p| p.x_range == axis), "one time axis");
        let open: Vec<(f64, f64)> = fig.panels[0].spans.iter().map(|s| (s.x0, s.x1)).collect();
        assert_eq!(open, vec![(1.0, 2.0), (3.0, 3.99)]);
        let why: Vec<&str> = fig.panels[1].spans.iter().map(|s| s.label.as_str()).collect();
        assert_eq!(
            why,
            vec!["warming up (too few columns yet)", "the certificate is below the margin"]
        );
        assert!(fig.panels[1].strip && fig.panels[2].strip && fig.panels[2].spans.is_empty());
        streamcert_plot::init_fonts().expect("the embedded font");
        let svg = streamcert_plot::svg_string(&fig).expect("drawn");
        for text in ["calibrated gate open (the verdict)", "the certificate is below the margin"] {
            assert!(svg.contains(text), "{text}");
        }
    }
}
