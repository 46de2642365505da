//! The equi-energy sampler (Kou, Zhou & Wong 2006; thesis §5.3.6).
//!
//! After burn-in, every chain `c_j` (`j ≥ 2`) stores each of its samples in
//! the ring set `D_{c_j,i}` of its ring `i`; the rings of chain `j` are
//! defined with `π_{j−1}`, the density of the chain that will receive its
//! samples (the thesis's tweak, Fig. 5.10). Once every ring set of `c_j`
//! holds a sample, chain `c_{j−1}` replaces its mutation with probability
//! `p_EEJ` by an *equi-energy jump*: it draws `v` uniformly from the ring set
//! of its own state's ring and accepts with
//! `min(1, π_{j−1}(v) π_j(u) / (π_{j−1}(u) π_j(v)))`. Jumps go between
//! neighbours only (footnote 4). The sampler is not a Markov chain (it uses
//! the past); it is included because the thesis compares it, and its
//! adaptive variant ([`super::AdaptiveEquiEnergy`]) has a convergence proof.

use super::context::{ExchangeContext, swap_log_acceptance};
use super::family::ReplicaFamily;
use super::rings::{EnergyRings, RingRange};
use super::{ExchangeMove, Jump, Schedule};
use crate::error::{Result, invalid};
use crate::mh::accept;
use crate::rng::{ChainRng, uniform};
use crate::sample::Sample;

/// A stored past state with its densities at its own level and the level
/// below (the receiving chain).
#[derive(Clone, Debug)]
pub(crate) struct Stored<S> {
    pub(crate) state: S,
    /// `ln π_j(v)` (the storing chain's level).
    pub(crate) log_own: f64,
    /// `ln π_{j−1}(v)` (the receiving chain's level).
    pub(crate) log_lower: f64,
}

/// Draws and evaluates an equi-energy jump of level `level` to stored state
/// `v` of level `level + 1`.
pub(crate) fn jump_to<S: Clone, P: Clone>(
    level: usize,
    current: &Sample<S, P>,
    v: &Stored<S>,
    family: &(dyn ReplicaFamily<S, Payload = P> + Sync),
    rng: &mut ChainRng,
) -> Jump<S, P> {
    let partner = level + 1;
    let log_alpha = swap_log_acceptance(
        current.log_density,
        v.log_own,
        v.log_lower,
        family.log_density_of(partner, current),
    );
    if !accept(log_alpha, rng) {
        return Jump::Rejected {
            partner,
            alpha: log_alpha.exp(),
        };
    }
    let e = family.evaluate(level, &v.state);
    Jump::Accepted {
        partner,
        alpha: log_alpha.exp(),
        sample: Sample {
            state: v.state.clone(),
            log_density: e.log_density,
            payload: e.payload,
        },
    }
}

pub(crate) fn validate(levels: usize, rings: usize, p_jump: f64) -> Result<()> {
    if levels == 0 || rings == 0 {
        return Err(invalid("rings", "need at least one level and one ring"));
    }
    if !(0.0..=1.0).contains(&p_jump) {
        return Err(invalid(
            "p_eej",
            format!("must lie in [0, 1], got {p_jump}"),
        ));
    }
    Ok(())
}

/// The equi-energy sampler with fixed (log-spaced) rings per chain.
#[derive(Clone, Debug)]
pub struct EquiEnergySampler<S> {
    p_jump: f64,
    /// `rings[j]`: the rings of chain `j` (on `ln π_{j−1}`); `rings[0]` unused.
    rings: Vec<EnergyRings>,
    /// `stores[j][i]`: chain `j`'s past states in ring `i`.
    stores: Vec<Vec<Vec<Stored<S>>>>,
    frozen: bool,
}

impl<S> EquiEnergySampler<S> {
    /// The sampler for `levels` levels with `rings` rings per chain over
    /// `range` (of `ln π_{j−1}` for chain `j`) and jump probability `p_eej`
    /// (the thesis recommends 0.1).
    pub fn new(levels: usize, rings: usize, p_eej: f64, range: RingRange) -> Result<Self> {
        validate(levels, rings, p_eej)?;
        let r = EnergyRings::new(rings, range)?;
        Ok(EquiEnergySampler {
            p_jump: p_eej,
            rings: vec![r; levels],
            stores: (0..levels)
                .map(|_| (0..rings).map(|_| Vec::new()).collect())
                .collect(),
            frozen: false,
        })
    }

    /// Number of stored states of every chain.
    pub fn stored_states(&self) -> usize {
        self.stores.iter().flatten().map(Vec::len).sum()
    }

    fn ready(&self, level: usize) -> bool {
        self.stores
            .get(level)
            .is_some_and(|s| s.iter().all(|ring| !ring.is_empty()))
    }
}

impl<S: Clone + Send + Sync, P: Clone> ExchangeMove<S, P> for EquiEnergySampler<S> {
    fn name(&self) -> String {
        "ees".into()
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
        if !self.frozen || !self.ready(partner) || uniform(rng) >= self.p_jump {
            return Jump::None;
        }
        let ring = self.rings[partner].ring(current.log_density);
        let set = &self.stores[partner][ring];
        let v = &set[((uniform(rng) * set.len() as f64) as usize).min(set.len() - 1)];
        jump_to(level, current, v, family, rng)
    }

    fn end_sweep(&mut self, cx: &mut ExchangeContext<'_, S, P>) {
        for j in 1..cx.levels().min(self.rings.len()) {
            let lower = cx.log_density(j - 1, j);
            if !self.frozen {
                self.rings[j].observe(lower);
                continue;
            }
            let ring = self.rings[j].ring(lower);
            let s = cx.sample(j);
            self.stores[j][ring].push(Stored {
                state: s.state.clone(),
                log_own: s.log_density,
                log_lower: lower,
            });
        }
    }

    fn freeze(&mut self) {
        self.frozen = true;
        self.rings.iter_mut().for_each(EnergyRings::freeze);
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
            .flatten()
            .map(|r| r.capacity() * std::mem::size_of::<Stored<S>>())
            .sum()
    }
}
