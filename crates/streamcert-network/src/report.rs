//! [`EpochReport`]: what the network service says at one epoch.

use serde::{Deserialize, Serialize};
use streamcert_certificate::{NotCertified, SampleTime};

/// Why a subsystem does not count as certified at an epoch.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "why", rename_all = "snake_case")]
pub enum NotCertifiedLocal {
    /// No sample yet.
    NoSample,
    /// The newest sample is older than `stale_after` (fail safe: a silent sensor certifies
    /// nothing).
    Stale {
        /// Time of the newest sample.
        last: f64,
    },
    /// The local gate is closed, for this reason.
    Local(NotCertified),
    /// An estimated coupling into this subsystem has no upper bound yet.
    CouplingUnbounded {
        /// The driving subsystem.
        from: usize,
    },
}

impl std::fmt::Display for NotCertifiedLocal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NoSample => f.write_str("no sample yet"),
            Self::Stale { last } if SampleTime::is_unix(*last) => {
                write!(f, "stale: last sample at {}", SampleTime::new(*last, None))
            }
            Self::Stale { last } => {
                write!(f, "stale: last sample at t = {}", SampleTime::new(*last, None))
            }
            Self::Local(r) => write!(f, "{r}"),
            Self::CouplingUnbounded { from } => {
                write!(f, "the coupling from subsystem {from} has no upper bound yet")
            }
        }
    }
}

/// How the network rate was computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ComposeMethod {
    /// The dense composition (`network_rate`, `N <= dense_limit`): the safe end of a
    /// `1e-13` bracket on the spectral abscissa, or the eigendecomposition's value.
    Dense,
    /// The Collatz–Wielandt lower bound (`certify_sparse`).
    Sparse,
}

/// The network at one epoch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpochReport {
    /// Epoch time `k · epoch`.
    pub t: f64,
    /// Epoch number `k`.
    pub epoch: u64,
    /// Each subsystem's composing certificate `β_cert,i` (`None` without a sample, when stale,
    /// or while it has no certificate value).
    pub local: Vec<Option<f64>>,
    /// The estimated couplings' upper bounds `γ̄` the composition used, one per entry of
    /// [`NetworkConfig::estimated`](crate::NetworkConfig::estimated) (`None` while a coupling
    /// has no bound: the network is then not certified).
    pub estimated: Vec<Option<f64>>,
    /// `β_net` from the local certificates and the coupling bounds, when every subsystem has
    /// a value.
    pub rate: Option<f64>,
    /// How `rate` was computed.
    pub method: Option<ComposeMethod>,
    /// Every local gate open and `rate >= margin`.
    pub certified: bool,
    /// The network gate: certified for `consecutive` epochs in a row.
    pub open: bool,
    /// The largest `s` such that the network with every coupling scaled by `s` still
    /// contracts (`s* = 1/ρ(D⁻¹ Γ_off)`, `D = diag β_cert`; needs every `β_cert,i > 0`).
    pub critical_scale: Option<f64>,
    /// The Perron weights of the composition: each subsystem's participation
    /// `p_i = w_i v_i / (wᵀ v)` (left and right Perron vectors of `Γ`, summing to 1), how much
    /// the network rate gains per unit of its local rate (empty without a network rate).
    pub participation: Vec<f64>,
    /// Whether the Perron-vector iteration behind `participation`, `limiting_subsystem` and
    /// `limiting_coupling` met its tolerance (`1e-12` within 1000 iterations); when it did
    /// not, they come from its last iterate. They describe the rate; the certificate does not
    /// depend on them.
    pub sensitivity_converged: bool,
    /// The subsystem whose local rate the network rate depends on most.
    pub limiting_subsystem: Option<usize>,
    /// The coupling `(i, j)` (j drives i) with the largest share in the network rate.
    pub limiting_coupling: Option<(usize, usize)>,
    /// Subsystems that are not certified, and why.
    pub not_certified: Vec<(usize, NotCertifiedLocal)>,
}
