//! The legend column beside (or below) a panel: one entry per span label, reference line and
//! series, each a mark and its words wrapped.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::{MISSING, Panel, Result, anyhow};

/// One legend entry: a line or a filled box, and its text.
pub(crate) struct Entry {
    pub(crate) text: String,
    pub(crate) color: RGBColor,
    pub(crate) boxed: bool,
    pub(crate) dashed: bool,
}

/// The legend entries of `panel`, in drawing order.
pub(crate) fn entries(panel: &Panel, labels: &[(String, bool)]) -> Vec<Entry> {
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
pub(crate) fn wrap(text: &str, width: usize) -> Vec<String> {
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
pub(crate) fn draw_legend<DB: DrawingBackend>(
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
