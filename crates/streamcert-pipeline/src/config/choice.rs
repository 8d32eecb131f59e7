//! `horizon` and `window`: a number, or `"auto"`, the rule that chooses from the data without
//! spending the risk (a [`HorizonLadder`]).

use serde::{Deserialize, Deserializer, de};
use streamcert_certificate::HorizonLadder;

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
