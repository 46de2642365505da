//! Frequent equi-energy moves (§5.3.5): before chain `c_j` mutates, find
//! the ring of its state; if other chains' states lie in that ring, pick
//! one uniformly (`1/(n−1)`) and try the Eq. 4.11 swap. The swap keeps the
//! ring's occupancy, so the reverse choice has the same probability
//! (App. 5.B.3).
//!
//! The rings of the move initiated by `c_j` are defined on `ln π_j`, the
//! initiator's own density, with per-level ranges (the thesis's footnote 3;
//! flagged uncertain in our spec). Any ring function fixed per initiator
//! keeps the move exact.

use super::context::ExchangeContext;
use super::rings::{EnergyRings, RingRange};
use super::{ExchangeMove, Schedule};
use crate::error::Result;
use crate::rng::uniform;

/// Chains (other than `initiator`) whose ring equals the initiator's.
pub fn frequent_partners(initiator: usize, rings: &[usize]) -> Vec<usize> {
    (0..rings.len())
        .filter(|&l| l != initiator && rings[l] == rings[initiator])
        .collect()
}

/// Frequent equi-energy moves, one attempt before each chain's mutation.
#[derive(Clone, Debug)]
pub struct FrequentEquiEnergy {
    rings: Vec<EnergyRings>,
    template: EnergyRings,
    ring_of: Vec<usize>,
}

impl FrequentEquiEnergy {
    /// The move with `rings` rings per level over `range` of that level's
    /// `ln π_j`.
    pub fn new(rings: usize, range: RingRange) -> Result<Self> {
        Ok(FrequentEquiEnergy {
            rings: Vec::new(),
            template: EnergyRings::new(rings, range)?,
            ring_of: Vec::new(),
        })
    }

    /// The rings of the move initiated by `level` (after the first sweep).
    pub fn rings(&self, level: usize) -> Option<&EnergyRings> {
        self.rings.get(level)
    }
}

impl<S, P: Clone> ExchangeMove<S, P> for FrequentEquiEnergy {
    fn name(&self) -> String {
        "frequent-eem".into()
    }

    fn schedule(&self) -> Schedule {
        Schedule::BeforeEachMutation
    }

    fn exchange(&mut self, level: Option<usize>, cx: &mut ExchangeContext<'_, S, P>) {
        let Some(j) = level else { return };
        let m = cx.levels();
        if self.rings.len() != m {
            self.rings = vec![self.template.clone(); m];
        }
        cx.stats().move_attempts += 1;
        self.ring_of.clear();
        for k in 0..m {
            let e = cx.log_density(j, k);
            self.rings[j].observe(e);
        }
        for k in 0..m {
            let e = cx.log_density(j, k);
            self.ring_of.push(self.rings[j].ring(e));
        }
        let partners = frequent_partners(j, &self.ring_of);
        if partners.is_empty() {
            return;
        }
        let n = partners.len();
        let l = partners[((uniform(cx.rng()) * n as f64) as usize).min(n - 1)];
        if cx.try_swap(j, l).1 {
            cx.stats().move_changes += 1;
        }
    }

    fn freeze(&mut self) {
        self.template.freeze();
        for r in &mut self.rings {
            r.freeze();
        }
    }
}
