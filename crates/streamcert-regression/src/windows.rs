//! Several sliding windows of instrumented statistics over one column stream: the regression
//! behind the calibrated certificate.
//!
//! Columns `(Z_q, ΔY_q)` arrive one per sample (from [`SlidingRegression`](crate::SlidingRegression)
//! or any other source with stride one sample and horizon `h`). Column `q` is paired with the
//! instrument
//!
//! ```text
//! W_q = Z_{q − h − L}        (the regressor of the interval that ends L samples before t_q)
//! ```
//!
//! where `L >= 0` is the instrument lag. `W_q` is built from samples up to `t_q − L·dt` only,
//! so it is uncorrelated with the error `E_q = ΔY_q − Θ Z_q` whenever that error involves
//! noise after `t_q − L·dt` only: white process noise for any `L >= 0`, white sensor noise
//! for `L >= 1` (the trapezoidal integral of `W_q` then ends before the sample `y(t_q)`
//! that `ΔY_q` differences), sensor noise correlated over `c` samples for `L >= c`.
//!
//! For each window length `M_w` (ascending) the structure keeps, over the newest `M_w`
//! instrumented columns, the sums
//!
//! ```text
//! N = Σ Z Wᵀ,  Cw = Σ ΔY Wᵀ,  H = Σ W Wᵀ,  G = Σ Z Zᵀ,  C = Σ ΔY Zᵀ,  S = Σ ΔY ΔYᵀ
//! ```
//!
//! A column costs `(W + 1)` outer products (the new one once, one eviction per window):
//! `O(W d²)`, no allocation, independent of the window lengths. Each window is recomputed
//! exactly from the ring every `M_w` columns, so rounding drift stays bounded.
//! [`InstrumentedWindows::estimate`] solves one window on demand (`O(d³)`), which the
//! calibrated certificate does only at its looks.

use serde::{Deserialize, Serialize};

use crate::{RegressionError, linalg};

/// Layout of one window's sums inside the flat statistics buffer.
#[derive(Debug, Clone, Copy)]
struct Layout {
    p: usize,
    d: usize,
}

impl Layout {
    /// `N` (d × d), `Cw` (p × d), `H` (d × d), `G` (d × d), `C` (p × d), `S` (p × p).
    fn stride(self) -> usize {
        3 * self.d * self.d + 2 * self.p * self.d + self.p * self.p
    }
    fn n(self) -> usize {
        0
    }
    fn cw(self) -> usize {
        self.d * self.d
    }
    fn h(self) -> usize {
        self.cw() + self.p * self.d
    }
    fn g(self) -> usize {
        self.h() + self.d * self.d
    }
    fn c(self) -> usize {
        self.g() + self.d * self.d
    }
    fn s(self) -> usize {
        self.c() + self.p * self.d
    }
}

/// The outcome of [`InstrumentedWindows::estimate`] for one window, in buffers the caller owns
/// (make one with [`WindowEstimate::new`] and reuse it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WindowEstimate {
    /// `true` when the fields below hold an estimate of this call.
    pub ready: bool,
    /// Instrumented columns in the window.
    pub columns: usize,
    /// `Θ̂ = Cw (N + λI)⁻¹`, `p × d` row-major.
    pub theta: Vec<f64>,
    /// Long-run covariance of the score, `p² × p²` row-major (see
    /// [`InstrumentedWindows::estimate`]): for a unit `v`, the variance of
    /// `vᵀ(Θ̂ − Θ)T v` is estimated by `vec(vvᵀ)ᵀ Ω̂ vec(vvᵀ) <= λ_max(Ω̂)`.
    pub score_cov: Vec<f64>,
    /// Pivot ratio of the LU factorisation of `N + λI` (instrument strength).
    pub pivot_ratio: f64,
    // Scratch: an LU factor, pivots, `X = (N + λI)⁻¹ T`, and one block's score sum.
    lu: Vec<f64>,
    piv: Vec<usize>,
    x: Vec<f64>,
    block: Vec<f64>,
}

impl WindowEstimate {
    /// `true` when every buffer has the length of `other`'s (a restored state's check).
    #[must_use]
    pub fn matches(&self, other: &Self) -> bool {
        self.theta.len() == other.theta.len()
            && self.score_cov.len() == other.score_cov.len()
            && self.block.len() == other.block.len()
            && self.lu.len() == other.lu.len()
            && self.piv.len() == other.piv.len()
            && self.x.len() == other.x.len()
    }

    /// Buffers for `p` outputs and `m` inputs.
    #[must_use]
    pub fn new(p: usize, m: usize) -> Self {
        let d = p + m;
        Self {
            ready: false,
            columns: 0,
            theta: vec![0.0; p * d],
            score_cov: vec![0.0; p * p * p * p],
            pivot_ratio: 0.0,
            lu: vec![0.0; d * d],
            piv: vec![0; d],
            x: vec![0.0; d * p],
            block: vec![0.0; p * p],
        }
    }
}

/// Sliding instrumented statistics over several window lengths; see the module docs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InstrumentedWindows {
    p: usize,
    m: usize,
    horizon: usize,
    lag: usize,
    windows: Vec<usize>,
    // Ring of the newest `cap` columns; `head` is the next slot, `len` the columns stored.
    ring_z: Vec<f64>,
    ring_dy: Vec<f64>,
    head: usize,
    len: usize,
    // Instrumented columns seen since the last reset.
    usable: u64,
    // Per window: sums (`stride` values each), columns counted, columns since refresh.
    sums: Vec<f64>,
    counts: Vec<usize>,
    since_refresh: Vec<usize>,
    // One column's contribution (scratch, meaningless between calls).
    contrib: Vec<f64>,
}

impl InstrumentedWindows {
    /// Windows `windows` (strictly ascending, each at least `p + m`) over columns of horizon
    /// `horizon >= 1`, with instrument lag `lag` samples.
    ///
    /// # Errors
    /// [`RegressionError::InvalidConfig`] for empty or unsorted windows, a window shorter than
    /// `p + m`, or `p`, `m`, `horizon` of zero.
    ///
    /// ```
    /// use streamcert_regression::{InstrumentedWindows, RegressionError};
    /// assert!(InstrumentedWindows::new(1, 1, 5, 1, &[150, 300]).is_ok());
    /// let err = InstrumentedWindows::new(1, 1, 5, 1, &[300, 150]).unwrap_err();
    /// assert!(matches!(err, RegressionError::InvalidConfig { field: "windows", .. }));
    /// ```
    pub fn new(
        p: usize,
        m: usize,
        horizon: usize,
        lag: usize,
        windows: &[usize],
    ) -> Result<Self, RegressionError> {
        let bad = |field: &'static str, reason: String| {
            Err(RegressionError::InvalidConfig { field, reason })
        };
        if p == 0 || m == 0 || horizon == 0 {
            return bad("outputs", "p, m and the horizon must be at least 1".into());
        }
        let d = p + m;
        if windows.is_empty() || windows.windows(2).any(|w| w[0] >= w[1]) || windows[0] < d {
            return bad(
                "windows",
                format!("must be strictly ascending and at least p + m = {d}, got {windows:?}"),
            );
        }
        let lay = Layout { p, d };
        let cap = windows[windows.len() - 1] + horizon + lag + 1;
        Ok(Self {
            p,
            m,
            horizon,
            lag,
            windows: windows.to_vec(),
            ring_z: vec![0.0; cap * d],
            ring_dy: vec![0.0; cap * p],
            head: 0,
            len: 0,
            usable: 0,
            sums: vec![0.0; windows.len() * lay.stride()],
            counts: vec![0; windows.len()],
            since_refresh: vec![0; windows.len()],
            contrib: vec![0.0; lay.stride()],
        })
    }

    fn layout(&self) -> Layout {
        Layout { p: self.p, d: self.p + self.m }
    }

    fn cap(&self) -> usize {
        self.ring_z.len() / (self.p + self.m)
    }

    /// The window lengths.
    #[must_use]
    pub fn windows(&self) -> &[usize] {
        &self.windows
    }

    /// Instrumented columns in window `w`.
    #[must_use]
    pub fn columns(&self, w: usize) -> usize {
        self.counts[w]
    }

    /// Instrumented columns seen since construction or the last [`reset`](Self::reset).
    #[must_use]
    pub fn seen(&self) -> u64 {
        self.usable
    }

    /// The sums of window `w`, `(N, Cw, H, G, C, S)` row-major (full matrices).
    #[must_use]
    pub fn sums(&self, w: usize) -> [&[f64]; 6] {
        let lay = self.layout();
        let (p, d) = (lay.p, lay.d);
        let s = &self.sums[w * lay.stride()..(w + 1) * lay.stride()];
        [
            &s[lay.n()..lay.n() + d * d],
            &s[lay.cw()..lay.cw() + p * d],
            &s[lay.h()..lay.h() + d * d],
            &s[lay.g()..lay.g() + d * d],
            &s[lay.c()..lay.c() + p * d],
            &s[lay.s()..lay.s() + p * p],
        ]
    }

    /// Forget every column.
    pub fn reset(&mut self) {
        self.head = 0;
        self.len = 0;
        self.usable = 0;
        self.sums.fill(0.0);
        self.counts.fill(0);
        self.since_refresh.fill(0);
    }

    /// Ring slot of the column `back` columns before the newest (`back < len`).
    fn slot(&self, back: usize) -> usize {
        let cap = self.cap();
        (self.head + cap - 1 - back) % cap
    }

    /// Write the outer products of the column `back` columns before the newest (paired with
    /// its instrument) into `contrib`.
    fn contribution(&mut self, back: usize) {
        let lay = self.layout();
        let (p, d) = (lay.p, lay.d);
        let q = self.slot(back);
        let r = self.slot(back + self.horizon + self.lag);
        let z = &self.ring_z[q * d..(q + 1) * d];
        let dy = &self.ring_dy[q * p..(q + 1) * p];
        let w = &self.ring_z[r * d..(r + 1) * d];
        let c = &mut self.contrib;
        for i in 0..d {
            for j in 0..d {
                c[lay.n() + i * d + j] = z[i] * w[j];
                c[lay.h() + i * d + j] = w[i] * w[j];
                c[lay.g() + i * d + j] = z[i] * z[j];
            }
        }
        for i in 0..p {
            for j in 0..d {
                c[lay.cw() + i * d + j] = dy[i] * w[j];
                c[lay.c() + i * d + j] = dy[i] * z[j];
            }
            for j in 0..p {
                c[lay.s() + i * p + j] = dy[i] * dy[j];
            }
        }
    }

    /// Absorb the newest column `(z, dy)` (`z` of length `p + m`, `dy` of length `p`). No
    /// allocation; `O(W d²)`.
    ///
    /// # Panics
    /// If `z` or `dy` has the wrong length (the caller builds them from a validated
    /// configuration).
    pub fn push_column(&mut self, z: &[f64], dy: &[f64]) {
        let lay = self.layout();
        let (p, d, stride) = (lay.p, lay.d, lay.stride());
        let cap = self.cap();
        let k = self.head;
        self.ring_z[k * d..(k + 1) * d].copy_from_slice(z);
        self.ring_dy[k * p..(k + 1) * p].copy_from_slice(dy);
        self.head = if k + 1 == cap { 0 } else { k + 1 };
        self.len = (self.len + 1).min(cap);
        if self.len <= self.horizon + self.lag {
            return;
        }
        self.usable += 1;
        self.contribution(0);
        for sums in self.sums.chunks_exact_mut(stride) {
            for (s, c) in sums.iter_mut().zip(&self.contrib) {
                *s += c;
            }
        }
        for w in 0..self.windows.len() {
            let mw = self.windows[w];
            if self.counts[w] == mw {
                // The column that leaves window w is mw columns before the newest.
                self.contribution(mw);
                let sums = &mut self.sums[w * stride..(w + 1) * stride];
                for (s, c) in sums.iter_mut().zip(&self.contrib) {
                    *s -= c;
                }
            } else {
                self.counts[w] += 1;
            }
            self.since_refresh[w] += 1;
            if self.since_refresh[w] >= mw {
                self.refresh(w);
            }
        }
    }

    /// Recompute window `w`'s sums exactly from the ring (`O(M_w d²)`), oldest column first.
    pub fn refresh(&mut self, w: usize) {
        let stride = self.layout().stride();
        self.sums[w * stride..(w + 1) * stride].fill(0.0);
        for back in (0..self.counts[w]).rev() {
            self.contribution(back);
            for (s, c) in self.sums[w * stride..(w + 1) * stride].iter_mut().zip(&self.contrib) {
                *s += c;
            }
        }
        self.since_refresh[w] = 0;
    }

    /// Solve window `w` with ridge `λ` for the candidate directions `t` (`d × p` row-major,
    /// `T = [I_p; K]`) into `out` (built with this structure's `p`, `m`, `h`):
    ///
    /// ```text
    /// Θ̂ = Cw (N + λI)⁻¹,   X = (N + λI)⁻¹ T,   R_q = ΔY_q − Θ̂ Z_q,   g_q = Xᵀ W_q
    /// u_q = vec(sym(R_q g_qᵀ))           (p² values; Σ_q u_q over the errors is vec(sym ΔJ_cl))
    /// S_j = Σ_{q in block j} u_q         (B = ⌊n/h⌋ blocks of h columns, the newest B h)
    /// Ω̂  = c_h · B/(B − d) · Σ_j S_j S_jᵀ,   c_h = 3h² / (2h² + 1)
    /// ```
    ///
    /// Batch means: a block sum is a sum of `h` consecutive scores, so `Ω̂` is positive
    /// semi-definite by construction and the blocks are nearly independent. Neighbouring
    /// blocks still share the overlap of their columns: for white process noise the column
    /// errors have the triangular autocorrelation `1 − |l|/h`, a block's variance is then
    /// `h² − (h² − 1)/3` and the long-run variance per block `h²` (in units of one column's),
    /// hence `c_h`. White sensor noise makes neighbouring blocks negatively correlated (a sample
    /// enters `ΔY_q` and `ΔY_{q+h}` with opposite signs), so there `Ω̂` is conservative.
    /// `B/(B − d)` makes up for the `d` fitted directions (the scores sum to zero at `Θ̂`).
    /// Cost `O(n (d p + p²) + B p⁴)`: the calibrated certificate calls it at its looks only.
    ///
    /// `out.ready` is `false` when the window holds fewer than `h (p + m + 1)` columns, `N + λI` is
    /// singular to working precision (pivot ratio at most `min_pivot_ratio`), or a value is not
    /// finite.
    pub fn estimate(
        &self,
        w: usize,
        ridge: f64,
        t: &[f64],
        min_pivot_ratio: f64,
        out: &mut WindowEstimate,
    ) {
        let lay = self.layout();
        let (p, d) = (lay.p, lay.d);
        let n = self.counts[w];
        out.ready = false;
        out.columns = n;
        if n / self.horizon <= d {
            return;
        }
        let [nm, cw, ..] = self.sums(w);
        // Θ̂ row i solves (N + λI)ᵀ θᵢᵀ = Cwᵢᵀ.
        for i in 0..d {
            for j in 0..d {
                out.lu[i * d + j] = nm[j * d + i] + if i == j { ridge } else { 0.0 };
            }
        }
        let ratio = linalg::lu_in_place(&mut out.lu, d, &mut out.piv);
        out.pivot_ratio = ratio;
        if !(ratio > min_pivot_ratio) {
            return;
        }
        for i in 0..p {
            let row = &mut out.theta[i * d..(i + 1) * d];
            row.copy_from_slice(&cw[i * d..(i + 1) * d]);
            linalg::lu_solve_in_place(&out.lu, d, &out.piv, row);
        }
        // X = (N + λI)⁻¹ T, one column at a time (stored as p rows of d).
        for i in 0..d {
            for j in 0..d {
                out.lu[i * d + j] = nm[i * d + j] + if i == j { ridge } else { 0.0 };
            }
        }
        if !(linalg::lu_in_place(&mut out.lu, d, &mut out.piv) > min_pivot_ratio) {
            return;
        }
        for j in 0..p {
            let xj = &mut out.x[j * d..(j + 1) * d];
            for i in 0..d {
                xj[i] = t[i * p + j];
            }
            linalg::lu_solve_in_place(&out.lu, d, &out.piv, xj);
        }
        // Block sums of the scores over the newest B h columns, oldest first.
        let (pp, h) = (p * p, self.horizon);
        let blocks = n / h;
        out.score_cov.fill(0.0);
        out.block.fill(0.0);
        for (k, back) in (0..blocks * h).rev().enumerate() {
            let q = self.slot(back);
            let r = self.slot(back + self.horizon + self.lag);
            let z = &self.ring_z[q * d..(q + 1) * d];
            let dy = &self.ring_dy[q * p..(q + 1) * p];
            let wv = &self.ring_z[r * d..(r + 1) * d];
            for i in 0..p {
                let th = &out.theta[i * d..(i + 1) * d];
                let mut ri = dy[i];
                for a in 0..d {
                    ri -= th[a] * z[a];
                }
                for j in 0..p {
                    let xj = &out.x[j * d..(j + 1) * d];
                    let mut gj = 0.0;
                    for a in 0..d {
                        gj += xj[a] * wv[a];
                    }
                    // Both halves of sym(R g ᵀ): entry (i, j) gets R_i g_j / 2 and entry (j, i)
                    // the same.
                    let v = 0.5 * ri * gj;
                    out.block[i * p + j] += v;
                    out.block[j * p + i] += v;
                }
            }
            if (k + 1) % h == 0 {
                for a in 0..pp {
                    for b in 0..pp {
                        out.score_cov[a * pp + b] += out.block[a] * out.block[b];
                    }
                }
                out.block.fill(0.0);
            }
        }
        let hf = h as f64;
        let overlap = 3.0 * hf * hf / (2.0 * hf * hf + 1.0);
        let scale = overlap * blocks as f64 / (blocks - d) as f64;
        for v in &mut out.score_cov {
            *v *= scale;
        }
        out.ready = out.theta.iter().chain(&out.score_cov).all(|v| v.is_finite());
    }

    /// Check a deserialised state against its own dimensions.
    ///
    /// # Errors
    /// [`RegressionError::CorruptState`] naming the first inconsistency.
    pub fn check_state(&self) -> Result<(), RegressionError> {
        let fresh = Self::new(self.p, self.m, self.horizon, self.lag, &self.windows)?;
        let sizes_ok = self.ring_z.len() == fresh.ring_z.len()
            && self.ring_dy.len() == fresh.ring_dy.len()
            && self.sums.len() == fresh.sums.len()
            && self.counts.len() == fresh.counts.len()
            && self.since_refresh.len() == fresh.since_refresh.len()
            && self.contrib.len() == fresh.contrib.len();
        if !sizes_ok {
            return Err(RegressionError::CorruptState("window buffers have the wrong size".into()));
        }
        let cap = self.cap();
        let counters_ok = self.head < cap
            && self.len <= cap
            && self.counts.iter().zip(&self.windows).all(|(&c, &w)| c <= w)
            && self.since_refresh.iter().zip(&self.windows).all(|(&c, &w)| c < w)
            && self
                .counts
                .iter()
                .zip(&self.windows)
                .all(|(&c, &w)| c as u64 == self.usable.min(w as u64))
            && self.len as u64 <= self.usable + (self.horizon + self.lag) as u64;
        if !counters_ok {
            return Err(RegressionError::CorruptState("window counters out of range".into()));
        }
        if !self.ring_z.iter().chain(&self.ring_dy).chain(&self.sums).all(|v| v.is_finite()) {
            return Err(RegressionError::CorruptState("non-finite value in the windows".into()));
        }
        Ok(())
    }
}
