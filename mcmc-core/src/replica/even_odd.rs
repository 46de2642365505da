//! Deterministic even–odd swaps (Okabe et al. 2001; the non-reversible
//! schedule of Syed et al. 2021 / Pigeons): after all chains mutated, even
//! sweeps try the pairs `(0,1), (2,3), …` and odd sweeps `(1,2), (3,4), …`.
//! Each half is reversible; their alternation is not, which makes the index
//! process travel ballistically instead of diffusing.

use super::context::ExchangeContext;
use super::{ExchangeMove, Schedule};

/// Deterministic even–odd (DEO) neighbour swaps.
#[derive(Clone, Copy, Debug, Default)]
pub struct EvenOdd {
    sweep: u64,
}

impl EvenOdd {
    /// The move, starting with the even pairs.
    pub fn new() -> Self {
        EvenOdd { sweep: 0 }
    }

    /// Pairs `(i, i+1)` tried on sweep number `sweep` among `levels` levels.
    pub fn pairs(sweep: u64, levels: usize) -> impl Iterator<Item = (usize, usize)> {
        let first = (sweep % 2) as usize;
        (first..levels.saturating_sub(1))
            .step_by(2)
            .map(|i| (i, i + 1))
    }
}

impl<S, P: Clone> ExchangeMove<S, P> for EvenOdd {
    fn name(&self) -> String {
        "even-odd".into()
    }

    fn schedule(&self) -> Schedule {
        Schedule::AfterAllMutations
    }

    fn exchange(&mut self, _level: Option<usize>, cx: &mut ExchangeContext<'_, S, P>) {
        let m = cx.levels();
        let mut changed = false;
        for (i, j) in EvenOdd::pairs(self.sweep, m) {
            changed |= cx.try_swap(i, j).1;
        }
        cx.stats().move_attempts += 1;
        cx.stats().move_changes += changed as u64;
        self.sweep += 1;
    }

    fn state_words(&self) -> Option<Vec<u64>> {
        Some(vec![self.sweep])
    }

    fn restore_words(&mut self, words: &[u64]) -> bool {
        match words {
            &[sweep] => {
                self.sweep = sweep;
                true
            }
            _ => false,
        }
    }
}
