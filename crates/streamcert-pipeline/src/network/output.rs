//! The epoch rows of `network`: CSV (csv crate, a `cert_<name>` column per subsystem) or JSON
//! lines.

use std::io::Write;

use serde::Serialize;
use streamcert_network::EpochReport;

use super::NetSummary;
use crate::output::{Flush, Format, Header};

/// One output row per epoch (JSON lines; the CSV has the same fields, `local` as one column
/// `cert_<name>` per subsystem).
#[derive(Debug, Serialize)]
struct EpochRow<'a> {
    t: f64,
    epoch: u64,
    rate: Option<f64>,
    certified: u8,
    open: u8,
    critical_scale: Option<f64>,
    limiting_subsystem: Option<&'a str>,
    limiting_coupling: Option<String>,
    /// 1 when the Perron iteration behind the two fields above met its tolerance.
    sensitivity_converged: u8,
    not_certified: String,
    local: std::collections::BTreeMap<&'a str, Option<f64>>,
    /// Upper bounds of the estimated couplings, keyed `gamma_<from>_<to>`.
    #[serde(skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    estimated: std::collections::BTreeMap<&'a str, Option<f64>>,
}

/// Epoch rows as CSV (csv crate) or JSON lines.
pub(super) struct EpochWriter<W: Write> {
    csv: Option<csv::Writer<W>>,
    json: Option<std::io::BufWriter<W>>,
    flush_each_row: bool,
    header: bool,
    /// `gamma_<from>_<to>` per estimated coupling.
    estimated: Vec<String>,
}

/// The fixed CSV columns before the per-subsystem `cert_<name>` columns (and the
/// `gamma_<from>_<to>` columns of the estimated couplings after them).
const CSV_COLUMNS: [&str; 10] = [
    "t",
    "epoch",
    "rate",
    "certified",
    "open",
    "critical_scale",
    "limiting_subsystem",
    "limiting_coupling",
    "sensitivity_converged",
    "not_certified",
];

impl<W: Write> EpochWriter<W> {
    pub(super) fn new(
        out: W,
        format: Format,
        flush: Flush,
        header: Header,
        estimated: Vec<String>,
    ) -> Self {
        let flush_each_row = flush == Flush::EachRow;
        let header = header == Header::Write;
        let (csv, json) = match format {
            Format::Csv => (Some(csv::Writer::from_writer(out)), None),
            Format::Jsonl => (None, Some(std::io::BufWriter::new(out))),
        };
        Self { csv, json, flush_each_row, header, estimated }
    }

    pub(super) fn write(
        &mut self,
        r: &EpochReport,
        names: &[String],
        summary: &mut NetSummary,
    ) -> std::io::Result<()> {
        summary.epochs += 1;
        summary.certified += u64::from(r.certified);
        summary.open += u64::from(r.open);
        summary.open_at_end = r.open;
        super::verdict::count(summary, r, names);
        if let Some(trace) = &mut summary.trace {
            trace.push_epoch(r.t, r.rate, r.open, r.not_certified.len(), &r.local);
        }
        if r.open && summary.first_open.is_none() {
            summary.first_open = Some(r.t);
        }
        let not_certified = r
            .not_certified
            .iter()
            .map(|(i, why)| format!("{}: {why}", names[*i]))
            .collect::<Vec<_>>()
            .join("; ");
        let row = EpochRow {
            t: r.t,
            epoch: r.epoch,
            rate: r.rate,
            certified: u8::from(r.certified),
            open: u8::from(r.open),
            critical_scale: r.critical_scale,
            limiting_subsystem: r.limiting_subsystem.map(|i| names[i].as_str()),
            limiting_coupling: r
                .limiting_coupling
                .map(|(i, j)| format!("{}->{}", names[j], names[i])),
            sensitivity_converged: u8::from(r.sensitivity_converged),
            not_certified,
            local: names.iter().map(String::as_str).zip(r.local.iter().copied()).collect(),
            estimated: self
                .estimated
                .iter()
                .map(String::as_str)
                .zip(r.estimated.iter().copied())
                .collect(),
        };
        if let Some(w) = &mut self.csv {
            if std::mem::take(&mut self.header) {
                let mut header: Vec<String> =
                    CSV_COLUMNS.iter().map(|c| (*c).to_string()).collect();
                header.extend(names.iter().map(|n| format!("cert_{n}")));
                header.extend(self.estimated.iter().cloned());
                w.write_record(&header)?;
            }
            let num = |v: Option<f64>| {
                v.map_or(String::new(), |x| ryu::Buffer::new().format(x).to_string())
            };
            let mut record = vec![
                num(Some(row.t)),
                row.epoch.to_string(),
                num(row.rate),
                row.certified.to_string(),
                row.open.to_string(),
                num(row.critical_scale),
                row.limiting_subsystem.unwrap_or_default().to_string(),
                row.limiting_coupling.clone().unwrap_or_default(),
                row.sensitivity_converged.to_string(),
                row.not_certified.clone(),
            ];
            record.extend(r.local.iter().map(|v| num(*v)));
            record.extend(r.estimated.iter().map(|v| num(*v)));
            w.write_record(&record)?;
        }
        if let Some(w) = &mut self.json {
            serde_json::to_writer(&mut *w, &row)?;
            w.write_all(b"\n")?;
        }
        if self.flush_each_row {
            self.flush()?;
        }
        Ok(())
    }

    pub(super) fn flush(&mut self) -> std::io::Result<()> {
        if let Some(w) = &mut self.csv {
            w.flush()?;
        }
        if let Some(w) = &mut self.json {
            w.flush()?;
        }
        Ok(())
    }
}
