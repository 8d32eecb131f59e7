//! Minimal figure description rendered with plotters to PNG and SVG.

use std::path::Path;

use anyhow::{Result, anyhow};
use plotters::coord::Shift;
use plotters::prelude::*;

/// Register the embedded DejaVu Sans font (no system fonts needed).
pub(crate) fn init_fonts() -> Result<()> {
    plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
        .map_err(|_| anyhow!("embedded font rejected"))
}

/// Colours used across figures.
pub(crate) const BLUE: RGBColor = RGBColor(31, 119, 180);
pub(crate) const ORANGE: RGBColor = RGBColor(255, 127, 14);
pub(crate) const GREEN: RGBColor = RGBColor(44, 160, 44);
pub(crate) const RED_: RGBColor = RGBColor(214, 39, 40);
pub(crate) const PURPLE: RGBColor = RGBColor(148, 103, 189);
pub(crate) const GREY: RGBColor = RGBColor(127, 127, 127);

/// One line.
pub(crate) struct Series {
    pub(crate) name: String,
    pub(crate) points: Vec<(f64, f64)>,
    pub(crate) color: RGBColor,
}

/// A cell grid coloured on a diverging red (negative) / white / green (positive) scale.
pub(crate) struct Heatmap {
    /// Cell edges along x (len nx + 1) and y (len ny + 1).
    pub(crate) x_edges: Vec<f64>,
    pub(crate) y_edges: Vec<f64>,
    /// Values, row-major by x then y: `z[ix * ny + iy]`.
    pub(crate) z: Vec<f64>,
    /// Saturation magnitude.
    pub(crate) scale: f64,
    /// Legend text for the cells without a value (drawn in [`MISSING`] grey).
    pub(crate) missing: String,
}

/// One panel.
pub(crate) struct Panel {
    pub(crate) title: String,
    pub(crate) x_label: String,
    pub(crate) y_label: String,
    pub(crate) series: Vec<Series>,
    /// Horizontal reference lines `(y, label)`.
    pub(crate) hlines: Vec<(f64, String)>,
    /// Vertical reference lines.
    pub(crate) vlines: Vec<f64>,
    pub(crate) y_range: Option<(f64, f64)>,
    pub(crate) heatmap: Option<Heatmap>,
}

impl Panel {
    pub(crate) fn new(title: &str, x_label: &str, y_label: &str) -> Self {
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

    pub(crate) fn line(mut self, name: &str, points: Vec<(f64, f64)>, color: RGBColor) -> Self {
        self.series.push(Series { name: name.into(), points, color });
        self
    }
}

/// A figure: panels stacked in `rows × cols`.
pub(crate) struct Figure {
    pub(crate) panels: Vec<Panel>,
    pub(crate) rows: usize,
    pub(crate) cols: usize,
    pub(crate) size: (u32, u32),
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
pub(crate) const MISSING: RGBColor = RGBColor(225, 225, 225);

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
        .map_err(|e| anyhow!("{e:?}"))?;
    chart
        .configure_mesh()
        .x_desc(panel.x_label.as_str())
        .y_desc(panel.y_label.as_str())
        .light_line_style(WHITE)
        .draw()
        .map_err(|e| anyhow!("{e:?}"))?;
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
            .map_err(|e| anyhow!("{e:?}"))?
            .label(h.missing.as_str())
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 18, y + 5)], MISSING.filled()));
    }
    for (y, label) in &panel.hlines {
        chart
            .draw_series(LineSeries::new(vec![(x0, *y), (x1, *y)], GREY.stroke_width(1)))
            .map_err(|e| anyhow!("{e:?}"))?
            .label(label.as_str())
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], GREY));
    }
    for x in &panel.vlines {
        chart
            .draw_series(LineSeries::new(vec![(*x, y0), (*x, y1)], BLACK.mix(0.3).stroke_width(1)))
            .map_err(|e| anyhow!("{e:?}"))?;
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
            label = format!("{label} (clipped to [{lo}, {hi}])");
        }
        let mut first = true;
        for seg in segments.into_iter().filter(|s| !s.is_empty()) {
            let drawn = if twin.is_some() {
                chart
                    .draw_series(DashedLineSeries::new(seg, 6, 6, color.stroke_width(2)))
                    .map_err(|e| anyhow!("{e:?}"))?
            } else {
                chart
                    .draw_series(LineSeries::new(seg, color.stroke_width(2)))
                    .map_err(|e| anyhow!("{e:?}"))?
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
            .map_err(|e| anyhow!("{e:?}"))?;
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
    root.fill(&WHITE).map_err(|e| anyhow!("{e:?}"))?;
    let areas = root.split_evenly((fig.rows, fig.cols));
    for (area, panel) in areas.iter().zip(&fig.panels) {
        draw_panel(area, panel)?;
    }
    root.present().map_err(|e| anyhow!("{e:?}"))?;
    Ok(())
}

/// Write `dir/name.png` and `dir/name.svg`.
pub(crate) fn save(fig: &Figure, dir: &Path, name: &str) -> Result<()> {
    let png = dir.join(format!("{name}.png"));
    draw(BitMapBackend::new(&png, fig.size).into_drawing_area(), fig)?;
    let svg = dir.join(format!("{name}.svg"));
    draw(SVGBackend::new(&svg, fig.size).into_drawing_area(), fig)?;
    Ok(())
}
