//! Replica exchange with the levels spread over ranks.

use super::DistributedError;
use super::checkpoint::{
    REPLICA_MAGIC, REPLICA_MAGIC_V1, read_on_rank_0, rng_from_words, rng_words, write_on_rank_0,
};
use super::comm::{
    Traffic, agree, all_gather_u64, exchange_bytes, exchange_pair, gather_bytes, receive_bytes,
    send_bytes, share, tag,
};
use super::wire::{Wire, decode, encode};
use crate::chain::{Algorithm, ChainState, Transition};
use crate::checkpoint::{FNV_OFFSET, fnv1a};
use crate::mh::accept;
use crate::replica::ensemble::{EXCHANGE_STREAM, Observer, level_chains};
use crate::replica::{
    EvenOdd, LevelTarget, PairStatistics, ReplicaFamily, ReplicaStatistics, swap_log_acceptance,
};
use crate::rng::{ChainRng, stream_rng};
use crate::sample::Sample;
use mpi::topology::{Communicator, SimpleCommunicator};
use rand::Rng;
use rayon::prelude::*;
use std::ops::Range;
use std::path::Path;

/// The exchange schedules that can be spread over ranks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DistributedSchedule {
    /// Deterministic even–odd swaps after all levels mutated
    /// ([`crate::replica::EvenOdd`]): the levels of all ranks mutate in
    /// parallel.
    EvenOdd,
    /// The neighbour sweep ([`crate::replica::NeighbourSwap`]): from the
    /// hottest level down, mutate, then try the swap with the level below.
    /// Inherently sequential: ranks take turns (the ensemble is spread for
    /// memory, not for speed).
    Neighbour,
}

/// Whether [`accept`] draws a uniform for `ln α` (it does when
/// `−∞ < ln α < 0`, or for NaN).
fn draws_uniform(log_alpha: f64) -> bool {
    log_alpha.is_nan() || (log_alpha < 0.0 && log_alpha > f64::NEG_INFINITY)
}

/// A level's sample and the replica (travelling identity) it carries.
type Parcel<S, P> = (Sample<S, P>, usize);

/// A neighbour pair's `(attempted, (accepted, Σα))` on the wire.
type PairCounts = (u64, (u64, f64));

/// What a checkpoint holds for one level: its parcel and its stream's state.
type LevelRecord<S, P> = (Parcel<S, P>, Vec<u64>);

/// A checkpoint file: magic, set-up fingerprint, sweeps done, exchange
/// stream position and state words, every level's record in level order,
/// the neighbour pairs' counts.
type CheckpointFile<S, P> = (
    u64,
    (
        u64,
        (
            u64,
            (u64, (Vec<u64>, (Vec<LevelRecord<S, P>>, Vec<PairCounts>))),
        ),
    ),
);

/// More sweeps than any run makes (2^53: 285 years at a nanosecond per
/// sweep). A checkpoint claiming more is corrupt, and the counters that
/// continue from it must not overflow.
const MAX_CHECKPOINT_SWEEPS: u64 = 1 << 53;

/// A restored level's recorded `ln π` and the one its state evaluates to
/// must agree to this relative precision. Not bit for bit: a family's
/// [`ReplicaFamily::log_density_of`] (how a swapped state's density was
/// computed) may round differently from [`ReplicaFamily::evaluate`].
const RESTORED_DENSITY_TOLERANCE: f64 = 1e-9;

/// Replica exchange whose levels live on several MPI ranks: rank `r` owns
/// the contiguous block [`super::share`]`(M, K, r)` of levels, with their
/// chains (sample, stream, statistics) and mutation algorithms.
///
/// Bit-identical to [`crate::replica::ReplicaExchange`] with
/// [`crate::replica::EvenOdd`] / [`crate::replica::NeighbourSwap`] for the
/// same family, initial states, algorithms and seed, for any number of
/// ranks and threads: level `l` mutates with `stream_rng(seed, l)`, and the
/// swap uniforms are drawn from the single-process exchange stream at the
/// positions the single-process run would use.
pub struct DistributedReplicaExchange<S, F: ReplicaFamily<S>, A> {
    comm: SimpleCommunicator,
    rank: usize,
    size: usize,
    family: F,
    /// Levels of this rank.
    owned: Range<usize>,
    /// Chains of the owned levels.
    chains: Vec<ChainState<S, F::Payload>>,
    algorithms: Vec<A>,
    /// Replica at each owned level.
    replicas: Vec<usize>,
    schedule: DistributedSchedule,
    /// This rank's copy of the exchange stream, at position `drawn`.
    rng: ChainRng,
    drawn: u64,
    sweeps: u64,
    /// The set-up fingerprint the ranks agreed on (checked on resume).
    fingerprint: u64,
    /// Neighbour sweeps on more than one rank: rank 0 owes the top rank
    /// (the highest owning levels) the stream position at the end of the
    /// last sweep, and the top rank expects it; sent at the start of the
    /// next sweep.
    position_pending: bool,
    /// Pairs whose swap this rank decided.
    stats: ReplicaStatistics,
    traffic: Traffic,
}

impl<S, F, A> DistributedReplicaExchange<S, F, A>
where
    S: Clone + Send + Wire,
    F: ReplicaFamily<S> + Sync,
    F::Payload: Send + Sync + Wire,
    A: Algorithm<S, F::Payload> + Send,
{
    /// Spreads an ensemble over the ranks of `comm` (a duplicate of it is
    /// used, so the run's messages never mix with the caller's). Every rank
    /// calls this with the same arguments: `initial` and `algorithms` as in
    /// [`crate::replica::ReplicaExchange::new`] (each rank keeps its own
    /// levels' algorithms). Collective: every rank returns the same error
    /// when one rank's set-up fails or its inputs differ (levels, seed,
    /// schedule, the initial states' densities at every level, executable,
    /// and `fingerprint`: any number describing inputs the densities at the
    /// start may not reveal, e.g. a hash of the temperatures and data; 0 if
    /// none).
    pub fn new<C: Communicator>(
        comm: &C,
        family: F,
        initial: Vec<S>,
        algorithms: Vec<A>,
        schedule: DistributedSchedule,
        seed: u64,
        fingerprint: u64,
    ) -> Result<Self, DistributedError> {
        let comm = comm.duplicate();
        let (rank, size) = (comm.rank() as usize, comm.size() as usize);
        let mut traffic = Traffic::default();
        let m = family.levels();
        let owned = share(m, size, rank);
        let local = (|| {
            let chains = level_chains(&family, &initial, &algorithms, seed, owned.clone())?;
            // Fingerprint of the inputs every rank must share: a different
            // target, schedule, seed or start shows in these densities.
            let mut fp = FNV_OFFSET;
            for v in [
                m as u64,
                seed,
                schedule as u64,
                initial.len() as u64,
                fingerprint,
            ] {
                fp = fnv1a(&v.to_le_bytes(), fp);
            }
            for level in 0..m {
                let state = &initial[if initial.len() == 1 { 0 } else { level }];
                let ld = family.evaluate(level, state).log_density;
                fp = fnv1a(&ld.to_bits().to_le_bytes(), fp);
            }
            Ok((chains, fp))
        })();
        let (chains, fingerprint) = agree(
            &comm,
            &mut traffic,
            "replica set-up (levels, seed, schedule, initial densities or input fingerprint)",
            local.map(|(c, fp)| ((c, fp), fp)),
        )?;
        let algorithms: Vec<A> = algorithms
            .into_iter()
            .enumerate()
            .filter(|(l, _)| owned.contains(l))
            .map(|(_, a)| a)
            .collect();
        let name = match schedule {
            DistributedSchedule::EvenOdd => "even-odd",
            DistributedSchedule::Neighbour => "neighbour",
        };
        Ok(DistributedReplicaExchange {
            comm,
            rank,
            size,
            family,
            replicas: owned.clone().collect(),
            owned,
            chains,
            algorithms,
            schedule,
            rng: stream_rng(seed, EXCHANGE_STREAM),
            drawn: 0,
            sweeps: 0,
            fingerprint,
            position_pending: false,
            stats: ReplicaStatistics::new(m, name),
            traffic,
        })
    }

    /// This rank.
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// Number of ranks.
    pub fn ranks(&self) -> usize {
        self.size
    }

    /// Number of levels `M` (over all ranks).
    pub fn levels(&self) -> usize {
        self.family.levels()
    }

    /// The levels this rank holds.
    pub fn owned_levels(&self) -> Range<usize> {
        self.owned.clone()
    }

    /// The sample at `level`, if this rank holds it.
    pub fn current(&self, level: usize) -> Option<&Sample<S, F::Payload>> {
        self.local(level).map(|l| &self.chains[l].current)
    }

    /// The bytes and messages this rank has sent so far.
    pub fn traffic(&self) -> Traffic {
        self.traffic
    }

    /// Sweeps done.
    pub fn sweeps(&self) -> u64 {
        self.sweeps
    }

    fn local(&self, level: usize) -> Option<usize> {
        self.owned
            .contains(&level)
            .then(|| level - self.owned.start)
    }

    /// End of burn-in: freezes the kernels' adaptation.
    pub fn freeze(&mut self) {
        for a in &mut self.algorithms {
            a.freeze();
        }
    }

    /// One sweep (collective: every rank calls it).
    pub fn sweep(&mut self) {
        self.sweep_observed(&mut |_| {});
    }

    /// One sweep, reporting level 0's mutation transition to `observer` on
    /// the rank that holds level 0 (rank 0).
    pub fn sweep_observed(&mut self, observer: &mut Observer<'_, S, F::Payload>) {
        match self.schedule {
            DistributedSchedule::EvenOdd => self.sweep_even_odd(observer),
            DistributedSchedule::Neighbour => self.sweep_neighbour(observer),
        }
        self.stats.end_sweep();
        self.sweeps += 1;
    }

    fn mutate(&mut self, level: usize, observer: &mut Observer<'_, S, F::Payload>) {
        let l = level - self.owned.start;
        let mut ignore = |_: &Transition<'_, S, F::Payload>| {};
        let observer: &mut Observer<'_, S, F::Payload> =
            if level == 0 { observer } else { &mut ignore };
        let target = LevelTarget {
            family: &self.family,
            level,
        };
        self.algorithms[l].step(&mut self.chains[l], &target, observer);
    }

    fn mutate_all(&mut self, observer: &mut Observer<'_, S, F::Payload>) {
        if rayon::current_num_threads() <= 1 || self.chains.len() < 2 {
            for level in self.owned.clone() {
                self.mutate(level, observer);
            }
            return;
        }
        // Every level draws from its own stream: the order does not matter.
        let start = self.owned.start;
        let family = &self.family;
        let (first_chain, other_chains) = self.chains.split_at_mut(1);
        let (first_alg, other_algs) = self.algorithms.split_at_mut(1);
        let mut ignore = |_: &Transition<'_, S, F::Payload>| {};
        let first_observer: &mut Observer<'_, S, F::Payload> =
            if start == 0 { observer } else { &mut ignore };
        rayon::join(
            || {
                let target = LevelTarget {
                    family,
                    level: start,
                };
                first_alg[0].step(&mut first_chain[0], &target, first_observer);
            },
            || {
                other_chains
                    .par_iter_mut()
                    .zip(other_algs.par_iter_mut())
                    .enumerate()
                    .for_each(|(i, (c, a))| {
                        let target = LevelTarget {
                            family,
                            level: start + 1 + i,
                        };
                        a.step(c, &target, &mut |_| {});
                    });
            },
        );
    }

    /// Moves this rank's copy of the exchange stream to `position`.
    fn advance_to(&mut self, position: u64) {
        debug_assert!(position >= self.drawn);
        while self.drawn < position {
            self.rng.next_u64();
            self.drawn += 1;
        }
    }

    /// [`accept`] on the exchange stream, keeping its position.
    fn decide(&mut self, log_alpha: f64) -> bool {
        self.drawn += draws_uniform(log_alpha) as u64;
        accept(log_alpha, &mut self.rng)
    }

    /// `[ln π_own(x), ln π_partner(x)]` for the sample at `level`: what the
    /// partner level's rank needs for the swap decision.
    fn densities_for(&self, level: usize, partner: usize) -> [f64; 2] {
        let s = &self.chains[level - self.owned.start].current;
        [s.log_density, self.family.log_density_of(partner, s)]
    }

    /// Puts `parcel`, arriving from level `from`, at `level` with
    /// `log_density = ln π_level(x)` as the partner computed it.
    fn receive_at(&mut self, level: usize, parcel: Parcel<S, F::Payload>, log_density: f64) {
        let l = level - self.owned.start;
        let (mut sample, replica) = parcel;
        self.family.retarget(level, &mut sample, log_density);
        self.chains[l].current = sample;
        self.replicas[l] = replica;
        self.stats.touch(level);
    }

    fn parcel(&self, level: usize) -> Parcel<S, F::Payload> {
        let l = level - self.owned.start;
        (self.chains[l].current.clone(), self.replicas[l])
    }

    /// `(ln α, ln π_i(x_j), ln π_j(x_i))` of swapping levels `i` and `j`
    /// held by this rank: the single-process
    /// [`crate::replica::ExchangeContext::try_swap`] rule.
    fn local_log_alpha(&self, i: usize, j: usize) -> (f64, f64, f64) {
        let (ci, cj) = (
            &self.chains[i - self.owned.start].current,
            &self.chains[j - self.owned.start].current,
        );
        let ld_ij = self.family.log_density_of(i, cj);
        let ld_ji = self.family.log_density_of(j, ci);
        let log_alpha = swap_log_acceptance(ci.log_density, cj.log_density, ld_ij, ld_ji);
        (log_alpha, ld_ij, ld_ji)
    }

    /// Decides and, if accepted, applies the swap of levels `i` and `j`
    /// held by this rank (arguments from [`Self::local_log_alpha`]).
    fn local_swap(
        &mut self,
        i: usize,
        j: usize,
        (log_alpha, ld_ij, ld_ji): (f64, f64, f64),
    ) -> bool {
        let accepted = self.decide(log_alpha);
        self.stats.record_pair(i, j, log_alpha.exp(), accepted);
        if accepted {
            let (li, lj) = (i - self.owned.start, j - self.owned.start);
            let (a, b) = (li.min(lj), li.max(lj));
            let (lo, hi) = self.chains.split_at_mut(b);
            std::mem::swap(&mut lo[a].current, &mut hi[0].current);
            self.family.retarget(i, &mut self.chains[li].current, ld_ij);
            self.family.retarget(j, &mut self.chains[lj].current, ld_ji);
            self.replicas.swap(li, lj);
            self.stats.touch(i);
            self.stats.touch(j);
        }
        accepted
    }

    fn sweep_even_odd(&mut self, observer: &mut Observer<'_, S, F::Payload>) {
        let m = self.levels();
        self.mutate_all(observer);
        let (lo, hi) = (self.owned.start, self.owned.end);
        let first = (self.sweeps % 2) as usize;
        let active = |i: usize| i + 1 < m && i >= first && (i - first).is_multiple_of(2);
        debug_assert!(EvenOdd::pairs(self.sweeps, m).all(|(i, _)| active(i)));
        // Boundary pairs: (lo−1, lo) with the rank below, (hi−1, hi) with
        // the rank above. Densities first, lower boundary first on every
        // rank, so that the pairwise exchanges chain without deadlock.
        let lower = (lo > 0 && lo < hi && active(lo - 1)).then(|| {
            let own = self.densities_for(lo, lo - 1);
            let other = exchange_pair(&self.comm, &mut self.traffic, self.rank - 1, own);
            // Pair (i, j) = (lo−1, lo): `own` = [ln π_j(x_j), ln π_i(x_j)],
            // `other` = [ln π_i(x_i), ln π_j(x_i)].
            (
                swap_log_acceptance(other[0], own[0], own[1], other[1]),
                other[1],
            )
        });
        let upper = (hi < m && lo < hi && active(hi - 1)).then(|| {
            let own = self.densities_for(hi - 1, hi);
            let other = exchange_pair(&self.comm, &mut self.traffic, self.rank + 1, own);
            // Pair (i, j) = (hi−1, hi): `own` = [ln π_i(x_i), ln π_j(x_i)],
            // `other` = [ln π_j(x_j), ln π_i(x_j)].
            (
                swap_log_acceptance(own[0], other[0], other[1], own[1]),
                other[1],
            )
        });
        // Uniforms used by the pairs this rank decides (lower level here).
        let decided: Vec<(usize, (f64, f64, f64))> = (lo..hi.min(m - 1))
            .filter(|&i| active(i))
            .map(|i| {
                if i + 1 < hi {
                    (i, self.local_log_alpha(i, i + 1))
                } else {
                    let (log_alpha, ld) = upper.expect("upper boundary pair");
                    (i, (log_alpha, ld, f64::NAN))
                }
            })
            .collect();
        let used = decided.iter().filter(|(_, a)| draws_uniform(a.0)).count() as u64;
        let counts = if self.size > 1 {
            all_gather_u64(&self.comm, &mut self.traffic, used)
        } else {
            vec![used]
        };
        let start = self.drawn;
        let before: u64 = counts[..self.rank].iter().sum();
        let total: u64 = counts.iter().sum();
        // The lower boundary pair is the rank below's last pair: its
        // uniform, if any, is the one just before this rank's.
        let lower_accepted = lower.map(|(log_alpha, _)| {
            if draws_uniform(log_alpha) {
                self.advance_to(start + before - 1);
            }
            self.decide(log_alpha)
        });
        self.advance_to(start + before);
        let mut upper_accepted = false;
        for (i, swap) in decided {
            if i + 1 < hi {
                self.local_swap(i, i + 1, swap);
            } else {
                upper_accepted = self.decide(swap.0);
                self.stats
                    .record_pair(i, i + 1, swap.0.exp(), upper_accepted);
            }
        }
        self.advance_to(start + total);
        // States cross only for accepted boundary swaps, lower first.
        if let (Some((_, ld)), Some(true)) = (lower, lower_accepted) {
            self.swap_across(lo, self.rank - 1, ld);
        }
        if let Some((_, ld)) = upper
            && upper_accepted
        {
            self.swap_across(hi - 1, self.rank + 1, ld);
        }
    }

    /// Exchanges the sample at `level` with the partner rank's boundary
    /// sample; `log_density` is the partner's sample's density at `level`.
    fn swap_across(&mut self, level: usize, partner: usize, log_density: f64) {
        let mine = encode(&self.parcel(level));
        let theirs = exchange_bytes(&self.comm, &mut self.traffic, partner, tag::STATE, &mine);
        let parcel = decode(&theirs).expect("state from the partner rank");
        self.receive_at(level, parcel, log_density);
    }

    fn sweep_neighbour(&mut self, observer: &mut Observer<'_, S, F::Payload>) {
        let (lo, hi) = (self.owned.start, self.owned.end);
        // The highest rank that owns levels (with fewer levels than ranks,
        // the ranks above own none and take no part).
        let top = self.size.min(self.levels()) - 1;
        if lo == hi {
            return;
        }
        // The stream position reaches the top rank from rank 0, which
        // ended the previous sweep. It is sent now, not at the end of that
        // sweep: after the last sweep no message may be left unreceived
        // (once the communicator is freed, MPI may match it in a later
        // one, which desynchronised the ranks of the next run).
        if self.position_pending {
            self.position_pending = false;
            if self.rank == 0 {
                send_bytes(
                    &self.comm,
                    &mut self.traffic,
                    top,
                    tag::POSITION,
                    &encode(&self.drawn),
                );
            } else {
                let p: u64 = decode(&receive_bytes(&self.comm, 0, tag::POSITION))
                    .expect("stream position from rank 0");
                self.advance_to(p);
            }
        }
        if self.rank < top {
            // Pair (hi, hi−1) is decided above: its deciding rank needs
            // this rank's boundary densities, which do not change before.
            let own = self.densities_for(hi - 1, hi);
            send_bytes(
                &self.comm,
                &mut self.traffic,
                self.rank + 1,
                tag::DENSITIES,
                &encode(&own.to_vec()),
            );
            let msg = receive_bytes(&self.comm, self.rank + 1, tag::DECISION);
            let (position, (accepted, ld)): (u64, (bool, f64)) =
                decode(&msg).expect("decision from the rank above");
            if accepted {
                let mine = encode(&self.parcel(hi - 1));
                send_bytes(
                    &self.comm,
                    &mut self.traffic,
                    self.rank + 1,
                    tag::STATE,
                    &mine,
                );
                let parcel = decode(&receive_bytes(&self.comm, self.rank + 1, tag::STATE))
                    .expect("state from the rank above");
                self.receive_at(hi - 1, parcel, ld);
            }
            self.advance_to(position);
        }
        for level in (lo..hi).rev() {
            self.mutate(level, observer);
            if level > lo {
                let swap = self.local_log_alpha(level, level - 1);
                self.local_swap(level, level - 1, swap);
            } else if level > 0 {
                // Pair (i, j) = (lo, lo−1), decided here.
                let other: Vec<f64> =
                    decode(&receive_bytes(&self.comm, self.rank - 1, tag::DENSITIES))
                        .expect("densities from the rank below");
                let own = self.densities_for(lo, lo - 1);
                let log_alpha = swap_log_acceptance(own[0], other[0], other[1], own[1]);
                let accepted = self.decide(log_alpha);
                self.stats
                    .record_pair(lo, lo - 1, log_alpha.exp(), accepted);
                send_bytes(
                    &self.comm,
                    &mut self.traffic,
                    self.rank - 1,
                    tag::DECISION,
                    &encode(&(self.drawn, (accepted, own[1]))),
                );
                if accepted {
                    let parcel = decode(&receive_bytes(&self.comm, self.rank - 1, tag::STATE))
                        .expect("state from the rank below");
                    let mine = encode(&self.parcel(lo));
                    send_bytes(
                        &self.comm,
                        &mut self.traffic,
                        self.rank - 1,
                        tag::STATE,
                        &mine,
                    );
                    self.receive_at(lo, parcel, other[1]);
                }
            }
        }
        if top > 0 && (self.rank == 0 || self.rank == top) {
            self.position_pending = true;
        }
    }

    /// Every level's sample and replica, in level order, on rank 0
    /// (collective; `None` on the other ranks).
    pub fn gather_levels(&mut self) -> Option<Vec<Parcel<S, F::Payload>>> {
        let local: Vec<Parcel<S, F::Payload>> =
            self.owned.clone().map(|l| self.parcel(l)).collect();
        let blocks = gather_bytes(&self.comm, &mut self.traffic, &encode(&local))?;
        let mut out = Vec::with_capacity(self.levels());
        for b in blocks {
            out.extend(decode::<Vec<Parcel<S, F::Payload>>>(&b).expect("levels from a rank"));
        }
        Some(out)
    }

    /// The neighbour pairs' swap statistics `(i, i+1)`, pooled over ranks,
    /// on rank 0 (collective; `None` elsewhere). Each pair is decided, and
    /// counted, by exactly one rank.
    pub fn gather_pair_statistics(&mut self) -> Option<Vec<PairStatistics>> {
        let local = self.local_pairs();
        let blocks = gather_bytes(&self.comm, &mut self.traffic, &encode(&local))?;
        let v: Vec<Vec<PairCounts>> = blocks
            .iter()
            .map(|b| decode(b).expect("statistics from a rank"))
            .collect();
        Some(pool_pairs(self.levels(), v))
    }

    /// This rank's counts of every neighbour pair (zero for the pairs other
    /// ranks decide).
    fn local_pairs(&self) -> Vec<PairCounts> {
        (0..self.levels().saturating_sub(1))
            .map(|i| {
                let p = self.stats.pair(i, i + 1);
                (p.attempted, (p.accepted, p.sum_alpha))
            })
            .collect()
    }

    /// Whether this rank decides (and counts) pair `(i, i+1)`: the lower
    /// level's rank in an even–odd sweep, the upper one's in a neighbour
    /// sweep (which runs downwards).
    fn decides_pair(&self, i: usize) -> bool {
        match self.schedule {
            DistributedSchedule::EvenOdd => self.owned.contains(&i),
            DistributedSchedule::Neighbour => self.owned.contains(&(i + 1)),
        }
    }

    /// Writes the state of the run after the sweeps done so far to `path`
    /// (collective; rank 0 writes, through a temporary file renamed over
    /// `path`). Holds every level's sample, replica and random stream, the
    /// exchange stream's position and state, the sweep count and the
    /// neighbour pairs' swap counts, in level order, then a checksum of
    /// all of it (FNV-1a, last 8 bytes): [`Self::resume`] can continue
    /// it on any number of ranks. Not in it: the algorithms (their kernels
    /// and any adaptation state: the caller re-creates them; resume is
    /// bit-identical for kernels that do not adapt, or are frozen with
    /// the same parameters) and the per-level chain statistics. Every rank
    /// returns the same result.
    pub fn checkpoint(&mut self, path: &Path) -> Result<(), DistributedError> {
        let levels: Vec<LevelRecord<S, F::Payload>> = self
            .owned
            .clone()
            .map(|l| {
                (
                    self.parcel(l),
                    rng_words(&self.chains[l - self.owned.start].rng),
                )
            })
            .collect();
        let local = encode(&(levels, self.local_pairs()));
        let bytes = gather_bytes(&self.comm, &mut self.traffic, &local).map(|blocks| {
            let mut all = Vec::with_capacity(self.levels());
            let mut pairs = Vec::with_capacity(blocks.len());
            for b in blocks {
                let (l, p): (Vec<LevelRecord<S, F::Payload>>, Vec<PairCounts>) =
                    decode(&b).expect("a rank's checkpoint block");
                all.extend(l);
                pairs.push(p);
            }
            let pooled = pool_pairs(self.levels(), pairs)
                .iter()
                .map(|p| (p.attempted, (p.accepted, p.sum_alpha)))
                .collect();
            // Rank 0 ends every sweep, so its stream position is the
            // run's (in a neighbour sweep the others' may lag).
            let file: CheckpointFile<S, F::Payload> = (
                REPLICA_MAGIC,
                (
                    self.fingerprint,
                    (
                        self.sweeps,
                        (self.drawn, (rng_words(&self.rng), (all, pooled))),
                    ),
                ),
            );
            let mut bytes = encode(&file);
            let checksum = fnv1a(&bytes, FNV_OFFSET);
            bytes.extend_from_slice(&checksum.to_le_bytes());
            bytes
        });
        write_on_rank_0(&self.comm, &mut self.traffic, path, bytes)
    }

    /// Continues from the checkpoint at `path` (collective; call it right
    /// after [`Self::new`], with the same inputs as the run that wrote it,
    /// on any number of ranks). Returns `Ok(false)` and changes nothing
    /// when there is no file, `Ok(true)` after restoring the run to the
    /// sweep the checkpoint was written after: the sweeps that follow are
    /// bit-identical to those of the run that was not interrupted.
    /// Rank 0 reads the file and broadcasts it. A file written for other
    /// inputs (levels, seed, schedule, initial densities, fingerprint), not
    /// a checkpoint, damaged (checksum) or inconsistent (more uniforms than
    /// its sweeps could draw, replicas that are not a permutation, swap
    /// counts out of range, a state whose log density is not the one
    /// recorded with it) is the same error on every rank, and nothing is
    /// changed. A resume costs one evaluation per owned level, whatever
    /// the number of sweeps recorded.
    pub fn resume(&mut self, path: &Path) -> Result<bool, DistributedError> {
        if self.sweeps != 0 {
            return Err(DistributedError::Checkpoint(
                "resume must come before the first sweep".into(),
            ));
        }
        let Some(message) = read_on_rank_0(&self.comm, &mut self.traffic, path)? else {
            return Ok(false);
        };
        let not_ours =
            |why: &str| DistributedError::Checkpoint(format!("{} {why}", path.display()));
        let bytes = &message[..];
        match bytes.get(..8) {
            Some(m) if m == REPLICA_MAGIC.to_le_bytes() => {}
            Some(m) if m == REPLICA_MAGIC_V1.to_le_bytes() => {
                return Err(not_ours(
                    "was written by an earlier mcmc-core (format mcmcRE01), which this version cannot continue; start the run afresh",
                ));
            }
            _ => return Err(not_ours("is not a replica-exchange checkpoint")),
        }
        // The last word is the FNV-1a hash of the rest: a damaged file
        // (a flipped bit, a partial copy) is refused, not continued.
        // (At least the magic and the checksum: 16 bytes.)
        let Some(body_len) = bytes.len().checked_sub(8).filter(|&n| n >= 8) else {
            return Err(not_ours("is corrupt: it ends before its checksum"));
        };
        let (body, checksum) = bytes.split_at(body_len);
        if fnv1a(body, FNV_OFFSET).to_le_bytes() != checksum {
            return Err(not_ours("is corrupt: its checksum does not match"));
        }
        let (_, (fingerprint, (sweeps, (drawn, (exchange_words, (levels, pairs)))))): CheckpointFile<
            S,
            F::Payload,
        > = decode(body).map_err(|_| not_ours("is corrupt: it does not decode"))?;
        let m = self.levels();
        if fingerprint != self.fingerprint
            || levels.len() != m
            || pairs.len() != m.saturating_sub(1)
        {
            return Err(not_ours(
                "was written by a run with other inputs (levels, seed, schedule, initial densities or input fingerprint)",
            ));
        }
        // Every check below sees the same broadcast bytes on every rank,
        // so all ranks refuse together; only the densities (each rank
        // evaluates its own levels) need a vote.
        let corrupt = |why: String| not_ours(&format!("is corrupt: {why}"));
        if sweeps > MAX_CHECKPOINT_SWEEPS {
            return Err(corrupt(format!("{sweeps} sweeps")));
        }
        // A sweep draws at most one uniform per neighbour pair.
        if u128::from(drawn) > u128::from(sweeps) * m.saturating_sub(1) as u128 {
            return Err(corrupt(format!(
                "{drawn} exchange uniforms drawn in {sweeps} sweeps of {} pairs",
                m.saturating_sub(1)
            )));
        }
        let exchange_rng = rng_from_words(&exchange_words)?;
        let mut seen = vec![false; m];
        let mut records = Vec::with_capacity(m);
        for (level, ((sample, replica), words)) in levels.into_iter().enumerate() {
            if replica >= m || std::mem::replace(&mut seen[replica], true) {
                return Err(corrupt(format!(
                    "the replicas at the levels are not a permutation of 0..{m} (level {level} holds {replica})"
                )));
            }
            records.push(((sample, replica), rng_from_words(&words)?));
        }
        for (i, &(attempted, (accepted, sum_alpha))) in pairs.iter().enumerate() {
            if accepted > attempted
                || attempted > sweeps
                || !(0.0..=attempted as f64).contains(&sum_alpha)
            {
                return Err(corrupt(format!(
                    "pair ({i}, {}) accepted {accepted} of {attempted} swaps with Σα = {sum_alpha} in {sweeps} sweeps",
                    i + 1
                )));
            }
        }
        // This rank's levels evaluated afresh: the recorded log density
        // must be the state's, and the payload is taken from the
        // evaluation (the file's copy is redundant, and a damaged one
        // would feed every later swap a wrong density).
        let evaluations: Vec<_> = self
            .owned
            .clone()
            .map(|level| self.family.evaluate(level, &records[level].0.0.state))
            .collect();
        let bad_level = self
            .owned
            .clone()
            .zip(&evaluations)
            .find(|&(level, now)| {
                let (recorded, now) = (records[level].0.0.log_density, now.log_density);
                !(recorded.is_finite()
                    && now.is_finite()
                    && (recorded - now).abs() <= RESTORED_DENSITY_TOLERANCE * (1.0 + now.abs()))
            })
            .map_or(0, |(level, _)| level as u64 + 1);
        let votes = all_gather_u64(&self.comm, &mut self.traffic, bad_level);
        if let Some(&level) = votes.iter().find(|&&v| v != 0) {
            return Err(corrupt(format!(
                "the state at level {} does not have the log density recorded with it",
                level - 1
            )));
        }
        let mut evaluations = evaluations.into_iter();
        for (level, ((mut sample, replica), rng)) in records.into_iter().enumerate() {
            if let Some(l) = self.local(level) {
                sample.payload = evaluations.next().expect("one per owned level").payload;
                self.chains[l].current = sample;
                self.chains[l].rng = rng;
                self.replicas[l] = replica;
            }
        }
        for (i, (attempted, (accepted, sum_alpha))) in pairs.into_iter().enumerate() {
            if self.decides_pair(i) {
                let p = PairStatistics {
                    attempted,
                    accepted,
                    sum_alpha,
                };
                self.stats.set_pair(i, i + 1, p);
            }
        }
        self.rng = exchange_rng;
        self.drawn = drawn;
        self.sweeps = sweeps;
        self.stats.sweeps = sweeps;
        self.position_pending = false;
        Ok(true)
    }
}

/// Every rank's pair counts pooled: each pair is counted by the one rank
/// that decides it (the others send zeros).
fn pool_pairs(levels: usize, blocks: Vec<Vec<PairCounts>>) -> Vec<PairStatistics> {
    let mut out = vec![PairStatistics::default(); levels.saturating_sub(1)];
    for v in blocks {
        for (o, (att, (acc, sum))) in out.iter_mut().zip(v) {
            if att > 0 {
                o.attempted += att;
                o.accepted += acc;
                o.sum_alpha += sum;
            }
        }
    }
    out
}
