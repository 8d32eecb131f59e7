//! # streamcert-plot
//!
//! A minimal figure description ([`Figure`]: panels of [`Series`], shaded [`Span`]s behind
//! them, reference lines and an optional [`Heatmap`]; or a [`Panel::strip`] of labelled
//! colour spans) rendered with plotters to PNG and SVG ([`save`], [`save_as`]), with the
//! DejaVu Sans font embedded (no system fonts needed). Every legend sits beside its panel,
//! outside the data; ticks are written as a person writes numbers (`500`, not `500.0`). One plotting module for the whole
//! workspace: `cargo xtask`'s figures and the pictures of `streamcert certify --plot` and
//! `streamcert network --plot`.
//!
//! ```no_run
//! use streamcert_plot::{BLUE, Figure, Panel, init_fonts, save_as};
//! init_fonts()?;
//! let panel = Panel::new("rate", "t [s]", "β").line("β̂", vec![(0.0, 1.0), (1.0, 0.5)], BLUE);
//! let fig = Figure { panels: vec![panel], rows: 1, cols: 1, size: (800, 400) };
//! save_as(&fig, std::path::Path::new("run.png"))?;
//! # Ok::<(), streamcert_plot::PlotError>(())
//! ```

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
pub use plotters::style::RGBColor;

/// A figure that could not be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The embedded font was refused by plotters.
    #[error("embedded font rejected")]
    Font,
    /// Drawing or writing the file failed (the backend's message).
    #[error("drawing {path}: {message}")]
    Draw {
        /// The file.
        path: String,
        /// What the backend said.
        message: String,
    },
    /// The file name ends in neither `.png` nor `.svg`.
    #[error("{0}: a picture is written as .png or .svg")]
    Format(String),
}

type Result<T> = std::result::Result<T, PlotError>;

/// The backend's error as a [`PlotError`] (the path is filled in by [`save_as`]).
fn anyhow<E: std::fmt::Debug>(e: E) -> PlotError {
    PlotError::Draw { path: String::new(), message: format!("{e:?}") }
}

/// Register the embedded DejaVu Sans font (no system fonts needed). Call once before drawing.
///
/// # Errors
/// [`PlotError::Font`].
pub fn init_fonts() -> Result<()> {
    plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
        .map_err(|_| PlotError::Font)
}

/// Blue (the first series colour).
pub const BLUE: RGBColor = RGBColor(31, 119, 180);
/// Orange.
pub const ORANGE: RGBColor = RGBColor(255, 127, 14);
/// Green.
pub const GREEN: RGBColor = RGBColor(44, 160, 44);
/// Red.
pub const RED_: RGBColor = RGBColor(214, 39, 40);
/// Purple.
pub const PURPLE: RGBColor = RGBColor(148, 103, 189);
/// Grey (reference lines).
pub const GREY: RGBColor = RGBColor(127, 127, 127);

/// One line.
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Points `(x, y)`; a non-finite value breaks the line.
    pub points: Vec<(f64, f64)>,
    /// Colour.
    pub color: RGBColor,
}

/// A cell grid coloured on a diverging red (negative) / white / green (positive) scale.
pub struct Heatmap {
    /// Cell edges along x (len nx + 1).
    pub x_edges: Vec<f64>,
    /// Cell edges along y (len ny + 1).
    pub y_edges: Vec<f64>,
    /// Values, row-major by x then y: `z[ix * ny + iy]`.
    pub z: Vec<f64>,
    /// Saturation magnitude.
    pub scale: f64,
    /// Legend text for the cells without a value (drawn in [`MISSING`] grey).
    pub missing: String,
}

/// A shaded span of `x` (for example where a gate was open), drawn behind a panel's lines or
/// as a cell of a [`Panel::strip`]; spans with the same label share one legend entry.
#[derive(Debug, Clone, PartialEq)]
pub struct Span {
    /// Start.
    pub x0: f64,
    /// End.
    pub x1: f64,
    /// Legend text (words).
    pub label: String,
    /// Colour (drawn light behind lines, full in a strip).
    pub color: RGBColor,
}

/// The width in pixels of the legend column beside every panel.
pub const LEGEND_WIDTH: u32 = 320;

/// One panel.
pub struct Panel {
    /// Caption.
    pub title: String,
    /// Axis labels.
    pub x_label: String,
    /// Axis labels.
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
    /// Horizontal reference lines `(y, label)`.
    pub hlines: Vec<(f64, String)>,
    /// Vertical reference lines.
    pub vlines: Vec<f64>,
    /// A fixed y range (lines outside are clipped, and the legend says so).
    pub y_range: Option<(f64, f64)>,
    /// A heat map under the lines.
    pub heatmap: Option<Heatmap>,
    /// Shaded spans behind the lines.
    pub spans: Vec<Span>,
    /// A fixed x range (the figure's one time axis when every panel gets the same).
    pub x_range: Option<(f64, f64)>,
    /// A strip: only its spans, full height, no y axis ([`Panel::strip`]).
    pub strip: bool,
    /// Relative height in a one-column figure (a strip 1, other panels 3).
    pub weight: u32,
}

impl Panel {
    /// An empty panel.
    #[must_use]
    pub fn new(title: &str, x_label: &str, y_label: &str) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            hlines: Vec::new(),
            vlines: Vec::new(),
            y_range: None,
            heatmap: None,
            spans: Vec::new(),
            x_range: None,
            strip: false,
            weight: 3,
        }
    }

    /// A strip of labelled colour spans over time (for example why a gate was closed, in
    /// words): no lines, no y axis, a third of a panel's height.
    #[must_use]
    pub fn strip(title: &str, x_label: &str, spans: Vec<Span>) -> Self {
        Self { spans, strip: true, weight: 1, ..Self::new(title, x_label, "") }
    }

    /// With one more line.
    #[must_use]
    pub fn line(mut self, name: &str, points: Vec<(f64, f64)>, color: RGBColor) -> Self {
        self.series.push(Series { name: name.into(), points, color });
        self
    }
}

/// A figure: panels stacked in `rows × cols`.
pub struct Figure {
    /// The panels, row by row.
    pub panels: Vec<Panel>,
    /// Rows of panels.
    pub rows: usize,
    /// Columns of panels.
    pub cols: usize,
    /// Size in pixels.
    pub size: (u32, u32),
}

fn range(panel: &Panel) -> ((f64, f64), (f64, f64)) {
    let (mut x0, mut x1, mut y0, mut y1) =
        (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for s in &panel.series {
        for &(x, y) in &s.points {
            if x.is_finite() && y.is_finite() {
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
        }
    }
    if let Some(h) = &panel.heatmap {
        x0 = x0.min(h.x_edges[0]);
        x1 = x1.max(h.x_edges[h.x_edges.len() - 1]);
        y0 = y0.min(h.y_edges[0]);
        y1 = y1.max(h.y_edges[h.y_edges.len() - 1]);
    }
    for (y, _) in &panel.hlines {
        y0 = y0.min(*y);
        y1 = y1.max(*y);
    }
    if !x0.is_finite() {
        (x0, x1) = (0.0, 1.0);
    }
    if !y0.is_finite() {
        (y0, y1) = (0.0, 1.0);
    }
    for sp in &panel.spans {
        if sp.x0.is_finite() && sp.x1.is_finite() {
            x0 = x0.min(sp.x0);
            x1 = x1.max(sp.x1);
        }
    }
    if let Some(r) = panel.y_range {
        (y0, y1) = r;
    }
    if let Some(r) = panel.x_range {
        (x0, x1) = r;
    }
    if panel.strip {
        (y0, y1) = (0.0, 1.0);
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    if y1 <= y0 {
        y1 = y0 + 1.0;
    }
    let pad = if panel.strip { 0.0 } else { 0.05 * (y1 - y0) };
    ((x0, x1), (y0 - pad, y1 + pad))
}

/// A tick as a person writes it: at most four decimals, no trailing zeros (`500`, `2.5`,
/// `0.05`, `-1`).
#[must_use]
pub fn tick(v: f64) -> String {
    let text = format!("{v:.4}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    if text == "-0" { "0".into() } else { text.into() }
}

/// One legend entry: a line or a filled box, and its text.
struct Entry {
    text: String,
    color: RGBColor,
    boxed: bool,
    dashed: bool,
}

/// The legend entries of `panel`, in drawing order.
fn entries(panel: &Panel, labels: &[(String, bool)]) -> Vec<Entry> {
    let mut out: Vec<Entry> = Vec::new();
    for sp in &panel.spans {
        if !out.iter().any(|e| e.text == sp.label) {
            out.push(Entry { text: sp.label.clone(), color: sp.color, boxed: true, dashed: false });
        }
    }
    if let Some(h) = &panel.heatmap {
        out.push(Entry { text: h.missing.clone(), color: MISSING, boxed: true, dashed: false });
    }
    for (_, label) in &panel.hlines {
        out.push(Entry { text: label.clone(), color: BLACK, boxed: false, dashed: false });
    }
    for (s, (text, dashed)) in panel.series.iter().zip(labels) {
        out.push(Entry { text: text.clone(), color: s.color, boxed: false, dashed: *dashed });
    }
    out
}

/// Words of `text` in lines of at most `width` characters.
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines: Vec<String> = vec![String::new()];
    for word in text.split_whitespace() {
        let last = lines.last_mut().expect("one line");
        if !last.is_empty() && last.chars().count() + 1 + word.chars().count() > width {
            lines.push(word.to_string());
        } else {
            if !last.is_empty() {
                last.push(' ');
            }
            last.push_str(word);
        }
    }
    lines
}

/// Draw the legend column of a panel: each entry's mark and its words, wrapped.
fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[Entry],
    wrap_at: usize,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let font = ("sans-serif", 13).into_font();
    let mut y = 30;
    for e in entries {
        let mark_y = y + 7;
        if e.boxed {
            area.draw(&Rectangle::new(
                [(6, mark_y - 6), (26, mark_y + 6)],
                e.color.mix(0.45).filled(),
            ))
            .map_err(anyhow)?;
        } else if e.dashed {
            area.draw(&PathElement::new(vec![(6, mark_y), (12, mark_y)], e.color.stroke_width(2)))
                .map_err(anyhow)?;
            area.draw(&PathElement::new(vec![(18, mark_y), (26, mark_y)], e.color.stroke_width(2)))
                .map_err(anyhow)?;
        } else {
            area.draw(&PathElement::new(vec![(6, mark_y), (26, mark_y)], e.color.stroke_width(2)))
                .map_err(anyhow)?;
        }
        for line in wrap(&e.text, wrap_at) {
            area.draw(&Text::new(line, (32, y), font.clone())).map_err(anyhow)?;
            y += 16;
        }
        y += 4;
    }
    Ok(())
}

/// The colour of a heatmap cell without a value (for example before the first estimate).
pub const MISSING: RGBColor = RGBColor(225, 225, 225);

fn diverging(z: f64, scale: f64) -> RGBColor {
    if !z.is_finite() {
        return MISSING;
    }
    let v = (z / scale).clamp(-1.0, 1.0);
    let mix = |a: u8, b: u8, t: f64| (f64::from(a) + (f64::from(b) - f64::from(a)) * t) as u8;
    if v >= 0.0 {
        RGBColor(mix(255, 26, v), mix(255, 150, v), mix(255, 65, v))
    } else {
        RGBColor(mix(255, 215, -v), mix(255, 48, -v), mix(255, 39, -v))
    }
}

/// A series cut into the segments drawn (broken at non-finite values and outside the x
/// range, clipped to the y range) and its legend text (saying what was clipped or hidden).
struct Drawn {
    segments: Vec<Vec<(f64, f64)>>,
    label: String,
    dashed: bool,
}

fn drawn_series(panel: &Panel, (x0, x1): (f64, f64), (lo, hi): (f64, f64)) -> Vec<Drawn> {
    panel
        .series
        .iter()
        .enumerate()
        .map(|(index, s)| {
            // A series identical to an earlier one is hidden under it: say so in the legend,
            // and draw it dashed on top so both stay visible.
            let twin = panel.series[..index].iter().find(|e| same_points(&e.points, &s.points));
            let mut clipped = false;
            let mut segments: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
            for &(x, y) in &s.points {
                if x.is_finite() && y.is_finite() && (x0..=x1).contains(&x) {
                    clipped |= y < lo || y > hi;
                    if let Some(seg) = segments.last_mut() {
                        seg.push((x, y.clamp(lo, hi)));
                    }
                } else if segments.last().is_some_and(|seg| !seg.is_empty()) {
                    segments.push(Vec::new());
                }
            }
            segments.retain(|seg| !seg.is_empty());
            let mut label = s.name.clone();
            if let Some(t) = twin {
                label = format!("{label} (identical to {}: dashed)", t.name);
            }
            if clipped {
                label = format!("{label} (clipped to [{}, {}])", tick(lo), tick(hi));
            }
            Drawn { segments, label, dashed: twin.is_some() }
        })
        .collect()
}

/// Panels at least this wide keep their legend in a column on the right; narrower ones
/// below the plot.
const LEGEND_BESIDE_FROM: u32 = 900;

fn draw_panel<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, panel: &Panel) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let ((x0, x1), (y0, y1)) = range(panel);
    let drawn = drawn_series(panel, (x0, x1), panel.y_range.unwrap_or((y0, y1)));
    let labels: Vec<(String, bool)> = drawn.iter().map(|d| (d.label.clone(), d.dashed)).collect();
    let legend_entries = entries(panel, &labels);
    // The legend outside the data: beside a wide panel, below a narrow one.
    let (width, height) = area.dim_in_pixel();
    let (area, legend, wrap_at) = if width >= LEGEND_BESIDE_FROM {
        let (plot, legend) = area.split_horizontally(width - LEGEND_WIDTH);
        (plot, legend, 40)
    } else {
        let wrap_at = (width as usize / 7).max(20);
        let lines: usize = legend_entries.iter().map(|e| wrap(&e.text, wrap_at).len()).sum();
        let needed = (16 * lines + 4 * legend_entries.len() + 36) as u32;
        let (plot, legend) = area.split_vertically(height - needed.min(height * 9 / 20));
        (plot, legend, wrap_at)
    };
    let mut chart = ChartBuilder::on(&area)
        .caption(&panel.title, ("sans-serif", 16))
        .margin(8)
        .x_label_area_size(32)
        .y_label_area_size(56)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(anyhow)?;
    let ticks = |v: &f64| tick(*v);
    let no_ticks = |_: &f64| String::new();
    chart
        .configure_mesh()
        .x_desc(panel.x_label.as_str())
        .y_desc(panel.y_label.as_str())
        .x_label_formatter(&ticks)
        .x_label_style(("sans-serif", 12))
        .y_label_style(("sans-serif", 12))
        .axis_desc_style(("sans-serif", 12))
        .y_label_formatter(if panel.strip { &no_ticks } else { &ticks })
        .y_labels(if panel.strip { 0 } else { 10 })
        .disable_y_mesh()
        .light_line_style(WHITE)
        .draw()
        .map_err(anyhow)?;
    // Spans under everything else: light behind lines, full in a strip.
    let shade = if panel.strip { 0.85 } else { 0.18 };
    chart
        .draw_series(panel.spans.iter().filter(|sp| sp.x1 > sp.x0).map(|sp| {
            Rectangle::new([(sp.x0.max(x0), y0), (sp.x1.min(x1), y1)], sp.color.mix(shade).filled())
        }))
        .map_err(anyhow)?;
    if let Some(h) = &panel.heatmap {
        let ny = h.y_edges.len() - 1;
        let cells = (0..h.x_edges.len() - 1).flat_map(|ix| (0..ny).map(move |iy| (ix, iy)));
        chart
            .draw_series(cells.map(|(ix, iy)| {
                Rectangle::new(
                    [(h.x_edges[ix], h.y_edges[iy]), (h.x_edges[ix + 1], h.y_edges[iy + 1])],
                    diverging(h.z[ix * ny + iy], h.scale).filled(),
                )
            }))
            .map_err(anyhow)?;
    }
    for (y, _) in &panel.hlines {
        chart
            .draw_series(LineSeries::new(vec![(x0, *y), (x1, *y)], BLACK.stroke_width(1)))
            .map_err(anyhow)?;
    }
    for x in &panel.vlines {
        chart
            .draw_series(LineSeries::new(vec![(*x, y0), (*x, y1)], BLACK.mix(0.3).stroke_width(1)))
            .map_err(anyhow)?;
    }
    for (s, d) in panel.series.iter().zip(drawn) {
        let color = s.color;
        for seg in d.segments {
            if d.dashed {
                chart
                    .draw_series(DashedLineSeries::new(seg, 6, 6, color.stroke_width(2)))
                    .map_err(anyhow)?;
            } else {
                chart.draw_series(LineSeries::new(seg, color.stroke_width(2))).map_err(anyhow)?;
            }
        }
    }
    draw_legend(&legend, &legend_entries, wrap_at)
}

/// Whether two series have the same points (NaN equal to NaN).
fn same_points(a: &[(f64, f64)], b: &[(f64, f64)]) -> bool {
    let eq = |x: f64, y: f64| x == y || (x.is_nan() && y.is_nan());
    a.len() == b.len() && a.iter().zip(b).all(|(p, q)| eq(p.0, q.0) && eq(p.1, q.1))
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, fig: &Figure) -> Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(anyhow)?;
    let areas = if fig.cols == 1 {
        // One column: heights by the panels' weights (a strip is a third of a panel).
        let total: u32 = fig.panels.iter().map(|p| p.weight.max(1)).sum::<u32>().max(1);
        let height = root.dim_in_pixel().1;
        let mut rest = root.clone();
        let mut out = Vec::new();
        for (i, p) in fig.panels.iter().enumerate() {
            if i + 1 == fig.panels.len() {
                out.push(rest.clone());
                break;
            }
            let h = height * p.weight.max(1) / total;
            let (top, bottom) = rest.split_vertically(h);
            out.push(top);
            rest = bottom;
        }
        out
    } else {
        root.split_evenly((fig.rows, fig.cols))
    };
    for (area, panel) in areas.iter().zip(&fig.panels) {
        draw_panel(area, panel)?;
    }
    root.present().map_err(anyhow)?;
    Ok(())
}

/// The SVG text of `fig` (what [`save_as`] writes to a `.svg` file).
///
/// # Errors
/// [`PlotError::Draw`] when drawing fails.
pub fn svg_string(fig: &Figure) -> Result<String> {
    let mut text = String::new();
    draw(SVGBackend::with_string(&mut text, fig.size).into_drawing_area(), fig)?;
    Ok(text)
}

/// Write `dir/name.png` and `dir/name.svg`.
///
/// # Errors
/// [`PlotError::Draw`].
pub fn save(fig: &Figure, dir: &Path, name: &str) -> Result<()> {
    save_as(fig, &dir.join(format!("{name}.png")))?;
    save_as(fig, &dir.join(format!("{name}.svg")))
}

/// Write `path`, a PNG or an SVG by its extension.
///
/// # Errors
/// [`PlotError::Format`] for another extension, [`PlotError::Draw`] when drawing or writing
/// fails (the path named).
pub fn save_as(fig: &Figure, path: &Path) -> Result<()> {
    let named = |e: PlotError| match e {
        PlotError::Draw { message, .. } => {
            PlotError::Draw { path: path.display().to_string(), message }
        }
        other => other,
    };
    match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("png") => draw(BitMapBackend::new(path, fig.size).into_drawing_area(), fig),
        Some("svg") => draw(SVGBackend::new(path, fig.size).into_drawing_area(), fig),
        _ => return Err(PlotError::Format(path.display().to_string())),
    }
    .map_err(named)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The data lines of an SVG (stroke width 2, left of the legend column) as pixel points.
    fn data_lines(svg: &str, plot_width: f64) -> Vec<Vec<(f64, f64)>> {
        svg.split("<polyline")
            .skip(1)
            .filter(|el| el.contains("stroke-width=\"2\""))
            .filter_map(|el| {
                let start = el.find("points=\"")? + 8;
                let end = start + el[start..].find('"')?;
                let points: Vec<(f64, f64)> = el[start..end]
                    .split_whitespace()
                    .filter_map(|p| {
                        let (x, y) = p.split_once(',')?;
                        Some((x.parse().ok()?, y.parse().ok()?))
                    })
                    .collect();
                (points.iter().all(|&(x, _)| x < plot_width)).then_some(points)
            })
            .collect()
    }

    fn figure() -> Figure {
        init_fonts().expect("the embedded font");
        let wave: Vec<(f64, f64)> =
            (0..=200).map(|k| f64::from(k) * 0.05).map(|t| (t, 10.0 * (t * 2.0).sin())).collect();
        let mut top = Panel::new("rate", "t [s]", "rate").line("estimate", wave, BLUE);
        top.y_range = Some((-5.0, 5.0));
        top.hlines.push((0.5, "margin 0.5".into()));
        top.spans = vec![
            Span { x0: 1.0, x1: 2.0, label: "gate open".into(), color: BLUE },
            Span { x0: 3.0, x1: 4.0, label: "gate open".into(), color: BLUE },
        ];
        let strip = Panel::strip(
            "why the gate was closed",
            "t [s]",
            vec![
                Span { x0: 0.0, x1: 1.0, label: "warming up".into(), color: GREY },
                Span { x0: 2.0, x1: 3.0, label: "below the margin".into(), color: RED_ },
            ],
        );
        // From t = 2 to 8 only: on its own axis it would span the panel.
        let flat: Vec<(f64, f64)> = (20..=80).map(|k| (f64::from(k) * 0.1, 0.2)).collect();
        let low = Panel::new("eps", "t [s]", "ε").line("radius", flat, GREEN);
        let mut panels = vec![top, strip, low];
        for p in &mut panels {
            p.x_range = Some((0.0, 10.0));
        }
        Figure { panels, rows: 3, cols: 1, size: (1200, 910) }
    }

    /// The SVG holds the shaded spans (one legend entry per label), the strip's labels in
    /// words, and the legend texts, clipping said.
    #[test]
    fn the_svg_holds_the_spans_and_the_labels() {
        let svg = svg_string(&figure()).expect("drawn");
        for label in ["gate open", "warming up", "below the margin", "radius", "margin 0.5"] {
            assert!(svg.contains(label), "{label}");
        }
        assert!(svg.contains("estimate (clipped to [-5, 5])"));
        assert_eq!(svg.matches("gate open").count(), 1, "one legend entry for both spans");
        // Two shaded spans and two strip cells, besides the legend's boxes.
        assert!(svg.matches("<rect").count() >= 4 + 3);
    }

    /// Every data line stays inside its own panel (the panels' bands by their weights: 3, 1,
    /// 3 of 910 pixels), left of the legend column; and the panels share one time axis: a
    /// time is at one pixel in both panels.
    #[test]
    fn every_line_stays_inside_its_panel_on_one_time_axis() {
        let fig = figure();
        let svg = svg_string(&fig).expect("drawn");
        let plot_width = f64::from(fig.size.0 - LEGEND_WIDTH);
        let lines = data_lines(&svg, plot_width);
        assert_eq!(lines.len(), 2, "the two panels' lines (the wave clipped, not broken)");
        let bands = [(0.0, 390.0), (390.0, 520.0), (520.0, 910.0)];
        for line in &lines {
            let band = bands
                .iter()
                .find(|(lo, hi)| line.iter().all(|&(_, y)| y >= *lo && y <= *hi))
                .unwrap_or_else(|| panic!("a line crosses panels: {:?}", &line[..3]));
            assert!(band.0 != 390.0, "no line in the strip");
        }
        assert_eq!(lines[0].len(), 201);
        // The wave's points are every 0.05 s from 0: t = 2 is its 41st, t = 8 its 161st.
        let (wave, flat) = (&lines[0], &lines[1]);
        assert!((wave[40].0 - flat[0].0).abs() <= 1.0, "t = 2: {} and {}", wave[40].0, flat[0].0);
        let end = flat.last().expect("points").0;
        assert!((wave[160].0 - end).abs() <= 1.0, "t = 8: {} and {end}", wave[160].0);
    }

    #[test]
    fn ticks_are_written_as_people_write_numbers() {
        assert_eq!(tick(500.0), "500");
        assert_eq!(tick(2.5), "2.5");
        assert_eq!(tick(0.05), "0.05");
        assert_eq!(tick(-0.0), "0");
        assert_eq!(tick(-1.0), "-1");
    }
}
