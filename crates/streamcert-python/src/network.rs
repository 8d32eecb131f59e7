//! [`NetworkRun`]: the command line's `network` over samples passed in by subsystem.

use streamcert_network::{EpochReport, NetworkCertifier};
use streamcert_pipeline::network::NetConfig;

use crate::Error;

/// Many subsystems' certifiers and the composer, configured as `streamcert network`: samples
/// go in by subsystem, and every epoch the composer reaches comes out as its report.
#[derive(Debug, Clone)]
pub struct NetworkRun {
    cfg: NetConfig,
    net: NetworkCertifier,
    names: Vec<String>,
}

impl NetworkRun {
    /// A network run of `cfg`.
    ///
    /// # Errors
    /// [`Error::Config`] when the network refuses the configuration.
    pub fn new(cfg: NetConfig) -> Result<Self, Error> {
        let net = NetworkCertifier::new(cfg.network.clone())
            .map_err(|e| Error::Config(format!("configuration: invalid configuration: {e}")))?;
        let names = cfg.network.subsystems.iter().map(|s| s.name.clone()).collect();
        Ok(Self { cfg, net, names })
    }

    /// The subsystems' names, in configuration order.
    #[must_use]
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// `(outputs, inputs)` of each subsystem.
    #[must_use]
    pub fn dims(&self) -> &[(usize, usize)] {
        &self.cfg.dims
    }

    /// The index of subsystem `name`.
    ///
    /// # Errors
    /// [`Error::Config`] naming the subsystems there are.
    pub fn index(&self, name: &str) -> Result<usize, Error> {
        self.names.iter().position(|n| n == name).ok_or_else(|| {
            Error::Config(format!("no subsystem `{name}`; the subsystems are {:?}", self.names))
        })
    }

    /// Feed subsystem `i` the samples `t[k]`, `y[k·p..]`, `u[k·m..]` (row-major); every epoch
    /// composed on the way is appended to `reports`. Values are checked as a CSV row is
    /// (finite), times must increase within the subsystem.
    ///
    /// # Errors
    /// [`Error::Shape`] for wrong lengths, [`Error::Data`] for a refused sample (the samples
    /// before it are absorbed and their epochs reported).
    pub fn push(
        &mut self,
        i: usize,
        t: &[f64],
        y: &[f64],
        u: &[f64],
        reports: &mut Vec<EpochReport>,
    ) -> Result<(), Error> {
        let (p, m) = *self.cfg.dims.get(i).ok_or_else(|| {
            Error::Config(format!("subsystem index {i} out of range ({})", self.names.len()))
        })?;
        let n = t.len();
        if y.len() != n * p || u.len() != n * m {
            return Err(Error::Shape(format!(
                "subsystem `{}`: {n} times need {n} × {p} outputs and {n} × {m} inputs, got {} \
                 and {} values",
                self.names[i],
                y.len(),
                u.len()
            )));
        }
        for k in 0..n {
            let (yk, uk) = (&y[k * p..(k + 1) * p], &u[k * m..(k + 1) * m]);
            if let Some(v) = std::iter::once(&t[k]).chain(yk).chain(uk).find(|v| !v.is_finite()) {
                return Err(Error::Data {
                    row: k,
                    column: None,
                    message: format!(
                        "subsystem `{}`: expected a finite number, found `{v}` (NaN and \
                         infinity are not accepted)",
                        self.names[i]
                    ),
                });
            }
            self.net
                .push(i, t[k], yk, uk, |r| reports.push(r.clone()))
                .map_err(|e| Error::Data { row: k, column: None, message: e.to_string() })?;
        }
        Ok(())
    }

    /// Compose every epoch up to time `t` (a clock tick: silent subsystems turn stale).
    ///
    /// # Errors
    /// [`Error::Data`] for a time before the epochs already composed.
    pub fn advance(&mut self, t: f64, reports: &mut Vec<EpochReport>) -> Result<(), Error> {
        self.net.advance(t, |r| reports.push(r.clone())).map_err(|e| Error::Data {
            row: 0,
            column: None,
            message: e.to_string(),
        })
    }
}
