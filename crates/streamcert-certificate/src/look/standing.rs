//! The gate rule shared by the calibrated and nonlinear certificates: among the windows'
//! latest looks, the largest one that still stands.

use crate::NotCertified;

/// A window's latest look, as the gate logic sees it.
pub(crate) trait Look: Copy {
    /// Time of the look.
    fn time(&self) -> f64;
    /// Window length in columns.
    fn window(&self) -> usize;
    /// The certificate.
    fn value(&self) -> f64;
    /// The one-look upper bound, when below the margin.
    fn upper(&self) -> Option<f64>;
}

/// The largest *standing* look among `looks` (one per window) that `admit(window index, look)`
/// lets through, and, when a look was passed over for it, why: a look stops standing when a
/// look at least as recent has an upper bound below the margin (the loop no longer contracts
/// enough; closing never costs validity).
pub(crate) fn standing<L: Look>(
    looks: &[Option<L>],
    margin: f64,
    mut admit: impl FnMut(usize, &L) -> bool,
) -> (Option<L>, Option<NotCertified>) {
    let mut best: Option<L> = None;
    let mut contradicted = None;
    for (w, look) in looks.iter().enumerate() {
        let Some(look) = look else { continue };
        if !admit(w, look) {
            continue;
        }
        let against = looks
            .iter()
            .flatten()
            .find(|s| s.time() >= look.time() && s.upper().is_some_and(|u| u < margin));
        if let Some(s) = against {
            contradicted.get_or_insert(NotCertified::RateBelowMargin {
                window: s.window(),
                upper: s.upper().unwrap_or(f64::INFINITY),
            });
            continue;
        }
        if best.is_none_or(|b| look.value() > b.value()) {
            best = Some(*look);
        }
    }
    (best, contradicted)
}
