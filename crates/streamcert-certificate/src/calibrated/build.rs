//! The pieces [`CalibratedState::new`](super::CalibratedState) builds: the guards.

use streamcert_regression::{HiddenDynamicsTest, LoopModel};

use super::Calibration;
use crate::CertifyError;
use crate::guard::{ChangeGuard, Groups, ModelGuard};

/// The model guards on the windows' columns: hidden dynamics and nonlinearity, each its own
/// larger fit when configured. The hidden-dynamics guard's extra regressors are the loop
/// model's test of itself ([`LoopModel::hidden_dynamics_test`]): this guard fits the first
/// order's, the past increment; a model whose test it does not fit is refused.
pub(super) fn model_guards(
    cal: &Calibration,
    model: LoopModel,
    (p, d, horizon): (usize, usize, usize),
    lengths: &[usize],
) -> Result<Vec<ModelGuard>, CertifyError> {
    if cal.hidden_dynamics && model.hidden_dynamics_test() != HiddenDynamicsTest::PastIncrement {
        return CertifyError::refuse(
            "regression.order",
            format!(
                "is {}: the calibrated certificate's hidden-dynamics guard tests the first-order \
                 model (order = 1)",
                model.order()
            ),
        );
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The hidden-dynamics guard is the first order's test: it is built for the first order,
    /// and a model whose test is another (order 2, tested by order 3) or none (order 3) is
    /// refused naming the order, unless the guard is off.
    #[test]
    fn the_guard_is_built_only_for_the_model_whose_test_it_fits() {
        let cal = Calibration::new(0.01);
        assert!(cal.hidden_dynamics);
        let lengths = cal.window_lengths(150, 5);
        let guards = model_guards(&cal, LoopModel::FirstOrder, (1, 3, 5), &lengths).expect("ok");
        assert!(!guards.is_empty());
        for n in [2, 3] {
            let model = LoopModel::of_order(n).expect("a model");
            match model_guards(&cal, model, (1, 3, 5), &lengths) {
                Err(CertifyError::InvalidConfig { field, reason }) => {
                    assert_eq!(field, "regression.order");
                    assert!(reason.starts_with(&format!("is {n}:")), "{reason}");
                }
                other => panic!("order {n}: {other:?}"),
            }
        }
        let off = Calibration { hidden_dynamics: false, ..cal };
        let model = LoopModel::of_order(2).expect("a model");
        assert!(model_guards(&off, model, (1, 3, 5), &lengths).is_ok());
    }
}
