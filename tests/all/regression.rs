//! streamcert-regression: incremental statistics against a batch recompute (nalgebra), drift
//! over long streams, bad samples, no excitation, offsets; the estimators on known systems in
//! `regression/estimators.rs`.

use nalgebra::DMatrix;
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::regression::{
    EstimateStatus, Estimator, InputIntegral, Model, RegressionConfig, RegressionError,
    SlidingRegression,
};

mod anchored;
mod coefficients;
mod estimators;
mod moments;
mod replay;
mod side_by_side;
mod units;
mod window_range;

type Sample = (f64, Vec<f64>, Vec<f64>);

/// A random stream with non-uniform sampling: AR(1) outputs and inputs around `offset`.
fn random_stream(p: usize, m: usize, len: usize, offset: f64, seed: u64) -> Vec<Sample> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut t = 0.0;
    let mut y = vec![0.0; p];
    let mut u = vec![0.0; m];
    (0..len)
        .map(|_| {
            t += 0.01 * (0.5 + rng.random::<f64>());
            for v in y.iter_mut().chain(u.iter_mut()) {
                *v = 0.9 * *v + rng.random::<f64>() - 0.5;
            }
            (t, y.iter().map(|v| v + offset).collect(), u.iter().map(|v| v + offset).collect())
        })
        .collect()
}

struct Batch {
    theta: DMatrix<f64>,
    /// The affine model's `ĉ` in the record's own coordinates.
    intercept: Option<Vec<f64>>,
    rms: f64,
    lambda_min: f64,
    lambda_max: f64,
    /// `Z Zᵀ`, `ΔY Zᵀ`, `ΔY ΔYᵀ`.
    g: DMatrix<f64>,
    c: DMatrix<f64>,
    s: DMatrix<f64>,
    /// Condition number of the solved system.
    cond: f64,
}

/// Column `k` recomputed from the raw samples: `(z, ΔY)` over the `h` intervals before it
/// (the trapezoid for `y`; for `u` the configured integral).
fn batch_column(samples: &[Sample], cfg: &RegressionConfig, k: usize) -> (Vec<f64>, Vec<f64>) {
    let (p, m, h) = (cfg.outputs, cfg.inputs, cfg.horizon);
    let d = p + m;
    let mut z = vec![0.0; d];
    for j in k - h..k {
        let dt = samples[j + 1].0 - samples[j].0;
        for i in 0..p {
            z[i] += 0.5 * dt * (samples[j].1[i] + samples[j + 1].1[i]);
        }
        for i in 0..m {
            z[p + i] += match cfg.input_integral {
                InputIntegral::Trapezoidal => 0.5 * dt * (samples[j].2[i] + samples[j + 1].2[i]),
                InputIntegral::ZeroOrderHold => dt * samples[j].2[i],
            };
        }
    }
    let dy: Vec<f64> = (0..p).map(|i| samples[k].1[i] - samples[k - h].1[i]).collect();
    (z, dy)
}

/// Batch recompute from the raw samples: builds every column from scratch, keeps the last
/// `M` usable ones, and solves with nalgebra.
fn batch(samples: &[Sample], cfg: &RegressionConfig) -> Option<Batch> {
    let (p, m, h) = (cfg.outputs, cfg.inputs, cfg.horizon);
    let d = p + m;
    let column = |k: usize| batch_column(samples, cfg, k);
    let first = match cfg.estimator {
        Estimator::Ordinary => h,
        Estimator::Instrumented => 2 * h,
    };
    if samples.len() <= first {
        return None;
    }
    let ks: Vec<usize> = (first..samples.len()).collect();
    let ks = &ks[ks.len().saturating_sub(cfg.window)..];
    if ks.len() < cfg.min_columns {
        return None;
    }
    let n = ks.len();
    // The affine model: `τ` (the column's span) as one more regressor and its own instrument,
    // not penalised by the ridge; `Θ̂` is the first `p + m` columns of the fit.
    let affine = cfg.model == Model::Affine;
    let da = d + usize::from(affine);
    let mut z = DMatrix::zeros(da, n);
    let mut w = DMatrix::zeros(da, n);
    let mut dy = DMatrix::zeros(p, n);
    for (c, &k) in ks.iter().enumerate() {
        let (zc, dyc) = column(k);
        for i in 0..d {
            z[(i, c)] = zc[i];
        }
        for i in 0..p {
            dy[(i, c)] = dyc[i];
        }
        if cfg.estimator == Estimator::Instrumented {
            let (wc, _) = column(k - h);
            for i in 0..d {
                w[(i, c)] = wc[i];
            }
        }
        if affine {
            // The instrumented estimator instruments `τ` by its instrument's own span.
            z[(d, c)] = samples[k].0 - samples[k - h].0;
            w[(d, c)] = match cfg.estimator {
                Estimator::Ordinary => z[(d, c)],
                Estimator::Instrumented => samples[k - h].0 - samples[k - 2 * h].0,
            };
        }
    }
    let mut ridge = DMatrix::identity(da, da) * cfg.ridge;
    if affine {
        ridge[(d, d)] = 0.0;
    }
    let a = match cfg.estimator {
        Estimator::Ordinary => &z * z.transpose() + ridge,
        Estimator::Instrumented => &z * w.transpose() + ridge,
    };
    let sv = a.clone().singular_values();
    let cond = sv.max() / sv.min();
    let rhs = match cfg.estimator {
        Estimator::Ordinary => &dy * z.transpose(),
        Estimator::Instrumented => &dy * w.transpose(),
    };
    let full = rhs * a.try_inverse()?;
    let r = &dy - &full * &z;
    let rms = (r.norm_squared() / (p * n) as f64).sqrt();
    let theta = full.columns(0, d).into_owned();
    let intercept = affine.then(|| full.column(d).iter().copied().collect());
    // The Gram matrix of `Z` with `τ` partialled out (the plain one through the origin).
    let zz = z.rows(0, d).into_owned();
    let gram = if affine {
        let tau = z.row(d).transpose();
        let a_z = &zz * &tau;
        &zz * zz.transpose() - &a_z * a_z.transpose() / tau.norm_squared()
    } else {
        &zz * zz.transpose()
    };
    let eig = (gram / n as f64).symmetric_eigen().eigenvalues;
    let (lambda_min, lambda_max) = (eig.min(), eig.max());
    let (g, c, s) = (&zz * zz.transpose(), &dy * zz.transpose(), &dy * dy.transpose());
    Some(Batch { theta, intercept, rms, lambda_min, lambda_max, g, c, s, cond })
}

/// The incremental statistics equal the batch ones within `tol` relative (entrywise against
/// the largest entry); the estimate, which amplifies rounding by the condition number of the
/// solved system, within `tol · cond`.
fn assert_matches_batch(reg: &mut SlidingRegression, samples: &[Sample], tol: f64) {
    let cfg = *reg.config();
    let batch = batch(samples, &cfg);
    // The running sums are checked against the batch's through the origin; the affine model
    // keeps them in working coordinates (relative to the first sample), checked through its
    // estimate, intercept and centred Gram matrix below.
    if let Some(b) = batch.as_ref().filter(|_| cfg.model == Model::ThroughOrigin) {
        let (g, c, s) = reg.statistics();
        let (d, p) = (cfg.outputs + cfg.inputs, cfg.outputs);
        for (name, inc, bat, cols, upper) in
            [("G", g, &b.g, d, true), ("C", c, &b.c, d, false), ("S", s, &b.s, p, true)]
        {
            let scale = bat.amax();
            for i in 0..bat.nrows() {
                for j in if upper { i } else { 0 }..cols {
                    let (x, y) = (inc[i * cols + j], bat[(i, j)]);
                    assert!(
                        (x - y).abs() <= tol * scale,
                        "step {}: {name}[{i},{j}] {x} vs {y}",
                        samples.len()
                    );
                }
            }
        }
    }
    let reg_origin = reg.origin().to_vec();
    let est = reg.estimate();
    let Some(b) = batch else {
        assert!(matches!(est.status, EstimateStatus::WarmingUp { .. }), "{:?}", est.status);
        return;
    };
    assert_eq!(est.status, EstimateStatus::Ready, "step {}", samples.len());
    let d = cfg.outputs + cfg.inputs;
    let scale = b.theta.amax().max(1.0);
    let tol = tol * b.cond.max(1.0);
    for i in 0..cfg.outputs {
        for j in 0..d {
            let (inc, bat) = (est.theta[i * d + j], b.theta[(i, j)]);
            assert!(
                (inc - bat).abs() <= tol * scale,
                "step {}: theta[{i},{j}] {inc} vs {bat}",
                samples.len()
            );
        }
    }
    if let Some(c) = &b.intercept {
        // ĉ in the record's coordinates: the working one less Θ̂ times the origin.
        let origin = reg_origin.as_slice();
        for i in 0..cfg.outputs {
            let shift: f64 = (0..d).map(|j| est.theta[i * d + j] * origin[j]).sum();
            let got = est.intercept[i] - shift;
            let scale = c[i].abs() + shift.abs() + scale;
            assert!(
                (got - c[i]).abs() <= tol * scale,
                "step {}: intercept[{i}] {got} vs {}",
                samples.len(),
                c[i]
            );
        }
    } else {
        assert!(est.intercept.is_empty());
    }
    assert!(
        (est.rms_residual - b.rms).abs() <= tol * b.rms.max(1e-300) + 1e-12 * scale,
        "rms {} vs {}",
        est.rms_residual,
        b.rms
    );
    assert!(
        (est.gram_lambda_min - b.lambda_min).abs() <= tol * est.gram_lambda_max,
        "lambda_min {} vs {}",
        est.gram_lambda_min,
        b.lambda_min
    );
    assert!(
        (est.gram_lambda_max - b.lambda_max).abs() <= tol * b.lambda_max,
        "lambda_max {} vs {}",
        est.gram_lambda_max,
        b.lambda_max
    );
}

/// Wide regressions (`d >= 8`: the reduction on both triangles and the one-pass solve with
/// `RSS` from the forward substitution) against the batch recompute at every sample.
#[test]
fn wide_regressions_equal_batch_at_every_step() {
    for (p, m, window, seed) in [(10, 10, 60, 5), (5, 4, 30, 6), (4, 4, 45, 7)] {
        let cfg = RegressionConfig {
            min_columns: 2 * (p + m),
            ..RegressionConfig::new(p, m, window, 3, 1e-6)
        };
        let samples = random_stream(p, m, 4 * window, 0.0, seed);
        matches_batch_at_every_step(cfg, &samples);
    }
}

/// Push every sample of `samples` into a regression of `cfg`, each step checked against the
/// batch recompute of the samples so far (`10⁻⁹`).
fn matches_batch_at_every_step(cfg: RegressionConfig, samples: &[Sample]) {
    let mut reg = SlidingRegression::new(cfg).expect("valid");
    for k in 0..samples.len() {
        let (t, y, u) = &samples[k];
        reg.push(*t, y, u).expect("valid sample");
        assert_matches_batch(&mut reg, &samples[..=k], 1e-9);
    }
}

#[test]
fn incremental_equals_batch_at_every_step() {
    use Model::{Affine, ThroughOrigin};
    for (estimator, integral, offset, model) in [
        (Estimator::Ordinary, InputIntegral::Trapezoidal, 0.0, Affine),
        (Estimator::Ordinary, InputIntegral::ZeroOrderHold, 0.0, Affine),
        (Estimator::Instrumented, InputIntegral::Trapezoidal, 0.0, Affine),
        (Estimator::Instrumented, InputIntegral::ZeroOrderHold, 0.0, Affine),
        (Estimator::Ordinary, InputIntegral::Trapezoidal, 100.0, Affine),
        (Estimator::Ordinary, InputIntegral::Trapezoidal, 0.0, ThroughOrigin),
        (Estimator::Instrumented, InputIntegral::Trapezoidal, 0.0, ThroughOrigin),
        (Estimator::Ordinary, InputIntegral::Trapezoidal, 100.0, ThroughOrigin),
    ] {
        let cfg = RegressionConfig {
            min_columns: 12,
            input_integral: integral,
            model,
            estimator,
            ..RegressionConfig::new(2, 1, 40, 3, 1e-4)
        };
        let samples = random_stream(2, 1, 1500, offset, 17);
        matches_batch_at_every_step(cfg, &samples);
    }
}

#[test]
fn rounding_drift_stays_bounded_over_a_long_stream() {
    let cfg = RegressionConfig::new(1, 1, 150, 5, 1e-4);
    let samples = random_stream(1, 1, 200_000, 10.0, 3);
    let mut reg = SlidingRegression::new(cfg).expect("valid");
    for (t, y, u) in &samples {
        reg.push(*t, y, u).expect("valid sample");
    }
    assert_matches_batch(&mut reg, &samples[samples.len() - 400..], 1e-9);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn incremental_equals_batch_for_any_shape(
        p in 1usize..4, m in 1usize..4, extra in 0usize..30, h in 1usize..6, seed in 0u64..1000,
        instrumented in any::<bool>(),
    ) {
        let window = p + m + 4 + extra;
        let estimator = if instrumented { Estimator::Instrumented } else { Estimator::Ordinary };
        let cfg = RegressionConfig { estimator, ..RegressionConfig::new(p, m, window, h, 1e-6) };
        let samples = random_stream(p, m, 3 * window + 20, 0.0, seed);
        let mut reg = SlidingRegression::new(cfg).expect("valid");
        for (t, y, u) in &samples {
            reg.push(*t, y, u).expect("valid sample");
        }
        assert_matches_batch(&mut reg, &samples, 1e-8);
    }
}

#[test]
fn bad_samples_are_rejected_without_changing_state() {
    let mut reg = SlidingRegression::new(RegressionConfig::new(1, 1, 10, 2, 1e-4)).expect("valid");
    reg.push(0.0, &[1.0], &[0.0]).expect("valid");
    let before = reg.clone();
    assert!(matches!(
        reg.push(0.1, &[f64::NAN], &[0.0]),
        Err(RegressionError::NonFinite { field: "y", .. })
    ));
    assert!(matches!(
        reg.push(0.1, &[1.0], &[f64::INFINITY]),
        Err(RegressionError::NonFinite { field: "u", .. })
    ));
    assert!(matches!(
        reg.push(f64::NAN, &[1.0], &[0.0]),
        Err(RegressionError::NonFinite { field: "t", .. })
    ));
    assert!(matches!(
        reg.push(0.0, &[1.0], &[0.0]),
        Err(RegressionError::NonIncreasingTime { .. })
    ));
    assert!(matches!(
        reg.push(-1.0, &[1.0], &[0.0]),
        Err(RegressionError::NonIncreasingTime { .. })
    ));
    assert!(matches!(
        reg.push(0.1, &[1.0, 2.0], &[0.0]),
        Err(RegressionError::DimensionMismatch { field: "y", .. })
    ));
    assert_eq!(reg, before);
    // Finite values that overflow a column clear the window.
    reg.push(0.1, &[1e300], &[0.0]).expect("finite sample");
    assert!(matches!(reg.push(0.2, &[1e300], &[0.0]), Err(RegressionError::Overflow)));
    assert_eq!(reg.columns(), 0);
}

#[test]
fn no_excitation_is_reported_not_estimated() {
    // u = −2 y exactly: Z has rank 1.
    let mut reg = SlidingRegression::new(RegressionConfig::new(1, 1, 50, 5, 1e-4)).expect("valid");
    let mut y = 1.0f64;
    for k in 0..200 {
        reg.push(k as f64 * 0.01, &[y], &[-2.0 * y]).expect("valid");
        y *= 0.99;
    }
    assert!(matches!(reg.estimate().status, EstimateStatus::InsufficientExcitation { .. }));
    // A constant signal: Z Zᵀ is rank one too.
    let mut reg = SlidingRegression::new(RegressionConfig::new(1, 1, 50, 5, 1e-4)).expect("valid");
    for k in 0..200 {
        reg.push(k as f64 * 0.01, &[0.0], &[0.0]).expect("valid");
    }
    assert!(matches!(reg.estimate().status, EstimateStatus::InsufficientExcitation { .. }));
}

/// The affine model's estimate does not depend on constant offsets of `y` and `u` (the
/// operating point): `Θ̂`, `RMS(R)` and the centred `λ_min` on `(y + a, u + b)` equal those on
/// `(y, u)`, for offsets up to `10⁶`, both estimators, irregular sampling. Tolerance: the
/// working origin (the first sample) leaves the sums holding the record's excursions, so
/// the only offset-dependent rounding is that of forming `y − y_o` from `10⁶`-sized values
/// (`ulp(10⁶) ≈ 1.2·10⁻¹⁰` against excursions of order 1), amplified by the solve's
/// condition number (below `10⁴` here): `10⁻⁵` relative to the estimate's scale.
#[test]
fn affine_estimates_are_offset_invariant() {
    let mut runner = proptest::test_runner::TestRunner::new(ProptestConfig::with_cases(48));
    let strategy = (
        -1e6..1e6f64,
        -1e6..1e6f64,
        0u64..1000,
        prop_oneof![Just(Estimator::Ordinary), Just(Estimator::Instrumented)],
    );
    runner
        .run(&strategy, |(a, b, seed, estimator)| {
            let cfg = RegressionConfig {
                estimator,
                input_integral: InputIntegral::ZeroOrderHold,
                ..RegressionConfig::new(2, 1, 60, 3, 1e-4)
            };
            let base = random_stream(2, 1, 150, 0.0, seed);
            let (mut plain, mut shifted) =
                (SlidingRegression::new(cfg).unwrap(), SlidingRegression::new(cfg).unwrap());
            for (t, y, u) in &base {
                plain.push(*t, y, u).unwrap();
                let ys: Vec<f64> = y.iter().map(|v| v + a).collect();
                shifted.push(*t, &ys, &[u[0] + b]).unwrap();
            }
            let (e0, e1) = (plain.estimate(), shifted.estimate());
            prop_assert_eq!(e0.status, EstimateStatus::Ready);
            prop_assert_eq!(e1.status, EstimateStatus::Ready);
            let e1 = (e1.theta.to_vec(), e1.rms_residual, e1.gram_lambda_min);
            let scale = e0.theta.iter().fold(1.0f64, |s, v| s.max(v.abs()));
            for (x, y) in e0.theta.iter().zip(&e1.0) {
                prop_assert!((x - y).abs() <= 1e-5 * scale, "theta {} vs {}", x, y);
            }
            prop_assert!((e0.rms_residual - e1.1).abs() <= 1e-5 * e0.rms_residual);
            prop_assert!((e0.gram_lambda_min - e1.2).abs() <= 1e-5 * e0.gram_lambda_max);
            Ok(())
        })
        .unwrap();
}

/// Through the origin the operating point enters `Θ̂` as dynamics (the reason the affine
/// model is the default): the same record offset by `50` gives a different estimate.
#[test]
fn through_the_origin_an_offset_changes_the_estimate() {
    let cfg = RegressionConfig {
        model: Model::ThroughOrigin,
        ..RegressionConfig::new(1, 1, 60, 3, 1e-4)
    };
    let base = random_stream(1, 1, 150, 0.0, 7);
    let (mut plain, mut shifted) =
        (SlidingRegression::new(cfg).unwrap(), SlidingRegression::new(cfg).unwrap());
    for (t, y, u) in &base {
        plain.push(*t, y, u).unwrap();
        shifted.push(*t, &[y[0] + 50.0], u).unwrap();
    }
    let th0 = plain.estimate().theta[0];
    let th1 = shifted.estimate().theta[0];
    assert!((th0 - th1).abs() > 0.1 * th0.abs().max(0.1), "{th0} vs {th1}");
}
