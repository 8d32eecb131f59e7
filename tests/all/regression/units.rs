//! The instrumented solve in other units: the instruments' strength (the pivot ratio that
//! refuses a fit) is measured on `A` equilibrated to a unit diagonal, so a regressor logged
//! in units a million times smaller (an output in mK instead of K, and its powers in the
//! guards' fits) is neither refused for its unit nor estimated differently.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::regression::{InstrumentedWindows, WindowEstimate};

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
                base.estimate(w, 0.0, &t, 1e-9, &mut a);
                let tt = [t[0], t[1], t[2] / scale];
                scaled.estimate(w, 0.0, &tt, 1e-9, &mut b);
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
