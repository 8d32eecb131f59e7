//! # streamcert-certificate
//!
//! The streaming contraction certificate of the paper (Section II-B) for one subsystem with
//! `p` outputs, `m` inputs and a candidate output-feedback gain `K` (`m × p`):
//!
//! ```text
//! J_cl = J_obs + B_obs K                                         (Section II-B)
//! β̂   = −λ_max(½ (J_cl + J_clᵀ))                                 (eq. betahat)
//! ρ    = c (1 + ‖K‖₂) RMS(R) / √(λ_min(Z Zᵀ / M) + λ)             (eq. rho)
//! β_cert = β̂ − ρ                                                 (Gaussian certificate)
//! ```
//!
//! and the deployment gate: the controller may be deployed once `β_cert >= β_margin` for `n_s`
//! consecutive samples ([`Gate`]).
//!
//! [`Certifier`] takes one sample at a time and returns the full [`Evidence`]: `β̂`, `ρ`, the
//! certificate, the gate, and the reason whenever it does not certify. It never certifies from
//! a window with a bad value (bad samples are rejected before they enter the window), from a
//! window still warming up, or from a regression without excitation.
//!
//! With an ambiguity model configured ([`CertifierConfig::ambiguity`]), the same certifier also
//! reports the Wasserstein certificate of Section III-B, with its own gate:
//!
//! ```text
//! β_cert(t, ε) = β̂ − ρ (1 + 2ε(t))                              (eq. wass_cert)
//! ```
//!
//! Since `ρ >= 0` and `ε >= 0`, the Wasserstein certificate is never above the Gaussian one and
//! equals it at `ε = 0`. The paper's Table II reports the Wasserstein certificate valid *more*
//! often than the Gaussian one; the formulas as written cannot produce that, and the
//! experiments report it as a discrepancy.
//!
//! The radius `ρ` is the paper's heuristic with a tuned constant `c`, not a confidence bound.
//! The calibrated certificate ([`CertifierConfig::calibration`], [`Calibration`]) is one, over
//! the whole run; the nonlinear certificate ([`CertifierConfig::nonlinear`]) bounds the rate
//! over the explored region; and with [`CertifierConfig::couplings`] the same calibrated
//! windows give upper confidence bounds on the gains of input channels that are neighbours'
//! outputs ([`CouplingConfig`], [`Certifier::coupling_bounds`]), for network composition
//! without given gains.
//!
//! Which residuals feed `ε` is not said by the paper ([`ResidualSource`]). The default is the
//! one-step residual: the `h`-step column residual is a sum of `h` per-step noise increments,
//! whose excess kurtosis is `1/h` of the per-step one (`0.6` instead of `3` for Laplace noise at
//! `h = 5`) and in which a spike is diluted by the other `h − 1` steps; the one-step residual
//! keeps the tail shape that `ε` is meant to detect. With `p > 1` outputs each output has its
//! own estimator and `ε` is the largest of their radii.
//!
//! The entry point is [`CertifierConfig::guarded`]: the calibrated certificate with its
//! guards, the verdict with a stated risk (what `streamcert certify` runs by default);
//! [`CertifierConfig::new`] is the paper's certificates alone.
//!
//! ```
//! use streamcert_certificate::{Certifier, CertifierConfig, NotCertified};
//! use streamcert_regression::{InputIntegral, RegressionConfig};
//! let reg = RegressionConfig {
//!     input_integral: InputIntegral::ZeroOrderHold,
//!     ..RegressionConfig::new(1, 1, 150, 5, 1e-4)
//! };
//! let mut cert = Certifier::new(CertifierConfig::guarded(reg, vec![-1.0], 0.05, 10))?;
//! let ev = cert.push(0.0, &[0.0], &[0.0])?;
//! // The verdict to deploy on: closed, with its reason, until the data prove the rate.
//! assert!(!ev.calibrated.open);
//! assert!(matches!(ev.calibrated.reason, Some(NotCertified::WarmingUp { .. })));
//! # Ok::<(), streamcert_certificate::CertifyError>(())
//! ```

mod calibrated;
mod certifier;
mod clock;
mod config;
mod error;
mod evidence;
mod fixed;
mod gap;
mod gate;
mod guard;
mod ladder;
mod look;
pub mod nonlinear;
mod order_n;
mod radius;
mod rate;
mod row;

pub use calibrated::{
    Calibration, CouplingBlock, CouplingBound, CouplingConfig, GuardVariance, RiskSplit,
    WindowLook, anchored_look_risk, calibrated_radius, look_risk, rank_one_variance_bound,
    t_quantile,
};
#[cfg(feature = "checkpoint")]
pub use certifier::checkpoint::{
    CHECKPOINT_JSON_VERSION, CHECKPOINT_MAGIC, CHECKPOINT_PACKED_VERSION,
    CHECKPOINT_UNPACKED_VERSION, CHECKPOINT_VERSION, Encoding, Sealed, config_fingerprint, decode,
    encode, fnv1a64, seal, seal_value, unseal,
};
pub use certifier::{Certifier, RungStatus};
pub use clock::{SampleTime, UNIX_SECONDS, iso8601_utc};
pub use config::{BadSamplePolicy, CertifierConfig};
pub use error::CertifyError;
pub use evidence::{AmbiguityLevel, CertificateKind, Evidence, Fit, NotCertified, Verdict};
pub use fixed::{Sig, SigRange};
pub use gate::{Gate, GateState};
pub use ladder::{HorizonLadder, OrderLadder};
pub use nonlinear::{
    Feature, FeatureSet, NonlinearConfig, NonlinearLook, NonlinearityTest, RegionBound,
};
pub use order_n::{OrderNCertificate, OrderNCertificateConfig, OrderNLook, OrderNRegion};
pub use radius::{certificate_surface, certificate_value};
pub use rate::order_n::{Ellipsoid, robust_margin, robustly_stable, robustly_stable_rational};
pub use row::{
    ColumnKind, EVIDENCE_COLUMN_KINDS, EVIDENCE_COLUMNS, EvidenceRow, NUMBER_COLUMNS, ReasonText,
    WINDOW_COLUMNS,
};
pub use streamcert_regression::Interval;
pub use streamcert_regression::ResidualSource;

/// The module layering ARCHITECTURE.md states, checked on the source: `look` depends on no
/// certificate, the guards only on `look` (never on the calibrated or nonlinear certificate),
/// the nonlinear certificate not on the calibrated one (which owns it), and `rate` on no
/// certificate; by path or by a name the crate's root re-exports.
#[cfg(test)]
mod layering {
    /// The code lines of `source` (doc and line comments dropped) that name `module`.
    fn uses(source: &str, module: &str) -> Vec<String> {
        source
            .lines()
            .map(str::trim)
            .filter(|l| !l.starts_with("//"))
            .filter(|l| l.contains(&format!("crate::{module}")))
            .map(String::from)
            .collect()
    }

    /// The names `source` takes from the crate's root (`use crate::Name;`,
    /// `use crate::{A, B};`), each item's last segment.
    fn root_names(source: &str) -> Vec<String> {
        let code: String = source
            .lines()
            .map(str::trim)
            .filter(|l| !l.starts_with("//"))
            .collect::<Vec<_>>()
            .join(" ");
        let mut names = Vec::new();
        for stmt in code.split("use crate::").skip(1) {
            let stmt = stmt.split(';').next().unwrap_or("");
            let items = stmt.strip_prefix('{').and_then(|s| s.strip_suffix('}'));
            match items {
                Some(items) => names.extend(
                    items
                        .split(',')
                        .map(|i| i.trim().rsplit("::").next().unwrap_or("").to_string())
                        .filter(|i| !i.is_empty() && i != "self" && !i.contains('{')),
                ),
                None if !stmt.contains("::") => names.push(stmt.trim().to_string()),
                None => {}
            }
        }
        names
    }

    /// Whether one of `sources` defines `name` (a public enum, struct, function, constant,
    /// type or trait).
    fn defines(sources: &[&str], name: &str) -> bool {
        ["enum", "struct", "fn", "const", "type", "trait"].iter().any(|kind| {
            sources.iter().any(|s| {
                s.contains(&format!("pub {kind} {name}"))
                    || s.contains(&format!("pub(crate) {kind} {name}"))
            })
        })
    }

    #[test]
    fn each_module_uses_only_the_modules_beneath_it() {
        let look = [
            include_str!("look.rs"),
            include_str!("look/guard_variance.rs"),
            include_str!("look/hotelling.rs"),
            include_str!("look/larger.rs"),
            include_str!("look/quantile.rs"),
            include_str!("look/split.rs"),
            include_str!("look/standing.rs"),
        ];
        let guards = [
            include_str!("guard/change.rs"),
            include_str!("guard/curvature.rs"),
            include_str!("guard/model.rs"),
        ];
        let nonlinear = [
            include_str!("nonlinear.rs"),
            include_str!("nonlinear/bounds.rs"),
            include_str!("nonlinear/cells.rs"),
            include_str!("nonlinear/check.rs"),
            include_str!("nonlinear/config.rs"),
            include_str!("nonlinear/features.rs"),
        ];
        let rate = [include_str!("rate.rs"), include_str!("rate/first_order.rs")];
        let calibrated = [
            include_str!("calibrated.rs"),
            include_str!("calibrated/access.rs"),
            include_str!("calibrated/anchor.rs"),
            include_str!("calibrated/build.rs"),
            include_str!("calibrated/check.rs"),
            include_str!("calibrated/config.rs"),
            include_str!("calibrated/coupling.rs"),
            include_str!("calibrated/look.rs"),
            include_str!("calibrated/options.rs"),
            include_str!("calibrated/replay.rs"),
            include_str!("calibrated/trail.rs"),
            include_str!("calibrated/update.rs"),
            include_str!("calibrated/validate.rs"),
            include_str!("calibrated/window_look.rs"),
        ];
        for source in look {
            for module in ["calibrated", "nonlinear", "guard", "certifier", "rate"] {
                assert_eq!(uses(source, module), Vec::<String>::new(), "look uses {module}");
            }
        }
        for source in guards {
            for module in ["calibrated", "nonlinear", "certifier", "rate"] {
                assert_eq!(uses(source, module), Vec::<String>::new(), "a guard uses {module}");
            }
        }
        for source in nonlinear {
            for module in ["calibrated", "guard", "certifier", "rate"] {
                assert_eq!(uses(source, module), Vec::<String>::new(), "nonlinear uses {module}");
            }
        }
        for source in rate {
            for module in ["calibrated", "nonlinear", "guard", "certifier"] {
                assert_eq!(uses(source, module), Vec::<String>::new(), "rate uses {module}");
            }
        }
        // Nor through the crate's root: no name these modules take from it is defined in
        // the calibrated certificate.
        for source in look.iter().chain(&guards).chain(&nonlinear).chain(&rate) {
            for name in root_names(source) {
                assert!(!defines(&calibrated, &name), "`{name}` is the calibrated certificate's");
            }
        }
        assert_eq!(
            root_names("use crate::{a::B, C};\nuse crate::D;\nuse crate::e::F;"),
            ["B", "C", "D"]
        );
        assert!(defines(&calibrated, "Calibration"));
        // The check sees a use where there is one.
        assert_eq!(uses("use crate::calibrated::X;\n// crate::calibrated", "calibrated").len(), 1);
    }
}
