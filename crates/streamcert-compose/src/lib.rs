//! # streamcert-compose
//!
//! Compose locally certified contraction rates into a network guarantee without a joint model
//! (paper Section IV), and extend the paper's Lemma 1 to asymmetric coupling and to `N`
//! subsystems.
//!
//! * [`lemma1_rate`]: `β_net = (β_A + β_B)/2 − √((β_A − β_B)²/4 + γ²)` (eq. beta_net), positive
//!   iff `γ < γ_warn = √(β_A β_B)` ([`warning_gain`]).
//! * [`two_block_rate`]: with `γ_AB` bounding how B drives A and `γ_BA` how A drives B,
//!   `β_net = (β_A + β_B)/2 − √((β_A − β_B)²/4 + γ_AB γ_BA)`, positive iff
//!   `γ_AB γ_BA < β_A β_B`; a cascade (one gain zero) contracts whenever both blocks do.
//! * [`network_rate`] (dense): the gain matrix `Γ` with `−β_i` on the diagonal and the
//!   coupling bounds `γ_ij >= 0` off it is Metzler; the network contracts iff `Γ` is Hurwitz,
//!   at rate `−α(Γ)` (spectral abscissa), attained by the weighted Euclidean norm
//!   `‖x‖² = Σ η_i x_i²` with `η_i = w_i / v_i` from the left and right Perron vectors
//!   (Davydov, Jafarpour and Bullo, "Non-Euclidean Contraction Theory for Robust Nonlinear
//!   Stability", IEEE TAC 2022; Bullo, "Contraction Theory for Dynamical Systems", 2023).
//!   It also returns the symmetric (unweighted) bound `λ_min(diag β − sym Γ_off)` and the
//!   critical coupling scale `s* = 1/ρ(D⁻¹ Γ_off)`, `D = diag β`: the largest `s` with
//!   `diag(−β) + s Γ_off` Hurwitz, which generalises `γ_warn`. Every one of these is the
//!   Perron root of a nonnegative matrix, computed as a Collatz–Wielandt bracket along a power
//!   iteration (`O(N + edges)` a step) whose safe end is reported (8.3 ms at `N = 1000`,
//!   against 1.3 s for the eigendecomposition, BENCHMARKS.md); [`network_rate_with`] with
//!   [`DenseOptions`] takes the eigendecomposition (`O(N³)`) on request, and falls back to it
//!   where a bracket does not close and `N <= eigen_limit`.
//! * [`certify_sparse`] (large sparse networks): certificates instead of eigenvalues. Any
//!   `x > 0` gives the certified rate `min_i −(Γ x)_i / x_i` (Collatz–Wielandt); power
//!   iteration on the nonnegative `Γ + cI` finds good `x` in a few sparse products. The
//!   symmetric bound "rate at least `μ`" is a successful sparse Cholesky factorisation of
//!   `diag β − sym Γ_off − μ I` (faer), bisected over `μ`.
//!
//! Why the weighted rate is never below the symmetric one: for the Metzler `Γ`,
//! `−α(Γ) = max over positive diagonal weights of the weighted log-norm rate`, and the
//! unweighted symmetric bound is that rate for unit weights.
//!
//! ```
//! use streamcert_compose::{lemma1_rate, network_rate, warning_gain, Network};
//! let (a, b, g) = (0.8, 1.2, 0.5);
//! let net = Network::from_dense(&[a, b], &[0.0, g, g, 0.0])?;
//! let cert = network_rate(&net)?;
//! assert!((cert.rate - lemma1_rate(a, b, g)?).abs() < 1e-12);
//! assert!((cert.critical_scale * g - warning_gain(a, b)?).abs() < 1e-12);
//! # Ok::<(), streamcert_compose::ComposeError>(())
//! ```

mod dense;
mod network;
mod sparse;

pub use dense::{DenseMethod, DenseOptions, NetworkCertificate, network_rate, network_rate_with};
pub use network::Network;
pub use sparse::{
    Method, SparseCertificate, SparseOptions, certify_sparse, metzler_rate, symmetric_rate_at_least,
};

/// Errors of this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ComposeError {
    /// A rate or gain is NaN or infinite.
    #[error("`{name}` must be finite, got {value}")]
    NonFinite {
        /// Which quantity.
        name: &'static str,
        /// Offending value.
        value: f64,
    },
    /// A coupling gain is negative (gains are bounds on magnitudes).
    #[error("coupling gain `{name}` must be >= 0, got {value}")]
    NegativeGain {
        /// Which gain.
        name: &'static str,
        /// Offending value.
        value: f64,
    },
    /// A local rate that must be positive (Lemma 1, the warning gain) is not.
    #[error("local rate `{name}` must be > 0 for this formula, got {value}")]
    NonPositiveRate {
        /// Which rate.
        name: &'static str,
        /// Offending value.
        value: f64,
    },
    /// Sizes do not match.
    #[error("`{name}` has {got} entries, expected {expected}")]
    DimensionMismatch {
        /// What was mis-sized.
        name: &'static str,
        /// Expected.
        expected: usize,
        /// Given.
        got: usize,
    },
    /// An edge index is out of range or a self-loop.
    #[error("edge ({i}, {j}) is invalid for {n} subsystems (indices must be < n and distinct)")]
    InvalidEdge {
        /// Receiving subsystem.
        i: usize,
        /// Driving subsystem.
        j: usize,
        /// Number of subsystems.
        n: usize,
    },
    /// A network without subsystems.
    #[error("a network needs at least one subsystem")]
    Empty,
    /// A linear-algebra routine failed (eigen solver did not converge, out of memory).
    #[error("numerical failure: {0}")]
    Numerical(String),
}

fn finite(name: &'static str, value: f64) -> Result<f64, ComposeError> {
    if value.is_finite() { Ok(value) } else { Err(ComposeError::NonFinite { name, value }) }
}

fn positive_rate(name: &'static str, value: f64) -> Result<f64, ComposeError> {
    finite(name, value)?;
    if value > 0.0 { Ok(value) } else { Err(ComposeError::NonPositiveRate { name, value }) }
}

fn gain(name: &'static str, value: f64) -> Result<f64, ComposeError> {
    finite(name, value)?;
    if value >= 0.0 { Ok(value) } else { Err(ComposeError::NegativeGain { name, value }) }
}

/// Lemma 1 (eq. beta_net): `β_net = (β_A + β_B)/2 − √((β_A − β_B)²/4 + γ²)`.
///
/// # Errors
/// [`ComposeError::NonPositiveRate`] when a local rate is not positive (the lemma assumes
/// `β_A, β_B > 0`), [`ComposeError::NegativeGain`] or [`ComposeError::NonFinite`].
pub fn lemma1_rate(beta_a: f64, beta_b: f64, gamma: f64) -> Result<f64, ComposeError> {
    two_block_rate(beta_a, beta_b, gamma, gamma)
}

/// The warning gain `γ_warn = √(β_A β_B)`: Lemma 1's rate is positive iff `γ < γ_warn`.
///
/// # Errors
/// [`ComposeError::NonPositiveRate`] or [`ComposeError::NonFinite`].
pub fn warning_gain(beta_a: f64, beta_b: f64) -> Result<f64, ComposeError> {
    Ok((positive_rate("beta_a", beta_a)? * positive_rate("beta_b", beta_b)?).sqrt())
}

/// Asymmetric two blocks: `β_net = (β_A + β_B)/2 − √((β_A − β_B)²/4 + γ_AB γ_BA)`, the
/// spectral-abscissa rate of `[[−β_A, γ_AB], [γ_BA, −β_B]]`. Positive iff
/// `γ_AB γ_BA < β_A β_B`. With `γ_AB γ_BA = 0` (a cascade) it is `min(β_A, β_B)`.
///
/// # Errors
/// As [`lemma1_rate`].
pub fn two_block_rate(
    beta_a: f64,
    beta_b: f64,
    gamma_ab: f64,
    gamma_ba: f64,
) -> Result<f64, ComposeError> {
    let (a, b) = (positive_rate("beta_a", beta_a)?, positive_rate("beta_b", beta_b)?);
    let p = gain("gamma_ab", gamma_ab)? * gain("gamma_ba", gamma_ba)?;
    let half_gap = 0.5 * (a - b);
    Ok(0.5 * (a + b) - (half_gap * half_gap + p).sqrt())
}
