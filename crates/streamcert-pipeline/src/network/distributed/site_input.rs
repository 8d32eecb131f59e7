//! What a site reads: a file or a pipe (opened again after a lost peer), or a live source
//! opened for its subsystems' columns; its rows as timely rows, a live source's gap marking
//! the next one.

use std::io::Read;

use streamcert_timely::{Placement, Row};

use super::super::config::NetConfig;
use super::super::input::{Item, Rows};
use crate::CliError;

/// Opens this process's input again (the run reads it from the start after a restart).
pub type Reopen = dyn Fn() -> Result<Box<dyn Read + Send>, CliError>;

/// Opens a live source for these columns (the outputs and inputs of the subsystems placed
/// on this process, in the wide layout), again after a lost peer.
pub type OpenLive<'a> =
    dyn Fn(&crate::config::Columns) -> Result<Box<dyn crate::source::Source + Send>, CliError> + 'a;

/// Where this process's rows come from.
#[derive(Clone, Copy)]
pub enum SiteInput<'a> {
    /// A file or a pipe.
    File(&'a Reopen),
    /// A live source (wide rows; `--silence` required, so a quiet site's clock advances).
    Live(&'a OpenLive<'a>),
}

/// The rows of `input` as timely rows.
pub(super) struct RowIter<R: Read> {
    rows: Option<Rows<R>>,
    first: Option<CliError>,
    values: Vec<f64>,
    items: Vec<(usize, usize, usize, usize)>,
    /// A live source declared a gap (or yielded a bad payload) since the last row.
    gap: bool,
}

/// What this process reads, opened.
pub(super) enum Opened {
    File(Box<dyn Read + Send>),
    Live(Box<dyn crate::source::Source + Send>),
}

impl<R: Read> RowIter<R> {
    /// The rows of `input` this process reads (its subsystems' columns); a refused input is
    /// the iterator's first item.
    fn for_site(
        cfg: &NetConfig,
        process_of: &[usize],
        process: usize,
        input: R,
        name: &str,
    ) -> Self {
        let (rows, first) = match Rows::for_site(cfg, process_of, process, input, name) {
            Ok(rows) => (Some(rows), None),
            Err(e) => (None, Some(e)),
        };
        Self { rows, first, values: Vec::new(), items: Vec::new(), gap: false }
    }
}

impl RowIter<Box<dyn Read + Send>> {
    /// The rows this process reads, from a file or a live source.
    pub(super) fn opened(
        cfg: &NetConfig,
        process_of: &[usize],
        process: usize,
        input: Opened,
        name: &str,
    ) -> Self {
        match input {
            Opened::File(r) => Self::for_site(cfg, process_of, process, r, name),
            Opened::Live(source) => Self {
                rows: Some(Rows::live_for_site(cfg, process_of, process, source)),
                first: None,
                values: Vec::new(),
                items: Vec::new(),
                gap: false,
            },
        }
    }
}

impl<R: Read> Iterator for RowIter<R> {
    type Item = Result<Row, CliError>;

    fn next(&mut self) -> Option<Self::Item> {
        if let Some(e) = self.first.take() {
            return Some(Err(e));
        }
        // A live source's gap, or a bad payload (skipped, and the windows of this site's
        // subsystems restart at the next row), marks the next row.
        let next = loop {
            match self.rows.as_mut()?.next(&mut self.values, &mut self.items)? {
                Ok(Item::Gap(why)) => {
                    eprintln!("gap: {why}; the windows restart at the next row");
                    self.gap = true;
                }
                Ok(Item::Bad(e)) => {
                    eprintln!("skipped: {e}; the windows restart at the next row");
                    self.gap = true;
                }
                Ok(Item::Idle) => {}
                Ok(Item::Row(line, t)) => break Ok((line, t)),
                Err(e) => break Err(e),
            }
        };
        let gap = std::mem::take(&mut self.gap);
        Some(next.map(|(line, t)| {
            Row {
                gap,
                line,
                t,
                samples: self
                    .items
                    .iter()
                    .map(|&(i, start, p, m)| (i, self.values[start..start + p + m].to_vec()))
                    .collect(),
            }
        }))
    }
}

/// A live source on sites yields wide rows and needs `--silence`.
pub(super) fn check_live(
    cfg: &NetConfig,
    open: SiteInput<'_>,
    place: &Placement,
) -> Result<(), String> {
    if let SiteInput::Live(_) = open {
        if cfg.layout != super::super::config::InputLayout::Wide {
            return Err("a live [source] yields wide rows: set [network] input = \"wide\"".into());
        }
        if place.silence.is_none() {
            return Err("a live [source] on sites needs --silence SECONDS: how long a quiet \
                        site waits before its clock advances by the wall clock (its subsystems \
                        turn stale rather than hold every epoch back)"
                .into());
        }
    }
    Ok(())
}

/// This process's input, opened (a live source for its subsystems' columns).
pub(super) fn open_site(
    cfg: &NetConfig,
    open: SiteInput<'_>,
    process_of: &[usize],
    process: usize,
) -> Result<Opened, CliError> {
    Ok(match open {
        SiteInput::File(open) => Opened::File(open()?),
        SiteInput::Live(open) => {
            Opened::Live(open(&super::super::input::site(cfg, process_of, process).0)?)
        }
    })
}
