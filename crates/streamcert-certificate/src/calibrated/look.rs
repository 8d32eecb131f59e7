//! A window's look (its estimate, radius and the risk it spends), the fresh estimates of the
//! change guard, and the verdict over the windows' latest looks: which one stands, and why
//! none does.

use super::{
    CalibratedState, CalibratedVerdict, CouplingLook, WindowLook, calibrated_radius, look_risk,
    standing,
};
use crate::NotCertified;
use crate::guard::ModelGuard;
use crate::nonlinear::LookAt;
use crate::rate::first_order;
use streamcert_regression::{RateMap, Solve};

/// The share of an input's variation (beyond its level) that the outputs may leave unexplained
/// for a refused fit to be put down to the controller (`u = K y` with nothing added, up to
/// rounding): far below what any dither leaves (a ±1 dither on a loop whose `K y` moves by
/// ±1 leaves a share of order 0.1) and far above rounding (about 1e-16 on exact data, 1e-12
/// on data written with six significant digits).
pub(super) const FOLLOWS_SHARE: f64 = 1e-6;

/// What a look's radius needs besides its estimate: the risk it spends, the margin (for the
/// upper bound of a rate below it) and whether it carries the second covariance.
pub(super) struct Bound {
    pub(super) risk: f64,
    pub(super) margin: f64,
    pub(super) auto: bool,
}

/// A look's radius, the spread and degrees of freedom of the covariance that gave it, and its
/// upper bound (for a rate below the margin).
pub(super) struct Radius {
    pub(super) radius: f64,
    pub(super) sd: f64,
    pub(super) nu: f64,
    pub(super) upper: Option<f64>,
}

impl CalibratedState {
    /// Window `w`'s look at time `t`: spends `δ_{w,k}` whether or not it certifies; the
    /// nonlinear certificate looks at the same window with the same risk. Returns the
    /// window's estimate [`rate`](Self::rate)`(w, 0)` (the change guard's fresh estimate of
    /// the same block, so that it is not computed twice).
    pub(super) fn look(&mut self, w: usize, t: f64, margin: f64) -> Option<(f64, f64, f64)> {
        self.looks[w] += 1;
        self.look_cols[w] = self.seen;
        let k = self.looks[w];
        if let Some(n) = &mut self.nonlinear {
            let risk = look_risk(self.cal.delta, n.share(w), k);
            let (delta, ridge, min_pivot) = (self.cal.delta, self.ridge, self.min_pivot);
            let origin = self.nl_origin;
            n.look(w, LookAt { k, t, risk, delta, margin, ridge, min_pivot, origin });
        }
        for o in &mut self.model {
            o.look(w, self.ridge, self.min_pivot);
        }
        let p = self.sym.len().isqrt();
        // The estimate, and where the window carries it the covariance in batches, in one
        // solve and one pass over the blocks.
        let (rate, batched) = if self.auto_applies(w) {
            let b = self.auto_blocks(w);
            let solve = Solve {
                ridge: self.ridge,
                rate: RateMap::SymmetricPart(&self.tmat),
                min_pivot_ratio: self.min_pivot,
            };
            self.windows.estimate_batched(w, b, solve, &mut self.est);
            let batched = self.batched_rate();
            (self.rate_of_estimate(), batched)
        } else {
            (self.rate(w, 0), None)
        };
        // A look that the data do not identify: the fit refused (a regressor that never
        // moved beyond the intercept, a block that alone identifies a direction), or too few
        // effective moves for a bound (`ν <= 0`).
        self.weak[w] = match rate {
            None if self.windows.is_full(w) => Some(if self.est.pivot_ratio > self.min_pivot {
                self.est.effective_blocks
            } else {
                0.0
            }),
            Some((_, _, nu)) if !(nu > 0.0) => Some(self.est.effective_blocks.max(0.0)),
            _ => None,
        };
        // A refused fit whose inputs the outputs explain: a closed loop with nothing added to
        // `u = K y`, which no data separate from the plant (the reason names the dither).
        let refused = rate.is_none() && self.weak[w] == Some(0.0);
        let follows = refused && self.inputs_follow_outputs();
        if let Some(f) = self.follows.get_mut(w) {
            *f = follows;
        }
        let Some((beta_hat, variance, nu)) = rate else {
            self.latest[w] = None;
            if let Some(c) = &mut self.coupling {
                let window = self.windows.window(w);
                let look = CouplingLook { w, k, t, share: self.shares[w], nu: 0.0, window };
                c.look(&look, &self.windows, &mut self.est, p);
            }
            return None;
        };
        let risk = look_risk(self.cal.delta, self.sliding_share * self.shares[w], k);
        let pp = self.col_range.len();
        self.windows.window_range(w, &mut self.regions[w * pp..(w + 1) * pp]);
        if let Some(c) = &mut self.coupling {
            let window = self.windows.window(w);
            let look = CouplingLook { w, k, t, share: self.shares[w], nu, window };
            c.look(&look, &self.windows, &mut self.est, p);
        }
        let at = Bound { risk, margin, auto: self.auto_applies(w) };
        self.latest[w] = self.bound(&at, (beta_hat, variance, nu), batched).map(|b| WindowLook {
            window: self.windows.window(w),
            look: k,
            t,
            beta_hat,
            radius: b.radius,
            sd: b.sd,
            nu: b.nu,
            upper: b.upper,
            anchored: false,
        });
        rate
    }

    /// A look's radius at risk `at.risk` from its estimate `(β̂, σ²_max, ν)` and, where it
    /// carries one (`at.auto`), its second covariance `batched` `(σ²_max, ν)`: the second
    /// radius at [`auto_batch_risk`](crate::Calibration::auto_batch_risk) of the risk, the
    /// first at the rest, the smaller standing; and the upper bound at the whole `δ` (split
    /// the same way) for a rate below the margin. `None` when a number is not finite.
    pub(super) fn bound(
        &self,
        at: &Bound,
        (beta_hat, variance, nu): (f64, f64, f64),
        batched: Option<(f64, f64)>,
    ) -> Option<Radius> {
        let (second, delta, below) =
            (self.cal.auto_batch_risk, self.cal.delta, beta_hat < at.margin);
        let risk = at.risk;
        let (mut variance, mut nu) = (variance, nu);
        let mut radius;
        let upper_radius;
        match batched {
            Some((v2, nu2)) => {
                radius = calibrated_radius(variance, nu, risk * (1.0 - second));
                let r2 = calibrated_radius(v2, nu2, risk * second);
                upper_radius =
                    below.then(|| {
                        calibrated_radius(variance, nu, delta * (1.0 - second))
                            .min(calibrated_radius(v2, nu2, delta * second))
                    });
                if r2 < radius {
                    (radius, variance, nu) = (r2, v2, nu2);
                }
            }
            None if at.auto => {
                // Not ready with batches: the first radius at the share of the risk it was
                // given.
                radius = calibrated_radius(variance, nu, risk * (1.0 - second));
                upper_radius =
                    below.then(|| calibrated_radius(variance, nu, delta * (1.0 - second)));
            }
            None => {
                radius = calibrated_radius(variance, nu, risk);
                upper_radius = below.then(|| calibrated_radius(variance, nu, delta));
            }
        }
        (beta_hat.is_finite() && radius.is_finite()).then(|| Radius {
            radius,
            sd: variance.max(0.0).sqrt(),
            nu,
            upper: upper_radius.map(|r| beta_hat + r),
        })
    }

    /// Blocks per batch of window `w`'s second covariance
    /// ([`Calibration::auto_batch_blocks`](crate::Calibration::auto_batch_blocks)).
    pub(super) fn auto_blocks(&self, w: usize) -> usize {
        let p = self.sym.len().isqrt();
        let d = self.tmat.len() / p;
        self.cal.auto_batch_blocks(self.windows.window(w) / self.horizon, d)
    }

    /// Whether window `w` carries the second covariance: on, the first covariance in batches
    /// of one block, and at least two blocks per batch (then at least `2d + 1` batches).
    /// Fixed by the window's length, so the risk split is decided before any data.
    pub(super) fn auto_applies(&self, w: usize) -> bool {
        self.cal.batch_blocks == 1 && self.auto_blocks(w) >= 2
    }

    /// The estimate's second covariance (in batches, `self.est.batched` of
    /// [`InstrumentedWindows::estimate_batched`](streamcert_regression::InstrumentedWindows::estimate_batched)):
    /// `(σ²_max, ν)` as [`rate`](Self::rate) gives them, `None` when not ready.
    pub(super) fn batched_rate(&mut self) -> Option<(f64, f64)> {
        let b = &self.est.batched;
        if !(self.est.ready && b.ready) {
            return None;
        }
        let p = self.sym.len().isqrt();
        let d = self.tmat.len() / p;
        let variance = first_order::direction_variance(&b.score_cov, p, &mut self.eig_work);
        let nu = b.effective_blocks.min(b.batches as f64) - d as f64;
        Some((variance, nu))
    }

    /// Window `w`'s instrumented estimate (into `self.est`) on its blocks less the newest
    /// `skip`: `(β̂_w, σ²_max, ν)` of the module docs, `None` when the fit is not ready.
    pub(super) fn rate(&mut self, w: usize, skip: usize) -> Option<(f64, f64, f64)> {
        let solve = Solve {
            ridge: self.ridge,
            rate: RateMap::SymmetricPart(&self.tmat),
            min_pivot_ratio: self.min_pivot,
        };
        self.windows.estimate_older(w, skip, solve, &mut self.est);
        self.rate_of_estimate()
    }

    /// The change guard's fresh estimate of window `w` less its newest `skip` blocks: as
    /// [`rate`](Self::rate), with the first-order variance from the windows' segment sums
    /// ([`InstrumentedWindows::fresh_estimate`](streamcert_regression::InstrumentedWindows::fresh_estimate),
    /// `O(1)` in the window's length). A fresh estimate spends no risk and only closes looks,
    /// so its variance need not carry the jackknife's leverage.
    pub(super) fn fresh_rate(&mut self, w: usize, skip: usize) -> Option<(f64, f64, f64)> {
        let solve = Solve {
            ridge: self.ridge,
            rate: RateMap::SymmetricPart(&self.tmat),
            min_pivot_ratio: self.min_pivot,
        };
        self.windows.fresh_estimate(w, skip, solve, &mut self.est);
        self.rate_of_estimate()
    }

    /// `(β̂, σ²_max, ν)` of the estimate in `self.est`, `None` when it is not ready.
    pub(super) fn rate_of_estimate(&mut self) -> Option<(f64, f64, f64)> {
        let p = self.sym.len().isqrt();
        let d = self.tmat.len() / p;
        if !self.est.ready {
            return None;
        }
        first_order::sym_theta_t(&self.est.theta, &self.tmat, &mut self.sym, p, d);
        let beta_hat = first_order::rate_of_sym(&self.sym, p, &mut self.eig_work);
        let variance = first_order::direction_variance(&self.est.score_cov, p, &mut self.eig_work);
        let nu = self.est.effective_blocks.min(self.est.batches as f64) - d as f64;
        Some((beta_hat, variance, nu))
    }

    /// After a refused fit (its sums in `self.est`): whether an input is a fixed linear
    /// function of the outputs (and the intercept) over the window while every regressor
    /// moved beyond its level. Each input's share of variation the outputs do not explain
    /// ([`WindowEstimate::unexplained_share`](streamcert_regression::WindowEstimate::unexplained_share))
    /// is at most [`FOLLOWS_SHARE`] of its share beyond the intercept, and no regressor's share
    /// beyond the intercept is that small (a held signal is the other reason for a refused
    /// fit, named as such). Words only: the look is refused either way.
    fn inputs_follow_outputs(&self) -> bool {
        let p = self.sym.len().isqrt();
        let d = self.tmat.len() / p;
        let level = usize::from(self.affine);
        let mut by = [0usize; 16];
        if d > by.len() {
            return false;
        }
        for (i, b) in by.iter_mut().enumerate().take(p) {
            *b = i;
        }
        let intercept = [d - 1];
        let level_rows: &[usize] = if self.affine {
            by[p] = d - 1;
            &intercept
        } else {
            &[]
        };
        let beyond_level = |x: usize| self.est.unexplained_share(x, level_rows);
        let moved = (0..d - level).all(|x| beyond_level(x).is_some_and(|s| s > FOLLOWS_SHARE));
        moved && (p..d - level).any(|j| {
            let by_outputs = self.est.unexplained_share(j, &by[..p + level]);
            matches!((by_outputs, beyond_level(j)), (Some(u), Some(b)) if u <= FOLLOWS_SHARE * b)
        })
    }

    /// The words for a look the change guard refused (`reason`): "the plant changed" only
    /// where the data still fit the model ([`ModelGuard::fits`]). A model of the wrong order
    /// fitted to a plant that never changed gives rates that depend on the window, which the
    /// change guard reads as a change; where a hidden-dynamics test rejects, its rejection
    /// names the cause instead. Words only: the looks stand or not as before.
    fn blame_change(&self, reason: NotCertified) -> NotCertified {
        if self.model.iter().all(ModelGuard::fits) {
            return reason;
        }
        let w0 = self.windows.window(0);
        self.model.iter().find_map(|g| g.admits(0, w0).err()).unwrap_or(reason)
    }

    /// The largest standing certificate, and why the gate must stay closed if none stands.
    pub(super) fn verdict(&self, margin: f64) -> CalibratedVerdict {
        let mut varying = None;
        let nonlinear = self.nonlinear_looks();
        let mut order = None;
        let mut changed = None;
        // The windows' latest looks, then the anchored look (index `W`): it holds the data of
        // every window and more, so the guards must admit it as they admit the longest full
        // window (every window's fresh estimate; that window's model tests, and a rejection
        // of a longer one's).
        let count = self.latest.len();
        let mut looks = [None; 17];
        looks[..count].copy_from_slice(&self.latest);
        looks[count] = self.anchored_look();
        let longest = (0..count).rev().find(|&w| self.windows.is_full(w)).unwrap_or(0);
        let anchored_start = self.anchored.as_ref().map_or(0, |a| a.start);
        let (best, contradicted) = standing(&looks[..=count], margin, |w, look| {
            // The anchored look: compared with every window's fresh estimate, refused as the
            // longest full window's look is by the model guards.
            let (w, first, others) = if w == count {
                (longest, anchored_start, Some(count - 1))
            } else {
                (w, self.look_cols[w].saturating_sub(look.window as u64), None)
            };
            // The change guard: the look must agree with the newest data.
            if let Some(guard) = &self.change {
                let v = others.unwrap_or(w);
                if let Err(reason) = guard.admits(v, (look.window, look.beta_hat, look.sd), first) {
                    changed.get_or_insert(reason);
                    return false;
                }
            }
            // The model guards: each window's larger fits must have run and found no
            // past-increment or curvature term.
            for guard in &self.model {
                if let Err(reason) = guard.admits(w, look.window) {
                    // A significant test is the stronger reason.
                    let stronger = matches!(
                        reason,
                        NotCertified::HiddenDynamics { .. } | NotCertified::VaryingDynamics { .. }
                    );
                    if stronger || order.is_none() {
                        order = Some(reason);
                    }
                    return false;
                }
            }
            // With a nonlinear model, the same window's nonlinearity test must have run and
            // found no variation: a significant test says the linear model does not hold over
            // the region, and a missing one (no feature fit yet) cannot say that it does.
            let Some(state) = &self.nonlinear else { return true };
            let look_nl = nonlinear.get(w).copied().flatten();
            let tested = look_nl.is_some_and(|n| n.test.is_some() || state.features() == 1);
            if let Some(test) = look_nl.and_then(|n| n.test).filter(|t| t.significant()) {
                varying.get_or_insert(NotCertified::VaryingDynamics {
                    window: look.window,
                    statistic: test.statistic,
                    threshold: test.threshold,
                });
                return false;
            }
            if !tested {
                varying.get_or_insert(NotCertified::LinearityUntested { window: look.window });
            }
            tested
        });
        let w0 = self.windows.window(0);
        let columns = self.windows.columns(0);
        // The longest window whose latest look the data did not identify names the reason.
        let weak = (0..self.weak.len()).rev().find_map(|w| {
            self.weak[w].map(|moves| {
                let window = self.windows.window(w);
                if self.follows.get(w) == Some(&true) {
                    NotCertified::InputFollowsOutputs { window }
                } else {
                    NotCertified::WeaklyIdentified { window, moves }
                }
            })
        });
        let warming = if columns < w0 {
            NotCertified::WarmingUp { columns, needed: w0 }
        } else {
            weak.unwrap_or(NotCertified::WeakInstruments)
        };
        let changed = changed.map(|reason| self.blame_change(reason));
        let blocked = if best.is_some() {
            None
        } else {
            Some(contradicted.or(changed).or(order).or(varying).unwrap_or(warming))
        };
        let (nonlinear, nonlinear_blocked) = match &self.nonlinear {
            Some(n) => n.verdict(margin, warming),
            None => (None, None),
        };
        CalibratedVerdict { best, blocked, nonlinear, nonlinear_blocked }
    }
}
