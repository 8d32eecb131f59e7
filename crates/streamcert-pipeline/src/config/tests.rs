//! The configuration file: defaults, refusals, and what each section selects.

use super::*;
use streamcert_certificate::{FeatureSet, NonlinearConfig, RegionBound, RiskSplit};

/// The printed configuration with G5 node b's required keys set.
fn base() -> String {
    g5_node_b()
}

#[test]
fn default_config_parses() {
    let c = parse(&base(), "default").unwrap();
    assert_eq!(c.certifier.gain, vec![-4.0]);
    assert!(c.certifier.ambiguity.is_some());
}

#[test]
fn bad_configs_are_refused() {
    let unknown = base().replace("margin = 0.05", "margin = 0.05\nmargn = 1");
    assert!(parse(&unknown, "x").unwrap_err().to_string().contains("margn"));
    let shape = base().replace("gain = [[-4.0]]", "gain = [[-4.0, 1.0]]");
    assert!(parse(&shape, "x").unwrap_err().to_string().contains("m × p"));
    let invalid = base().replace("conservatism = 0.1", "conservatism = -1.0");
    assert!(parse(&invalid, "x").unwrap_err().to_string().contains("conservatism"));
    let risk = base().replace("delta = 0.01 ", "delta = 1.5 ");
    assert!(parse(&risk, "x").unwrap_err().to_string().contains("delta"));
}

#[test]
fn keys_with_documented_defaults_may_be_omitted() {
    let full = parse(&base(), "default").unwrap();
    let text = base();
    let start = text.find("[ambiguity]").unwrap();
    let end = text.find("[calibration]").unwrap();
    let short = format!("{}[ambiguity]\nenabled = true\n\n{}", &text[..start], &text[end..]);
    let short = short.replace("window = 150 ", "# window = 150 ");
    let parsed = parse(&short, "short").unwrap();
    assert_eq!(parsed.certifier, full.certifier);
}

#[test]
fn calibration_section_selects_the_calibrated_certificate() {
    // The default is the calibrated certificate with every guard.
    assert_eq!(
        parse(&base(), "default").unwrap().certifier.calibration,
        Some(Calibration::new(0.01))
    );
    let on = base().replace("delta = 0.01 ", "delta = 0.05 ");
    let c = parse(&on, "x").unwrap();
    assert_eq!(c.certifier.calibration, Some(Calibration::new(0.05)));
    let tuned = on.replace("# windows = 5 ", "windows = 2 ");
    let c = parse(&tuned, "x").unwrap();
    assert_eq!(c.certifier.calibration.map(|c| c.windows), Some(Some(2)));
    let batched = on.replace("# batch_blocks = 1 ", "batch_blocks = 4 ");
    let c = parse(&batched, "x").unwrap().certifier.calibration.unwrap();
    assert_eq!(c.batch_blocks, 4);
    // A window below h (u + 2) has no calibrated bound: refused, naming the smallest. With
    // the guards u = p + m + 1 + 2p = 5 (the nonlinearity guard's fit: 35 columns); through
    // the origin 30; without the guards 25 and 20.
    let short = on.replace("window = 150 ", "window = 10 ");
    let err = parse(&short, "x").unwrap_err().to_string();
    assert!(err.contains("smallest valid window is 35"), "{err}");
    let origin = short.replace("model = \"affine\"", "model = \"through_origin\"");
    let err = parse(&origin, "x").unwrap_err().to_string();
    assert!(err.contains("smallest valid window is 30"), "{err}");
    let bare = short
        .replace("# hidden_dynamics = true ", "hidden_dynamics = false ")
        .replace("# nonlinearity = true ", "nonlinearity = false ");
    let err = parse(&bare, "x").unwrap_err().to_string();
    assert!(err.contains("smallest valid window is 25"), "{err}");
    let origin = bare.replace("model = \"affine\"", "model = \"through_origin\"");
    let err = parse(&origin, "x").unwrap_err().to_string();
    assert!(err.contains("smallest valid window is 20"), "{err}");
    let zero_margin = on.replace("margin = 0.05", "margin = 0.0");
    assert!(parse(&zero_margin, "x").unwrap_err().to_string().contains("margin"));
}

#[test]
fn nonlinear_section_selects_the_nonlinear_certificate() {
    let nl = "enabled = false\nfeatures";
    let both = base().replace(nl, "enabled = true\nfeatures");
    // Without a calibration (the paper-only mode) the nonlinear certificate is refused,
    // saying what to set.
    let paper = both.replace("enabled = true\ndelta = 0.01", "enabled = false\ndelta = 0.01");
    let err = parse(&paper, "x").unwrap_err().to_string();
    assert!(err.contains("needs a calibration"), "{err}");
    let c = parse(&both, "x").unwrap();
    assert_eq!(c.certifier.nonlinear, Some(NonlinearConfig::default()));
    let deg = both.replace("degree = 2", "degree = 3").replace("# cells = 32 ", "cells = 8 ");
    let c = parse(&deg, "x").unwrap().certifier.nonlinear.unwrap();
    assert_eq!((c.degree, c.cells, c.check_terms, c.region_trim), (3, 8, 2, 0.025));
    // The region: the quantiles' trim, or the bounding box (trim 0), never both.
    let trim = both.replace("# region_trim = 0.025 ", "region_trim = 0.05 ");
    assert_eq!(parse(&trim, "x").unwrap().certifier.nonlinear.unwrap().region_trim, 0.05);
    let hull = both.replace("region = \"quantiles\"", "region = \"bounding_box\"");
    assert_eq!(parse(&hull, "x").unwrap().certifier.nonlinear.unwrap().region_trim, 0.0);
    let both_rules = hull.replace("# region_trim = 0.025 ", "region_trim = 0.05 ");
    assert!(parse(&both_rules, "x").unwrap_err().to_string().contains("region_trim"));
    let sim = both.replace("# bound = \"pointwise\" ", "bound = \"simultaneous\" ");
    let bound = |t: &str| parse(t, "x").unwrap().certifier.nonlinear.unwrap().bound;
    assert_eq!((bound(&both), bound(&sim)), (RegionBound::Pointwise, RegionBound::Simultaneous));
    let typo = both.replace("# bound = \"pointwise\" ", "bound = \"both\" ");
    assert!(parse(&typo, "x").unwrap_err().to_string().contains("bound"));
    // The certificate's own split of delta: M_w² by default, or as [calibration]'s.
    let split = |t: &str| parse(t, "x").unwrap().certifier.nonlinear.unwrap().risk_split;
    let key = "# risk_split = \"by_length_squared\" ";
    let equal = both.replace(key, "risk_split = \"equal\" ");
    assert_eq!((split(&both), split(&equal)), (RiskSplit::ByLengthSquared, RiskSplit::Equal));
    let typo = both.replace(key, "risk_split = \"longest\" ");
    assert!(parse(&typo, "x").unwrap_err().to_string().contains("risk_split"));
    let wide = both.replace("# region_trim = 0.025 ", "region_trim = 0.3 ");
    assert!(parse(&wide, "x").unwrap_err().to_string().contains("region_trim"));
    let off = both.replace("# check_terms = 2 ", "check_terms = 0 ");
    assert_eq!(parse(&off, "x").unwrap().certifier.nonlinear.unwrap().check_terms, 0);
    let many = both.replace("# check_terms = 2 ", "check_terms = 9 ");
    assert!(parse(&many, "x").unwrap_err().to_string().contains("check_terms"));
    let unknown = both.replace("features = \"polynomial\"", "features = \"splines\"");
    assert!(parse(&unknown, "x").unwrap_err().to_string().contains("splines"));
    let named = both.replace("features = \"polynomial\"", "features = [\"y\", \"y*tanh(y)\"]");
    let c = parse(&named, "x").unwrap().certifier.nonlinear.unwrap();
    assert_eq!(c.library(), FeatureSet::from_names(&["y", "y*tanh(y)"]).unwrap());
    let first = both.replace("features = \"polynomial\"", "features = [\"tanh(y)\"]");
    assert!(parse(&first, "x").unwrap_err().to_string().contains("start with `y`"));
}

#[test]
fn the_defaults_are_the_guarded_calibrated_certificate_with_the_zero_order_hold() {
    use streamcert_regression::InputIntegral;
    let full = parse(&base(), "default").unwrap().certifier;
    let cal = full.calibration.expect("the calibrated certificate by default");
    assert!(cal.hidden_dynamics && cal.nonlinearity && cal.plant_change);
    assert_eq!(full.regression.input_integral, InputIntegral::ZeroOrderHold);
    // Omitted sections and keys give the same.
    let minimal = "[columns]\ntime = \"t\"\noutputs = [\"y\"]\ninputs = [\"u\"]\n\
                   [controller]\ngain = [[-4.0]]\n\
                   [certificate]\nconservatism = 0.1\nmargin = 0.05\nconsecutive = 10\n";
    let short = parse(minimal, "minimal").unwrap().certifier;
    assert_eq!(short.calibration, Some(cal));
    assert_eq!(short.regression.input_integral, InputIntegral::ZeroOrderHold);
    // Each guard and the calibration can be turned off by name only.
    let off = base()
        .replace("# plant_change = true ", "plant_change = false ")
        .replace("# nonlinearity = true ", "nonlinearity = false ");
    let c = parse(&off, "x").unwrap().certifier.calibration.unwrap();
    assert!(!c.plant_change && !c.nonlinearity && c.hidden_dynamics);
    // The change guard's risk: δ unless stated.
    assert_eq!((cal.change_risk, cal.change_risk()), (None, cal.delta));
    let risk = base().replace("# change_risk = 0.01 ", "change_risk = 0.002 ");
    let c = parse(&risk, "x").unwrap().certifier.calibration.unwrap();
    assert_eq!(c.change_risk(), 0.002);
    // The model guards' risk: δ over the windows unless stated.
    assert_eq!((cal.guard_risk, cal.guard_risk(4)), (None, cal.delta / 4.0));
    let risk = base().replace("# guard_risk = 0.002 ", "guard_risk = 0.05 ");
    let c = parse(&risk, "x").unwrap().certifier.calibration.unwrap();
    assert_eq!(c.guard_risk(4), 0.05);
    // The model guards' covariance: first-order unless stated; the jackknife on request; a
    // misspelt name is refused.
    assert_eq!(cal.guard_variance, streamcert_certificate::GuardVariance::FirstOrder);
    let jack =
        base().replace("# guard_variance = \"first_order\" ", "guard_variance = \"jackknife\" ");
    let c = parse(&jack, "x").unwrap().certifier.calibration.unwrap();
    assert_eq!(c.guard_variance, streamcert_certificate::GuardVariance::Jackknife);
    assert!(parse(&jack.replace("\"jackknife\"", "\"jack\""), "x").is_err());
    // The risk split across windows: equal unless stated; a misspelt split is refused.
    assert_eq!(cal.risk_split, streamcert_certificate::RiskSplit::Equal);
    let split = base().replace("# risk_split = \"equal\" ", "risk_split = \"by_length\" ");
    let c = parse(&split, "x").unwrap().certifier.calibration.unwrap();
    assert_eq!(c.risk_split, streamcert_certificate::RiskSplit::ByLength);
    assert!(parse(&split.replace("by_length", "bylength"), "x").is_err());
    // The batched radius's share of the risk: 0.2 unless stated.
    assert_eq!(cal.auto_batch_risk, 0.2);
    let share = base().replace("# auto_batch_risk = 0.2 ", "auto_batch_risk = 0.5 ");
    let c = parse(&share, "x").unwrap().certifier.calibration.unwrap();
    assert_eq!(c.auto_batch_risk, 0.5);
    // The automatic batches: about 30 per window unless stated; 0 turns them off; the key
    // of the fixed-size rule before (`auto_batch`) is refused, not silently ignored.
    assert_eq!(cal.auto_batches, 30);
    let off = base().replace("# auto_batches = 30 ", "auto_batches = 0 ");
    assert_eq!(parse(&off, "x").unwrap().certifier.calibration.unwrap().auto_batches, 0);
    let old = base().replace("# auto_batches = 30 ", "auto_batch = 8 ");
    let err = parse(&old, "x").unwrap_err().to_string();
    assert!(err.contains("unknown field `auto_batch`"), "{err}");
    let paper = base().replace("enabled = true\ndelta", "enabled = false\ndelta");
    assert_eq!(parse(&paper, "x").unwrap().certifier.calibration, None);
}

#[test]
fn every_default_in_print_config_carries_its_reason() {
    // Every active `key = value` line of the printed configuration has a comment on it or on
    // the line before.
    let lines: Vec<&str> = DEFAULT_CONFIG.lines().collect();
    for (i, line) in lines.iter().enumerate() {
        let l = line.trim();
        if l.is_empty() || l.starts_with('#') || l.starts_with('[') || !l.contains('=') {
            continue;
        }
        let commented = l.contains('#') || lines[i.saturating_sub(1)].trim().starts_with('#');
        assert!(commented, "line {} has no reason: {l}", i + 1);
    }
}

/// Oracle: the printed configuration. A file with only the required keys gives the same
/// certifier as `--print-config`'s (whose active lines are the defaults), and one without a
/// required key names it and every required key.
#[test]
fn only_the_required_keys_give_the_printed_configuration() {
    let minimal = "[columns]\ntime = \"t\"\noutputs = [\"y_b\"]\ninputs = [\"u_b\"]\n\
                   [controller]\ngain = [[-4.0]]\n[certificate]\nmargin = 0.05\n";
    let full = parse(&base(), "default").unwrap();
    let parsed = parse(minimal, "minimal").unwrap();
    assert_eq!(parsed.certifier, full.certifier);
    assert_eq!(parsed.columns, full.columns);
    for (drop, key) in
        [("margin = 0.05\n", "certificate.margin"), ("gain = [[-4.0]]\n", "controller.gain")]
    {
        let err = parse(&minimal.replace(drop, ""), "x").unwrap_err().to_string();
        assert!(err.contains("required key not set"), "{err}");
        assert!(err.contains(key), "{err}");
        assert!(err.contains("--print-config"), "{err}");
    }
    // A key with a default set to another value is kept.
    let other = minimal.replace("margin = 0.05\n", "margin = 0.05\nconsecutive = 3\n");
    assert_eq!(parse(&other, "x").unwrap().certifier.consecutive, 3);
}

/// The printed template certifies nothing until the user's five choices are written: each
/// unset key (left "REQUIRED", or absent) is named with what it is, and no other.
#[test]
fn the_template_is_refused_naming_every_required_key() {
    let err = parse(DEFAULT_CONFIG, "plant.toml").unwrap_err().to_string();
    for (section, key, what) in REQUIRED_KEYS {
        assert!(err.contains(&format!("{section}.{key}: {what}")), "{err}");
    }
    assert!(err.contains("plant.toml"), "{err}");
    let text = base();
    for (line, key) in [
        ("gain = [[-4.0]]", "controller.gain"),
        ("margin = 0.05", "certificate.margin"),
        ("outputs = [\"y_b\"]", "columns.outputs"),
    ] {
        for unset in [String::new(), line.split('=').next().unwrap().to_string() + "= \"REQUIRED\""]
        {
            let err = parse(&text.replacen(line, &unset, 1), "x").unwrap_err().to_string();
            assert!(err.contains(key) && err.contains("required key not set"), "{err}");
            let others = REQUIRED_KEYS.iter().filter(|(s, k, _)| format!("{s}.{k}") != key);
            for (s, k, _) in others {
                assert!(!err.contains(&format!("{s}.{k}:")), "{err}");
            }
        }
    }
    // A placeholder inside a list is unset too.
    let partial = text.replacen("outputs = [\"y_b\"]", "outputs = [\"y_b\", \"REQUIRED\"]", 1);
    assert!(parse(&partial, "x").unwrap_err().to_string().contains("columns.outputs"));
}

/// The example configuration the README's commands use is `g5_node_b()`, byte for byte.
#[test]
fn the_committed_example_is_g5_node_b() {
    let committed = include_str!("../../../../examples/data/g5_node_b.toml");
    assert_eq!(committed, g5_node_b());
    assert!(parse(committed, "g5_node_b.toml").is_ok());
}

/// `horizon = "auto"` and `window = "auto"`: the horizon ladder (h = 1, 2, 5, 10, 30 blocks
/// per base window) beside the paper's certificates at h = 5, M = 150; a number keeps one
/// horizon; without the calibrated certificate `"auto"` is the paper's h = 5; anything else
/// is refused naming what is valid.
#[test]
fn auto_horizon_and_window_select_the_ladder() {
    let auto = base()
        .replace("\nwindow = 150 ", "\nwindow = \"auto\" ")
        .replace("horizon = 5 ", "horizon = \"auto\" ");
    let c = parse(&auto, "x").unwrap().certifier;
    let ladder = c.ladder.expect("a ladder");
    assert_eq!((ladder.horizons, ladder.blocks), (vec![1, 2, 5, 10], Some(30)));
    assert_eq!((c.regression.horizon, c.regression.window), (5, 150));
    assert_eq!(parse(&base(), "x").unwrap().certifier.ladder, None);
    let fixed_window = base().replace("horizon = 5 ", "horizon = \"auto\" ");
    assert_eq!(parse(&fixed_window, "x").unwrap().certifier.ladder.unwrap().blocks, None);
    let paper_only = auto.replace("enabled = true\ndelta", "enabled = false\ndelta");
    assert_ne!(paper_only, auto);
    assert_eq!(parse(&paper_only, "x").unwrap().certifier.ladder, None);
    let bad = base().replace("horizon = 5 ", "horizon = \"automatic\" ");
    let err = parse(&bad, "x").unwrap_err().to_string();
    assert!(err.contains("a positive integer or \"auto\""), "{err}");
}

/// `[regression] order` selects the certificate of order n; what it does not support is
/// refused naming the key, and an order outside 1..=3 does not parse.
#[test]
fn order_selects_the_certificate_of_order_n() {
    let first = parse(&base(), "default").unwrap();
    assert!(first.certifier.regression.order.is_first_order());
    assert!(first.certifier.order_n().is_none());
    let order2 = base()
        .replace("order = 1", "order = 2")
        .replace("window = 150 ", "window = 2000 ")
        .replace("horizon = 5 ", "horizon = 50 ");
    let c = parse(&order2, "x").unwrap();
    let on = c.certifier.order_n().expect("order 2");
    assert_eq!(
        (on.regression.model.order(), on.regression.window, on.regression.horizon),
        (2, 2000, 50)
    );
    assert_eq!(on.delta, c.certifier.calibration.unwrap().delta);
    // Too small a window for the horizon: refused, naming what would be valid.
    let small = base().replace("order = 1", "order = 2").replace("horizon = 5 ", "horizon = 50 ");
    let err = parse(&small, "x").unwrap_err().to_string();
    assert!(err.contains("min_rows") && err.contains("horizon"), "{err}");
    // Without the calibrated certificate there is no risk to certify at.
    let bare = order2.replacen("\nenabled = true\n", "\nenabled = false\n", 1);
    assert_ne!(bare, order2, "the calibration section's switch");
    let err = parse(&bare, "x").unwrap_err().to_string();
    assert!(err.contains("calibration"), "{err}");
    for bad in ["order = 4", "order = 0", "order = \"second\""] {
        let text = base().replace("order = 1", bad);
        assert!(parse(&text, "x").is_err(), "{bad}");
    }
}

/// `order = "auto"` is the first order with the order ladder at risk `δ / 3` per rung; with
/// `horizon = "auto"` too it is refused, naming both; without the calibrated certificate it is
/// the first order (the paper's certificates are of the first order).
#[test]
fn order_auto_is_the_order_ladder() {
    // The default is the first order alone.
    let default = parse(&base(), "x").unwrap().certifier;
    assert!(default.regression.order.is_first_order() && default.orders.is_none());
    let auto = base().replace("order = 1", "order = \"auto\"");
    let c = parse(&auto, "x").unwrap().certifier;
    assert!(c.regression.order.is_first_order());
    assert_eq!(c.orders.as_ref().map(|l| l.orders.clone()), Some(vec![1, 2, 3]));
    let delta = c.calibration.unwrap().delta;
    assert_eq!(c.calibration_in_effect().unwrap().delta, delta / 3.0);
    let both = auto.replace("horizon = 5 ", "horizon = \"auto\" ");
    assert_ne!(both, auto, "the horizon key");
    let err = parse(&both, "x").unwrap_err().to_string();
    assert!(err.contains("order = \"auto\" and horizon = \"auto\""), "{err}");
    let bare = auto.replacen("\nenabled = true\n", "\nenabled = false\n", 1);
    let c = parse(&bare, "x").unwrap().certifier;
    assert!(c.regression.order.is_first_order() && c.orders.is_none());
}
