//! The snapshots as they cross processes. Timely serialises with bincode, which cannot read
//! the internally tagged `NotCertified` of the certificate crate's serde form; the wire form
//! is the same data with an externally tagged reason (serde's remote derive, so the compiler
//! checks every variant and field against the certificate crate).

use serde::{Deserialize, Serialize};
use streamcert_certificate::{NotCertified, Verdict};
use streamcert_network::LocalSnapshot;

#[derive(Serialize, Deserialize)]
#[serde(remote = "NotCertified")]
enum ReasonDef {
    WarmingUp { columns: usize, needed: usize },
    InsufficientExcitation,
    WeakInstruments,
    BelowMargin { certificate: f64, margin: f64 },
    Accumulating { streak: usize, needed: usize },
    SkippedSample,
    NoAmbiguityModel,
    NoCalibration,
    Gap { dt: f64, reference: f64 },
    RateBelowMargin { window: usize, upper: f64 },
    VaryingDynamics { window: usize, statistic: f64, threshold: f64 },
    LinearityUntested { window: usize },
    HiddenDynamics { window: usize, statistic: f64, threshold: f64, order: usize },
    OrderUntested { window: usize },
    PlantChanged { window: usize, beta_hat: f64, newest_upper: f64 },
    NoNonlinearModel,
    LibraryMisfit { window: usize, statistic: f64, threshold: f64 },
    LibraryUntested { window: usize },
    WeaklyIdentified { window: usize, moves: f64 },
    InputFollowsOutputs { window: usize },
    OutsideRegion { y: f64, lo: f64, hi: f64 },
    FirstOrderOnly,
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Reason(#[serde(with = "ReasonDef")] NotCertified);

/// What a site sends the composing worker, at the timely timestamp of the epoch it concerns.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) enum Msg {
    /// The site's first row makes epochs `< first` due and starts its clock (timestamp 0).
    Start { first: u64 },
    /// The site's rows make the epochs `< end` due.
    Reached { end: u64 },
    /// Subsystem `index`'s newest snapshot, valid from this timestamp's epoch on.
    Snap { index: u32, snapshot: WireSnapshot },
    /// The site's row count and last time (at the end of its input).
    Rows { process: u32, rows: u64, last_time: Option<f64> },
    /// The site stopped at `line` (a rejected row, sample or time).
    Failed { process: u32, line: u64, message: String },
}

/// A [`LocalSnapshot`] in bincode-friendly form.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct WireSnapshot {
    t: f64,
    value: Option<f64>,
    radius: Option<f64>,
    open: bool,
    reason: Option<Reason>,
    couplings: Vec<Option<f64>>,
}

impl From<&LocalSnapshot> for WireSnapshot {
    fn from(s: &LocalSnapshot) -> Self {
        let v = s.verdict;
        Self {
            t: s.t,
            value: v.value,
            radius: v.radius,
            open: v.open,
            reason: v.reason.map(Reason),
            couplings: s.couplings.clone(),
        }
    }
}

impl From<WireSnapshot> for LocalSnapshot {
    fn from(w: WireSnapshot) -> Self {
        let verdict = Verdict {
            value: w.value,
            radius: w.radius,
            open: w.open,
            reason: w.reason.map(|r| r.0),
        };
        Self { t: w.t, verdict, couplings: w.couplings }
    }
}

/// The dataflow's input of messages (a site's snapshots and marks), by epoch.
pub(crate) type MsgInput =
    timely::dataflow::InputHandle<u64, timely::container::CapacityContainerBuilder<Vec<Msg>>>;
