//! Importance-sampled swaps (§5.3.3, Eqs. 5.9–5.11): before chain `c_i`
//! mutates, it picks a partner `j` (possibly itself) with probability
//! `p(i,j) ∝ π_i(x_j) π_j(x_i)` and the swap is accepted with
//! `min(1, Σ_k π_i(x_k)π_k(x_i) / Σ_k π_i(x'_k)π_k(x'_i))`, where `x'` is the
//! post-swap configuration (the reverse choice's normaliser). The
//! initiating chain is fixed by the sweep (from the hottest down), so the
//! reverse move is initiated by the same chain (App. 5.B.2).

use super::context::ExchangeContext;
use super::{ExchangeMove, Schedule};
use crate::math::{log_sum_exp, sample_log_categorical};
use crate::mh::accept;
use crate::rng::uniform;

fn valid(v: f64) -> f64 {
    if v.is_nan() || v == f64::INFINITY {
        f64::NEG_INFINITY
    } else {
        v
    }
}

/// `ln` of the unnormalised partner weights of Eq. 5.9 for initiator `i`:
/// `w_k = ln π_i(x_k) + ln π_k(x_i)`, `k = 0..M`, where
/// `ln_pi(level, at) = ln π_level(x_at)`. Invalid entries weigh zero.
pub fn is_swap_log_weights(
    i: usize,
    levels: usize,
    ln_pi: &mut dyn FnMut(usize, usize) -> f64,
) -> Vec<f64> {
    (0..levels)
        .map(|k| valid(ln_pi(i, k)) + valid(ln_pi(k, i)))
        .collect()
}

/// `ln r_IS(i, j)` of Eq. 5.10: the log ratio of the forward normaliser to
/// the normaliser of the reverse choice in the post-swap configuration
/// (Eq. 5.11), capped at 0. `j = i` is the identity (`0`).
pub fn is_swap_log_acceptance(
    i: usize,
    j: usize,
    levels: usize,
    ln_pi: &mut dyn FnMut(usize, usize) -> f64,
) -> f64 {
    if i == j {
        return 0.0;
    }
    let forward = log_sum_exp(&is_swap_log_weights(i, levels, ln_pi));
    // After the swap x'_i = x_j, x'_j = x_i: the term for k reads
    // π_i(x'_k) π_k(x'_i) = π_i(x_{σ(k)}) π_k(x_j), σ exchanging i and j.
    let sigma = |k: usize| {
        if k == i {
            j
        } else if k == j {
            i
        } else {
            k
        }
    };
    let reverse: Vec<f64> = (0..levels)
        .map(|k| valid(ln_pi(i, sigma(k))) + valid(ln_pi(k, j)))
        .collect();
    let reverse = log_sum_exp(&reverse);
    if !forward.is_finite() || !reverse.is_finite() {
        // The forward normaliser includes the chosen (finite) term, and the
        // reverse one the identity term of the post-swap configuration; a
        // non-finite value means an invalid configuration: do not move.
        return f64::NEG_INFINITY;
    }
    (forward - reverse).min(0.0)
}

/// Importance-sampled swaps, one attempt before each chain's mutation.
#[derive(Clone, Debug, Default)]
pub struct IsSwap {
    weights: Vec<f64>,
}

impl IsSwap {
    /// The move.
    pub fn new() -> Self {
        IsSwap::default()
    }
}

impl<S, P: Clone> ExchangeMove<S, P> for IsSwap {
    fn name(&self) -> String {
        "is-swap".into()
    }

    fn schedule(&self) -> Schedule {
        Schedule::BeforeEachMutation
    }

    fn exchange(&mut self, level: Option<usize>, cx: &mut ExchangeContext<'_, S, P>) {
        let Some(i) = level else { return };
        let m = cx.levels();
        cx.stats().move_attempts += 1;
        self.weights = is_swap_log_weights(i, m, &mut |l, a| cx.log_density(l, a));
        let u = uniform(cx.rng());
        let Some(j) = sample_log_categorical(&self.weights, u) else {
            return;
        };
        if j == i {
            cx.stats().record_pair(i, i, 1.0, true);
            return;
        }
        let log_alpha = is_swap_log_acceptance(i, j, m, &mut |l, a| cx.log_density(l, a));
        let accepted = accept(log_alpha, cx.rng());
        cx.stats().record_pair(i, j, log_alpha.exp(), accepted);
        if accepted {
            cx.stats().move_changes += 1;
            cx.swap(i, j);
        }
    }

    /// Nothing carries over (the weights are rebuilt every attempt).
    fn state_words(&self) -> Option<Vec<u64>> {
        Some(Vec::new())
    }

    fn restore_words(&mut self, words: &[u64]) -> bool {
        words.is_empty()
    }
}
