//! The instrumented solve in other units: the instruments' strength (the pivot ratio that
//! refuses a fit) is measured on `A` equilibrated to a unit diagonal, so a regressor logged
//! in units a million times smaller (an output in mK instead of K, and its powers in the
//! guards' fits) is neither refused for its unit nor estimated differently.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::regression::{InstrumentedWindows, RateMap, Solve, WindowEstimate};

/// Oracle: the same data in other units. Without a ridge the two-stage least-squares
/// estimate transforms exactly with a regressor's unit (`θ_i` scales by the inverse factor)
/// and the equilibrated pivot ratio does not change, from `10⁻⁶` to `10⁶`: every fit the
/// data in their own units accept is accepted in the others.
#[test]
fn a_regressor_in_other_units_changes_neither_the_strength_nor_the_estimate() {
    let (p, m) = (1, 2);
    let windows = [60usize, 120];
    for scale in [1e-6, 1e-3, 1e3, 1e6] {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut base = InstrumentedWindows::new(p, m, 3, 1, 1, &windows).expect("valid");
        let mut scaled = InstrumentedWindows::new(p, m, 3, 1, 1, &windows).expect("valid");
        let (mut a, mut b) = (WindowEstimate::new(p, m, 1), WindowEstimate::new(p, m, 1));
        let t = [1.0, -0.5, 0.2];
        let mut state = 0.0;
        let mut compared = 0;
        for _ in 0..400 {
            let u = [rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5];
            let dy = [-0.3 * state + 0.4 * u[0] - 0.2 * u[1] + 0.02 * (rng.random::<f64>() - 0.5)];
            let z = [state, u[0], u[1]];
            state += dy[0];
            let ready = base.push_column(&z, &dy);
            // The second input in units `scale` times smaller: its values `1/scale` times larger.
            scaled.push_column(&[z[0], z[1], z[2] / scale], &dy);
            if !ready {
                continue;
            }
            for w in 0..windows.len() {
                base.estimate(
                    w,
                    Solve { ridge: 0.0, rate: RateMap::SymmetricPart(&t), min_pivot_ratio: 1e-9 },
                    &mut a,
                );
                let tt = [t[0], t[1], t[2] / scale];
                scaled.estimate(
                    w,
                    Solve { ridge: 0.0, rate: RateMap::SymmetricPart(&tt), min_pivot_ratio: 1e-9 },
                    &mut b,
                );
                assert_eq!(a.ready, b.ready, "scale {scale}, window {w}");
                if !a.ready {
                    continue;
                }
                let close = |x: f64, y: f64| (x - y).abs() <= 1e-7 * (x.abs() + y.abs()) + 1e-300;
                assert!(close(a.pivot_ratio, b.pivot_ratio), "{} {}", a.pivot_ratio, b.pivot_ratio);
                assert!(close(a.theta[0], b.theta[0]) && close(a.theta[1], b.theta[1]));
                assert!(close(a.theta[2], b.theta[2] / scale), "{:?} {:?}", a.theta, b.theta);
                compared += 1;
            }
        }
        assert!(compared > 100, "scale {scale}: {compared} estimates compared");
    }
}

/// One row's calibrated verdict: the gate, the certificate and the reason's kind.
type Row = (bool, Option<f64>, Option<&'static str>);

/// G5's subsystem B (Experiment 2, run 1) under the default calibrated certificate, every
/// guard on: `(open, certificate, reason kind)` of the calibrated verdict at every row, with
/// `y` logged times `sy` and `u` times `su` (the gain scaled by `su / sy`: the same loop).
fn g5_verdicts(sy: f64, su: f64) -> Vec<Row> {
    use std::sync::OnceLock;
    use streamcert::certificate::{Calibration, Certifier, CertifierConfig};
    use streamcert::dynamics::Coupling;
    use streamcert::experiments::{Experiment, G5Dataset};
    use streamcert::regression::{InputIntegral, RegressionConfig};
    static DATA: OnceLock<streamcert::dynamics::Trajectory> = OnceLock::new();
    let data = DATA.get_or_init(|| {
        G5Dataset { coupling: Coupling::Cascade, ..G5Dataset::defaults(Experiment::Two) }
            .run_seeded(1)
            .expect("data")
    });
    let k4 = Experiment::Two.setting().k4;
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(1, 1, 150, 5, 1e-4)
    };
    let mut cfg = CertifierConfig::new(reg, vec![k4 * su / sy], 0.1, 0.1, 10);
    cfg.calibration = Some(Calibration::new(0.01));
    let mut cert = Certifier::new(cfg).expect("valid");
    (0..data.len())
        .map(|j| {
            let (y, u) = (data.output(j)[1] * sy, data.input(j)[1] * su);
            let v = cert.push(data.t[j], &[y], &[u]).expect("sample").calibrated;
            (v.open, v.value, v.reason.map(|r| r.kind()))
        })
        .collect()
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(12))]

    /// The calibrated fits are in no unit (the identification-and-units study): any positive
    /// scaling of `y` and `u` from `10⁻⁶` to `10⁶`, the gain scaled with them, gives the same
    /// gate and the same reason at every row of a G5 run, and the same certificate to `10⁻⁹`
    /// relative. The base run opens its gate (the comparison covers open and closed rows).
    #[test]
    fn every_gate_of_a_g5_run_is_the_same_in_any_units(ly in -6.0f64..6.0, lu in -6.0f64..6.0) {
        use std::sync::OnceLock;
        static BASE: OnceLock<Vec<Row>> = OnceLock::new();
        let base = BASE.get_or_init(|| g5_verdicts(1.0, 1.0));
        proptest::prop_assert!(base.iter().any(|v| v.0) && base.iter().any(|v| !v.0));
        let scaled = g5_verdicts(10f64.powf(ly), 10f64.powf(lu));
        for (row, (a, b)) in base.iter().zip(&scaled).enumerate() {
            proptest::prop_assert_eq!(a.0, b.0, "gate at row {}", row);
            proptest::prop_assert_eq!(a.2, b.2, "reason at row {}", row);
            match (a.1, b.1) {
                (Some(x), Some(y)) => proptest::prop_assert!(
                    (x - y).abs() <= 1e-9 * x.abs().max(y.abs()).max(1e-3),
                    "certificate at row {}: {} against {}", row, x, y
                ),
                (x, y) => proptest::prop_assert_eq!(x.is_some(), y.is_some(), "row {}", row),
            }
        }
    }
}
