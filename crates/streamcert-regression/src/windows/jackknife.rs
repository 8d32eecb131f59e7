//! The delete-one-block jackknife of a window's two-stage least-squares estimate
//! ([`Jackknife`]), and the two refusals it rests on: a block of leverage 1
//! ([`MIN_LEVERAGE_PIVOT`]) and an exact identity ([`MIN_RESIDUAL_SHARE`]).

use crate::linalg;

/// A block whose leverage on the coefficients reaches 1 within this pivot ratio of
/// `I − L_j` (see `Jackknife::block`) identifies a direction of `Θ` alone: the window is
/// not ready (its delete-one-block variance is unbounded).
pub const MIN_LEVERAGE_PIVOT: f64 = 1e-9;

/// The delete-one-block change of a window's two-stage least-squares estimate, from block
/// sums alone.
pub(super) struct Jackknife<'a> {
    /// `Θ̂`, `p × d`.
    pub(super) theta: &'a [f64],
    /// `Q A⁻¹`, `k × d`.
    pub(super) qa: &'a [f64],
    /// `√A_aa` (`d` values): `I − L_j` is factored equilibrated, `S (I − L_j) S⁻¹` with
    /// `S = diag(√A_aa)`, so that its pivot ratio is in no unit.
    pub(super) root: &'a [f64],
    pub(super) p: usize,
    pub(super) d: usize,
    pub(super) k: usize,
}

impl<'a> Jackknife<'a> {
    /// The view of a solved window with `(p, d, k)` outputs, regressors and instrument
    /// columns: `Θ̂`, `Q A⁻¹` and `√A_aa` from the estimate's buffers (each at least its
    /// shape's length).
    pub(super) fn of(
        theta: &'a [f64],
        qa: &'a [f64],
        root: &'a [f64],
        (p, d, k): (usize, usize, usize),
    ) -> Self {
        Self { theta: &theta[..p * d], qa: &qa[..k * d], root: &root[..d], p, d, k }
    }
}

/// Scratch and sums for [`Jackknife::block`].
pub(super) struct JackScratch<'a> {
    /// The LU factor of `I − L_j` (`d × d`) and its pivots.
    pub(super) lu: &'a mut [f64],
    pub(super) piv: &'a mut [usize],
    /// The block's delete-one-block influence rows, `p × d`.
    pub(super) g: &'a mut [f64],
    /// `Σ_j ‖r_j‖²` and `Σ_j ‖Cw_j‖²` over the blocks so far (an exact fit's test).
    pub(super) residual: f64,
    pub(super) raw: f64,
    /// `1/√A_aa` for `d <= 8` (see [`JackScratch::new`]).
    pub(super) inv_root: [f64; 8],
}

impl<'a> JackScratch<'a> {
    /// Scratch over the given buffers, `residual` and `raw` at zero, and the reciprocals of
    /// `root` (`√A_aa`, the first eight) for the shaped blocks.
    pub(super) fn new(
        view: &Jackknife<'_>,
        lu: &'a mut [f64],
        piv: &'a mut [usize],
        g: &'a mut [f64],
    ) -> Self {
        let (p, d, root) = (view.p, view.d, view.root);
        let (lu, piv, g) = (&mut lu[..d * d], &mut piv[..d], &mut g[..p * d]);
        let mut inv_root = [0.0; 8];
        for (o, r) in inv_root.iter_mut().zip(root) {
            *o = 1.0 / r;
        }
        Self { lu, piv, g, residual: 0.0, raw: 0.0, inv_root }
    }
}

/// A window whose residual moments `Σ_j ‖Cw_j − Θ̂ N_j‖²` are at most this share of its raw
/// moments `Σ_j ‖Cw_j‖²` is an exact identity, not a noisy fit: a proportional feedback law
/// logged with a dither that did not move over the window makes `∫u` (zero-order hold) the
/// feedback gain times the left Riemann sum of `y`, which differs from the trapezoidal `∫y`
/// by `dt/2 · ΔY`, so `ΔY` is an exact combination of the regressors and the variance is
/// zero; where the dither moved once in the window the identity holds but for that move's
/// columns, and the fit still follows it (a coupling estimate of `10⁻⁴` with a bound of
/// `10⁻²` against a true gain of 0.3). Such windows' shares, measured over `cargo xtask
/// validity --runs 5` and the coupling study, run from `10⁻¹⁶` to `10⁻⁵`; noisy fits' from
/// `10⁻³` up, most above `10⁻²`. Such a window does not identify the rate and is refused; a
/// plant whose residuals are below 1 % of its signal (in rms over the window's moments) is
/// refused with it, a power cost on very clean data.
pub const MIN_RESIDUAL_SHARE: f64 = 1e-4;

impl Jackknife<'_> {
    /// Block `j`'s sums `N_j` (`bn`, `d × k`) and `Cw_j` (`bcw`, `p × k`): with the residual
    /// scores `r_{j,i} = Cw_{j,i} − θ̂_i N_j` and the block's leverage
    /// `L_j = A⁻¹ Qᵀ N_jᵀ` (`d × d`),
    ///
    /// ```text
    /// g_{j,i} = (I − L_j)⁻¹ A⁻¹ Qᵀ r_{j,i}            (into s.g, row i)
    /// ```
    ///
    /// `g_{j,i}` is `θ̂_i − θ̂_{(j),i}`, the change of output `i`'s coefficients when block
    /// `j` is deleted from the second stage (exact for `J = 1`, where the estimate is
    /// `Cw N⁻¹`: Sherman–Morrison–Woodbury on `N − N_j`; the first stage `H` held for
    /// `J >= 2`); without the factor `(I − L_j)⁻¹` it is the first-order influence, which a
    /// block that carries most of the information in a direction shrinks toward zero (its
    /// residual is fitted away). Adds `‖r_j‖²` and `‖Cw_j‖²` to `s.residual` and `s.raw`.
    /// Returns the pivot ratio of `I − L_j` equilibrated (0 when it is singular: the block
    /// alone identifies a direction, and `s.g` is meaningless).
    #[inline(always)]
    pub(super) fn block(&self, bn: &[f64], bcw: &[f64], s: &mut JackScratch<'_>) -> f64 {
        let (p, d, k) = (self.p, self.d, self.k);
        let qa = self.qa;
        for a in 0..d {
            for b in 0..d {
                let mut v = 0.0;
                for c in 0..k {
                    v += qa[c * d + a] * bn[b * k + c];
                }
                // Equilibrated: S L_j S⁻¹.
                let v = v * self.root[a] / self.root[b];
                s.lu[a * d + b] = if a == b { 1.0 - v } else { -v };
            }
        }
        self.first_order_any(bn, bcw, s);
        let ratio = linalg::lu_in_place(s.lu, d, s.piv);
        if !(ratio > 0.0) {
            return 0.0;
        }
        // (I − L_j)⁻¹ = S⁻¹ (I − S L_j S⁻¹)⁻¹ S.
        for i in 0..p {
            let g = &mut s.g[i * d..(i + 1) * d];
            for (ga, &r) in g.iter_mut().zip(self.root) {
                *ga *= r;
            }
            linalg::lu_solve_in_place(s.lu, d, s.piv, g);
            for (ga, &r) in g.iter_mut().zip(self.root) {
                *ga /= r;
            }
        }
        ratio
    }

    /// [`block`](Self::block) with the shape of the window chosen at compile time where it is
    /// one of the common single-output shapes (`p = 1`, `d = k` from 2 to 8), in registers (see
    /// `block_fixed`).
    #[inline(always)]
    pub(super) fn block_shaped(&self, bn: &[f64], bcw: &[f64], s: &mut JackScratch<'_>) -> f64 {
        self.shaped::<true>(bn, bcw, s)
    }

    /// [`block_shaped`](Self::block_shaped) (`JACK`) or [`first_order`](Self::first_order)
    /// (which returns 1), dispatched on the window's shape.
    #[inline(always)]
    fn shaped<const JACK: bool>(&self, bn: &[f64], bcw: &[f64], s: &mut JackScratch<'_>) -> f64 {
        match (self.p, self.d, self.k) {
            (1, 2, 2) => self.fixed::<2, JACK>(bn, bcw, s),
            (1, 3, 3) => self.fixed::<3, JACK>(bn, bcw, s),
            (1, 4, 4) => self.fixed::<4, JACK>(bn, bcw, s),
            (1, 5, 5) => self.fixed::<5, JACK>(bn, bcw, s),
            (1, 6, 6) => self.fixed::<6, JACK>(bn, bcw, s),
            (1, 7, 7) => self.fixed::<7, JACK>(bn, bcw, s),
            (1, 8, 8) => self.fixed::<8, JACK>(bn, bcw, s),
            _ if JACK => self.block(bn, bcw, s),
            _ => {
                self.first_order_any(bn, bcw, s);
                1.0
            }
        }
    }

    /// One block for `p = 1`, `d = k = D`: the jackknife's change (`JACK`) or the
    /// first-order influence.
    #[inline(always)]
    fn fixed<const D: usize, const JACK: bool>(
        &self,
        bn: &[f64],
        bcw: &[f64],
        s: &mut JackScratch<'_>,
    ) -> f64 {
        if JACK {
            self.block_fixed::<D>(bn, bcw, s)
        } else {
            let g = self.influence_fixed::<D>(bn, bcw, s);
            s.g[..D].copy_from_slice(&g);
            1.0
        }
    }

    /// [`block`](Self::block) for `p = 1`, `d = k = D`, in arrays, with every division but
    /// one per pivot replaced by a product with a reciprocal (the equilibration's `1/√A_bb`
    /// once per window, each pivot's `1/u_kk` once per block): a division's latency, in the
    /// elimination's chain of dependent operations, made the generic form several times
    /// slower. The same quantity up to rounding (a product with a rounded reciprocal
    /// differs from the quotient in the last bit at most).
    #[inline(always)]
    fn block_fixed<const D: usize>(&self, bn: &[f64], bcw: &[f64], s: &mut JackScratch<'_>) -> f64 {
        let (qa, root) = (&self.qa[..D * D], &self.root[..D]);
        let mut inv_root = [0.0f64; D];
        inv_root.copy_from_slice(&s.inv_root[..D]);
        let bn = &bn[..D * D];
        let mut lu = [[0.0f64; D]; D];
        for a in 0..D {
            for b in 0..D {
                let mut v = 0.0;
                for c in 0..D {
                    v += qa[c * D + a] * bn[b * D + c];
                }
                let v = v * root[a] * inv_root[b];
                lu[a][b] = if a == b { 1.0 - v } else { -v };
            }
        }
        let mut g = self.influence_fixed::<D>(bn, bcw, s);
        // `linalg::lu_in_place` on the array, each pivot's reciprocal kept for the solve.
        let mut piv = [0usize; D];
        let mut inv_pivot = [0.0f64; D];
        let (mut umin, mut umax) = (f64::INFINITY, 0.0f64);
        for k in 0..D {
            let mut p = k;
            let mut best = lu[k][k].abs();
            for i in k + 1..D {
                let v = lu[i][k].abs();
                if v > best {
                    best = v;
                    p = i;
                }
            }
            piv[k] = p;
            if p != k {
                lu.swap(k, p);
            }
            umin = umin.min(best);
            umax = umax.max(best);
            if best == 0.0 || !best.is_finite() {
                s.g[..D].copy_from_slice(&g);
                return 0.0;
            }
            let inv = 1.0 / lu[k][k];
            inv_pivot[k] = inv;
            for i in k + 1..D {
                let f = lu[i][k] * inv;
                lu[i][k] = f;
                for j in k + 1..D {
                    lu[i][j] -= f * lu[k][j];
                }
            }
        }
        let ratio = if umax > 0.0 { umin / umax } else { 0.0 };
        if !(ratio > 0.0) {
            s.g[..D].copy_from_slice(&g);
            return 0.0;
        }
        for a in 0..D {
            g[a] *= root[a];
        }
        // `linalg::lu_solve_in_place` on the array.
        for k in 0..D {
            g.swap(k, piv[k]);
        }
        for i in 0..D {
            let mut v = g[i];
            for k in 0..i {
                v -= lu[i][k] * g[k];
            }
            g[i] = v;
        }
        for i in (0..D).rev() {
            let mut v = g[i];
            for k in i + 1..D {
                v -= lu[i][k] * g[k];
            }
            g[i] = v * inv_pivot[i];
        }
        for a in 0..D {
            g[a] *= inv_root[a];
        }
        s.g[..D].copy_from_slice(&g);
        ratio
    }

    /// The first-order influence of block `j` (no leverage): `g_{j,i} = A⁻¹ Qᵀ r_{j,i}` into
    /// `s.g`, adding `‖r_j‖²` and `‖Cw_j‖²` to `s.residual` and `s.raw` as
    /// [`block`](Self::block) does. For a covariance that closes (a guard's test), not one
    /// that certifies: where one block carries most of the information in a direction its
    /// residual is fitted away and this understates that direction's spread.
    #[inline(always)]
    pub(super) fn first_order(&self, bn: &[f64], bcw: &[f64], s: &mut JackScratch<'_>) {
        self.shaped::<false>(bn, bcw, s);
    }

    /// The first-order influence `A⁻¹ Qᵀ r_j` of a block for `p = 1`, `d = k = D`, adding
    /// `‖r_j‖²` and `‖Cw_j‖²` to `s.residual` and `s.raw`.
    #[inline(always)]
    fn influence_fixed<const D: usize>(
        &self,
        bn: &[f64],
        bcw: &[f64],
        s: &mut JackScratch<'_>,
    ) -> [f64; D] {
        let (qa, th, bn) = (&self.qa[..D * D], &self.theta[..D], &bn[..D * D]);
        let mut g = [0.0f64; D];
        for b in 0..D {
            let raw = bcw[b];
            let mut r = raw;
            for a in 0..D {
                r -= th[a] * bn[a * D + b];
            }
            s.residual += r * r;
            s.raw += raw * raw;
            for a in 0..D {
                g[a] += r * qa[b * D + a];
            }
        }
        g
    }

    fn first_order_any(&self, bn: &[f64], bcw: &[f64], s: &mut JackScratch<'_>) {
        let (p, d, k) = (self.p, self.d, self.k);
        for i in 0..p {
            let th = &self.theta[i * d..(i + 1) * d];
            let g = &mut s.g[i * d..(i + 1) * d];
            g.fill(0.0);
            for b in 0..k {
                let raw = bcw[i * k + b];
                let mut r = raw;
                for a in 0..d {
                    r -= th[a] * bn[a * k + b];
                }
                s.residual += r * r;
                s.raw += raw * raw;
                for (ga, &m) in g.iter_mut().zip(&self.qa[b * d..(b + 1) * d]) {
                    *ga += r * m;
                }
            }
        }
    }
}
