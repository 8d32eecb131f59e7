//! The exact test's floating-point filter: the test carried in balls `[mid ± rad]` whose radius
//! bounds every rounding error, so that a sign a ball decides is the sign the rational
//! arithmetic would find.
//!
//! Each operation computes its midpoint in floating point and a radius that encloses the true
//! result of the operation on every pair of values inside its operands' balls, including the
//! midpoint's own rounding (at most `2⁻⁵³ |mid|` for a correctly rounded operation, bounded by
//! `2⁻⁵² |mid|`) and the radius's (each radius is raised by `2⁻⁵⁰` of itself and by the
//! smallest normal number):
//!
//! ```text
//! a ± b:  rad = ra + rb + 2⁻⁵² |mid|
//! a · b:  rad = |a| rb + |b| ra + ra rb + 2⁻⁵² |mid|
//! a / b:  rad = (ra + |a / b| rb) / (|b| − rb) + 2⁻⁵² |mid|      (|b| > rb)
//! ```
//!
//! A query whose answer the ball does not decide (a sign of a ball that holds zero and is not
//! exactly zero, a division by such a ball, a comparison of overlapping balls, a value that is
//! not finite) marks the run undecided. A run that was not marked has answered every query as
//! the rational arithmetic would, so it took the same path and reached the same result; a
//! marked run is decided again in rational arithmetic. `is_zero` is true only for an exact
//! zero: where the rationals would drop a leading zero the ball keeps a ball that holds zero,
//! and the next query on it (its sign, a division by it) marks the run.

use std::cell::Cell;
use std::cmp::Ordering;
use std::ops::{Add, Div, Mul, Neg, Rem, Sub};

use num_traits::{Num, One, Signed, Zero};

thread_local! {
    /// Whether a query of the current run was not decided by its ball.
    static UNDECIDED: Cell<bool> = const { Cell::new(false) };
}

/// The relative bound on one correctly rounded operation's error, with room: `2⁻⁵²`.
const ROUNDING: f64 = f64::EPSILON;

/// `x` raised past the rounding of the few operations that computed it.
fn up(x: f64) -> f64 {
    x + x * (4.0 * f64::EPSILON) + f64::MIN_POSITIVE
}

/// `[mid ± rad]`: every value the rational arithmetic may hold at this point of the test.
#[derive(Debug, Clone, Copy)]
pub(super) struct Ball {
    mid: f64,
    rad: f64,
}

impl Ball {
    /// `x` exactly.
    pub(super) fn exact(x: f64) -> Self {
        Self { mid: x, rad: 0.0 }
    }

    fn rounded(mid: f64, rad: f64) -> Self {
        let ball = Self { mid, rad: up(rad + ROUNDING * mid.abs()) };
        if !(ball.mid.is_finite() && ball.rad.is_finite()) {
            mark();
        }
        ball
    }

    /// The sign the rational arithmetic would find, where the ball decides it.
    fn sign(&self) -> Option<Ordering> {
        if self.mid > self.rad {
            Some(Ordering::Greater)
        } else if self.mid < -self.rad {
            Some(Ordering::Less)
        } else if self.mid == 0.0 && self.rad == 0.0 {
            Some(Ordering::Equal)
        } else {
            None
        }
    }

    /// [`sign`](Self::sign), marking the run undecided where the ball does not decide it.
    fn sign_or_mark(&self) -> Ordering {
        self.sign().unwrap_or_else(|| {
            mark();
            Ordering::Equal
        })
    }
}

fn mark() {
    UNDECIDED.with(|u| u.set(true));
}

/// Run `f` with the mark cleared: its result where no query was undecided, else `None`.
pub(super) fn decided<R>(f: impl FnOnce() -> R) -> Option<R> {
    UNDECIDED.with(|u| u.set(false));
    let result = f();
    let undecided = UNDECIDED.with(Cell::get);
    UNDECIDED.with(|u| u.set(false));
    (!undecided).then_some(result)
}

impl PartialEq for Ball {
    fn eq(&self, other: &Self) -> bool {
        self.partial_cmp(other) == Some(Ordering::Equal)
    }
}

impl PartialOrd for Ball {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some((*self - *other).sign_or_mark())
    }
}

impl Add for Ball {
    type Output = Self;
    fn add(self, b: Self) -> Self {
        Self::rounded(self.mid + b.mid, self.rad + b.rad)
    }
}

impl Sub for Ball {
    type Output = Self;
    fn sub(self, b: Self) -> Self {
        Self::rounded(self.mid - b.mid, self.rad + b.rad)
    }
}

impl Neg for Ball {
    type Output = Self;
    fn neg(self) -> Self {
        Self { mid: -self.mid, rad: self.rad }
    }
}

impl Mul for Ball {
    type Output = Self;
    fn mul(self, b: Self) -> Self {
        if self.is_zero() || b.is_zero() {
            return Self::exact(0.0);
        }
        let rad = self.mid.abs() * b.rad + b.mid.abs() * self.rad + self.rad * b.rad;
        Self::rounded(self.mid * b.mid, rad)
    }
}

impl Div for Ball {
    type Output = Self;
    fn div(self, b: Self) -> Self {
        let floor = (b.mid.abs() - b.rad) * (1.0 - f64::EPSILON);
        if !(floor > 0.0) {
            mark();
            return Self { mid: 0.0, rad: f64::INFINITY };
        }
        let mid = self.mid / b.mid;
        Self::rounded(mid, up(self.rad + mid.abs() * b.rad) / floor)
    }
}

impl Rem for Ball {
    type Output = Self;
    /// Not used by the test; undecided.
    fn rem(self, _: Self) -> Self {
        mark();
        Self { mid: 0.0, rad: f64::INFINITY }
    }
}

impl Zero for Ball {
    fn zero() -> Self {
        Self::exact(0.0)
    }
    /// An exact zero only (module docs).
    fn is_zero(&self) -> bool {
        self.mid == 0.0 && self.rad == 0.0
    }
}

impl One for Ball {
    fn one() -> Self {
        Self::exact(1.0)
    }
}

impl Num for Ball {
    type FromStrRadixErr = <f64 as Num>::FromStrRadixErr;
    fn from_str_radix(s: &str, radix: u32) -> Result<Self, Self::FromStrRadixErr> {
        f64::from_str_radix(s, radix).map(|x| Self::rounded(x, 0.0))
    }
}

impl Signed for Ball {
    fn abs(&self) -> Self {
        match self.sign_or_mark() {
            Ordering::Less => -*self,
            _ => *self,
        }
    }
    fn abs_sub(&self, other: &Self) -> Self {
        let d = *self - *other;
        if d.sign_or_mark() == Ordering::Greater { d } else { Self::zero() }
    }
    fn signum(&self) -> Self {
        match self.sign_or_mark() {
            Ordering::Greater => Self::one(),
            Ordering::Less => -Self::one(),
            Ordering::Equal => Self::zero(),
        }
    }
    fn is_positive(&self) -> bool {
        self.sign_or_mark() == Ordering::Greater
    }
    fn is_negative(&self) -> bool {
        self.sign_or_mark() == Ordering::Less
    }
}

#[cfg(test)]
mod tests {
    use num_rational::BigRational;
    use rand::{Rng as _, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    fn rational(x: f64) -> BigRational {
        BigRational::from_float(x).unwrap()
    }

    /// Every operation's ball holds the exact result of its operands' midpoints, for operands
    /// spread over many scales and of both signs (the rational arithmetic as the oracle):
    /// ordinary scales, and scales from `2⁻⁵⁴⁰` to `2⁵⁰⁰` where products and quotients
    /// underflow to subnormal numbers or zero.
    #[test]
    fn each_operation_encloses_the_exact_result() {
        let mut rng = ChaCha8Rng::seed_from_u64(31);
        let draw = |rng: &mut ChaCha8Rng, wide: bool| {
            let scale = 2f64.powi(if wide {
                rng.random_range(-540..500)
            } else {
                rng.random_range(-40..40)
            });
            (rng.random::<f64>() - 0.5) * scale
        };
        for case in 0..24_000 {
            let wide = case % 3 == 0;
            let (a, b) = (draw(&mut rng, wide), draw(&mut rng, wide));
            let (ra, rb) = (rational(a), rational(b));
            let (x, y) = (Ball::exact(a), Ball::exact(b));
            for (ball, exact) in [
                (x + y, &ra + &rb),
                (x - y, &ra - &rb),
                (x * y, &ra * &rb),
                (x / y, &ra / &rb),
                ((x * y + x) / (y - x), (&ra * &rb + &ra) / (&rb - &ra)),
            ] {
                // A ball that is not finite has marked its run: it claims nothing.
                if !(ball.mid.is_finite() && ball.rad.is_finite()) {
                    continue;
                }
                let lo = rational(ball.mid) - rational(ball.rad);
                let hi = rational(ball.mid) + rational(ball.rad);
                assert!(lo <= exact && exact <= hi, "{a} {b}: {ball:?}");
            }
        }
    }

    /// A sign the ball cannot tell marks the run; one it can does not.
    #[test]
    fn an_undecided_sign_marks_the_run() {
        let tiny = Ball::exact(1.0) + Ball::exact(1e-17) - Ball::exact(1.0);
        assert_eq!(decided(|| tiny.is_positive()), None);
        assert_eq!(decided(|| (Ball::exact(1.0) / tiny).mid), None);
        assert_eq!(decided(|| (Ball::exact(1.0) + Ball::exact(1e-3)).is_positive()), Some(true));
        assert_eq!(decided(|| Ball::exact(0.0).is_positive()), Some(false));
        assert!(decided(|| Ball::exact(f64::MAX) * Ball::exact(4.0)).is_none());
    }
}
