//! The sliding block rings rebuilt from the sample trail: what lets a checkpoint carry the
//! newest samples (about 41 KB for the default certifier) instead of the block sums of the
//! linear windows and of the model guards' larger fits (about 220 KB).
//!
//! A ring's blocks are sums of columns, and a column is formed afresh from its `h + 1`
//! samples (`streamcert-regression`'s column construction, `curvature.rs`'s terms), so the
//! same samples pushed through a reset copy of the regression, the guards and the windows in
//! the same order give the same sums bit for bit, in other slots of the rings; the refill
//! moves them into the original slots. Nothing is assumed: [`CalibratedState::stripped`]
//! rebuilds the rings before they are left out and compares every bit (a state whose rings
//! differ in one bit, or whose trail does not reach back far enough, is written whole), and
//! a restore refuses a trail that does not rebuild its rings.

use streamcert_regression::{InstrumentedWindows, Interval, SlidingRegression};

use super::CalibratedState;
use super::trail::SampleTrail;
use crate::CertifyError;
use crate::guard::ModelGuard;

/// The newest column of `reg` as the block rings take it (`z`, with the column's span `τ`
/// appended under the affine model in `zaug`; `dy`), its output ranges into `range`; `None`
/// before the first column.
#[inline(always)]
pub(super) fn ring_column<'a>(
    reg: &'a SlidingRegression,
    affine: bool,
    zaug: &'a mut [f64],
    range: &mut [Interval],
) -> Option<(&'a [f64], &'a [f64])> {
    let (z, dy) = reg.newest_column()?;
    if !reg.newest_column_ranges(range) {
        return None;
    }
    if affine {
        let d = z.len();
        zaug[..d].copy_from_slice(z);
        zaug[d] = reg.newest_column_span().unwrap_or(0.0);
        return Some((zaug, dy));
    }
    Some((z, dy))
}

/// The samples a trail keeps for `windows` of horizon `h`: the most columns the rings hold,
/// `h` more whose increments the hidden-dynamics guard's oldest column takes, and the `h`
/// samples before the first column.
pub(super) fn trail_cap(windows: &InstrumentedWindows, horizon: usize) -> usize {
    windows.columns_held_max() + 2 * horizon
}

impl CalibratedState {
    /// The linear windows and each model guard's windows rebuilt from the trail: reset copies
    /// fed the columns the rings hold. `None` when the trail does not reach back that far (or
    /// has no source to replay from).
    fn replayed(&self) -> Option<(InstrumentedWindows, Vec<InstrumentedWindows>)> {
        let trail = self.trail.as_ref()?;
        let (cfg, origin) = trail.source()?;
        let held = self.windows.columns_held();
        if self.model.iter().any(|g| g.ring().columns_held() != held) {
            return None;
        }
        let lead = self.model.iter().map(|g| g.lead_in(held)).max().unwrap_or(0);
        let mut windows = self.windows.cleared();
        let mut model: Vec<ModelGuard> = self.model.clone();
        for g in &mut model {
            g.reset();
            *g.ring_mut() = g.ring().cleared();
            g.restore_scratch();
        }
        if held > 0 {
            let samples = lead + held + self.horizon;
            if trail.len() < samples {
                return None;
            }
            let mut reg = SlidingRegression::new(*cfg).ok()?.with_origin(origin);
            let (mut zaug, mut range) = (self.zaug.clone(), self.col_range.clone());
            let mut col = 0;
            for row in trail.rows(samples) {
                let (y, u) = row[1..].split_at(cfg.outputs);
                reg.push(row[0], y, u).ok()?;
                let Some((z, dy)) = ring_column(&reg, self.affine, &mut zaug, &mut range) else {
                    continue;
                };
                if col < lead {
                    for g in &mut model {
                        g.lead_column(dy);
                    }
                } else {
                    for g in &mut model {
                        g.push(z, dy, &reg);
                    }
                    windows.push_column_ranged(z, dy, &range);
                }
                col += 1;
            }
            if col != lead + held {
                return None;
            }
        }
        Some((windows, model.iter().map(|g| g.ring().clone()).collect()))
    }

    /// This state with its sliding block rings left out (a checkpoint's), when the trail
    /// rebuilds them bit for bit; `None` otherwise (the state is then written whole).
    pub(crate) fn stripped(&self) -> Option<Self> {
        let (windows, rings) = self.replayed()?;
        let rebuilds = |own: &InstrumentedWindows, replayed: &InstrumentedWindows| {
            let mut copy = own.clone();
            copy.strip() && copy.refill_from(replayed) && copy.same_bits(own)
        };
        if !rebuilds(&self.windows, &windows)
            || !self.model.iter().zip(&rings).all(|(g, r)| rebuilds(g.ring(), r))
        {
            return None;
        }
        let mut out = self.clone();
        let mut stripped = out.windows.strip();
        for g in &mut out.model {
            stripped &= g.ring_mut().strip();
        }
        if !stripped {
            return None;
        }
        out.rings_replayed = true;
        Some(out)
    }

    /// After a restore: the trail set to follow `reg` (a new one for a state written before
    /// the trail), and the rings a checkpoint left out rebuilt from it.
    ///
    /// # Errors
    /// [`CertifyError::Checkpoint`] when the trail does not fit the configuration or does not
    /// rebuild the rings.
    pub(crate) fn rebuild_rings(&mut self, reg: &SlidingRegression) -> Result<(), CertifyError> {
        let bad = |what: &str| Err(CertifyError::Checkpoint(format!("the checkpoint's {what}")));
        let cap = trail_cap(&self.windows, self.horizon);
        // A state written before the trail gets an empty one.
        let trail = self.trail.get_or_insert_with(|| SampleTrail::new(reg.config(), cap));
        if !trail.settle(reg, cap) {
            return bad("sample trail does not fit its configuration");
        }
        if !self.rings_replayed {
            return Ok(());
        }
        let Some((windows, rings)) = self.replayed() else {
            return bad("sample trail does not reach back to its windows' oldest column");
        };
        let refilled = self.windows.refill_from(&windows)
            && self.model.iter_mut().zip(&rings).all(|(g, r)| g.ring_mut().refill_from(r));
        if !refilled || rings.len() != self.model.len() {
            return bad("block rings do not fit their replay");
        }
        self.rings_replayed = false;
        Ok(())
    }
}
