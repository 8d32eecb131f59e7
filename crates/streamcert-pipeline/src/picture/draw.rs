//! Drawing a [`Trace`] (the pipeline's `plot` feature): the figures of `certify` and
//! `network` through `streamcert-plot`.

use std::path::Path;

use streamcert_certificate::NotCertified;
use streamcert_plot::{
    BLUE, Figure, GREEN, GREY, ORANGE, PURPLE, Panel, RED_, RGBColor, Span, save_as,
};

use super::{Row, Trace};
use crate::CliError;
use crate::reasons::reason_phrase;

impl Trace {
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
        if self.rows.iter().any(|r| r.values[8].is_finite()) {
            rate = rate.line(
                "calibrated: the newest window's upper bound β̂_w + ρ_w (below the margin: \
                 closes the gate)",
                self.line(8),
                RED_,
            );
        }
        rate.hlines.push((margin, format!("margin {margin}")));
        rate.vlines.clone_from(&self.gaps);
        // Where a look of order 2 or 3 stood (order = 2 | 3, or "auto"), the open stretches
        // name the order they stood at.
        let orders = self.rows.iter().any(|r| r.values[9] > 1.5);
        rate.spans = self.spans(|r| {
            (r.values[4] > 0.5).then(|| {
                let label = if orders && r.values[9].is_finite() {
                    format!("calibrated gate open at order {} (the verdict)", r.values[9])
                } else {
                    "calibrated gate open (the verdict)".into()
                };
                (label, BLUE)
            })
        });
        rate.y_range = Some(self.rate_axis(margin));
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

    /// The rate panel's axis: every estimate (`β̂`, `β̂_w`, the newest window's upper bound)
    /// and the margin inside it, and the certificates down to twice the estimates' spread
    /// below the lowest estimate (a certificate far below, from a short window's wide radius,
    /// would flatten the rest: it is clipped there and its legend says so); 5 % of the range
    /// free at both ends.
    fn rate_axis(&self, margin: f64) -> (f64, f64) {
        let finite =
            |k: usize| self.rows.iter().map(move |r| r.values[k]).filter(|v| v.is_finite());
        let estimates = || finite(0).chain(finite(2)).chain(finite(8));
        let top = estimates().chain(finite(1)).chain(finite(3)).fold(margin, f64::max);
        let low = estimates().fold(margin, f64::min);
        let floor = low - 2.0 * (top - low).max(0.1 * margin.abs()).max(1e-3);
        let bottom = finite(1).chain(finite(3)).fold(low, f64::min).max(floor);
        let pad = 0.05 * (top - bottom);
        (bottom - pad, top + pad)
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

/// The colour of a reason in the strip: one per phrase, every two at least 60 apart in RGB
/// (tested), the two reds kept for "below the margin" alone.
fn reason_color(kind: &str) -> RGBColor {
    match kind {
        "warming_up" => RGBColor(170, 170, 170),
        "insufficient_excitation" | "weak_instruments" => RGBColor(255, 200, 60),
        "below_margin" => RGBColor(214, 39, 40),
        "accumulating" => RGBColor(140, 86, 75),
        "skipped_sample" => RGBColor(40, 40, 40),
        "gap" => RGBColor(0, 0, 128),
        "rate_below_margin" => RGBColor(255, 127, 14),
        "varying_dynamics" => RGBColor(227, 119, 194),
        "hidden_dynamics" => RGBColor(23, 190, 207),
        "order_untested" | "linearity_untested" => RGBColor(210, 210, 150),
        "plant_changed" => RGBColor(90, 60, 160),
        "weakly_identified" => RGBColor(188, 189, 34),
        "input_follows_outputs" => RGBColor(0, 150, 100),
        "outside_region" => RGBColor(31, 119, 180),
        "library_misfit" => RGBColor(44, 160, 44),
        "library_untested" => RGBColor(152, 223, 138),
        "no_ambiguity_model" => RGBColor(255, 152, 150),
        "no_calibration" => RGBColor(230, 220, 250),
        "first_order_only" => RGBColor(250, 250, 180),
        _ => RGBColor(120, 20, 90),
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
            [1.0, 0.5, 1.5, 0.2, g, g, 0.01, if on { 0.0 } else { 4.0 }, 0.3, 1.0]
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
        for k in 0..crate::picture::VALUES {
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
            trace.keep(t, [1.0, 0.5, 1.5, 0.2, g, 0.0, 0.01, code, f64::NAN, 1.0]);
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

    /// A candidate the data refuse (its rate about -0.2 against a margin of 0.05, the
    /// calibrated certificate never standing): the estimate, the Gaussian certificate and
    /// the newest window's upper bound that closed the gate are all inside the rate axis, not
    /// clipped to its edge.
    #[test]
    fn a_refused_candidate_s_estimate_and_bounds_are_inside_the_axis() {
        let mut trace = Trace::new();
        let nan = f64::NAN;
        for k in 0..500u32 {
            let t = f64::from(k) * 0.1;
            let wobble = 0.02 * (f64::from(k) * 0.1).sin();
            let beta = -0.2 + wobble;
            trace.keep(t, [beta, nan, nan, beta - 0.03, 0.0, 0.0, 0.015, 10.0, beta + 0.02, nan]);
        }
        let fig = trace.certify_figure(0.05, "y");
        let (lo, hi) = fig.panels[0].y_range.expect("a rate axis");
        for row in &trace.rows {
            for k in [0, 3, 8] {
                let v = row.values[k];
                assert!(lo < v && v < hi, "{v} outside [{lo}, {hi}]");
            }
        }
        assert!(lo < 0.05 && 0.05 < hi, "the margin");
        assert!(hi - lo < 1.0, "the axis is the data's, not [0, 1]: [{lo}, {hi}]");
        let why: Vec<&str> = fig.panels[1].spans.iter().map(|s| s.label.as_str()).collect();
        assert_eq!(why, vec!["the newest data bound the rate below the margin"]);
        streamcert_plot::init_fonts().expect("the embedded font");
        let svg = streamcert_plot::svg_string(&fig).expect("drawn");
        assert!(svg.contains("the newest window"), "the upper bound's line is in the legend");
        assert!(!svg.contains("clipped"), "nothing is clipped");
    }

    /// Every reason's colour in the strip is told apart from every other's (aliases that
    /// share a phrase share a colour).
    #[test]
    fn every_reason_has_a_colour_of_its_own() {
        let kinds = NotCertified::KINDS;
        for (i, a) in kinds.iter().enumerate() {
            for b in &kinds[i + 1..] {
                if reason_phrase(a) == reason_phrase(b) {
                    continue;
                }
                let (RGBColor(r1, g1, b1), RGBColor(r2, g2, b2)) =
                    (reason_color(a), reason_color(b));
                let d = |x: u8, y: u8| (f64::from(x) - f64::from(y)).powi(2);
                let distance = (d(r1, r2) + d(g1, g2) + d(b1, b2)).sqrt();
                assert!(distance >= 60.0, "{a} and {b}: {distance:.0} apart");
            }
        }
    }

    /// With looks of order 2 or 3 standing (`order = "auto"`), each open stretch names the
    /// order it stood at; a first-order run's stretches keep their plain words.
    #[test]
    fn the_open_stretches_name_the_standing_order() {
        let mut trace = Trace::new();
        for k in 0..300u32 {
            let t = f64::from(k) * 0.01;
            let (open, order) = match k {
                0..100 => (false, f64::NAN),
                100..200 => (true, 1.0),
                _ => (true, 2.0),
            };
            let g = f64::from(u8::from(open));
            let code = if open { 0.0 } else { 1.0 };
            trace.keep(t, [1.0, 0.5, 1.5, 0.2, g, 0.0, 0.01, code, f64::NAN, order]);
        }
        let fig = trace.certify_figure(0.05, "level");
        let open: Vec<&str> = fig.panels[0].spans.iter().map(|s| s.label.as_str()).collect();
        assert_eq!(
            open,
            [
                "calibrated gate open at order 1 (the verdict)",
                "calibrated gate open at order 2 (the verdict)"
            ]
        );
    }
}
