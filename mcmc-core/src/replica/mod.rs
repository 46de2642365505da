//! Replica exchange (parallel tempering) with pluggable exchange moves.
//!
//! # Design
//!
//! - A [`ReplicaFamily`] gives `M` densities `π_1 … π_M` over one state
//!   space; level 0 (`π_1`) is the target of interest. Levels are general
//!   densities; [`PowerFamily`] is `ln π_β = β ln L + ln prior` with
//!   `0·(−∞) = −∞`, and [`FnFamily`] wraps a closure `(level, x) ↦ ln π`.
//! - [`ReplicaExchange`] owns one chain per level: the level's mutation
//!   algorithm (its kernel and the kernel's adaptation, tuned to the level's
//!   density — e.g. a scale `∝ √T`, see [`kernel_scales`]), its random
//!   stream, its statistics, and the sample it currently holds.
//! - Exchange moves implement [`ExchangeMove`]. A move says *when* it runs
//!   relative to the mutations ([`Schedule`]: after all chains mutated, or
//!   before / after each chain's mutation in a sweep from the hottest level
//!   down) and acts through an [`ExchangeContext`].
//! - **Swaps move samples, not copies.** Exchanging two levels moves the
//!   two `Sample`s (state, `ln π`, payload — e.g. a gradient) between the
//!   levels, then re-targets each to its new level (a multiply-add for a
//!   power family, a re-evaluation that refreshes the payload otherwise).
//!   Kernel adaptation stays with the level. The [`IndexProcess`] records
//!   which replica (travelling state) sits at which level, which gives round
//!   trips. A permutation is applied along its cycles by swaps, so no state
//!   is ever duplicated or lost.
//! - Randomness: level `l` mutates with `stream_rng(seed, l)`, exchanges
//!   draw from their own stream, and mutations between exchanges run in
//!   parallel on rayon, so a run is bit-identical for any thread count.
//!
//! Moves (one file each): [`NeighbourSwap`] (the thesis's sweep §5.3.1),
//! [`EvenOdd`] (deterministic, non-reversible), [`RandomNeighbour`]
//! (one uniformly chosen neighbour pair per sweep, Kitaoka et al. 2009), [`IsPermutation`] (§5.3.2,
//! subset DP in [`permutation_dp`]), [`IsSwap`] (§5.3.3),
//! [`EquiEnergyMove`] (§5.3.4), [`FrequentEquiEnergy`] (§5.3.5),
//! [`EquiEnergySampler`] (Kou et al. 2006) and [`AdaptiveEquiEnergy`]
//! (Schreck et al. 2013).

mod adaptive_equi_energy;
pub mod combination;
mod context;
pub(crate) mod ensemble;
mod equi_energy;
mod equi_energy_sampler;
mod even_odd;
pub mod exact;
mod family;
mod frequent_equi_energy;
mod is_permutation;
mod is_swap;
mod neighbour;
pub mod permutation_dp;
pub mod population_annealing;
mod random_neighbour;
mod rings;
pub mod schedule;
mod stats;

pub use adaptive_equi_energy::AdaptiveEquiEnergy;
pub use context::{ExchangeContext, swap_log_acceptance};
pub use ensemble::{LevelObserver, ReplicaExchange, ReplicaProgress};
pub use equi_energy::{EquiEnergyMove, equi_energy_pair_probabilities};
pub use equi_energy_sampler::{EquiEnergySampler, JumpRule};
pub use even_odd::EvenOdd;
pub use family::{
    FlatPrior, FnFamily, LevelTarget, PowerFamily, ReplicaFamily, Tempered, TunableFamily,
    betas_from_temperatures, geometric_temperatures, kernel_scales, tempered_log_density,
    validate_temperatures,
};
pub use frequent_equi_energy::{FrequentEquiEnergy, frequent_partners};
pub use is_permutation::IsPermutation;
pub use is_swap::{IsSwap, is_swap_log_acceptance, is_swap_log_weights};
pub use neighbour::NeighbourSwap;
pub use random_neighbour::RandomNeighbour;
pub use rings::{EnergyRings, RingRange};
pub use stats::{IndexProcess, PairStatistics, ReplicaStatistics};

use crate::rng::ChainRng;
use crate::sample::Sample;

/// When an exchange move runs relative to the chains' mutations within one
/// sweep.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Schedule {
    /// All chains mutate (in parallel), then the move runs once.
    AfterAllMutations,
    /// For each level from the hottest down: the move runs for that level,
    /// then the level mutates.
    BeforeEachMutation,
    /// For each level from the hottest down: the level mutates, then the
    /// move runs for that level.
    AfterEachMutation,
}

/// What a move that may replace a mutation (the equi-energy sampler's jump)
/// did at one level.
#[derive(Clone, Debug)]
pub enum Jump<S, P> {
    /// No jump: the level mutates as usual.
    None,
    /// A jump to the partner level was attempted and rejected (`α`).
    Rejected {
        /// Partner level whose store was used.
        partner: usize,
        /// Acceptance probability.
        alpha: f64,
    },
    /// A jump was accepted: the level's new sample.
    Accepted {
        /// Partner level whose store was used.
        partner: usize,
        /// Acceptance probability.
        alpha: f64,
        /// The new sample, evaluated at the level.
        sample: Sample<S, P>,
    },
}

/// An exchange move: a pluggable object that changes which level holds
/// which state (or, for the equi-energy sampler, replaces some mutations by
/// jumps to stored states).
pub trait ExchangeMove<S, P>: Send + Sync {
    /// A short name for statistics and reports.
    fn name(&self) -> String;

    /// When the move runs relative to the mutations.
    fn schedule(&self) -> Schedule;

    /// Runs the move: once per sweep (`level = None`) for
    /// [`Schedule::AfterAllMutations`], or for each level (`Some(l)`) for the
    /// per-chain schedules.
    fn exchange(&mut self, level: Option<usize>, cx: &mut ExchangeContext<'_, S, P>);

    /// Called for every level, in parallel, in place of the level's
    /// mutation; a move that returns anything but [`Jump::None`] replaces
    /// the mutation. Must draw only from `rng` (the level's stream).
    fn jump(
        &self,
        _level: usize,
        _current: &Sample<S, P>,
        _family: &(dyn ReplicaFamily<S, Payload = P> + Sync),
        _rng: &mut ChainRng,
    ) -> Jump<S, P> {
        Jump::None
    }

    /// Called at the end of every sweep (the equi-energy sampler stores the
    /// states here).
    fn end_sweep(&mut self, _cx: &mut ExchangeContext<'_, S, P>) {}

    /// End of burn-in: stop adapting energy levels, start storing.
    fn freeze(&mut self) {}

    /// Refuses an ensemble of `levels` levels when the move was built for
    /// another number (called by [`ReplicaExchange::new`]).
    fn check_levels(&self, _levels: usize) -> crate::Result<()> {
        Ok(())
    }

    /// Bytes held by the move (stores of past states, DP tables); heap data
    /// owned by the states themselves is not counted.
    fn memory_bytes(&self) -> usize {
        0
    }

    /// The move's own state that carries over from one sweep to the next
    /// (a sweep counter, its counters), as words for a checkpoint
    /// ([`ReplicaExchange::progress`]); scratch space rebuilt every sweep
    /// is not part of it. `None` (the default): the move cannot be saved
    /// (stores of past states, adapted energy levels).
    fn state_words(&self) -> Option<Vec<u64>> {
        None
    }

    /// Puts back what [`ExchangeMove::state_words`] gave; `false` when
    /// the words do not fit this move.
    fn restore_words(&mut self, _words: &[u64]) -> bool {
        false
    }
}
