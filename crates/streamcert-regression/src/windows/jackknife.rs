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
                for (ga, &m) in g.iter_mut().zip(&qa[b * d..(b + 1) * d]) {
                    *ga += r * m;
                }
            }
        }
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
}
