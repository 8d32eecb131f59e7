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
//! default step's target), `unguarded`, `without_change`, `without_model` (the default with
//! no guard, without its change guard, without its two model guards), `auto` (the default
//! with the horizon ladder of `horizon = "auto"`: `h = 1, 2, 5, 10`, `M = 30 h`), `order2`
//! (the default at `[regression] order = 2` with its documented `M = 2000` rows, `h = 50`:
//! the certificate of order 2, its looks included; on this stream its hidden-dynamics guard
//! refuses every look, so the later fit and the bisection are not paid), `order2_loop` (the
//! same on an exactly simulated order-2 loop at five times the margin, whose looks pass
//! both guards, fit three times and bisect the margin; at most [`LOOP_SAMPLES`] samples, the
//! record simulated whole before the loop whatever their number), `orders_loop` (the same
//! record under `order = "auto"`: orders 1, 2 and 3 side by side), `order1_loop` (the same
//! record at the first order with the same `M = 2000`, `h = 50`: the ladder's own first
//! rung alone, at `δ`), all for `p = m = 1`; `wide` (`Certifier::push`,
//! Gaussian, `p = m = 10`, gain `−I`, the bench's `gaussian/p10_m10_M150`); `M = 150`, `h = 5`,
//! on the stream of `benches/regression.rs`.

use std::hint::black_box;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use streamcert::ambiguity::{AmbiguityConfig, AmbiguityRadius};
use streamcert::certificate::{
    Calibration, Certifier, CertifierConfig, HorizonLadder, NonlinearConfig, OrderLadder, RiskSplit,
};
use streamcert::regression::{LoopModel, Model, RegressionConfig, SlidingRegression};

/// The calibrated certifier of `mode`, `None` for a mode without one: `calibrated`
/// (Gaussian + calibrated, δ = 0.01, the default windows, as the bench's
/// `gaussian_and_calibrated`), `baseline` (through the origin, no guard, four windows, the
/// risk split by length), `nonlinear` (the default with the nonlinear certificate of degree
/// 3), and the default with a part of it off, for the share of each part (BENCHMARKS.md):
/// `unguarded` (no guard), `without_change` (no change guard), `without_model` (no model
/// guard), `auto` (the default with the automatic horizon ladder).
fn calibrated(
    reg_cfg: RegressionConfig,
    mode: &str,
) -> Result<Option<Certifier>, Box<dyn std::error::Error>> {
    let mut cfg = CertifierConfig::new(reg_cfg, vec![-1.0], 0.2, 0.05, 10);
    let default = Calibration::new(0.01);
    let cal = match mode {
        "calibrated" => default,
        "baseline" => {
            cfg.regression.model = Model::ThroughOrigin;
            Calibration {
                windows: Some(4),
                risk_split: RiskSplit::ByLength,
                anchored_share: 0.0,
                ..default.unguarded()
            }
        }
        "nonlinear" => {
            cfg.nonlinear = Some(NonlinearConfig::with_degree(3));
            default
        }
        "unguarded" => default.unguarded(),
        "without_change" => Calibration { plant_change: false, ..default },
        "without_model" => Calibration { hidden_dynamics: false, nonlinearity: false, ..default },
        "auto" => {
            cfg.ladder = Some(HorizonLadder::automatic());
            default
        }
        "order2" | "order2_loop" | "orders_loop" | "order1_loop" => {
            if mode.starts_with("order2") {
                cfg.regression.order = LoopModel::Order(2);
            }
            cfg.regression = RegressionConfig { order: cfg.regression.order, ..reg(2000, 50) };
            if mode == "orders_loop" {
                cfg.orders = Some(OrderLadder::automatic());
            }
            if mode.ends_with("_loop") {
                cfg.gain = vec![LOOP_GAIN];
            }
            default
        }
        _ => return Ok(None),
    };
    cfg.calibration = Some(cal);
    Ok(Some(Certifier::new(cfg)?))
}

/// The first-order regression at window `m` and horizon `h` (the bench's ridge).
fn reg(m: usize, h: usize) -> RegressionConfig {
    RegressionConfig::new(1, 1, m, h, 1e-4)
}

/// The `order2_loop` record's length, and its loop's gain: `ÿ + 1.2 ẏ + y = u + 0.1` under
/// `u = 0.7625 y_m + d`, the closed loop `(s + 0.25)(s + 0.95)`.
const LOOP_SAMPLES: usize = 60_000;
const LOOP_GAIN: f64 = 0.7625;

/// `len` samples of `width` independent AR(0.95) channels driven by uniforms on
/// `[−0.5, 0.5)`, interleaved (seed 1): the bench's stream.
fn ar_stream(width: usize, len: usize) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut state = vec![0.0f64; width];
    let mut data = Vec::with_capacity(width * len);
    for _ in 0..len {
        for v in &mut state {
            *v = 0.95 * *v + rng.random::<f64>() - 0.5;
        }
        data.extend_from_slice(&state);
    }
    data
}

/// A simulated record: its times, and `y, u` interleaved.
type Record = (Vec<f64>, Vec<f64>);

/// The `order2_loop` record, [`LOOP_SAMPLES`] long whatever the run's length (so that its
/// simulation cancels in the difference of two runs); empty for the other modes.
fn loop_record(mode: &str, samples: usize) -> Result<Record, Box<dyn std::error::Error>> {
    let mut record = (Vec::new(), Vec::new());
    if mode.ends_with("_loop") {
        if samples > LOOP_SAMPLES {
            return Err(format!("{mode} runs at most {LOOP_SAMPLES} samples").into());
        }
        let plant = streamcert::dynamics::ObservableLoop {
            samples: LOOP_SAMPLES,
            ..streamcert::dynamics::ObservableLoop::new(&[1.2, 1.0], LOOP_GAIN)
        };
        plant.run(7, |t, y, u| {
            record.0.push(t);
            record.1.extend_from_slice(&[y, u]);
            true
        });
    }
    Ok(record)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mode = args.next().unwrap_or_else(|| "step".into());
    let samples: usize = args.next().map_or(Ok(1_000_000), |s| s.parse())?;
    let len = 4096;
    let data = ar_stream(2, len);
    let reg_cfg = RegressionConfig::new(1, 1, 150, 5, 1e-4);
    let mut cfg = CertifierConfig::new(reg_cfg, vec![-1.0], 0.2, 0.05, 10);
    cfg.ambiguity = Some(AmbiguityConfig::paper(150));
    let mut cert = Certifier::new(cfg)?;
    let mut gauss = Certifier::new(CertifierConfig::new(reg_cfg, vec![-1.0], 0.2, 0.05, 10))?;
    let mut reg = SlidingRegression::new(reg_cfg)?;
    let mut amb = AmbiguityRadius::new(AmbiguityConfig::paper(150))?;
    let (pw, mw) = (10usize, 10usize);
    let wide_data = ar_stream(pw + mw, len);
    let wide_gain: Vec<f64> =
        (0..mw * pw).map(|i| if i % (pw + 1) == 0 { -1.0 } else { 0.0 }).collect();
    let wide_cfg = RegressionConfig::new(pw, mw, 150, 5, 1e-4);
    let mut wide = Certifier::new(CertifierConfig::new(wide_cfg, wide_gain, 0.2, 0.05, 10))?;
    let mut cal = calibrated(reg_cfg, &mode)?;
    let (times, record) = loop_record(&mode, samples)?;
    let mut t = 0.0;
    for i in 0..samples {
        let k = i % len;
        t += 0.01;
        let (src, k) = if times.is_empty() { (&data, k) } else { (&record, i) };
        t = times.get(i).copied().unwrap_or(t);
        let (y, u) = (&src[2 * k..2 * k + 1], &src[2 * k + 1..2 * k + 2]);
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
            "nonlinear" => {
                let Some(cert) = cal.as_mut() else { unreachable!("built for this mode") };
                let ev = cert.push(black_box(t), y, u)?;
                black_box((ev.calibrated.value, ev.nonlinear.value, ev.nonlinear.open));
            }
            "calibrated" | "baseline" | "unguarded" | "without_change" | "without_model"
            | "auto" | "order2" | "order2_loop" | "orders_loop" | "order1_loop" => {
                let Some(cert) = cal.as_mut() else { unreachable!("built for these modes") };
                let ev = cert.push(black_box(t), y, u)?;
                black_box((ev.gaussian.value, ev.calibrated.value, ev.calibrated.open));
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
