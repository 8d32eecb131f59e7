//! [`Certifier`]: the streaming certifier that runs the regression, forms `β̂` and the radii,
//! feeds the ambiguity estimators and the calibrated windows, and updates the gates. The
//! checkpoint (serialise and restore with checks) is in `checkpoint.rs`, the calibrated and
//! nonlinear part of a step in `calibrated_step.rs`.
//!
//! ## One step
//!
//! [`Certifier::push`] runs the regression, forms `J_cl = J_obs + B_obs K`
//! (`linalg::closed_loop_jacobian`) and `β̂ = −λ_max(sym J_cl)` (from `p = 10` through
//! `SlidingRegression::estimate_and_sym_max`, which solves first and then computes the Gram
//! matrix's extremes and `λ_max(sym J_cl)` side by side, the same bits as one after the other),
//! `ρ` (eq. rho), feeds the residual of the newest interval (or column) to one
//! `AmbiguityRadius` per output (`ε` = the largest; for `p = 1` taken as the residual goes in,
//! `push_and_snapshot`, since `ε` ends the step's longest chain of dependent operations), steps
//! the calibrated state and returns [`Evidence`] with every certificate, gate and reason.
//!
//! On the `p = 1` path no value is read back in one load that spans several stores made just
//! before (such a load is not forwarded from the stores and waits for them to reach the
//! cache): the scalar update adds the sample's own interval from registers, `evaluate` is
//! inlined so its result stays in registers, and `ε` is taken as its residual goes in
//! (measured by the benchmarks in `benches/regression.rs`).
//!
//! ## The checkpoint (feature `checkpoint`, on by default)
//!
//! `checkpoint.rs`: the envelope (a text header line: magic, version, FNV-1a checksum of the
//! payload, the configuration's fingerprint) and the whole state in CBOR (each float in the
//! shortest exact width) or JSON. In the binary encoding the calibrated state's sliding block
//! rings are left out where its sample trail rebuilds them bit for bit (`calibrated/replay.rs`,
//! checked before they are left out, rebuilt by `verify.rs` on restore). `pack.rs`: the block
//! rings still written, packed: each model guard's ring as the entries with an extra regressor
//! or instrument (the rest are the linear ring's same products), every ring without the lower
//! triangle of `H`; each derived entry is compared bit for bit with its source before it is
//! left out, a ring that differs is written whole, and a packed ring that does not fit its
//! layout is refused on restore. `verify.rs`: a deserialised state checked against its
//! configuration and itself, whatever deserialised it.

mod access;
mod calibrated_step;
#[cfg(feature = "checkpoint")]
pub(crate) mod checkpoint;
mod closed;
mod gaps;
mod ladder_step;
mod order_n_step;
use closed::closed_reason;
pub use ladder_step::RungStatus;
#[cfg(feature = "checkpoint")]
mod pack;
mod verify;

use serde::{Deserialize, Serialize};
use streamcert_ambiguity::AmbiguityRadius;
use streamcert_regression::{
    EstimateStatus, FastPath, LoopModel, RegressionConfig, ResidualSource, SlidingRegression,
    linalg,
};

use crate::calibrated::CalibratedState;
use crate::gap::GapDetector;
use crate::rate::first_order::{self, form_sym_jcl};
use crate::{
    AmbiguityLevel, CertifierConfig, CertifyError, Evidence, Fit, Gate, NotCertified,
    OrderNCertificate, Verdict, certificate_value,
};

/// The streaming certifier. Serde-serialisable: [`Certifier::checkpoint`] and
/// [`Certifier::restore`] continue a run with bit-identical output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Certifier {
    cfg: CertifierConfig,
    regression: SlidingRegression,
    gain_norm: f64,
    gauss: Gate,
    samples: u64,
    skipped: u64,
    wass: Gate,
    calibrated_gate: Gate,
    /// In a binary checkpoint, its sliding block rings left out for the sample trail where it
    /// rebuilds them (`calibrated/replay.rs`), the rest packed (`pack.rs`).
    #[cfg_attr(
        feature = "checkpoint",
        serde(serialize_with = "pack::serialize", deserialize_with = "pack::deserialize")
    )]
    calibrated: Option<CalibratedState>,
    nonlinear_gate: Gate,
    // The window length of the standing calibrated look (for its region).
    #[serde(default)]
    calibrated_window: Option<usize>,
    gap: GapDetector,
    ambiguity: Vec<AmbiguityRadius>,
    resid: Vec<f64>,
    jcl: Vec<f64>,
    work: Vec<f64>,
    eig_work: Vec<f64>,
    /// The gain in the metric's units, `K W⁻¹` ([`CertifierConfig::metric_gain`]).
    gain: Vec<f64>,
    /// Scratch: one sample's outputs in the metric's units (empty without a metric).
    scaled: Vec<f64>,
    /// A [`HorizonLadder`](crate::HorizonLadder)'s other rungs, in the ladder's order without
    /// this certifier's horizon; each computes the calibrated certificate only.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    rungs: Vec<Certifier>,
    /// Every rung's latest calibrated verdict, in the ladder's order (this certifier's too).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    rung_verdicts: Vec<Verdict>,
    /// The rung whose look stands (an index into `rungs`; `None`: this certifier's own).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    standing: Option<usize>,
    /// A rung of another certifier's ladder: the paper's estimate is not computed.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    calibrated_only: bool,
    /// At `[regression] order = 2 | 3`: the certificate of order `n`, which then takes every
    /// sample (the first-order regression above is built but not fed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    order_n: Option<Box<OrderNCertificate>>,
}

/// The regression's outcome, reduced to what the certificate needs.
#[derive(Debug, Clone, Copy)]
struct Ready {
    beta_hat: f64,
    rho: f64,
    rms: f64,
    lambda_min: f64,
}

/// [`Certifier::evaluate`]'s result: the ready estimate, the window's columns, why not ready,
/// and the ambiguity level when the `p = 1` step took it as its residual went in.
type Evaluated = (Option<Ready>, usize, Option<NotCertified>, Option<AmbiguityLevel>);

impl Certifier {
    /// Validate and build.
    ///
    /// # Errors
    /// [`CertifyError::InvalidConfig`] or [`CertifyError::Regression`].
    ///
    /// ```
    /// use streamcert_certificate::{Certifier, CertifierConfig, CertifyError};
    /// use streamcert_regression::RegressionConfig;
    /// // K must be m × p = 1 × 1.
    /// let cfg = CertifierConfig::new(RegressionConfig::new(1, 1, 100, 5, 1e-4), vec![1.0, 2.0], 0.2, 0.05, 10);
    /// assert!(matches!(Certifier::new(cfg), Err(CertifyError::InvalidConfig { field: "gain", .. })));
    /// ```
    pub fn new(cfg: CertifierConfig) -> Result<Self, CertifyError> {
        cfg.validate()?;
        let (p, m) = (cfg.regression.outputs, cfg.regression.inputs);
        let gain = cfg.metric_gain();
        let order_n = cfg.order_n().map(OrderNCertificate::new).transpose()?.map(Box::new);
        // At order n the first-order regression is built (its state's shape) but not fed.
        let first_order = RegressionConfig { order: LoopModel::FirstOrder, ..cfg.regression };
        Ok(Self {
            regression: SlidingRegression::new(first_order)?,
            gain_norm: linalg::spectral_norm(&gain, m, p),
            gauss: Gate::new(cfg.margin, cfg.consecutive),
            wass: Gate::new(cfg.margin, cfg.consecutive),
            calibrated_gate: Gate::new(cfg.margin, cfg.consecutive),
            nonlinear_gate: Gate::new(cfg.margin, cfg.consecutive),
            calibrated_window: None,
            calibrated: cfg
                .calibration_in_effect()
                .filter(|_| order_n.is_none())
                .map(|c| {
                    let coupling = cfg.couplings.as_ref();
                    CalibratedState::new(c, cfg.nonlinear, coupling, &cfg.regression, &gain)
                })
                .transpose()?,
            gap: GapDetector::new(cfg.gap_factor),
            ambiguity: match &cfg.ambiguity {
                Some(a) => (0..p).map(|_| AmbiguityRadius::new(*a)).collect::<Result<_, _>>()?,
                None => Vec::new(),
            },
            resid: vec![0.0; p],
            samples: 0,
            skipped: 0,
            jcl: vec![0.0; p * p],
            work: vec![0.0; p * p],
            eig_work: vec![0.0; linalg::eig_work_len(p)],
            scaled: vec![0.0; if cfg.metric.is_some() { p } else { 0 }],
            rungs: ladder_step::rungs(&cfg)?,
            rung_verdicts: ladder_step::verdicts(&cfg),
            standing: None,
            calibrated_only: false,
            order_n,
            gain,
            cfg,
        })
    }

    /// Absorb one sample and return the evidence. No allocation.
    ///
    /// A step larger than `gap_factor` times the reference step resets the window first (the
    /// sample then starts a new one) and the evidence gives [`NotCertified::Gap`].
    ///
    /// # Errors
    /// Under [`BadSamplePolicy::Reject`], the regression's sample error (the state is
    /// untouched, except after [`RegressionError::Overflow`], which clears the window). Under
    /// [`BadSamplePolicy::Skip`] a bad sample is not an error: it is [`skip`](Self::skip)ped.
    ///
    /// [`RegressionError::Overflow`]: streamcert_regression::RegressionError::Overflow
    /// [`BadSamplePolicy::Reject`]: crate::BadSamplePolicy::Reject
    /// [`BadSamplePolicy::Skip`]: crate::BadSamplePolicy::Skip
    pub fn push(&mut self, t: f64, y: &[f64], u: &[f64]) -> Result<Evidence, CertifyError> {
        if let Some(w) = &self.cfg.metric {
            // The outputs in the metric's units, `w_i y_i` (a wrong length is the
            // regression's error below).
            let mut scaled = std::mem::take(&mut self.scaled);
            let n = y.len().min(scaled.len());
            for ((s, &v), &wi) in scaled[..n].iter_mut().zip(y).zip(w) {
                *s = wi * v;
            }
            let ev = self.push_scaled(t, if y.len() == scaled.len() { &scaled } else { y }, u);
            self.scaled = scaled;
            return ev;
        }
        self.push_scaled(t, y, u)
    }

    /// [`push`](Self::push) of outputs already in the metric's units.
    #[inline(always)]
    fn push_scaled(&mut self, t: f64, y: &[f64], u: &[f64]) -> Result<Evidence, CertifyError> {
        if self.order_n.is_some() {
            return self.push_order_n(t, y, u);
        }
        let previous = self.regression.last_time();
        if let Err(e) = self.regression.push(t, y, u) {
            return self.refused(e.into(), t);
        }
        let (dt, gap) = self.step_gap(previous, t);
        if gap.is_some() {
            // Start a new window at this sample; the calibrated windows follow the
            // regression's reset through its column count.
            self.regression.reset();
            self.regression.push(t, y, u)?;
        }
        self.samples += 1;
        let scale = self.gap.residual_scale(dt);
        let (ready, columns, blocked, fused) = self.evaluate(scale);
        // The p = 1 step's snapshot was taken as the residual went in (see `evaluate`).
        let amb = if fused.is_some() { fused } else { self.ambiguity_snapshot() };
        let cert_gauss = ready.map(|r| certificate_value(r.beta_hat, r.rho, 0.0));
        let (rho_wass, cert_wass) = match (ready, amb) {
            (Some(r), Some(a)) => (
                Some(r.rho * (1.0 + 2.0 * a.eps)),
                Some(certificate_value(r.beta_hat, r.rho, a.eps)),
            ),
            _ => (None, None),
        };
        let gauss_gate = self.gauss.update(t, cert_gauss);
        let wass_gate = self.wass.update(t, cert_wass);
        let ((mut calibrated, calibrated_window, calibrated_horizon, calibrated_order), nl) =
            self.calibrated_step(t, y, u);
        let (nonlinear_gate, mut nonlinear_reason, nl_best) = nl;
        let mut reason = closed_reason(blocked, cert_gauss, &gauss_gate, &self.gauss);
        let mut wass_reason = if amb.is_none() {
            Some(NotCertified::NoAmbiguityModel)
        } else {
            closed_reason(blocked, cert_wass, &wass_gate, &self.wass)
        };
        if let Some(g) = gap {
            let reasons =
                [&mut reason, &mut wass_reason, &mut calibrated.reason, &mut nonlinear_reason];
            self.gap_reasons(g, amb.is_some(), reasons);
        }
        Ok(Evidence {
            t,
            columns,
            fit: ready.map(|r| Fit {
                beta_hat: r.beta_hat,
                rms_residual: r.rms,
                gram_lambda_min: r.lambda_min,
            }),
            ambiguity: amb,
            gaussian: Verdict {
                value: cert_gauss,
                radius: ready.map(|r| r.rho),
                open: gauss_gate.open,
                reason,
            },
            wasserstein: Verdict {
                value: cert_wass,
                radius: rho_wass,
                open: wass_gate.open,
                reason: wass_reason,
            },
            calibrated,
            calibrated_window,
            calibrated_horizon,
            calibrated_order,
            nonlinear: Verdict {
                value: nl_best.map(|b| b.value),
                radius: nl_best.map(|b| b.radius),
                open: nonlinear_gate.open,
                reason: nonlinear_reason,
            },
            nonlinear_window: nl_best.map(|b| b.window),
            nonlinear_region: nl_best.map(|b| b.region),
        })
    }

    /// `(ε, κ_e, ŝ)`, each the largest over outputs; `None` without an ambiguity model.
    #[inline]
    fn ambiguity_snapshot(&self) -> Option<AmbiguityLevel> {
        let (first, rest) = self.ambiguity.split_first()?;
        let s = first.snapshot();
        let (mut eps, mut kurtosis, mut spikes) = (s.eps, s.kurtosis, s.spike_fraction);
        for a in rest {
            let s = a.snapshot();
            eps = eps.max(s.eps);
            kurtosis = match (kurtosis, s.kurtosis) {
                (Some(x), Some(y)) => Some(x.max(y)),
                (x, y) => x.or(y),
            };
            spikes = spikes.max(s.spike_fraction);
        }
        Some(AmbiguityLevel { eps, kurtosis, spike_fraction: spikes })
    }

    /// Solve the regression, form `β̂` and `ρ`, and feed the residuals to the ambiguity
    /// estimators; when not ready, say why.
    /// `scale` multiplies the one-step residual (see the gap module: `√(Δt_ref/Δt)`).
    /// Inlined into `push`: out of line, its result came back through memory and `push` read
    /// two of its fields with one load, which is not forwarded from two stores (about 2 ns
    /// of the `p = 1` step, `examples/step_profile`).
    #[inline(always)]
    fn evaluate(&mut self, scale: f64) -> Evaluated {
        if self.calibrated_only {
            return (None, self.regression.columns(), None, None);
        }
        // Literal dimensions for the paper's p = m = 1 let the compiler unroll the kernels.
        let reg = &self.cfg.regression;
        if reg.order.fast_path(reg.outputs, reg.inputs) == FastPath::Scalar {
            self.evaluate_dims(1, 1, scale)
        } else {
            self.evaluate_dims(self.cfg.regression.outputs, self.cfg.regression.inputs, scale)
        }
    }

    /// [`evaluate`](Self::evaluate) with the configured dimensions passed in.
    #[inline(always)]
    fn evaluate_dims(&mut self, p: usize, m: usize, scale: f64) -> Evaluated {
        let order = self.cfg.regression.order;
        let residual_source = self.cfg.residuals;
        // From p = 10 the regression forms sym Ĵ_cl itself, after its solve, so the two
        // eigenvalue problems run side by side (the same numbers as one after the other).
        // Below, the plain estimate: routing p = 1 through the callback cost its step about
        // 15 ns (criterion, `certifier_step/`), the inlining lost.
        let (est, wide_top) = if p >= 10 {
            let (gain, jcl) = (&self.gain[..m * p], &mut self.jcl[..p * p]);
            let (sym, eig_work) = (&mut self.work[..p * p], &mut self.eig_work[..]);
            self.regression.estimate_and_sym_max(sym, p, eig_work, |theta, sym| {
                form_sym_jcl(theta, gain, jcl, sym, p, m);
            })
        } else {
            (self.regression.estimate(), f64::NAN)
        };
        let columns = est.columns;
        let blocked = match est.status {
            EstimateStatus::Ready => None,
            EstimateStatus::WarmingUp { columns, needed } => {
                Some(NotCertified::WarmingUp { columns, needed })
            }
            EstimateStatus::InsufficientExcitation { .. } => {
                Some(NotCertified::InsufficientExcitation)
            }
            EstimateStatus::WeakInstruments { .. } => Some(NotCertified::WeakInstruments),
        };
        if blocked.is_some() {
            return (None, columns, blocked, None);
        }
        let (rms, lambda_min) = (est.rms_residual, est.gram_lambda_min);
        if p < 10 {
            let (gain, jcl) = (&self.gain[..m * p], &mut self.jcl[..p * p]);
            form_sym_jcl(est.theta, gain, jcl, &mut self.work[..p * p], p, m);
        }
        // Residuals for ε: ΔY − Θ̂ Z of the newest interval or column.
        let mut fused = None;
        let scalar_theta =
            (order.fast_path(p, m) == FastPath::Scalar).then(|| [est.theta[0], est.theta[1]]);
        let intercept = est.intercept.first().copied();
        if let ([amb], ResidualSource::OneStep, Some(th), Some((z1, dy1))) = (
            &mut self.ambiguity[..],
            residual_source,
            scalar_theta,
            self.regression.newest_interval(),
        ) {
            // p = m = 1 with the default residual, written out: going through `residual` and
            // the `resid` buffer costs about 10 % of the whole step (measured A/B with
            // criterion), and this is the paper's case.
            // The snapshot is taken at once, from the sums in registers (`ε` ends the step's
            // longest chain of dependent operations).
            let mut r = dy1[0] - (th[0] * z1[0] + th[1] * z1[1]);
            if let (Some(c), Some(tau)) = (intercept, self.regression.newest_interval_span()) {
                // The affine model's intercept over the same interval.
                r -= c * tau;
            }
            let r = r * scale;
            fused = amb.push_and_snapshot(r).ok().map(|s| AmbiguityLevel {
                eps: s.eps,
                kurtosis: s.kurtosis,
                spike_fraction: s.spike_fraction,
            });
        } else if !self.ambiguity.is_empty()
            && self.regression.residual(residual_source, &mut self.resid)
        {
            // The interval normalisation applies to the one-step residual only.
            let scale = if residual_source == ResidualSource::OneStep { scale } else { 1.0 };
            for (amb, &r) in self.ambiguity.iter_mut().zip(&self.resid[..p]) {
                let r = r * scale;
                // A non-finite residual is not absorbed (AmbiguityError::NonFinite).
                let _ = amb.push(r);
            }
        }
        let beta_hat = if p >= 10 {
            -wide_top
        } else {
            first_order::rate_of_upper(&self.work, p, &mut self.eig_work)
        };
        let rho = self.cfg.conservatism * (1.0 + self.gain_norm) * rms
            / (lambda_min + self.cfg.regression.ridge).sqrt();
        if !(beta_hat.is_finite() && rho.is_finite()) {
            return (None, columns, Some(NotCertified::InsufficientExcitation), fused);
        }
        (Some(Ready { beta_hat, rho, rms, lambda_min }), columns, None, fused)
    }
}
