//! [`NetworkCertifier`]: `N` local certifiers and the composition at every epoch.

use serde::{Deserialize, Serialize};
use streamcert_certificate::{Certifier, Evidence, Verdict};
use streamcert_compose::{Network, SparseOptions, certify_sparse, network_rate};

use crate::report::ComposeMethod;
use crate::{EpochReport, NetworkConfig, NetworkError, NotCertifiedLocal, perron_sensitivity};

/// A subsystem's newest sample time and composing verdict.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
struct Last {
    t: f64,
    verdict: Verdict,
}

/// The live network certifier. Serde-serialisable as a whole (checkpoint and resume).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NetworkCertifier {
    cfg: NetworkConfig,
    certifiers: Vec<Certifier>,
    last: Vec<Option<Last>>,
    /// Index `k` of the next epoch to compose (at `k · epoch`); `None` before any sample.
    next: Option<u64>,
    streak: usize,
}

impl NetworkCertifier {
    /// Validate and build every subsystem's certifier.
    ///
    /// # Errors
    /// [`NetworkError::InvalidConfig`], or [`NetworkError::Subsystem`] for a certifier's
    /// configuration.
    pub fn new(cfg: NetworkConfig) -> Result<Self, NetworkError> {
        cfg.validate()?;
        let certifiers = cfg
            .subsystems
            .iter()
            .enumerate()
            .map(|(index, s)| {
                Certifier::new(s.certifier.clone()).map_err(|source| NetworkError::Subsystem {
                    index,
                    name: s.name.clone(),
                    source,
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { last: vec![None; certifiers.len()], certifiers, next: None, streak: 0, cfg })
    }

    /// Check a state read back from a checkpoint: the configuration is valid, there is one
    /// certifier and one newest verdict per subsystem, each certifier passes
    /// [`Certifier::verify`] and was built from its subsystem's configuration, and every
    /// stored time and value is finite. A state that fails is refused, never used.
    ///
    /// # Errors
    /// [`NetworkError::InvalidConfig`] naming what is wrong, or [`NetworkError::Subsystem`].
    pub fn verify(self) -> Result<Self, NetworkError> {
        self.cfg.validate()?;
        let n = self.cfg.subsystems.len();
        let bad = |reason: String| Err(NetworkError::InvalidConfig { field: "checkpoint", reason });
        if self.certifiers.len() != n || self.last.len() != n {
            return bad(format!(
                "{} certifiers and {} verdicts for {n} subsystems",
                self.certifiers.len(),
                self.last.len()
            ));
        }
        let mut certifiers = Vec::with_capacity(n);
        for (index, (c, spec)) in self.certifiers.into_iter().zip(&self.cfg.subsystems).enumerate()
        {
            let c = c.verify().map_err(|source| NetworkError::Subsystem {
                index,
                name: spec.name.clone(),
                source,
            })?;
            if c.config() != &spec.certifier {
                return bad(format!("subsystem `{}` has another configuration", spec.name));
            }
            certifiers.push(c);
        }
        for l in self.last.iter().flatten() {
            let finite = |v: Option<f64>| v.is_none_or(f64::is_finite);
            if !(l.t.is_finite() && finite(l.verdict.value) && finite(l.verdict.radius)) {
                return bad("a stored time or certificate is not finite".into());
            }
            if l.verdict.open != l.verdict.reason.is_none() {
                return bad("a stored verdict is open with a reason, or closed without one".into());
            }
        }
        Ok(Self { certifiers, ..self })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &NetworkConfig {
        &self.cfg
    }

    /// Number of subsystems.
    #[must_use]
    pub fn len(&self) -> usize {
        self.certifiers.len()
    }

    /// Whether there are no subsystems (never, after validation).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.certifiers.is_empty()
    }

    /// The certifier of subsystem `i`.
    #[must_use]
    pub fn subsystem(&self, i: usize) -> Option<&Certifier> {
        self.certifiers.get(i)
    }

    /// One sample of subsystem `i`. Every epoch `k · epoch <= t` not yet composed is composed
    /// first (from the samples before this one) and handed to `on_epoch`; then the sample goes
    /// to the subsystem's certifier, whose evidence is returned. Times must increase within a
    /// subsystem; across subsystems they may interleave.
    ///
    /// # Errors
    /// [`NetworkError::UnknownSubsystem`]; [`NetworkError::TimeJump`];
    /// [`NetworkError::Subsystem`] for a sample the certifier rejects (under its bad-sample
    /// policy); [`NetworkError::Compose`].
    pub fn push(
        &mut self,
        i: usize,
        t: f64,
        y: &[f64],
        u: &[f64],
        mut on_epoch: impl FnMut(&EpochReport),
    ) -> Result<Evidence, NetworkError> {
        let len = self.certifiers.len();
        if i >= len {
            return Err(NetworkError::UnknownSubsystem { index: i, len });
        }
        self.advance(t, &mut on_epoch)?;
        let ev = self.certifiers[i].push(t, y, u).map_err(|source| NetworkError::Subsystem {
            index: i,
            name: self.cfg.subsystems[i].name.clone(),
            source,
        })?;
        self.last[i] = Some(Last { t, verdict: *ev.verdict(self.cfg.certificate) });
        Ok(ev)
    }

    /// Compose every epoch up to time `t` (for example at the end of a stream, or on a clock
    /// tick when no sample arrives: silent subsystems then turn stale).
    ///
    /// # Errors
    /// [`NetworkError::TimeJump`], [`NetworkError::Compose`].
    pub fn advance(
        &mut self,
        t: f64,
        mut on_epoch: impl FnMut(&EpochReport),
    ) -> Result<(), NetworkError> {
        if !t.is_finite() {
            return Ok(());
        }
        let epoch = self.cfg.epoch;
        let first = (t / epoch).floor().max(0.0) + 1.0;
        let mut k = match self.next {
            Some(k) => k,
            None if first < u64::MAX as f64 => first as u64,
            None => return Err(NetworkError::TimeJump { t, epochs: first, max: 0 }),
        };
        // Refuse before composing anything: the state stays as it was.
        let epochs = (t / epoch).floor() - k as f64 + 1.0;
        if epochs > self.cfg.max_epoch_jump as f64 {
            return Err(NetworkError::TimeJump { t, epochs, max: self.cfg.max_epoch_jump });
        }
        self.next = Some(k);
        while k as f64 * epoch <= t {
            let report = self.compose(k)?;
            on_epoch(&report);
            k += 1;
            self.next = Some(k);
        }
        Ok(())
    }

    /// Compose epoch `k` from the subsystems' newest verdicts.
    fn compose(&mut self, k: u64) -> Result<EpochReport, NetworkError> {
        let at = k as f64 * self.cfg.epoch;
        let n = self.certifiers.len();
        let mut local = Vec::with_capacity(n);
        let mut not_certified = Vec::new();
        for (i, last) in self.last.iter().enumerate() {
            let value = match last {
                None => {
                    not_certified.push((i, NotCertifiedLocal::NoSample));
                    None
                }
                Some(l) if at - l.t > self.cfg.stale_after => {
                    not_certified.push((i, NotCertifiedLocal::Stale { last: l.t }));
                    None
                }
                Some(l) => {
                    if let Some(r) = l.verdict.reason {
                        not_certified.push((i, NotCertifiedLocal::Local(r)));
                    }
                    l.verdict.value
                }
            };
            local.push(value);
        }
        let mut report = EpochReport {
            t: at,
            epoch: k,
            local,
            rate: None,
            method: None,
            certified: false,
            open: false,
            critical_scale: None,
            limiting_subsystem: None,
            limiting_coupling: None,
            not_certified,
        };
        if let Some(beta) = report.local.iter().copied().collect::<Option<Vec<f64>>>() {
            let net = Network::new(beta, &self.cfg.couplings)?;
            let (rate, scale, method) = if n <= self.cfg.dense_limit {
                let c = network_rate(&net)?;
                (c.rate, c.critical_scale, ComposeMethod::Dense)
            } else {
                let c = certify_sparse(&net, &SparseOptions::default())?;
                (c.rate, c.critical_scale, ComposeMethod::Sparse)
            };
            let s = perron_sensitivity(&net, 1000, 1e-12);
            report.rate = Some(rate);
            report.method = Some(method);
            report.critical_scale = Some(scale);
            report.limiting_subsystem = Some(s.limiting_subsystem);
            report.limiting_coupling = s.limiting_coupling;
            report.certified = report.not_certified.is_empty() && rate >= self.cfg.margin;
        }
        self.streak = if report.certified { self.streak + 1 } else { 0 };
        report.open = self.streak >= self.cfg.consecutive;
        Ok(report)
    }
}
