//! Exchange statistics: acceptance per pair of levels and per move, the
//! fraction of sweeps in which a level's state was replaced (the thesis's
//! Table 5.3 quantity), the index process with round trips, and the
//! communication barrier `Λ`.

use crate::checkpoint::take_words;

/// Which replica (an identity that travels with a state through exchanges)
/// sits at which level, and the round trips each replica has completed.
///
/// A round trip is a replica's journey from level 1 (the target) to level
/// `M` (the hottest) and back to level 1 (Katzgraber et al. 2006; Pigeons
/// counts the same). With `M = 1` there are none.
#[derive(Clone, Debug, PartialEq)]
pub struct IndexProcess {
    replica_at_level: Vec<usize>,
    level_of_replica: Vec<usize>,
    /// Per replica: 0 = has not yet been at level 1; 1 = left level 1 and
    /// has not reached the top; 2 = reached the top, heading down.
    phase: Vec<u8>,
    round_trips: Vec<u64>,
}

impl IndexProcess {
    /// Replica `i` starts at level `i`.
    pub fn new(levels: usize) -> Self {
        let mut ip = IndexProcess {
            replica_at_level: (0..levels).collect(),
            level_of_replica: (0..levels).collect(),
            phase: vec![0; levels],
            round_trips: vec![0; levels],
        };
        for r in 0..levels {
            ip.visit(r);
        }
        ip
    }

    fn visit(&mut self, replica: usize) {
        let m = self.replica_at_level.len();
        if m < 2 {
            return;
        }
        let level = self.level_of_replica[replica];
        if level == 0 {
            if self.phase[replica] == 2 {
                self.round_trips[replica] += 1;
            }
            self.phase[replica] = 1;
        } else if level == m - 1 && self.phase[replica] == 1 {
            self.phase[replica] = 2;
        }
    }

    /// Appends the process to `out` (for checkpoints): per level the
    /// replica there, per replica its phase and its round trips.
    pub(crate) fn to_words(&self, out: &mut Vec<u64>) {
        out.extend(self.replica_at_level.iter().map(|&r| r as u64));
        out.extend(self.phase.iter().map(|&p| u64::from(p)));
        out.extend(&self.round_trips);
    }

    /// The process of `levels` levels [`IndexProcess::to_words`] wrote at
    /// the front of `input` (advanced past it); `None` when the words do
    /// not describe one.
    pub(crate) fn from_words(levels: usize, input: &mut &[u64]) -> Option<Self> {
        let replica_at_level: Vec<usize> = take_words(input, levels)?
            .iter()
            .map(|&r| r as usize)
            .collect();
        let phase = take_words(input, levels)?
            .iter()
            .map(|&p| u8::try_from(p).ok().filter(|&p| p <= 2))
            .collect::<Option<Vec<u8>>>()?;
        let round_trips = take_words(input, levels)?.to_vec();
        let mut level_of_replica = vec![usize::MAX; levels];
        for (level, &r) in replica_at_level.iter().enumerate() {
            // A permutation: every replica at exactly one level.
            let slot = level_of_replica.get_mut(r).filter(|l| **l == usize::MAX)?;
            *slot = level;
        }
        Some(IndexProcess {
            replica_at_level,
            level_of_replica,
            phase,
            round_trips,
        })
    }

    /// The replica at `level`.
    pub fn replica_at(&self, level: usize) -> usize {
        self.replica_at_level[level]
    }

    /// The level of `replica`.
    pub fn level_of(&self, replica: usize) -> usize {
        self.level_of_replica[replica]
    }

    /// Records that levels `i` and `j` exchanged their states.
    pub fn swap(&mut self, i: usize, j: usize) {
        self.replica_at_level.swap(i, j);
        let (a, b) = (self.replica_at_level[i], self.replica_at_level[j]);
        self.level_of_replica[a] = i;
        self.level_of_replica[b] = j;
        self.visit(a);
        self.visit(b);
    }

    /// Round trips completed by each replica.
    pub fn round_trips(&self) -> &[u64] {
        &self.round_trips
    }

    /// Round trips completed by all replicas.
    pub fn total_round_trips(&self) -> u64 {
        self.round_trips.iter().sum()
    }
}

/// Counts for exchanges between two levels.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PairStatistics {
    /// Exchanges attempted.
    pub attempted: u64,
    /// Exchanges accepted.
    pub accepted: u64,
    /// Sum of acceptance probabilities.
    pub sum_alpha: f64,
}

impl PairStatistics {
    /// Mean acceptance probability (NaN before any attempt).
    pub fn mean_alpha(&self) -> f64 {
        self.sum_alpha / self.attempted as f64
    }
    /// Fraction accepted (NaN before any attempt).
    pub fn acceptance_rate(&self) -> f64 {
        self.accepted as f64 / self.attempted as f64
    }
}

/// Everything an ensemble counts about its exchanges.
///
/// Pair counts mean "an exchange between levels `i` and `j` was attempted /
/// accepted, with acceptance probability α". For importance-sampled
/// permutations (always accepted) they count how often level `i` received
/// the state of level `j` (`i = j`: kept its own); for IS swaps `(i, i)`
/// counts identity choices; for equi-energy jumps `(j−1, j)` counts jumps of
/// `c_{j−1}` to `c_j`'s store.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplicaStatistics {
    levels: usize,
    /// The exchange move's name.
    pub move_name: String,
    /// Sweeps completed.
    pub sweeps: u64,
    /// `pairs[i·M + j]` (`i ≤ j`): exchanges between levels `i` and `j`.
    /// `i = j` counts "identity" choices of the importance-sampled moves.
    pairs: Vec<PairStatistics>,
    /// Exchange moves attempted (one per sweep, or one per chain and sweep
    /// for the per-chain schedules), whatever their outcome.
    pub move_attempts: u64,
    /// Exchange moves that changed at least one level's state.
    pub move_changes: u64,
    /// Per level: sweeps in which an exchange replaced the level's state.
    pub changed: Vec<u64>,
    touched: Vec<bool>,
    /// Target evaluations made by exchange moves (cross-level densities,
    /// payload refreshes); 0 for families with cheap cross densities.
    pub evaluations: u64,
    /// Per neighbour pair `(i, i+1)`: the sum of the swap acceptance
    /// probability `α_{i,i+1}` evaluated at the end of every sweep, whatever
    /// the move (families with cheap cross densities only).
    neighbour_probe_sums: Vec<f64>,
    /// Sweeps whose neighbour acceptance was probed.
    neighbour_probes: u64,
}

impl ReplicaStatistics {
    /// Empty statistics for `levels` levels.
    pub fn new(levels: usize, move_name: impl Into<String>) -> Self {
        ReplicaStatistics {
            levels,
            move_name: move_name.into(),
            sweeps: 0,
            pairs: vec![PairStatistics::default(); levels * levels],
            move_attempts: 0,
            move_changes: 0,
            changed: vec![0; levels],
            touched: vec![false; levels],
            evaluations: 0,
            neighbour_probe_sums: vec![0.0; levels.saturating_sub(1)],
            neighbour_probes: 0,
        }
    }

    /// Number of levels.
    pub fn levels(&self) -> usize {
        self.levels
    }

    /// Records one attempted exchange between levels `i` and `j`.
    pub fn record_pair(&mut self, i: usize, j: usize, alpha: f64, accepted: bool) {
        let (a, b) = if i <= j { (i, j) } else { (j, i) };
        let p = &mut self.pairs[a * self.levels + b];
        p.attempted += 1;
        p.accepted += accepted as u64;
        p.sum_alpha += alpha;
    }

    /// Adds pair `(i, i+1)`'s swap acceptance probability `α_{i,i+1}` in
    /// the configuration at the end of a sweep; call for every pair, then
    /// [`Self::end_neighbour_probe`] once.
    pub fn add_neighbour_probe(&mut self, i: usize, alpha: f64) {
        self.neighbour_probe_sums[i] += alpha;
    }

    /// Closes one sweep's neighbour probe.
    pub fn end_neighbour_probe(&mut self) {
        self.neighbour_probes += 1;
    }

    /// Mean neighbour swap acceptance `E[α_{i,i+1}]` from the end-of-sweep
    /// probes, `None` when no sweep was probed (families whose cross
    /// densities cost a target evaluation are not probed).
    pub fn probed_neighbour_acceptance(&self) -> Option<Vec<f64>> {
        (self.neighbour_probes > 0).then(|| {
            self.neighbour_probe_sums
                .iter()
                .map(|s| s / self.neighbour_probes as f64)
                .collect()
        })
    }

    /// Marks that `level`'s state was replaced by an exchange in this sweep.
    pub fn touch(&mut self, level: usize) {
        self.touched[level] = true;
    }

    /// Closes a sweep.
    pub fn end_sweep(&mut self) {
        self.sweeps += 1;
        for (c, t) in self.changed.iter_mut().zip(self.touched.iter_mut()) {
            *c += *t as u64;
            *t = false;
        }
    }

    /// Appends the counts to `out` (for checkpoints; the number of levels
    /// and the move's name are the ensemble's, not saved): sweeps, every
    /// pair's counts, the move counters, per level the changes and this
    /// sweep's touches, the evaluations and the neighbour probes.
    pub(crate) fn to_words(&self, out: &mut Vec<u64>) {
        out.push(self.sweeps);
        for p in &self.pairs {
            out.extend([p.attempted, p.accepted, p.sum_alpha.to_bits()]);
        }
        out.extend([self.move_attempts, self.move_changes]);
        out.extend(&self.changed);
        out.extend(self.touched.iter().map(|&t| u64::from(t)));
        out.push(self.evaluations);
        out.extend(self.neighbour_probe_sums.iter().map(|s| s.to_bits()));
        out.push(self.neighbour_probes);
    }

    /// Replaces the counts by those [`ReplicaStatistics::to_words`] wrote
    /// at the front of `input` (advanced past it) for as many levels;
    /// `None` (and no change) when the words are cut short.
    pub(crate) fn read_words(&mut self, input: &mut &[u64]) -> Option<()> {
        let m = self.levels;
        let mut next = |n: usize| take_words(input, n);
        let sweeps = next(1)?[0];
        let pairs = next(3 * m * m)?
            .chunks_exact(3)
            .map(|p| PairStatistics {
                attempted: p[0],
                accepted: p[1],
                sum_alpha: f64::from_bits(p[2]),
            })
            .collect();
        let [move_attempts, move_changes] = next(2)?.try_into().ok()?;
        let changed = next(m)?.to_vec();
        let touched = next(m)?.iter().map(|&t| t != 0).collect();
        let evaluations = next(1)?[0];
        let sums = next(m.saturating_sub(1))?
            .iter()
            .map(|&s| f64::from_bits(s));
        let neighbour_probe_sums = sums.collect();
        let neighbour_probes = next(1)?[0];
        *self = ReplicaStatistics {
            levels: m,
            move_name: std::mem::take(&mut self.move_name),
            sweeps,
            pairs,
            move_attempts,
            move_changes,
            changed,
            touched,
            evaluations,
            neighbour_probe_sums,
            neighbour_probes,
        };
        Some(())
    }

    /// Sets the statistics of pair `(i, j)` (unordered), e.g. from a
    /// checkpoint of a distributed run.
    #[cfg(feature = "mpi")]
    pub(crate) fn set_pair(&mut self, i: usize, j: usize, p: PairStatistics) {
        let (a, b) = if i <= j { (i, j) } else { (j, i) };
        self.pairs[a * self.levels + b] = p;
    }

    /// Statistics of exchanges between levels `i` and `j` (unordered).
    pub fn pair(&self, i: usize, j: usize) -> PairStatistics {
        let (a, b) = if i <= j { (i, j) } else { (j, i) };
        self.pairs[a * self.levels + b]
    }

    /// Mean acceptance probability of neighbour pairs `(i, i+1)`, NaN where
    /// none was attempted.
    pub fn neighbour_acceptance(&self) -> Vec<f64> {
        (0..self.levels.saturating_sub(1))
            .map(|i| self.pair(i, i + 1).mean_alpha())
            .collect()
    }

    /// Every pair with at least one attempt: `(i, j, stats)` with `i ≤ j`.
    pub fn attempted_pairs(&self) -> Vec<(usize, usize, PairStatistics)> {
        let mut out = Vec::new();
        for i in 0..self.levels {
            for j in i..self.levels {
                let p = self.pair(i, j);
                if p.attempted > 0 {
                    out.push((i, j, p));
                }
            }
        }
        out
    }

    /// Accepted over attempted, over all pairs `i ≠ j`.
    pub fn overall_acceptance(&self) -> f64 {
        let (mut a, mut n) = (0u64, 0u64);
        for (i, j, p) in self.attempted_pairs() {
            if i != j {
                a += p.accepted;
                n += p.attempted;
            }
        }
        a as f64 / n as f64
    }

    /// Fraction of sweeps in which each level's state was replaced by an
    /// exchange (identity draws and impossible moves count as "unchanged").
    pub fn change_fraction(&self) -> Vec<f64> {
        self.changed
            .iter()
            .map(|c| *c as f64 / self.sweeps as f64)
            .collect()
    }

    /// The thesis's Table 5.3 figure: the mean over levels of
    /// [`ReplicaStatistics::change_fraction`].
    pub fn mean_change_fraction(&self) -> f64 {
        let total: u64 = self.changed.iter().sum();
        total as f64 / (self.sweeps as f64 * self.levels as f64)
    }

    /// Estimated communication barrier `Λ = Σ_i r_i`, the sum of neighbour
    /// rejection rates `r_i = 1 − E[α_{i,i+1}]` (Syed et al. 2021), for any
    /// exchange move.
    ///
    /// For families with cheap cross densities (power families), the
    /// ensemble evaluates every neighbour pair's Eq. 4.11 swap probability
    /// at the end of every sweep ([`Self::probed_neighbour_acceptance`]),
    /// whatever move it runs: the levels' states are then draws from their
    /// own levels, so the mean is `E[α_{i,i+1}]` under `π_i ⊗ π_{i+1}`, the
    /// quantity Λ is defined by, and it costs no evaluation. Otherwise Λ
    /// comes from the attempted neighbour swaps, which only the neighbour
    /// and even–odd moves make (other moves record their own acceptance
    /// probabilities, which are not the neighbour swap's): `None` when some
    /// neighbour pair was never attempted.
    pub fn barrier(&self) -> Option<f64> {
        let rejections = self.neighbour_rejection();
        if rejections.iter().any(|r| r.is_nan()) {
            return None;
        }
        Some(rejections.iter().sum())
    }

    /// The neighbour rejection rates `r_i = 1 − E[α_{i,i+1}]` that
    /// [`Self::barrier`] sums: from the end-of-sweep probes when there are
    /// any, else from the attempted neighbour swaps (NaN for a pair never
    /// attempted).
    pub fn neighbour_rejection(&self) -> Vec<f64> {
        self.probed_neighbour_acceptance()
            .unwrap_or_else(|| self.neighbour_acceptance())
            .iter()
            .map(|a| 1.0 - a)
            .collect()
    }

    /// Forgets the pair counts (after a schedule change, whose old
    /// acceptance no longer applies).
    pub fn reset_pairs(&mut self) {
        self.pairs
            .iter_mut()
            .for_each(|p| *p = PairStatistics::default());
        self.neighbour_probe_sums.iter_mut().for_each(|s| *s = 0.0);
        self.neighbour_probes = 0;
    }
}

impl IndexProcess {
    /// Records a permutation: level `i` received the replica of level
    /// `source[i]`.
    pub fn permute(&mut self, source: &[usize]) {
        let old = self.replica_at_level.clone();
        for (i, &s) in source.iter().enumerate() {
            self.replica_at_level[i] = old[s];
            self.level_of_replica[old[s]] = i;
        }
        for i in 0..source.len() {
            if source[i] != i {
                self.visit(self.replica_at_level[i]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_replica_going_up_and_down_completes_one_round_trip() {
        let mut ip = IndexProcess::new(3);
        ip.swap(0, 1);
        ip.swap(1, 2);
        assert_eq!(ip.level_of(0), 2);
        assert_eq!(ip.total_round_trips(), 0);
        ip.swap(1, 2);
        assert_eq!(ip.total_round_trips(), 0);
        ip.swap(0, 1);
        assert_eq!(ip.level_of(0), 0);
        assert_eq!(ip.round_trips()[0], 1);
        // The same through a permutation: level i receives level source[i].
        ip.permute(&[2, 0, 1]); // replica 0 goes to level 1… then to the top
        ip.permute(&[2, 0, 1]);
        assert_eq!(ip.level_of(0), 2);
        ip.permute(&[1, 2, 0]);
        ip.permute(&[1, 2, 0]);
        assert_eq!(ip.level_of(0), 0);
        assert_eq!(ip.round_trips()[0], 2);
    }
}
