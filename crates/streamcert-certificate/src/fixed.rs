//! [`Fixed`]: `format!("{:.P}", x)`, byte for byte, by exact integer arithmetic.
//!
//! The reasons a closed gate gives carry the certificate to four decimals at every sample;
//! core's fixed-precision formatting often falls back to its big-number (Dragon) algorithm
//! there (on data whose gates stay closed, 23 % of the command line's `perf record` samples
//! were in `dragon::format_exact`; measured with `perf record`). Here `|x| · 10^P` is rounded exactly in 128-bit
//! integers (`x = m · 2^e` with `m < 2^53`, so `m · 10^P < 2^67`), half to even as core does;
//! numbers too large for that (`|x| >= 2^60`), NaN and infinities go to core's formatter.

use std::fmt;

/// `x` as a person writes it: six significant digits, trailing zeros dropped (`3.26`, not
/// `3.2600000000000002`; `0.000123457`; `1.5e-7` and `2.5e+9` outside `[10⁻⁴, 10⁹)`);
/// NaN and infinities as Rust writes them. For messages and summaries; the evidence files
/// keep every digit.
#[derive(Debug, Clone, Copy)]
pub struct Sig(pub f64);

impl fmt::Display for Sig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let x = self.0;
        if !x.is_finite() || x == 0.0 {
            return if x == 0.0 { f.write_str("0") } else { write!(f, "{x}") };
        }
        let a = x.abs();
        if (1e-4..1e9).contains(&a) {
            // Decimals for six significant digits; the rounding may carry into a new digit
            // (999999.5 → 1000000), which only drops a decimal.
            let digits = a.log10().floor() as i32 + 1;
            let decimals = (6 - digits).max(0) as usize;
            let text = format!("{x:.decimals$}");
            let text = if text.contains('.') {
                text.trim_end_matches('0').trim_end_matches('.')
            } else {
                &text
            };
            return f.write_str(text);
        }
        let text = format!("{x:.5e}");
        let (mantissa, exp) = text.split_once('e').unwrap_or((&text, "0"));
        let mantissa = if mantissa.contains('.') {
            mantissa.trim_end_matches('0').trim_end_matches('.')
        } else {
            mantissa
        };
        let sign = if exp.starts_with('-') { "" } else { "+" };
        write!(f, "{mantissa}e{sign}{exp}")
    }
}

/// A range `[lo, hi]` as a person writes it: both ends as [`Sig`] writes them, unless six
/// significant digits hide the range's width (an operating point far from zero: the region
/// `[999999.36, 1000000.91]` would read `[999999, 1000001]`); then both ends with the decimals
/// that give the width `hi − lo` three significant digits, trailing zeros dropped. Ends
/// that are not finite, an empty or reversed range, and ends of `10¹⁵` or more in size (whose
/// width `f64` cannot resolve to three digits anyway) are written as [`Sig`] writes them.
#[derive(Debug, Clone, Copy)]
pub struct SigRange(pub f64, pub f64);

impl fmt::Display for SigRange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (lo, hi) = (self.0, self.1);
        let (a, b) = (Sig(lo).to_string(), Sig(hi).to_string());
        let width = hi - lo;
        let size = lo.abs().max(hi.abs());
        let shown = match (a.parse::<f64>(), b.parse::<f64>()) {
            (Ok(x), Ok(y)) => y - x,
            _ => f64::NAN,
        };
        // The six significant digits keep the width to within 0.5 % (a digit in the third).
        if !(width > 0.0 && width.is_finite() && size < 1e15)
            || (shown - width).abs() <= 5e-3 * width
        {
            return write!(f, "[{a}, {b}]");
        }
        let decimals = (3 - (width.log10().floor() as i32 + 1)).clamp(0, 17) as usize;
        let trim = |x: f64| {
            let text = format!("{x:.decimals$}");
            if text.contains('.') {
                text.trim_end_matches('0').trim_end_matches('.').to_string()
            } else {
                text
            }
        };
        write!(f, "[{}, {}]", trim(lo), trim(hi))
    }
}

/// `x` with `P` decimals (`P <= 9`), exactly as `format!("{:.P}", x)` writes it (tested
/// against it on random and tie values).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Fixed<const P: u32>(pub(crate) f64);

impl<const P: u32> fmt::Display for Fixed<P> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut buf = [0u8; 48];
        match write_fixed(self.0, P, &mut buf) {
            // Only ASCII digits, a sign and a point are written.
            Some(n) => f.write_str(std::str::from_utf8(&buf[..n]).map_err(|_| fmt::Error)?),
            None => write!(f, "{:.*}", P as usize, self.0),
        }
    }
}

/// The text of `x` with `p` decimals into `out`, its length; `None` where core's formatter
/// is needed (not finite, `|x| >= 2^60`, `p > 9`).
fn write_fixed(x: f64, p: u32, out: &mut [u8; 48]) -> Option<usize> {
    if !x.is_finite() || x.abs() >= (1u64 << 60) as f64 || p > 9 {
        return None;
    }
    let bits = x.to_bits();
    let exp_bits = ((bits >> 52) & 0x7ff) as i32;
    let frac = bits & ((1u64 << 52) - 1);
    // |x| = m · 2^e exactly.
    let (m, e) = if exp_bits == 0 { (frac, -1074) } else { (frac | (1u64 << 52), exp_bits - 1075) };
    let scale = 10u128.pow(p);
    let prod = u128::from(m) * scale;
    let n: u128 = if e >= 0 {
        // |x| < 2^60 and m >= 2^52 give e <= 7: no overflow.
        prod << e
    } else {
        let s = e.unsigned_abs();
        if s >= 128 {
            // prod < 2^67 <= half of 2^s: rounds to zero.
            0
        } else {
            let q = prod >> s;
            let r = prod & ((1u128 << s) - 1);
            let half = 1u128 << (s - 1);
            if r > half || (r == half && q & 1 == 1) { q + 1 } else { q }
        }
    };
    let (int, fraction) = (n / scale, n % scale);
    let mut len = 0;
    if x.is_sign_negative() {
        out[0] = b'-';
        len = 1;
    }
    // The integer part's digits, most significant first.
    let mut digits = [0u8; 40];
    let mut k = digits.len();
    let mut v = int;
    loop {
        k -= 1;
        digits[k] = b'0' + (v % 10) as u8;
        v /= 10;
        if v == 0 {
            break;
        }
    }
    let whole = &digits[k..];
    out[len..len + whole.len()].copy_from_slice(whole);
    len += whole.len();
    if p > 0 {
        out[len] = b'.';
        len += 1;
        let mut v = fraction;
        for i in (0..p as usize).rev() {
            out[len + i] = b'0' + (v % 10) as u8;
            v /= 10;
        }
        len += p as usize;
    }
    Some(len)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn same(x: f64) -> Result<(), TestCaseError> {
        prop_assert_eq!(Fixed::<4>(x).to_string(), format!("{x:.4}"));
        prop_assert_eq!(Fixed::<3>(x).to_string(), format!("{x:.3}"));
        prop_assert_eq!(Fixed::<0>(x).to_string(), format!("{x:.0}"));
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20_000))]
        #[test]
        fn equals_core_on_any_bits(bits in any::<u64>()) {
            same(f64::from_bits(bits))?;
        }

        #[test]
        fn equals_core_on_certificate_sized_numbers(x in -1e4f64..1e4, shift in -30i32..12) {
            same(x * 2f64.powi(shift))?;
        }

        /// Exact ties at the last kept decimal (odd multiples of a power of two), where the
        /// rounding rule (half to even) decides.
        #[test]
        fn equals_core_on_ties(k in -100_000i64..100_000, j in 0i32..12) {
            same((2 * k + 1) as f64 / 2f64.powi(j))?;
            same((2 * k + 1) as f64 / 20_000.0)?;
        }
    }

    #[test]
    fn signed_zeros_and_edges() {
        for x in [0.0, -0.0, -1e-10, 5e-5, 1e-320, 0.03125, 0.09375, 2.5, (1u64 << 60) as f64] {
            same(x).expect("equal to core");
        }
    }

    #[test]
    fn sig_writes_what_a_person_writes() {
        for (x, text) in [
            (3.2600000000000002, "3.26"),
            (-0.1 - 0.2, "-0.3"),
            (0.0, "0"),
            (-0.0, "0"),
            (1234567.0, "1234567"),
            (999_999.5, "1000000"),
            (0.000_123_456_7, "0.000123457"),
            (1.5e-7, "1.5e-7"),
            (2.5e9, "2.5e+9"),
            (f64::INFINITY, "inf"),
        ] {
            assert_eq!(Sig(x).to_string(), text, "{x:?}");
        }
    }

    #[test]
    fn sig_range_keeps_the_width_of_a_range_far_from_zero() {
        for (lo, hi, text) in [
            (-0.637455, 0.9089, "[-0.637455, 0.9089]"),
            (999_999.362_545, 1_000_000.908_9, "[999999.36, 1000000.91]"),
            (999_999.362_545, 999_999.362_9, "[999999.362545, 999999.3629]"),
            (1e9 - 0.637455, 1e9 + 0.9089, "[999999999.36, 1000000000.91]"),
            (49.362545, 50.9089, "[49.3625, 50.9089]"),
            (1e9, 5e9, "[1e+9, 5e+9]"),
            (2.0, 1.0, "[2, 1]"),
            (f64::NEG_INFINITY, 1.0, "[-inf, 1]"),
        ] {
            assert_eq!(SigRange(lo, hi).to_string(), text, "{lo:?} {hi:?}");
        }
    }

    proptest! {
        /// Oracle: the range's own numbers. Both ends read back within six significant digits
        /// or within half a unit of the width's third digit, and the width they span is the
        /// range's to within one percent.
        #[test]
        fn sig_range_reads_back_with_its_width(
            size_exp in -3.0f64..12.0,
            negative in any::<bool>(),
            relative_exp in -11.0f64..2.0,
        ) {
            // A width relative to the ends' size, from 10⁻¹¹ (which the check's own
            // subtraction still resolves to 10⁻⁴ of itself) to 100.
            let lo = if negative { -1.0 } else { 1.0 } * 10f64.powf(size_exp);
            let hi = lo + lo.abs() * 10f64.powf(relative_exp);
            let width = hi - lo;
            let text = SigRange(lo, hi).to_string();
            let inner = text.trim_start_matches('[').trim_end_matches(']');
            let (a, b) = inner.split_once(", ").expect("two ends");
            let (a, b): (f64, f64) = (a.parse().expect("lo"), b.parse().expect("hi"));
            let unit = 10f64.powi(width.log10().floor() as i32 - 2);
            for (x, back) in [(lo, a), (hi, b)] {
                let close = (back - x).abs() <= (5e-6 * x.abs()).max(0.5 * unit) * (1.0 + 1e-9);
                prop_assert!(close, "{} -> {}", x, text);
            }
            prop_assert!(((b - a) - width).abs() <= 0.01 * width, "{} {} -> {}", lo, hi, text);
        }
    }

    proptest! {
        /// Six significant digits: the text reads back within half a unit of the sixth digit.
        #[test]
        fn sig_is_within_six_significant_digits(x in any::<f64>().prop_filter("finite", |x| x.is_finite())) {
            let back: f64 = Sig(x).to_string().parse().expect("a number");
            prop_assert!((back - x).abs() <= 5e-6 * x.abs() * (1.0 + 1e-12), "{} -> {}", x, back);
        }
    }
}
