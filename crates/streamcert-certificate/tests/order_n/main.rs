//! The certificate of order `n` (`[regression] order = 2 | 3`) tested end to end on
//! simulated loops: at its boundary, its hidden-dynamics guard, and through the certifier.

mod auto;
mod boundary;
mod certifier;
mod hidden;
mod support;
