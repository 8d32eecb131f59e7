//! The [`Dynamics`] trait.

/// A controlled stochastic system `dx = f(t, x, u) dt + E dη`, with measurement `y = C x`.
///
/// Dimensions: state `n`, input `m`, output `p`, disturbance channels `q`. All matrices
/// exchanged through this trait are dense and **row-major**.
///
/// Implementations must be pure functions of their arguments (no interior state), so that a
/// simulation is reproducible from its seed.
pub trait Dynamics {
    /// State dimension `n`.
    fn state_dim(&self) -> usize;
    /// Input dimension `m`.
    fn input_dim(&self) -> usize;
    /// Output dimension `p`.
    fn output_dim(&self) -> usize;
    /// Number of scalar disturbance channels `q`.
    fn disturbance_dim(&self) -> usize;

    /// Drift `dx ← f(t, x, u)` (without the disturbance).
    ///
    /// `x.len() == n`, `u.len() == m`, `dx.len() == n`.
    fn drift(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]);

    /// Measurement `y ← C x`. `y.len() == p`.
    fn output(&self, x: &[f64], y: &mut [f64]);

    /// The disturbance gain `E` (`n × q`, row-major): channel `j` enters state `i` with weight
    /// `E[i * q + j]`.
    fn disturbance_gain(&self) -> &[f64];

    /// Analytic state Jacobian `J ← ∂f/∂x (t, x, u)` (`n × n`, row-major).
    ///
    /// Returns `false` (leaving `jac` unspecified) when the Jacobian is not known analytically;
    /// the default implementation does that.
    fn jacobian(&self, t: f64, x: &[f64], u: &[f64], jac: &mut [f64]) -> bool {
        let _ = (t, x, u, jac);
        false
    }
}
