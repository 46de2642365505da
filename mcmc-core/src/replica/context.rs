//! What an exchange move sees and may do: read `ln π_i(x_j)` entries
//! (memoised until the configuration changes), swap or permute the states
//! of levels, and draw random numbers from the exchange stream.

use super::family::ReplicaFamily;
use super::stats::{IndexProcess, ReplicaStatistics};
use crate::chain::ChainState;
use crate::mh::accept;
use crate::rng::ChainRng;
use crate::sample::Sample;
use crate::target::DensityClass;

/// `ln α` of swapping the states of levels `i` and `j` (Eq. 4.11):
/// `min(0, ln π_i(x_j) + ln π_j(x_i) − ln π_i(x_i) − ln π_j(x_j))`.
///
/// Arguments: `current_i = ln π_i(x_i)`, `current_j = ln π_j(x_j)`,
/// `swapped_i = ln π_i(x_j)`, `swapped_j = ln π_j(x_i)`. A swapped entry
/// that is `−∞`, NaN or `+∞` rejects; a `−∞` current entry (a zero-density
/// configuration) accepts any valid swap, as in Eq. 3.2; differences are
/// taken before sums so that `±1e300` entries do not overflow.
#[inline]
pub fn swap_log_acceptance(current_i: f64, current_j: f64, swapped_i: f64, swapped_j: f64) -> f64 {
    if DensityClass::of(swapped_i) != DensityClass::Finite
        || DensityClass::of(swapped_j) != DensityClass::Finite
    {
        return f64::NEG_INFINITY;
    }
    if current_i == f64::NEG_INFINITY || current_j == f64::NEG_INFINITY {
        return 0.0;
    }
    let d = (swapped_i - current_i) + (swapped_j - current_j);
    if d.is_nan() {
        f64::NEG_INFINITY
    } else {
        d.min(0.0)
    }
}

/// Memo of `ln π_level(x_at)` for the current configuration.
#[derive(Clone, Debug, Default)]
pub(crate) struct DensityCache {
    values: Vec<f64>,
    known: Vec<bool>,
}

impl DensityCache {
    pub(crate) fn new(levels: usize) -> Self {
        DensityCache {
            values: vec![0.0; levels * levels],
            known: vec![false; levels * levels],
        }
    }
    pub(crate) fn clear(&mut self) {
        self.known.iter_mut().for_each(|k| *k = false);
    }
}

/// The ensemble as an exchange move sees it.
///
/// States never get copied: a swap exchanges the two levels' samples (state,
/// `ln π`, payload) by moving them, then re-targets each to its new level
/// (for a [`super::PowerFamily`] this is one multiply-add, for a general
/// family a re-evaluation that refreshes the payload, e.g. a gradient).
/// Kernels and their adaptation stay with their level, because they are
/// tuned to the level's density, not to the state.
pub struct ExchangeContext<'a, S, P> {
    pub(crate) family: &'a (dyn ReplicaFamily<S, Payload = P> + Sync),
    pub(crate) chains: &'a mut [ChainState<S, P>],
    pub(crate) rng: &'a mut ChainRng,
    pub(crate) index: &'a mut IndexProcess,
    pub(crate) stats: &'a mut ReplicaStatistics,
    pub(crate) cache: &'a mut DensityCache,
    pub(crate) frozen: bool,
}

impl<S, P: Clone> ExchangeContext<'_, S, P> {
    /// Number of levels `M`.
    pub fn levels(&self) -> usize {
        self.chains.len()
    }

    /// The sample at `level`.
    pub fn sample(&self, level: usize) -> &Sample<S, P> {
        &self.chains[level].current
    }

    /// The family.
    pub fn family(&self) -> &(dyn ReplicaFamily<S, Payload = P> + Sync) {
        self.family
    }

    /// True after the end of burn-in (moves stop adapting their levels).
    pub fn frozen(&self) -> bool {
        self.frozen
    }

    /// The exchange random stream.
    pub fn rng(&mut self) -> &mut ChainRng {
        self.rng
    }

    /// Exchange statistics.
    pub fn stats(&mut self) -> &mut ReplicaStatistics {
        self.stats
    }

    /// `ln π_level(x_at)`: the density of level `level` at the state held
    /// by level `at`. Diagonal entries are the cached densities; the others
    /// are computed once per configuration.
    pub fn log_density(&mut self, level: usize, at: usize) -> f64 {
        if level == at {
            return self.chains[at].current.log_density;
        }
        let m = self.chains.len();
        let k = level * m + at;
        if !self.cache.known[k] {
            self.cache.values[k] = self.family.log_density_of(level, &self.chains[at].current);
            self.cache.known[k] = true;
            if !self.family.cross_densities_are_cheap() {
                self.stats.evaluations += 1;
            }
        }
        self.cache.values[k]
    }

    /// Records every neighbour pair's swap acceptance probability in the
    /// statistics (for Λ under any move), when cross densities are cheap.
    pub(crate) fn probe_neighbours(&mut self) {
        if !self.family.cross_densities_are_cheap() || self.levels() < 2 {
            return;
        }
        // Per sweep and per pair: no allocation (cheap families sweep fast).
        for i in 0..self.levels() - 1 {
            let log_alpha = swap_log_acceptance(
                self.log_density(i, i),
                self.log_density(i + 1, i + 1),
                self.log_density(i, i + 1),
                self.log_density(i + 1, i),
            );
            self.stats.add_neighbour_probe(i, log_alpha.exp());
        }
        self.stats.end_neighbour_probe();
    }

    /// The full matrix `out[level·M + at] = ln π_level(x_at)`.
    pub fn log_density_matrix(&mut self, out: &mut Vec<f64>) {
        let m = self.levels();
        out.clear();
        for level in 0..m {
            for at in 0..m {
                let v = self.log_density(level, at);
                out.push(v);
            }
        }
    }

    /// Exchanges the states of levels `i` and `j` unconditionally (the
    /// move has decided), re-targeting both and updating the index process.
    pub fn swap(&mut self, i: usize, j: usize) {
        if i == j {
            return;
        }
        let new_i = self.log_density(i, j);
        let new_j = self.log_density(j, i);
        let (a, b) = if i < j { (i, j) } else { (j, i) };
        let (lo, hi) = self.chains.split_at_mut(b);
        std::mem::swap(&mut lo[a].current, &mut hi[0].current);
        self.retarget(i, new_i);
        self.retarget(j, new_j);
        self.index.swap(i, j);
        self.stats.touch(i);
        self.stats.touch(j);
        self.cache.clear();
    }

    fn retarget(&mut self, level: usize, log_density: f64) {
        self.family
            .retarget(level, &mut self.chains[level].current, log_density);
        if !self.family.cross_densities_are_cheap() {
            self.stats.evaluations += 1;
        }
    }

    /// Attempts the Eq. 4.11 swap of levels `i ≠ j`; returns `(α, accepted)`
    /// and records the attempt under the pair.
    pub fn try_swap(&mut self, i: usize, j: usize) -> (f64, bool) {
        let log_alpha = swap_log_acceptance(
            self.log_density(i, i),
            self.log_density(j, j),
            self.log_density(i, j),
            self.log_density(j, i),
        );
        let accepted = accept(log_alpha, self.rng);
        let alpha = log_alpha.exp();
        self.stats.record_pair(i, j, alpha, accepted);
        if accepted {
            self.swap(i, j);
        }
        (alpha, accepted)
    }

    /// Applies a permutation: level `i` receives the state held by level
    /// `source[i]`. `log_density` must give `ln π_i(x_{source[i]})` (the
    /// move has them from its matrix). States move along the permutation's
    /// cycles by swaps, so no state is ever duplicated or lost (the
    /// PTMCMCSampler#58 bug).
    pub fn permute(&mut self, source: &[usize]) {
        let m = self.levels();
        debug_assert_eq!(source.len(), m);
        let targets: Vec<f64> = (0..m).map(|i| self.log_density(i, source[i])).collect();
        let mut done = vec![false; m];
        for start in 0..m {
            if done[start] {
                continue;
            }
            // Walk the cycle start → source[start] → …: after swapping the
            // current position with the next one, the current position
            // holds its final state and the cycle's first state moves on.
            let mut cur = start;
            done[cur] = true;
            loop {
                let next = source[cur];
                if done[next] {
                    break;
                }
                let (a, b) = if cur < next { (cur, next) } else { (next, cur) };
                let (lo, hi) = self.chains.split_at_mut(b);
                std::mem::swap(&mut lo[a].current, &mut hi[0].current);
                done[next] = true;
                cur = next;
            }
        }
        for i in 0..m {
            if source[i] != i {
                self.retarget(i, targets[i]);
                self.stats.touch(i);
            }
        }
        self.index.permute(source);
        self.cache.clear();
    }
}
