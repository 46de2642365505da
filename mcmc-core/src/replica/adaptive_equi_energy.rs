//! The adaptive equi-energy sampler (Schreck, Fort & Moulines 2013; thesis
//! §5.3.6): as [`super::EquiEnergySampler`], but chain `j`'s rings are the
//! `d` quantile groups of all its stored states ranked by `ln π_{j−1}`, so
//! every ring holds the same number of states. Each store keeps its states
//! in place and a sorted list of `(energy, index)` keys beside them, so a
//! ring is a contiguous range of keys, finding it is a binary search, and an
//! insertion moves 16-byte keys rather than states.
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
    /// `stores[j]`: chain `j`'s stored states.
    stores: Vec<Vec<Stored<S>>>,
    /// `keys[j]`: `(ln π_{j−1}, index into stores[j])`, sorted by energy.
    keys: Vec<Vec<(f64, u32)>>,
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
        if cap > u32::MAX as usize {
            return Err(invalid("cap", "at most 2^32 − 1 stored states per chain"));
        }
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
            keys: (0..levels).map(|_| Vec::new()).collect(),
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
        let (Some(store), Some(keys)) = (self.stores.get(partner), self.keys.get(partner)) else {
            return Jump::None;
        };
        let n = keys.len();
        if !self.frozen || n < self.rings || uniform(rng) >= self.p_jump {
            return Jump::None;
        }
        // The ring of u: the quantile group its rank among the stored
        // energies falls into.
        let rank = keys
            .partition_point(|k| k.0 <= current.log_density)
            .min(n - 1);
        let ring = rank * self.rings / n;
        let (lo, hi) = quantile_ring(n, self.rings, ring);
        let k = keys[lo + ((uniform(rng) * (hi - lo) as f64) as usize).min(hi - lo - 1)].1 as usize;
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
            let replace = if self.stores[j].len() < self.cap {
                None
            } else {
                // Reservoir sampling: keep a uniform sample of the history.
                let r = (uniform(cx.rng()) * self.seen[j] as f64) as u64;
                if r >= self.cap as u64 {
                    continue;
                }
                let r = r as usize;
                let old = self.stores[j][r].log_lower;
                let keys = &mut self.keys[j];
                let from = keys.partition_point(|k| k.0 < old);
                if let Some(p) = keys[from..].iter().position(|k| k.1 as usize == r) {
                    keys.remove(from + p);
                }
                Some(r)
            };
            let s = cx.sample(j);
            let stored = Stored {
                state: s.state.clone(),
                log_own: s.log_density,
                log_lower: lower,
            };
            let slot = match replace {
                None => {
                    self.stores[j].push(stored);
                    self.stores[j].len() - 1
                }
                Some(r) => {
                    self.stores[j][r] = stored;
                    r
                }
            };
            let keys = &mut self.keys[j];
            let at = keys.partition_point(|k| k.0 <= lower);
            keys.insert(at, (lower, slot as u32));
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
        let states: usize = self
            .stores
            .iter()
            .map(|r| r.capacity() * std::mem::size_of::<Stored<S>>())
            .sum();
        let keys: usize = self
            .keys
            .iter()
            .map(|k| k.capacity() * std::mem::size_of::<(f64, u32)>())
            .sum();
        states + keys
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chain::ChainState;
    use crate::replica::context::DensityCache;
    use crate::replica::family::FnFamily;
    use crate::replica::stats::{IndexProcess, ReplicaStatistics};
    use crate::rng::stream_rng;
    use crate::stats::ChainStatistics;

    #[test]
    fn the_capped_store_keeps_sorted_consistent_keys() {
        let family = FnFamily::new(3, |l: usize, x: &f64| -x * x / (1.0 + l as f64));
        let mut aees = AdaptiveEquiEnergy::<f64>::new(3, 4, 0.1, 50).unwrap();
        ExchangeMove::<f64, ()>::freeze(&mut aees);
        let mut rng = stream_rng(1, 0);
        let mut exchange_rng = stream_rng(2, 0);
        let mut index = IndexProcess::new(3);
        let mut stats = ReplicaStatistics::new(3, "adaptive-ees");
        let mut cache = DensityCache::new(3);
        for step in 0..500 {
            let mut chains: Vec<ChainState<f64, ()>> = (0..3)
                .map(|l| {
                    let x = 4.0 * uniform(&mut rng) - 2.0;
                    ChainState {
                        current: Sample {
                            state: x,
                            log_density: family.evaluate(l, &x).log_density,
                            payload: (),
                        },
                        rng: stream_rng(3, l as u64),
                        stats: ChainStatistics::default(),
                    }
                })
                .collect();
            cache.clear();
            let mut cx = ExchangeContext {
                family: &family,
                chains: &mut chains,
                rng: &mut exchange_rng,
                index: &mut index,
                stats: &mut stats,
                cache: &mut cache,
                frozen: true,
            };
            aees.end_sweep(&mut cx);
            for j in 1..3 {
                let (store, keys) = (&aees.stores[j], &aees.keys[j]);
                assert_eq!(store.len(), (step + 1).min(50));
                assert_eq!(keys.len(), store.len());
                assert!(keys.windows(2).all(|w| w[0].0 <= w[1].0), "keys not sorted");
                let mut idx: Vec<u32> = keys.iter().map(|k| k.1).collect();
                idx.sort_unstable();
                assert_eq!(idx, (0..store.len() as u32).collect::<Vec<_>>());
                for k in keys {
                    assert_eq!(k.0, store[k.1 as usize].log_lower);
                    let x = store[k.1 as usize].state;
                    assert_eq!(k.0, -x * x / j as f64, "energy is ln π_(j−1)");
                }
            }
        }
        assert!(ExchangeMove::<f64, ()>::memory_bytes(&aees) > 0);
    }

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
