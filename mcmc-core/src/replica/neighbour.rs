//! Neighbour swapping with the thesis's sweep (§5.3.1, Gruson et al. 2016):
//! for `i = M` down to 1, mutate `c_i`, then try `swap(c_i, c_{i−1})`, so a
//! state can climb towards high density before it is passed down.

use super::context::ExchangeContext;
use super::{ExchangeMove, Schedule};

/// Swap of neighbouring levels right after the hotter one mutated.
#[derive(Clone, Copy, Debug, Default)]
pub struct NeighbourSwap;

impl NeighbourSwap {
    /// The move.
    pub fn new() -> Self {
        NeighbourSwap
    }
}

impl<S, P: Clone> ExchangeMove<S, P> for NeighbourSwap {
    fn name(&self) -> String {
        "neighbour".into()
    }

    fn schedule(&self) -> Schedule {
        Schedule::AfterEachMutation
    }

    fn exchange(&mut self, level: Option<usize>, cx: &mut ExchangeContext<'_, S, P>) {
        if let Some(i) = level.filter(|&i| i > 0) {
            cx.stats().move_attempts += 1;
            if cx.try_swap(i, i - 1).1 {
                cx.stats().move_changes += 1;
            }
        }
    }

    fn state_words(&self) -> Option<Vec<u64>> {
        Some(Vec::new())
    }

    fn restore_words(&mut self, words: &[u64]) -> bool {
        words.is_empty()
    }
}
