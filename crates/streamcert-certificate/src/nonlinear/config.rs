//! [`NonlinearConfig`]: the feature library and region rule of the nonlinear certificate, and
//! their validation.

use serde::{Deserialize, Serialize};
use streamcert_regression::RegressionConfig;

use super::{Feature, FeatureSet};
use crate::CertifyError;
use crate::look::split::RiskSplit;

/// Settings of the nonlinear certificate (an addition to the paper; see the
/// [`nonlinear`](crate::nonlinear) module). It needs a [`Calibration`](crate::Calibration):
/// it shares its windows, looks and risk `δ`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NonlinearConfig {
    /// Degree `D >= 1` of the polynomial feature library `φ(y) = (y, y², …, y^D)` (default 2,
    /// at most 5). `D = 1` is the linear model: the certificate then equals the calibrated one.
    /// Degree 2 (a local rate linear in `y`) with the lack-of-fit check on `y³, y⁴` is the
    /// default because its bound at the region's edge is far tighter than degree 3's
    /// (NONLINEAR.md measures both); a drift the quadratic does not hold is what the check
    /// refuses.
    #[serde(default = "default_degree")]
    pub degree: usize,
    /// A named feature library instead of the polynomial one (default none): for example
    /// `y, y*tanh(y)` for G5's node 1, whose drift is `−x1 tanh x1`. Starts with `y`; at most
    /// [`FeatureSet::CAPACITY`] features.
    #[serde(default)]
    pub features: Option<FeatureSet>,
    /// Cells of the grid over the region on which the certificate's minimum is bounded
    /// (default 32; `1..=4096`). The bound holds between grid points too (interval bounds of
    /// the polynomials on each cell), so more cells only tighten it.
    #[serde(default = "default_cells")]
    pub cells: usize,
    /// Risk of the nonlinearity test (default: the calibration's `δ`). When the terms of
    /// degree `>= 2` are significant at this risk for a window, that window's *linear*
    /// calibrated certificate does not stand ([`NotCertified::VaryingDynamics`]). Closing a
    /// gate costs no validity, so this risk is not part of `δ`.
    ///
    /// [`NotCertified::VaryingDynamics`]: crate::NotCertified::VaryingDynamics
    #[serde(default)]
    pub test_risk: Option<f64>,
    /// Lack-of-fit check of the library (default 2; 0 turns it off): the number `e` of extra
    /// terms, the lowest powers `y^k` (`2 <= k <= 8`) the library lacks (`y³, y⁴` for the default quadratic, `y⁴, y⁵` for the cubic
    /// library, `y², y³` for `y, y·tanh y`). A second instrumented fit on the library plus
    /// these terms tests them with the same Wald statistic and risk as the nonlinearity test;
    /// where they are significant, or cannot be tested yet, the window's nonlinear certificate
    /// does not stand ([`NotCertified::LibraryMisfit`], [`NotCertified::LibraryUntested`]):
    /// the certificate assumes the drift lies in the library's span, and the check refuses
    /// where the data show it does not. It closes gates only, so its risk is not part of `δ`;
    /// it cannot prove the library right (a drift the extra terms do not see passes).
    ///
    /// [`NotCertified::LibraryMisfit`]: crate::NotCertified::LibraryMisfit
    /// [`NotCertified::LibraryUntested`]: crate::NotCertified::LibraryUntested
    #[serde(default = "default_check_terms")]
    pub check_terms: usize,
    /// The share `q` of each window's outputs left outside its region at each end (default
    /// 0.025, `0 <= q < 0.25`): the region is `[y_(k), y_(n−1−k)]`, `k = ⌊q n⌋`, over the
    /// outputs at the window's `n` column starts, its `q` and `1 − q` quantiles. `q = 0` is
    /// the range of every sample the window's columns integrate (the bounding box). The trim
    /// spares the bound the region's few extreme states, where the local slope is least
    /// known; the bound holds for the region the data chose ([`RegionBound`]). The
    /// certificate then speaks for the trimmed region only, and the gate stays closed while
    /// the output lies outside it
    /// ([`NotCertified::OutsideRegion`]).
    ///
    /// [`NotCertified::OutsideRegion`]: crate::NotCertified::OutsideRegion
    #[serde(default = "default_region_trim")]
    pub region_trim: f64,
    /// The multiplier `c` of the bound at each point of the region (default
    /// [`RegionBound::Pointwise`]); see [`RegionBound`].
    #[serde(default)]
    pub bound: RegionBound,
    /// How the nonlinear certificate splits its risk `δ` across the calibrated windows
    /// (default [`RiskSplit::ByLengthSquared`]): window `w`'s `k`-th nonlinear look spends
    /// `δ · share_w / (k (k + 1))`, its own `δ` beside the linear certificate's (each
    /// certificate's guarantee is its own). The default gives the longest windows most of
    /// `δ`, since the bound at the region's edge needs the most data a window holds. Any split
    /// is valid by the union bound. Measured with `cargo xtask nonlinear --runs 500`
    /// (NONLINEAR.md; `--split equal` or `--split by_length` gives the other rules on the same
    /// runs): on 40 s runs with the default windows, G5's subsystem B certified in 47 % of
    /// runs (26 % with equal shares, 39 % by length), `−x tanh x` at 16× the margin 31 %
    /// (17 %, 30 %). The cost falls on windows longer than the run, which never look yet hold
    /// most of `δ`: with windows up to 51 200 columns on 400 s runs, `−x tanh x` at 16× opened
    /// in 53 % of runs (74 % equal, 68 % by length) and the cubic at 10× at a median of 96 s
    /// (48 s, 64 s). Where the windows reach beyond the data, `Equal` or `ByLength` suits.
    #[serde(default = "default_risk_split")]
    pub risk_split: RiskSplit,
}

/// How the nonlinear certificate's multiplier `c` in `β_nl = min_y β̂(y) − c · s(y)` is chosen
/// ([`NonlinearConfig::bound`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RegionBound {
    /// `c = t_ν(1 − δ_{w,k})`, one direction's quantile (the default). A lower bound on a
    /// *minimum* needs no simultaneity: with `y*` the point of the region where the true rate
    /// is smallest, `min_y (β̂(y) − c s(y)) <= β̂(y*) − c s(y*)`, and that one point's bound
    /// is below `β*(y*) = min_y β*(y)` with probability `1 − δ_{w,k}`. Exact for a fixed
    /// region; for the region the data choose (the quantiles of the window's outputs,
    /// [`NonlinearConfig::region_trim`]) `y*` is the interior point where `β*` is smallest (a
    /// fixed state) or an end of the region, which converges to a fixed quantile as the
    /// window grows, so the bound holds as the window's other approximations do (the batch
    /// means, the Student-t quantile). Its radius is 0.75 to 0.87 of the simultaneous one at
    /// `D = 2` (`ν >= 100`, risks `10⁻²` to `10⁻⁴`; a test). Measured with
    /// `cargo xtask nonlinear --runs 500` (NONLINEAR.md): no false opening in 500 runs of any
    /// near-margin cell, two of them a quadratic drift whose smallest rate is at the region's
    /// upper end and crosses the margin where that end falls (opened in 27 and 64 % of the
    /// runs, at 0.1 % of samples above the truth), and G5's subsystem B certified in 47 % of
    /// 40 s runs against 18 % with the simultaneous bound. A library that misses the drift loses more with it
    /// (`y, y·tanh y` on those quadratic cells: 69 and 12 false openings against 31 and 12);
    /// the library is the assumption either way.
    #[default]
    Pointwise,
    /// `c² = ν D/(ν − D + 1) · F_{D, ν−D+1}(1 − δ_{w,k})` (Hotelling's `T²`, Scheffé): the
    /// bound holds at every point of every region at once, so its validity does not depend on
    /// which region the data chose, and a drift just outside the library's span has the
    /// slack of the larger multiplier (NONLINEAR.md's band cell with `y, y·tanh y`).
    Simultaneous,
}

impl RegionBound {
    /// The directions `r` the multiplier covers for a library of `D` features whose slopes
    /// span `rank` directions over the region: 1 for [`Pointwise`](Self::Pointwise), `rank`
    /// for [`Simultaneous`](Self::Simultaneous).
    #[must_use]
    pub fn directions(self, rank: usize) -> usize {
        match self {
            Self::Pointwise => 1,
            Self::Simultaneous => rank,
        }
    }
}

fn default_degree() -> usize {
    2
}
fn default_region_trim() -> f64 {
    0.025
}
fn default_cells() -> usize {
    32
}
fn default_check_terms() -> usize {
    2
}
fn default_risk_split() -> RiskSplit {
    RiskSplit::ByLengthSquared
}

impl Default for NonlinearConfig {
    fn default() -> Self {
        Self {
            degree: default_degree(),
            features: None,
            cells: default_cells(),
            test_risk: None,
            check_terms: default_check_terms(),
            region_trim: default_region_trim(),
            bound: RegionBound::default(),
            risk_split: default_risk_split(),
        }
    }
}

impl NonlinearConfig {
    /// Degree `degree`, every other setting at its default.
    #[must_use]
    pub fn with_degree(degree: usize) -> Self {
        Self { degree, ..Self::default() }
    }

    /// Features `library` with every other setting at its default.
    #[must_use]
    pub fn with_features(library: FeatureSet) -> Self {
        Self { features: Some(library), ..Self::default() }
    }

    /// The feature library: the named one, or `y, …, y^degree` ([`FeatureSet::polynomial`]).
    #[must_use]
    pub fn library(&self) -> FeatureSet {
        self.features.unwrap_or_else(|| FeatureSet::polynomial(self.degree))
    }

    /// Regressors per column: `D` features and `m` inputs.
    #[must_use]
    pub fn regressors(&self, inputs: usize) -> usize {
        self.library().len() + inputs
    }

    /// The extra terms of the lack-of-fit check: the lowest `check_terms` powers `y^k`,
    /// `2 <= k <= 8`, that the library lacks (fewer when the powers run out).
    #[must_use]
    pub fn check_features(&self) -> Vec<Feature> {
        let library = self.library();
        (2..=8u8)
            .map(Feature::Power)
            .filter(|f| library.iter().all(|g| g != *f))
            .take(self.check_terms)
            .collect()
    }

    /// The degree, the cells, the test's risk and the lack-of-fit terms in their ranges.
    fn check_settings(&self) -> Result<(), CertifyError> {
        let bad = CertifyError::refuse::<()>;
        if self.features.is_none() && !(1..=FeatureSet::CAPACITY).contains(&self.degree) {
            return bad(
                "nonlinear.degree",
                format!("must lie in 1..={}, got {}", FeatureSet::CAPACITY, self.degree),
            );
        }
        if !(1..=4096).contains(&self.cells) {
            return bad("nonlinear.cells", format!("must lie in 1..=4096, got {}", self.cells));
        }
        if let Some(a) = self.test_risk
            && !(a > 0.0 && a < 1.0)
        {
            return bad("nonlinear.test_risk", format!("must lie in (0, 1), got {a}"));
        }
        if !(0.0..0.25).contains(&self.region_trim) {
            return bad(
                "nonlinear.region_trim",
                format!(
                    "must lie in [0, 0.25) (the share of outputs left out at each end of the \
                     region; 0 for the full range), got {}",
                    self.region_trim
                ),
            );
        }
        if self.check_terms > 7 {
            return bad(
                "nonlinear.check_terms",
                format!("must lie in 0..=7 (powers up to y^8), got {}", self.check_terms),
            );
        }
        Ok(())
    }

    /// Check the settings against the regression (one output) and the calibration (which
    /// must be present) and its smallest window for the larger fit's `D + e + m` unknowns
    /// (`e`: the lack-of-fit terms, and the past increment when
    /// [`Calibration::hidden_dynamics`](crate::Calibration::hidden_dynamics) is on).
    ///
    /// # Errors
    /// [`CertifyError::InvalidConfig`] saying what would be valid.
    pub fn validate(
        &self,
        reg: &RegressionConfig,
        calibration: Option<&crate::Calibration>,
    ) -> Result<(), CertifyError> {
        let bad = CertifyError::refuse::<()>;
        let Some(calibration) = calibration else {
            return bad(
                "nonlinear",
                "the nonlinear certificate is calibrated: it needs a calibration (set \
                 [calibration] delta, for example 0.01)"
                    .into(),
            );
        };
        if reg.outputs != 1 {
            return bad(
                "nonlinear",
                format!(
                    "the nonlinear certificate is built for one output (p = 1), got p = {}: \
                     certify each output's loop separately, or drop [nonlinear] and rely on \
                     the linear calibrated certificate, which assumes the Jacobian is constant \
                     over the window",
                    reg.outputs
                ),
            );
        }
        self.check_settings()?;
        // The larger fits: the lack-of-fit terms, and (a fit of its own) the hidden-dynamics
        // test's past increment.
        let e = self.check_features().len().max(usize::from(calibration.hidden_dynamics));
        // The affine model's intercept is one more unknown (its `τ` an input with gain 0).
        let affine = usize::from(reg.model == streamcert_regression::Model::Affine);
        let d = self.regressors(reg.inputs + affine) + e;
        let min = crate::Calibration::min_window(reg.horizon, d);
        if reg.window < min && e > 0 {
            return bad(
                "window",
                format!(
                    "M = {} is too short for the nonlinear certificate with {} features, its \
                     larger fits' {e} extra terms ({} lack-of-fit terms; 1, the past \
                     increment, for the hidden-dynamics test), h = {} and m = {} (+ 1 \
                     for the affine model's intercept): the smallest valid window is {min} \
                     columns (h · (D + e + m + 2)); or set check_terms = 0 (no check: the \
                     library is then trusted to hold the drift) and [calibration] \
                     hidden_dynamics = false (the output is then trusted to be the state)",
                    reg.window,
                    self.library().len(),
                    self.check_features().len(),
                    reg.horizon,
                    reg.inputs
                ),
            );
        }
        if reg.window < min {
            return bad(
                "window",
                format!(
                    "M = {} is too short for the nonlinear certificate with {} features, h = {} \
                     and m = {} (+ 1 for the affine model's intercept): the smallest valid window \
                     is {min} columns (h · (D + m + 2))",
                    reg.window,
                    self.library().len(),
                    reg.horizon,
                    reg.inputs
                ),
            );
        }
        Ok(())
    }
}
