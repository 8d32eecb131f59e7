//! [`WindowLook`]: one look's fits from the kept rows and units.

use super::super::fit::{in_plant_coordinates, solve_gram};
use super::super::rows::RowWeights;
use super::super::variance::{Filtered, finish_covariance};
use super::super::{OrderNFit, RegressorTest, Shape};
use super::filter::{Kernels, Layout, Products, accumulate, shift_ops, shift_products};
use super::{OrderNWindow, UNIT};
use crate::RegressionError;
use crate::linalg::dot;
use pulp::{Arch, Simd, WithSimd};
use std::mem::take;

/// One look of an [`OrderNWindow`]: the window's fit and its two model tests, each the same
/// estimate as [`OrderNRecord`](super::super::OrderNRecord)'s over the window's samples (the
/// same rows, least squares and model-structured covariance, up to rounding), from the kept
/// rows and units.
#[derive(Debug)]
pub struct WindowLook<'a> {
    window: &'a mut OrderNWindow,
    first: u64,
    end: u64,
    key: u64,
    weights: RowWeights,
    /// The window's kernels.
    kernels: Kernels,
    /// `[y; u]` of the window's first sample, which its rows are taken relative to.
    origin: Vec<f64>,
    /// The window's rows widened ([`Layout`]), by column, and their regressands.
    x: Vec<f64>,
    z: Vec<f64>,
    /// The Gram matrices of `[x, z]` (`D + 1` columns) over every row and over the rows from
    /// `n h + 1` (those with a past row).
    gram_whole: Vec<f64>,
    gram_tail: Vec<f64>,
    /// The filtered products over every row of the window, once computed.
    whole: Option<Products>,
    /// Those of the complete filtered rows from the past-row test's first and of the trailing
    /// edge (common to both fits), once computed.
    tail: Option<Products>,
}

/// A fit's `θ̂` (about the window's origin), its covariance, `(σ_e², σ_v²)`, the residuals'
/// root mean square and the rows.
type Regressed = (Vec<f64>, Vec<f64>, f64, f64, f64, usize);

impl<'a> WindowLook<'a> {
    pub(super) fn new(window: &'a mut OrderNWindow, first: u64, end: u64, key: u64) -> Self {
        let lay = Layout::new(window.shape);
        let (m, d, base) = (lay.m, lay.d, window.base());
        let w = window.weights_of(key);
        let (weights, kernels) = (window.weights[w].1.clone(), window.weights[w].2.clone());
        let origin = window.origins[..1 + m].to_vec();
        let l1 = window.shape.span() as u64 + 1;
        let (mut x, mut a) = (Vec::new(), take(&mut window.scratch.a));
        window.widened_columns(first..end, &origin, |r| r >= first + l1, &mut x, &mut a);
        window.scratch.a = a;
        let z: Vec<f64> = (0..(end - first) as usize).map(|i| window.rows[i * base + d]).collect();
        let split = (l1 as usize).min(z.len());
        let gram_tail = gram(&x, &z, split..z.len());
        let head = gram(&x, &z, 0..split);
        let gram_whole = head.iter().zip(&gram_tail).map(|(a, b)| a + b).collect();
        Self {
            window,
            first,
            end,
            key,
            weights,
            kernels,
            origin,
            x,
            z,
            gram_whole,
            gram_tail,
            whole: None,
            tail: None,
        }
    }

    fn shape(&self) -> Shape {
        self.window.shape
    }

    /// The window's fit: as [`OrderNRecord::fit`](super::super::OrderNRecord::fit) over every
    /// row of the window.
    ///
    /// # Errors
    /// As [`OrderNRecord::fit`](super::super::OrderNRecord::fit).
    pub fn fit(&mut self) -> Result<OrderNFit, RegressionError> {
        let Shape { n, m, .. } = self.shape();
        let (d, span) = (self.shape().width(), self.shape().span());
        let count = (self.end - self.first) as usize;
        if count <= d {
            return Err(RegressionError::InsufficientData {
                needed: d + 1 + span,
                got: count + span,
            });
        }
        let cols = Layout::new(self.shape()).certificate();
        let (theta, covariance, sensor_variance, equation_variance, residual_rms, rows) =
            self.regress(&cols, self.first)?;
        let (theta, covariance) = in_plant_coordinates(&self.origin, n, m, theta, &covariance);
        Ok(OrderNFit {
            n,
            m,
            rows,
            theta,
            covariance,
            sensor_variance,
            equation_variance,
            residual_rms,
        })
    }

    /// The past-row test: as
    /// [`OrderNRecord::past_row_test`](super::super::OrderNRecord::past_row_test) over every row
    /// of the window.
    ///
    /// # Errors
    /// As [`OrderNRecord::past_row_test`](super::super::OrderNRecord::past_row_test).
    pub fn past_row_test(&mut self) -> Result<RegressorTest, RegressionError> {
        let (d, span) = (self.shape().width(), self.shape().span());
        let first = self.first + span as u64 + 1;
        let count = self.end.saturating_sub(first) as usize;
        if count <= d + 1 {
            return Err(RegressionError::InsufficientData {
                needed: d + 2 + 2 * span + 1,
                got: count + 2 * span + 1,
            });
        }
        let cols = Layout::new(self.shape()).past();
        let regressed = self.regress(&cols, first)?;
        Ok(test(regressed, d))
    }

    /// The curvature test: as
    /// [`OrderNRecord::curvature_test`](super::super::OrderNRecord::curvature_test) over every
    /// row of the window.
    ///
    /// # Errors
    /// As [`OrderNRecord::curvature_test`](super::super::OrderNRecord::curvature_test).
    pub fn curvature_test(&mut self) -> Result<RegressorTest, RegressionError> {
        let (d, span) = (self.shape().width(), self.shape().span());
        let count = (self.end - self.first) as usize;
        if count <= d + 2 {
            return Err(RegressionError::InsufficientData {
                needed: d + 3 + span,
                got: count + span,
            });
        }
        let cols = Layout::new(self.shape()).curvature();
        let regressed = self.regress(&cols, self.first)?;
        Ok(test(regressed, d))
    }

    /// Least squares of the regressands on the columns `cols` of the rows from `first`, and
    /// the model-structured covariance.
    fn regress(&mut self, cols: &[usize], first: u64) -> Result<Regressed, RegressionError> {
        let n = self.shape().n;
        let q = cols.len();
        let skip = (first - self.first) as usize;
        let z = &self.z[skip..];
        let count = z.len();
        let len = self.z.len();
        // The fit's block of the Gram matrix of `[x, z]` over its rows.
        let wide = Layout::new(self.shape()).wide();
        let g = if first == self.first { &self.gram_whole } else { &self.gram_tail };
        let at = |a: usize, b: usize| g[a * (wide + 1) + b];
        let gram: Vec<f64> = (0..q * q).map(|i| at(cols[i / q], cols[i % q])).collect();
        let rhs: Vec<f64> = cols.iter().map(|&c| at(c, wide)).collect();
        let (theta, ginv) = solve_gram(&gram, &rhs, q, n, self.window.min_excitation_ratio)?;
        let mut resid = z.to_vec();
        for (&c, th) in cols.iter().zip(&theta) {
            for (r, x) in resid.iter_mut().zip(&self.x[c * len + skip..(c + 1) * len]) {
                *r -= th * x;
            }
        }
        let rms = (resid.iter().map(|r| r * r).sum::<f64>() / count as f64).sqrt();
        let filtered = if first == self.first {
            let whole = match self.whole.take() {
                Some(whole) => whole,
                None => self.products(first, false),
            };
            let filtered = self.filtered(&whole, cols, &theta);
            self.whole = Some(whole);
            filtered
        } else {
            let products = self.products(first, true);
            self.filtered(&products, cols, &theta)
        };
        let (covariance, se, sv) = finish_covariance(&filtered, &resid, &ginv, q);
        Ok((theta, covariance, se, sv, rms, count))
    }

    /// `Σ_J Ψ_J Ψ_Jᵀ` over every sample the rows from `first` reach (the window's first row,
    /// or the past-row test's, `n h + 1` rows later), relative to the window's origin: the
    /// complete filtered rows (`J` from `first + n h` to the last row, all their rows in the
    /// fit), the partial ones at the two edges. The complete ones from the past-row test's
    /// and the trailing edge are the same for both fits, computed once. `past`: the past
    /// columns are needed.
    fn products(&mut self, first: u64, past: bool) -> Products {
        let lay = Layout::new(self.shape());
        let (wide, span, end) = (lay.wide(), self.shape().span() as u64, self.end);
        let (kernels, mut psi) = (take(&mut self.kernels), take(&mut self.window.scratch.psi));
        let groups = kernels.groups;
        let shared_from = self.first + 2 * span + 1;
        let mut total = Products::zero(groups, wide);
        let mut fresh = Products::zero(groups, wide);
        if shared_from < end {
            if self.tail.is_none() {
                let mut tail = self.complete(shared_from..end, true, &kernels, &mut psi);
                let mut trail = Products::zero(groups, wide);
                let rows = end - span..end;
                self.fresh(rows, end..end + span, &kernels, &mut trail, &mut psi);
                trail.mirror(groups, wide);
                tail.add(&trail);
                self.tail = Some(tail);
            }
            if let Some(tail) = &self.tail {
                total.add(tail);
            }
            if first + span < shared_from {
                total.add(&self.complete(first + span..shared_from, past, &kernels, &mut psi));
            }
        } else {
            total.add(&self.complete((first + span).min(end)..end, past, &kernels, &mut psi));
            let trail = end.max(first + span)..end + span;
            self.fresh(first..end, trail, &kernels, &mut fresh, &mut psi);
        }
        let lead = first..(first + span).min(end + span);
        self.fresh(first..end, lead, &kernels, &mut fresh, &mut psi);
        fresh.mirror(groups, wide);
        total.add(&fresh);
        (self.kernels, self.window.scratch.psi) = (kernels, psi);
        total
    }

    /// The products of the complete filtered rows at the samples `js`: the units wholly
    /// inside, kept or computed and kept, moved to the window's origin; the rest computed here.
    fn complete(
        &mut self,
        js: std::ops::Range<u64>,
        past: bool,
        kernels: &Kernels,
        psi: &mut Vec<f64>,
    ) -> Products {
        let lay = Layout::new(self.shape());
        let (wide, groups) = (lay.wide(), kernels.groups);
        let mut total = Products::zero(groups, wide);
        let mut fresh = Products::zero(groups, wide);
        let mut sums = Products::zero(groups, wide);
        let mut ops = Vec::new();
        let mut pos = js.start;
        while pos < js.end {
            if pos.is_multiple_of(UNIT) && pos + UNIT <= js.end {
                let at = match self.window.units.binary_search_by_key(&pos, |u| u.first) {
                    Ok(at) if !past || self.window.units[at].past => at,
                    _ => self.window.keep_unit(pos, self.first, self.key),
                };
                let unit = &self.window.units[at];
                sums.copy_from(&unit.sums);
                shift_ops(lay, &unit.origin, &self.origin, true, &mut ops);
                shift_products(&mut sums.e, groups * wide, groups, wide, &ops);
                shift_products(&mut sums.v, wide, 1, wide, &ops);
                total.add(&sums);
                pos += UNIT;
            } else {
                let next = (pos - pos % UNIT + UNIT).min(js.end);
                self.fresh(self.first..self.end, pos..next, kernels, &mut fresh, psi);
                pos = next;
            }
        }
        fresh.mirror(groups, wide);
        total.add(&fresh);
        total
    }

    /// [`accumulate`] on the window's rows.
    fn fresh(
        &self,
        rows: std::ops::Range<u64>,
        js: std::ops::Range<u64>,
        kernels: &Kernels,
        out: &mut Products,
        psi: &mut Vec<f64>,
    ) {
        accumulate(&self.x, self.first, self.z.len(), kernels, rows, js, out, psi);
    }

    /// `H_e`, `H_v` and the mean kernels of a fit on the columns `cols` with `θ̂`: the residual's
    /// kernel is `wz − Σ_k â_k wy_k`, so `H_e = Σ_{p,q} c_p c_q E_{pq}` with `c = (1, −â)`.
    fn filtered(&self, products: &Products, cols: &[usize], theta: &[f64]) -> Filtered {
        let (n, span) = (self.shape().n, self.shape().span());
        let wide = Layout::new(self.shape()).wide();
        let (groups, q) = (n + 1, cols.len());
        let de = groups * wide;
        let c: Vec<f64> = std::iter::once(1.0).chain(theta[..n].iter().map(|t| -t)).collect();
        let mut he = vec![0.0; q * q];
        let mut hv = vec![0.0; q * q];
        for (a, &ca) in cols.iter().enumerate() {
            for (b, &cb) in cols.iter().enumerate() {
                let mut s = 0.0;
                for (p, cp) in c.iter().enumerate() {
                    let row = &products.e[(p * wide + ca) * de..];
                    for (r, cr) in c.iter().enumerate() {
                        s += cp * cr * row[r * wide + cb];
                    }
                }
                he[a * q + b] = s;
                hv[a * q + b] = products.v[ca * wide + cb];
            }
        }
        let mut mean_e = self.weights.wz.clone();
        for (k, th) in theta.iter().enumerate().take(n) {
            let wy = &self.weights.wy[k * (span + 1)..(k + 1) * (span + 1)];
            for (o, w) in mean_e.iter_mut().zip(wy) {
                *o -= th * w;
            }
        }
        Filtered { he, hv, mean_e, mean_v: self.weights.wv.clone() }
    }
}

/// The Gram matrix of the columns of `x` (by column, `len` rows each) and `z` over the rows
/// `rows`: `(D + 1) × (D + 1)`, each entry a [`dot`] (compiled for the widest vectors).
fn gram(x: &[f64], z: &[f64], rows: std::ops::Range<usize>) -> Vec<f64> {
    struct Gram<'a>(&'a [f64], &'a [f64], std::ops::Range<usize>);
    impl WithSimd for Gram<'_> {
        type Output = Vec<f64>;
        #[inline(always)]
        fn with_simd<S: Simd>(self, _: S) -> Vec<f64> {
            let Gram(x, z, rows) = self;
            let len = z.len();
            let columns: Vec<&[f64]> =
                x.chunks_exact(len.max(1)).chain([z]).map(|c| &c[rows.clone()]).collect();
            let dim = columns.len();
            let mut g = vec![0.0; dim * dim];
            // A loop, not a closure: a closure is not compiled with the vectors' features.
            for a in 0..dim {
                for b in a..dim {
                    let v = dot(columns[a], columns[b]);
                    (g[a * dim + b], g[b * dim + a]) = (v, v);
                }
            }
            g
        }
    }
    Arch::new().dispatch(Gram(x, z, rows))
}

/// A model test from its larger fit: the coefficients beyond the first `d`, their covariance.
fn test(regressed: Regressed, d: usize) -> RegressorTest {
    let (theta, covariance, _, _, _, rows) = regressed;
    let wide = theta.len();
    let q = wide - d;
    let covariance = (0..q * q).map(|i| covariance[(d + i / q) * wide + d + i % q]).collect();
    RegressorTest { coefficients: theta[d..].to_vec(), covariance, rows }
}
