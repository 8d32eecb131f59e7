//! The paper's certificates as functions of `β̂`, `ρ` and `ε` (eqs. rho and wass_cert).

/// `β_cert(ε) = β̂ − ρ (1 + 2ε)` (paper eq. wass_cert); `ε = 0` is the Gaussian certificate
/// `β̂ − ρ`.
#[must_use]
pub fn certificate_value(beta_hat: f64, rho: f64, eps: f64) -> f64 {
    beta_hat - rho * (1.0 + 2.0 * eps)
}

/// `β_cert(t, ε)` on a grid of radii for one step (the certificate surface of Fig. 3):
/// `out[i] = β̂ − ρ (1 + 2 eps[i])`.
///
/// # Panics
/// If `out` is shorter than `eps`.
pub fn certificate_surface(beta_hat: f64, rho: f64, eps: &[f64], out: &mut [f64]) {
    for (o, &e) in out[..eps.len()].iter_mut().zip(eps) {
        *o = certificate_value(beta_hat, rho, e);
    }
}
