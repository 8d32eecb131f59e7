//! Times as the summary writes them: the instant in ISO 8601 UTC where a time reads as Unix
//! seconds, else seconds with the decimals the time column's step resolves; and the hint for
//! a time column that looks like milliseconds.

use streamcert_certificate::{SampleTime, Sig};

use super::Summary;

/// A time as the summary writes it: `t = 20` in the data's own seconds (the decimals its
/// step resolves), or the instant in ISO 8601 UTC where the time reads as Unix seconds
/// ([`SampleTime`]).
pub(crate) fn at_time(t: f64, step: Option<f64>) -> String {
    if SampleTime::is_unix(t) {
        SampleTime::new(t, step).to_string()
    } else {
        format!("t = {}", SampleTime::new(t, step))
    }
}

impl Summary {
    /// The time column's median step over its first steps (positive steps only; `None`
    /// before two rows).
    #[must_use]
    pub fn median_step(&self) -> Option<f64> {
        let mut steps: Vec<f64> = self.first_steps.iter().copied().filter(|d| *d > 0.0).collect();
        if steps.is_empty() {
            return None;
        }
        steps.sort_by(f64::total_cmp);
        Some(steps[steps.len() / 2])
    }

    /// `t = …` (or the instant in UTC), or `never`.
    pub(super) fn when(&self, t: Option<f64>) -> String {
        t.map_or_else(|| "never".into(), |t| at_time(t, self.median_step()))
    }

    /// `first at t = …`, or `never opened`: a gate's first opening.
    pub(super) fn first(&self, t: Option<f64>) -> String {
        t.map_or_else(
            || "never opened".into(),
            |t| format!("first at {}", at_time(t, self.median_step())),
        )
    }

    /// A hint when the time column's median step (over its first steps) is 10 or more: a
    /// control loop sampled that slowly is rare, a time column in milliseconds is not (its
    /// rates would read 1000 times too small against a margin per second).
    #[must_use]
    pub fn time_unit_hint(&self) -> Option<String> {
        let median = self.median_step()?;
        (median >= 10.0).then(|| {
            format!(
                "the time column's median step is {} (read as seconds, as every rate and the \
                 margin are per second): if the times are in milliseconds, divide them by 1000",
                Sig(median)
            )
        })
    }
}
