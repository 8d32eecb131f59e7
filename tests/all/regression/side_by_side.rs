//! The wide estimate with its side-by-side eigenvalue problems against `estimate()`.

use streamcert::regression::{EstimateStatus, RegressionConfig, SlidingRegression};

use super::random_stream;

/// `estimate_and_sym_max` (the solve first, then the Gram matrix's extremes and a symmetric
/// matrix's `λ_max` side by side) against `estimate()` then `sym_eig_max`, bit for bit, at
/// every sample: ready estimates, warm-up, a Gram matrix that fails the excitation test (an
/// input held at zero for a stretch, no ridge) and one whose factorisation fails.
#[test]
fn the_side_by_side_estimate_is_the_estimate_bit_for_bit() {
    use streamcert::regression::linalg::{eig_work_len, sym_eig_max};
    // The last case accepts any positive λ_min (ratio 0), so a singular Gram matrix whose
    // rounded λ_min is positive passes the excitation test and fails the factorisation.
    let cases = [
        (10, 10, 1e-6, 11, 1e-9),
        (12, 1, 0.0, 12, 1e-9),
        (10, 3, 0.0, 13, 1e-9),
        (3, 9, 1e-6, 14, 1e-9),
        (4, 4, 1e-6, 16, 1e-9),
        (10, 3, 0.0, 15, 0.0),
    ];
    let mut factorisation_failed = 0;
    for (p, m, ridge, seed, ratio) in cases {
        let cfg = RegressionConfig {
            min_columns: 2 * (p + m),
            min_excitation_ratio: ratio,
            ..RegressionConfig::new(p, m, 40, 3, ridge)
        };
        let mut samples = random_stream(p, m, 240, 0.0, seed);
        for s in &mut samples[90..150] {
            s.2[0] = 0.0;
            s.1[0] = 0.0;
        }
        if ratio == 0.0 {
            // Two inputs equal up to a rounding-level difference: a numerically singular
            // Gram matrix whose computed λ_min may come out positive.
            for s in &mut samples {
                s.2[2] = s.2[1] * (1.0 + 1e-15);
            }
        }
        let (mut a, mut b) = (
            SlidingRegression::new(cfg).expect("valid"),
            SlidingRegression::new(cfg).expect("valid"),
        );
        let (mut sym, mut work) = (vec![0.0; p * p], vec![0.0; eig_work_len(p)]);
        let (mut sym_a, mut work_a) = (vec![0.0; p * p], vec![0.0; eig_work_len(p)]);
        let mut seen = [0usize; 3];
        for (t, y, u) in &samples {
            a.push(*t, y, u).expect("valid");
            b.push(*t, y, u).expect("valid");
            // sym = Θ̂'s first p columns, symmetrised, plus the rest of each row.
            let form = |theta: &[f64], sym: &mut [f64]| {
                for i in 0..p {
                    for j in i..p {
                        sym[i * p + j] = theta[i * (p + m) + j]
                            + theta[j * (p + m) + i]
                            + theta[i * (p + m) + p];
                    }
                }
            };
            let want = a.estimate();
            let top_a = if want.status == EstimateStatus::Ready {
                form(want.theta, &mut sym_a);
                sym_eig_max(&sym_a, p, &mut work_a)
            } else {
                f64::NAN
            };
            let (got, top) = b.estimate_and_sym_max(&mut sym, p, &mut work, form);
            assert_eq!(format!("{:?}", got.status), format!("{:?}", want.status));
            if let EstimateStatus::InsufficientExcitation { lambda_min, lambda_max } = want.status {
                factorisation_failed += usize::from(lambda_min > ratio * lambda_max);
            }
            seen[match want.status {
                EstimateStatus::Ready => 0,
                EstimateStatus::WarmingUp { .. } => 1,
                _ => 2,
            }] += 1;
            let bits = |v: f64| v.to_bits();
            assert_eq!(bits(got.rms_residual), bits(want.rms_residual));
            assert_eq!(bits(got.gram_lambda_min), bits(want.gram_lambda_min));
            assert_eq!(bits(got.gram_lambda_max), bits(want.gram_lambda_max));
            assert_eq!(
                got.theta.iter().map(|v| bits(*v)).collect::<Vec<_>>(),
                want.theta.iter().map(|v| bits(*v)).collect::<Vec<_>>()
            );
            assert_eq!(bits(top), bits(top_a));
        }
        assert!(seen.iter().all(|&c| c > 0), "p = {p}, m = {m}: every status met: {seen:?}");
    }
    assert!(factorisation_failed > 0, "no sample passed the excitation test and failed to factor");
}
