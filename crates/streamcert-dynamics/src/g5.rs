//! The five-node benchmark network G5 (paper, Section II-D, eqs. SA1 to SB5).
//!
//! Subsystem A (nodes 1 to 3) and subsystem B (nodes 4 and 5):
//!
//! ```text
//! ẋ1 = −x1 tanh(x1) + u1 + γ x4                       (SA1)
//! ẋ2 = x2³ − x2 + a12 x1                               (SA2)
//! ẋ3 = −x3 + a13 x1 x3 + a32 x2                        (SA3)
//! ẋ4 = −x4 + u4 + [γ x1 if Bidirectional] + η(t)       (SB4)
//! ẋ5 = −x5 + x4²                                       (SB5)
//! ```
//!
//! Measurements `y_A = x1`, `y_B = x4`; inputs `u = (u1, u4)`.
//!
//! The equations as printed couple one way only (`γ x4` enters `x1`): that is
//! [`Coupling::Cascade`], which contracts for every `γ` once both blocks do. The paper's
//! Experiment 2 text ("bidirectionally coupled") and Lemma 1 (a symmetric off-diagonal `γ`)
//! assume the other direction too: [`Coupling::Bidirectional`] adds `γ x1` to `ẋ4`.
//!
//! Disturbance channels (`q = 2`): channel 0 enters `x1` (process noise on subsystem A, which
//! the paper does not have; leave it at zero to follow the paper), channel 1 is the paper's
//! `η(t)` entering `x4` (eq. SB4).

use serde::{Deserialize, Serialize};

use crate::{Dynamics, DynamicsError, finite};

/// How subsystems A and B are coupled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Coupling {
    /// As printed in eqs. SA1 and SB4: `γ x4` enters `ẋ1` only (a cascade B → A).
    Cascade,
    /// `γ x4` enters `ẋ1` and `γ x1` enters `ẋ4`, as Lemma 1 and Experiment 2 assume.
    Bidirectional,
}

/// Parameters of G5. Every field is public; [`G5::new`] validates them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct G5Config {
    /// Weight of `x1` in `ẋ2` (paper: 0.3).
    pub a12: f64,
    /// Weight of `x1 x3` in `ẋ3` (paper: 0.4).
    pub a13: f64,
    /// Weight of `x2` in `ẋ3` (paper: 0.2).
    pub a32: f64,
    /// Coupling gain `γ >= 0` (eq. coupling).
    pub gamma: f64,
    /// Candidate local gain `k1` of `u1 = k1 x1` (paper Section II-D: −2.5).
    pub k1: f64,
    /// Candidate local gain `k4` of `u4 = k4 x4` (paper Section II-D: −3.0).
    pub k4: f64,
    /// Coupling structure.
    pub coupling: Coupling,
}

impl G5Config {
    /// The paper's fixed parameters (`a12 = 0.3`, `a13 = 0.4`, `a32 = 0.2`), the gains of
    /// Section II-D (`k1 = −2.5`, `k4 = −3.0`), `γ = 0`, and the given coupling structure.
    #[must_use]
    pub fn paper(coupling: Coupling) -> Self {
        Self { a12: 0.3, a13: 0.4, a32: 0.2, gamma: 0.0, k1: -2.5, k4: -3.0, coupling }
    }
}

/// True local contraction rates of the two observed closed loops at one state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalRates {
    /// `β*_A = −∂(ẋ1)/∂x1 = tanh x1 + x1 sech² x1 − k1` (subsystem A, `y_A = x1`, `u1 = k1 x1`).
    pub a: f64,
    /// `β*_B = −∂(ẋ4)/∂x4 = 1 − k4` (subsystem B, `y_B = x4`, `u4 = k4 x4`).
    pub b: f64,
}

/// The G5 benchmark network; implements [`Dynamics`] with `n = 5`, `m = 2`, `p = 2`, `q = 2`.
#[derive(Debug, Clone, PartialEq)]
pub struct G5 {
    cfg: G5Config,
    e: [f64; 10],
}

/// `E` (5 × 2, row-major): channel 0 into `x1`, channel 1 into `x4`.
const G5_E: [f64; 10] = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0];

impl G5 {
    /// Validate and build.
    ///
    /// # Errors
    /// [`DynamicsError::NonFinite`] for a NaN or infinite parameter,
    /// [`DynamicsError::Negative`] for `γ < 0`.
    ///
    /// ```
    /// use streamcert_dynamics::{G5, G5Config, Coupling, DynamicsError};
    /// assert!(G5::new(G5Config::paper(Coupling::Cascade)).is_ok());
    /// let bad = G5Config { gamma: -1.0, ..G5Config::paper(Coupling::Cascade) };
    /// assert!(matches!(G5::new(bad), Err(DynamicsError::Negative { name: "gamma", .. })));
    /// ```
    pub fn new(cfg: G5Config) -> Result<Self, DynamicsError> {
        finite("a12", cfg.a12)?;
        finite("a13", cfg.a13)?;
        finite("a32", cfg.a32)?;
        crate::non_negative("gamma", cfg.gamma)?;
        finite("k1", cfg.k1)?;
        finite("k4", cfg.k4)?;
        Ok(Self { cfg, e: G5_E })
    }

    /// The validated configuration.
    #[must_use]
    pub fn config(&self) -> &G5Config {
        &self.cfg
    }

    fn back_coupling(&self) -> f64 {
        match self.cfg.coupling {
            Coupling::Cascade => 0.0,
            Coupling::Bidirectional => self.cfg.gamma,
        }
    }

    /// Closed-loop Jacobian `∂f/∂x + B K C` (5 × 5, row-major) of G5 under the candidate local
    /// feedback `u1 = k1 x1`, `u4 = k4 x4` of the configuration.
    pub fn closed_loop_jacobian(&self, x: &[f64], jac: &mut [f64]) {
        self.jacobian(0.0, x, &[0.0, 0.0], jac);
        jac[0] += self.cfg.k1;
        jac[3 * 5 + 3] += self.cfg.k4;
    }

    /// True contraction rates of each subsystem's observed closed loop at state `x`
    /// ([`LocalRates`]): the negated scalar Jacobian of the measured channel under the
    /// configuration's local gains, with the coupling term excluded (it is what composition
    /// accounts for). These are the ground truth every local certificate is judged against.
    #[must_use]
    pub fn observed_closed_loop_rates(&self, x: &[f64]) -> LocalRates {
        let x1 = x[0];
        let th = x1.tanh();
        let sech2 = 1.0 - th * th;
        LocalRates { a: th + x1 * sech2 - self.cfg.k1, b: 1.0 - self.cfg.k4 }
    }

    /// True rates at the origin (the equilibrium of the undisturbed closed loop):
    /// `β*_A = −k1`, `β*_B = 1 − k4`.
    #[must_use]
    pub fn rates_at_origin(&self) -> LocalRates {
        self.observed_closed_loop_rates(&[0.0; 5])
    }
}

impl Dynamics for G5 {
    fn state_dim(&self) -> usize {
        5
    }
    fn input_dim(&self) -> usize {
        2
    }
    fn output_dim(&self) -> usize {
        2
    }
    fn disturbance_dim(&self) -> usize {
        2
    }

    fn drift(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let c = &self.cfg;
        let (x1, x2, x3, x4, x5) = (x[0], x[1], x[2], x[3], x[4]);
        dx[0] = -x1 * x1.tanh() + u[0] + c.gamma * x4;
        dx[1] = x2 * x2 * x2 - x2 + c.a12 * x1;
        dx[2] = -x3 + c.a13 * x1 * x3 + c.a32 * x2;
        dx[3] = -x4 + u[1] + self.back_coupling() * x1;
        dx[4] = -x5 + x4 * x4;
    }

    fn output(&self, x: &[f64], y: &mut [f64]) {
        y[0] = x[0];
        y[1] = x[3];
    }

    fn disturbance_gain(&self) -> &[f64] {
        &self.e
    }

    fn jacobian(&self, _t: f64, x: &[f64], _u: &[f64], jac: &mut [f64]) -> bool {
        let c = &self.cfg;
        let (x1, x2, x3, x4) = (x[0], x[1], x[2], x[3]);
        let th = x1.tanh();
        jac.fill(0.0);
        jac[0] = -(th + x1 * (1.0 - th * th));
        jac[3] = c.gamma;
        jac[5] = c.a12;
        jac[5 + 1] = 3.0 * x2 * x2 - 1.0;
        jac[10] = c.a13 * x3;
        jac[10 + 1] = c.a32;
        jac[10 + 2] = -1.0 + c.a13 * x1;
        jac[15] = self.back_coupling();
        jac[15 + 3] = -1.0;
        jac[20 + 3] = 2.0 * x4;
        jac[20 + 4] = -1.0;
        true
    }
}
