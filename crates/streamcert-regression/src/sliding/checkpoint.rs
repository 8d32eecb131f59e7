//! The consistency check of a deserialised [`SlidingRegression`].

use super::SlidingRegression;
use crate::RegressionError;

impl SlidingRegression {
    /// Check the internal consistency of a deserialised state (buffer sizes, counters).
    ///
    /// # Errors
    /// [`RegressionError::CorruptState`] describing the first inconsistency, or the
    /// configuration error.
    pub fn check_state(&self) -> Result<(), RegressionError> {
        self.cfg.validate()?;
        let fresh = Self::new(self.cfg)?;
        let sizes = [
            ("hist_t", self.hist_t.len(), fresh.hist_t.len()),
            ("hist_y", self.hist_y.len(), fresh.hist_y.len()),
            ("hist_u", self.hist_u.len(), fresh.hist_u.len()),
            ("zhist", self.zhist.len(), fresh.zhist.len()),
            ("col_z", self.col_z.len(), fresh.col_z.len()),
            ("col_dy", self.col_dy.len(), fresh.col_dy.len()),
            ("col_w", self.col_w.len(), fresh.col_w.len()),
            ("g", self.g.len(), fresh.g.len()),
            ("c", self.c.len(), fresh.c.len()),
            ("s", self.s.len(), fresh.s.len()),
            ("gw", self.gw.len(), fresh.gw.len()),
            ("cw", self.cw.len(), fresh.cw.len()),
            ("theta", self.theta.len(), fresh.theta.len()),
            ("work", self.work.len(), fresh.work.len()),
            ("work2", self.work2.len(), fresh.work2.len()),
            ("piv", self.piv.len(), fresh.piv.len()),
            ("z", self.z.len(), fresh.z.len()),
            ("dy", self.dy.len(), fresh.dy.len()),
            ("hist_z1", self.hist_z1.len(), fresh.hist_z1.len()),
            ("dy1", self.dy1.len(), fresh.dy1.len()),
        ];
        if let Some((name, got, want)) = sizes.iter().find(|(_, g, w)| g != w) {
            return Err(RegressionError::CorruptState(format!(
                "{name} has {got} entries, expected {want}"
            )));
        }
        let cap = self.cfg.horizon + 1;
        let ok = self.hist_len <= cap
            && self.hist_head < cap
            && self.zhist_len <= cap
            && self.zhist_head < cap
            && self.col_len <= self.cfg.window
            && self.col_next < self.cfg.window
            && self.since_refresh < self.cfg.refresh_period.max(1)
            && self.inv_window == fresh.inv_window;
        if !ok {
            return Err(RegressionError::CorruptState("ring counters out of range".into()));
        }
        let all_finite =
            [&self.hist_t, &self.hist_y, &self.hist_u, &self.col_z, &self.col_dy, &self.g]
                .iter()
                .all(|v| v.iter().all(|x| x.is_finite()));
        if !all_finite {
            return Err(RegressionError::CorruptState("non-finite value in the window".into()));
        }
        Ok(())
    }
}
