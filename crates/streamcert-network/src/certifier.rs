//! [`NetworkCertifier`]: `N` local certifiers and the composition at every epoch.

use serde::{Deserialize, Serialize};
use streamcert_certificate::{Certifier, Evidence};

use crate::composer::record;
use crate::{Composer, EpochReport, LocalSnapshot, NetworkConfig, NetworkError};

/// The live network certifier. Serde-serialisable as a whole (checkpoint and resume).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NetworkCertifier {
    pub(crate) cfg: NetworkConfig,
    pub(crate) certifiers: Vec<Certifier>,
    pub(crate) last: Vec<Option<LocalSnapshot>>,
    pub(crate) composer: Composer,
    /// Per-thread scratch of [`push_batch`](Self::push_batch) (positions sorted by subsystem).
    #[serde(skip)]
    pub(crate) scratch: crate::batch::Scratch,
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
        Ok(Self {
            last: vec![None; certifiers.len()],
            certifiers,
            composer: Composer::new(),
            scratch: crate::batch::Scratch::default(),
            cfg,
        })
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
        for (l, c) in self.last.iter().zip(&certifiers) {
            let Some(l) = l else { continue };
            if !l.is_valid() {
                return bad("a stored time, certificate or coupling bound is not finite, or a \
                            verdict is open with a reason"
                    .into());
            }
            if l.couplings.len() != c.coupling_bounds().len() {
                return bad("a stored snapshot has another number of coupling bounds".into());
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
        record(&mut self.last[i], t, self.cfg.certificate, &self.certifiers[i], &ev);
        Ok(ev)
    }

    /// Declare that subsystem `i`'s samples are missing before its next one (a live source's
    /// outage): its certifier's next sample starts new windows
    /// ([`Certifier::gap`](streamcert_certificate::Certifier::gap)). Out of range, nothing.
    pub fn gap(&mut self, i: usize) {
        if let Some(c) = self.certifiers.get_mut(i) {
            c.gap();
        }
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
        for k in self.composer.due(&self.cfg, t)? {
            let report = self.composer.compose(&self.cfg, k, &self.last)?;
            on_epoch(&report);
        }
        Ok(())
    }

    /// The newest snapshot of every subsystem (`None` before its first sample).
    #[must_use]
    pub fn snapshots(&self) -> &[Option<LocalSnapshot>] {
        &self.last
    }
}
