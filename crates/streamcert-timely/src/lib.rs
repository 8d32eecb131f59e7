//! # streamcert-timely
//!
//! The live network certificate of `streamcert-network` across processes and machines, on
//! [timely-dataflow](https://github.com/TimelyDataflow/timely-dataflow). Every process is a
//! *site*: it reads its own input, holding only the subsystems the [`Placement`] gives it,
//! and certifies them itself. Raw samples never leave a site; what crosses to worker 0 (process
//! 0), which composes the epochs with the same [`Composer`] as the one-process
//! [`NetworkCertifier`](streamcert_network::NetworkCertifier), is per epoch the snapshots
//! ([`LocalSnapshot`]: time, verdict, coupling bounds) of the subsystems whose samples changed
//! them, and two marks (the site's first epoch, the epochs its rows made due).
//!
//! **Event time.** The timely timestamp is the epoch index `k` (composed at `t = k · epoch`
//! from every sample at `t < k · epoch`). A site runs its own epoch clock ([`Composer::due`])
//! on its rows; when a row crosses the boundaries `a..b` it sends the changed snapshots at
//! timestamp `a` and advances its input to `b`. Worker 0 composes epoch `k` once timely's
//! frontier has passed `k`: every site has passed it. The epochs composed are those the
//! one-process run over the sites' rows merged in time order composes, from the same
//! snapshots, with the same code: the same reports, bit for bit (tested over three processes).
//!
//! **Pace and memory.** Before a site crosses a boundary `a` it waits until worker 0 has
//! composed every epoch before `a` (a probe on the composer, which holds a capability at its
//! next epoch): no site runs more than one epoch ahead of the composition, so nothing queues
//! without bound when one site is slow, behind in event time, or down. The network runs at
//! the pace of its slowest site. A site whose live input is silent for
//! [`Placement::silence`] of wall-clock time advances its own clock by the wall-clock time
//! elapsed since its last row (the one-process run's `advance` on a clock tick), so its
//! subsystems turn stale under `stale_after` and the network is not certified, instead of
//! holding every epoch back. A time far ahead at one site (within `max_epoch_jump`) makes the
//! epochs up to it due, where the other sites' subsystems are stale, as in one process; beyond
//! `max_epoch_jump` it stops that site with [`NetworkError::TimeJump`].
//!
//! **Checkpoints and restart.** With checkpoints every `e` epochs, every site hands out its
//! [`SiteState`] when a row crosses a boundary range `a..b` holding a multiple of `e` (before
//! it sends anything of the new epochs) and when its input ends, and process 0 its
//! [`ComposerState`] at the run's first epoch and whenever its next epoch is a multiple of
//! `e` (after the reports before it were handed out, before its next epoch shows on the
//! probe). The caller writes them; the worker waits until the caller says they are written.
//! A restarted run resumes at the composer's checkpointed epoch `K`: every site whose
//! checkpoint holds epochs from `valid_from <= K` resumes it and re-sends its snapshots at
//! `K`; a site whose checkpoint is newer than the composer's reads its input again from the
//! start (every send is at a timestamp no earlier than `K`, so the composer sees at `K` the
//! state its rows give at `K`). Either way the reports from `K` on are the uninterrupted
//! run's (tested by restarting from the checkpoints of every moment of a run). At the start
//! every process broadcasts what it resumes from; a process whose checkpoint is of another
//! configuration, placement or run is refused ([`TimelyError::Checkpoint`]) and the others
//! get [`TimelyError::PeerRefused`]. Timely takes the whole computation down when one
//! process dies (its connections fail): the others return [`TimelyError::PeerLost`] and may
//! rejoin from their own checkpoints; no epoch is composed while a process is down (held
//! back until it returns).
//!
//! **Failures.** A row the source rejects, a time too far ahead or a sample a subsystem
//! rejects stops that site, like the one-process run: the epochs before it are composed and
//! reported, no later one; the site returns its error and process 0
//! [`TimelyError::Remote`] naming the site.

mod api;
mod compose;
mod events;
mod handshake;
mod ingest;
mod operator;
mod run;
mod site;
mod wire;
mod worker;

pub use api::{Outcome, Output, Placement, Resume, Row, TimelyError};
pub use compose::ComposerState;
pub(crate) use events::{Event, Failure, Shared, Tx, ask, send};
pub use run::run;
pub use site::SiteState;
