//! The original equi-energy move (§5.3.4, Baragatti et al. 2012): after all
//! chains mutated, pick uniformly one ring holding the current states of at
//! least two chains, pick two of those chains uniformly, and try to swap
//! them with Eq. 4.11.
//!
//! Rings are defined on `ln π_1` (the untempered target) so that a state's
//! ring does not depend on which chain holds it: a swap leaves every ring's
//! occupancy unchanged, the selection probability is the same forward and
//! backward, and plain Eq. 4.11 acceptance is exact.

use super::context::ExchangeContext;
use super::rings::{EnergyRings, RingRange};
use super::{ExchangeMove, Schedule};
use crate::error::Result;
use crate::rng::uniform;

/// Every unordered pair `(a, b)` of chains the move may pick, with its
/// selection probability, given each chain's ring: `(1/R) · 2/(n_r(n_r−1))`
/// for a pair in ring `r` holding `n_r ≥ 2` chains, `R` such rings.
pub fn equi_energy_pair_probabilities(rings: &[usize]) -> Vec<(usize, usize, f64)> {
    let groups = eligible_groups(rings);
    let mut out = Vec::new();
    for g in &groups {
        let n = g.len() as f64;
        let p = 1.0 / groups.len() as f64 * 2.0 / (n * (n - 1.0));
        for (x, &a) in g.iter().enumerate() {
            for &b in &g[x + 1..] {
                out.push((a, b, p));
            }
        }
    }
    out
}

/// Chains grouped by ring, keeping only rings with at least two chains, in
/// ring order (chains in level order within a ring).
fn eligible_groups(rings: &[usize]) -> Vec<Vec<usize>> {
    let top = rings.iter().copied().max().unwrap_or(0);
    let mut groups = vec![Vec::new(); top + 1];
    for (chain, &r) in rings.iter().enumerate() {
        groups[r].push(chain);
    }
    groups.retain(|g| g.len() >= 2);
    groups
}

/// The original equi-energy move, once per sweep.
#[derive(Clone, Debug)]
pub struct EquiEnergyMove {
    rings: EnergyRings,
    ring_of: Vec<usize>,
}

impl EquiEnergyMove {
    /// The move with `rings` rings over `range` of `ln π_1` (the thesis uses
    /// `d = 8` log-spaced levels; `d ≈ M` worked best).
    pub fn new(rings: usize, range: RingRange) -> Result<Self> {
        Ok(EquiEnergyMove {
            rings: EnergyRings::new(rings, range)?,
            ring_of: Vec::new(),
        })
    }

    /// The rings.
    pub fn rings(&self) -> &EnergyRings {
        &self.rings
    }
}

impl<S, P: Clone> ExchangeMove<S, P> for EquiEnergyMove {
    fn name(&self) -> String {
        "eem".into()
    }

    fn schedule(&self) -> Schedule {
        Schedule::AfterAllMutations
    }

    fn exchange(&mut self, _level: Option<usize>, cx: &mut ExchangeContext<'_, S, P>) {
        let m = cx.levels();
        cx.stats().move_attempts += 1;
        self.ring_of.clear();
        for k in 0..m {
            let e = cx.log_density(0, k);
            self.rings.observe(e);
        }
        for k in 0..m {
            let e = cx.log_density(0, k);
            self.ring_of.push(self.rings.ring(e));
        }
        let groups = eligible_groups(&self.ring_of);
        if groups.is_empty() {
            return;
        }
        let g = &groups[((uniform(cx.rng()) * groups.len() as f64) as usize).min(groups.len() - 1)];
        let n = g.len();
        let a = ((uniform(cx.rng()) * n as f64) as usize).min(n - 1);
        let mut b = ((uniform(cx.rng()) * (n - 1) as f64) as usize).min(n - 2);
        if b >= a {
            b += 1;
        }
        if cx.try_swap(g[a], g[b]).1 {
            cx.stats().move_changes += 1;
        }
    }

    fn freeze(&mut self) {
        self.rings.freeze();
    }
}
