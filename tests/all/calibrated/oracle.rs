//! The calibrated formula test's oracle: a look recomputed by nalgebra from the columns.

use statrs::distribution::{ContinuousCDF, StudentsT};
use streamcert::certificate::Calibration;

use super::H;

/// A column of the regression: `(z, ΔY)`.
type Column = (nalgebra::DVector<f64>, nalgebra::DVector<f64>);

/// A calibrated look recomputed by nalgebra from the columns: two-stage least squares on the
/// newest `n` columns with the ridge relative to each diagonal entry,
/// `Q = (H + λ diag H)⁻¹Nᵀ`, `A = N Q + λ diag(N Q)`, `Θ̂ = Cw Q A⁻¹`, `X = Q A⁻¹ T`.
pub(super) struct LookOracle<'a> {
    cols: &'a [Column],
    n: usize,
    dd: usize,
    k: usize,
    lag: usize,
    intervals: usize,
    t_mat: &'a nalgebra::DMatrix<f64>,
    q: nalgebra::DMatrix<f64>,
    a: nalgebra::DMatrix<f64>,
    cw: nalgebra::DMatrix<f64>,
    theta: nalgebra::DMatrix<f64>,
    x: nalgebra::DMatrix<f64>,
}

impl<'a> LookOracle<'a> {
    pub(super) fn new(
        cols: &'a [Column],
        n: usize,
        t_mat: &'a nalgebra::DMatrix<f64>,
        (lag, intervals): (usize, usize),
    ) -> Self {
        let dd = t_mat.nrows();
        let k = dd * intervals;
        let empty = || nalgebra::DMatrix::zeros(0, 0);
        let mut o = Self {
            cols,
            n,
            dd,
            k,
            lag,
            intervals,
            t_mat,
            q: empty(),
            a: empty(),
            cw: nalgebra::DMatrix::zeros(2, k),
            theta: empty(),
            x: empty(),
        };
        let mut nm = nalgebra::DMatrix::zeros(dd, k);
        let mut hm = nalgebra::DMatrix::zeros(k, k);
        for j in 0..n {
            let (z, dy) = &o.window()[j];
            let wv = o.inst(j);
            nm += z * wv.transpose();
            o.cw += dy * wv.transpose();
            hm += &wv * wv.transpose();
        }
        let lambda = Calibration { instrument_intervals: 3, ..Calibration::new(0.01) }.fit_ridge();
        let ridged = |m: &nalgebra::DMatrix<f64>| {
            let mut m = m.clone();
            for i in 0..m.nrows() {
                m[(i, i)] *= 1.0 + lambda;
            }
            m
        };
        o.q = ridged(&hm).try_inverse().expect("invertible") * nm.transpose();
        o.a = ridged(&(&nm * &o.q));
        let ainv = o.a.clone().try_inverse().expect("invertible");
        o.theta = &o.cw * &o.q * &ainv;
        o.x = &o.q * &ainv * t_mat;
        o
    }

    /// The window's columns, oldest first.
    fn window(&self) -> &'a [Column] {
        &self.cols[self.cols.len() - self.n..]
    }

    /// The instruments of the window's column `j`: the intervals' regressors `l h + lag`
    /// columns back.
    fn inst(&self, j: usize) -> nalgebra::DVector<f64> {
        let at = self.cols.len() - self.n + j;
        let parts: Vec<f64> = (1..=self.intervals)
            .flat_map(|l| self.cols[at - l * H - self.lag].0.iter().copied().collect::<Vec<_>>())
            .collect();
        nalgebra::DVector::from_vec(parts)
    }

    /// `β̂ = −λ_max(sym(Θ̂ T))`.
    pub(super) fn beta(&self) -> f64 {
        let j = &self.theta * self.t_mat;
        -((&j + j.transpose()) * 0.5).symmetric_eigen().eigenvalues.max()
    }

    /// Block b's delete-one-block estimate (the second stage without the block, the first
    /// stage `Q` held): `(Cw − Cw_b) Q (A − N_b Q)⁻¹`.
    fn deleted(&self, b: usize) -> nalgebra::DMatrix<f64> {
        let (mut nb, mut cb) =
            (nalgebra::DMatrix::zeros(self.dd, self.k), nalgebra::DMatrix::zeros(2, self.k));
        for j in b * H..(b + 1) * H {
            let (z, dy) = &self.window()[j];
            let wv = self.inst(j);
            nb += z * wv.transpose();
            cb += dy * wv.transpose();
        }
        let rest = (&self.a - &nb * &self.q).try_inverse().expect("invertible");
        (&self.cw - cb) * &self.q * rest
    }

    /// The radius from the variance in batches of `batch` blocks at risk `risk`.
    pub(super) fn radius_in(&self, batch: usize, risk: f64) -> f64 {
        let (n, dd, x, theta, t_mat) = (self.n, self.dd, &self.x, &self.theta, self.t_mat);
        let blocks = n / H;
        let batches = blocks.div_ceil(batch);
        let c = |b: usize| {
            let b = b as f64;
            3.0 * b * 25.0 / (3.0 * b * 25.0 - 25.0 + 1.0)
        };
        let mut omega = nalgebra::DMatrix::<f64>::zeros(4, 4);
        let mut weights = Vec::new();
        // Batch k covers blocks [starts[k], starts[k + 1]), oldest first; the oldest holds
        // the remainder.
        let rem = blocks % batch;
        let mut starts = vec![0];
        starts.extend((if rem == 0 { batch } else { rem }..=blocks).step_by(batch));
        for k in 0..batches {
            let (b0, b1) = (starts[k], starts[k + 1]);
            let mut sum = nalgebra::DMatrix::<f64>::zeros(2, 2);
            let mut weight = 0.0;
            for j in b0 * H..b1 * H {
                weight += (x.transpose() * self.inst(j)).norm_squared();
            }
            for b in b0..b1 {
                let change = (theta - self.deleted(b)) * t_mat;
                sum += (&change + change.transpose()) * 0.5;
            }
            let v = nalgebra::DVector::from_column_slice(sum.as_slice());
            omega += &v * v.transpose() * (c(b1 - b0) / c(batch));
            weights.push(weight);
        }
        assert_eq!(starts.len(), batches + 1);
        assert_eq!(*starts.last().expect("batches"), blocks);
        // Welch–Satterthwaite: effective batches (Σw)²/Σw², at most their number.
        let ess = weights.iter().sum::<f64>().powi(2) / weights.iter().map(|w| w * w).sum::<f64>();
        omega *= c(batch);
        let nu = ess.min(batches as f64) - dd as f64;
        let t = -StudentsT::new(0.0, 1.0, nu).expect("valid").inverse_cdf(risk);
        // The largest variance over unit v (p = 2): λ_max(Ω̂), or the rank-one grid bound.
        let lambda = omega.clone().symmetric_eigen().eigenvalues.max();
        let grid = streamcert::certificate::rank_one_variance_bound(omega.as_slice());
        t * lambda.min(grid).sqrt()
    }
}
