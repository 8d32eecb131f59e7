//! [`LoopModel`]: what the regression's columns stand for, and everything that varies with it.
//!
//! The paper's model is first order in the outputs (Section II, eq. regressor):
//!
//! ```text
//! ẏ = J y + B u + c        ΔY_q = y(t_q) − y(t_q − h) ≈ Θ Z_q + c τ_q,   Z_q = [∫y; ∫u]
//! ```
//!
//! with the integrals over the `h` sample intervals a column spans. A plant whose output is not
//! its whole state (a tank behind a tank, a mass read by its position, a sensor lag) needs a
//! model of higher order, whose columns are wider and span more samples. The regression asks
//! this type for the width of a column and for the specialised code path its shape takes:
//! the fast paths are chosen here, by the model's width, never by counting signals, so that a
//! wider model with one output and one input cannot run code written for two regressors.

use serde::{Deserialize, Serialize};

/// The loop model the regression's columns are built for (see the module docs). The first
/// order is the paper's and the default; its columns, and every number derived from them, are
/// the regression's as it always was.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum LoopModel {
    /// `ẏ = J y + B u + c`: a column `Z_q = [∫y; ∫u]` over `h` sample intervals, `p + m`
    /// regressors (and the intercept's `τ_q` beside them with the affine model).
    #[default]
    FirstOrder,
}

/// The code a regression of a given shape takes for its per-sample update and its solve
/// ([`LoopModel::fast_path`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FastPath {
    /// One output and two regressors (the first-order model with `p = m = 1`, the paper's
    /// case): the arithmetic written out for scalars, in the general path's order, so the
    /// same bits.
    Scalar,
    /// Any other shape: the general code over slices.
    General,
}

impl LoopModel {
    /// Every loop model, for the tests that must hold for each.
    pub const ALL: [Self; 1] = [Self::FirstOrder];

    /// The number of regressors of a column, `d` (without the intercept's `τ`): `p + m` for
    /// the first order.
    #[must_use]
    pub fn width(self, outputs: usize, inputs: usize) -> usize {
        match self {
            Self::FirstOrder => outputs + inputs,
        }
    }

    /// The code path for `outputs` outputs and `inputs` inputs: [`FastPath::Scalar`] for one
    /// output and a width of two, [`FastPath::General`] otherwise.
    #[must_use]
    pub fn fast_path(self, outputs: usize, inputs: usize) -> FastPath {
        // Per model, so that the first order's choice costs what counting did (one output and
        // one input is its width of two).
        match self {
            Self::FirstOrder if outputs == 1 && inputs == 1 => FastPath::Scalar,
            Self::FirstOrder => FastPath::General,
        }
    }

    /// Whether this is the first-order model (the default, left out of a configuration's
    /// serialised form, so that states and fingerprints written before this type read and
    /// compare as they did).
    #[must_use]
    pub fn is_first_order(&self) -> bool {
        *self == Self::FirstOrder
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first order's shape is the regression's as it always was: `p + m` regressors, the
    /// scalar path exactly for `p = m = 1`.
    #[test]
    fn the_first_order_is_the_papers_shape() {
        let m = LoopModel::default();
        assert!(m.is_first_order());
        for (p, i) in [(1, 1), (1, 2), (2, 1), (2, 2), (3, 3)] {
            assert_eq!(m.width(p, i), p + i);
            let scalar = (p, i) == (1, 1);
            assert_eq!(m.fast_path(p, i) == FastPath::Scalar, scalar, "{p} {i}");
        }
    }
}
