//! Sample times as a person reads them, for messages, summaries and the status page (the
//! evidence files and every JSON document keep the seconds, every digit).
//!
//! A time between [`UNIX_SECONDS`]' ends (2001-09-09 to 2100-01-01) reads as seconds since the
//! Unix epoch, as a live source's timestamps are: it is written in ISO 8601 UTC to the
//! millisecond, `2026-12-06T02:55:06.123Z`. Any other time is a clock of the data's own and is
//! written in seconds with the decimals its sampling step resolves, never with an exponent:
//! `t = 1234.57` at a step of 10 ms.

use std::fmt;

/// Sample times from `10⁹` s (2001-09-09T01:46:40Z) up to 2100-01-01T00:00:00Z read as Unix
/// seconds. A plant's own clock (seconds since its run began) stays below `10⁹` s for 31 years.
pub const UNIX_SECONDS: std::ops::Range<f64> = 1e9..4_102_444_800.0;

/// A sample time `t` as a person reads it (module docs). `step` is the data's sampling step
/// in seconds where known: the decimals resolve it (`⌈−log₁₀ step⌉`, at most 9), trailing
/// zeros dropped; without one (`None`, or a step that is not positive and finite), six
/// significant digits, trailing zeros dropped, never fewer than the integer's digits.
#[derive(Debug, Clone, Copy)]
pub struct SampleTime {
    /// The time, seconds.
    pub t: f64,
    /// The sampling step, seconds (`None`: not known).
    pub step: Option<f64>,
}

impl SampleTime {
    /// `t` with the step `step` (see the type's docs).
    #[must_use]
    pub fn new(t: f64, step: Option<f64>) -> Self {
        Self { t, step }
    }

    /// Whether `t` reads as Unix seconds ([`UNIX_SECONDS`]).
    #[must_use]
    pub fn is_unix(t: f64) -> bool {
        UNIX_SECONDS.contains(&t)
    }
}

impl fmt::Display for SampleTime {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let t = self.t;
        if !t.is_finite() {
            return write!(f, "{t}");
        }
        if Self::is_unix(t) {
            return f.write_str(&iso8601_utc(t));
        }
        let decimals = match self.step.filter(|s| s.is_finite() && *s > 0.0) {
            // A step of 0.01 or 0.025 takes 2 decimals (within half a step; the slack keeps
            // 0.1 at 1).
            Some(step) => (-step.log10() - 1e-9).ceil().clamp(0.0, 9.0) as usize,
            None if t == 0.0 => 0,
            None => {
                let digits = t.abs().log10().floor() as i32 + 1;
                (6 - digits).clamp(0, 9) as usize
            }
        };
        let text = format!("{t:.decimals$}");
        let text = if text.contains('.') {
            text.trim_end_matches('0').trim_end_matches('.')
        } else {
            &text
        };
        // `-0` (a negative time that rounds to zero) reads as `0`.
        f.write_str(if text == "-0" { "0" } else { text })
    }
}

/// `t` seconds since the Unix epoch in ISO 8601 UTC, rounded to the millisecond:
/// `YYYY-MM-DDThh:mm:ss.sssZ` (proleptic Gregorian calendar; `t` finite and within years 0 to
/// 9999, else the seconds as Rust writes them).
#[must_use]
pub fn iso8601_utc(t: f64) -> String {
    // Years 0000 to 9999.
    const LO: f64 = -62_167_219_200.0;
    const HI: f64 = 253_402_300_800.0;
    if !(LO..HI).contains(&t) {
        return format!("{t}");
    }
    let ms = (t * 1000.0).round() as i64;
    let (secs, milli) = (ms.div_euclid(1000), ms.rem_euclid(1000));
    let (days, of_day) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let (y, m, d) = civil_from_days(days);
    if y > 9999 {
        // 9999-12-31T23:59:59.9995 and later round into year 10000.
        return format!("{t}");
    }
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{milli:03}Z",
        of_day / 3600,
        of_day % 3600 / 60,
        of_day % 60
    )
}

/// The civil date `(year, month, day)` of `days` since 1970-01-01 (H. Hinnant's
/// `civil_from_days`, the proleptic Gregorian calendar in 400-year eras).
fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Days since 1970-01-01 of a civil date, by counting (the oracle of `civil_from_days`).
    fn days_by_counting(y: i64, m: u32, d: u32) -> i64 {
        let leap = |y: i64| (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
        let len = |y: i64| if leap(y) { 366 } else { 365 };
        let month = [31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31];
        let mut days: i64 =
            if y >= 1970 { (1970..y).map(len).sum() } else { -(y..1970).map(len).sum::<i64>() };
        for k in 0..(m - 1) as usize {
            days += month[k] + i64::from(k == 1 && leap(y));
        }
        days + i64::from(d) - 1
    }

    #[test]
    fn known_instants_in_utc() {
        assert_eq!(iso8601_utc(0.0), "1970-01-01T00:00:00.000Z");
        assert_eq!(iso8601_utc(1e9), "2001-09-09T01:46:40.000Z");
        // 2000-02-29, a leap day of a century year divisible by 400.
        assert_eq!(iso8601_utc(951_782_400.0), "2000-02-29T00:00:00.000Z");
        assert_eq!(iso8601_utc(-1.0), "1969-12-31T23:59:59.000Z");
        // Rounding to the millisecond carries into the next day.
        assert_eq!(iso8601_utc(86_399.999_6), "1970-01-02T00:00:00.000Z");
        assert_eq!(iso8601_utc(1_796_480_000.123_4), "2026-12-05T14:13:20.123Z");
    }

    #[test]
    fn unix_times_read_in_utc_and_others_in_seconds_with_their_decimals() {
        let unix = SampleTime::new(1_796_480_012.345, Some(0.01)).to_string();
        assert_eq!(unix, "2026-12-05T14:13:32.345Z");
        assert_eq!(SampleTime::new(20.0, Some(0.01)).to_string(), "20");
        assert_eq!(SampleTime::new(12_345.67, Some(0.01)).to_string(), "12345.67");
        assert_eq!(SampleTime::new(0.125, Some(0.025)).to_string(), "0.12");
        assert_eq!(SampleTime::new(3.1, Some(0.1)).to_string(), "3.1");
        assert_eq!(SampleTime::new(0.0, None).to_string(), "0");
        assert_eq!(SampleTime::new(-1e-12, Some(0.01)).to_string(), "0");
        assert_eq!(SampleTime::new(123.456_789, None).to_string(), "123.457");
        // Beyond 2100 and without a step: the seconds, no exponent.
        assert_eq!(SampleTime::new(5e9, None).to_string(), "5000000000");
        assert_eq!(SampleTime::new(f64::NAN, None).to_string(), "NaN");
    }

    proptest! {
        /// The date and time of every millisecond from year 0 to 9999 count back to it.
        #[test]
        fn utc_text_counts_back_to_its_millisecond(ms in -62_167_219_200_000i64..253_402_300_799_000) {
            let text = iso8601_utc(ms as f64 / 1000.0);
            prop_assert_eq!(text.len(), 24, "{}", text);
            let n = |a: usize, b: usize| text[a..b].parse::<i64>().unwrap();
            let days = days_by_counting(n(0, 4), n(5, 7) as u32, n(8, 10) as u32);
            let back = ((days * 24 + n(11, 13)) * 60 + n(14, 16)) * 60 + n(17, 19);
            // The nearest millisecond of ms / 1000 in f64 is ms.
            prop_assert_eq!(back * 1000 + n(20, 23), ms, "{}", text);
        }

        /// A time whose step is known reads back within half a step (every decimal it
        /// needs is written) and carries no exponent.
        #[test]
        fn seconds_resolve_the_step(t in -1e8f64..1e8, exp in -6i32..2) {
            let step = 10f64.powi(exp);
            let text = SampleTime::new(t, Some(step)).to_string();
            prop_assert!(!text.contains('e'), "{}", text);
            let back: f64 = text.parse().unwrap();
            prop_assert!((back - t).abs() <= 0.5 * step * (1.0 + 1e-6) + t.abs() * 1e-15, "{} {}", t, text);
        }
    }
}
