//! The verdict line's two parts: the linear calibrated verdict, and with `[nonlinear]` the
//! region-valid verdict beside it; without `[nonlinear]`, how to get it.

use streamcert_certificate::{CertifierConfig, NonlinearConfig, NotCertified};
use streamcert_regression::RegressionConfig;

use super::Summary;

fn config(nonlinear: bool) -> CertifierConfig {
    let reg = RegressionConfig::new(1, 1, 150, 5, 1e-4);
    let mut cfg = CertifierConfig::guarded(reg, vec![-4.0], 0.05, 10);
    cfg.nonlinear = nonlinear.then(|| NonlinearConfig::with_degree(2));
    cfg
}

fn certified() -> Summary {
    Summary {
        rows: 100,
        calibrated_since: Some(12.5),
        calibrated_region: vec![(-0.5, 0.75)],
        ..Summary::default()
    }
}

#[test]
fn without_nonlinear_a_certified_verdict_says_how_to_get_the_region_valid_one() {
    let line = certified().verdict_line(&config(false), &["level".into()]);
    assert!(line.starts_with("verdict: CERTIFIED for K = [[-4]]"), "{line}");
    assert!(line.contains("over the region level in [-0.5, 0.75]"), "{line}");
    assert!(line.contains("`[nonlinear] enabled = true` adds the region-valid verdict"), "{line}");
    assert!(!line.contains("region-valid verdict:"), "{line}");
}

#[test]
fn with_nonlinear_the_line_carries_both_verdicts() {
    let cfg = config(true);
    let mut s = certified();
    s.nonlinear_since = Some(20.0);
    s.nonlinear_region = Some((-0.25, 0.5));
    let line = s.verdict_line(&cfg, &["level".into()]);
    assert!(line.starts_with("verdict: CERTIFIED"), "{line}");
    assert!(
        line.contains(
            "; region-valid verdict: CERTIFIED from t = 20 to the end (nonlinear certificate: \
             the rate bounded at every state of level in [-0.25, 0.5]; its gate closes while \
             level is outside)"
        ),
        "{line}"
    );
    // The region-valid gate closed at the end: its reason, whatever the linear verdict.
    s.nonlinear_since = None;
    s.nonlinear_region = None;
    s.nonlinear_last_reason = Some(NotCertified::WarmingUp { columns: 10, needed: 150 });
    let line = s.verdict_line(&cfg, &["level".into()]);
    assert!(line.contains("region-valid verdict: NOT CERTIFIED at the end"), "{line}");
    assert!(line.contains("warming up"), "{line}");
    s.calibrated_since = None;
    let line = s.verdict_line(&cfg, &["level".into()]);
    assert!(line.starts_with("verdict: NOT CERTIFIED"), "{line}");
    assert!(line.contains("region-valid verdict: NOT CERTIFIED"), "{line}");
}

/// A summary written when the kind was named `rate_dropped` (a checkpoint's) reads it under
/// its current name, so the verdict puts it in words and a resumed run counts both together.
#[test]
fn a_summary_with_the_earlier_kind_name_reads_it_under_the_current_one() {
    let old = r#"{"rows": 10, "skipped": 0, "gauss_open": 0, "wass_open": 0,
        "first_deploy_gauss": null, "first_deploy_wass": null, "last_time": 1.0,
        "calibrated_reasons": [["warming_up", 4], ["rate_dropped", 6]]}"#;
    let s: Summary = serde_json::from_str(old).expect("reads");
    assert_eq!(s.calibrated_reasons[1], ("rate_below_margin".to_string(), 6));
    assert_eq!(s.longest_reason(), Some("rate_below_margin"));
}
