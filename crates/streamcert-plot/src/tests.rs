//! The figures drawn to SVG: spans, strips, legends, one time axis, ticks.

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
