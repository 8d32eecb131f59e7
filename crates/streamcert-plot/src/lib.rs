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

mod legend;

use plotters::coord::Shift;
use plotters::prelude::*;
pub use plotters::style::RGBColor;

use legend::{draw_legend, entries, wrap};

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
mod tests;
