//! The crate's error type.

/// Everything that can be wrong with a dynamics, disturbance, dither or simulation
/// configuration. Constructors validate once; simulation itself is infallible.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DynamicsError {
    /// A parameter is NaN or infinite.
    #[error("parameter `{name}` must be finite, got {value}")]
    NonFinite {
        /// Parameter name.
        name: &'static str,
        /// Offending value.
        value: f64,
    },
    /// A parameter that must be `>= 0` (a variance, a scale, a gain bound) is negative.
    #[error("parameter `{name}` must be >= 0, got {value}")]
    Negative {
        /// Parameter name.
        name: &'static str,
        /// Offending value.
        value: f64,
    },
    /// A parameter that must be `> 0` (a time step, a period, a hold time) is not.
    #[error("parameter `{name}` must be > 0, got {value}")]
    NotPositive {
        /// Parameter name.
        name: &'static str,
        /// Offending value.
        value: f64,
    },
    /// A probability outside `[0, 1]`.
    #[error("probability `{name}` must lie in [0, 1], got {value}")]
    InvalidProbability {
        /// Parameter name.
        name: &'static str,
        /// Offending value.
        value: f64,
    },
    /// A range whose lower end exceeds its upper end.
    #[error("range `{name}` must satisfy low <= high, got [{low}, {high}]")]
    InvalidRange {
        /// Parameter name.
        name: &'static str,
        /// Lower end.
        low: f64,
        /// Upper end.
        high: f64,
    },
    /// A disturbance schedule with no segment.
    #[error("a disturbance schedule needs at least one segment")]
    EmptySchedule,
    /// A schedule segment with `start >= end`.
    #[error("schedule segment {index} is empty: [{start}, {end})")]
    EmptySegment {
        /// Index of the segment in the schedule.
        index: usize,
        /// Segment start time.
        start: f64,
        /// Segment end time.
        end: f64,
    },
    /// Two schedule segments overlap (segments must be sorted and disjoint).
    #[error(
        "schedule segment {index} starts at {start} before the previous one ends at {previous_end}; \
         segments must be sorted by time and disjoint"
    )]
    OverlappingSegments {
        /// Index of the later segment.
        index: usize,
        /// Its start time.
        start: f64,
        /// End time of the segment before it.
        previous_end: f64,
    },
    /// A vector or matrix has the wrong length.
    #[error("`{name}` has length {got}, expected {expected}")]
    DimensionMismatch {
        /// What was mis-sized.
        name: &'static str,
        /// Expected length.
        expected: usize,
        /// Length given.
        got: usize,
    },
}
