//! Per-sample cost of the streaming regression and certifier, beside a naive baseline in the
//! same group: the naive step absorbs the sample and then recomputes every statistic from the
//! window (`O(M d²)`), which is what a non-incremental implementation does.
//!
//! Run: `cargo bench --bench regression`.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::ambiguity::{AmbiguityConfig, AmbiguityRadius};
use streamcert::certificate::{
    Calibration, Certifier, CertifierConfig, GuardVariance, NonlinearConfig, ResidualSource,
    RiskSplit, certificate_value,
};
use streamcert::regression::{
    EstimateStatus, InstrumentedWindows, Model, RegressionConfig, SlidingRegression,
};

/// A pre-generated stream of `len` samples with `p` outputs and `m` inputs.
fn stream(p: usize, m: usize, len: usize) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut state = vec![0.0; p + m];
    let mut out = Vec::with_capacity(len * (p + m));
    for _ in 0..len {
        for v in &mut state {
            *v = 0.95 * *v + rng.random::<f64>() - 0.5;
        }
        out.extend_from_slice(&state);
    }
    out
}

/// Warm a regression up to a full window.
fn warm(cfg: RegressionConfig, data: &[f64], t: &mut f64) -> SlidingRegression {
    let d = cfg.outputs + cfg.inputs;
    let mut reg = SlidingRegression::new(cfg).expect("valid");
    for s in data.chunks(d).take(cfg.window + cfg.horizon + 1) {
        *t += 0.01;
        reg.push(*t, &s[..cfg.outputs], &s[cfg.outputs..]).expect("valid");
    }
    reg
}

fn regression_update(c: &mut Criterion) {
    let mut group = c.benchmark_group("regression_update");
    for (p, m, window) in [(1usize, 1usize, 150usize), (1, 1, 1500), (10, 10, 150)] {
        let d = p + m;
        let len = 4096;
        let data = stream(p, m, len);
        let cfg = RegressionConfig::new(p, m, window, 5, 1e-4);
        let id = format!("p{p}_m{m}_M{window}");
        let mut t = 0.0;
        let mut reg = warm(cfg, &data, &mut t);
        let mut k = 0usize;
        group.bench_function(BenchmarkId::new("incremental", &id), |b| {
            b.iter(|| {
                k = (k + 1) % len;
                t += 0.01;
                let s = &data[k * d..(k + 1) * d];
                reg.push(black_box(t), &s[..p], &s[p..]).expect("valid");
            });
        });
        let mut t = 0.0;
        let mut reg = warm(cfg, &data, &mut t);
        group.bench_function(BenchmarkId::new("naive_recompute", &id), |b| {
            b.iter(|| {
                k = (k + 1) % len;
                t += 0.01;
                let s = &data[k * d..(k + 1) * d];
                reg.push(black_box(t), &s[..p], &s[p..]).expect("valid");
                reg.refresh();
            });
        });
        let mut t = 0.0;
        let mut reg = warm(cfg, &data, &mut t);
        group.bench_function(BenchmarkId::new("incremental_plus_estimate", &id), |b| {
            b.iter(|| {
                k = (k + 1) % len;
                t += 0.01;
                let s = &data[k * d..(k + 1) * d];
                reg.push(black_box(t), &s[..p], &s[p..]).expect("valid");
                black_box(reg.estimate().rms_residual);
            });
        });
        if d >= 8 {
            // Naive baseline of the estimate: the same statistics, solved with nalgebra (all
            // eigenvalues of G, a Cholesky solve, RSS from the quadratic form).
            let mut t = 0.0;
            let mut reg = warm(cfg, &data, &mut t);
            group.bench_function(
                BenchmarkId::new("incremental_plus_nalgebra_estimate", &id),
                |b| {
                    b.iter(|| {
                        k = (k + 1) % len;
                        t += 0.01;
                        let s = &data[k * d..(k + 1) * d];
                        reg.push(black_box(t), &s[..p], &s[p..]).expect("valid");
                        let (g, c, sm) = reg.statistics();
                        let g = nalgebra::DMatrix::from_fn(d, d, |i, j| g[i.min(j) * d + i.max(j)]);
                        let c = nalgebra::DMatrix::from_row_slice(p, d, c);
                        let eig = g.clone().symmetric_eigen().eigenvalues;
                        let a = &g + nalgebra::DMatrix::identity(d, d) * cfg.ridge;
                        let theta = a.cholesky().expect("spd").solve(&c.transpose()).transpose();
                        let rss = (0..p).map(|i| sm[i * p + i]).sum::<f64>()
                            - 2.0 * (&theta * c.transpose()).trace()
                            + (&theta * &g * theta.transpose()).trace();
                        black_box((eig.min(), eig.max(), rss));
                    });
                },
            );
        }
    }
    group.finish();
}

/// The certifier of `certifier_step`'s `variant` (see there) with `p` outputs and `m` inputs,
/// and the benchmark's name.
fn step_config(p: usize, m: usize, variant: u8) -> (CertifierConfig, &'static str) {
    let wasserstein = variant == 1 || variant == 3 || variant == 5;
    let gain: Vec<f64> = (0..m * p).map(|i| if i % (p + 1) == 0 { -1.0 } else { 0.0 }).collect();
    let mut cfg =
        CertifierConfig::new(RegressionConfig::new(p, m, 150, 5, 1e-4), gain, 0.2, 0.05, 10);
    if wasserstein {
        cfg.ambiguity = Some(AmbiguityConfig::paper(150));
    }
    if variant == 2 || variant == 4 || variant == 11 {
        cfg.calibration = Some(Calibration::new(0.01));
    }
    if variant == 7 {
        cfg.calibration = Some(Calibration::new(0.01).unguarded());
    }
    if variant == 8 {
        cfg.calibration = Some(Calibration { plant_change: false, ..Calibration::new(0.01) });
    }
    if variant == 9 {
        let no_model =
            Calibration { hidden_dynamics: false, nonlinearity: false, ..Calibration::new(0.01) };
        cfg.calibration = Some(no_model);
    }
    if variant == 10 {
        let jackknife =
            Calibration { guard_variance: GuardVariance::Jackknife, ..Calibration::new(0.01) };
        cfg.calibration = Some(jackknife);
    }
    if variant == 5 || variant == 6 {
        cfg.regression.model = Model::ThroughOrigin;
    }
    if variant == 6 {
        // The calibrated step as it was before the intercept, the guards, the default
        // windows and the anchored window: four windows, the risk split by length.
        let was = Calibration {
            windows: Some(4),
            risk_split: RiskSplit::ByLength,
            anchored_share: 0.0,
            ..Calibration::new(0.01).unguarded()
        };
        cfg.calibration = Some(was);
    }
    if variant == 4 {
        cfg.nonlinear = Some(NonlinearConfig::with_degree(3));
    }
    if variant == 11 {
        cfg.nonlinear = Some(NonlinearConfig::default());
    }
    if variant == 3 {
        cfg.regression.refresh_period = 1;
    }
    let name = [
        "gaussian",
        "gaussian_and_wasserstein",
        "gaussian_and_calibrated",
        "naive_gaussian_and_wasserstein",
        "gaussian_calibrated_and_nonlinear_degree3",
        "through_origin_gaussian_and_wasserstein",
        "through_origin_gaussian_and_calibrated_unguarded",
        "gaussian_and_calibrated_unguarded",
        "gaussian_and_calibrated_without_change_guard",
        "gaussian_and_calibrated_without_model_guards",
        "gaussian_and_calibrated_jackknife_guards",
        "gaussian_calibrated_and_nonlinear",
    ][usize::from(variant)];
    (cfg, name)
}

fn certifier_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("certifier_step");
    // Variant 3 is the naive baseline of the full step: the same Gaussian + Wasserstein
    // certifier with `refresh_period = 1`, so the regression statistics are recomputed from the
    // whole window at every sample (`O(M d²)`).
    // Variant 4 adds the nonlinear certificate of degree 3 to the calibrated one (variant 2 is
    // its baseline in the same run); variant 11 adds the default nonlinear certificate
    // (degree 2 over the trimmed region, whose looks select the region's quantiles).
    // Variants 0 to 4 run the defaults (the affine model; with a calibration, its guards:
    // hidden dynamics, nonlinearity, plant change). Variants 5 and 6 are their baselines in
    // the same run: the paper's model through the origin, and the calibrated certificate
    // without any guard (the calibrated step as it was before the intercept and the guards);
    // variant 7 is the affine calibrated certificate without its guards; variants 8 and 9
    // are the default without its change guard and without its two model guards (hidden
    // dynamics, nonlinearity), so that each guard's share of the default step is measured;
    // variant 10 is the default with the model guards' tests on the jackknife covariance
    // (`GuardVariance::Jackknife`, the certificate's own) instead of the first-order one.
    let cases = [
        (1usize, 1usize, 0u8),
        (1, 1, 1),
        (1, 1, 2),
        (1, 1, 3),
        (1, 1, 4),
        (1, 1, 5),
        (1, 1, 6),
        (1, 1, 7),
        (1, 1, 8),
        (1, 1, 9),
        (1, 1, 10),
        (1, 1, 11),
        (10, 10, 0),
        (10, 10, 1),
        (10, 10, 5),
    ];
    for (p, m, variant) in cases {
        let d = p + m;
        let len = 4096;
        let data = stream(p, m, len);
        let (cfg, name) = step_config(p, m, variant);
        let mut cert = Certifier::new(cfg).expect("valid");
        let mut t = 0.0;
        for s in data.chunks(d).take(200) {
            t += 0.01;
            cert.push(t, &s[..p], &s[p..]).expect("valid");
        }
        let mut k = 0usize;
        group.bench_function(BenchmarkId::new(name, format!("p{p}_m{m}_M150")), |b| {
            b.iter(|| {
                k = (k + 1) % len;
                t += 0.01;
                let s = &data[k * d..(k + 1) * d];
                // Read what a deployment loop reads; passing the whole 384-byte `Evidence`
                // through `black_box` would add a copy that is the bench's, not the step's.
                let ev = cert.push(black_box(t), &s[..p], &s[p..]).expect("valid");
                black_box((
                    ev.gaussian.value,
                    ev.wasserstein.value,
                    ev.calibrated.value,
                    ev.nonlinear.value,
                    ev.wasserstein.open,
                ));
            });
        });
    }
    group.finish();
}

/// What the arithmetic of the `p = m = 1` step costs without the certifier's bookkeeping: the
/// same regression update and estimate, `β̂`, `ρ` (eq. rho), the one-step residual into the
/// ambiguity radius, `ε` and both certificate values, assembled from the public crates, but
/// no gates, no reasons and no `Evidence`. A measuring device, not an API: it says how much of
/// the full step is computation and how much is the evidence it returns.
fn computation_only(c: &mut Criterion) {
    let mut group = c.benchmark_group("certifier_step");
    let (len, k_gain, conservatism) = (4096usize, -1.0f64, 0.2f64);
    let data = stream(1, 1, len);
    let cfg = RegressionConfig::new(1, 1, 150, 5, 1e-4);
    let mut reg = SlidingRegression::new(cfg).expect("valid");
    let mut amb = AmbiguityRadius::new(AmbiguityConfig::paper(150)).expect("valid");
    let mut resid = [0.0];
    let mut t = 0.0;
    let mut k = 0usize;
    group.bench_function(
        BenchmarkId::new("computation_only_gaussian_and_wasserstein", "p1_m1_M150"),
        |b| {
            b.iter(|| {
                k = (k + 1) % len;
                t += 0.01;
                let s = &data[2 * k..2 * k + 2];
                reg.push(black_box(t), &s[..1], &s[1..]).expect("valid");
                let est = reg.estimate();
                let Some(rms) = (est.status == EstimateStatus::Ready).then_some(est.rms_residual)
                else {
                    return black_box(None);
                };
                let beta_hat = -(est.j_obs(0, 0) + est.b_obs(0, 0) * k_gain);
                let rho = conservatism * (1.0 + k_gain.abs()) * rms
                    / (est.gram_lambda_min + cfg.ridge).sqrt();
                if reg.residual(ResidualSource::OneStep, &mut resid) {
                    amb.push(resid[0]).expect("finite");
                }
                let eps = amb.snapshot().eps;
                black_box(Some((
                    certificate_value(beta_hat, rho, 0.0),
                    certificate_value(beta_hat, rho, eps),
                )))
            });
        },
    );
    group.finish();
}

/// What one column costs to push into the calibrated certificate's windows (the default five,
/// 150 to 2400 columns, `h = 5`, `p = 1`): the linear windows' three regressors (`y`, `u`,
/// the intercept's `τ`), the hidden-dynamics guard's larger fit's four (those and the past
/// increment) and the nonlinearity guard's five (those and the square and the cube). The
/// guards' pushes are a floor under their cost per sample, before any test: BENCHMARKS.md
/// compares them with what the step's cost target leaves the guards.
fn windows_push(c: &mut Criterion) {
    let mut group = c.benchmark_group("windows_push");
    let len = 4096usize;
    let data = stream(3, 3, len);
    for regressors in [3usize, 4, 5] {
        let lengths = [150, 300, 600, 1200, 2400];
        let mut windows =
            InstrumentedWindows::with_regressors(1, regressors, 5, 1, 1, &lengths).expect("valid");
        let mut k = 0usize;
        group.bench_function(BenchmarkId::new("regressors", regressors), |b| {
            b.iter(|| {
                k = (k + 1) % len;
                let col = &data[6 * k..6 * k + 6];
                black_box(windows.push_column(black_box(&col[..regressors]), &col[5..]))
            });
        });
    }
    group.finish();
}

/// The slowest step: the sample that completes a block where the longest window looks and
/// the guards run their tests (an `O(B)` pass over each window's blocks). Found by timing
/// every step of a run once (the look's step is tens of times the median; the choice only
/// picks which sample to measure), then measured on clones of the state just before it.
/// The default configuration (`p = m = 1`, `h = 5`) at `M = 150` and `M = 600`: its cost
/// grows with `M`, the amortised step's does not.
fn worst_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("certifier_worst_step");
    let len = 40_000usize;
    let data = stream(1, 1, len);
    for window in [150usize, 600] {
        let mut cfg = CertifierConfig::new(
            RegressionConfig::new(1, 1, window, 5, 1e-4),
            vec![-1.0],
            0.2,
            0.05,
            10,
        );
        cfg.calibration = Some(Calibration::new(0.01));
        let mut cert = Certifier::new(cfg).expect("valid");
        // The slowest step after every window is full (16 M columns and some).
        let settle = 17 * window + 200;
        let (mut worst, mut before, mut at) = (std::time::Duration::ZERO, None, 0);
        for k in 0..len {
            let s = &data[2 * k..2 * k + 2];
            let t = 0.01 * (k + 1) as f64;
            let snapshot = (k >= settle).then(|| cert.clone());
            let start = std::time::Instant::now();
            cert.push(t, &s[..1], &s[1..]).expect("valid");
            let took = start.elapsed();
            if took > worst && k >= settle {
                (worst, before, at) = (took, snapshot, k);
            }
        }
        let before = before.expect("a step after the windows filled");
        let (t, s) = (0.01 * (at + 1) as f64, [data[2 * at], data[2 * at + 1]]);
        group.bench_function(BenchmarkId::new("default", format!("p1_m1_M{window}")), |b| {
            b.iter_batched(
                || before.clone(),
                |mut c| black_box(c.push(t, &s[..1], &s[1..]).expect("valid").calibrated.value),
                criterion::BatchSize::SmallInput,
            );
        });
    }
    group.finish();
}

criterion_group!(
    benches,
    regression_update,
    certifier_step,
    computation_only,
    windows_push,
    worst_step
);
criterion_main!(benches);
