//! # streamcert-plot
//!
//! A minimal figure description ([`Figure`]: panels of [`Series`], reference lines and an
//! optional [`Heatmap`]) rendered with plotters to PNG and SVG ([`save`], [`save_as`]), with
//! the DejaVu Sans font embedded (no system fonts needed). One plotting module for the whole
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
        }
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
    if let Some(r) = panel.y_range {
        (y0, y1) = r;
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    if y1 <= y0 {
        y1 = y0 + 1.0;
    }
    let pad = 0.05 * (y1 - y0);
    ((x0, x1), (y0 - pad, y1 + pad))
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

fn draw_panel<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, panel: &Panel) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let ((x0, x1), (y0, y1)) = range(panel);
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, ("sans-serif", 16))
        .margin(8)
        .x_label_area_size(32)
        .y_label_area_size(56)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(anyhow)?;
    chart
        .configure_mesh()
        .x_desc(panel.x_label.as_str())
        .y_desc(panel.y_label.as_str())
        .light_line_style(WHITE)
        .draw()
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
            .map_err(anyhow)?
            .label(h.missing.as_str())
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 18, y + 5)], MISSING.filled()));
    }
    for (y, label) in &panel.hlines {
        chart
            .draw_series(LineSeries::new(vec![(x0, *y), (x1, *y)], GREY.stroke_width(1)))
            .map_err(anyhow)?
            .label(label.as_str())
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], GREY));
    }
    for x in &panel.vlines {
        chart
            .draw_series(LineSeries::new(vec![(*x, y0), (*x, y1)], BLACK.mix(0.3).stroke_width(1)))
            .map_err(anyhow)?;
    }
    for (index, s) in panel.series.iter().enumerate() {
        let color = s.color;
        // A series identical to an earlier one is hidden under it: say so in the legend, and
        // draw it dashed on top so both stay visible.
        let twin = panel.series[..index].iter().find(|e| same_points(&e.points, &s.points));
        let mut clipped = false;
        // Clip to the requested range when there is one (the panel adds a margin around it).
        let (lo, hi) = panel.y_range.unwrap_or((y0, y1));
        // Break the line at non-finite values; clip to the panel and say so in the legend.
        let mut segments: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
        for &(x, y) in &s.points {
            if x.is_finite() && y.is_finite() {
                clipped |= y < lo || y > hi;
                if let Some(seg) = segments.last_mut() {
                    seg.push((x, y.clamp(lo, hi)));
                }
            } else if segments.last().is_some_and(|seg| !seg.is_empty()) {
                segments.push(Vec::new());
            }
        }
        let mut label = s.name.clone();
        if let Some(t) = twin {
            label = format!("{label} (identical to {}: dashed)", t.name);
        }
        if clipped {
            label = format!("{label} (clipped to [{lo:.3}, {hi:.3}])");
        }
        let mut first = true;
        for seg in segments.into_iter().filter(|s| !s.is_empty()) {
            let drawn = if twin.is_some() {
                chart
                    .draw_series(DashedLineSeries::new(seg, 6, 6, color.stroke_width(2)))
                    .map_err(anyhow)?
            } else {
                chart.draw_series(LineSeries::new(seg, color.stroke_width(2))).map_err(anyhow)?
            };
            if first {
                drawn.label(label.as_str()).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                });
                first = false;
            }
        }
    }
    if !panel.series.is_empty() || !panel.hlines.is_empty() {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 13))
            .draw()
            .map_err(anyhow)?;
    }
    Ok(())
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
    let areas = root.split_evenly((fig.rows, fig.cols));
    for (area, panel) in areas.iter().zip(&fig.panels) {
        draw_panel(area, panel)?;
    }
    root.present().map_err(anyhow)?;
    Ok(())
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
