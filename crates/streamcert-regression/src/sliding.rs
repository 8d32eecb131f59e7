//! [`SlidingRegression`]: the ring buffers of samples, interval regressors and columns, and the
//! sufficient statistics over the window (see the crate docs). The per-sample update lives in
//! `update.rs`, the solve in `solve.rs`, the consistency check of a restored state in
//! `checkpoint.rs`.
//!
//! Rings: the last `h + 1` samples with their one-interval regressors `[∫y; ∫u]` (stored twice,
//! so the `h` intervals of a column are one contiguous run), the last `h + 1` regressors
//! (instruments), and `M` columns. [`SlidingRegression::ranges`] is the window's region (every
//! output and input over the last `M + h` samples, `range.rs`: the block algorithm of van Herk
//! and Gil–Werman, exact, `O(1)` per channel; the range is joined with the previous block's
//! suffix only when asked). Under the affine model the origin and the `τ`-weighted sums live in
//! `affine.rs`; for `p = m = 1` with the ordinary estimator `push` takes the scalar path of
//! `scalar.rs` (the same arithmetic in the same order, so the same bits) and `estimate` solves
//! the `2 × 2` ridge system by its closed-form inverse. The refresh's sums are formed by
//! `linalg::outer` (each entry's products added in column order, the same bits on every vector
//! width). `estimate` solves by Cholesky (ridge) or LU (instrumented); for `d >= 8` every output
//! row in one pass, and for a wide ordinary regression the two eigenvalue problems side by side.

mod affine;
mod checkpoint;
mod scalar;
mod solve;
mod update;

use serde::{Deserialize, Serialize};

use crate::{FastPath, Interval, RegressionConfig, RegressionError, SlidingRange, linalg};

/// Element-wise copy; for the short slices of the hot path a plain loop beats a `memcpy` call.
#[inline]
pub(crate) fn copy(dst: &mut [f64], src: &[f64]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d = *s;
    }
}

/// `true` when all three values are finite: `0 · x` is `±0` for a finite `x` and NaN for an
/// infinite or NaN one, so one comparison tests the three (the per-sample path's check).
#[inline(always)]
pub(crate) fn finite3(a: f64, b: f64, c: f64) -> bool {
    0.0 * a + 0.0 * b + 0.0 * c == 0.0
}

/// `(i + 1) mod cap` without a division.
#[inline]
pub(crate) fn next(i: usize, cap: usize) -> usize {
    if i + 1 == cap { 0 } else { i + 1 }
}

/// The streaming estimator. See the crate docs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlidingRegression {
    cfg: RegressionConfig,
    // Sample history, ring of h + 1 samples; `hist_head` is the newest.
    hist_t: Vec<f64>,
    hist_y: Vec<f64>,
    hist_u: Vec<f64>,
    hist_len: usize,
    hist_head: usize,
    // Regressor history for instruments, ring of h + 1 columns.
    zhist: Vec<f64>,
    zhist_len: usize,
    zhist_head: usize,
    // Column ring of M; `col_next` is where the next column goes.
    col_z: Vec<f64>,
    col_dy: Vec<f64>,
    col_w: Vec<f64>,
    col_len: usize,
    col_next: usize,
    // Sufficient statistics.
    g: Vec<f64>,
    c: Vec<f64>,
    s: Vec<f64>,
    gw: Vec<f64>,
    cw: Vec<f64>,
    since_refresh: usize,
    // Output and scratch.
    theta: Vec<f64>,
    work: Vec<f64>,
    work2: Vec<f64>,
    piv: Vec<usize>,
    z: Vec<f64>,
    dy: Vec<f64>,
    // Per-interval regressors `[∫y; ∫u]` over `[t_{j−1}, t_j]`, ring aligned with the sample
    // ring (slot `j` holds the interval that ends at sample slot `j`), stored twice (slots `j`
    // and `j + h + 1`) so the `h` intervals of a column are one contiguous run.
    hist_z1: Vec<f64>,
    // The newest single sample interval's output increment.
    dy1: Vec<f64>,
    // `1 / M`, so the per-sample estimate needs no division for it (checked on restore).
    inv_window: f64,
    // Columns built since construction or the last reset.
    #[serde(default)]
    built: u64,
    // The largest value of each diagonal running sum (`G_ii`, then `S_ii`) since the last
    // exact recompute.
    #[serde(default)]
    peaks: Vec<f64>,
    // Range of each output and input over the last `M + h` samples (the window's region).
    range: SlidingRange,
    // The affine model (`Model::Affine`; untouched through the origin): the working origin
    // `[y; u]` of the integrals (the first sample since construction, kept across resets),
    // each column's span `τ`, the window sums `a_z = Σ Z τ_w`, `a_y = Σ ΔY τ_w`,
    // `T = Σ τ τ_w`, `a_w = Σ W τ` (`τ_w = τ` for the ordinary estimator, the instrument's
    // own span for the instrumented one), and the latest estimate's intercept `ĉ` (scratch).
    origin: Vec<f64>,
    origin_set: bool,
    col_tau: Vec<f64>,
    // The instrumented estimator's: each column's instrument's span `τ_w` (ring of `M`) and the
    // spans of the regressors held for instruments (ring of `h + 1`, aligned with `zhist`).
    col_tauw: Vec<f64>,
    zhist_tau: Vec<f64>,
    // The instrumented estimator's sums with the column's own span, `Σ Z τ`, `Σ ΔY τ`,
    // `Σ τ²` (its Gram matrix and residual sum of squares are centred by these).
    zto: Vec<f64>,
    dyto: Vec<f64>,
    tto: f64,
    zt: Vec<f64>,
    dyt: Vec<f64>,
    tt: f64,
    wt: Vec<f64>,
    intercept: Vec<f64>,
    // The span of the newest column (scratch of the general push).
    tau: f64,
    // The centred statistics the estimate solves (scratch; swapped with the running sums
    // for the solve).
    centred: Centred,
}

/// Scratch for the centred statistics `ZZᵀ − a_z a_zᵀ/T`, … (see [`Model::Affine`]).
///
/// [`Model::Affine`]: crate::Model::Affine
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Centred {
    g: Vec<f64>,
    c: Vec<f64>,
    s: Vec<f64>,
    gw: Vec<f64>,
    cw: Vec<f64>,
}

impl SlidingRegression {
    /// Validate the configuration and reserve every buffer.
    ///
    /// # Errors
    /// [`RegressionError::InvalidConfig`].
    ///
    /// ```
    /// use streamcert_regression::{RegressionConfig, RegressionError, SlidingRegression};
    /// assert!(SlidingRegression::new(RegressionConfig::new(1, 1, 150, 5, 1e-4)).is_ok());
    /// let err = SlidingRegression::new(RegressionConfig::new(1, 1, 150, 0, 1e-4)).unwrap_err();
    /// assert!(matches!(err, RegressionError::InvalidConfig { field: "horizon", .. }));
    /// ```
    pub fn new(cfg: RegressionConfig) -> Result<Self, RegressionError> {
        cfg.validate()?;
        let (p, m, h, mm) = (cfg.outputs, cfg.inputs, cfg.horizon, cfg.window);
        let d = p + m;
        Ok(Self {
            cfg,
            hist_t: vec![0.0; h + 1],
            hist_y: vec![0.0; (h + 1) * p],
            hist_u: vec![0.0; (h + 1) * m],
            hist_len: 0,
            hist_head: 0,
            zhist: vec![0.0; (h + 1) * d],
            zhist_len: 0,
            zhist_head: 0,
            col_z: vec![0.0; mm * d],
            col_dy: vec![0.0; mm * p],
            col_w: vec![0.0; mm * d],
            col_len: 0,
            col_next: 0,
            g: vec![0.0; d * d],
            c: vec![0.0; p * d],
            s: vec![0.0; p * p],
            gw: vec![0.0; d * d],
            cw: vec![0.0; p * d],
            since_refresh: 0,
            theta: vec![0.0; p * d],
            work: vec![0.0; linalg::eig_work_len(d)],
            work2: vec![0.0; d * d],
            piv: vec![0; d],
            z: vec![0.0; d],
            dy: vec![0.0; p],
            hist_z1: vec![0.0; 2 * (h + 1) * d],
            dy1: vec![0.0; p],
            inv_window: 1.0 / mm as f64,
            built: 0,
            peaks: vec![0.0; d + p],
            range: SlidingRange::new(d, cfg.window + cfg.horizon)?,
            origin: vec![0.0; d],
            origin_set: false,
            col_tau: vec![0.0; mm],
            col_tauw: vec![0.0; mm],
            zhist_tau: vec![0.0; h + 1],
            zto: vec![0.0; d],
            dyto: vec![0.0; p],
            tto: 0.0,
            zt: vec![0.0; d],
            dyt: vec![0.0; p],
            tt: 0.0,
            wt: vec![0.0; d],
            intercept: vec![0.0; p],
            tau: 0.0,
            centred: Centred {
                g: vec![0.0; d * d],
                c: vec![0.0; p * d],
                s: vec![0.0; p * p],
                gw: vec![0.0; d * d],
                cw: vec![0.0; p * d],
            },
        })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &RegressionConfig {
        &self.cfg
    }

    /// Number of columns in the window.
    #[must_use]
    pub fn columns(&self) -> usize {
        self.col_len
    }

    /// Time of the newest accepted sample, if any.
    #[must_use]
    pub fn last_time(&self) -> Option<f64> {
        (self.hist_len > 0).then(|| self.hist_t[self.hist_head])
    }

    /// The region of the window: the range of each output, then each input, over the last
    /// `M + h` samples accepted since the last reset (the samples the window's `M` columns
    /// integrate, for the ordinary estimator). A linear certificate speaks for the averaged
    /// linearisation over this region, nothing more. [`Interval::EMPTY`] before the first
    /// sample. Formed on each call (`O(p + m)`; see [`SlidingRange::ranges`]).
    ///
    /// [`SlidingRange::ranges`]: crate::SlidingRange::ranges
    pub fn ranges(&self) -> impl ExactSizeIterator<Item = Interval> + '_ {
        self.range.ranges()
    }

    /// The `h + 1` samples of the newest column, oldest first: times into `t` (length
    /// `h + 1`) and outputs into `y` (`(h + 1) p` values, one sample's outputs after
    /// another). `false` (buffers untouched) before `h + 1` samples are held.
    ///
    /// # Panics
    /// If a buffer is shorter than stated.
    pub fn column_samples(&self, t: &mut [f64], y: &mut [f64]) -> bool {
        let (p, cap) = (self.cfg.outputs, self.cfg.horizon + 1);
        if self.hist_len < cap {
            return false;
        }
        let mut slot = next(self.hist_head, cap);
        let (t, y) = (&mut t[..cap], &mut y[..cap * p]);
        for i in 0..cap {
            t[i] = self.hist_t[slot];
            // Element by element: for the few values of one sample a loop beats `memcpy`.
            copy(&mut y[i * p..(i + 1) * p], &self.hist_y[slot * p..(slot + 1) * p]);
            slot = next(slot, cap);
        }
        true
    }

    /// The range of each output over the `h + 1` samples of the newest column, into `out`
    /// (`p` values); `false` (untouched) before `h + 1` samples are held. `O(h p)`, no copy.
    #[inline(always)]
    pub fn newest_column_ranges(&self, out: &mut [Interval]) -> bool {
        let (p, cap) = (self.cfg.outputs, self.cfg.horizon + 1);
        if self.hist_len < cap {
            return false;
        }
        let ys = &self.hist_y[..cap * p];
        if let ([r], 1) = (&mut out[..1], p) {
            let (mut lo, mut hi) = (ys[0], ys[0]);
            for &v in &ys[1..] {
                (lo, hi) = (if v < lo { v } else { lo }, if v > hi { v } else { hi });
            }
            *r = Interval { lo, hi };
            return true;
        }
        for (i, r) in out[..p].iter_mut().enumerate() {
            let (mut lo, mut hi) = (ys[i], ys[i]);
            for s in 1..cap {
                let v = ys[s * p + i];
                (lo, hi) = (if v < lo { v } else { lo }, if v > hi { v } else { hi });
            }
            *r = Interval { lo, hi };
        }
        true
    }

    /// The newest column `(Z_q, ΔY_q)`, if any.
    #[must_use]
    #[inline]
    pub fn newest_column(&self) -> Option<(&[f64], &[f64])> {
        if self.col_len == 0 {
            return None;
        }
        let (d, p, mm) = (self.d(), self.cfg.outputs, self.cfg.window);
        let q = if self.col_next == 0 { mm - 1 } else { self.col_next - 1 };
        Some((&self.col_z[q * d..(q + 1) * d], &self.col_dy[q * p..(q + 1) * p]))
    }

    /// Columns built since construction or the last [`reset`](Self::reset) (the window
    /// clears itself on [`RegressionError::Overflow`]): a consumer of
    /// [`newest_column`](Self::newest_column) compares it with the count it last saw.
    #[must_use]
    pub fn columns_built(&self) -> u64 {
        self.built
    }

    fn d(&self) -> usize {
        self.cfg.order.width(self.cfg.outputs, self.cfg.inputs)
    }

    /// The code path of this regression's shape ([`LoopModel::fast_path`]).
    #[inline(always)]
    fn fast_path(&self) -> FastPath {
        self.cfg.order.fast_path(self.cfg.outputs, self.cfg.inputs)
    }

    /// Forget every sample and column (the configuration is kept).
    pub fn reset(&mut self) {
        self.built = 0;
        self.range.reset();
        self.peaks.fill(0.0);
        self.hist_len = 0;
        self.zhist_len = 0;
        self.col_len = 0;
        self.col_next = 0;
        self.since_refresh = 0;
        for v in [&mut self.g, &mut self.c, &mut self.s, &mut self.gw, &mut self.cw] {
            v.fill(0.0);
        }
        self.clear_affine();
    }

    /// Zero the affine model's window sums.
    fn clear_affine(&mut self) {
        for v in [&mut self.zt, &mut self.dyt, &mut self.wt, &mut self.zto, &mut self.dyto] {
            v.fill(0.0);
        }
        self.tt = 0.0;
        self.tto = 0.0;
    }

    /// `true` for [`Model::Affine`](crate::Model::Affine).
    #[inline(always)]
    pub(crate) fn affine(&self) -> bool {
        self.cfg.model == crate::Model::Affine
    }

    /// The working origin `[y; u]` the integrals are taken relative to: the first sample
    /// since construction for the affine model (kept across [`reset`](Self::reset)), zero
    /// through the origin or before the first sample. `Z` from
    /// [`newest_column`](Self::newest_column) and [`newest_interval`](Self::newest_interval)
    /// is `∫ (y − y_o)` and `∫ (u − u_o)`; under the affine model every estimate is the same
    /// for any origin (in exact arithmetic), and the origin keeps the sums' digits.
    #[must_use]
    pub fn origin(&self) -> &[f64] {
        &self.origin
    }

    /// A regression that starts from the working origin `origin` (`[y; u]`, `p + m` values)
    /// instead of its first sample: the same configuration fed the samples that followed that
    /// first one then builds the same columns bit for bit (a state's replay from its recent
    /// samples). Through the origin, or with the wrong length, the origin stays unset.
    #[must_use]
    pub fn with_origin(mut self, origin: &[f64]) -> Self {
        if origin.len() == self.d() {
            self.set_origin(&origin[..self.cfg.outputs], &origin[self.cfg.outputs..]);
        }
        self
    }

    /// The newest sample `(t, y, u)` absorbed since the last [`reset`](Self::reset), if any.
    #[must_use]
    #[inline]
    pub fn newest_sample(&self) -> Option<(f64, &[f64], &[f64])> {
        let (p, m, k) = (self.cfg.outputs, self.cfg.inputs, self.hist_head);
        (self.hist_len > 0).then(|| {
            (self.hist_t[k], &self.hist_y[k * p..(k + 1) * p], &self.hist_u[k * m..(k + 1) * m])
        })
    }

    /// The span `τ = t_new − t_old` of the newest column, if any (the regressor of the
    /// affine model's intercept).
    #[must_use]
    #[inline]
    pub fn newest_column_span(&self) -> Option<f64> {
        (self.col_len > 0).then(|| {
            let q = if self.col_next == 0 { self.cfg.window - 1 } else { self.col_next - 1 };
            self.col_tau[q]
        })
    }

    /// The span `t_k − t_{k−1}` of the newest sample interval, once two samples are in.
    #[must_use]
    #[inline]
    pub fn newest_interval_span(&self) -> Option<f64> {
        let cap = self.cfg.horizon + 1;
        let b = self.hist_head;
        let a = if b == 0 { cap - 1 } else { b - 1 };
        (self.hist_len >= 2).then(|| self.hist_t[b] - self.hist_t[a])
    }

    /// The newest sample interval's two samples `(t_{k−1}, t_k, y_{k−1}, y_k)` (outputs, `p`
    /// each), once two samples are in: what a caller that keeps per-interval terms of its
    /// own (the curvature guard's integrals of `y²` and `y³`) adds at each sample, `O(1)`.
    #[must_use]
    #[inline]
    pub fn newest_interval_samples(&self) -> Option<(f64, f64, &[f64], &[f64])> {
        let (p, cap) = (self.cfg.outputs, self.cfg.horizon + 1);
        let b = self.hist_head;
        let a = if b == 0 { cap - 1 } else { b - 1 };
        (self.hist_len >= 2).then(|| {
            let (ya, yb) = (&self.hist_y[a * p..(a + 1) * p], &self.hist_y[b * p..(b + 1) * p]);
            (self.hist_t[a], self.hist_t[b], ya, yb)
        })
    }

    /// Check a sample without absorbing it.
    ///
    /// # Errors
    /// [`RegressionError::DimensionMismatch`], [`RegressionError::NonFinite`],
    /// [`RegressionError::NonIncreasingTime`].
    #[inline]
    pub fn check_sample(&self, t: f64, y: &[f64], u: &[f64]) -> Result<(), RegressionError> {
        let (p, m) = (self.cfg.outputs, self.cfg.inputs);
        if y.len() != p {
            return Err(RegressionError::DimensionMismatch {
                field: "y",
                expected: p,
                got: y.len(),
            });
        }
        if u.len() != m {
            return Err(RegressionError::DimensionMismatch {
                field: "u",
                expected: m,
                got: u.len(),
            });
        }
        if !t.is_finite() {
            return Err(RegressionError::NonFinite { field: "t", index: 0, value: t });
        }
        // One branch for the common all-finite case; the search for the culprit only runs on
        // a bad sample.
        let mut finite = true;
        for x in y.iter().chain(u) {
            finite &= x.is_finite();
        }
        if !finite {
            for (field, v) in [("y", y), ("u", u)] {
                if let Some((index, &value)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
                    return Err(RegressionError::NonFinite { field, index, value });
                }
            }
        }
        if let Some(previous) = self.last_time()
            && t <= previous
        {
            return Err(RegressionError::NonIncreasingTime { previous, got: t });
        }
        Ok(())
    }

    /// The newest single sample interval `(Z, ΔY)` (one-step regressor and output increment),
    /// once two samples are in. Its residual `ΔY − Θ̂ Z` keeps the tails of the per-step
    /// noise that the `h`-step columns average away.
    #[must_use]
    #[inline]
    pub fn newest_interval(&self) -> Option<(&[f64], &[f64])> {
        let d = self.d();
        let b = self.hist_head;
        (self.hist_len >= 2).then_some((&self.hist_z1[b * d..(b + 1) * d], &self.dy1[..]))
    }

    /// The sufficient statistics `(G = ZZᵀ, C = ΔY Zᵀ, S = ΔY ΔYᵀ)`, row-major; only the
    /// upper triangles of `G` and `S` are maintained. Raw sums of the working coordinates
    /// (see [`origin`](Self::origin)); the affine model solves their centred form (see
    /// [`affine_statistics`](Self::affine_statistics)).
    #[must_use]
    pub fn statistics(&self) -> (&[f64], &[f64], &[f64]) {
        (&self.g, &self.c, &self.s)
    }

    /// The affine model's window sums `(a_z = Σ Z τ, a_y = Σ ΔY τ, T = Σ τ²)` (zero through
    /// the origin).
    #[must_use]
    pub fn affine_statistics(&self) -> (&[f64], &[f64], f64) {
        (&self.zt, &self.dyt, self.tt)
    }
}
