//! [`NetworkConfig`]: the subsystems, their coupling bounds, the epoch and the network gate.

use serde::{Deserialize, Serialize};
use streamcert_certificate::{Calibration, CertificateKind, CertifierConfig};

use crate::NetworkError;

/// One subsystem: a name and its certifier's configuration (its outputs, inputs, gain `K_i`
/// and every streaming choice).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SubsystemSpec {
    /// Name, for reports.
    pub name: String,
    /// The local certifier.
    pub certifier: CertifierConfig,
}

impl SubsystemSpec {
    /// A named subsystem.
    #[must_use]
    pub fn new(name: &str, certifier: CertifierConfig) -> Self {
        Self { name: name.into(), certifier }
    }
}

/// A coupling whose gain is estimated from the data: subsystem `to`'s regression takes
/// subsystem `from`'s outputs as the input channels of its coupling block `block` (see
/// [`CouplingConfig`](streamcert_certificate::CouplingConfig)), and the composition uses that
/// block's current upper confidence bound `γ̄` as `γ_to,from`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EstimatedCoupling {
    /// The driven subsystem (whose regression holds the block).
    pub to: usize,
    /// The driving subsystem (whose outputs are the block's channels).
    pub from: usize,
    /// The block's index in `to`'s `couplings.blocks`.
    pub block: usize,
}

/// The network's configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkConfig {
    /// The subsystems, indexed from 0.
    pub subsystems: Vec<SubsystemSpec>,
    /// Coupling bounds `(i, j, γ_ij)`: how subsystem `j` drives subsystem `i` (`γ_ij >= 0`).
    pub couplings: Vec<(usize, usize, f64)>,
    /// Couplings whose gains are estimated by the driven subsystem's regression (default
    /// none). The caller feeds the driving subsystem's outputs to the driven one as the
    /// block's input channels.
    #[serde(default)]
    pub estimated: Vec<EstimatedCoupling>,
    /// Epoch period in seconds: the network is composed at `t = k · epoch`.
    pub epoch: f64,
    /// A subsystem whose newest sample is older than this (seconds) at an epoch is not
    /// certified (fail safe). Default: 5 epochs.
    pub stale_after: f64,
    /// Which local certificate composes (default: the calibrated one when every subsystem
    /// has a calibration, the Gaussian one otherwise).
    pub certificate: CertificateKind,
    /// Network margin: certified when `β_net >= margin`. Default 0.
    pub margin: f64,
    /// Consecutive certified epochs before the network gate opens. Default 1.
    pub consecutive: usize,
    /// The most epochs one sample may make the network compose (its time minus the last
    /// composed epoch, in epochs); a later time is refused ([`NetworkError::TimeJump`]).
    /// Default 100 000.
    #[serde(default = "default_max_epoch_jump")]
    pub max_epoch_jump: u64,
    /// Up to this many subsystems the dense composition (`network_rate`: the spectral
    /// abscissa, weights, symmetric bound and critical scale as Perron brackets, the
    /// eigendecomposition where one does not close); beyond it the sparse Collatz–Wielandt
    /// certificate (a certified lower bound, `O(iterations · edges)`). Default 64.
    pub dense_limit: usize,
}

fn default_max_epoch_jump() -> u64 {
    100_000
}

impl NetworkConfig {
    /// Subsystems, couplings and the epoch; every other field at its default.
    #[must_use]
    pub fn new(
        subsystems: Vec<SubsystemSpec>,
        couplings: Vec<(usize, usize, f64)>,
        epoch: f64,
    ) -> Self {
        let calibrated =
            !subsystems.is_empty() && subsystems.iter().all(|s| s.certifier.calibration.is_some());
        Self {
            subsystems,
            couplings,
            estimated: Vec::new(),
            epoch,
            stale_after: 5.0 * epoch,
            certificate: if calibrated {
                CertificateKind::Calibrated
            } else {
                CertificateKind::Gaussian
            },
            margin: 0.0,
            consecutive: 1,
            dense_limit: 64,
            max_epoch_jump: default_max_epoch_jump(),
        }
    }

    /// Spend the run-level risk `δ` over the network: with `N` subsystems and `E` estimated
    /// couplings, every subsystem gets a calibration with risk `δ/(N + E)` (other calibration
    /// settings kept, or the defaults), every subsystem with `E_i` estimated couplings gives
    /// its coupling bounds the risk `E_i δ/(N + E)`, and the calibrated certificate composes.
    /// By the union bound the probability that any local certificate overstates its
    /// subsystem's rate, or any coupling bound understates its gain, during the run is at
    /// most `δ`.
    #[must_use]
    pub fn split_risk(mut self, delta: f64) -> Self {
        let share = delta / (self.subsystems.len() + self.estimated.len()).max(1) as f64;
        for (i, s) in self.subsystems.iter_mut().enumerate() {
            let mut cal = s.certifier.calibration.take().unwrap_or_else(|| Calibration::new(delta));
            cal.delta = share;
            s.certifier.calibration = Some(cal);
            let e = self.estimated.iter().filter(|e| e.to == i).count();
            if let (Some(c), true) = (&mut s.certifier.couplings, e > 0) {
                c.delta = share * e as f64;
            }
        }
        self.certificate = CertificateKind::Calibrated;
        self
    }

    /// The run-level risk the network verdict carries: `Σ_i δ_i + Σ_i δ_{c,i}`, every
    /// subsystem's calibrated risk and its coupling bounds' (by the union bound, the chance
    /// that any local certificate overstates its rate or any estimated coupling bound
    /// understates its gain during the run; [`split_risk`](Self::split_risk)`(δ)` makes it
    /// `δ`). `None` when the network composes the paper's certificates, which carry no stated
    /// risk.
    #[must_use]
    pub fn total_risk(&self) -> Option<f64> {
        (self.certificate == CertificateKind::Calibrated).then(|| {
            self.subsystems
                .iter()
                .map(|s| {
                    let c = &s.certifier;
                    c.calibration.as_ref().map_or(0.0, |cal| cal.delta)
                        + c.couplings.as_ref().map_or(0.0, |k| k.delta)
                })
                .sum()
        })
    }

    /// Check every field (the subsystems' certifiers are checked when built).
    ///
    /// # Errors
    /// [`NetworkError::InvalidConfig`].
    pub fn validate(&self) -> Result<(), NetworkError> {
        let bad = NetworkError::refuse::<()>;
        let n = self.subsystems.len();
        if n == 0 {
            return bad("subsystems", "at least one subsystem is needed".into());
        }
        if !(self.epoch > 0.0 && self.epoch.is_finite()) {
            return bad("epoch", format!("must be finite and > 0 seconds, got {}", self.epoch));
        }
        if !(self.stale_after > 0.0 && self.stale_after.is_finite()) {
            return bad(
                "stale_after",
                format!("must be finite and > 0 seconds, got {}", self.stale_after),
            );
        }
        if !self.margin.is_finite() {
            return bad("margin", format!("must be finite, got {}", self.margin));
        }
        if self.consecutive == 0 {
            return bad("consecutive", "at least 1 epoch".into());
        }
        if self.max_epoch_jump == 0 {
            return bad("max_epoch_jump", "at least 1 epoch".into());
        }
        for &(i, j, g) in &self.couplings {
            if i >= n || j >= n || i == j {
                return bad(
                    "couplings",
                    format!("({i}, {j}): indices must differ and be below {n}"),
                );
            }
            if !(g >= 0.0 && g.is_finite()) {
                return bad("couplings", format!("({i}, {j}): γ must be finite and >= 0, got {g}"));
            }
        }
        self.check_estimated()?;
        if let Some(s) = self.subsystems.iter().find(|s| {
            !s.certifier.regression.order.is_first_order() || s.certifier.orders.is_some()
        }) {
            return bad(
                "subsystems",
                format!(
                    "subsystem `{}` runs order {}: a certificate of order n > 1 bounds the \
                     closed loop's spectral abscissa, not a contraction rate in a metric its \
                     neighbours share, so Lemma 1 does not compose it; set its order = 1 (the \
                     first-order rate composes)",
                    s.name,
                    if s.certifier.orders.is_some() {
                        "\"auto\"".to_string()
                    } else {
                        s.certifier.regression.order.order().to_string()
                    }
                ),
            );
        }
        if self.certificate == CertificateKind::Calibrated
            && let Some(s) = self.subsystems.iter().find(|s| s.certifier.calibration.is_none())
        {
            return bad(
                "certificate",
                format!(
                    "the calibrated certificate composes, but subsystem `{}` has no \
                         calibration (use split_risk, or the Gaussian certificate)",
                    s.name
                ),
            );
        }
        if self.certificate == CertificateKind::Wasserstein
            && let Some(s) = self.subsystems.iter().find(|s| s.certifier.ambiguity.is_none())
        {
            return bad(
                "certificate",
                format!(
                    "the Wasserstein certificate composes, but subsystem `{}` has no \
                         ambiguity model",
                    s.name
                ),
            );
        }
        Ok(())
    }

    /// The estimated couplings: indices in range, a block that exists, none given twice.
    fn check_estimated(&self) -> Result<(), NetworkError> {
        let bad = NetworkError::refuse::<()>;
        let n = self.subsystems.len();
        for e in &self.estimated {
            if e.to >= n || e.from >= n || e.to == e.from {
                return bad(
                    "estimated",
                    format!("({}, {}): indices must differ and be below {n}", e.to, e.from),
                );
            }
            let blocks =
                self.subsystems[e.to].certifier.couplings.as_ref().map_or(0, |c| c.blocks.len());
            if e.block >= blocks {
                return bad(
                    "estimated",
                    format!(
                        "({}, {}): subsystem `{}` has {blocks} coupling blocks, no block {}",
                        e.to, e.from, self.subsystems[e.to].name, e.block
                    ),
                );
            }
            let twice = self.estimated.iter().filter(|f| (f.to, f.from) == (e.to, e.from)).count()
                > 1
                || self.estimated.iter().filter(|f| (f.to, f.block) == (e.to, e.block)).count() > 1
                || self.couplings.iter().any(|&(i, j, _)| (i, j) == (e.to, e.from));
            if twice {
                return bad(
                    "estimated",
                    format!(
                        "({}, {}): a coupling or block is given twice (estimated and given, or \
                         estimated twice)",
                        e.to, e.from
                    ),
                );
            }
        }
        Ok(())
    }
}
