//! Energy rings for the equi-energy moves (Eq. 5.12): `D_i = {x : π(x) ∈
//! [H_i, H_{i+1})}` with levels evenly spaced in `ln π` ("log-spaced" in
//! `π`). Ring 0 also holds everything below the range (including `π = 0`),
//! the last ring everything above.

use crate::error::{Result, invalid};

/// Where the ring levels lie.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RingRange {
    /// `ln H` from `low` to `high`, fixed.
    Fixed {
        /// Lowest level `ln H_2`.
        low: f64,
        /// Highest level `ln H_d`.
        high: f64,
    },
    /// From the smallest to the largest finite `ln π` observed during
    /// burn-in; frozen afterwards.
    Observed,
}

/// `d` rings over `ln π`.
#[derive(Clone, Debug, PartialEq)]
pub struct EnergyRings {
    rings: usize,
    range: RingRange,
    low: f64,
    high: f64,
    frozen: bool,
}

impl EnergyRings {
    /// `rings ≥ 1` rings over `range`.
    pub fn new(rings: usize, range: RingRange) -> Result<Self> {
        if rings == 0 {
            return Err(invalid("rings", "need at least one ring"));
        }
        let (low, high) = match range {
            RingRange::Fixed { low, high } => {
                if !(low.is_finite() && high.is_finite() && low < high) {
                    return Err(invalid("ring range", "need finite low < high"));
                }
                (low, high)
            }
            RingRange::Observed => (f64::INFINITY, f64::NEG_INFINITY),
        };
        Ok(EnergyRings {
            rings,
            range,
            low,
            high,
            frozen: false,
        })
    }

    /// Number of rings.
    pub fn rings(&self) -> usize {
        self.rings
    }

    /// Current `(ln H_low, ln H_high)`.
    pub fn range(&self) -> (f64, f64) {
        (self.low, self.high)
    }

    /// Widens an observed range with `ln π` (ignored when fixed, frozen or
    /// not finite).
    pub fn observe(&mut self, log_density: f64) {
        if self.range == RingRange::Observed && !self.frozen && log_density.is_finite() {
            self.low = self.low.min(log_density);
            self.high = self.high.max(log_density);
        }
    }

    /// Stops widening.
    pub fn freeze(&mut self) {
        self.frozen = true;
    }

    /// The ring holding a state of log density `log_density`.
    #[inline]
    pub fn ring(&self, log_density: f64) -> usize {
        if self.high.partial_cmp(&self.low) != Some(std::cmp::Ordering::Greater)
            || !log_density.is_finite()
        {
            // Before any range is known, or at π = 0 / an invalid value.
            return if log_density == f64::INFINITY {
                self.rings - 1
            } else {
                0
            };
        }
        let t = (log_density - self.low) / (self.high - self.low) * self.rings as f64;
        if t <= 0.0 {
            0
        } else {
            (t as usize).min(self.rings - 1)
        }
    }
}
