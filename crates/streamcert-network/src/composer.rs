//! [`Composer`]: the epoch clock and the composition of the subsystems' newest snapshots, shared
//! by the one-process [`NetworkCertifier`](crate::NetworkCertifier), its threaded batches and
//! the timely-dataflow workers (`streamcert-timely`), so that every path composes the same
//! snapshots the same way.

use serde::{Deserialize, Serialize};
use streamcert_certificate::{CertificateKind, Certifier, Verdict};
use streamcert_compose::{Network, SparseOptions, certify_sparse, network_rate};

use crate::report::ComposeMethod;
use crate::{EpochReport, NetworkConfig, NetworkError, NotCertifiedLocal, perron_sensitivity};

/// What the composition knows of one subsystem: its newest sample time, its composing
/// verdict and the current upper bounds of its estimated couplings (in the order of its
/// [`CouplingConfig`](streamcert_certificate::CouplingConfig) blocks).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalSnapshot {
    /// Time of the newest sample.
    pub t: f64,
    /// The composing certificate's verdict after it.
    pub verdict: Verdict,
    /// `γ̄` per coupling block (`None`: no bound yet).
    #[serde(default)]
    pub couplings: Vec<Option<f64>>,
}

impl LocalSnapshot {
    /// Overwrite with `certifier`'s state after a sample at `t` whose verdict is `verdict`
    /// (no allocation once the coupling list has its length).
    pub fn update(&mut self, t: f64, verdict: Verdict, certifier: &Certifier) {
        self.t = t;
        self.verdict = verdict;
        self.couplings.clear();
        self.couplings.extend(certifier.coupling_bounds().iter().map(|b| b.map(|b| b.upper)));
    }

    /// A snapshot of `certifier` after a sample at `t`, for certificate `kind`.
    #[must_use]
    pub fn new(t: f64, verdict: Verdict, certifier: &Certifier) -> Self {
        let mut s = Self { t, verdict, couplings: Vec::new() };
        s.update(t, verdict, certifier);
        s
    }

    /// `true` when every stored number is finite and the verdict is consistent.
    #[must_use]
    pub fn is_valid(&self) -> bool {
        let finite = |v: Option<f64>| v.is_none_or(f64::is_finite);
        self.t.is_finite()
            && finite(self.verdict.value)
            && finite(self.verdict.radius)
            && self.verdict.open == self.verdict.reason.is_none()
            && self.couplings.iter().all(|&g| g.is_none_or(|g| g.is_finite() && g >= 0.0))
    }
}

/// Record `certifier`'s verdict of kind `kind` after a sample at `t` in `slot`.
pub(crate) fn record(
    slot: &mut Option<LocalSnapshot>,
    t: f64,
    kind: CertificateKind,
    certifier: &Certifier,
    verdict: &streamcert_certificate::Evidence,
) {
    let v = *verdict.verdict(kind);
    match slot {
        Some(s) => s.update(t, v, certifier),
        None => *slot = Some(LocalSnapshot::new(t, v, certifier)),
    }
}

/// The epoch clock and the network gate. Feed it the time of every sample in arrival order
/// ([`due`](Self::due)); compose each due epoch from the snapshots as they were *before* that
/// sample ([`compose`](Self::compose)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Composer {
    /// Index `k` of the next epoch to compose (at `k · epoch`); `None` before any sample.
    next: Option<u64>,
    streak: usize,
}

impl Default for Composer {
    fn default() -> Self {
        Self::new()
    }
}

impl Composer {
    /// Before any sample.
    #[must_use]
    pub fn new() -> Self {
        Self { next: None, streak: 0 }
    }

    /// The epochs `k` with `k · epoch <= t` not composed yet, as `first..end` (empty when
    /// none); marks them as composed. The first sample's epochs start after it (a network
    /// is not composed before it has data).
    ///
    /// # Errors
    /// [`NetworkError::TimeJump`] when more than `max_epoch_jump` epochs would be due (the
    /// clock is then unchanged).
    pub fn due(
        &mut self,
        cfg: &NetworkConfig,
        t: f64,
    ) -> Result<std::ops::Range<u64>, NetworkError> {
        if !t.is_finite() {
            let k = self.next.unwrap_or(0);
            return Ok(k..k);
        }
        let epoch = cfg.epoch;
        let first = (t / epoch).floor().max(0.0) + 1.0;
        let k = match self.next {
            Some(k) => k,
            None if first < u64::MAX as f64 => first as u64,
            None => return Err(NetworkError::TimeJump { t, epochs: first, max: 0 }),
        };
        let epochs = (t / epoch).floor() - k as f64 + 1.0;
        if epochs > cfg.max_epoch_jump as f64 {
            return Err(NetworkError::TimeJump { t, epochs, max: cfg.max_epoch_jump });
        }
        let mut end = k;
        while end as f64 * epoch <= t {
            end += 1;
        }
        self.next = Some(end);
        Ok(k..end)
    }

    /// The next epoch to compose, once a sample has arrived.
    #[must_use]
    pub fn next_epoch(&self) -> Option<u64> {
        self.next
    }

    /// Compose epoch `k` from every subsystem's newest snapshot (`snapshots[i]`, `None` before
    /// its first sample) and update the network gate.
    ///
    /// # Errors
    /// [`NetworkError::Compose`].
    pub fn compose(
        &mut self,
        cfg: &NetworkConfig,
        k: u64,
        snapshots: &[Option<LocalSnapshot>],
    ) -> Result<EpochReport, NetworkError> {
        let at = k as f64 * cfg.epoch;
        let n = snapshots.len();
        let mut local = Vec::with_capacity(n);
        let mut not_certified = Vec::new();
        for (i, last) in snapshots.iter().enumerate() {
            let value = match last {
                None => {
                    not_certified.push((i, NotCertifiedLocal::NoSample));
                    None
                }
                Some(l) if at - l.t > cfg.stale_after => {
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
        // Estimated couplings: the subsystem's current upper bound, or not certified.
        let mut couplings = cfg.couplings.clone();
        let mut estimated = Vec::with_capacity(cfg.estimated.len());
        for e in &cfg.estimated {
            let bound = snapshots[e.to].as_ref().and_then(|s| s.couplings.get(e.block).copied());
            estimated.push(bound.flatten());
            match bound.flatten() {
                Some(g) => couplings.push((e.to, e.from, g)),
                None => {
                    let why = NotCertifiedLocal::CouplingUnbounded { from: e.from };
                    if !not_certified.iter().any(|&(i, _)| i == e.to) {
                        not_certified.push((e.to, why));
                    }
                }
            }
        }
        not_certified.sort_by_key(|&(i, _)| i);
        let mut report = EpochReport {
            t: at,
            epoch: k,
            local,
            estimated,
            rate: None,
            method: None,
            certified: false,
            open: false,
            critical_scale: None,
            participation: Vec::new(),
            sensitivity_converged: false,
            limiting_subsystem: None,
            limiting_coupling: None,
            not_certified,
        };
        let all_bounded = couplings.len() == cfg.couplings.len() + cfg.estimated.len();
        if let (Some(beta), true) =
            (report.local.iter().copied().collect::<Option<Vec<f64>>>(), all_bounded)
        {
            let net = Network::new(beta, &couplings)?;
            let (rate, scale, method) = if n <= cfg.dense_limit {
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
            report.participation = s.participation;
            report.sensitivity_converged = s.converged;
            report.certified = report.not_certified.is_empty() && rate >= cfg.margin;
        }
        self.streak = if report.certified { self.streak + 1 } else { 0 };
        report.open = self.streak >= cfg.consecutive;
        Ok(report)
    }
}
