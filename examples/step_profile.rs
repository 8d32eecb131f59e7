//! A loop over one per-sample path, for instruction counts under valgrind (which, unlike wall
//! time, do not depend on the other tenants of a shared machine).
//!
//! ```sh
//! cargo build --release --example step_profile
//! for n in 100000 300000; do
//!   valgrind --tool=cachegrind --cache-sim=no --cachegrind-out-file=/dev/null \
//!     target/release/examples/step_profile step $n 2>&1 | grep "I *refs"
//! done   # (difference) / 200000 = instructions per sample
//! ```
//!
//! Modes: `update` (`SlidingRegression::push`), `estimate` (push + estimate), `ambiguity`
//! (`AmbiguityRadius::push` + `snapshot`), `step` (`Certifier::push`, Gaussian + Wasserstein),
//! `gaussian` (`Certifier::push`, the paper's Gaussian certificate only), `calibrated`
//! (`Certifier::push`, Gaussian + calibrated with its default windows), `nonlinear` (the same
//! plus the nonlinear certificate of degree 3), `baseline` (`Certifier::push`, the bench's
//! `through_origin_gaussian_and_calibrated_unguarded`: the calibrated step before the
//! intercept, the guards, the fifth window and the anchored window, the baseline of the
//! default step's target), all for `p = m = 1`; `wide` (`Certifier::push`,
//! Gaussian, `p = m = 10`, gain `−I`, the bench's `gaussian/p10_m10_M150`); `M = 150`, `h = 5`,
//! on the stream of `benches/regression.rs`.

use std::hint::black_box;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::ambiguity::{AmbiguityConfig, AmbiguityRadius};
use streamcert::certificate::{
    Calibration, Certifier, CertifierConfig, NonlinearConfig, RiskSplit,
};
use streamcert::regression::{Model, RegressionConfig, SlidingRegression};

/// The calibrated certifiers: Gaussian + calibrated (δ = 0.01, the default windows, as the
/// bench's `gaussian_and_calibrated`), the baseline (through the origin, no guard, four windows,
/// the risk split by length) and the default with the nonlinear certificate of degree 3.
fn calibrated(reg_cfg: RegressionConfig) -> Result<[Certifier; 3], Box<dyn std::error::Error>> {
    let mut cal_cfg = CertifierConfig::new(reg_cfg, vec![-1.0], 0.2, 0.05, 10);
    cal_cfg.calibration = Some(Calibration::new(0.01));
    let mut was_cfg = cal_cfg.clone();
    was_cfg.regression.model = Model::ThroughOrigin;
    was_cfg.calibration = Some(Calibration {
        windows: Some(4),
        risk_split: RiskSplit::ByLength,
        anchored_share: 0.0,
        ..Calibration::new(0.01).unguarded()
    });
    let mut nonlinear_cfg = cal_cfg.clone();
    nonlinear_cfg.nonlinear = Some(NonlinearConfig::with_degree(3));
    Ok([Certifier::new(cal_cfg)?, Certifier::new(was_cfg)?, Certifier::new(nonlinear_cfg)?])
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mode = args.next().unwrap_or_else(|| "step".into());
    let samples: usize = args.next().map_or(Ok(1_000_000), |s| s.parse())?;
    let len = 4096;
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut state = [0.0f64; 2];
    let mut data = Vec::with_capacity(2 * len);
    for _ in 0..len {
        for v in &mut state {
            *v = 0.95 * *v + rng.random::<f64>() - 0.5;
        }
        data.extend_from_slice(&state);
    }
    let reg_cfg = RegressionConfig::new(1, 1, 150, 5, 1e-4);
    let mut cfg = CertifierConfig::new(reg_cfg, vec![-1.0], 0.2, 0.05, 10);
    cfg.ambiguity = Some(AmbiguityConfig::paper(150));
    let mut cert = Certifier::new(cfg)?;
    let [mut cal, mut baseline, mut nonlinear] = calibrated(reg_cfg)?;
    let mut gauss = Certifier::new(CertifierConfig::new(reg_cfg, vec![-1.0], 0.2, 0.05, 10))?;
    let mut reg = SlidingRegression::new(reg_cfg)?;
    let mut amb = AmbiguityRadius::new(AmbiguityConfig::paper(150))?;
    let (pw, mw) = (10usize, 10usize);
    let mut wide_data = Vec::with_capacity((pw + mw) * len);
    let mut wide_state = vec![0.0f64; pw + mw];
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for _ in 0..len {
        for v in &mut wide_state {
            *v = 0.95 * *v + rng.random::<f64>() - 0.5;
        }
        wide_data.extend_from_slice(&wide_state);
    }
    let wide_gain: Vec<f64> =
        (0..mw * pw).map(|i| if i % (pw + 1) == 0 { -1.0 } else { 0.0 }).collect();
    let wide_cfg = RegressionConfig::new(pw, mw, 150, 5, 1e-4);
    let mut wide = Certifier::new(CertifierConfig::new(wide_cfg, wide_gain, 0.2, 0.05, 10))?;
    let mut t = 0.0;
    for i in 0..samples {
        let k = i % len;
        t += 0.01;
        let (y, u) = (&data[2 * k..2 * k + 1], &data[2 * k + 1..2 * k + 2]);
        match mode.as_str() {
            "update" => reg.push(black_box(t), y, u)?,
            "estimate" => {
                reg.push(black_box(t), y, u)?;
                black_box(reg.estimate().rms_residual);
            }
            "ambiguity" => {
                // A white residual-like value: the innovation of the AR(0.95) stream.
                let prev = data[(2 * k + 2 * len - 2) % (2 * len)];
                amb.push(black_box(data[2 * k] - 0.95 * prev))?;
                black_box(amb.snapshot().eps);
            }
            "step" => {
                let ev = cert.push(black_box(t), y, u)?;
                black_box((ev.gaussian.value, ev.wasserstein.value, ev.wasserstein.open));
            }
            "gaussian" => {
                let ev = gauss.push(black_box(t), y, u)?;
                black_box((ev.gaussian.value, ev.gaussian.open));
            }
            "calibrated" => {
                let ev = cal.push(black_box(t), y, u)?;
                black_box((ev.gaussian.value, ev.calibrated.value, ev.calibrated.open));
            }
            "baseline" => {
                let ev = baseline.push(black_box(t), y, u)?;
                black_box((ev.gaussian.value, ev.calibrated.value, ev.calibrated.open));
            }
            "nonlinear" => {
                let ev = nonlinear.push(black_box(t), y, u)?;
                black_box((ev.calibrated.value, ev.nonlinear.value, ev.nonlinear.open));
            }
            "wide" => {
                let s = &wide_data[(pw + mw) * k..(pw + mw) * (k + 1)];
                let ev = wide.push(black_box(t), &s[..pw], &s[pw..])?;
                black_box((ev.gaussian.value, ev.gaussian.open));
            }
            other => return Err(format!("unknown mode {other}").into()),
        }
    }
    Ok(())
}
