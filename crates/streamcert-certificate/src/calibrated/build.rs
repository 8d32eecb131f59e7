//! The pieces [`CalibratedState::new`](super::CalibratedState) builds: the closed-loop map and
//! the guards.

use super::Calibration;
use crate::CertifyError;
use crate::guard::{ChangeGuard, Groups, ModelGuard};

/// The model guards on the windows' columns: hidden dynamics and nonlinearity, each its own
/// larger fit when configured.
pub(super) fn model_guards(
    cal: &Calibration,
    (p, d, horizon): (usize, usize, usize),
    lengths: &[usize],
) -> Result<Vec<ModelGuard>, CertifyError> {
    [
        Groups { order: cal.hidden_dynamics, curvature: false },
        Groups { order: false, curvature: cal.nonlinearity },
    ]
    .into_iter()
    .filter(|g| g.order || g.curvature)
    .map(|groups| {
        // Batches of one block: see `Calibration::guard_unknowns`.
        let shape = (cal.instrument_lag, cal.instrument_intervals, 1);
        // A window's rejection closes it and every shorter window: by default δ split over the
        // windows keeps the false closings of a look at about δ.
        let alpha = cal.guard_risk(lengths.len());
        ModelGuard::new((p, d, horizon), groups, shape, lengths, alpha)
            .map(|g| g.with_variance(cal.guard_variance))
    })
    .collect()
}

/// The change guard, when configured: `δ` split over its window pairs and splits.
pub(super) fn change_guard(
    cal: &Calibration,
    horizon: usize,
    lengths: &[usize],
) -> Option<ChangeGuard> {
    cal.plant_change.then(|| {
        let blocks: Vec<usize> = lengths.iter().map(|&w| w / horizon).collect();
        let w = lengths.len();
        let pairs = (w * (w + 1) / 2 + w).max(1);
        ChangeGuard::new(&blocks, cal.delta / pairs as f64, cal.change_risk())
    })
}
