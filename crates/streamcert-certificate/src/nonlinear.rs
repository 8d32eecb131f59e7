//! The nonlinear certificate (an addition to the paper): a lower confidence bound on the
//! smallest contraction rate over the region of states the window explored, for one output
//! whose drift is a polynomial in `y`.
//!
//! ## Why
//!
//! A linear certificate estimates one averaged (secant) Jacobian over whatever states its
//! window visited. On a nonlinear loop that average can contract while part of the visited
//! region does not (`ẏ = −y tanh y + u` under `u = −1.1 y` has the local rate
//! `1.1 + tanh y + y sech² y`, negative around `y ≈ −1.2`), and the linear certificate then
//! claims more than the data show.
//!
//! ## Model
//!
//! The drift is linear in the feature library `φ(y) = (y, y², …, y^D)` (or a named library
//! starting with `y`, [`FeatureSet`]: `y, y·tanh y` holds G5's node 1 exactly) and in the
//! input: `ẏ = Σ_k θ_k φ_k(y) + B u + noise`. The integral form of the paper is kept: column `q`
//! regresses `ΔY_q = y(t_q + h) − y(t_q)` on
//!
//! ```text
//! Z_q = [∫ y; ∫ y²; …; ∫ y^D; ∫ u]      over [t_q, t_q + h]
//! ```
//!
//! (`∫ y` and `∫ u` are the regression's own columns; `∫ y^k` is trapezoidal over the same
//! samples), with the calibrated certificate's instrumented windows, looks and risk
//! ([`InstrumentedWindows`] with `D + m` regressors). Under `u = K y` the closed-loop local
//! rate at `y` is
//!
//! ```text
//! β(y) = −(Σ_k k θ_k y^{k−1} + B K) = −a(y)ᵀ θ,    a(y) = (1, 2y, …, D y^{D−1}, K)
//! ```
//!
//! ## Region, certificate and radius
//!
//! The region `[y_lo, y_hi]`, reported with the certificate, is the `q` and `1 − q` quantiles
//! of the outputs at the window's column starts ([`NonlinearConfig::region_trim`], default
//! `q = 0.025`; `q = 0`: the bounding box of every sample the columns integrate). The gate
//! stays closed while the output lies outside the standing look's region
//! ([`NotCertified::OutsideRegion`]): the certificate speaks for that region only. With `Ω̂_θ` the
//! batch-means covariance of the coefficients
//! ([`InstrumentedWindows::coefficient_covariance`]) and `s(y)² = a(y)ᵀ Ω̂_θ a(y)`,
//!
//! ```text
//! β_nl = min over y in [y_lo, y_hi] of  β̂(y) − c · s(y)
//! c    = t_ν(1 − δ_{w,k})                                  (RegionBound::Pointwise, the default)
//! c²   = ν D / (ν − D + 1) · F_{D, ν−D+1}(1 − δ_{w,k})      (RegionBound::Simultaneous, D >= 2)
//! ```
//!
//! A lower bound on a minimum needs one point's quantile ([`RegionBound::Pointwise`]): with
//! `y*` where the true rate is smallest over the region, `β_nl <= β̂(y*) − c s(y*)`, which
//! is below `β*(y*) = min_y β*(y)` with probability `1 − δ_{w,k}` per look. `y*` is a fixed
//! state or an end of the region, whose quantile settles as the window grows, so this holds
//! for the region the data chose as the window's other approximations do (NONLINEAR.md
//! measures it at a quadratic drift whose smallest rate is at the region's edge). With
//! [`RegionBound::Simultaneous`], as `a(y)` spans a space of dimension `D` when `y` varies,
//! by Cauchy–Schwarz the Hotelling bound holds *for every y at once*: so `β_nl <= min_y
//! β*(y)` over every region, with no appeal to the region settling, at about 1.15 to 1.33
//! times the pointwise radius for `D = 2` (`ν >= 100`, risks `10⁻⁴` to `10⁻²`). The minimum
//! is bounded, not sampled: the region is cut into `cells` intervals and on each `β̂(y)` is
//! bounded below and `s(y)²` above by their Taylor expansions at the cell's midpoint
//! ([`polynomial_bounds`]); for a named library every slope `φ_k'` is bounded on the cell
//! ([`Feature::slope_bounds`]), `β̂` by interval arithmetic and `s²`, convex in `a`, at the
//! corners of the box of slopes. The certificate is the smallest cell bound (so it holds
//! between grid points too). `ν` is the calibrated certificate's: the effective number of
//! blocks (weights in the direction `a` at the region's midpoint) less `D + m`. The looks are
//! the calibrated one's, with a split of `δ` of its own, `δ_{w,k} = δ · share_w / (k (k+1))`
//! with `share_w = M_w² / Σ_v M_v²` by default ([`NonlinearConfig::risk_split`]): the bound at
//! the region's edge needs the most data a window holds, so most of `δ` goes to the longest
//! windows. With `D = 1` and the linear certificate's split the certificate equals the linear
//! calibrated certificate (up to rounding; a property test).
//!
//! ## Nonlinearity test
//!
//! The same fit tests whether the dynamics vary over the region: the Wald statistic of the
//! terms of degree `>= 2`, `W = θ̂_Hᵀ Ω̂_HH⁻¹ θ̂_H`, against Hotelling's quantile with `D − 1`
//! and `ν` degrees of freedom at `test_risk`. When it is significant, the *linear* calibrated
//! certificate of that window does not stand ([`NotCertified::VaryingDynamics`]): the linear
//! model does not describe the region. Closing a gate never costs validity.
//!
//! ## Lack-of-fit check
//!
//! The certificate's model is its library. A second instrumented fit on the same columns adds
//! `e` powers of `y` the library lacks ([`NonlinearConfig::check_terms`], default 2: `y³, y⁴`
//! for the default quadratic library, `y⁴, y⁵` for the cubic, `y², y³` for `y, y·tanh y`)
//! and tests them with the same Wald statistic and risk as the nonlinearity test. A window's nonlinear certificate stands only
//! where that test ran and found nothing ([`NotCertified::LibraryMisfit`],
//! [`NotCertified::LibraryUntested`]). Closing costs no validity; the check cannot prove a
//! library right (a drift the extra terms do not see passes), so the assumption below stays.
//! Measured with `cargo xtask nonlinear` (NONLINEAR.md): the libraries that miss the cubic
//! band or the cubic drift open far less often, and where they still open their value is
//! rarely above the truth; the matching libraries are unchanged or slightly slower.
//!
//! With [`Calibration::hidden_dynamics`](crate::Calibration::hidden_dynamics) (on by
//! default) a third fit, the library plus the output's increment over the `h` samples
//! before the column, gives the certificate's order test (its Wald test, same risk; a fit of
//! its own, so that the past increment does not take the lack-of-fit check's power): a
//! window's certificate stands only where it ran and found nothing
//! ([`NotCertified::HiddenDynamics`], [`NotCertified::OrderUntested`]).
//!
//! ## Assumptions (when one fails the guarantee is void)
//! * One output (`p = 1`) whose drift lies in the span of the feature library over the
//!   region, plus `B u`; a drift that does not is covered only as far as the library's best
//!   fit is close over the region, or as the lack-of-fit check catches it (`cargo xtask
//!   nonlinear` measures libraries that miss the drift: degree 2 and `y, y·tanh y` on a cubic
//!   band and on cubics).
//! * Every assumption of the calibrated certificate (white process noise, exogenous
//!   exploration, instruments relevant, negligible ridge), with the features as regressors.
//! * The output is the state (or the feature model holds for the measured output; the order
//!   test refuses where the past increment shows otherwise); sensor noise widens the
//!   reported region slightly (the box of noisy samples), which only makes the minimum
//!   smaller.

mod bounds;
mod cells;
mod check;
mod config;
mod features;

pub use bounds::polynomial_bounds;
use cells::Bounds;
use check::{LackOfFit, refused};
pub use config::{NonlinearConfig, RegionBound};
pub use features::{Feature, FeatureSet};

use serde::{Deserialize, Serialize};
use streamcert_regression::{
    InstrumentedWindows, Interval, RateMap, RegressionConfig, Solve, WindowEstimate,
};

use crate::look::hotelling::wald_entries;
pub use crate::look::hotelling::{NonlinearityTest, f_quantile, simultaneous_multiplier};
use crate::look::quantile::t_quantile;
use crate::look::{Look, standing};
use crate::{CertifyError, NotCertified};

/// One window's latest nonlinear look.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NonlinearLook {
    /// Window length `M_w` in columns.
    pub window: usize,
    /// Look number `k` of this window.
    pub look: u64,
    /// Time of the look.
    pub t: f64,
    /// `β_nl`: the lower bound of `β̂(y) − c s(y)` over the region.
    pub certificate: f64,
    /// The lower bound of `β̂(y)` over the region (the estimate's own minimum, no radius).
    pub beta_hat_min: f64,
    /// The multiplier `c`.
    pub multiplier: f64,
    /// Degrees of freedom `ν`.
    pub nu: f64,
    /// The region `[y_lo, y_hi]` the certificate speaks for.
    pub region: Interval,
    /// Midpoint of the cell that gives the certificate (where the loop is closest to not
    /// contracting, by this bound).
    pub worst: f64,
    /// The upper bound `min over cells of β̂(y) + t_ν(1 − δ) s(y)` (one look's risk), when
    /// below the margin: some visited state then contracts by less than the margin, and the
    /// window's older certificates stop standing.
    pub upper: Option<f64>,
    /// The nonlinearity test (degree `>= 2`, when `Ω̂_HH` is positive definite).
    pub test: Option<NonlinearityTest>,
    /// The lack-of-fit check of the library (when configured and computable): the Wald test
    /// of the extra terms in the larger fit ([`NonlinearConfig::check_terms`]).
    #[serde(default)]
    pub misfit: Option<NonlinearityTest>,
    /// The hidden-dynamics test (when [`Calibration::hidden_dynamics`] is on and the larger
    /// fit is ready): the Wald test of the past increment `ΔY_{q−h}` in its own larger fit
    /// (the library plus that increment).
    ///
    /// [`Calibration::hidden_dynamics`]: crate::Calibration::hidden_dynamics
    #[serde(default)]
    pub order: Option<NonlinearityTest>,
    /// The edge-slope factor: the certificate's radius `β̂_min − β_nl` over `c · s(y_mid)`,
    /// the radius the same multiplier gives the rate at the region's midpoint (for an
    /// exploring input that visits the region symmetrically, about the average slope's). How
    /// much wider the bound is where the certificate is decided, at the region's edge, than
    /// at its centre (`None` when `s(y_mid) = 0`).
    #[serde(default)]
    pub edge_factor: Option<f64>,
}

/// One look's circumstances, from the calibrated schedule that drives it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LookAt {
    /// Look number `k` of the window.
    pub k: u64,
    /// Time of the look.
    pub t: f64,
    /// The risk the look spends, `δ_{w,k}`.
    pub risk: f64,
    /// The run-level risk `δ` (one look's risk for the closing upper bound).
    pub delta: f64,
    /// `β_margin`.
    pub margin: f64,
    /// The ridge `λ`.
    pub ridge: f64,
    /// The smallest pivot ratio of an instrumented solve.
    pub min_pivot: f64,
    /// The origin the features were taken about (the affine model's working origin for a
    /// polynomial library, else 0): the look's region and worst point are reported in the
    /// record's own coordinates, `origin +` the internal ones.
    pub origin: f64,
}

impl Look for NonlinearLook {
    fn time(&self) -> f64 {
        self.t
    }
    fn window(&self) -> usize {
        self.window
    }
    fn value(&self) -> f64 {
        self.certificate
    }
    fn upper(&self) -> Option<f64> {
        self.upper
    }
}

/// The streaming state of the nonlinear certificate (inside the calibrated state, which drives
/// its columns and looks).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct NonlinearState {
    cfg: NonlinearConfig,
    library: FeatureSet,
    horizon: usize,
    windows: InstrumentedWindows,
    est: WindowEstimate,
    /// `K` (`m` values).
    gain: Vec<f64>,
    latest: Vec<Option<NonlinearLook>>,
    /// Each window's share of `δ` ([`NonlinearConfig::risk_split`]).
    #[serde(default)]
    shares: Vec<f64>,
    /// The lack-of-fit check, when `check_terms > 0`.
    #[serde(default)]
    check: Option<LackOfFit>,
    /// The order test's fit (the library plus the past increment), when
    /// `Calibration::hidden_dynamics` is on: its own fit, since in the lack-of-fit check's
    /// the past increment would carry the terms a library misses and take that test's power.
    #[serde(default)]
    order: Option<LackOfFit>,
    // Scratch (meaningless between calls): one column's regressors, `a(y_mid)`, `Ω̂_θ`, the
    // polynomials of `β̂(y)` and `s(y)²`, their bound work space, the Wald sub-problem.
    z: Vec<f64>,
    dir: Vec<f64>,
    cov: Vec<f64>,
    poly_f: Vec<f64>,
    poly_s: Vec<f64>,
    work: Vec<f64>,
    sub: Vec<f64>,
    rhs: Vec<f64>,
    /// The trimmed region's selection scratch (the longest window's column values; not
    /// serialised, sized on restore by [`restore_scratch`](Self::restore_scratch)).
    #[serde(skip)]
    values: Vec<f64>,
}

impl NonlinearState {
    /// The state for `cfg` on the calibrated windows `lengths`, instrumented as they are
    /// (`lag`, `intervals`); `order`: whether the larger fit holds the past increment (the
    /// hidden-dynamics test, [`Calibration::hidden_dynamics`](crate::Calibration::hidden_dynamics)).
    pub(crate) fn new(
        cfg: NonlinearConfig,
        reg: &RegressionConfig,
        gain: &[f64],
        lengths: &[usize],
        (lag, intervals, order): (usize, usize, bool),
    ) -> Result<Self, CertifyError> {
        let library = cfg.library();
        // The inputs' gains, then zero for the affine model's `τ` (an input with gain zero).
        let (dg, m) = (library.len(), gain.len());
        let d = dg + m;
        let windows =
            InstrumentedWindows::with_regressors(1, d, reg.horizon, lag, intervals, lengths)?
                .with_ranges(1);
        let windows = if cfg.region_trim > 0.0 { windows.with_values() } else { windows };
        let longest = windows.window(lengths.len() - 1);
        let powers: Vec<u8> = cfg
            .check_features()
            .into_iter()
            .filter_map(|f| match f {
                Feature::Power(k) => Some(k),
                _ => None,
            })
            .collect();
        let fit = |terms| LackOfFit::new(terms, dg, m, (reg.horizon, lag, intervals), lengths);
        let check = (!powers.is_empty()).then(|| fit((powers, false))).transpose()?;
        let order = order.then(|| fit((Vec::new(), true))).transpose()?;
        Ok(Self {
            check,
            order,
            cfg,
            library,
            horizon: reg.horizon,
            windows,
            est: WindowEstimate::with_regressors(1, d, intervals),
            gain: gain.to_vec(),
            latest: vec![None; lengths.len()],
            shares: cfg.risk_split.shares(lengths),
            z: vec![0.0; d],
            dir: vec![0.0; d],
            cov: vec![0.0; d * d],
            poly_f: vec![0.0; dg],
            poly_s: vec![0.0; 2 * dg - 1],
            work: vec![0.0; (2 * dg - 1).max(d)],
            sub: vec![0.0; (dg - 1) * (dg - 1)],
            rhs: vec![0.0; dg - 1],
            values: vec![0.0; longest],
        })
    }

    /// Size the scratch a checkpoint does not carry, so that no look allocates.
    pub(crate) fn restore_scratch(&mut self) {
        let longest = self.windows.window(self.latest.len() - 1);
        self.values.resize(longest, 0.0);
    }

    /// Whether the library is polynomial (its class is the same about any origin).
    pub(crate) fn is_polynomial(&self) -> bool {
        self.library.is_polynomial()
    }

    /// Window `w`'s share of `δ` ([`NonlinearConfig::risk_split`] over the configured window
    /// lengths, as the linear certificate's shares are).
    pub(crate) fn share(&self, w: usize) -> f64 {
        self.shares[w]
    }

    /// The number of features `D`.
    pub(crate) fn features(&self) -> usize {
        self.library.len()
    }

    pub(crate) fn looks(&self) -> &[Option<NonlinearLook>] {
        &self.latest
    }

    pub(crate) fn reset(&mut self) {
        self.windows.reset();
        self.latest.fill(None);
        for c in self.check.iter_mut().chain(self.order.iter_mut()) {
            c.reset();
        }
    }

    /// Absorb the newest column: `z_lin = [∫y; ∫u]` and `dy` from the regression, and its
    /// `h + 1` samples (`ts`, `ys`, oldest first) for the higher powers and the region.
    /// `O(h D + (D + m)²)`, no allocation.
    pub(crate) fn push(&mut self, z_lin: &[f64], dy: &[f64], ts: &[f64], ys: &[f64]) -> bool {
        let dg = self.library.len();
        let m = self.gain.len();
        self.z[0] = z_lin[0];
        self.z[dg..dg + m].copy_from_slice(&z_lin[1..=m]);
        for v in &mut self.z[1..dg] {
            *v = 0.0;
        }
        let (mut lo, mut hi) = (ys[0], ys[0]);
        for i in 1..ts.len() {
            let half = 0.5 * (ts[i] - ts[i - 1]);
            let (ya, yb) = (ys[i - 1], ys[i]);
            lo = lo.min(yb);
            hi = hi.max(yb);
            if self.library.is_polynomial() {
                let (mut pa, mut pb) = (ya, yb);
                for v in &mut self.z[1..dg] {
                    pa *= ya;
                    pb *= yb;
                    *v += half * (pa + pb);
                }
            } else {
                for (v, f) in self.z[1..dg].iter_mut().zip(self.library.iter().skip(1)) {
                    *v += half * (f.value(ya) + f.value(yb));
                }
            }
        }
        for c in self.check.iter_mut().chain(self.order.iter_mut()) {
            c.push(&self.z, dy, ts, ys);
        }
        // The column's value for the trimmed region: the output at its start.
        self.windows.push_column_valued(&self.z, dy, &[Interval { lo, hi }], ys[0])
    }

    /// Window `w`'s look (see [`LookAt`]); its outcome replaces the window's latest look.
    pub(crate) fn look(&mut self, w: usize, at: LookAt) {
        self.latest[w] = self.compute(w, at);
    }

    fn compute(&mut self, w: usize, at: LookAt) -> Option<NonlinearLook> {
        let LookAt { k, t, risk, delta, margin, ridge, min_pivot, origin } = at;
        let (dg, m) = (self.library.len(), self.gain.len());
        let d = dg + m;
        let region = self.region(w);
        if !region.is_proper() {
            return None;
        }
        let mid = 0.5 * (region.lo + region.hi);
        // a(y_mid) = (φ'(y_mid), K): the direction whose weights give ν.
        for (a, f) in self.dir[..dg].iter_mut().zip(self.library.iter()) {
            *a = f.slope(mid);
        }
        self.dir[dg..d].copy_from_slice(&self.gain);
        let (windows, est, cov) = (&self.windows, &mut self.est, &mut self.cov);
        if !windows.estimate_coefficients(
            w,
            Solve { ridge, rate: RateMap::SymmetricPart(&self.dir), min_pivot_ratio: min_pivot },
            est,
            cov,
        ) {
            return None;
        }
        let blocks = (self.est.columns / self.horizon) as f64;
        let nu = self.est.effective_blocks.min(blocks) - d as f64;
        let rank = if dg == 1 || region.hi == region.lo { 1 } else { dg };
        let c = simultaneous_multiplier(self.cfg.bound.directions(rank), nu, risk);
        let c_upper = t_quantile(nu, delta);
        let cells = if region.hi > region.lo { self.cfg.cells } else { 1 };
        let bounds = if self.library.is_polynomial() {
            self.cells_polynomial(region, cells, c, c_upper)
        } else {
            self.cells_named(region, cells, c, c_upper)
        };
        let Bounds { cert, worst, beta_min, upper } = bounds;
        // s(y_mid)² = a(y_mid)ᵀ Ω̂_θ a(y_mid).
        let s_mid = (0..d)
            .map(|i| self.dir[i] * (0..d).map(|j| self.cov[i * d + j] * self.dir[j]).sum::<f64>())
            .sum::<f64>()
            .max(0.0)
            .sqrt();
        let edge_factor = (s_mid > 0.0).then(|| (beta_min - cert) / (c * s_mid));
        let alpha = self.cfg.test_risk.unwrap_or(delta);
        let scratch = (&mut self.sub[..], &mut self.rhs[..], &mut self.work[..]);
        let (theta, cov) = (&self.est.theta[..d], &self.cov[..d * d]);
        let test = wald_entries((theta, cov), (dg - 1, |a| 1 + a), (nu, alpha), scratch);
        let misfit =
            self.check.as_mut().and_then(|c| c.test(w, &self.dir, ridge, min_pivot, alpha));
        let order = self.order.as_mut().and_then(|c| c.test(w, &self.dir, ridge, min_pivot, alpha));
        (cert.is_finite() && beta_min.is_finite()).then_some(NonlinearLook {
            window: self.windows.window(w),
            look: k,
            t,
            certificate: cert,
            beta_hat_min: beta_min,
            multiplier: c,
            nu,
            region: Interval { lo: region.lo + origin, hi: region.hi + origin },
            worst: worst + origin,
            upper: (upper < margin).then_some(upper),
            test,
            misfit,
            order,
            edge_factor,
        })
    }

    /// Window `w`'s region: its trimmed region ([`NonlinearConfig::region_trim`]) where values
    /// are tracked, else the hull of its columns' samples.
    fn region(&mut self, w: usize) -> Interval {
        if self.windows.tracks_values() {
            return self.windows.window_quantiles(w, self.cfg.region_trim, &mut self.values);
        }
        let mut region = [Interval::EMPTY];
        self.windows.window_range(w, &mut region);
        region[0]
    }

    /// The largest standing nonlinear certificate, and why the gate stays closed if none.
    pub(crate) fn verdict(
        &self,
        margin: f64,
        warming: NotCertified,
    ) -> (Option<NonlinearLook>, Option<NotCertified>) {
        // With the lack-of-fit check, a look stands only where the check ran and found no
        // missing term (the certificate's model is its library); with the hidden-dynamics
        // test, only where it ran and found no past-increment term in its own larger fit
        // (the linear guard's order test does not gate this certificate: on a nonlinear loop
        // the linear model's misfit reads as a past-increment term; measured: the −x tanh x
        // loop at σ = 0.02 closed at most samples).
        let (powers, order) = (self.check.is_some(), self.order.is_some());
        let mut misfit = None;
        let (best, contradicted) = standing(&self.latest, margin, |_, look| {
            let window = look.window;
            let order = refused(order, look.order, NotCertified::OrderUntested { window });
            let library = refused(powers, look.misfit, NotCertified::LibraryUntested { window });
            match order.or(library) {
                Some(reason) => {
                    misfit.get_or_insert(reason);
                    false
                }
                None => true,
            }
        });
        let blocked =
            if best.is_some() { None } else { Some(contradicted.or(misfit).unwrap_or(warming)) };
        (best, blocked)
    }
}
