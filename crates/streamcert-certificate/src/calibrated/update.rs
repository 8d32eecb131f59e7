//! The per-sample part of the calibrated certificate: absorb the regression's newest column
//! into every window and guard, look where due, take the change guard's fresh estimates, and
//! recompute the verdict only when a look or an estimate changed it.

use streamcert_regression::SlidingRegression;

use super::replay::ring_column;
use super::{CalibratedState, CalibratedVerdict};
use crate::guard::Fresh;

/// A window's estimate `(β̂, variance, ν)` as the change guard's fresh estimate at time `t`.
fn fresh_at(t: f64, (beta_hat, variance, nu): (f64, f64, f64)) -> Fresh {
    Fresh::new(t, beta_hat, variance.max(0.0).sqrt(), nu)
}

/// The windows that looked at this block (bit `w`) and their estimates (at most 16 windows).
#[derive(Clone, Copy)]
struct Looks {
    looking: u32,
    rates: [Option<(f64, f64, f64)>; 16],
}

impl CalibratedState {
    /// Absorb the regression's newest column if it is new, look where due (at block
    /// boundaries), and return the verdict. No allocation.
    pub(crate) fn update(
        &mut self,
        t: f64,
        reg: &SlidingRegression,
        margin: f64,
    ) -> &CalibratedVerdict {
        if let Some(trail) = &mut self.trail {
            trail.record(reg);
        }
        let built = reg.columns_built();
        let mut looked = false;
        if built < self.seen {
            self.reset();
            looked = true;
        }
        if built > self.seen {
            self.seen = built;
            let block_done = self.absorb(reg);
            // While the shortest window fills, the verdict's warm-up count changes with every
            // block: recompute it, so that it is the same whether or not the state was
            // restored from a checkpoint in between (a restore recomputes it).
            looked |= block_done && !self.windows.is_full(0);
            let looks = self.look_due(t, margin, block_done);
            looked |= looks.looking != 0;
            // The anchored window takes every block and looks at its sizes.
            if block_done {
                looked |= self.anchored_block(t, margin);
            }
            looked |= self.take_fresh(t, block_done, &looks);
            if looked {
                self.retake_exact(t);
            }
        }
        // The verdict changes only with the looks (returned by reference: with a nonlinear
        // look it is a few hundred bytes).
        if looked || self.verdict.is_none() {
            // The change guard's evidence of a change against the anchored look starts a new
            // epoch: the anchored window then holds no data from before it.
            if looked && self.anchored_contradicted() {
                let (cal, base, seen) = (self.cal, self.base_blocks(), self.seen);
                if let Some(a) = &mut self.anchored {
                    a.restart(&cal, base, seen);
                }
            }
            let verdict = self.verdict(margin);
            return self.verdict.insert(verdict);
        }
        self.verdict.get_or_insert_with(CalibratedVerdict::default)
    }

    /// Push the regression's newest column into the model guards, the nonlinear certificate
    /// and the windows; true when it completed a block.
    #[inline]
    fn absorb(&mut self, reg: &SlidingRegression) -> bool {
        let Some((z, dy)) = ring_column(reg, self.affine, &mut self.zaug, &mut self.col_range)
        else {
            return false;
        };
        for o in &mut self.model {
            o.push(z, dy, reg);
        }
        if let Some(n) = &mut self.nonlinear {
            reg.column_samples(&mut self.ts, &mut self.ys);
            if self.affine && n.is_polynomial() {
                // Powers of `y − y_o` (the regression's origin): with the intercept the
                // polynomial class is the same, and the digits are those of the plant's
                // excursions.
                self.nl_origin = reg.origin()[0];
                for y in &mut self.ys {
                    *y -= self.nl_origin;
                }
            }
            n.push(z, dy, &self.ts, &self.ys);
        }
        self.windows.push_column_ranged(z, dy, &self.col_range)
    }

    /// The windows whose look is due at this block look, and their spacing restarts.
    #[inline]
    fn look_due(&mut self, t: f64, margin: f64, block_done: bool) -> Looks {
        let mut looks = Looks { looking: 0, rates: [None; 16] };
        for w in 0..self.latest.len() {
            if !block_done || !self.windows.is_full(w) {
                continue;
            }
            if self.until_look[w] == 0 {
                looks.rates[w] = self.look(w, t, margin);
                looks.looking |= 1 << w;
                let blocks = (self.windows.window(w) / self.horizon) as f64;
                self.until_look[w] = ((self.cal.look_spacing * blocks).ceil() as usize).max(1);
            }
            self.until_look[w] -= 1;
        }
        looks
    }

    /// A window's estimate on its newest blocks: its look's, where it looked at this block
    /// (the same numbers), else first-order.
    #[inline]
    fn newest_fresh(&mut self, t: f64, v: usize, looks: &Looks) -> Option<Fresh> {
        if looks.looking >> v & 1 == 1 {
            looks.rates[v].map(|r| fresh_at(t, r)).map(Fresh::exact)
        } else {
            self.fresh_rate(v, 0).map(|r| fresh_at(t, r))
        }
    }

    /// The change guard's fresh estimates, at the blocks its pace makes due and at each
    /// window's look (so that no look stands unchecked against the newest data). Each
    /// window's split test takes the shorter window's estimate of the same block. A fresh
    /// estimate is first-order (`O(1)`, `fresh_rate`) unless it is the look's; one that would
    /// close something is retaken with the look's variance first, so that what closes is what
    /// the look's variance says. True when an estimate was taken.
    #[inline]
    fn take_fresh(&mut self, t: f64, block_done: bool, looks: &Looks) -> bool {
        let block = self.windows.seen() / self.horizon as u64;
        let mut taken = 0u32;
        for v in 0..self.latest.len() {
            let due = block_done
                && self.windows.is_full(v)
                && self
                    .change
                    .as_ref()
                    .is_some_and(|c| c.due(v, block) | (looks.looking >> v & 1 == 1));
            if !due {
                continue;
            }
            let newest = self.newest_fresh(t, v, looks);
            // The split's two parts at the same block: the older part of window v and window
            // v − 1's estimate now (taken above when it was due too).
            let skip = if v == 0 { 0 } else { self.windows.window(v - 1) / self.horizon };
            let newer =
                (v > 0 && taken >> (v - 1) & 1 == 0).then(|| self.newest_fresh(t, v - 1, looks));
            let mut older =
                if v == 0 { None } else { self.fresh_rate(v, skip).map(|r| fresh_at(t, r)) };
            if let Some(c) = &mut self.change {
                c.set(v, newest);
                if let Some(newer) = newer {
                    c.set(v - 1, newer);
                }
            }
            if v > 0 {
                if self.change.as_ref().is_some_and(|c| c.split_needs_exact(v, older)) {
                    older = self.rate(v, skip).map(|r| fresh_at(t, r)).map(Fresh::exact);
                    let newer = self.rate(v - 1, 0).map(|r| fresh_at(t, r)).map(Fresh::exact);
                    if let Some(c) = &mut self.change {
                        c.set(v - 1, newer);
                    }
                }
                let first = self.seen.saturating_sub(self.windows.window(v - 1) as u64);
                if let Some(c) = &mut self.change {
                    c.set_split(v, older, first);
                }
            }
            taken |= 1 << v;
        }
        taken != 0
    }

    /// A first-order fresh estimate that would close a held look (a window's, or the anchored
    /// look, compared with every window's fresh estimate) is retaken with the look's variance,
    /// on the window's newest blocks now.
    #[inline]
    fn retake_exact(&mut self, t: f64) {
        let mut held = [None; 17];
        for (h, l) in held.iter_mut().zip(&self.latest) {
            *h = l.map(|l| (l.beta_hat, l.sd));
        }
        let w = self.latest.len();
        held[w] = self.anchored_look().map(|l| (l.beta_hat, l.sd));
        let mask = self.change.as_ref().map_or(0, |c| c.needs_exact(&held[..=w]));
        for v in 0..w {
            if mask >> v & 1 == 0 || !self.windows.is_full(v) {
                continue;
            }
            let exact = self.rate(v, 0).map(|r| fresh_at(t, r)).map(Fresh::exact);
            if let Some(c) = &mut self.change {
                c.set(v, exact);
            }
        }
    }
}
