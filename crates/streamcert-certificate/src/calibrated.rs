//! The calibrated certificate (an addition to the paper): a lower confidence bound on the
//! closed-loop rate whose gate opens for a candidate with true rate below `β_margin` with
//! probability at most `δ` over the whole run, under the assumptions listed below.
//!
//! ## Method
//!
//! **Estimator: instrumental variables, several windows.** The data come from a loop, so the
//! regressor `Z_q` (the integrals of `y` and `u` over the column) responds to the very noise
//! that forms the column's error `E_q = ΔY_q − Θ Z_q`: the ordinary estimate is biased, and
//! for a candidate gain less aggressive than the exploring one the bias raises `β̂` (toward
//! certifying). The calibrated certificate therefore solves its own instrumented regression
//! ([`streamcert_regression::InstrumentedWindows`]): the instrument stacks the regressors of
//! the `J` intervals (`instrument_intervals`, default 1) that end `L` samples (the
//! *instrument lag*, default 1) before the column starts; the estimate is instrumental
//! variables for `J = 1` and two-stage least squares (over-identified, finite moments) for
//! `J >= 2`. The instrument is built from data before the column's noise, so it is
//! uncorrelated with `E_q` under white process noise and under white sensor noise on `y`
//! (errors in variables); sensor noise correlated over `c` samples needs `L >= c`. It runs on
//! windows `M, 2M, 4M, …` side by side (`windows`, up to `max_window`).
//!
//! **Radius.** For window `w` with `n` columns, `T = [I_p; K]`, `Ĵ_cl = Θ̂ T`,
//! `β̂_w = −λ_max(sym Ĵ_cl)`, and
//!
//! ```text
//! ρ_w = t_ν(1 − δ_{w,k}) · √σ²_max,         β_cal,w = β̂_w − ρ_w
//! σ²_max = λ_max(Ω̂)   (p = 2: the smaller of that and the rank-one bound)
//! Ω̂  = batch-means covariance over blocks of h columns of each block's delete-one-block
//!       change vec(sym((Θ̂ − Θ̂_(j)) T))   (the jackknife; exact for the default J = 1)
//! ν   = min(B, (Σ_j w_j)² / Σ_j w_j²) − u,   w_j = tr(X_jᵀ H_j X_j)  (block j's weight)
//! u   = p + m unknowns per output (+ 1: the affine model's intercept, regressor τ)
//! ```
//!
//! (see [`InstrumentedWindows::estimate`](streamcert_regression::InstrumentedWindows::estimate)
//! for `Ω̂` and the scores `g_q`). Why each factor:
//! * Let `v*` be the top eigenvector of `sym J_cl` (true, unknown, but fixed). Then
//!   `λ_max(sym J_cl) = v*ᵀ sym(Ĵ − ΔJ) v* <= λ_max(sym Ĵ) − v*ᵀ ΔJ v*`, so
//!   `β̂ − β* <= −v*ᵀ ΔJ v*` exactly: a one-sided bound needs the tail of one scalar linear
//!   functional of the noise, not of `‖ΔJ‖` (no `χ²_{p²}` quantile, no union over
//!   directions). Its variance is `vec(vvᵀ)ᵀ Ω vec(vvᵀ) <= λ_max(Ω)` for every unit `v`; for
//!   `p = 2` the maximum over rank-one `vvᵀ` is bounded directly
//!   ([`rank_one_variance_bound`]).
//! * Why not the variance in the estimated direction, or a bound over every direction at
//!   once? Measured; see *Efficiency* below.
//! * Consecutive columns overlap in `h − 1` of their `h` sample intervals; batch means over
//!   blocks of `h` columns with the overlap factor `3h²/(2h² + 1)` estimate the long-run
//!   variance of the scores (exact in expectation for the triangular correlation of white
//!   process noise, conservative for white sensor noise, positive semi-definite by
//!   construction). With [`Calibration::batch_blocks`] `= b > 1` the blocks are summed in
//!   batches of `b` (factor `3bh²/(3bh² − h² + 1)`, `B` the number of batches): less
//!   conservative under sensor noise, fewer degrees of freedom.
//! * `Ω̂` is estimated from `B` block sums that carry unequal weight (a window where the
//!   dither rarely switched has a few heavy blocks): the Welch–Satterthwaite effective number
//!   of blocks, less one per unknown, is the Student-t's degrees of freedom. With the nominal
//!   `B − d` instead, the studentised estimate exceeded the `10⁻³` and `10⁻⁴` quantiles 1.7
//!   to 2 times too often on the study's scalar cells (measured with
//!   `cargo xtask validity`); with the effective number it does not.
//!
//! **Looks and risk.** Window `w` *looks* (computes its certificate) once it is full and then
//! every `⌈look_spacing · B_w⌉` blocks of `h` columns (`B_w = ⌊M_w/h⌋`), at a block
//! boundary; between looks its latest certificate is held. Its
//! `k`-th look spends
//!
//! ```text
//! δ_{w,k} = (1 − a) δ · share_w · 1 / (k (k + 1)),   share_w = 1 / W,   Σ_{w,k} δ_{w,k} = (1 − a) δ
//! ```
//!
//! (`a` the anchored window's share, below), so
//! by the union bound the probability that any look of any window, or of the anchored window,
//! overstates a rate below the margin is at most `δ` for a run of any length and any stopping
//! rule. By default every sliding window gets the same share `1 / W` (`W` windows): each
//! doubling of the window is one more time scale the loop may need, and none is favoured;
//! [`RiskSplit::ByLength`](crate::RiskSplit::ByLength) gives the longer windows more
//! (`M_w / Σ M_v`, the split before). The price of the
//! schedule is decision time: a window certifies at its looks only, up to
//! `⌈look_spacing · B_w⌉ · h` samples after the data would allow it.
//!
//! **The anchored window** ([`Calibration::anchored_share`], default `a = 0.9`). A sliding
//! window's radius stops shrinking at the longest window; the anchored window holds every block
//! since its *epoch* began (the start, a gap, or a change point) in at most 256 records that
//! merge in pairs as it grows
//! ([`AnchoredWindow`](streamcert_regression::AnchoredWindow): the delete-a-record jackknife
//! with the overlap factor of the record's blocks). It looks when it holds
//! `⌈B_0 g^(j−1)⌉` blocks (`g = √2`, `B_0` the shortest window's), with the same estimate,
//! variance, second covariance and Student-t radius as a window, at the risk
//! [`anchored_look_risk`]`(δ, a, e, j, K)`: 90 % of `a δ` for the first epoch, 90 % of an
//! epoch's part shared equally by its first `K = 11` looks (sizes `M` to `32 M`), a
//! decreasing tail after. Where the verdicts are made: the sliding windows' first looks see
//! exactly the anchored window's data at sizes `M 2^i`, so most of `δ` is spent once, on the
//! window that holds the most data. Its look stands only where every guard admits it as the
//! longest full window's (the change guard's fresh estimates of every window; that window's
//! model tests, which must have run, and a rejection of a longer window's). Closing never costs
//! validity, so a held comparison of the change guard closes it until the next comparison,
//! as for a window, and so does a newer look with an upper bound below the margin; a change
//! point after the epoch began, or a fresh estimate below it at the split test's smaller
//! risk, starts a new epoch, so that it holds no data from before a change (VALIDITY.md's
//! plant-change table). Without the change guard (`plant_change = false`) only a gap starts
//! one.
//!
//! Measured against the sliding windows alone and other rules in
//! [`Calibration::anchored_share`]'s docs: the loop at 5× the margin certified in 91.0 % of
//! 400 runs at a median 17.19 s (84.8 % at 24.19 s), the fast loops as before.
//!
//! **Combining windows, and stale certificates.** The gate is fed the largest *standing*
//! window certificate. A window's certificate stops standing when a window whose latest look is
//! at least as recent gives an upper bound `β̂_s + t_ν(1 − δ) sd_s` below the margin (one
//! look's risk `δ`, not the spending sequence: closing never costs validity, and a loose upper
//! bound would keep a stale certificate open for longer): the newer data say
//! the loop no longer contracts enough (a plant change), and the gate closes. Closing never
//! costs validity, and every opening still needs some look with `β_cal,w >= β_margin`.
//!
//! ## Measured
//!
//! `cargo xtask validity --runs 2000` (δ = 0.01; VALIDITY.md): for candidates just below the
//! margin with a one-sample gate, every accepted cell (windows 50 to 165, Gaussian, Laplace
//! and Student-t(3) noise, sensor noise, a candidate far from the exploring gain, p = 2 with
//! common-mode and unequal noise, p = 3, an operating point at `y₀ = 50` and `10⁶`, two
//! outputs with a hidden state) opened in at most 12 of 2000 runs, with the 95 %
//! Clopper–Pearson upper bound at most 2δ (the defaults: the affine model, every guard, five
//! windows at an equal share of `δ`, the relative ridge and the delete-one-block variance);
//! so did every cell of the held-input family (inputs held 0.2 to 30 s, at most 9 of 2000)
//! and of the units family (0 of 2000 at every scale). With the first-order variance and the
//! absolute ridge before, the cells at `M = 50` to 150 opened in 12 to 18 of 2000, and the
//! held-input cells in up to 921 of 1000 (`--only-held 1000` on those fits). With the
//! automatic batches of a fixed 8 blocks before,
//! in the first 1000 of those runs (`--runs 1000` runs them) the cell at `M = 50` opened in
//! 14 (upper bound 0.0234, above 2δ), in the second 1000 in 4 (17 of 2000 with about 30
//! batches per window); at 1000 runs under
//! the split by length (before) it had opened in 10. With the nominal `B − (p + m)` degrees
//! of freedom instead of the effective number, the scalar cells opened in 14 to 28 of 1000
//! (an earlier commit).
//!
//! ## Efficiency against a one-look oracle
//!
//! VALIDITY.md splits the longest window's ratio `ρ / (z(1 − δ) sd(β̂))` into the look
//! spending `t / z` (1.51 to 1.93: Student's t at the last look's `δ_{w,k}` over the
//! one-look `z`) and the spread factor `sd used / sd(β̂)`: 0.86 to 0.99 in the scalar cells
//! without sensor noise (the just-identified estimate's spread across runs exceeds its
//! batch-means sd, its tails being heavier than the normal; the spending covers it, every
//! cell stays within 2δ), 1.20 to 1.86 for `p >= 2`, 1.01 (near the margin) and 1.29 (the
//! power cell) under sensor noise with the automatic batches. With the spending near 1.5
//! alone, a ratio of at most 1.6 needs a spread factor of about 1. Measured with
//! `cargo xtask validity --runs 1000` on variants of this module (none kept):
//! * `p >= 2`, the variance in the estimated direction `vec(v̂v̂ᵀ)ᵀ Ω̂ vec(v̂v̂ᵀ)` (`v̂` the top
//!   eigenvector of `sym Ĵ`, the delta method): ratios 1.55 (`p = 3`) and 1.53
//!   (common-mode), but the unequal-noise cell opened falsely in 251 of 1000 runs (q99 of
//!   `(β̂ − β*)/ρ` 2.52): where `v̂` swings toward the quiet output the plug-in variance is
//!   the quiet output's. Used only when the estimated eigengap exceeds 3 `√λ_max(Ω̂)`:
//!   unequal 5 of 1000 and 1.53, common-mode 2.03, `p = 3` 2.99; a Davis–Kahan cone from a
//!   Hotelling bound on `‖ΔJ‖` is never informative at these gaps.
//! * `p >= 2`, a bound valid in every direction at once (`max_v vᵀŜv + c √q̂(v)`, Hotelling's
//!   `c` over the `p(p + 1)/2` entries of `sym ΔJ`, a Lipschitz branch and bound over the
//!   sphere, the smaller of it and the present radius at half the risk each): 2.23, 1.90,
//!   3.20 and 2.11 (common-mode, unequal, `p = 3`, the `p = 2` power cell) against 2.37,
//!   1.86, 3.04 and 2.23; `c` exceeds `t` by about what the direction saves.
//! * Sensor noise, chosen automatically ([`Calibration::auto_batches`], the default): beside
//!   the covariance in batches of one block, every window of `B_w` blocks computes it in
//!   about 30 batches at the same look (`b_w = ⌊B_w / max(30, 2d + 1)⌋` blocks each, where
//!   `b_w >= 2`: 2, 4, 8, 16 for the four longer default windows from `M = 150`); the batched
//!   radius at [`Calibration::auto_batch_risk`] of the look's risk (default a fifth), the
//!   first at the rest, the smaller standing (the union bound keeps the look's risk). At half
//!   each, the scalar power cell at 20× the margin certified at a median 3.94 s (VALIDITY.md
//!   at f06157c, `cargo xtask validity --runs 1000`); at a fifth at 3.19 s, as without the
//!   second radius. A fixed number of batches rather than a fixed size: sensor noise
//!   telescopes across blocks, so batches of `b` overstate the spread by about `√(1 + c/b)`
//!   (`c ≈ 10` on the sensor power cell), and the longest windows, which decide the late
//!   looks, get the largest batches while every window keeps about 27 degrees of freedom.
//!   On the sensor power cell (100 runs each, power cells only): batches of a fixed 8
//!   blocks (the rule before) spread factor 1.45, median first opening 6.19 s; about 20, 30
//!   and 40 batches per window 1.11, 1.24 and 1.32 at 3.19, 3.19 and 6.19 s, the efficiency
//!   ratio `ρ / (z·sd)` 2.57, 2.52 and 2.56 (2.69 before): 30 is the default. The other
//!   scalar power cells' shares and medians matched under the four rules but for one run of
//!   the 5× cell (88 or 89 of 100). In VALIDITY.md (400 runs) the power
//!   cell went from 1.52 and 4.69 s to 1.29 and 3.19 s, the near-margin sensor cell's spread
//!   factor from 1.05 to 1.01, with 0 of 2000 false openings under both. (Batches of a
//!   fixed 16 blocks, measured at an earlier commit on four windows, left the longest window
//!   15 batches: the power cell's spread factor 1.33 but the near-margin sensor cell's 1.47,
//!   the batched radius losing to its Student-t quantile: a count keeps the degrees of
//!   freedom.)
//! * Sensor noise: batches of `b` blocks ([`Calibration::batch_blocks`], kept as an option):
//!   in VALIDITY.md the sensor cell's spread factor falls from 1.78 to 1.23 and 1.07 for
//!   `b = 4, 8` and the power cell's from 3.92 to 2.06 and 1.42, but the spending rises (1.78
//!   to 2.05, fewer degrees of freedom), so the ratios are 2.20 and 2.22 (from 2.83) and 3.53
//!   and 2.70 (from 6.21); every batched cell, down to the smallest window each setting
//!   accepts, opened falsely in at most 1 of 1000 runs. The shortest windows hold few
//!   batches, so decisions can come later (the power cell's median time 3.19 s at `b = 4`,
//!   6.19 s at `b = 8`). Without sensor noise `b = 1` is tighter.
//! * Sensor noise, the lag-one cross products of neighbouring blocks added with weight one
//!   (unbiased in expectation for the triangular and the telescoping correlation; no overlap
//!   factor, a third of the effective blocks): 1.56 and 2.13, but the sensor cell opened
//!   falsely in 69 of 1000 runs (39 with the correction only on windows of at least 100
//!   blocks): not valid.
//!
//! ## Assumptions (when one fails the guarantee is void)
//! * The closed-loop Jacobian is constant over each window (linear dynamics, or a nonlinear
//!   system explored over a region where its Jacobian does not vary). The certificate speaks
//!   for the averaged linearisation over its window's region
//!   ([`Certifier::calibrated_region`](crate::Certifier::calibrated_region)). With a
//!   [`NonlinearConfig`](crate::NonlinearConfig), a window's linear certificate stands only
//!   where the nonlinearity test of the same window ran and found no variation; the test has
//!   limited power on short windows, so for a loop whose rate varies over the region the
//!   nonlinear certificate is the one to deploy on (`cargo xtask nonlinear` measures both).
//! * Process noise is white; sensor noise, if any, is white beyond `L` samples; both are
//!   independent of the exploration signal. Heavy tails with finite variance are covered
//!   through the central limit theorem over the blocks (measured for Laplace and
//!   Student-t(3) in `cargo xtask validity`).
//! * The exploration makes the instruments relevant and identifies the rate (a dither held
//!   over more than `h` samples, moving several times per window): a regressor that never
//!   moved beyond the intercept in a window (a zero or collinear column: pivot ratio of the
//!   equilibrated `A` below `max(min_excitation_ratio, 10³ λ)`), or a block that alone
//!   identifies a direction, refuses the look
//!   ([`NotCertified::WeaklyIdentified`](crate::NotCertified::WeaklyIdentified)); where the
//!   information sits in a few blocks, the jackknife puts each block's leverage back into
//!   the variance and the effective number of blocks (`ν`) falls. Measured on step tests
//!   (inputs held 0.2 to 30 s) in VALIDITY.md's held-input table.
//! * The fits' ridge is relative to each diagonal entry ([`Calibration::relative_ridge`],
//!   `10⁻¹²`), so the verdict is the same in any units of `y` and `u` (VALIDITY.md's units
//!   table; `tests/all/regression/units.rs`). An absolute ridge, as the calibrated fits had,
//!   estimated a gain the window did not identify as zero and certified on the drift alone
//!   (`cargo xtask validity --only-held 1000` on the fits as they were: a candidate of true
//!   rate −0.5 deployed in 921 of 1000 step tests held 30 s at σ = 0.1). A proportional
//!   feedback logged with a dither that did not move over a window makes `ΔY` an exact
//!   combination of the regressors (zero-order-hold `∫u` against trapezoidal `∫y`); such a
//!   window's residuals vanish and it is refused
//!   ([`MIN_RESIDUAL_SHARE`](streamcert_regression::MIN_RESIDUAL_SHARE)).
//! * The studentised instrumented estimate is close to Student's t at the window's `ν`: the
//!   smallest accepted window ([`Calibration::min_window`]) keeps `B − u >= 2` (`u` the
//!   unknowns per output: `p + m`, one more for the affine model's intercept), and
//!   `cargo xtask validity` measures the false-opening rate down to it.

mod access;
mod anchor;
mod build;
mod check;
mod config;
mod coupling;
mod look;
mod options;
mod replay;
mod trail;
mod update;
mod validate;
mod window_look;

pub(crate) use crate::look::standing;
pub use config::Calibration;
pub use coupling::{CouplingBlock, CouplingBound, CouplingConfig};
use coupling::{CouplingLook, CouplingState};
pub use options::{GuardVariance, RiskSplit};
pub use window_look::WindowLook;

pub use crate::look::quantile::{
    anchored_look_risk, calibrated_radius, look_risk, rank_one_variance_bound, t_quantile,
};

use serde::{Deserialize, Serialize};
use streamcert_regression::{
    InstrumentedWindows, Interval, RegressionConfig, WindowEstimate, linalg,
};

use crate::guard::{ChangeGuard, ModelGuard};
use crate::nonlinear::{NonlinearLook, NonlinearState};
use crate::rate::first_order::closed_loop_map;
use crate::{CertifyError, NonlinearConfig, NotCertified};
use anchor::AnchoredState;
use build::{change_guard, model_guards};
use streamcert_regression::Model;
use trail::SampleTrail;

fn one() -> f64 {
    1.0
}

/// The calibrated certificate after one sample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct CalibratedVerdict {
    /// The window look that gives the certificate (the largest standing one).
    pub best: Option<WindowLook>,
    /// Why no certificate stands, or why it cannot open.
    pub blocked: Option<NotCertified>,
    /// The nonlinear window look that gives the nonlinear certificate, when configured.
    pub nonlinear: Option<NonlinearLook>,
    /// Why no nonlinear certificate stands (`None` when one does or none is configured).
    pub nonlinear_blocked: Option<NotCertified>,
}

/// The streaming state of the calibrated certificate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct CalibratedState {
    cal: Calibration,
    horizon: usize,
    /// The calibrated fits' ridge, relative to each diagonal entry ([`Calibration::relative_ridge`]).
    ridge: f64,
    min_pivot: f64,
    windows: InstrumentedWindows,
    /// `T = [I_p; K]`, `d × p` row-major.
    tmat: Vec<f64>,
    /// Risk share per window ([`RiskSplit::shares`](crate::RiskSplit::shares)), of the
    /// sliding windows' part `sliding_share` of `δ` for the linear looks (of all of `δ` for
    /// the nonlinear certificate and the coupling bounds).
    shares: Vec<f64>,
    /// `1 − anchored_share`: the sliding windows' part of the linear certificate's `δ`.
    #[serde(default = "one")]
    sliding_share: f64,
    /// The anchored window, when its share is positive.
    #[serde(default)]
    anchored: Option<AnchoredState>,
    /// Columns of the regression already absorbed (its `columns_built`).
    seen: u64,
    /// Columns until the next look, per window (0: look at the next full column).
    until_look: Vec<usize>,
    looks: Vec<u64>,
    latest: Vec<Option<WindowLook>>,
    /// Per window, the effective moves of its latest look when the data did not identify the
    /// rate ([`NotCertified::WeaklyIdentified`]; `None` after a look that did, or before one).
    #[serde(default)]
    weak: Vec<Option<f64>>,
    /// Per window, whether its latest look's refused fit had inputs the outputs explain
    /// ([`NotCertified::InputFollowsOutputs`]; empty in states written before it, whose
    /// refusals keep their first words).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    follows: Vec<bool>,
    est: WindowEstimate,
    /// The verdict of the latest looks (`None` until computed after construction, a reset or
    /// a restore).
    #[serde(skip)]
    verdict: Option<CalibratedVerdict>,
    sym: Vec<f64>,
    eig_work: Vec<f64>,
    /// The region (output ranges, `p` per window) of each window's latest look.
    regions: Vec<Interval>,
    /// The nonlinear certificate on the same columns and looks, when configured.
    nonlinear: Option<NonlinearState>,
    /// The estimated coupling bounds on the same looks, when configured.
    #[serde(default)]
    coupling: Option<CouplingState>,
    /// The affine model ([`Model::Affine`]): every window regresses on `[∫y; ∫u; τ]`, the
    /// column's span `τ` carrying the intercept (`zaug` is that column, scratch), and the
    /// nonlinear certificate's polynomial features are taken about the regression's working
    /// origin `nl_origin`.
    affine: bool,
    zaug: Vec<f64>,
    nl_origin: f64,
    /// The model guards on the same columns and looks: hidden dynamics and nonlinearity, each
    /// its own larger fit when configured (in one fit the past increment, which carries the
    /// drift, soaks up the curvature terms' signal, and the reverse).
    model: Vec<ModelGuard>,
    /// The change guard, when configured.
    change: Option<ChangeGuard>,
    /// The column count (`seen`) at each window's latest look.
    look_cols: Vec<u64>,
    /// The newest samples, from which a checkpoint's sliding block rings are rebuilt
    /// (`replay.rs`; `None` in a state written before it, made on restore).
    #[serde(default)]
    trail: Option<SampleTrail>,
    /// `true` in a checkpoint that left the sliding block rings out (rebuilt on restore).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    rings_replayed: bool,
    // Scratch: the newest column's samples (times, outputs) and output ranges.
    ts: Vec<f64>,
    ys: Vec<f64>,
    col_range: Vec<Interval>,
}

impl CalibratedState {
    pub(crate) fn new(
        cal: Calibration,
        nonlinear: Option<NonlinearConfig>,
        coupling: Option<&CouplingConfig>,
        reg: &RegressionConfig,
        gain: &[f64],
    ) -> Result<Self, CertifyError> {
        let (p, m) = (reg.outputs, reg.inputs);
        let affine = reg.model == Model::Affine;
        // The intercept's regressor `τ` after the inputs; its row of `T` is zero.
        let d = p + m + usize::from(affine);
        let lengths = cal.window_lengths(reg.window, reg.horizon);
        let windows = InstrumentedWindows::with_regressors(
            p,
            d,
            reg.horizon,
            cal.instrument_lag,
            cal.instrument_intervals,
            &lengths,
        )?
        .with_ranges(p)
        .with_batch(cal.batch_blocks)?;
        // The change guard's fresh estimates from the segment sums (`O(1)` per estimate).
        let windows = if cal.plant_change { windows.with_moments() } else { windows };
        // The nonlinear certificate takes `τ` as one more input with gain zero.
        let mut nl_gain = gain.to_vec();
        if affine {
            nl_gain.push(0.0);
        }
        let nonlinear = nonlinear
            .map(|nl| {
                NonlinearState::new(
                    nl,
                    reg,
                    &nl_gain,
                    &lengths,
                    (cal.instrument_lag, cal.instrument_intervals, cal.hidden_dynamics),
                )
            })
            .transpose()?;
        let tmat = closed_loop_map(p, m, d, gain);
        let trail = SampleTrail::new(reg, replay::trail_cap(&windows, reg.horizon));
        let anchored = (cal.anchored_share > 0.0)
            .then(|| AnchoredState::new(&windows, &cal, p, reg.horizon))
            .transpose()?;
        Ok(Self {
            cal,
            horizon: reg.horizon,
            sliding_share: 1.0 - cal.anchored_share,
            anchored,
            ridge: cal.fit_ridge(),
            // Collinear regressors have a pivot ratio of about `2λ`: refused (see
            // `Calibration::relative_ridge`).
            min_pivot: reg.min_excitation_ratio.max(1e3 * cal.fit_ridge()),
            shares: cal.risk_split.shares(&lengths),
            until_look: vec![0; lengths.len()],
            look_cols: vec![0; lengths.len()],
            looks: vec![0; lengths.len()],
            latest: vec![None; lengths.len()],
            weak: vec![None; lengths.len()],
            follows: vec![false; lengths.len()],
            windows,
            tmat,
            seen: 0,
            est: WindowEstimate::with_regressors(p, d, cal.instrument_intervals),
            verdict: None,
            sym: vec![0.0; p * p],
            eig_work: vec![0.0; linalg::eig_work_len(p * p)],
            regions: vec![Interval::EMPTY; p * lengths.len()],
            nonlinear,
            coupling: coupling.map(|c| CouplingState::new(c.clone(), p, d - p, lengths.len())),
            affine,
            zaug: vec![0.0; d],
            nl_origin: 0.0,
            model: model_guards(&cal, reg.order, (p, d, reg.horizon), &lengths)?,
            change: change_guard(&cal, reg.horizon, &lengths),
            trail: Some(trail),
            rings_replayed: false,
            ts: vec![0.0; reg.horizon + 1],
            ys: vec![0.0; (reg.horizon + 1) * p],
            col_range: vec![Interval::EMPTY; p],
        })
    }

    /// Forget every column and look (after a regression reset).
    fn reset(&mut self) {
        self.windows.reset();
        self.seen = 0;
        // Read only beside a window's latest look, which the reset clears; zeroed so that a
        // state checkpointed before the next look passes the restore's check (`≤ seen`).
        self.look_cols.fill(0);
        self.until_look.fill(0);
        self.latest.fill(None);
        self.weak.fill(None);
        self.follows.fill(false);
        self.regions.fill(Interval::EMPTY);
        if let Some(n) = &mut self.nonlinear {
            n.reset();
        }
        if let Some(c) = &mut self.coupling {
            c.reset();
        }
        for o in &mut self.model {
            o.reset();
        }
        if let Some(c) = &mut self.change {
            c.reset();
        }
        let (cal, base) = (self.cal, self.base_blocks());
        if let Some(a) = &mut self.anchored {
            a.restart(&cal, base, 0);
        }
    }

    /// Recompute what the checkpoint does not carry (the windows' segment sums, the looks'
    /// scratch), after a restore: the same bits as the uninterrupted run.
    pub(crate) fn rebuild(&mut self) {
        if self.change.is_some() {
            self.windows.keep_moments();
        }
        // The looks' batched covariance (scratch, not serialised), sized here so that no
        // step allocates.
        let pp = self.sym.len();
        self.est.batched.score_cov.resize(pp * pp, 0.0);
        for guard in &mut self.model {
            guard.restore_scratch();
        }
        if let Some(n) = &mut self.nonlinear {
            n.restore_scratch();
        }
    }
}
