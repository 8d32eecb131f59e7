//! Why a gate is closed after a sample: the reason the certifier reports beside each
//! verdict.

use crate::{Gate, GateState, NotCertified};

/// Why a gate is closed after this sample (`None` when it is open).
pub(super) fn closed_reason(
    blocked: Option<NotCertified>,
    cert: Option<f64>,
    state: &GateState,
    gate: &Gate,
) -> Option<NotCertified> {
    if state.open {
        return None;
    }
    if blocked.is_some() {
        return blocked;
    }
    match cert {
        Some(c) if c >= gate.margin() => {
            Some(NotCertified::Accumulating { streak: state.streak, needed: gate.needed() })
        }
        Some(c) => Some(NotCertified::BelowMargin { certificate: c, margin: gate.margin() }),
        None => Some(NotCertified::InsufficientExcitation),
    }
}
