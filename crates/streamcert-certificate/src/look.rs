//! The machinery the calibrated, nonlinear and coupling certificates share, beneath them: a
//! window's *look* and the rule for which look stands ([`Look`], [`standing`]), the risk a
//! look spends (`δ_{w,k} = δ · share / (k (k + 1))`, [`quantile::look_risk`]), and the
//! quantiles its bound needs (Student's t, [`quantile::t_quantile`]; the incomplete beta
//! function's continued fraction, which the F quantile of the Hotelling tests reuses). It
//! depends on no certificate; the certificates and the guards depend on it.

pub(crate) mod quantile;
mod standing;

pub(crate) use standing::{Look, standing};
