//! [`Calibration`]: the settings of the calibrated certificate and their validation against
//! the regression and the margin.

use serde::{Deserialize, Serialize};

use super::options::{GuardVariance, RiskSplit};

/// Settings of the calibrated certificate. Only `delta` is required; the rest have documented
/// defaults.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// Risk `δ ∈ (0, 1)` over the whole run.
    pub delta: f64,
    /// Number of windows `M, 2M, 4M, …`. `None` (default): double from `M` until there are at
    /// least five and the longest holds at least 200 blocks of `h` columns (about 200 degrees
    /// of freedom, where the Student-t quantile at the risks a look spends is within 2 % of the
    /// normal one), at most 16. At least five, so that the longest window spans `16 M`: with
    /// the affine model's intercept a window learns nothing from the loop's level, which a
    /// longer window makes up for (VALIDITY.md's power cell at 5× the margin). `Some(n)`:
    /// exactly `n` (`1..=16`).
    #[serde(default)]
    pub windows: Option<usize>,
    /// Cap on the window length in columns: windows above it are dropped (default none), and
    /// the anchored window ([`anchored_share`](Self::anchored_share)) looks only at sizes up
    /// to it, its latest look dropped once it holds more (data older than the cap are then
    /// in no standing look).
    #[serde(default)]
    pub max_window: Option<usize>,
    /// A window looks every `⌈look_spacing · B_w⌉` blocks of `h` columns once full
    /// (`B_w = ⌊M_w/h⌋`; default 0.5; `(0, 1]`).
    #[serde(default = "default_look_spacing")]
    pub look_spacing: f64,
    /// Instrument lag `L` in samples (default 1: valid under white sensor noise).
    #[serde(default = "default_lag")]
    pub instrument_lag: usize,
    /// Instrument intervals `J` (default 1; `1..=8`): the instrument stacks the regressors of
    /// the `J` intervals before the column, so for `J >= 2` the estimate is two-stage least
    /// squares over-identified by `(J − 1)(p + m)` restrictions (finite moments up to that
    /// order). `cargo xtask validity` measured `J = 1` and `J = 3` alike on every cell (the
    /// studentised estimate is what the bound uses), and `J = 1` costs a ninth of the outer
    /// products for `p = m = 1`.
    #[serde(default = "default_intervals")]
    pub instrument_intervals: usize,
    /// Blocks of `h` columns per batch of the batch-means covariance `Ω̂` (default 1;
    /// `1..=8`). Sensor noise on `y` enters `ΔY_q` and `ΔY_{q+h}` with opposite signs, so it
    /// telescopes in a window's sum but batch means count it once per batch boundary: under
    /// sensor noise the radius is then several times what the estimate's spread needs.
    /// Batches of `b` blocks have `b` times fewer boundaries, at the price of `b` times fewer
    /// degrees of freedom and a window at least `h (b (p + m + 1) + 1)` columns long
    /// ([`smallest_window`](Self::smallest_window)). `cargo xtask validity` measures `b = 4`
    /// and `8` on the sensor-noise cells and at their smallest windows (VALIDITY.md); without sensor noise `b = 1` is tighter. It
    /// applies to the linear calibrated certificate and its coupling bounds; the nonlinear
    /// certificate keeps batches of one block.
    #[serde(default = "default_batch", skip_serializing_if = "is_default_batch")]
    pub batch_blocks: usize,
    /// The number of batches of a second covariance computed beside the first at every look
    /// of a window long enough for it (default 30; 0 turns it off): window `w` of `B_w`
    /// blocks cuts its blocks into batches of
    ///
    /// ```text
    /// b_w = ⌊B_w / n⌋ blocks,   n = max(auto_batches, 2d + 1)     (d the regressors)
    /// ```
    ///
    /// (so about `n` batches, `ν ≈ n − d`), on every window where `b_w >= 2`; the second
    /// radius at [`auto_batch_risk`](Self::auto_batch_risk) of the look's risk and the first
    /// at the rest, the smaller standing (valid by the union bound). Sensor noise telescopes
    /// across blocks: batches of one block count it at every block boundary, batches of `b`
    /// once per batch, so the batched spread overstates the estimate's by a factor about
    /// `√(1 + c/b)` (`c` the sensor noise's weight; about 10 on VALIDITY.md's sensor cell),
    /// and a fixed number of batches gives the longer windows, whose radius decides the
    /// late looks, the larger batches. With batches of a fixed 8 blocks (the rule before)
    /// the sensor-noise power cell's spread factor was 1.52 and its median first opening
    /// 4.69 s; with about 30 batches per window, 1.29 and 3.19 s (`cargo xtask validity
    /// --runs 2000`, VALIDITY.md; 20 and 40 batches measured in the calibrated module's
    /// docs). Without sensor noise the first radius is mostly the smaller.
    /// The linear calibrated certificate's looks only: the nonlinear certificate, the
    /// coupling bounds and the guards keep batches of one block (or `batch_blocks`).
    #[serde(default = "default_auto_batches")]
    pub auto_batches: usize,
    /// The share of each look's risk (and of `δ` in the one-look bound) that the second
    /// radius of [`auto_batches`](Self::auto_batches) spends; the first radius spends the rest
    /// (default 0.2; `(0, 1)`). Any fixed split is valid (the union bound); it decides which
    /// noise the certificate is quickest on. Without sensor noise the first radius stands
    /// and pays `1 − share` of the risk; under sensor noise the second stands, its spread a
    /// half or less of the first's, and pays `share`. At 0.5 the scalar power cell at 20× the
    /// margin certified at a median 3.94 s, at 0.2 at 3.19 s, as without the second radius
    /// (`cargo xtask validity --runs 1000`, VALIDITY.md at f06157c and as committed; it
    /// measures both noises at the default).
    #[serde(default = "default_auto_batch_risk")]
    pub auto_batch_risk: f64,
    /// The hidden-dynamics guard (default on): at every look, a larger fit with the output's
    /// past increment `ΔY_{q−h}` as one more regressor, and the Wald test of its coefficients
    /// at risk [`guard_risk`](Self::guard_risk) (default `δ / W` per look of each of the `W`
    /// windows); where a window's latest test rejects, neither its linear calibrated look nor
    /// a shorter window's stands, and a window whose test could not run does not stand
    /// (`NotCertified::HiddenDynamics`, `NotCertified::OrderUntested`). Off, a rate is
    /// certified on the first-order model even when the output carries a hidden state (a
    /// mass measured by its position), which the certificate's risk does not cover. It tests
    /// the linear model's order and gates the linear calibrated certificate. The nonlinear
    /// certificate (`[nonlinear]`) is not gated by that test (on a nonlinear loop the linear
    /// model's misfit reads as a past-increment term); with this flag on, its own larger fit
    /// (beside the lack-of-fit check's, on the library plus the past increment) gives its Wald
    /// test at the nonlinear certificate's test risk, which gates the nonlinear certificate
    /// the same way (its smallest window is that of the larger of the two fits). See the
    /// guard's module
    /// (`guard::model`) for what it sees and what it cannot.
    #[serde(default = "default_true")]
    pub hidden_dynamics: bool,
    /// The nonlinearity guard (default on, every output): at every look, the same larger fit
    /// with the square and the cube of each output's excursion integrated over the column as
    /// `2p` more regressors, and the joint Wald test of their `2p²` coefficients at risk
    /// [`guard_risk`](Self::guard_risk) (default `δ / W`); where a window's latest test rejects,
    /// neither its linear calibrated look nor a shorter window's stands
    /// (`NotCertified::VaryingDynamics`), and a window whose test could not run does not stand
    /// (`NotCertified::LinearityUntested`). Off, a loop whose slope varies over the explored
    /// region is certified on its average slope, above the smallest local rate it visits,
    /// which the certificate's risk does not cover. It needs no nonlinear certificate; for a
    /// nonlinear loop, the nonlinear certificate (`[nonlinear]`) is the one that can open.
    #[serde(default = "default_true")]
    pub nonlinearity: bool,
    /// The change guard (default on): a window's look stands only while the fresh estimates
    /// of it and of every shorter window on their newest columns are not significantly below
    /// it (one-sided, risk [`change_risk`](Self::change_risk) per comparison) and no window's
    /// older blocks are significantly above its newer ones (the split test, at a smaller
    /// risk); `NotCertified::PlantChanged`. The estimates are taken every eighth of the
    /// shortest window's blocks (the third and longer windows at slower paces) and at every
    /// look. Off, after a plant change the longer windows keep certifying the plant that was until a newer look bounds the rate below the margin (a
    /// median of several shortest-window spans). See the guard's module (`guard::change`).
    #[serde(default = "default_true")]
    pub plant_change: bool,
    /// The change guard's risk per comparison of a standing look with a fresh estimate
    /// (`None`, the default: `δ`; `(0, 1)`). A false rejection closes that look until the
    /// next comparison, an eighth of the shortest window later, so it costs a few samples of
    /// power and no validity; a larger risk closes sooner after a change (VALIDITY.md's
    /// plant-change table). The split test, whose rejection is kept as a change point and
    /// closes the longer windows until they have filled past it, keeps its own smaller risk,
    /// `δ / (W (W + 1) / 2 + W)` for `W` windows (see the guard's module, `guard::change`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub change_risk: Option<f64>,
    /// The model guards' risk per test (the hidden-dynamics and the nonlinearity tests, each
    /// at every look of every window; `None`, the default: `δ / W` for `W` windows, so that
    /// the false closings of a look stay near `δ`; `(0, 1)`). Closing costs no validity, so
    /// this is a false-closing rate, traded against protection: a larger risk lowers the
    /// tests' thresholds, so the gate closes at every sample where it closes at the default
    /// and at more (tested), sooner on a hidden state or a varying slope, more often on a
    /// plant the first-order linear model fits. It does not make the linear certificate
    /// valid on a nonlinear loop (NONLINEAR.md; the nonlinear certificate is the one that
    /// bounds every state of the region).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub guard_risk: Option<f64>,
    /// How `δ` is split across the windows (default [`RiskSplit::Equal`], `δ / W` each). Any
    /// fixed split is valid (the union bound); it decides which loops are certified sooner.
    #[serde(default, skip_serializing_if = "RiskSplit::is_equal")]
    pub risk_split: RiskSplit,
    /// The ridge of every calibrated fit *relative to each diagonal entry* (default `1e-12`;
    /// `[0, 1e-3]`): the fits solve `Q = (H + λ diag H)⁻¹ Nᵀ` and `A = N Q + λ diag(N Q)`
    /// ([`InstrumentedWindows::estimate`](streamcert_regression::InstrumentedWindows::estimate)),
    /// so that an output or input logged in other units gives the same estimate, radius and
    /// gate (to rounding), and a regressor that never moved in a window (a zero diagonal)
    /// gets no ridge and is refused instead of being estimated as zero. The regression's
    /// absolute `ridge` applies to the paper's certificates only. It guards rounding (the
    /// affine model's repeated `τ` instruments for `J >= 2` make `H` singular); it is not a
    /// prior. A fit stands only where its equilibrated pivot ratio exceeds both the
    /// regression's `min_excitation_ratio` and `10³ λ`: exactly collinear regressors (an
    /// input held over the whole window is a multiple of the intercept's `τ`) have a pivot
    /// ratio of about `2λ`, which the ridge alone lifts from zero. With
    /// `instrument_intervals >= 2` the fits use at least `10⁻⁸`
    /// ([`fit_ridge`](Self::fit_ridge)).
    #[serde(default = "default_relative_ridge")]
    pub relative_ridge: f64,
    /// The model guards' coefficient covariance (default [`GuardVariance::FirstOrder`]).
    /// A guard's test only closes looks, so its variance decides how often it closes, not
    /// the certificate's risk; see [`GuardVariance`].
    #[serde(default, skip_serializing_if = "GuardVariance::is_first_order")]
    pub guard_variance: GuardVariance,
    /// The share `a` of `δ` that the anchored window spends (default 0.9; `[0, 1)`, 0 turns
    /// it off); the sliding windows split the rest, `1 − a`, by
    /// [`risk_split`](Self::risk_split). The anchored window holds every block since its
    /// epoch began (the start, a gap, or a change point of the change guard), so its radius
    /// keeps shrinking where the sliding
    /// windows' stops at the longest window; it looks when it holds
    /// `⌈B_0 g^(j−1)⌉` blocks (`j >= 1`, `B_0` the shortest window's blocks, `g`
    /// [`anchored_growth`](Self::anchored_growth)), and its `j`-th look of epoch `e` spends
    /// [`anchored_look_risk`](crate::anchored_look_risk). The sliding windows and the guards
    /// keep closing the gate as before, and the anchored look stands only where every guard
    /// admits it (`NotCertified` names the reason as for a window).
    ///
    /// Measured (`cargo xtask validity --only-power 400`, the power table's seeds, with these
    /// settings as the defaults; the first epoch's share is fixed in
    /// [`anchored_look_risk`](crate::anchored_look_risk) and was edited there for its row; the
    /// 5× loop certified / median first opening, then the median first opening of the 20×, `p = 2`,
    /// sensor-noise and sensor-noise-in-batches-of-4 and -of-8 loops, in s):
    ///
    /// | `a`, first epoch's share, `K`, `g` | 5× loop | 20× | `p = 2` | sensor | `b = 4` | `b = 8` |
    /// |---|---|---|---|---|---|---|
    /// | off (the sliding windows alone) | 84.8 % / 24.19 | 3.19 | 6.19 | 3.19 | 3.19 | 6.79 |
    /// | 0.9, 0.9, 11, `√2` (the default) | 91.0 % / 17.19 | 3.19 | 6.19 | 3.19 | 4.44 | 4.89 |
    /// | 0.75, 0.75, 11, `√2` | 88.8 % / 18.19 | 4.44 | 8.69 | 4.44 | 4.44 | 4.89 |
    /// | 0.9, 0.9, 8, `√2` | 82.5 % / 17.19 | 3.19 | 6.19 | 3.19 | 4.44 | 3.49 |
    /// | 0.9, 0.9, 6, 2 | 82.0 % / 24.19 | 3.19 | 6.19 | 3.19 | 4.69 | 3.49 |
    /// | 0.9, 0.9, 16, 1.26 | 92.5 % / 19.29 | 3.99 | 6.24 | 3.99 | 3.99 | 4.39 |
    ///
    /// The default is no later than the sliding windows alone on the fast loops but the batched
    /// sensor cell (`b = 4`) and gains most on the 5× loop. None reaches the power target
    /// (95 % at a median of at most 12.2 s), and the data say why: at the 12 s look (the 7th,
    /// `8 M` columns) the 5× loop's median standardised excess `(β̂ − β_margin)/sd` is 2.68
    /// against the quantile 3.38 its risk `6.6·10⁻⁴` gives (VALIDITY.md's `7th anchored look`
    /// column, `cargo xtask validity`). A quantile of 2.68 at that look's `ν ≈ 97` is a
    /// one-look risk of `4.3·10⁻³`, 0.43 δ on one look of one window, and 95 % of the runs
    /// open within 40 s asks a similar share of a later look: a split that gives most of δ to
    /// the two looks this loop needs is fitted to the cell, not a rule. Two measured choices:
    /// a newer look's one-look upper bound below the margin restarted the epoch in a first
    /// version, which dropped the data of 26 of 300 runs of a 5×
    /// loop (the shortest window's just-identified estimate falls four of its spreads below the
    /// rate about once a run); and the anchored look refused by a model test of any window (not
    /// only of the longest full one's and longer) delayed the `p = 2` loop to 9.19 s.
    #[serde(default = "default_anchored_share")]
    pub anchored_share: f64,
    /// The growth `g` of the anchored window between looks (default `√2`: two looks per
    /// doubling; `(1, 4]`).
    #[serde(default = "default_anchored_growth")]
    pub anchored_growth: f64,
    /// The anchored looks `K` that share most of its risk equally (default 11: from the
    /// shortest window to 32 times it at the default growth; `1..=64`); later looks spend a
    /// decreasing tail ([`anchored_look_risk`](crate::anchored_look_risk)).
    #[serde(default = "default_anchored_looks")]
    pub anchored_looks: usize,
}

fn default_true() -> bool {
    true
}

fn default_batch() -> usize {
    1
}

fn default_auto_batches() -> usize {
    30
}

fn default_auto_batch_risk() -> f64 {
    0.2
}
#[allow(clippy::trivially_copy_pass_by_ref)] // serde's `skip_serializing_if` passes a reference
fn is_default_batch(b: &usize) -> bool {
    *b == 1
}

fn default_relative_ridge() -> f64 {
    1e-12
}

fn default_anchored_share() -> f64 {
    0.9
}

fn default_anchored_growth() -> f64 {
    std::f64::consts::SQRT_2
}

fn default_anchored_looks() -> usize {
    11
}

fn default_look_spacing() -> f64 {
    0.5
}
fn default_lag() -> usize {
    1
}
fn default_intervals() -> usize {
    1
}

impl Calibration {
    /// Risk `delta` with every other setting at its default.
    #[must_use]
    pub fn new(delta: f64) -> Self {
        Self {
            delta,
            windows: None,
            max_window: None,
            look_spacing: default_look_spacing(),
            instrument_lag: default_lag(),
            instrument_intervals: default_intervals(),
            batch_blocks: default_batch(),
            auto_batches: default_auto_batches(),
            auto_batch_risk: default_auto_batch_risk(),
            hidden_dynamics: true,
            nonlinearity: true,
            plant_change: true,
            change_risk: None,
            guard_risk: None,
            risk_split: RiskSplit::Equal,
            relative_ridge: default_relative_ridge(),
            guard_variance: GuardVariance::FirstOrder,
            anchored_share: default_anchored_share(),
            anchored_growth: default_anchored_growth(),
            anchored_looks: default_anchored_looks(),
        }
    }

    /// The anchored window's size at its `j`-th look of an epoch (`j >= 1`), in blocks of `h`
    /// columns, for a shortest window of `base` blocks: `⌈base · g^(j−1)⌉`, at least one more
    /// than the size before (so that every look holds new blocks).
    ///
    /// ```
    /// use streamcert_certificate::Calibration;
    /// let cal = Calibration::new(0.01);
    /// let sizes: Vec<u64> = (1..=5).map(|j| cal.anchored_size(30, j)).collect();
    /// assert_eq!(sizes, [30, 43, 60, 85, 120]);
    /// ```
    #[must_use]
    pub fn anchored_size(&self, base: usize, look: u64) -> u64 {
        let mut size = 0u64;
        for j in 1..=look.max(1) {
            // Less `10⁻¹²` relative, so that `√2²` (`2.0000000000000004`) is 2.
            let at =
                (base as f64 * self.anchored_growth.powf((j - 1) as f64) * (1.0 - 1e-12)).ceil();
            size = (size + 1).max(at.min(u64::MAX as f64 / 2.0) as u64);
        }
        size
    }

    /// The relative ridge the calibrated fits use: [`relative_ridge`](Self::relative_ridge),
    /// at least `10⁻⁸` for `instrument_intervals >= 2`. There the affine model's instrument
    /// repeats the column span `τ` once per interval, so `H` is singular but for the ridge;
    /// at `10⁻¹²` its condition number (about `10¹²`) left the estimate with errors of
    /// `10⁻⁵` relative (measured against a nalgebra recompute in `tests/all/calibrated.rs`).
    /// A fit then stands only where its pivot ratio exceeds `10⁻⁵`.
    #[must_use]
    pub fn fit_ridge(&self) -> f64 {
        if self.instrument_intervals >= 2 {
            self.relative_ridge.max(1e-8)
        } else {
            self.relative_ridge
        }
    }

    /// Blocks per batch of the second covariance ([`auto_batches`](Self::auto_batches)) of
    /// a window of `blocks` blocks of `h` columns with `d` regressors per output:
    ///
    /// ```text
    /// b = ⌊blocks / max(auto_batches, 2d + 1)⌋
    /// ```
    ///
    /// 0 when the second covariance is off; the window carries it when `b >= 2` (and
    /// [`batch_blocks`](Self::batch_blocks) is 1).
    ///
    /// ```
    /// use streamcert_certificate::Calibration;
    /// let cal = Calibration::new(0.01);
    /// // M = 150 doubling to 2400 columns, h = 5, d = 3 (y, u and the intercept).
    /// let b: Vec<usize> = [30, 60, 120, 240, 480].iter().map(|&n| cal.auto_batch_blocks(n, 3)).collect();
    /// assert_eq!(b, [1, 2, 4, 8, 16]);
    /// ```
    #[must_use]
    pub fn auto_batch_blocks(&self, blocks: usize, d: usize) -> usize {
        match self.auto_batches {
            0 => 0,
            n => blocks / n.max(2 * d + 1),
        }
    }

    /// The settings with every guard off: the calibrated certificate alone, whose risk then
    /// covers only plants that are linear, first order in the measured outputs and unchanged
    /// over the windows (an explicit choice; see the guards' fields for what each one gives).
    #[must_use]
    pub fn unguarded(self) -> Self {
        Self { hidden_dynamics: false, nonlinearity: false, plant_change: false, ..self }
    }

    /// The change guard's risk per held-look comparison: [`change_risk`](Self::change_risk),
    /// or `δ` when it is not set.
    #[must_use]
    pub fn change_risk(&self) -> f64 {
        self.change_risk.unwrap_or(self.delta)
    }

    /// The model guards' risk per test with `windows` windows:
    /// [`guard_risk`](Self::guard_risk), or `δ / windows` when it is not set.
    #[must_use]
    pub fn guard_risk(&self, windows: usize) -> f64 {
        self.guard_risk.unwrap_or(self.delta / windows.max(1) as f64)
    }

    /// The extra regressors per output of the model guards' larger fits for `p` outputs: `p`
    /// for the hidden-dynamics guard, `2p` for the nonlinearity guard, each in its own fit (the
    /// larger of the two counts). The larger fits' variance uses batches of one block whatever [`batch_blocks`](Self::batch_blocks) is
    /// (under sensor noise that variance is conservative, so the guards lose power, not
    /// validity), so their smallest window is [`min_window`](Self::min_window) for `u` plus
    /// these.
    #[must_use]
    pub fn guard_unknowns(&self, outputs: usize) -> usize {
        let order = if self.hidden_dynamics { outputs } else { 0 };
        let curvature = if self.nonlinearity { 2 * outputs } else { 0 };
        order.max(curvature)
    }

    /// The smallest base window with a calibrated bound: `h (u + 2)` columns for `u`
    /// unknowns per output (`p + m`, one more for the affine model's intercept, and the model
    /// guard's [`guard_unknowns`](Self::guard_unknowns)), so that the
    /// window holds at least two non-overlapping intervals per unknown plus two
    /// (`ν = ⌊M/h⌋ − u >= 2`).
    #[must_use]
    pub fn min_window(horizon: usize, unknowns: usize) -> usize {
        horizon * (unknowns + 2)
    }

    /// The smallest base window with a calibrated bound for these settings:
    /// `h (b (u + 1) + 1)` columns for batches of `b` blocks and `u` unknowns per output, so
    /// that the window holds at least `u + 2` batches (`ν >= 2`);
    /// [`min_window`](Self::min_window) for `b = 1`.
    #[must_use]
    pub fn smallest_window(&self, horizon: usize, unknowns: usize) -> usize {
        horizon * (self.batch_blocks * (unknowns + 1) + 1)
    }

    /// The window lengths for base window `base` and horizon `h`: `base · 2^i` for
    /// `i < windows` (see [`windows`](Self::windows) for the default count), those above
    /// `max_window` dropped.
    #[must_use]
    pub fn window_lengths(&self, base: usize, horizon: usize) -> Vec<usize> {
        let length = |i: usize| base.saturating_mul(1usize << i.min(30));
        let count = self.windows.unwrap_or_else(|| {
            let mut n = 5;
            while n < 16 && length(n - 1) < 200 * horizon {
                n += 1;
            }
            n
        });
        (0..count).map(length).filter(|&w| self.max_window.is_none_or(|cap| w <= cap)).collect()
    }
}
