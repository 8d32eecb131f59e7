//! # streamcert-experiments
//!
//! The paper's two experiments on G5 (Section V, Table I), in one place: each experiment's
//! constants ([`Experiment::setting`]), Experiment 1's noise schedule ([`regime_schedule`]), its data set ([`G5Dataset`]: G5 under the candidate
//! gains plus PRBS dither, the noise schedule) and the seed rule ([`G5Dataset::seeds`]). The
//! reproduction (`cargo xtask reproduce`) and `streamcert simulate g5` both read them from
//! here, so `simulate g5 --experiment E --seed s` writes exactly the data of reproduction run
//! `s`.
//!
//! This crate is for the experiments; the simulation substrate it uses
//! (`streamcert-dynamics`) knows nothing about them.
//!
//! ```
//! use streamcert_experiments::{Experiment, G5Dataset};
//! let one = Experiment::One.setting();
//! assert_eq!((one.k1, one.k4, one.steps), (-3.5, -4.0, 1500));
//! let data = G5Dataset::defaults(Experiment::Two).run_seeded(0)?;
//! assert_eq!(data.len(), Experiment::Two.setting().steps + 1);
//! # Ok::<(), streamcert_dynamics::DynamicsError>(())
//! ```

mod dataset;

pub use dataset::{Experiment, G5Dataset, Setting, regime_schedule};
