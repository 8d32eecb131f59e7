//! Seeded disturbance processes and schedules (paper Section II-D and Section V-A).
//!
//! A channel's disturbance at step `k` is `η_k = r_k + p(t_k)`: a random draw `r_k` from the
//! [`Process`] whose [`Segment`] contains `t_k`, plus the deterministic [`Periodic`] layer
//! `p(t)`. [`Impulse`]s are separate: each is a jump of the state by `magnitude · E` at its
//! time (the integral of a Dirac pulse of that area), independent of the noise scaling.
//!
//! Experiment 1's three-regime schedule is built from these pieces in the
//! `streamcert-experiments` crate (`regime_schedule`).

use rand::Rng;
use rand_distr::{Distribution, StandardNormal, StudentT};
use serde::{Deserialize, Serialize};

use crate::{DynamicsError, SeededRng, finite, non_negative, positive, seeded_rng};

/// A stationary random process, drawn independently at every step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Process {
    /// Always zero.
    Zero,
    /// Gaussian with mean 0 and standard deviation `sigma`.
    Gaussian {
        /// Standard deviation (`>= 0`).
        sigma: f64,
    },
    /// Laplace with mean 0 and scale `b` (variance `2 b²`, excess kurtosis 3).
    Laplace {
        /// Scale `b` (`>= 0`).
        scale: f64,
    },
    /// Laplace with scale `b` plus, with probability `spike_prob` per step, a spike of
    /// magnitude uniform in `[spike_min, spike_max] · sigma0` and random sign.
    LaplaceSpikes {
        /// Laplace scale `b` (`>= 0`).
        scale: f64,
        /// Spike probability per step, in `[0, 1]`.
        spike_prob: f64,
        /// Smallest spike magnitude in units of `sigma0`.
        spike_min: f64,
        /// Largest spike magnitude in units of `sigma0`.
        spike_max: f64,
        /// Nominal scale `σ0` the spike magnitudes are expressed in.
        sigma0: f64,
    },
    /// Student-t with `dof` degrees of freedom, multiplied by `scale`.
    StudentT {
        /// Degrees of freedom (`> 0`).
        dof: f64,
        /// Multiplier (`>= 0`).
        scale: f64,
    },
}

impl Process {
    fn validate(&self) -> Result<(), DynamicsError> {
        match *self {
            Self::Zero => {}
            Self::Gaussian { sigma } => {
                non_negative("sigma", sigma)?;
            }
            Self::Laplace { scale } => {
                non_negative("scale", scale)?;
            }
            Self::LaplaceSpikes { scale, spike_prob, spike_min, spike_max, sigma0 } => {
                non_negative("scale", scale)?;
                finite("spike_prob", spike_prob)?;
                if !(0.0..=1.0).contains(&spike_prob) {
                    return Err(DynamicsError::InvalidProbability {
                        name: "spike_prob",
                        value: spike_prob,
                    });
                }
                non_negative("spike_min", spike_min)?;
                non_negative("spike_max", spike_max)?;
                if spike_min > spike_max {
                    return Err(DynamicsError::InvalidRange {
                        name: "spike magnitude",
                        low: spike_min,
                        high: spike_max,
                    });
                }
                non_negative("sigma0", sigma0)?;
            }
            Self::StudentT { dof, scale } => {
                positive("dof", dof)?;
                non_negative("scale", scale)?;
            }
        }
        Ok(())
    }

    /// Draw one value.
    fn draw(&self, rng: &mut SeededRng) -> f64 {
        match *self {
            Self::Zero => 0.0,
            Self::Gaussian { sigma } => {
                let z: f64 = StandardNormal.sample(rng);
                sigma * z
            }
            Self::Laplace { scale } => scale * standard_laplace(rng),
            Self::LaplaceSpikes { scale, spike_prob, spike_min, spike_max, sigma0 } => {
                let base = scale * standard_laplace(rng);
                // Always consume the same number of uniforms so the stream stays aligned.
                let hit: f64 = rng.random();
                let mag: f64 = rng.random();
                let sign: bool = rng.random();
                if hit < spike_prob {
                    let m = (spike_min + (spike_max - spike_min) * mag) * sigma0;
                    base + if sign { m } else { -m }
                } else {
                    base
                }
            }
            Self::StudentT { dof, scale } => {
                // Validated dof > 0, so construction cannot fail.
                let t = StudentT::new(dof).map_or(0.0, |d| d.sample(rng));
                scale * t
            }
        }
    }

    /// Theoretical variance of one draw (`∞` for Student-t with `dof <= 2`).
    #[must_use]
    pub fn variance(&self) -> f64 {
        match *self {
            Self::Zero => 0.0,
            Self::Gaussian { sigma } => sigma * sigma,
            Self::Laplace { scale } => 2.0 * scale * scale,
            Self::LaplaceSpikes { scale, spike_prob, spike_min, spike_max, sigma0 } => {
                // E[m²] for m uniform on [lo, hi]: (lo² + lo hi + hi²) / 3.
                let (lo, hi) = (spike_min * sigma0, spike_max * sigma0);
                2.0 * scale * scale + spike_prob * (lo * lo + lo * hi + hi * hi) / 3.0
            }
            Self::StudentT { dof, scale } => {
                if dof > 2.0 {
                    scale * scale * dof / (dof - 2.0)
                } else {
                    f64::INFINITY
                }
            }
        }
    }
}

/// Standard Laplace draw (scale 1) by inversion: `−sgn(v) ln(1 − 2|v|)`, `v ∈ (−½, ½)`.
fn standard_laplace(rng: &mut SeededRng) -> f64 {
    // u in (0, 1): random::<f64>() is in [0, 1); reject the single value 0.
    let mut u: f64 = rng.random();
    while u == 0.0 {
        u = rng.random();
    }
    let v = u - 0.5;
    -v.signum() * (1.0 - 2.0 * v.abs()).ln()
}

/// A process active on the half-open time interval `[start, end)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Segment {
    /// Start time (inclusive).
    pub start: f64,
    /// End time (exclusive); may be `f64::INFINITY`.
    pub end: f64,
    /// The process drawn on this interval.
    pub process: Process,
}

/// One term `amplitude · sin(2π t / period + phase)` of a periodic layer.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PeriodicTerm {
    /// Amplitude.
    pub amplitude: f64,
    /// Period in seconds (`> 0`).
    pub period: f64,
    /// Phase in radians.
    pub phase: f64,
}

/// A deterministic sum of sinusoids added to the disturbance (paper Section V-A).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Periodic {
    /// The terms; empty means no periodic layer.
    pub terms: Vec<PeriodicTerm>,
}

impl Periodic {
    /// The paper's layer `0.10 sin(2πt/10) + 0.05 sin(2πt/5 + 0.7)`.
    #[must_use]
    pub fn paper() -> Self {
        Self {
            terms: vec![
                PeriodicTerm { amplitude: 0.10, period: 10.0, phase: 0.0 },
                PeriodicTerm { amplitude: 0.05, period: 5.0, phase: 0.7 },
            ],
        }
    }

    /// `p(t) = Σ aᵢ sin(2π t / Tᵢ + φᵢ)`.
    #[must_use]
    pub fn value(&self, t: f64) -> f64 {
        self.terms
            .iter()
            .map(|k| k.amplitude * (std::f64::consts::TAU * t / k.period + k.phase).sin())
            .sum()
    }
}

/// A state jump of `magnitude` along the channel's column of `E` at time `time`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Impulse {
    /// When the impulse acts (it is applied in the step `[t_k, t_k + dt)` containing it).
    pub time: f64,
    /// Its area (the size of the state jump).
    pub magnitude: f64,
}

/// Full description of one disturbance channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DisturbanceConfig {
    /// Sorted, disjoint segments; outside every segment the random part is zero.
    pub segments: Vec<Segment>,
    /// Deterministic periodic layer.
    #[serde(default)]
    pub periodic: Periodic,
    /// Impulses.
    #[serde(default)]
    pub impulses: Vec<Impulse>,
}

impl DisturbanceConfig {
    /// One process on `[0, ∞)`, no periodic layer, no impulse.
    #[must_use]
    pub fn stationary(process: Process) -> Self {
        Self {
            segments: vec![Segment { start: 0.0, end: f64::INFINITY, process }],
            periodic: Periodic::default(),
            impulses: Vec::new(),
        }
    }

    /// No disturbance at all.
    #[must_use]
    pub fn none() -> Self {
        Self::stationary(Process::Zero)
    }

    /// Validate: at least one segment, each non-empty with finite start, sorted and disjoint;
    /// every process parameter valid; periods positive; impulses finite.
    ///
    /// # Errors
    /// [`DynamicsError::EmptySchedule`], [`DynamicsError::EmptySegment`],
    /// [`DynamicsError::OverlappingSegments`], or the process parameter error.
    pub fn validate(&self) -> Result<(), DynamicsError> {
        if self.segments.is_empty() {
            return Err(DynamicsError::EmptySchedule);
        }
        let mut previous_end = f64::NEG_INFINITY;
        for (index, s) in self.segments.iter().enumerate() {
            finite("segment start", s.start)?;
            if s.end.is_nan() {
                return Err(DynamicsError::NonFinite { name: "segment end", value: s.end });
            }
            if s.start >= s.end {
                return Err(DynamicsError::EmptySegment { index, start: s.start, end: s.end });
            }
            if s.start < previous_end {
                return Err(DynamicsError::OverlappingSegments {
                    index,
                    start: s.start,
                    previous_end,
                });
            }
            previous_end = s.end;
            s.process.validate()?;
        }
        for k in &self.periodic.terms {
            finite("periodic amplitude", k.amplitude)?;
            positive("periodic period", k.period)?;
            finite("periodic phase", k.phase)?;
        }
        for i in &self.impulses {
            finite("impulse time", i.time)?;
            finite("impulse magnitude", i.magnitude)?;
        }
        Ok(())
    }
}

/// A seeded disturbance channel: a validated [`DisturbanceConfig`] and its generator.
#[derive(Debug, Clone)]
pub struct Disturbance {
    cfg: DisturbanceConfig,
    rng: SeededRng,
    cursor: usize,
}

impl Disturbance {
    /// Validate the configuration and seed the generator.
    ///
    /// # Errors
    /// See [`DisturbanceConfig::validate`].
    ///
    /// ```
    /// use streamcert_dynamics::{Disturbance, DisturbanceConfig, DynamicsError, Process};
    /// let mut d = Disturbance::new(DisturbanceConfig::stationary(Process::Laplace { scale: 0.5 }), 42)?;
    /// let _eta = d.random(0.0);
    /// let bad = DisturbanceConfig::stationary(Process::Gaussian { sigma: -1.0 });
    /// assert!(matches!(Disturbance::new(bad, 42), Err(DynamicsError::Negative { .. })));
    /// # Ok::<(), DynamicsError>(())
    /// ```
    pub fn new(cfg: DisturbanceConfig, seed: u64) -> Result<Self, DynamicsError> {
        cfg.validate()?;
        Ok(Self { cfg, rng: seeded_rng(seed), cursor: 0 })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &DisturbanceConfig {
        &self.cfg
    }

    /// The process active at time `t` ([`Process::Zero`] outside every segment).
    #[must_use]
    pub fn process_at(&self, t: f64) -> Process {
        self.cfg
            .segments
            .iter()
            .find(|s| s.start <= t && t < s.end)
            .map_or(Process::Zero, |s| s.process)
    }

    /// Draw the random part `r_k` at time `t` (one draw per call; call once per step with
    /// non-decreasing `t` for the amortised O(1) segment lookup).
    pub fn random(&mut self, t: f64) -> f64 {
        let segs = &self.cfg.segments;
        if self.cursor >= segs.len() || t < segs[self.cursor].start {
            self.cursor = 0;
        }
        while self.cursor < segs.len() && segs[self.cursor].end <= t {
            self.cursor += 1;
        }
        match segs.get(self.cursor) {
            Some(s) if s.start <= t => s.process.draw(&mut self.rng),
            _ => 0.0,
        }
    }

    /// The deterministic periodic layer `p(t)`.
    #[must_use]
    pub fn periodic(&self, t: f64) -> f64 {
        self.cfg.periodic.value(t)
    }

    /// Sum of the impulse magnitudes with time in `[t0, t1)`.
    #[must_use]
    pub fn impulses_in(&self, t0: f64, t1: f64) -> f64 {
        self.cfg.impulses.iter().filter(|i| t0 <= i.time && i.time < t1).map(|i| i.magnitude).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedule_switches_processes_at_the_given_times() {
        let spikes = Process::LaplaceSpikes {
            scale: 0.3,
            spike_prob: 0.1,
            spike_min: 4.0,
            spike_max: 6.0,
            sigma0: 0.1,
        };
        let cfg = DisturbanceConfig {
            segments: [Process::Gaussian { sigma: 0.1 }, Process::Laplace { scale: 0.5 }, spikes]
                .into_iter()
                .enumerate()
                .map(|(i, process)| Segment {
                    start: 10.0 * i as f64,
                    end: 10.0 * (i + 1) as f64,
                    process,
                })
                .collect(),
            periodic: Periodic::paper(),
            impulses: Vec::new(),
        };
        let d = Disturbance::new(cfg, 0).unwrap();
        assert!(matches!(d.process_at(0.0), Process::Gaussian { .. }));
        assert!(matches!(d.process_at(9.999), Process::Gaussian { .. }));
        assert!(matches!(d.process_at(10.0), Process::Laplace { .. }));
        assert!(matches!(d.process_at(25.0), Process::LaplaceSpikes { .. }));
        assert_eq!(d.process_at(30.0), Process::Zero);
        assert_eq!(d.process_at(-1.0), Process::Zero);
    }

    #[test]
    fn random_part_is_zero_outside_segments_and_impulses_are_counted_once() {
        let cfg = DisturbanceConfig {
            segments: vec![Segment {
                start: 1.0,
                end: 2.0,
                process: Process::Gaussian { sigma: 1.0 },
            }],
            periodic: Periodic::paper(),
            impulses: vec![Impulse { time: 3.0, magnitude: 2.5 }],
        };
        let mut d = Disturbance::new(cfg, 1).unwrap();
        let xs: Vec<f64> = (0..300).map(|k| d.random(k as f64 * 0.01)).collect();
        assert!(xs[..100].iter().all(|v| *v == 0.0));
        assert!(xs[100..200].iter().all(|v| *v != 0.0));
        assert!(xs[200..].iter().all(|v| *v == 0.0));
        let total: f64 =
            (0..500).map(|k| d.impulses_in(k as f64 * 0.01, (k + 1) as f64 * 0.01)).sum();
        assert_eq!(total, 2.5);
        assert!(
            (d.periodic(2.5)
                - (0.10 * (std::f64::consts::TAU * 0.25).sin()
                    + 0.05 * (std::f64::consts::TAU * 0.5 + 0.7).sin()))
            .abs()
                < 1e-15
        );
    }
}
