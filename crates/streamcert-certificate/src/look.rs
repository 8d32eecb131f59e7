//! The machinery the calibrated, nonlinear and coupling certificates share, beneath them: a
//! window's *look* and the rule for which look stands ([`Look`], [`standing`]), the risk a
//! look spends (`δ_{w,k} = δ · share / (k (k + 1))`, [`quantile::look_risk`]), and the
//! quantiles its bound needs (Student's t, [`quantile::t_quantile`]; the incomplete beta
//! function's continued fraction, which the F quantile reuses), Hotelling's machinery (the F
//! quantile, the simultaneous multiplier, the Wald test of a group of coefficients and its
//! [`NonlinearityTest`](hotelling::NonlinearityTest), [`hotelling`]), and the restore check
//! of a windowed state ([`same_windows`]). It depends on no certificate; the certificates
//! and the guards depend on it.

pub(crate) mod guard_variance;
pub(crate) mod hotelling;
pub(crate) mod larger;
pub(crate) mod quantile;
pub(crate) mod split;
mod standing;

pub(crate) use standing::{Look, standing};
use streamcert_regression::InstrumentedWindows;

/// Whether two window sets have the same lengths (a restored state against a fresh one).
pub(crate) fn same_windows(a: &InstrumentedWindows, b: &InstrumentedWindows) -> bool {
    a.count() == b.count() && (0..a.count()).all(|w| a.window(w) == b.window(w))
}
