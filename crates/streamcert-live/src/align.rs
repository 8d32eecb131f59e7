//! Per-signal updates into rows on a grid, by source time: the sample-and-hold rule.
//!
//! A plant's signals arrive one at a time (a topic or node each), on their own clocks. The
//! certifier needs rows `(t, y, u)` at a steady step. The rule, with a period `T`, a
//! `max_age` `A` and a reorder window `R` (all in seconds of source time):
//!
//! 1. **The grid** is `g_k = k·T` for integers `k`, in source time (so a restarted process
//!    forms the same rows). It starts at the first `g_k` at or after `t₁ − R`, `t₁` the first
//!    update's source time (so that updates reordered within the window before it count).
//! 2. **A row at `g_k`** takes, for every signal, its latest value with source time `≤ g_k`
//!    (of two with the same time, the one that arrived later). If every such value is at most
//!    `A` old (`g_k − t ≤ A`), the row is formed. Otherwise it is **stale**: not formed, never
//!    interpolated; once a row has been formed, a stale stretch is a **gap** before the next
//!    formed row, and the certifier restarts its windows there. Before the first formed row,
//!    grid points that lack a signal are passed over (the signals are still arriving).
//! 3. **Order**: `g_k` is decided once the newest source time seen is at least `g_k + R`
//!    (the watermark). An update whose source time is at or before the last decided grid
//!    point arrives too late to change a row that is out: it is dropped and counted as
//!    **late**. Updates within the window are put in order of source time.
//!
//! What each setting costs: `R` delays every row by `R` (the latency from a sample to its
//! evidence row); a smaller `R` drops more reordered updates. A larger `A` holds a value
//! longer (a stuck sensor looks alive for `A`); a smaller one turns jitter into gaps. `T`
//! below the signals' own period repeats held values (rows that carry no new information
//! about one signal; the integral regression still sees the others move).
//!
//! Memory: the updates within the reorder window, per signal; no allocation per update once
//! the buffers have grown to that.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

/// The alignment rule's settings (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AlignRule {
    /// The grid's period `T`, seconds.
    pub period: f64,
    /// The oldest a held value may be at a grid point, `A`, seconds.
    pub max_age: f64,
    /// How far behind the newest source time a grid point is decided, `R`, seconds.
    pub reorder_window: f64,
}

impl AlignRule {
    /// Check the settings: `T > 0`, `A ≥ 0`, `R ≥ 0`, all finite.
    ///
    /// # Errors
    /// Which setting is wrong, in words.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.period > 0.0 && self.period.is_finite()) {
            return Err(format!("period must be finite and > 0, got {}", self.period));
        }
        if !(self.max_age >= 0.0 && self.max_age.is_finite()) {
            return Err(format!("max_age must be finite and >= 0, got {}", self.max_age));
        }
        if !(self.reorder_window >= 0.0 && self.reorder_window.is_finite()) {
            return Err(format!(
                "reorder_window must be finite and >= 0, got {}",
                self.reorder_window
            ));
        }
        Ok(())
    }
}

/// What the aligner yields.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Aligned {
    /// A formed row at this grid time; its values are in the caller's buffer.
    Row(f64),
    /// Rows were stale before the next formed row: new windows start there.
    Gap,
}

/// The aligner's state: everything needed to continue bit for bit (it is saved in a
/// checkpoint with the certifier).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Aligner {
    rule: AlignRule,
    /// Per signal, updates after the last decided grid point, in order of source time.
    pending: Vec<VecDeque<(f64, f64)>>,
    /// Per signal, the latest update at or before the last decided grid point.
    held: Vec<Option<(f64, f64)>>,
    /// The next grid index to decide (`None` before the first update).
    next: Option<i64>,
    /// The newest source time seen.
    newest: f64,
    /// A row has been formed.
    started: bool,
    /// A stale grid point since the last formed row.
    gap: bool,
    /// Updates dropped as late.
    late: u64,
    /// Grid points not formed after the first row.
    stale: u64,
    /// The last formed row's values.
    out: Vec<f64>,
    /// A formed row held back behind the gap yielded before it.
    queued: Option<f64>,
}

/// An update that came too late: its rows are already out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Late {
    /// The update's source time.
    pub t: f64,
    /// The last decided grid time.
    pub decided: f64,
}

impl Aligner {
    /// An aligner for `signals` signals.
    ///
    /// # Errors
    /// The rule's settings ([`AlignRule::validate`]), or no signal.
    pub fn new(signals: usize, rule: AlignRule) -> Result<Self, String> {
        rule.validate()?;
        if signals == 0 {
            return Err("no signal to align".into());
        }
        Ok(Self {
            rule,
            pending: vec![VecDeque::new(); signals],
            held: vec![None; signals],
            next: None,
            newest: f64::NEG_INFINITY,
            started: false,
            gap: false,
            late: 0,
            stale: 0,
            out: vec![0.0; signals],
            queued: None,
        })
    }

    /// The number of signals.
    #[must_use]
    pub fn signals(&self) -> usize {
        self.held.len()
    }

    /// `true` when the state is one [`push`](Self::push) and [`pop`](Self::pop) could have
    /// produced (every per-signal buffer sized for the signals, each queue in order of time,
    /// every time finite): what a restored state is checked against.
    #[must_use]
    pub fn is_consistent(&self) -> bool {
        let n = self.held.len();
        let ordered = |q: &VecDeque<(f64, f64)>| {
            q.iter().all(|(t, v)| t.is_finite() && v.is_finite())
                && q.iter().zip(q.iter().skip(1)).all(|(a, b)| a.0 <= b.0)
        };
        self.rule.validate().is_ok()
            && n > 0
            && self.pending.len() == n
            && self.out.len() == n
            && self.pending.iter().all(ordered)
            && self.held.iter().flatten().all(|(t, v)| t.is_finite() && v.is_finite())
    }

    /// The rule.
    #[must_use]
    pub fn rule(&self) -> AlignRule {
        self.rule
    }

    /// Updates dropped as late so far.
    #[must_use]
    pub fn late(&self) -> u64 {
        self.late
    }

    /// Grid points not formed (stale) after the first formed row.
    #[must_use]
    pub fn stale(&self) -> u64 {
        self.stale
    }

    /// The grid time of index `k`.
    fn grid(&self, k: i64) -> f64 {
        k as f64 * self.rule.period
    }

    /// Take an update of `signal` with source time `t` and value `v` (both finite; the
    /// caller checks). Then [`pop`](Self::pop) until `None`.
    ///
    /// # Errors
    /// [`Late`] when a grid point at or after `t` was already decided (the update is dropped
    /// and counted).
    ///
    /// # Panics
    /// When `signal` is out of range (a caller's bug: signals are fixed at construction).
    pub fn push(&mut self, signal: usize, t: f64, v: f64) -> Result<(), Late> {
        let (p, r) = (self.rule.period, self.rule.reorder_window);
        let next = *self.next.get_or_insert_with(|| ((t - r) / p).ceil() as i64);
        let decided = self.grid(next - 1);
        if t <= decided {
            self.late += 1;
            return Err(Late { t, decided });
        }
        let queue = &mut self.pending[signal];
        // After every update of the same or an earlier time (the later arrival wins a tie).
        let at = queue.partition_point(|&(u, _)| u <= t);
        queue.insert(at, (t, v));
        self.newest = self.newest.max(t);
        Ok(())
    }

    /// The next decided grid point, if the watermark has passed one: a formed row (its values
    /// written into `row`, one per signal) or a gap before the next formed row. `None` when
    /// no grid point can be decided yet.
    ///
    /// # Panics
    /// When `row`'s length is not the number of signals.
    pub fn pop(&mut self, row: &mut [f64]) -> Option<Aligned> {
        if let Some(g) = self.queued.take() {
            row.copy_from_slice(&self.out);
            return Some(Aligned::Row(g));
        }
        loop {
            let k = self.next?;
            let g = self.grid(k);
            if !(self.newest - self.rule.reorder_window >= g) {
                return None;
            }
            self.next = Some(k + 1);
            let mut fresh = true;
            for (s, queue) in self.pending.iter_mut().enumerate() {
                while let Some(&(t, v)) = queue.front().filter(|(t, _)| *t <= g) {
                    self.held[s] = Some((t, v));
                    queue.pop_front();
                }
                match self.held[s] {
                    Some((t, v)) if g - t <= self.rule.max_age => self.out[s] = v,
                    _ => fresh = false,
                }
            }
            if fresh {
                self.started = true;
                if std::mem::take(&mut self.gap) {
                    // The row after a gap is yielded at the next call.
                    self.queued = Some(g);
                    return Some(Aligned::Gap);
                }
                row.copy_from_slice(&self.out);
                return Some(Aligned::Row(g));
            }
            if self.started {
                self.stale += 1;
                self.gap = true;
            }
        }
    }
}
