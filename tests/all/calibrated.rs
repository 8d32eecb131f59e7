//! The calibrated certificate: the multi-window instrumented statistics against a batch
//! recompute, the radius against its formula (nalgebra, statrs), the configuration it refuses,
//! and its guarantee at the boundary (a candidate just below the margin, the smallest accepted
//! window, a one-sample gate, many seeded runs, a Clopper–Pearson bound).

use statrs::distribution::{Beta, ContinuousCDF, StudentsT};
use streamcert::certificate::{Calibration, Certifier, CertifierConfig, NotCertified, look_risk};
use streamcert::dynamics::{LinearScenario, PlantSwitch, Process};
use streamcert::regression::{
    InputIntegral, InstrumentedWindows, Model, RegressionConfig, SlidingRegression,
};

use crate::support::{coupled_pair, run as run_scenario, scalar};

mod oracle;
use oracle::LookOracle;

const H: usize = 5;

pub(crate) fn calibrated(
    p: usize,
    gain: Vec<f64>,
    window: usize,
    consecutive: usize,
) -> CertifierConfig {
    let reg = RegressionConfig {
        input_integral: InputIntegral::ZeroOrderHold,
        ..RegressionConfig::new(p, p, window, H, 1e-4)
    };
    CertifierConfig {
        calibration: Some(Calibration::new(0.01)),
        ..CertifierConfig::new(reg, gain, 1.0, 0.05, consecutive)
    }
}

/// The short-window case: `ẏ = 0.5 y + u + w`, σ = 0.1, `u = −y + PRBS(±1, 0.2 s)`,
/// 40 s at dt = 0.01.
pub(crate) fn short_window_plant() -> LinearScenario {
    LinearScenario {
        dither_hold: 0.2,
        steps: 4000,
        ..scalar(0.5, -1.0, Process::Gaussian { sigma: 0.1 }, 1.0)
    }
}

/// Whether the calibrated gate ever opens on `scenario` run `seed`, and when.
pub(crate) fn first_opening(
    cfg: &CertifierConfig,
    scenario: &LinearScenario,
    seed: u64,
) -> Option<f64> {
    let traj = run_scenario(scenario, seed);
    let mut cert = Certifier::new(cfg.clone()).expect("valid");
    (0..traj.len()).find_map(|i| {
        let ev = cert.push(traj.t[i], traj.output(i), traj.input(i)).expect("valid");
        ev.calibrated.open.then_some(traj.t[i])
    })
}

/// The two-sided 95 % Clopper–Pearson interval for `k` successes in `n`.
pub(crate) fn clopper_pearson(k: usize, n: usize) -> (f64, f64) {
    let lower = if k == 0 {
        0.0
    } else {
        Beta::new(k as f64, (n - k + 1) as f64).expect("valid").inverse_cdf(0.025)
    };
    let upper = if k == n {
        1.0
    } else {
        Beta::new(k as f64 + 1.0, (n - k) as f64).expect("valid").inverse_cdf(0.975)
    };
    (lower, upper)
}

#[test]
fn instrumented_windows_equal_a_batch_recompute_at_every_column() {
    let windows = [20, 40, 80];
    let (lag, intervals) = (2, 3);
    let scenario = LinearScenario { steps: 900, ..short_window_plant() };
    let traj = run_scenario(&scenario, 4);
    let mut reg = SlidingRegression::new(RegressionConfig::new(1, 1, 20, H, 0.0)).expect("valid");
    let mut win = InstrumentedWindows::new(1, 1, H, lag, intervals, &windows).expect("valid");
    let mut cols: Vec<([f64; 2], f64)> = Vec::new();
    let reach = intervals * H + lag;
    for i in 0..traj.len() {
        reg.push(traj.t[i], traj.output(i), traj.input(i)).expect("valid");
        if reg.columns_built() as usize == cols.len() {
            continue;
        }
        let (z, dy) = reg.newest_column().expect("a column");
        win.push_column(z, dy);
        cols.push(([z[0], z[1]], dy[0]));
        for (w, &mw) in windows.iter().enumerate() {
            // Column j pairs Z_j with W_j = [Z_{j−h−L}; Z_{j−2h−L}; Z_{j−3h−L}]; a window is
            // the newest complete blocks of h instrumented columns.
            let complete = cols.len().saturating_sub(reach) / H;
            let end = reach + complete * H;
            let first = end - complete.min(mw / H) * H;
            let (mut n, mut cw, mut hm) = ([0.0f64; 12], [0.0f64; 6], [0.0f64; 36]);
            for j in first..end {
                let (z, dy) = cols[j];
                let wv: Vec<f64> = (1..=intervals).flat_map(|l| cols[j - l * H - lag].0).collect();
                for a in 0..6 {
                    for b in 0..2 {
                        n[b * 6 + a] += z[b] * wv[a];
                    }
                    cw[a] += dy * wv[a];
                    for b in 0..6 {
                        hm[a * 6 + b] += wv[a] * wv[b];
                    }
                }
            }
            assert_eq!(win.columns(w), end - first);
            let mut got = vec![0.0; 12 + 6 + 36];
            win.window_sums(w, &mut got);
            let want: Vec<f64> = n.iter().chain(&cw).chain(&hm).copied().collect();
            for (g, e) in got.iter().zip(&want) {
                assert!((g - e).abs() <= 1e-9 * (1.0 + e.abs()), "window {mw}: {g} vs {e}");
            }
        }
    }
    assert!(cols.len() > 800);
}

/// `β̂_w − ρ_w` at every look against the formula rebuilt with nalgebra and statrs from the
/// stored columns (batch): two-stage least squares with three instrument intervals,
/// `Θ̂ = Cw Q A⁻¹`, `X = Q A⁻¹ T`, scores `u_q = vec(sym(R_q (XᵀW_q)ᵀ))`,
/// block sums over `h` columns, `Ω̂ = c_h B/(B − d) Σ S_j S_jᵀ`, `ρ = t_ν(1 − δ_{w,k}) √λ_max(Ω̂)`
/// with `ν` the Welch–Satterthwaite effective number of blocks less `d`.
#[test]
fn every_look_matches_its_formula_for_two_outputs() {
    every_look_matches_its_formula(1, Model::Affine, 0.2);
    every_look_matches_its_formula(1, Model::ThroughOrigin, 0.2);
    // The batched radius at 95 % of the look's risk: it stands at some looks, so that its own
    // formula is checked too.
    every_look_matches_its_formula(1, Model::Affine, 0.95);
}

/// As above with batches of four blocks (`batch_blocks = 4`): the block sums are summed over
/// batches, the oldest batch holding the remainder (window 150: 30 blocks, a batch of 2 and
/// seven of 4), `c_{b,h} = 3bh²/(3bh² − h² + 1)` with the remainder's batch weighted by
/// `c_{2,h}/c_{4,h}`, `B` the number of batches, and the effective number over batch weights.
#[test]
fn every_look_matches_its_formula_with_batches_of_blocks() {
    every_look_matches_its_formula(4, Model::Affine, 0.2);
    every_look_matches_its_formula(4, Model::ThroughOrigin, 0.2);
}

/// The affine model's windows regress on `[∫y; ∫u; τ]` (`τ` the column's span, instrumented by
/// the instrument intervals' own spans, its row of `T` zero): `d = 5` unknowns per output.
fn every_look_matches_its_formula(batch: usize, model: Model, auto_share: f64) {
    let affine = model == Model::Affine;
    let dd = 4 + usize::from(affine);
    let gain = vec![-2.0, 0.0, 0.0, -2.0];
    let scenario = coupled_pair(short_window_plant(), 1500);
    let mut cfg = calibrated(2, gain.clone(), 150, 1);
    cfg.regression.model = model;
    cfg.calibration = Some(Calibration {
        windows: Some(2),
        instrument_intervals: 3,
        batch_blocks: batch,
        auto_batch_risk: auto_share,
        ..Calibration::new(0.01)
    });
    let traj = run_scenario(&scenario, 8);
    let mut cert = Certifier::new(cfg).expect("valid");
    let mut cols: Vec<(nalgebra::DVector<f64>, nalgebra::DVector<f64>)> = Vec::new();
    let mut last = [None, None];
    let (mut checked, mut batched) = (0, 0);
    let t_mat = nalgebra::DMatrix::from_fn(dd, 2, |r, c| match r {
        0 | 1 => f64::from(u8::from(r == c)),
        2 | 3 => gain[(r - 2) * 2 + c],
        _ => 0.0,
    });
    let (lag, intervals) = (1, 3);
    for i in 0..traj.len() {
        cert.push(traj.t[i], traj.output(i), traj.input(i)).expect("valid");
        if cert.regression().columns_built() as usize > cols.len() {
            let (z, dy) = cert.regression().newest_column().expect("column");
            let mut z = z.to_vec();
            if affine {
                z.push(cert.regression().newest_column_span().expect("column"));
            }
            cols.push((nalgebra::DVector::from_vec(z), nalgebra::DVector::from_column_slice(dy)));
        }
        for (w, look) in cert.calibrated_looks().iter().enumerate() {
            let Some(look) = look else { continue };
            if last[w] == Some(look.look) {
                continue;
            }
            last[w] = Some(look.look);
            let o = LookOracle::new(&cols, [150, 300][w], &t_mat, (lag, intervals));
            let beta = o.beta();
            // Two windows: an equal share of δ each. In batches of one block, the window of
            // 60 blocks also takes the automatic batches (⌊60 / 30⌋ = 2 blocks, 30 batches)
            // at its share of the risk (default a fifth), the smaller radius standing; the
            // window of 30 blocks (⌊30 / 30⌋ = 1) does not.
            // The sliding windows split `1 − anchored_share` of δ.
            let sliding = 1.0 - Calibration::new(0.01).anchored_share;
            let risk = look_risk(0.01, sliding * 0.5, look.look);
            let radius = if batch == 1 && w == 1 {
                let first = o.radius_in(1, risk * (1.0 - auto_share));
                let second = o.radius_in(2, risk * auto_share);
                batched += usize::from(second < first);
                first.min(second)
            } else {
                o.radius_in(batch, risk)
            };
            // `10⁻⁶`: with `J = 3` and the intercept, `H` is singular but for the ridge
            // (`Calibration::fit_ridge`, `10⁻⁸` relative), and both solves carry its condition.
            assert!((look.beta_hat - beta).abs() < 1e-6 * (1.0 + beta.abs()), "{look:?} vs {beta}");
            assert!((look.radius - radius).abs() < 1e-6 * radius, "{look:?} vs {radius}");
            checked += 1;
        }
    }
    // Window 150 looks at columns 150, 225, …; window 300 at 300, 450, …. With eight batches
    // in the short window, `ν = min(ESS, 8) − d` is not positive at some looks, which then
    // give no certificate (and nothing to check); the fits' pivot floor for `J = 3`
    // (`Calibration::fit_ridge`) refuses a few early looks.
    assert!(checked >= if batch == 1 { 15 } else { 5 }, "checked {checked} looks");
    if auto_share > 0.9 {
        // Measured: 2 of the 26 looks (of about 9 of the longer window; 30 batches against
        // 60 blocks cost the batched radius degrees of freedom where no sensor noise pays
        // for them; 4 before the anchored window took 90 % of δ: at the sliding windows'
        // smaller risks the first radius's degrees of freedom count for more).
        assert!(batched >= 2, "the batched radius stood at {batched} of {checked} looks");
    }
}

#[test]
fn contracting_candidates_are_certified_and_a_plant_change_closes_the_gate() {
    // K = −1.5: true rate 1.0, twenty times the margin.
    let cfg = calibrated(1, vec![-1.5], 150, 10);
    let opened = (0..20).filter(|&s| first_opening(&cfg, &short_window_plant(), 300 + s).is_some());
    assert!(opened.count() >= 18);
    // At 20 s the plant's a jumps from 0.5 to 1.6: the same K then gives rate −0.1.
    let switched = LinearScenario {
        switch: Some(PlantSwitch { at: 20.0, a: vec![1.6], ramp: 0.0 }),
        ..short_window_plant()
    };
    let mut delays = Vec::new();
    for seed in 0..10 {
        let traj = run_scenario(&switched, 400 + seed);
        let mut cert = Certifier::new(cfg.clone()).expect("valid");
        let (mut open_at_switch, mut closed_at) = (false, None);
        for i in 0..traj.len() {
            let ev = cert.push(traj.t[i], traj.output(i), traj.input(i)).expect("valid");
            if traj.t[i] < 20.0 {
                open_at_switch = ev.calibrated.open;
            } else if closed_at.is_none() && !ev.calibrated.open {
                closed_at = Some(traj.t[i] - 20.0);
                // The change guard, a newer window's bound, the certificate below the margin,
                // or the model guard (a window that mixes the two plants is neither first
                // order nor linear): every closing costs no validity.
                assert!(
                    matches!(
                        ev.calibrated.reason,
                        Some(
                            NotCertified::PlantChanged { .. }
                                | NotCertified::RateBelowMargin { .. }
                                | NotCertified::BelowMargin { .. }
                                | NotCertified::HiddenDynamics { .. }
                                | NotCertified::VaryingDynamics { .. }
                        )
                    ),
                    "{:?}",
                    ev.calibrated.reason
                );
            }
        }
        if open_at_switch {
            delays.push(closed_at.expect("the gate must close after the plant change"));
        }
    }
    assert!(delays.len() >= 8, "open at the switch in {} of 10 runs", delays.len());
    assert!(delays.iter().all(|&d| d < 10.0), "detection delays {delays:?}");
}

/// Sensor noise on `y` (errors in variables, `u = K y` carries it too): the ordinary estimate
/// of a loop with true rate 1.0 is biased upward; the instrumented window estimate is not.
#[test]
fn the_instrumented_window_is_unbiased_under_sensor_noise() {
    let scenario = LinearScenario {
        sensor_noise: 0.3,
        dither_hold: 0.2,
        steps: 4000,
        ..scalar(0.5, -1.5, Process::Gaussian { sigma: 0.1 }, 1.0)
    };
    let cfg = CertifierConfig {
        calibration: Some(Calibration { windows: Some(1), ..Calibration::new(0.01) }),
        ..calibrated(1, vec![-1.5], 1200, 1)
    };
    let (mut ordinary, mut instrumented) = (Vec::new(), Vec::new());
    for seed in 0..30 {
        let traj = run_scenario(&scenario, 600 + seed);
        let mut cert = Certifier::new(cfg.clone()).expect("valid");
        let mut last = None;
        for i in 0..traj.len() {
            last = Some(cert.push(traj.t[i], traj.output(i), traj.input(i)).expect("valid"));
        }
        ordinary.push(last.and_then(|e| e.beta_hat()).expect("estimate"));
        instrumented.push(cert.calibrated_looks()[0].expect("a look").beta_hat);
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (o, iv) = (median(&mut ordinary), median(&mut instrumented));
    assert!((iv - 1.0).abs() < 0.1, "instrumented median {iv} (ordinary {o})");
    assert!(
        o - 1.0 > 0.15 && o - 1.0 > 3.0 * (iv - 1.0).abs(),
        "ordinary {o} vs instrumented {iv}"
    );
}

proptest::proptest! {
    /// The rank-one bound for p = 2 is an upper bound on the variance along every unit v
    /// (checked on 1000 directions) and at most its grid factor above λ_max(Ω).
    #[test]
    fn rank_one_bound_covers_every_direction(entries in proptest::collection::vec(-1.0f64..1.0, 16)) {
        let a = nalgebra::DMatrix::from_row_slice(4, 4, &entries);
        // A PSD matrix symmetric under the swap of the two off-diagonal slots, as vec(sym ·).
        let swap = nalgebra::DMatrix::from_row_slice(4, 4, &[
            1.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.5, 0.0, 0.0, 0.5, 0.5, 0.0, 0.0, 0.0, 0.0, 1.0,
        ]);
        let omega = &swap * &a * a.transpose() * &swap;
        let bound = streamcert::certificate::rank_one_variance_bound(omega.as_slice());
        let lambda = omega.clone().symmetric_eigen().eigenvalues.max();
        let factor = 1.0 / (1.0 - 2.0 * std::f64::consts::PI / 256.0);
        proptest::prop_assert!(bound <= lambda * factor * (1.0 + 1e-9) + 1e-12);
        for i in 0..1000 {
            let th = std::f64::consts::PI * f64::from(i) / 1000.0;
            let (s, c) = th.sin_cos();
            let e = nalgebra::DVector::from_vec(vec![c * c, c * s, c * s, s * s]);
            let f = (e.transpose() * &omega * &e)[(0, 0)];
            proptest::prop_assert!(f <= bound * (1.0 + 1e-12) + 1e-15, "{f} > {bound}");
        }
    }

    /// The fast Student-t quantile against statrs' inverse incomplete beta.
    #[test]
    fn t_quantile_matches_statrs(nu in 1.0f64..2000.0, log_risk in -27.0f64..-0.95) {
        let risk = log_risk.exp();
        let want = -StudentsT::new(0.0, 1.0, nu).expect("valid").inverse_cdf(risk);
        let dist = StudentsT::new(0.0, 1.0, nu).expect("valid");
        let got = streamcert::certificate::t_quantile(nu, risk);
        // statrs' own inverse is accurate to about 1e-9; the defining property is S(t) = risk
        // (to 1e-6: where the continued fraction does not apply, t_quantile falls back on
        // statrs' inverse, whose round trip through statrs' survival function is looser).
        proptest::prop_assert!((got - want).abs() <= 1e-8 * want.abs(), "{got} vs {want}");
        proptest::prop_assert!((dist.sf(got) / risk - 1.0).abs() <= 1e-6, "S({got}) vs {risk}");
    }
}

/// A certifier with batches of blocks resumes from its checkpoint bit for bit, its windows'
/// batch setting is written only when it is not 1 (so a default state reads and writes as
/// before), and a state whose windows disagree with the configured batch is refused.
#[test]
fn batched_windows_checkpoint_and_are_checked_against_their_configuration() {
    let traj = run_scenario(&short_window_plant(), 3);
    let mut cfg = calibrated(1, vec![-0.54], 150, 1);
    cfg.calibration = Some(Calibration { batch_blocks: 4, ..Calibration::new(0.01) });
    let mut whole = Certifier::new(cfg.clone()).expect("valid");
    let all: Vec<_> = (0..traj.len())
        .map(|k| whole.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid"))
        .collect();
    let (text, _) = crate::support::resume_matches(&cfg, &traj, &all, 2345);
    assert!(all.iter().any(|e| e.calibrated.value.is_some()), "the calibrated looks ran");
    let payload = crate::support::json_payload(&text);
    // The calibrated windows' (the model guard's larger fit keeps batches of one block).
    assert_eq!(payload.matches("\"batch\":4").count(), 1, "the windows' batch is written");
    assert!(payload.contains("\"batch_blocks\":4"));
    let reseal = |edited: String| crate::support::reseal_json(&edited, &cfg);
    let err = Certifier::restore(reseal(payload.replace("\"batch\":4", "\"batch\":2")))
        .expect_err("refused");
    assert!(err.to_string().contains("calibrated state does not match"), "{err}");
    // The default setting writes neither key.
    let plain = Certifier::new(calibrated(1, vec![-0.54], 150, 1)).expect("valid");
    let text = plain.checkpoint_json().expect("serialises");
    assert!(!text.contains("\"batch\"") && !text.contains("batch_blocks"));
}
