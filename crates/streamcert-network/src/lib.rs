//! # streamcert-network
//!
//! Certify a network of subsystems live, without a joint model: one streaming
//! [`Certifier`](streamcert_certificate::Certifier) per subsystem, each fed its own samples
//! with its own timestamps, and at every epoch the current local certificates composed with the
//! coupling bounds into a network certificate (paper Section IV, extended to `N` subsystems and
//! asymmetric coupling by `streamcert-compose`):
//!
//! ```text
//! Γ = −diag(β_cert,i) + Γ_off,  (Γ_off)_ij = γ_ij  (how subsystem j drives subsystem i)
//! β_net = −α(Γ)             (dense, N <= dense_limit: `network_rate`)
//!       >= min_i −(Γ x)_i / x_i  (sparse: the Collatz–Wielandt certificate `certify_sparse`)
//! ```
//!
//! The network is certified at an epoch when every subsystem's local gate is open (with a
//! sample no older than `stale_after`) and `β_net >= margin`; the network gate opens after
//! `consecutive` certified epochs. Each epoch's [`EpochReport`] names the subsystems that are
//! not certified and why, the Perron weights (participation `w_i v_i / (wᵀv)` with the left
//! and right Perron vectors), the subsystem and the coupling that limit the rate (largest
//! sensitivity of `α(Γ)`: participation, and `γ_ij w_i v_j`), and the critical coupling scale
//! (how much every coupling may grow before contraction is lost).
//!
//! **Couplings, given or measured.** `couplings` are given bounds; [`EstimatedCoupling`]s are
//! measured: the driven subsystem's regression takes the driving outputs as inputs (a zero row
//! of its gain, a [`CouplingConfig`](streamcert_certificate::CouplingConfig) block) and the
//! composition uses the block's calibrated upper bound `γ̄` (a subsystem whose bound is not
//! there yet is not certified).
//!
//! **Many subsystems.** [`NetworkCertifier::push_batch`] takes a [`SampleBatch`] and shards
//! the subsystems over threads between the epochs it makes due, with the reports of pushing
//! the samples one by one (tested); the crate `streamcert-timely` runs the same composition
//! across processes and machines.
//!
//! **Risk over the network.** With the calibrated certificate as the local one,
//! [`NetworkConfig::split_risk`] gives each of the `N` subsystems the risk `δ/N`. By the union
//! bound, the probability that the network is certified while *any* local rate is overstated
//! (some `β_i < β_cert,i`) is at most `δ`; on the complementary event every `β_cert,i` is a
//! lower bound of the true local rate, and the composition is monotone in the local rates
//! (`α(Γ)` of a Metzler matrix does not decrease when a diagonal entry grows), so the network
//! rate is a lower bound of the rate the coupling bounds certify. Given coupling bounds are
//! taken as exact upper bounds; with `E` estimated couplings the split is `δ/(N + E)` per
//! local certificate and per coupling, and the composition is also monotone in each `γ_ij`,
//! so on the event that every bound holds the network rate is a lower bound of the true one.
//!
//! ```
//! use streamcert_certificate::{CertifierConfig, CertificateKind};
//! use streamcert_network::{NetworkCertifier, NetworkConfig, SubsystemSpec};
//! use streamcert_regression::RegressionConfig;
//! let local = |k: f64| CertifierConfig::new(RegressionConfig::new(1, 1, 100, 5, 1e-4), vec![k], 0.2, 0.05, 5);
//! let cfg = NetworkConfig::new(
//!     vec![SubsystemSpec::new("a", local(-2.0)), SubsystemSpec::new("b", local(-3.0))],
//!     vec![(0, 1, 0.3), (1, 0, 0.3)],
//!     1.0,
//! );
//! let mut net = NetworkCertifier::new(cfg)?;
//! let mut reports = Vec::new();
//! net.push(0, 0.0, &[0.0], &[0.0], |r| reports.push(r.clone()))?;
//! net.push(1, 1.5, &[0.0], &[0.0], |r| reports.push(r.clone()))?;
//! // The epoch at t = 1 was composed before the sample at 1.5: nothing is certified yet.
//! assert_eq!(reports.len(), 1);
//! assert!(!reports[0].certified && reports[0].not_certified.len() == 2);
//! # Ok::<(), streamcert_network::NetworkError>(())
//! ```

mod batch;
mod certifier;
mod composer;
mod config;
mod perron;
mod report;

pub use batch::SampleBatch;
pub use certifier::NetworkCertifier;
pub use composer::{Composer, LocalSnapshot};
pub use config::{EstimatedCoupling, NetworkConfig, SubsystemSpec};
pub use perron::{Sensitivity, perron_sensitivity};
pub use report::{EpochReport, NotCertifiedLocal};

/// Errors of this crate.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum NetworkError {
    /// A configuration field is out of range.
    #[error("invalid network configuration: `{field}` {reason}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// What is wrong and what is accepted.
        reason: String,
    },
    /// A subsystem's certifier configuration is invalid or rejected a sample.
    #[error("subsystem {index} (`{name}`): {source}")]
    Subsystem {
        /// Its index.
        index: usize,
        /// Its name.
        name: String,
        /// The certifier's error.
        source: streamcert_certificate::CertifyError,
    },
    /// A sample names a subsystem that does not exist.
    #[error("no subsystem {index} (the network has {len})")]
    UnknownSubsystem {
        /// The index given.
        index: usize,
        /// Number of subsystems.
        len: usize,
    },
    /// A sample's time is so far ahead that composing every epoch up to it would take more
    /// than `max_epoch_jump` epochs (a corrupted time, or an outage longer than the
    /// configuration allows); nothing was changed.
    #[error(
        "time {t} is {epochs} epochs after the last composed epoch (at most {max} per sample: \
         `max_epoch_jump`); restart the network after a long outage"
    )]
    TimeJump {
        /// The sample's time.
        t: f64,
        /// Epochs that would be composed.
        epochs: f64,
        /// The limit.
        max: u64,
    },
    /// Composition failed.
    #[error("composition: {0}")]
    Compose(#[from] streamcert_compose::ComposeError),
}

impl NetworkError {
    /// `Err(InvalidConfig)` for `field`, with what is wrong and what would be valid.
    pub(crate) fn refuse<T>(field: &'static str, reason: String) -> Result<T, Self> {
        Err(Self::InvalidConfig { field, reason })
    }
}
