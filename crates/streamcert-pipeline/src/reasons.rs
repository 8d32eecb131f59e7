//! The reasons a gate is closed, in words a person reads: the summary's, the picture's, the
//! network verdict's, the status page's and the verdict messages'. A module of its own, so
//! that the summary and the picture both use it without depending on each other.

/// A reason's kind in words, with the kind: `"<phrase> [<kind>]"` (the certify summary's, the
/// network verdict's, the status page's and the verdict messages').
pub fn reason_words(kind: &str) -> String {
    format!("{} [{kind}]", reason_phrase(kind))
}

/// A reason's kind in words a person reads (the kind itself where it has none).
pub fn reason_phrase(kind: &str) -> &str {
    match kind {
        "warming_up" => "warming up (too few columns yet)",
        "insufficient_excitation" | "weak_instruments" => {
            "too little excitation (weak instruments)"
        }
        "below_margin" => "the certificate is below the margin",
        "accumulating" => "above the margin, not yet for n_s samples",
        "gap" => "a gap in the time column reset the window",
        "rate_below_margin" => "the newest data bound the rate below the margin",
        "varying_dynamics" => "the dynamics vary over the explored region (nonlinearity guard)",
        "hidden_dynamics" => {
            "the output has dynamics beyond its model's order (hidden-dynamics guard)"
        }
        "order_untested" | "linearity_untested" => "the guards have not tested the window yet",
        "plant_changed" => "the plant changed (change guard)",
        "skipped_sample" => "a bad sample was skipped",
        "weakly_identified" => {
            "the data barely identify the rate: the input moved too rarely in the windows"
        }
        "input_follows_outputs" => {
            "the input follows the outputs: the data cannot separate the plant from the \
             controller (add a dither)"
        }
        "outside_region" => "the output is outside the region the nonlinear certificate speaks for",
        "library_misfit" => "the feature library misses the drift (lack-of-fit check)",
        "library_untested" => "the lack-of-fit check has not tested the window yet",
        "first_order_only" => {
            "not computed at this order (the paper's certificates are first-order)"
        }
        other => other,
    }
}
