//! What the certifier reports after each sample: [`Evidence`] (a numeric core and one
//! [`Verdict`] per certificate), and [`NotCertified`], why a gate is closed.

use serde::{Deserialize, Serialize};
use streamcert_regression::Interval;

mod text;

/// Why a sample is not certified.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "reason", rename_all = "snake_case")]
pub enum NotCertified {
    /// The window holds fewer columns than required.
    WarmingUp {
        /// Columns in the window.
        columns: usize,
        /// Columns needed.
        needed: usize,
    },
    /// The regression is singular or near-singular (no excitation).
    InsufficientExcitation,
    /// The instrumented regression is singular.
    WeakInstruments,
    /// The certificate is below the margin.
    BelowMargin {
        /// The certificate.
        certificate: f64,
        /// The margin.
        margin: f64,
    },
    /// At or above the margin, but not yet for `n_s` consecutive samples.
    Accumulating {
        /// Consecutive samples so far.
        streak: usize,
        /// Needed.
        needed: usize,
    },
    /// The sample was bad and skipped ([`BadSamplePolicy::Skip`](crate::BadSamplePolicy::Skip)).
    SkippedSample,
    /// No ambiguity model is configured, so there is no Wasserstein certificate.
    NoAmbiguityModel,
    /// No calibration is configured, so there is no calibrated certificate.
    NoCalibration,
    /// The step before this sample is a gap (larger than `gap_factor` times the reference
    /// step): the window was reset, so it is warming up again.
    Gap {
        /// The step.
        dt: f64,
        /// The reference step (median of the last 32).
        reference: f64,
    },
    /// Calibrated certificate: a window whose latest look is at least as recent as every
    /// standing certificate bounds the rate from above below the margin: the newest data
    /// show that the candidate does not contract enough (a loop that never did, or one that
    /// stopped, for example after a plant change). Read as `rate_dropped` too (its name
    /// before 0.1.0's release).
    #[serde(alias = "rate_dropped")]
    RateBelowMargin {
        /// The window length that gives the bound.
        window: usize,
        /// Its upper bound `β̂_w + ρ_w`.
        upper: f64,
    },
    /// Calibrated certificate: a window's nonlinearity test (the nonlinearity guard,
    /// [`Calibration::nonlinearity`](crate::Calibration::nonlinearity), or the nonlinear
    /// certificate's test, see the [`nonlinear`](crate::nonlinear) module) says the dynamics
    /// vary over the region it explored, so the linear model (one Jacobian) does not
    /// describe it.
    VaryingDynamics {
        /// The window length.
        window: usize,
        /// The Wald statistic of the terms of degree `>= 2`.
        statistic: f64,
        /// Its threshold at the test's risk.
        threshold: f64,
    },
    /// Calibrated certificate: the hidden-dynamics guard says the output has dynamics beyond
    /// the order of the model it tested (at the first order, the past increment predicts the
    /// next one, see the [`order`](crate::Calibration::hidden_dynamics) guard; at order `n`,
    /// the past row's regressand predicts what the model leaves,
    /// [`OrderNCertificateConfig::hidden_dynamics`](crate::OrderNCertificateConfig::hidden_dynamics)),
    /// so the window's rate speaks for a model that does not describe the plant. Its words
    /// name the order tried and what would be valid: a model of a higher order, or at the
    /// largest order ([`MAX_ORDER`](streamcert_regression::MAX_ORDER)) the unmeasured states
    /// logged as outputs.
    HiddenDynamics {
        /// The window length.
        window: usize,
        /// The Wald statistic of the past increment's (the past row's) coefficients.
        statistic: f64,
        /// Its threshold at the guard's risk.
        threshold: f64,
        /// The order of the model the guard tested: 1 for the first-order model (and when
        /// absent from a serialised reason), `n` for the certificate of order `n`.
        #[serde(default = "first_order")]
        order: usize,
    },
    /// Calibrated certificate: the hidden-dynamics guard's larger fit has no estimate for the
    /// window yet (too few columns, or a singular fit), so the model order is not checked and
    /// the window's certificate does not stand.
    OrderUntested {
        /// The window length.
        window: usize,
    },
    /// Calibrated certificate: the window's nonlinearity test (the guard's larger fit, or the
    /// nonlinear certificate's feature fit) has no estimate yet (too few columns, or a
    /// singular fit), so the linear model is not checked and the window's linear certificate
    /// does not stand.
    LinearityUntested {
        /// The window length.
        window: usize,
    },
    /// Calibrated certificate: the change guard
    /// ([`Calibration::plant_change`](crate::Calibration::plant_change)) found the newest
    /// data's rate significantly below the window's latest look (the plant changed since),
    /// so that look does not stand.
    PlantChanged {
        /// The window length of the look.
        window: usize,
        /// The look's `β̂_w`.
        beta_hat: f64,
        /// The newest data's one-sided upper bound `β̂_f + t √(s_f² + s_w²)`, below it.
        newest_upper: f64,
    },
    /// No nonlinear model is configured, so there is no nonlinear certificate.
    NoNonlinearModel,
    /// Nonlinear certificate: the window's lack-of-fit check says the drift is not in the
    /// span of the feature library (terms the library lacks are significant), so the
    /// certificate's model does not hold (see [`NonlinearConfig::check_terms`]).
    ///
    /// [`NonlinearConfig::check_terms`]: crate::NonlinearConfig::check_terms
    LibraryMisfit {
        /// The window length.
        window: usize,
        /// The Wald statistic of the extra terms.
        statistic: f64,
        /// Its threshold at the test's risk.
        threshold: f64,
    },
    /// Nonlinear certificate: the window's lack-of-fit check has no estimate yet (too few
    /// columns for the larger fit, or a singular one), so the library is not checked and the
    /// window's certificate does not stand.
    LibraryUntested {
        /// The window length.
        window: usize,
    },
    /// Calibrated certificate: no window's data identify the candidate's closed-loop rate.
    /// Either a regressor never moved beyond the intercept in the window (an input held over
    /// the whole window is a multiple of the intercept's `τ`: the fit is singular), one block
    /// alone identifies a direction of the coefficients (deleting it leaves the fit
    /// singular), or the blocks that carry the information in the candidate's direction are
    /// too few for a bound (`moves` at most the unknowns per output).
    WeaklyIdentified {
        /// The window length (the longest window that looked).
        window: usize,
        /// The effective number of blocks of `h` columns that carry the information on the
        /// rate in the candidate's direction (`(Σ_j w_j)² / Σ_j w_j²` over the window's
        /// delete-one-block weights; 0 where the fit is singular): for a step test, about
        /// the number of the input's moves the window holds times the blocks each move's
        /// transient spans.
        moves: f64,
    },
    /// Calibrated certificate: as [`WeaklyIdentified`](Self::WeaklyIdentified) with a
    /// singular fit, where the cause is the controller: every regressor moved beyond its
    /// level, but the inputs are a fixed linear function of the outputs over the window (a
    /// closed loop logged with `u = K y` and nothing added). The data cannot separate the
    /// plant from the controller, whatever their length: the input needs a part the outputs
    /// do not explain, a dither.
    InputFollowsOutputs {
        /// The window length (the longest window that looked).
        window: usize,
    },
    /// Nonlinear certificate: the output lies outside the standing look's region, the only
    /// states that certificate speaks for (its region is trimmed to quantiles of the visited
    /// outputs, [`NonlinearConfig::region_trim`]), so the gate stays closed until it returns.
    ///
    /// [`NonlinearConfig::region_trim`]: crate::NonlinearConfig::region_trim
    OutsideRegion {
        /// The output, in the certificate's units.
        y: f64,
        /// The region's lower end.
        lo: f64,
        /// The region's upper end.
        hi: f64,
    },
    /// The paper's Gaussian and Wasserstein certificates are of the first-order model: at
    /// `[regression] order = 2 | 3` they are not computed, and the calibrated column carries
    /// the certificate of order `n` ([`OrderNCertificate`](crate::OrderNCertificate)).
    FirstOrderOnly,
}

/// The order of a reason serialised before the order was recorded: the first.
fn first_order() -> usize {
    1
}

impl NotCertified {
    /// The bits of a reason's numbers: `==` treats `0.0` and `-0.0` as equal, their texts differ.
    /// The match lists every variant, so a new one with numbers must be added here.
    fn number_bits(&self) -> [u64; 3] {
        use NotCertified as N;
        match *self {
            N::BelowMargin { certificate, margin } => [certificate.to_bits(), margin.to_bits(), 0],
            N::Gap { dt, reference } => [dt.to_bits(), reference.to_bits(), 0],
            N::RateBelowMargin { upper, .. } => [upper.to_bits(), 0, 0],
            N::PlantChanged { beta_hat, newest_upper, .. } => {
                [beta_hat.to_bits(), newest_upper.to_bits(), 0]
            }
            N::WeaklyIdentified { moves, .. } => [moves.to_bits(), 0, 0],
            N::OutsideRegion { y, lo, hi } => [y.to_bits(), lo.to_bits(), hi.to_bits()],
            N::VaryingDynamics { statistic, threshold, .. }
            | N::HiddenDynamics { statistic, threshold, .. }
            | N::LibraryMisfit { statistic, threshold, .. } => {
                [statistic.to_bits(), threshold.to_bits(), 0]
            }
            N::WarmingUp { .. }
            | N::InsufficientExcitation
            | N::WeakInstruments
            | N::Accumulating { .. }
            | N::SkippedSample
            | N::NoAmbiguityModel
            | N::NoCalibration
            | N::LinearityUntested { .. }
            | N::OrderUntested { .. }
            | N::LibraryUntested { .. }
            | N::InputFollowsOutputs { .. }
            | N::FirstOrderOnly
            | N::NoNonlinearModel => [0; 3],
        }
    }

    /// Whether two reasons have the same text: equal, with their numbers equal bit for bit
    /// (`==` takes `0.0` and `-0.0` as equal, their texts differ). What a writer that reuses
    /// a column's text while its reason is unchanged compares.
    #[must_use]
    pub fn identical(&self, other: &Self) -> bool {
        self == other && self.number_bits() == other.number_bits()
    }

    /// Every reason's name (the `reason` tag of its serde form) in the order of
    /// [`code`](Self::code), from code 1.
    pub const KINDS: [&'static str; 22] = [
        "warming_up",
        "insufficient_excitation",
        "weak_instruments",
        "below_margin",
        "accumulating",
        "skipped_sample",
        "no_ambiguity_model",
        "no_calibration",
        "gap",
        "rate_below_margin",
        "varying_dynamics",
        "hidden_dynamics",
        "order_untested",
        "linearity_untested",
        "plant_changed",
        "no_nonlinear_model",
        "library_misfit",
        "library_untested",
        "weakly_identified",
        "outside_region",
        "input_follows_outputs",
        "first_order_only",
    ];

    /// A small stable integer per kind of reason, from 1 (0 is left for "certified" in
    /// tables of codes): the position in [`KINDS`](Self::KINDS) plus one.
    #[must_use]
    pub fn code(&self) -> u8 {
        match self {
            Self::WarmingUp { .. } => 1,
            Self::InsufficientExcitation => 2,
            Self::WeakInstruments => 3,
            Self::BelowMargin { .. } => 4,
            Self::Accumulating { .. } => 5,
            Self::SkippedSample => 6,
            Self::NoAmbiguityModel => 7,
            Self::NoCalibration => 8,
            Self::Gap { .. } => 9,
            Self::RateBelowMargin { .. } => 10,
            Self::VaryingDynamics { .. } => 11,
            Self::HiddenDynamics { .. } => 12,
            Self::OrderUntested { .. } => 13,
            Self::LinearityUntested { .. } => 14,
            Self::PlantChanged { .. } => 15,
            Self::NoNonlinearModel => 16,
            Self::LibraryMisfit { .. } => 17,
            Self::LibraryUntested { .. } => 18,
            Self::WeaklyIdentified { .. } => 19,
            Self::OutsideRegion { .. } => 20,
            Self::InputFollowsOutputs { .. } => 21,
            Self::FirstOrderOnly => 22,
        }
    }

    /// The reason's name, as in its serde form (`"plant_changed"`, …).
    #[must_use]
    pub fn kind(&self) -> &'static str {
        Self::KINDS[usize::from(self.code()) - 1]
    }
}

/// The three certificates the certifier reports, for [`Evidence::verdict`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CertificateKind {
    /// The paper's Gaussian certificate `β̂ − ρ` (Section II-B).
    Gaussian,
    /// The paper's Wasserstein certificate `β̂ − ρ(1 + 2ε)` (eq. wass_cert).
    Wasserstein,
    /// The calibrated certificate `β̂_w − ρ_w` (false deployment at most `δ`, for dynamics
    /// whose Jacobian is constant over the window).
    Calibrated,
    /// The nonlinear certificate: the smallest rate over the explored region, calibrated
    /// (false deployment at most `δ`; see the [`nonlinear`](crate::nonlinear) module).
    Nonlinear,
}

impl CertificateKind {
    /// All four, in the order of the output columns.
    pub const ALL: [Self; 4] =
        [Self::Gaussian, Self::Wasserstein, Self::Calibrated, Self::Nonlinear];
}

/// One certificate after one sample: its value, the radius it subtracts, its gate, and why the
/// gate is closed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// The certificate: an estimate of the rate less a radius (`None` when there is none:
    /// warming up, no excitation, not configured, skipped sample).
    pub value: Option<f64>,
    /// The radius subtracted from the estimate: `ρ` (Gaussian, eq. rho), `ρ(1 + 2ε)`
    /// (Wasserstein), `ρ_w` (calibrated, [`calibrated_radius`](crate::calibrated_radius)),
    /// `min_y β̂(y) − β_nl` (nonlinear: the estimate's own minimum over the region less the
    /// certificate).
    pub radius: Option<f64>,
    /// The gate: open once `value >= margin` for `consecutive` samples ([`Gate`](crate::Gate)).
    pub open: bool,
    /// Why the gate is closed (`None` exactly when it is open).
    pub reason: Option<NotCertified>,
}

impl Verdict {
    /// A closed verdict without a certificate.
    #[must_use]
    pub const fn closed(reason: NotCertified) -> Self {
        Self { value: None, radius: None, open: false, reason: Some(reason) }
    }
}

/// The regression's fit behind `β̂` (when the window is ready).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Fit {
    /// `β̂ = −λ_max(sym J_cl)` (eq. betahat).
    pub beta_hat: f64,
    /// `RMS(R)`, the root mean square of the window's column residuals.
    pub rms_residual: f64,
    /// `λ_min(Z Zᵀ / M)`.
    pub gram_lambda_min: f64,
}

/// The ambiguity estimators' state (largest over outputs), when a model is configured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AmbiguityLevel {
    /// Ambiguity radius `ε(t)` (eq. eps_est).
    pub eps: f64,
    /// Excess kurtosis of the residual tail window (`None` until it has enough residuals).
    pub kurtosis: Option<f64>,
    /// Spike fraction `ŝ(t)`.
    pub spike_fraction: f64,
}

/// Everything the certifier knows after one sample: a numeric core (the fit and the
/// ambiguity level) and one [`Verdict`] per certificate. Reasons stay enums; they are turned
/// into text only where they are shown (their `Display`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Evidence {
    /// Sample time.
    pub t: f64,
    /// Columns in the regression window.
    pub columns: usize,
    /// The fit, when the regression is ready.
    pub fit: Option<Fit>,
    /// The ambiguity level, when a model is configured.
    pub ambiguity: Option<AmbiguityLevel>,
    /// Gaussian certificate `β̂ − ρ`; its radius is `ρ` (eq. rho).
    pub gaussian: Verdict,
    /// Wasserstein certificate `β̂ − ρ(1 + 2ε)` (eq. wass_cert).
    pub wasserstein: Verdict,
    /// Calibrated certificate `β̂_w − ρ_w` of the largest standing window look (its `β̂_w` is
    /// that window's instrumented estimate, not `β̂`).
    pub calibrated: Verdict,
    /// Window length `M_w` (columns) of that look.
    pub calibrated_window: Option<usize>,
    /// The horizon `h` (samples per column) of that look: the regression's, or with a
    /// [`HorizonLadder`](crate::HorizonLadder) the standing rung's.
    pub calibrated_horizon: Option<usize>,
    /// The model order `n` of that look: the regression's (`1` for the paper's first-order
    /// model), or with an [`OrderLadder`](crate::OrderLadder) (`order = "auto"`) the standing
    /// rung's.
    pub calibrated_order: Option<usize>,
    /// Nonlinear certificate `min_y β̂(y) − c s(y)` over the region of the largest standing
    /// nonlinear look (see the [`nonlinear`](crate::nonlinear) module).
    pub nonlinear: Verdict,
    /// Window length of that look.
    pub nonlinear_window: Option<usize>,
    /// The region `[y_lo, y_hi]` that look's certificate speaks for.
    pub nonlinear_region: Option<Interval>,
}

impl Evidence {
    /// The verdict of one certificate.
    #[must_use]
    pub fn verdict(&self, kind: CertificateKind) -> &Verdict {
        match kind {
            CertificateKind::Gaussian => &self.gaussian,
            CertificateKind::Wasserstein => &self.wasserstein,
            CertificateKind::Calibrated => &self.calibrated,
            CertificateKind::Nonlinear => &self.nonlinear,
        }
    }

    /// `β̂` (eq. betahat), when the regression is ready.
    #[must_use]
    pub fn beta_hat(&self) -> Option<f64> {
        self.fit.map(|f| f.beta_hat)
    }

    /// `ρ` (eq. rho): the Gaussian certificate's radius.
    #[must_use]
    pub fn rho(&self) -> Option<f64> {
        self.gaussian.radius
    }

    /// `ε(t)`, when an ambiguity model is configured.
    #[must_use]
    pub fn eps(&self) -> Option<f64> {
        self.ambiguity.map(|a| a.eps)
    }
}

#[cfg(test)]
mod tests {
    use super::NotCertified;

    /// A reason written under its earlier name (`rate_dropped`, in a checkpoint's summary or
    /// state) reads as `RateBelowMargin`, and is written back under the new name.
    #[test]
    fn the_earlier_name_of_rate_below_margin_still_reads() {
        let old = r#"{"reason":"rate_dropped","window":150,"upper":-0.1787}"#;
        let r: NotCertified = serde_json::from_str(old).expect("the earlier name reads");
        assert_eq!(r, NotCertified::RateBelowMargin { window: 150, upper: -0.1787 });
        assert_eq!(r.kind(), "rate_below_margin");
        let again = serde_json::to_string(&r).expect("serialised");
        assert!(again.contains(r#""reason":"rate_below_margin""#), "{again}");
    }
}
