//! The nonlinearity guard's extra regressors, `∫(y_i − o_i)²` and `∫(y_i − o_i)³` over a
//! column (trapezoidal, as the regression integrates the outputs), kept per sample interval.
//!
//! A column spans `h` sample intervals and the next column the same intervals shifted by one,
//! so a column's integrals are the sums of `h` interval terms of which `h − 1` are the previous
//! column's:
//!
//! ```text
//! ∫ e² over interval s = ½ (t_s − t_{s−1}) (e²_{s−1} + e²_s),   e = y − o,
//! ```
//!
//! and the same with cubes. The ring keeps the last `h` intervals' terms; a column adds its
//! newest interval's (from the regression's newest two samples, `O(p)`) in place of the
//! oldest, and sums the ring oldest first, which is the arithmetic of integrating the
//! column's `h + 1` samples afresh in the same order, so the same bits. Where the ring does
//! not hold the intervals just before the newest one (the first column after construction, a
//! restore or a reset of the regression: its newest interval does not start where the
//! ring's newest ended), the column's samples are integrated whole and the ring refilled.
//!
//! The ring is a cache of what the regression's samples determine: a checkpoint does not
//! carry it, and equality ignores it.

use streamcert_regression::SlidingRegression;

/// The per-interval terms of the last `h` intervals (see the module docs).
#[derive(Debug, Clone, Default)]
pub(crate) struct CurvatureTerms {
    p: usize,
    horizon: usize,
    /// `h` slots of `2p` terms (each output's square, then its cube); `head` the oldest.
    ring: Vec<f64>,
    head: usize,
    /// The end time of the ring's newest interval, where the ring holds `h` consecutive
    /// intervals.
    end: Option<f64>,
    /// A column's samples, for the refill.
    ts: Vec<f64>,
    ys: Vec<f64>,
}

impl PartialEq for CurvatureTerms {
    /// Always equal: a cache the next column refills where it is not current.
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// The terms of the interval from `(t0, y0)` to `(t1, y1)` about `origin` into `out` (`2p`).
#[inline(always)]
fn interval_terms(
    out: &mut [f64],
    (t0, t1): (f64, f64),
    (y0, y1): (&[f64], &[f64]),
    origin: &[f64],
) {
    let half = 0.5 * (t1 - t0);
    for i in 0..origin.len() {
        let (a, b) = (y0[i] - origin[i], y1[i] - origin[i]);
        let (a2, a3) = (a * a, a * a * a);
        let (b2, b3) = (b * b, b * b * b);
        out[2 * i] = half * (a2 + b2);
        out[2 * i + 1] = half * (a3 + b3);
    }
}

impl CurvatureTerms {
    /// The terms of `p` outputs over columns of `horizon` intervals, empty.
    pub(crate) fn new(p: usize, horizon: usize) -> Self {
        Self {
            p,
            horizon,
            ring: vec![0.0; 2 * p * horizon],
            head: 0,
            end: None,
            ts: vec![0.0; horizon + 1],
            ys: vec![0.0; (horizon + 1) * p],
        }
    }

    /// The newest column's integrals of the squares and cubes of `reg`'s outputs about its
    /// origin into `out` (`2p`: each output's square, then its cube). `false` (and `out`
    /// untouched) before the regression holds a column's samples.
    pub(crate) fn column(&mut self, reg: &SlidingRegression, out: &mut [f64]) -> bool {
        let (p, h) = (self.p, self.horizon);
        let origin = &reg.origin()[..p];
        let width = 2 * p;
        match reg.newest_interval_samples() {
            Some((t0, t1, y0, y1)) if self.end == Some(t0) => {
                let slot = self.head;
                interval_terms(
                    &mut self.ring[slot * width..(slot + 1) * width],
                    (t0, t1),
                    (y0, y1),
                    origin,
                );
                self.head = if slot + 1 == h { 0 } else { slot + 1 };
                self.end = Some(t1);
            }
            _ => {
                if !reg.column_samples(&mut self.ts, &mut self.ys) {
                    self.end = None;
                    return false;
                }
                for s in 1..=h {
                    let ys = (&self.ys[(s - 1) * p..s * p], &self.ys[s * p..(s + 1) * p]);
                    let out = &mut self.ring[(s - 1) * width..s * width];
                    interval_terms(out, (self.ts[s - 1], self.ts[s]), ys, origin);
                }
                self.head = 0;
                self.end = Some(self.ts[h]);
            }
        }
        // Oldest first: the slots from `head` to the end, then those before it.
        let (newer, older) = self.ring[..h * width].split_at(self.head * width);
        if p == 1 {
            // Two sums in registers.
            let (mut sq, mut cu) = (0.0, 0.0);
            for v in older.chunks_exact(2) {
                sq += v[0];
                cu += v[1];
            }
            for v in newer.chunks_exact(2) {
                sq += v[0];
                cu += v[1];
            }
            (out[0], out[1]) = (sq, cu);
        } else {
            let out = &mut out[..width];
            out.fill(0.0);
            for v in older.chunks_exact(width).chain(newer.chunks_exact(width)) {
                for (o, &x) in out.iter_mut().zip(v) {
                    *o += x;
                }
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use streamcert_regression::RegressionConfig;

    /// The oracle: the column's `h + 1` samples integrated afresh, oldest first.
    fn afresh(reg: &SlidingRegression, p: usize, h: usize) -> Vec<f64> {
        let (mut ts, mut ys) = (vec![0.0; h + 1], vec![0.0; (h + 1) * p]);
        assert!(reg.column_samples(&mut ts, &mut ys));
        let origin = reg.origin();
        let mut out = vec![0.0; 2 * p];
        for i in 0..p {
            let (mut sq, mut cu) = (0.0, 0.0);
            for s in 1..=h {
                let (a, b) = (ys[(s - 1) * p + i] - origin[i], ys[s * p + i] - origin[i]);
                let half = 0.5 * (ts[s] - ts[s - 1]);
                sq += half * (a * a + b * b);
                cu += half * (a * a * a + b * b * b);
            }
            (out[2 * i], out[2 * i + 1]) = (sq, cu);
        }
        out
    }

    proptest! {
        /// At every column, through resets of the regression and a cache lost as on a
        /// restore, the cached terms equal the column integrated afresh bit for bit.
        #[test]
        fn every_column_equals_the_column_integrated_afresh(
            p in 1usize..3,
            h in 1usize..7,
            steps in proptest::collection::vec((0.01f64..2.0, -50.0f64..50.0, -3.0f64..3.0), 40..160),
            resets in proptest::collection::vec(0usize..160, 0..3),
            lost in 0usize..160,
        ) {
            let mut reg = SlidingRegression::new(RegressionConfig::new(p, 1, 3 * (p + 2), h, 1e-4)).unwrap();
            let mut terms = CurvatureTerms::new(p, h);
            let (mut t, mut out) = (0.0, vec![f64::NAN; 2 * p]);
            for (k, &(dt, level, slope)) in steps.iter().enumerate() {
                if resets.contains(&k) {
                    reg.reset();
                }
                if k == lost {
                    terms = CurvatureTerms::new(p, h);
                }
                t += dt;
                let y: Vec<f64> = (0..p).map(|i| level + slope * (t + i as f64).sin()).collect();
                reg.push(t, &y, &[slope]).unwrap();
                if reg.newest_column().is_some() && reg.columns_built() > 0 {
                    prop_assert!(terms.column(&reg, &mut out));
                    let want = afresh(&reg, p, h);
                    for (a, b) in out.iter().zip(&want) {
                        prop_assert_eq!(a.to_bits(), b.to_bits());
                    }
                }
            }
        }
    }
}
