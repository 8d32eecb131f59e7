//! streamcert-compose: N-subsystem rate against Lemma 1 and the asymmetric closed form,
//! weighted versus symmetric bounds, simulation of random certified networks, sparse versus
//! dense, and input validation.

use nalgebra::DMatrix;
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::compose::{
    ComposeError, DenseMethod, DenseOptions, Method, Network, SparseOptions, certify_sparse,
    lemma1_rate, metzler_rate, network_rate, network_rate_with, symmetric_rate_at_least,
    two_block_rate, warning_gain,
};

proptest! {
    #[test]
    fn two_subsystems_match_the_closed_forms(
        a in 0.05f64..5.0, b in 0.05f64..5.0, gab in 0.0f64..5.0, gba in 0.0f64..5.0,
    ) {
        // Symmetric: Lemma 1 and γ_warn.
        let net = Network::from_dense(&[a, b], &[0.0, gab, gab, 0.0]).expect("valid");
        let cert = network_rate(&net).expect("solves");
        let lemma = lemma1_rate(a, b, gab).expect("valid");
        prop_assert!((cert.rate - lemma).abs() < 1e-10 * (1.0 + lemma.abs()));
        prop_assert!((cert.symmetric_rate - lemma).abs() < 1e-10 * (1.0 + lemma.abs()));
        if gab > 0.0 {
            let warn = warning_gain(a, b).expect("valid");
            prop_assert!((cert.critical_scale * gab - warn).abs() < 1e-9 * warn);
        }
        // Asymmetric.
        let net = Network::from_dense(&[a, b], &[0.0, gab, gba, 0.0]).expect("valid");
        let cert = network_rate(&net).expect("solves");
        let closed = two_block_rate(a, b, gab, gba).expect("valid");
        prop_assert!((cert.rate - closed).abs() < 1e-9 * (1.0 + closed.abs()));
        prop_assert!(cert.rate >= cert.symmetric_rate - 1e-10 * (1.0 + closed.abs()));
        prop_assert!(cert.weighted_rate >= cert.symmetric_rate - 1e-9 * (1.0 + closed.abs()));
        prop_assert!((closed > 0.0) == (gab * gba < a * b));
    }

    #[test]
    fn weighted_rate_dominates_the_symmetric_bound(seed in 0u64..500, n in 2usize..12) {
        let net = random_network(n, 0.5, 1.0, seed);
        let cert = network_rate(&net).expect("solves");
        prop_assert!(cert.rate >= cert.symmetric_rate - 1e-9);
        // The weights attain the rate up to the regularisation of reducible networks.
        prop_assert!((cert.weighted_rate - cert.rate).abs() < 1e-6 + 1e3 * cert.weight_regularization.sqrt());
        prop_assert!(cert.weighted_rate <= cert.rate + 1e-9);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The Perron brackets against faer's eigendecomposition, on dense and sparse random
    /// networks, irreducible or not (density 0.15 leaves many reducible ones): every number
    /// on the safe side of the exact one and within the bracket tolerance of it.
    #[test]
    fn perron_brackets_match_the_eigendecomposition(
        seed in 0u64..10_000, n in 2usize..40, density in 0.05f64..0.9, scale in 0.05f64..3.0,
    ) {
        let net = random_network(n, density, scale, seed);
        let exact = network_rate_with(&net, &DenseOptions { exact: true, ..DenseOptions::default() })
            .expect("solves");
        // No fallback: the Perron path's own numbers.
        let opts = DenseOptions { eigen_limit: 0, ..DenseOptions::default() };
        let fast = network_rate_with(&net, &opts).expect("solves");
        prop_assert_eq!(fast.method, DenseMethod::Perron);
        let tol = 1e-9 * (1.0 + exact.rate.abs());
        // Safe side: never above the exact rate (up to rounding), and close when converged.
        prop_assert!(fast.rate <= exact.rate + 1e-12 * (1.0 + exact.rate.abs()));
        prop_assert!(fast.rate_upper >= exact.rate - 1e-12 * (1.0 + exact.rate.abs()));
        prop_assert!(fast.symmetric_rate <= exact.symmetric_rate + 1e-12);
        if exact.critical_scale.is_finite() {
            prop_assert!(fast.critical_scale <= exact.critical_scale * (1.0 + 1e-12));
        }
        if fast.converged {
            prop_assert!((fast.rate - exact.rate).abs() < tol, "{} vs {}", fast.rate, exact.rate);
            prop_assert!((fast.symmetric_rate - exact.symmetric_rate).abs() < tol);
            if exact.critical_scale.is_finite() && exact.critical_scale > 0.0 {
                prop_assert!((fast.critical_scale / exact.critical_scale - 1.0).abs() < 1e-8);
            }
            if exact.weight_regularization == 0.0 && fast.weight_regularization == 0.0 {
                prop_assert!((fast.weighted_rate - exact.weighted_rate).abs() < 1e-7);
            }
        }
    }
}

#[test]
fn an_unclosed_bracket_stays_on_the_safe_side_and_says_so() {
    // Nearly equal rates and weak coupling: the power iteration converges slowly.
    let net = random_network(60, 0.2, 0.01, 7);
    let exact = network_rate_with(&net, &DenseOptions { exact: true, ..DenseOptions::default() })
        .expect("solves");
    let opts = DenseOptions { max_iterations: 3, eigen_limit: 0, ..DenseOptions::default() };
    let rough = network_rate_with(&net, &opts).expect("solves");
    assert!(!rough.converged);
    assert!(rough.rate <= exact.rate && rough.rate_upper >= exact.rate - 1e-12);
    assert!(rough.symmetric_rate <= exact.symmetric_rate + 1e-12);
    assert!(rough.critical_scale <= exact.critical_scale);
    // With the fallback the eigendecomposition answers instead.
    let fallback =
        network_rate_with(&net, &DenseOptions { max_iterations: 3, ..DenseOptions::default() })
            .expect("solves");
    assert_eq!(fallback.method, DenseMethod::Eigendecomposition);
    assert_eq!(fallback.rate, exact.rate);
}

/// `n` subsystems with rates in [0.5, 2.5], each edge present with probability `density` and
/// gain uniform in [0, scale].
fn random_network(n: usize, density: f64, scale: f64, seed: u64) -> Network {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let beta: Vec<f64> = (0..n).map(|_| 0.5 + 2.0 * rng.random::<f64>()).collect();
    let mut edges = Vec::new();
    for i in 0..n {
        for j in 0..n {
            if i != j && rng.random::<f64>() < density {
                edges.push((i, j, scale * rng.random::<f64>()));
            }
        }
    }
    Network::new(beta, &edges).expect("valid")
}

#[test]
fn a_directed_network_that_only_the_weighted_test_certifies() {
    // B drives A strongly (3), A drives B weakly (0.1): γ_AB γ_BA = 0.3 < β_A β_B = 1.
    let net = Network::from_dense(&[1.0, 1.0], &[0.0, 3.0, 0.1, 0.0]).expect("valid");
    let cert = network_rate(&net).expect("solves");
    assert!((cert.rate - (1.0 - 0.3f64.sqrt())).abs() < 1e-12, "rate {}", cert.rate);
    assert!(cert.weighted_rate > 0.4);
    // Symmetric bound: 1 − (3 + 0.1)/2 < 0, not certified.
    assert!((cert.symmetric_rate - (1.0 - 1.55)).abs() < 1e-12);
    assert!(!symmetric_rate_at_least(&net, 0.0).expect("valid"));
    // The sparse Collatz–Wielandt certificate finds it too.
    let sparse = certify_sparse(&net, &SparseOptions::default()).expect("valid");
    assert!(sparse.rate > 0.4 && sparse.method == Method::CollatzWielandt);
}

#[test]
fn a_cascade_contracts_whenever_both_blocks_do() {
    for g in [0.0, 1.0, 100.0] {
        assert_eq!(two_block_rate(0.8, 1.2, g, 0.0).expect("valid"), 0.8);
        let cert =
            network_rate(&Network::from_dense(&[0.8, 1.2], &[0.0, g, 0.0, 0.0]).expect("valid"))
                .expect("solves");
        assert!((cert.rate - 0.8).abs() < 1e-9);
        if g > 0.0 {
            assert!(cert.weight_regularization > 0.0, "a cascade is reducible");
            assert!(cert.weighted_rate > 0.79, "weighted {}", cert.weighted_rate);
        }
    }
}

/// A random `k × k` block with `sym(A) ⪯ −β I`: `−β I − R Rᵀ + (S − Sᵀ)`.
fn contracting_block(k: usize, beta: f64, rng: &mut ChaCha8Rng) -> DMatrix<f64> {
    let r = DMatrix::from_fn(k, k, |_, _| rng.random::<f64>() - 0.5);
    let s = DMatrix::from_fn(k, k, |_, _| 2.0 * (rng.random::<f64>() - 0.5));
    DMatrix::identity(k, k) * -beta - &r * r.transpose() * 0.3 + (&s - s.transpose())
}

/// A random `k × k` coupling with spectral norm exactly `gamma`.
fn coupling_block(k: usize, gamma: f64, rng: &mut ChaCha8Rng) -> DMatrix<f64> {
    let u = DMatrix::from_fn(k, k, |_, _| rng.random::<f64>() - 0.5);
    let norm = u.clone().singular_values().max();
    u * (gamma / norm)
}

#[test]
fn simulated_networks_contract_at_least_at_the_certified_rate() {
    let k = 2;
    let mut checked = 0;
    for seed in 0..30u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(1000 + seed);
        let n = 2 + (seed as usize % 4);
        let net = random_network(n, 0.6, 0.6, seed);
        let cert = network_rate(&net).expect("solves");
        if cert.weighted_rate <= 0.0 {
            continue;
        }
        // Build the full linear system respecting the bounds.
        let mut a = DMatrix::zeros(n * k, n * k);
        for i in 0..n {
            a.view_mut((i * k, i * k), (k, k)).copy_from(&contracting_block(
                k,
                net.rates()[i],
                &mut rng,
            ));
            for (j, g) in net.row(i) {
                a.view_mut((i * k, j * k), (k, k)).copy_from(&coupling_block(k, g, &mut rng));
            }
        }
        // Exact flow e^{A t} by a fine scaling-and-squaring of the Taylor series (nalgebra).
        let x0 = DMatrix::from_fn(n * k, 1, |_, _| rng.random::<f64>() - 0.5);
        let norm = |x: &DMatrix<f64>| {
            (0..n * k).map(|r| cert.weights[r / k] * x[(r, 0)] * x[(r, 0)]).sum::<f64>().sqrt()
        };
        let dt = 0.05;
        let step = (&a * dt).exp();
        let mut x = x0.clone();
        for s in 1..=200 {
            x = &step * &x;
            let t = s as f64 * dt;
            let bound = (-cert.weighted_rate * t).exp() * norm(&x0);
            assert!(
                norm(&x) <= bound * (1.0 + 1e-9) + 1e-14,
                "seed {seed}, t {t}: {} > {bound}",
                norm(&x)
            );
        }
        checked += 1;
    }
    assert!(checked >= 10, "only {checked} certified networks simulated");
}

#[test]
fn sparse_and_dense_agree_on_mid_size_networks() {
    for seed in 0..4 {
        let net = random_network(150, 0.03, 1.0, seed);
        let dense = network_rate(&net).expect("solves");
        let opts = SparseOptions { max_iterations: 5000, tolerance: 1e-10, cholesky_steps: 40 };
        let sparse = certify_sparse(&net, &opts).expect("valid");
        // Certified bracket contains the exact rate and is tight after convergence.
        assert!(
            sparse.metzler_rate <= dense.rate + 1e-9,
            "{} > {}",
            sparse.metzler_rate,
            dense.rate
        );
        assert!(sparse.metzler_upper >= dense.rate - 1e-9);
        assert!(
            dense.rate - sparse.metzler_rate < 1e-6,
            "gap {}",
            dense.rate - sparse.metzler_rate
        );
        let sym = sparse.symmetric_rate.expect("requested");
        assert!(sym <= dense.symmetric_rate + 1e-9 && dense.symmetric_rate - sym < 1e-9);
        assert!(sparse.critical_scale <= dense.critical_scale * (1.0 + 1e-9));
        assert!(sparse.critical_scale >= dense.critical_scale * (1.0 - 1e-4));
        assert!(
            (metzler_rate(&net, &sparse.certificate).expect("positive") - sparse.metzler_rate)
                .abs()
                < 1e-12
        );
    }
}

#[test]
fn invalid_input_is_a_typed_error() {
    assert!(matches!(lemma1_rate(0.0, 1.0, 0.1), Err(ComposeError::NonPositiveRate { .. })));
    assert!(matches!(lemma1_rate(1.0, -1.0, 0.1), Err(ComposeError::NonPositiveRate { .. })));
    assert!(matches!(lemma1_rate(1.0, 1.0, -0.1), Err(ComposeError::NegativeGain { .. })));
    assert!(matches!(lemma1_rate(f64::NAN, 1.0, 0.1), Err(ComposeError::NonFinite { .. })));
    assert!(matches!(warning_gain(1.0, f64::INFINITY), Err(ComposeError::NonFinite { .. })));
    assert!(matches!(
        Network::new(vec![1.0, 1.0], &[(0, 1, -1.0)]),
        Err(ComposeError::NegativeGain { .. })
    ));
    assert!(matches!(
        Network::new(vec![1.0, 1.0], &[(0, 2, 1.0)]),
        Err(ComposeError::InvalidEdge { .. })
    ));
    assert!(matches!(Network::new(vec![1.0, f64::NAN], &[]), Err(ComposeError::NonFinite { .. })));
    assert!(matches!(Network::new(vec![], &[]), Err(ComposeError::Empty)));
    assert!(matches!(
        Network::from_dense(&[1.0, 1.0], &[0.0; 3]),
        Err(ComposeError::DimensionMismatch { .. })
    ));
    assert!(matches!(
        Network::from_dense(&[1.0, 1.0], &[1.0, 0.0, 0.0, 0.0]),
        Err(ComposeError::InvalidEdge { .. })
    ));
    let net = Network::new(vec![1.0, 1.0], &[(0, 1, 0.5), (0, 1, 0.25)]).expect("valid");
    assert_eq!(net.row(0).collect::<Vec<_>>(), vec![(1, 0.75)], "duplicates are summed");
    assert!(matches!(metzler_rate(&net, &[1.0, 0.0]), Err(ComposeError::NonPositiveRate { .. })));
}
