//! The minimum of a look's certificate over its region, bounded cell by cell: Taylor bounds
//! of the two polynomials for the polynomial library, interval slopes and the corners of
//! their box for a named library.

use streamcert_regression::Interval;

use super::{FeatureSet, NonlinearState, polynomial_bounds};

/// The running result of the cell bounds of one look.
pub(super) struct Bounds {
    pub(super) cert: f64,
    pub(super) worst: f64,
    pub(super) beta_min: f64,
    pub(super) upper: f64,
}

impl Bounds {
    fn start(region: Interval) -> Self {
        let mid = 0.5 * (region.lo + region.hi);
        Self { cert: f64::INFINITY, worst: mid, beta_min: f64::INFINITY, upper: f64::INFINITY }
    }

    /// Cell `[a, b]` with `β̂ ∈ [f.0, f.1]` and `s <= s_hi` on it, multipliers `(c, c_upper)`.
    fn cell(&mut self, a: f64, b: f64, f: (f64, f64), s_hi: f64, (c, c_upper): (f64, f64)) {
        let value = f.0 - c * s_hi;
        if value < self.cert {
            self.cert = value;
            self.worst = 0.5 * (a + b);
        }
        self.beta_min = self.beta_min.min(f.0);
        self.upper = self.upper.min(f.1 + c_upper * s_hi);
    }
}

/// The `cells` equal cells `[a, b]` of `region`, the last one ending exactly at its upper end.
fn cell_edges(region: Interval, cells: usize) -> impl Iterator<Item = (f64, f64)> {
    let width = (region.hi - region.lo) / cells as f64;
    (0..cells).map(move |cell| {
        let a = region.lo + width * cell as f64;
        (a, if cell + 1 == cells { region.hi } else { a + width })
    })
}

impl NonlinearState {
    /// `B K`: the fitted inputs' coefficients times the candidate gain.
    fn input_term(&self) -> f64 {
        let (dg, d) = (self.library.len(), self.dir.len());
        self.est.theta[dg..d].iter().zip(&self.gain).map(|(b, g)| b * g).sum()
    }

    /// The polynomial library: `β̂(y)` and `s(y)²` are polynomials, bounded on each cell by
    /// their Taylor expansions at its midpoint ([`polynomial_bounds`]).
    pub(super) fn cells_polynomial(
        &mut self,
        region: Interval,
        cells: usize,
        c: f64,
        c_upper: f64,
    ) -> Bounds {
        let (dg, d, bk) = (self.library.len(), self.dir.len(), self.input_term());
        let th = &self.est.theta;
        // β̂(y) = Σ_i f_i y^i, f_0 = −(θ_1 + B K), f_i = −(i + 1) θ_{i+1}.
        self.poly_f[0] = -(th[0] + bk);
        for i in 1..dg {
            self.poly_f[i] = -((i + 1) as f64) * th[i];
        }
        // s(y)² = Σ_n y^n Σ_{i+j=n} A_iᵀ Ω A_j with A_0 = e_0 + Σ K_l e_{D+l}, A_i = (i+1) e_i.
        let cov = &self.cov;
        let a_om_a = |i: usize, j: usize| -> f64 {
            let entry = |r: usize, s: usize| cov[r * d + s];
            // Coordinates of A_i as (index, weight) pairs.
            let coords = |i: usize, f: &mut dyn FnMut(usize, f64)| {
                if i == 0 {
                    f(0, 1.0);
                    for (l, &g) in self.gain.iter().enumerate() {
                        f(dg + l, g);
                    }
                } else {
                    f(i, (i + 1) as f64);
                }
            };
            let mut v = 0.0;
            coords(i, &mut |r, wr| coords(j, &mut |s, ws| v += wr * ws * entry(r, s)));
            v
        };
        self.poly_s.fill(0.0);
        for i in 0..dg {
            for j in 0..dg {
                self.poly_s[i + j] += a_om_a(i, j);
            }
        }
        let mut out = Bounds::start(region);
        for (a, b) in cell_edges(region, cells) {
            let (f_lo, f_hi) = polynomial_bounds(&self.poly_f, a, b, &mut self.work);
            let (_, s2_hi) = polynomial_bounds(&self.poly_s, a, b, &mut self.work);
            out.cell(a, b, (f_lo, f_hi), s2_hi.max(0.0).sqrt(), (c, c_upper));
        }
        out
    }

    /// A named library: on each cell every slope `φ_k'` lies in an interval
    /// ([`Feature::slope_bounds`](super::Feature::slope_bounds)), so `β̂(y) = −(Σ_k θ_k φ_k'(y) + B K)` is bounded by interval
    /// arithmetic, and `s(y)² = a(y)ᵀ Ω̂ a(y)`, convex in `a`, is at most its largest value at
    /// the `2^D` corners of the box of slopes.
    pub(super) fn cells_named(
        &mut self,
        region: Interval,
        cells: usize,
        c: f64,
        c_upper: f64,
    ) -> Bounds {
        let (dg, d, bk) = (self.library.len(), self.dir.len(), self.input_term());
        let th = &self.est.theta;
        let mut out = Bounds::start(region);
        let mut slopes = [(0.0, 0.0); FeatureSet::CAPACITY];
        for (a, b) in cell_edges(region, cells) {
            let (mut sum_lo, mut sum_hi) = (bk, bk);
            for (k, f) in self.library.iter().enumerate() {
                let (lo, hi) = f.slope_bounds(a, b);
                slopes[k] = (lo, hi);
                let (p, q) = (th[k] * lo, th[k] * hi);
                sum_lo += p.min(q);
                sum_hi += p.max(q);
            }
            let mut s2_hi = 0.0f64;
            let v = &mut self.work[..d];
            for corner in 0..1usize << dg {
                for k in 0..dg {
                    v[k] = if corner >> k & 1 == 0 { slopes[k].0 } else { slopes[k].1 };
                }
                v[dg..d].copy_from_slice(&self.gain);
                let mut q = 0.0;
                for r in 0..d {
                    let mut row = 0.0;
                    for col in 0..d {
                        row += self.cov[r * d + col] * v[col];
                    }
                    q += v[r] * row;
                }
                s2_hi = s2_hi.max(q);
            }
            out.cell(a, b, (-sum_hi, -sum_lo), s2_hi.max(0.0).sqrt(), (c, c_upper));
        }
        out
    }
}
