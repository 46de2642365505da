//! Importance-sampled permutations (§5.3.2): after all chains mutated, draw
//! one permutation `o` of the states over all `M!` permutations (identity
//! included) with probability `∏_i π_i(x_{o(i)}) / b_O` and apply it. The
//! move is always accepted (App. 5.B.1: `p(o⁻¹)` after the move has the same
//! normaliser, so the MH ratio is 1).

use super::context::ExchangeContext;
use super::permutation_dp::{DEFAULT_MAX_TABLE_BYTES, PermutationDp};
use super::{ExchangeMove, Schedule};
use crate::error::Result;
use crate::rng::uniform;

/// Importance-sampled permutations by the `O(M·2^M)` subset DP.
#[derive(Clone, Debug)]
pub struct IsPermutation {
    dp: PermutationDp,
    matrix: Vec<f64>,
    source: Vec<usize>,
    /// Sweeps in which the DP failed (every permutation had zero weight,
    /// impossible when the current states have finite density); the identity
    /// was kept.
    pub failures: u64,
}

impl IsPermutation {
    /// The move for `levels` levels, with the default table limit (128 MiB,
    /// `M ≤ 24`). Refuses larger `M` with a clear error.
    pub fn new(levels: usize) -> Result<Self> {
        Self::with_memory_limit(levels, DEFAULT_MAX_TABLE_BYTES)
    }

    /// The move with an explicit cap on the DP table's bytes.
    pub fn with_memory_limit(levels: usize, max_table_bytes: usize) -> Result<Self> {
        Ok(IsPermutation {
            dp: PermutationDp::new(levels, max_table_bytes)?,
            matrix: Vec::with_capacity(levels * levels),
            source: vec![0; levels],
            failures: 0,
        })
    }
}

impl<S, P: Clone> ExchangeMove<S, P> for IsPermutation {
    fn name(&self) -> String {
        "is-permutation".into()
    }

    fn schedule(&self) -> Schedule {
        Schedule::AfterAllMutations
    }

    fn exchange(&mut self, _level: Option<usize>, cx: &mut ExchangeContext<'_, S, P>) {
        let m = cx.levels();
        cx.log_density_matrix(&mut self.matrix);
        cx.stats().move_attempts += 1;
        if self.dp.levels() != m || self.dp.prepare(&self.matrix).is_err() {
            self.failures += 1;
            return;
        }
        let rng = cx.rng();
        self.dp.sample(|| uniform(rng), &mut self.source);
        for i in 0..m {
            // Record "level i received the state of level source[i]"; i = j
            // counts the fixed points (identity choices).
            cx.stats().record_pair(i, self.source[i], 1.0, true);
        }
        if self.source.iter().enumerate().any(|(i, &s)| s != i) {
            cx.stats().move_changes += 1;
            cx.permute(&self.source);
        }
    }

    fn check_levels(&self, levels: usize) -> Result<()> {
        if levels != self.dp.levels() {
            return Err(crate::error::invalid(
                "exchange move",
                format!("built for {} levels, used with {levels}", self.dp.levels()),
            ));
        }
        Ok(())
    }

    fn memory_bytes(&self) -> usize {
        self.dp.memory_bytes()
    }

    /// The failure count (the DP table, the matrix and the permutation are
    /// rebuilt every sweep).
    fn state_words(&self) -> Option<Vec<u64>> {
        Some(vec![self.failures])
    }

    fn restore_words(&mut self, words: &[u64]) -> bool {
        match words {
            &[failures] => {
                self.failures = failures;
                true
            }
            _ => false,
        }
    }
}
