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
//!
//! [`LoopModel::Order`] is the model of order `n = 2, 3` with one output,
//! `y⁽ⁿ⁾ + a_1 y⁽ⁿ⁻¹⁾ + … + a_n y = b_1 u⁽ⁿ⁻¹⁾ + … + b_n u + c`: its rows span `n h` sample
//! intervals and carry `n` regressors per signal ([`crate::OrderNRegression`], where the
//! rows are derived). The first-order sliding regression ([`crate::SlidingRegression`])
//! refuses it.
//!
//! In a configuration the model is written as its order, `order = 1 | 2 | 3`.

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// The loop model the regression's columns are built for (see the module docs). The first
/// order is the paper's and the default; its columns, and every number derived from them, are
/// the regression's as it always was.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[non_exhaustive]
pub enum LoopModel {
    /// `ẏ = J y + B u + c`: a column `Z_q = [∫y; ∫u]` over `h` sample intervals, `p + m`
    /// regressors (and the intercept's `τ_q` beside them with the affine model).
    #[default]
    FirstOrder,
    /// Order `n` (2 or 3; build it with [`LoopModel::of_order`]) with one output: a row
    /// spans `n h` sample intervals and has `n` regressors per signal, `n (1 + m)` in all (and
    /// the intercept's).
    Order(u8),
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

/// What the hidden-dynamics guard adds to a model's regression to test whether the model holds
/// ([`LoopModel::hidden_dynamics_test`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HiddenDynamicsTest {
    /// The outputs' increment over the `h` samples before the column, `ΔY_{q−h}`: one extra
    /// regressor per output, whose coefficients are zero when the first-order model holds
    /// with white noise (the first order's test).
    PastIncrement,
    /// The regression of the next order: its coefficients beyond the model's own are zero
    /// when the model holds.
    NextOrder(LoopModel),
    /// No larger model is fitted (order 3, the largest): the model cannot be tested, and a
    /// certificate that needs the test refuses, naming this.
    Unavailable,
}

impl HiddenDynamicsTest {
    /// The regressors the test adds to `model`'s, for `outputs` outputs and `inputs` inputs
    /// (`None` for [`HiddenDynamicsTest::Unavailable`]).
    #[must_use]
    pub fn extra_regressors(
        self,
        model: LoopModel,
        outputs: usize,
        inputs: usize,
    ) -> Option<usize> {
        match self {
            Self::PastIncrement => Some(outputs),
            Self::NextOrder(next) => {
                Some(next.width(outputs, inputs) - model.width(outputs, inputs))
            }
            Self::Unavailable => None,
        }
    }
}

impl LoopModel {
    /// Every loop model, for the tests that must hold for each.
    pub const ALL: [Self; 3] = [Self::FirstOrder, Self::Order(2), Self::Order(3)];

    /// The model of order `n`: [`LoopModel::FirstOrder`] for `1`, [`LoopModel::Order`] for
    /// `2` and `3`, `None` otherwise.
    #[must_use]
    pub fn of_order(n: usize) -> Option<Self> {
        match n {
            1 => Some(Self::FirstOrder),
            2 | 3 => Some(Self::Order(n as u8)),
            _ => None,
        }
    }

    /// The order `n`: `1` for the first order.
    #[must_use]
    pub fn order(self) -> usize {
        match self {
            Self::FirstOrder => 1,
            Self::Order(n) => usize::from(n),
        }
    }

    /// The number of regressors of a column, `d` (without the intercept's `τ`): `p + m` for
    /// the first order, `n (p + m)` for order `n` (which has `p = 1`).
    #[must_use]
    pub fn width(self, outputs: usize, inputs: usize) -> usize {
        match self {
            Self::FirstOrder => outputs + inputs,
            Self::Order(n) => usize::from(n) * (outputs + inputs),
        }
    }

    /// The sample intervals one column spans for a horizon of `h` samples: `h` for the first
    /// order, `n h` for order `n` (its knots are `h` samples apart).
    #[must_use]
    pub fn span(self, horizon: usize) -> usize {
        self.order() * horizon
    }

    /// The code path for `outputs` outputs and `inputs` inputs: [`FastPath::Scalar`] for one
    /// output and a width of two, [`FastPath::General`] otherwise.
    #[must_use]
    pub fn fast_path(self, outputs: usize, inputs: usize) -> FastPath {
        // Per model, so that the first order's choice costs what counting did (one output and
        // one input is its width of two).
        match self {
            Self::FirstOrder if outputs == 1 && inputs == 1 => FastPath::Scalar,
            Self::FirstOrder | Self::Order(_) => FastPath::General,
        }
    }

    /// The hidden-dynamics guard's test of this model: the past increment for the first order
    /// (the calibrated certificate's guard), the next order for order 2, none for order 3.
    #[must_use]
    pub fn hidden_dynamics_test(self) -> HiddenDynamicsTest {
        match self {
            Self::FirstOrder => HiddenDynamicsTest::PastIncrement,
            Self::Order(n) => match Self::of_order(usize::from(n) + 1) {
                Some(next) => HiddenDynamicsTest::NextOrder(next),
                None => HiddenDynamicsTest::Unavailable,
            },
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

/// Written as the order, `1 | 2 | 3`.
impl Serialize for LoopModel {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_u64(self.order() as u64)
    }
}

/// Read from the order, `1 | 2 | 3` (and `"first_order"`, the first order's earlier name).
impl<'de> Deserialize<'de> for LoopModel {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Written {
            Order(u64),
            Name(String),
        }
        let bad = || serde::de::Error::custom("order must be 1, 2 or 3");
        match Written::deserialize(deserializer)? {
            Written::Order(n) => {
                Self::of_order(usize::try_from(n).map_err(|_| bad())?).ok_or_else(bad)
            }
            Written::Name(name) if name == "first_order" => Ok(Self::FirstOrder),
            Written::Name(_) => Err(bad()),
        }
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

    /// Order `n` is wider and longer, never takes the scalar path, and is written as its
    /// order; anything else is refused.
    #[test]
    fn higher_orders_are_wider_longer_and_written_as_numbers() {
        for n in 1..=3 {
            let model = LoopModel::of_order(n).unwrap();
            assert_eq!(model.order(), n);
            assert_eq!(model.width(1, 2), n * 3);
            assert_eq!(model.span(7), 7 * n);
            assert_eq!(model.fast_path(1, 1) == FastPath::Scalar, n == 1);
            let json = serde_json::to_string(&model).unwrap();
            assert_eq!(json, n.to_string());
            assert_eq!(serde_json::from_str::<LoopModel>(&json).unwrap(), model);
        }
        assert_eq!(
            serde_json::from_str::<LoopModel>("\"first_order\"").unwrap(),
            LoopModel::FirstOrder
        );
        for bad in ["0", "4", "\"second\"", "-1", "2.5"] {
            assert!(serde_json::from_str::<LoopModel>(bad).is_err(), "{bad}");
        }
        assert_eq!(LoopModel::of_order(0), None);
        assert_eq!(LoopModel::of_order(4), None);
    }

    /// Each model's hidden-dynamics test: the first order's past increment (one regressor per
    /// output), order 2 tested by order 3 (one more of each signal's regressors), order 3
    /// untestable.
    #[test]
    fn each_model_names_its_hidden_dynamics_test() {
        let first = LoopModel::FirstOrder;
        assert_eq!(first.hidden_dynamics_test(), HiddenDynamicsTest::PastIncrement);
        assert_eq!(first.hidden_dynamics_test().extra_regressors(first, 2, 3), Some(2));
        let two = LoopModel::of_order(2).unwrap();
        let three = LoopModel::of_order(3).unwrap();
        assert_eq!(two.hidden_dynamics_test(), HiddenDynamicsTest::NextOrder(three));
        assert_eq!(two.hidden_dynamics_test().extra_regressors(two, 1, 2), Some(3));
        assert_eq!(three.hidden_dynamics_test(), HiddenDynamicsTest::Unavailable);
        assert_eq!(three.hidden_dynamics_test().extra_regressors(three, 1, 1), None);
    }
}
