//! The adaptive equi-energy sampler (Schreck, Fort & Moulines 2013; thesis
//! §5.3.6): as [`super::EquiEnergySampler`], but chain `j`'s rings are the
//! `d` quantile groups of all its stored states ranked by `ln π_{j−1}`, so
//! every ring holds the same number of states. The stores are kept sorted,
//! so a ring is a contiguous index range and finding it is a binary search.
//!
//! Memory is capped: once a chain has stored `cap` states, each new state
//! replaces a uniformly chosen stored one with probability `cap / seen`
//! (reservoir sampling), so the store stays a uniform sample of the chain's
//! history. [`ExchangeMove::memory_bytes`] reports the bytes held.

use super::context::ExchangeContext;
use super::equi_energy_sampler::{Stored, jump_to, validate};
use super::family::ReplicaFamily;
use super::{ExchangeMove, Jump, Schedule};
use crate::error::{Result, invalid};
use crate::rng::{ChainRng, uniform};
use crate::sample::Sample;

/// The adaptive equi-energy sampler with quantile rings and a capped store.
#[derive(Clone, Debug)]
pub struct AdaptiveEquiEnergy<S> {
    p_jump: f64,
    rings: usize,
    cap: usize,
    /// `stores[j]`: chain `j`'s stored states sorted by `ln π_{j−1}`.
    stores: Vec<Vec<Stored<S>>>,
    seen: Vec<u64>,
    frozen: bool,
}

/// Index range `[lo, hi)` of quantile ring `i` among `n` sorted states in
/// `d` rings: the positions `k` with `⌊k·d/n⌋ = i`.
pub(crate) fn quantile_ring(n: usize, d: usize, i: usize) -> (usize, usize) {
    let lo = (i * n).div_ceil(d);
    let hi = ((i + 1) * n).div_ceil(d);
    (lo, hi)
}

impl<S> AdaptiveEquiEnergy<S> {
    /// The sampler for `levels` levels with `rings` quantile rings (the
    /// thesis uses 16), jump probability `p_eej` (0.1) and at most `cap`
    /// stored states per chain (`cap ≥ rings`).
    pub fn new(levels: usize, rings: usize, p_eej: f64, cap: usize) -> Result<Self> {
        validate(levels, rings, p_eej)?;
        if cap < rings {
            return Err(invalid(
                "cap",
                format!("the store must hold at least one state per ring ({rings}), got {cap}"),
            ));
        }
        Ok(AdaptiveEquiEnergy {
            p_jump: p_eej,
            rings,
            cap,
            stores: (0..levels).map(|_| Vec::new()).collect(),
            seen: vec![0; levels],
            frozen: false,
        })
    }

    /// Number of stored states of every chain.
    pub fn stored_states(&self) -> usize {
        self.stores.iter().map(Vec::len).sum()
    }

    /// The cap per chain.
    pub fn cap(&self) -> usize {
        self.cap
    }
}

impl<S: Clone + Send + Sync, P: Clone> ExchangeMove<S, P> for AdaptiveEquiEnergy<S> {
    fn name(&self) -> String {
        "adaptive-ees".into()
    }

    fn schedule(&self) -> Schedule {
        Schedule::AfterAllMutations
    }

    fn exchange(&mut self, _level: Option<usize>, _cx: &mut ExchangeContext<'_, S, P>) {}

    fn jump(
        &self,
        level: usize,
        current: &Sample<S, P>,
        family: &(dyn ReplicaFamily<S, Payload = P> + Sync),
        rng: &mut ChainRng,
    ) -> Jump<S, P> {
        let partner = level + 1;
        let Some(store) = self.stores.get(partner) else {
            return Jump::None;
        };
        let n = store.len();
        if !self.frozen || n < self.rings || uniform(rng) >= self.p_jump {
            return Jump::None;
        }
        // The ring of u: the quantile group its rank among the stored
        // energies falls into.
        let rank = store
            .partition_point(|s| s.log_lower <= current.log_density)
            .min(n - 1);
        let ring = rank * self.rings / n;
        let (lo, hi) = quantile_ring(n, self.rings, ring);
        let k = lo + ((uniform(rng) * (hi - lo) as f64) as usize).min(hi - lo - 1);
        jump_to(level, current, &store[k], family, rng)
    }

    fn end_sweep(&mut self, cx: &mut ExchangeContext<'_, S, P>) {
        if !self.frozen {
            return;
        }
        for j in 1..cx.levels().min(self.stores.len()) {
            let lower = cx.log_density(j - 1, j);
            if lower.is_nan() {
                continue;
            }
            self.seen[j] += 1;
            if self.stores[j].len() >= self.cap {
                // Reservoir sampling: keep a uniform sample of the history.
                let r = (uniform(cx.rng()) * self.seen[j] as f64) as u64;
                if r >= self.cap as u64 {
                    continue;
                }
                self.stores[j].remove(r as usize);
            }
            let s = cx.sample(j);
            let stored = Stored {
                state: s.state.clone(),
                log_own: s.log_density,
                log_lower: lower,
            };
            let at = self.stores[j].partition_point(|x| x.log_lower <= lower);
            self.stores[j].insert(at, stored);
        }
    }

    fn freeze(&mut self) {
        self.frozen = true;
    }

    fn check_levels(&self, levels: usize) -> Result<()> {
        if levels != self.stores.len() {
            return Err(crate::error::invalid(
                "exchange move",
                format!("built for {} levels, used with {levels}", self.stores.len()),
            ));
        }
        Ok(())
    }

    fn memory_bytes(&self) -> usize {
        self.stores
            .iter()
            .map(|r| r.capacity() * std::mem::size_of::<Stored<S>>())
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::quantile_ring;

    #[test]
    fn quantile_rings_partition_the_store() {
        for n in 16..60 {
            let d = 16;
            let mut next = 0;
            for i in 0..d {
                let (lo, hi) = quantile_ring(n, d, i);
                assert_eq!(lo, next);
                assert!(hi > lo, "empty ring {i} of {n}");
                for k in lo..hi {
                    assert_eq!(k * d / n, i);
                }
                next = hi;
            }
            assert_eq!(next, n);
        }
    }
}
