//! Probing inputs (dither).
//!
//! Under pure output feedback `u = K y` the input integral is `K` times the output integral,
//! so the regressor `Z` of eq. (regressor) has rank `p`, not `p + m`, and `B_obs` is not
//! identifiable. A small dither added to the input breaks the collinearity.

use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::{DynamicsError, SeededRng, non_negative, positive, seeded_rng};

/// Which dither, with its amplitude.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum DitherConfig {
    /// No dither.
    None,
    /// Pseudo-random binary sequence `±amplitude` from a 15-bit maximal-length LFSR
    /// (`x¹⁵ + x¹⁴ + 1`, period 32767 bits), one bit per `hold` seconds.
    Prbs {
        /// Amplitude (`>= 0`).
        amplitude: f64,
        /// Hold time in seconds (`> 0`).
        hold: f64,
    },
    /// Independent Gaussian draws with standard deviation `sigma`, one per call.
    White {
        /// Standard deviation (`>= 0`).
        sigma: f64,
    },
}

/// A seeded dither generator.
#[derive(Debug, Clone)]
pub struct Dither {
    cfg: DitherConfig,
    rng: SeededRng,
    lfsr: u16,
    next_switch: f64,
    level: f64,
}

impl Dither {
    /// Validate and seed.
    ///
    /// # Errors
    /// [`DynamicsError::Negative`] for a negative amplitude, [`DynamicsError::NotPositive`]
    /// for a hold time `<= 0`, [`DynamicsError::NonFinite`] for NaN or infinity.
    ///
    /// ```
    /// use streamcert_dynamics::{Dither, DitherConfig};
    /// let mut d = Dither::new(DitherConfig::Prbs { amplitude: 0.5, hold: 0.1 }, 3)?;
    /// assert_eq!(d.value(0.0).abs(), 0.5);
    /// assert!(Dither::new(DitherConfig::Prbs { amplitude: 0.5, hold: 0.0 }, 3).is_err());
    /// # Ok::<(), streamcert_dynamics::DynamicsError>(())
    /// ```
    pub fn new(cfg: DitherConfig, seed: u64) -> Result<Self, DynamicsError> {
        match cfg {
            DitherConfig::None => {}
            DitherConfig::Prbs { amplitude, hold } => {
                non_negative("dither amplitude", amplitude)?;
                positive("dither hold", hold)?;
            }
            DitherConfig::White { sigma } => {
                non_negative("dither sigma", sigma)?;
            }
        }
        // A non-zero 15-bit LFSR state derived from the seed.
        let lfsr = ((seed ^ (seed >> 15) ^ (seed >> 30) ^ (seed >> 45)) & 0x7fff) as u16;
        let lfsr = if lfsr == 0 { 0x5a5a & 0x7fff } else { lfsr };
        Ok(Self { cfg, rng: seeded_rng(seed), lfsr, next_switch: f64::NEG_INFINITY, level: 0.0 })
    }

    fn lfsr_bit(&mut self) -> bool {
        let bit = ((self.lfsr >> 14) ^ (self.lfsr >> 13)) & 1;
        self.lfsr = ((self.lfsr << 1) | bit) & 0x7fff;
        bit == 1
    }

    /// The dither value at time `t` (call with non-decreasing `t`).
    pub fn value(&mut self, t: f64) -> f64 {
        match self.cfg {
            DitherConfig::None => 0.0,
            DitherConfig::Prbs { amplitude, hold } => {
                if self.next_switch == f64::NEG_INFINITY {
                    self.next_switch = t;
                }
                while t >= self.next_switch {
                    self.level = if self.lfsr_bit() { amplitude } else { -amplitude };
                    self.next_switch += hold;
                }
                self.level
            }
            DitherConfig::White { sigma } => {
                let z: f64 = StandardNormal.sample(&mut self.rng);
                sigma * z
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prbs_is_maximal_length_balanced_and_held() {
        let mut d = Dither::new(DitherConfig::Prbs { amplitude: 1.0, hold: 0.5 }, 11).unwrap();
        let bits: Vec<f64> = (0..2 * 32767).map(|k| d.value(k as f64 * 0.5)).collect();
        // Period 2^15 − 1, and not shorter (maximal length).
        assert!((0..32767).all(|k| bits[k] == bits[k + 32767]));
        assert!(bits[..32767].windows(2).any(|w| w[0] != w[1]));
        for period in [1usize, 3, 7, 127, 4681] {
            assert!((0..32767).any(|k| bits[k] != bits[k + period]), "period {period}");
        }
        // 2^14 ones and 2^14 − 1 zeros per period.
        let ones = bits[..32767].iter().filter(|b| **b > 0.0).count();
        assert_eq!(ones, 16384);
        // Held: constant within a hold interval.
        let mut d = Dither::new(DitherConfig::Prbs { amplitude: 0.3, hold: 0.1 }, 4).unwrap();
        let v: Vec<f64> = (0..100).map(|k| d.value(k as f64 * 0.02)).collect();
        assert!(v.chunks(5).all(|c| c.iter().all(|x| *x == c[0] && x.abs() == 0.3)));
    }

    #[test]
    fn invalid_dither_is_an_error() {
        assert!(matches!(
            Dither::new(DitherConfig::White { sigma: f64::NAN }, 0),
            Err(DynamicsError::NonFinite { .. })
        ));
        assert!(matches!(
            Dither::new(DitherConfig::Prbs { amplitude: -1.0, hold: 1.0 }, 0),
            Err(DynamicsError::Negative { .. })
        ));
    }
}
