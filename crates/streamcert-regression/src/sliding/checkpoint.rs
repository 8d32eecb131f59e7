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
        self.check_sizes(&fresh)?;
        let cap = self.cfg.horizon + 1;
        let ok = self.hist_len <= cap
            && self.hist_head < cap
            && self.zhist_len <= cap
            && self.zhist_head < cap
            && self.col_len <= self.cfg.window
            && self.col_next < self.cfg.window
            && self.since_refresh < self.cfg.refresh_period.max(1)
            && self.inv_window == fresh.inv_window
            && (self.affine() || (!self.origin_set && self.origin.iter().all(|&o| o == 0.0)));
        if !ok {
            return Err(RegressionError::CorruptState("ring counters out of range".into()));
        }
        self.range.check_state(self.d(), self.cfg.window + self.cfg.horizon)?;
        self.check_finite()
    }

    /// Every buffer of the size a fresh state of the same configuration has.
    fn check_sizes(&self, fresh: &Self) -> Result<(), RegressionError> {
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
            ("peaks", self.peaks.len(), fresh.peaks.len()),
            ("origin", self.origin.len(), fresh.origin.len()),
            ("col_tau", self.col_tau.len(), fresh.col_tau.len()),
            ("col_tauw", self.col_tauw.len(), fresh.col_tauw.len()),
            ("zhist_tau", self.zhist_tau.len(), fresh.zhist_tau.len()),
            ("zt", self.zt.len(), fresh.zt.len()),
            ("dyt", self.dyt.len(), fresh.dyt.len()),
            ("wt", self.wt.len(), fresh.wt.len()),
            ("zto", self.zto.len(), fresh.zto.len()),
            ("dyto", self.dyto.len(), fresh.dyto.len()),
            ("intercept", self.intercept.len(), fresh.intercept.len()),
            ("centred.g", self.centred.g.len(), fresh.centred.g.len()),
            ("centred.c", self.centred.c.len(), fresh.centred.c.len()),
            ("centred.s", self.centred.s.len(), fresh.centred.s.len()),
            ("centred.gw", self.centred.gw.len(), fresh.centred.gw.len()),
            ("centred.cw", self.centred.cw.len(), fresh.centred.cw.len()),
        ];
        if let Some((name, got, want)) = sizes.iter().find(|(_, g, w)| g != w) {
            return Err(RegressionError::CorruptState(format!(
                "{name} has {got} entries, expected {want}"
            )));
        }
        Ok(())
    }

    /// Every value that carries state from one sample to the next is finite.
    fn check_finite(&self) -> Result<(), RegressionError> {
        // Every buffer that carries state from one sample to the next (the scratch buffers
        // `theta`, `work`, `work2`, `z`, `dy` are overwritten before they are read).
        let state = [
            &self.hist_t,
            &self.hist_y,
            &self.hist_u,
            &self.hist_z1,
            &self.dy1,
            &self.zhist,
            &self.col_z,
            &self.col_dy,
            &self.col_w,
            &self.g,
            &self.c,
            &self.s,
            &self.gw,
            &self.cw,
            &self.peaks,
            &self.origin,
            &self.col_tau,
            &self.col_tauw,
            &self.zhist_tau,
            &self.zt,
            &self.dyt,
            &self.wt,
            &self.zto,
            &self.dyto,
        ];
        let all_finite = state.iter().all(|v| v.iter().all(|x| x.is_finite()))
            && self.tt.is_finite()
            && self.tto.is_finite();
        if !all_finite {
            return Err(RegressionError::CorruptState("non-finite value in the window".into()));
        }
        Ok(())
    }

    /// Recompute the running sums exactly from the window (as [`refresh`](Self::refresh)
    /// does) and compare: every entry must agree within `tol` times the Cauchy–Schwarz scale
    /// of its row and column (`√(G_ii G_jj)` for `G`, `√(S_ii G_jj)` for `C`, `√(S_ii S_jj)`
    /// for `S`, likewise for the instrumented sums). `O(M d²)`.
    ///
    /// # Errors
    /// [`RegressionError::CorruptState`] naming the first sum that disagrees.
    pub fn check_statistics(&self, tol: f64) -> Result<(), RegressionError> {
        let mut exact = self.clone();
        exact.refresh();
        let (p, d) = (self.cfg.outputs, self.d());
        let sg: Vec<f64> = (0..d).map(|i| exact.g[i * d + i].abs().sqrt()).collect();
        let ss: Vec<f64> = (0..p).map(|i| exact.s[i * p + i].abs().sqrt()).collect();
        let check = |name: &str, got: &[f64], want: &[f64], rows: &[f64], cols: &[f64]| {
            for (i, &ri) in rows.iter().enumerate() {
                for (j, &cj) in cols.iter().enumerate() {
                    let k = i * cols.len() + j;
                    let (a, b) = (got[k], want[k]);
                    if !(a.is_finite() && (a - b).abs() <= tol * (ri * cj + f64::MIN_POSITIVE)) {
                        return Err(RegressionError::CorruptState(format!(
                            "running sum {name}[{i}][{j}] = {a} disagrees with its exact \
                             recompute {b} from the window"
                        )));
                    }
                }
            }
            Ok(())
        };
        check("G", &self.g, &exact.g, &sg, &sg)?;
        check("C", &self.c, &exact.c, &ss, &sg)?;
        check("S", &self.s, &exact.s, &ss, &ss)?;
        if self.cfg.estimator == crate::Estimator::Instrumented {
            check("ZWᵀ", &self.gw, &exact.gw, &sg, &sg)?;
            check("ΔY Wᵀ", &self.cw, &exact.cw, &ss, &sg)?;
        }
        if self.affine() {
            // Σ τ² and the τ-weighted sums, on the scales √T · √G_ii and √T · √S_ii.
            let st = [exact.tt.abs().sqrt()];
            check("Σ τ²", &[self.tt], &[exact.tt], &st, &st)?;
            check("Σ Z τ", &self.zt, &exact.zt, &sg, &st)?;
            check("Σ ΔY τ", &self.dyt, &exact.dyt, &ss, &st)?;
            if self.cfg.estimator == crate::Estimator::Instrumented {
                let so = [exact.tto.abs().sqrt()];
                check("Σ W τ", &self.wt, &exact.wt, &sg, &so)?;
                check("Σ τ²", &[self.tto], &[exact.tto], &so, &so)?;
                check("Σ Z τ", &self.zto, &exact.zto, &sg, &so)?;
                check("Σ ΔY τ", &self.dyto, &exact.dyto, &ss, &so)?;
            }
        }
        Ok(())
    }
}
