//! `horizon`, `window` and `order`: a number, or `"auto"`, the rule that chooses from the data
//! without spending the risk (a [`HorizonLadder`], an [`OrderLadder`]).

use serde::{Deserialize, Deserializer, de};
use streamcert_certificate::{HorizonLadder, OrderLadder};
use streamcert_regression::LoopModel;

/// A count the user sets, or `"auto"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Choice {
    /// `"auto"`.
    Auto,
    /// A number (at least 1).
    Fixed(usize),
}

impl<'de> Deserialize<'de> for Choice {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl de::Visitor<'_> for V {
            type Value = Choice;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a positive integer or \"auto\"")
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Choice, E> {
                usize::try_from(v).ok().filter(|&n| n > 0).map(Choice::Fixed).ok_or_else(|| {
                    E::custom(format!("{v}: expected a positive integer or \"auto\""))
                })
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Choice, E> {
                usize::try_from(v).ok().filter(|&n| n > 0).map(Choice::Fixed).ok_or_else(|| {
                    E::custom(format!("{v}: expected a positive integer or \"auto\""))
                })
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<Choice, E> {
                if v == "auto" {
                    Ok(Choice::Auto)
                } else {
                    Err(E::custom(format!("\"{v}\": expected a positive integer or \"auto\"")))
                }
            }
        }
        d.deserialize_any(V)
    }
}

/// `order`: `1`, `2`, `3` (and `"first_order"`, the first order's earlier name), or `"auto"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum OrderChoice {
    /// `"auto"`.
    Auto,
    /// An order.
    Fixed(LoopModel),
}

impl Default for OrderChoice {
    fn default() -> Self {
        Self::Fixed(LoopModel::FirstOrder)
    }
}

impl<'de> Deserialize<'de> for OrderChoice {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        const EXPECTED: &str = "an order 1, 2, 3 or \"auto\"";
        impl de::Visitor<'_> for V {
            type Value = OrderChoice;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(EXPECTED)
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<OrderChoice, E> {
                usize::try_from(v)
                    .ok()
                    .and_then(LoopModel::of_order)
                    .map(OrderChoice::Fixed)
                    .ok_or_else(|| E::custom(format!("{v}: expected {EXPECTED}")))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<OrderChoice, E> {
                self.visit_i64(i64::try_from(v).unwrap_or(-1))
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<OrderChoice, E> {
                match v {
                    "auto" => Ok(OrderChoice::Auto),
                    "first_order" => Ok(OrderChoice::Fixed(LoopModel::FirstOrder)),
                    _ => Err(E::custom(format!("\"{v}\": expected {EXPECTED}"))),
                }
            }
        }
        d.deserialize_any(V)
    }
}

/// The regression's order and the order ladder the choice gives, for a run with
/// (`calibrated`) or without the calibrated certificate: `order = "auto"` with the calibrated
/// certificate is the first order with the rungs [`OrderLadder::AUTOMATIC_ORDERS`] at risk
/// `δ / K` each (the paper's certificates at the first order); without it (the paper's
/// certificates alone, which are of the first order) the first order.
pub(super) fn resolve_order(
    order: OrderChoice,
    calibrated: bool,
) -> (LoopModel, Option<OrderLadder>) {
    match order {
        OrderChoice::Fixed(model) => (model, None),
        OrderChoice::Auto => (LoopModel::FirstOrder, calibrated.then(OrderLadder::automatic)),
    }
}

/// The regression's `(window, horizon)` and the ladder the choices give, for a run with
/// (`calibrated`) or without the calibrated certificate:
///
/// - `horizon = "auto"` with the calibrated certificate: the rungs
///   [`HorizonLadder::AUTOMATIC_HORIZONS`] at risk `δ / K` each; the paper's certificates at
///   [`HorizonLadder::PAPER_HORIZON`]. Without the calibrated certificate (the paper's
///   certificates alone, which state no risk) `"auto"` is the paper's `h = 5`.
/// - `window = "auto"`: [`HorizonLadder::AUTOMATIC_BLOCKS`] blocks of `h` columns per base
///   window, at every rung (`M = 30 h`: the paper's `M = 150` at `h = 5`); a number: that
///   window at every rung.
pub(super) fn resolve(
    window: Choice,
    horizon: Choice,
    calibrated: bool,
) -> (usize, usize, Option<HorizonLadder>) {
    let h = match horizon {
        Choice::Fixed(h) => h,
        Choice::Auto => HorizonLadder::PAPER_HORIZON,
    };
    let blocks = (window == Choice::Auto).then_some(HorizonLadder::AUTOMATIC_BLOCKS);
    let m = match window {
        Choice::Fixed(m) => m,
        Choice::Auto => HorizonLadder::AUTOMATIC_BLOCKS.saturating_mul(h),
    };
    let ladder = (horizon == Choice::Auto && calibrated)
        .then(|| HorizonLadder { horizons: HorizonLadder::AUTOMATIC_HORIZONS.to_vec(), blocks });
    (m, h, ladder)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Deserialize)]
    struct T {
        v: Choice,
    }

    fn read(s: &str) -> Result<Choice, String> {
        toml::from_str::<T>(&format!("v = {s}")).map(|t| t.v).map_err(|e| e.to_string())
    }

    #[test]
    fn a_choice_is_a_positive_integer_or_auto() {
        assert_eq!(read("\"auto\""), Ok(Choice::Auto));
        assert_eq!(read("7"), Ok(Choice::Fixed(7)));
        for bad in ["0", "-3", "\"Auto\"", "2.5", "true"] {
            assert!(read(bad).is_err(), "{bad} accepted");
        }
    }

    #[derive(Deserialize)]
    struct O {
        order: OrderChoice,
    }

    #[test]
    fn an_order_is_one_two_three_or_auto() {
        let read = |s: &str| toml::from_str::<O>(&format!("order = {s}")).map(|o| o.order);
        assert_eq!(read("\"auto\"").unwrap(), OrderChoice::Auto);
        for n in 1..=3 {
            assert_eq!(
                read(&n.to_string()).unwrap(),
                OrderChoice::Fixed(LoopModel::of_order(n).unwrap())
            );
        }
        assert_eq!(read("\"first_order\"").unwrap(), OrderChoice::Fixed(LoopModel::FirstOrder));
        for bad in ["0", "4", "-1", "\"Auto\"", "2.0", "true"] {
            let err = read(bad).expect_err(bad).to_string();
            assert!(err.contains("an order 1, 2, 3 or \"auto\""), "{bad}: {err}");
        }
        let (model, ladder) = resolve_order(OrderChoice::Auto, true);
        assert!(model.is_first_order());
        assert_eq!(ladder.map(|l| l.orders), Some(vec![1, 2, 3]));
        assert_eq!(resolve_order(OrderChoice::Auto, false), (LoopModel::FirstOrder, None));
        let two = LoopModel::of_order(2).unwrap();
        assert_eq!(resolve_order(OrderChoice::Fixed(two), true), (two, None));
    }

    #[test]
    fn auto_resolves_to_the_ladder_and_thirty_blocks() {
        let (m, h, l) = resolve(Choice::Auto, Choice::Auto, true);
        assert_eq!((m, h), (150, 5));
        let l = l.expect("a ladder");
        assert_eq!((l.horizons, l.blocks), (vec![1, 2, 5, 10], Some(30)));
        assert_eq!(resolve(Choice::Auto, Choice::Fixed(10), true), (300, 10, None));
        assert_eq!(resolve(Choice::Fixed(80), Choice::Auto, false), (80, 5, None));
        let (_, _, l) = resolve(Choice::Fixed(80), Choice::Auto, true);
        assert_eq!(l.map(|l| l.blocks), Some(None));
    }
}
