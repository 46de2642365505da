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
//!
//! # When jumps start
//!
//! The thesis enables chain `c_{j−1}`'s jumps once *every* ring set of `c_j`
//! holds a sample ([`JumpRule::AllRingsFilled`], the default). With fixed
//! rings taken from the burn-in range that can take forever: a ring that
//! chain `j` rarely visits stays empty, and the chain below never jumps
//! (in the 6-d synthetic study of `docs/replica-exchange.md` the main chain
//! then misses 90% of the modes). Kou, Zhou & Wong (2006) start chain
//! `j − 1` after chain `j` has run and draw from the ring set of the current
//! state's ring; [`JumpRule::CurrentRingFilled`] takes that reading: a jump
//! is attempted whenever that one ring set is non-empty.

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

/// When a chain's equi-energy jumps are enabled (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum JumpRule {
    /// Once every ring set of the partner chain holds a state (the thesis).
    #[default]
    AllRingsFilled,
    /// Whenever the ring set of the current state's ring is non-empty (Kou
    /// et al. 2006).
    CurrentRingFilled,
}

/// The equi-energy sampler with fixed (log-spaced) rings per chain.
#[derive(Clone, Debug)]
pub struct EquiEnergySampler<S> {
    p_jump: f64,
    rule: JumpRule,
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
            rule: JumpRule::default(),
            rings: vec![r; levels],
            stores: (0..levels)
                .map(|_| (0..rings).map(|_| Vec::new()).collect())
                .collect(),
            frozen: false,
        })
    }

    /// The sampler with jumps enabled by `rule` instead of the default
    /// [`JumpRule::AllRingsFilled`].
    pub fn with_jump_rule(mut self, rule: JumpRule) -> Self {
        self.rule = rule;
        self
    }

    /// Number of stored states of every chain.
    pub fn stored_states(&self) -> usize {
        self.stores.iter().flatten().map(Vec::len).sum()
    }

    /// Whether chain `level − 1` may jump into ring `ring` of chain `level`.
    fn ready(&self, level: usize, ring: usize) -> bool {
        self.stores.get(level).is_some_and(|s| match self.rule {
            JumpRule::AllRingsFilled => s.iter().all(|r| !r.is_empty()),
            JumpRule::CurrentRingFilled => s.get(ring).is_some_and(|r| !r.is_empty()),
        })
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
        if !self.frozen || partner >= self.rings.len() {
            return Jump::None;
        }
        let ring = self.rings[partner].ring(current.log_density);
        if !self.ready(partner, ring) || uniform(rng) >= self.p_jump {
            return Jump::None;
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::replica::FnFamily;
    use crate::rng::stream_rng;

    /// Two levels, four fixed rings on `ln π_0 ∈ [−4, 0]`; chain 1 has
    /// stored one state, in ring 3 (the top ring), so rings 0–2 are empty.
    fn sampler_with_top_ring_filled(rule: JumpRule) -> EquiEnergySampler<f64> {
        let range = RingRange::Fixed {
            low: -4.0,
            high: 0.0,
        };
        let mut ees = EquiEnergySampler::new(2, 4, 0.5, range)
            .unwrap()
            .with_jump_rule(rule);
        ExchangeMove::<f64, ()>::freeze(&mut ees);
        ees.stores[1][3].push(Stored {
            state: 0.1,
            log_own: -0.005,
            log_lower: -0.5,
        });
        ees
    }

    /// Counts the jumps attempted from a level-0 state of log density
    /// `log_density` over `n` draws.
    fn attempts(ees: &EquiEnergySampler<f64>, log_density: f64, n: usize) -> usize {
        let family = FnFamily::new(2, |l: usize, x: &f64| -x * x / (1.0 + l as f64));
        let current = Sample {
            state: (-log_density).sqrt(),
            log_density,
            payload: (),
        };
        let mut rng = stream_rng(7, 0);
        (0..n)
            .filter(|_| !matches!(ees.jump(0, &current, &family, &mut rng), Jump::None))
            .count()
    }

    #[test]
    fn the_thesis_rule_waits_for_every_ring_and_kous_for_the_current_one() {
        let n = 10_000;
        // Thesis: three of chain 1's four ring sets are empty → no jumps.
        let all = sampler_with_top_ring_filled(JumpRule::AllRingsFilled);
        assert_eq!(attempts(&all, -0.5, n), 0);
        // Kou: a state in the filled ring (ln π_0 = −0.5 → ring 3) jumps
        // with probability p_EEJ = 0.5: Binomial(10⁴, 0.5), sd 50, so
        // ±300 is six standard deviations.
        let kou = sampler_with_top_ring_filled(JumpRule::CurrentRingFilled);
        let k = attempts(&kou, -0.5, n);
        assert!((k as i64 - 5_000).abs() < 300, "{k} attempts of {n}");
        // ... and one in an empty ring (ln π_0 = −3.5 → ring 0) never does.
        assert_eq!(attempts(&kou, -3.5, n), 0);
    }
}
