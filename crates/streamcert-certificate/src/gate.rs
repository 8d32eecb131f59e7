//! The deployment gate (paper Section II-B, last sentence).

use serde::{Deserialize, Serialize};

/// Deployment gate: open once the certificate is `>= margin` for `needed` consecutive samples;
/// any sample below the margin (or without a certificate) closes it and restarts the count.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Gate {
    margin: f64,
    needed: usize,
    streak: usize,
    opened_at: Option<f64>,
    first_opened_at: Option<f64>,
}

/// The gate after one sample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GateState {
    /// `true` while the last `needed` certificates were all `>= margin`.
    pub open: bool,
    /// Current run of consecutive samples at or above the margin.
    pub streak: usize,
    /// Time at which the current opening began (the `needed`-th sample of the run).
    pub opened_at: Option<f64>,
    /// Time of the first opening in the stream: the deployment decision.
    pub first_opened_at: Option<f64>,
}

impl Gate {
    /// A closed gate with threshold `margin` (`β_margin`) and `needed >= 1` samples (`n_s`).
    /// The caller validates the parameters.
    #[must_use]
    pub fn new(margin: f64, needed: usize) -> Self {
        Self { margin, needed, streak: 0, opened_at: None, first_opened_at: None }
    }

    /// Feed the certificate of one sample (`None` when there is none).
    pub fn update(&mut self, t: f64, certificate: Option<f64>) -> GateState {
        match certificate {
            Some(c) if c >= self.margin => {
                self.streak += 1;
                if self.streak >= self.needed && self.opened_at.is_none() {
                    self.opened_at = Some(t);
                    self.first_opened_at.get_or_insert(t);
                }
            }
            _ => {
                self.streak = 0;
                self.opened_at = None;
            }
        }
        self.state()
    }

    /// The current state.
    #[must_use]
    pub fn state(&self) -> GateState {
        GateState {
            open: self.opened_at.is_some(),
            streak: self.streak,
            opened_at: self.opened_at,
            first_opened_at: self.first_opened_at,
        }
    }

    /// The margin `β_margin`.
    #[must_use]
    pub fn margin(&self) -> f64 {
        self.margin
    }

    /// Samples needed, `n_s`.
    #[must_use]
    pub fn needed(&self) -> usize {
        self.needed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn opens_after_n_consecutive_and_closes_on_a_dip() {
        let mut g = Gate::new(0.05, 3);
        let certs = [0.1, 0.1, f64::NAN, 0.1, 0.1, 0.1, 0.2, 0.0, 0.1];
        let open: Vec<bool> =
            certs.iter().enumerate().map(|(k, c)| g.update(k as f64, Some(*c)).open).collect();
        assert_eq!(open, [false, false, false, false, false, true, true, false, false]);
        assert_eq!(g.state().first_opened_at, Some(5.0));
        assert_eq!(g.state().opened_at, None);
        assert!(!g.update(9.0, None).open);
    }
}
