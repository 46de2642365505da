//! One neighbour swap per sweep, the pair drawn uniformly (Kitaoka et al.
//! 2009, Algorithm 1: after every replica mutated, `k ← RandomInteger(1,
//! K−1)` and `swap(u_k, u_{k+1})` with `min{1, r}`).

use super::context::ExchangeContext;
use super::{ExchangeMove, Schedule};
use crate::rng::uniform;

/// After all chains mutated, one swap attempt of a neighbouring pair
/// `(k, k+1)` with `k` uniform in `0..M−1`. Each attempt is a reversible
/// Metropolis swap, and the pair is chosen independently of the states, so
/// the joint target is invariant.
#[derive(Clone, Copy, Debug, Default)]
pub struct RandomNeighbour;

impl RandomNeighbour {
    /// The move.
    pub fn new() -> Self {
        RandomNeighbour
    }
}

impl<S, P: Clone> ExchangeMove<S, P> for RandomNeighbour {
    fn name(&self) -> String {
        "random-neighbour".into()
    }

    fn schedule(&self) -> Schedule {
        Schedule::AfterAllMutations
    }

    fn exchange(&mut self, _level: Option<usize>, cx: &mut ExchangeContext<'_, S, P>) {
        let pairs = cx.levels().saturating_sub(1);
        if pairs == 0 {
            return;
        }
        // ⌊u·(M−1)⌋ with u ∈ [0, 1); the min guards the rounding edge.
        let k = ((uniform(cx.rng()) * pairs as f64) as usize).min(pairs - 1);
        cx.stats().move_attempts += 1;
        if cx.try_swap(k, k + 1).1 {
            cx.stats().move_changes += 1;
        }
    }

    // Nothing carries over between sweeps: the pair comes from the set's
    // exchange stream, which the set's progress saves.
    fn state_words(&self) -> Option<Vec<u64>> {
        Some(Vec::new())
    }

    fn restore_words(&mut self, words: &[u64]) -> bool {
        words.is_empty()
    }
}
