//! The driver's work units: tasks of independent chains (one family
//! member each) or of replica sets (one chain per member, coupled by an
//! exchange move), each with its films, normalisation estimates and
//! counters, run in rounds.

use super::estimator::{
    DepthAcceptance, FilmedSums, MemberSink, RatioSum, TransitionCounts, Weights, observe,
};
use super::{ChainFamily, ContinuedSearch, ExchangeSummary};
use crate::film::Film;
use crate::observer::Observer;
use crate::pss::PathSample;
use mcmc_core::chain::{Chain, Transition};
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::replica::{ReplicaExchange, ReplicaFamily};
use mcmc_core::sample::Sample;
use mcmc_core::startup::RunningNormalization;
use mcmc_core::stats::ChainStatistics;
use mcmc_core::target::{Evaluation, Target};
use std::sync::atomic::{AtomicBool, Ordering};

/// Mutations per chain per round (bounds the time between snapshots).
const ROUND: u64 = 256;

/// The metropolised kernel of a family's chains.
pub(crate) type FamilyAlgorithm<F> =
    MetropolisHastings<<F as ChainFamily>::Kernel, <F as ChainFamily>::State, PathSample>;

/// A replica group of a family's members (see
/// [`ChainFamily::replica_groups`]) seen as the levels of an `mcmc-core`
/// replica family: level `l` is member `first + l`.
pub(crate) struct Members<'f, F> {
    pub family: &'f F,
    pub first: usize,
    pub levels: usize,
}

impl<'f, F: ChainFamily> Members<'f, F> {
    /// All of `family`'s members as one ladder.
    pub fn all(family: &'f F) -> Self {
        Members {
            family,
            first: 0,
            levels: family.members(),
        }
    }
}

impl<F: ChainFamily> ReplicaFamily<F::State> for Members<'_, F> {
    type Payload = PathSample;

    fn levels(&self) -> usize {
        self.levels
    }

    fn evaluate(&self, level: usize, state: &F::State) -> Evaluation<PathSample> {
        self.family.target(self.first + level).evaluate(state)
    }

    fn log_density_of(&self, level: usize, sample: &Sample<F::State, PathSample>) -> f64 {
        self.family
            .member_log_density(self.first + level, &sample.payload)
            .unwrap_or_else(|| self.evaluate(level, &sample.state).log_density)
    }

    fn retarget(&self, level: usize, sample: &mut Sample<F::State, PathSample>, log_density: f64) {
        if self
            .family
            .member_log_density(self.first + level, &sample.payload)
            .is_some()
        {
            // The payload serves every member (the hook's promise).
            sample.log_density = log_density;
        } else {
            let e = self.evaluate(level, &sample.state);
            sample.payload = e.payload;
            sample.log_density = if e.log_density.is_nan() {
                e.log_density
            } else {
                log_density
            };
        }
    }
}

/// One replica set: a chain per member and the family's exchange move.
pub(crate) type ReplicaSet<'f, F> =
    ReplicaExchange<<F as ChainFamily>::State, Members<'f, F>, FamilyAlgorithm<F>>;

/// A chain and the mutations it still has to do (`None`: until stopped).
pub(crate) struct ChainSlot<F: ChainFamily> {
    pub chain: Chain<F::State, PathSample, FamilyAlgorithm<F>>,
    pub remaining: Option<u64>,
}

/// A replica set and the sweeps it still has to do (`None`: until stopped).
pub(crate) struct ReplicaSlot<'f, F: ChainFamily> {
    pub set: ReplicaSet<'f, F>,
    /// Sweeps done (they decide which members rest, see
    /// [`ChainFamily::sweep_share`]).
    pub sweeps: u64,
    pub remaining: Option<u64>,
}

/// What a task runs.
pub(crate) enum Units<'f, F: ChainFamily> {
    /// Independent chains, all of the task's single member.
    Chains(Vec<ChainSlot<F>>),
    /// Replica sets over the task's members (one replica group).
    Replicas(Vec<ReplicaSlot<'f, F>>),
}

/// A work unit: its chains or replica sets, run one after another, and
/// what they accumulate for the members they serve.
pub(crate) struct Task<'f, F: ChainFamily> {
    /// The members this task serves; slot `i` of the vectors below is
    /// member `members[i]`.
    pub members: Vec<usize>,
    /// Splat films (`None` for members whose image weight is 0).
    pub films: Vec<Option<Film>>,
    /// Running normalisation estimates.
    pub running: Vec<RunningNormalization>,
    /// Mutations done.
    pub mutations: Vec<u64>,
    /// `q_{d+1}/q_d` sums over each member's states.
    pub ratios: Vec<RatioSum>,
    /// Per member, the sums of [`super::Normalization::Filmed`] (empty
    /// unless it is chosen; replica sets only).
    pub filmed: Vec<FilmedSums>,
    /// Per-depth acceptance and the first NaN/inf proposal.
    pub counts: TransitionCounts,
    /// The chains or replica sets.
    pub units: Units<'f, F>,
    /// Per member, its search continued during the run, if any.
    pub searches: Vec<Option<TaskSearch>>,
}

/// A task's share of a member's search continued during the run
/// ([`ChainFamily::continued_search`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct TaskSearch {
    plan: ContinuedSearch,
    seed: u64,
    /// The task's index and the number of tasks (which interleave their
    /// units' candidate indices).
    task: (u64, u64),
    /// Draws made (after a checkpoint's resume, those of the saved rounds
    /// included: [`Task::recount_searches`]).
    made: u64,
}

impl TaskSearch {
    /// Units owed after `mutations` mutations of the task.
    fn owed(&self, mutations: u64) -> u64 {
        (mutations as f64 * self.plan.per_mutation / self.plan.unit as f64).floor() as u64
    }

    /// Candidate index of unit `u`'s first draw.
    fn first(&self, u: u64) -> u64 {
        let (t, tasks) = self.task;
        self.plan.first_index + (u * tasks + t) * self.plan.unit
    }
}

impl<'f, F: ChainFamily> Task<'f, F> {
    /// An empty task serving `members`, with a film (made by `film`) for
    /// each member of non-zero image weight.
    pub fn new(
        members: Vec<usize>,
        family: &F,
        film: &dyn Fn() -> Film,
        units: Units<'f, F>,
    ) -> Self {
        let n = members.len();
        let probe = film();
        Task {
            films: members
                .iter()
                .map(|&m| (family.image_weight(m) != 0.0).then(film))
                .collect(),
            members,
            running: vec![RunningNormalization::new(); n],
            mutations: vec![0; n],
            ratios: vec![RatioSum::default(); n],
            filmed: Vec::new(),
            counts: TransitionCounts::new(probe.width, probe.height),
            units,
            searches: vec![None; n],
        }
    }

    /// Gives the task its share of the members' continued searches (`task`:
    /// its index among all the run's tasks, and their number).
    pub fn plan_searches(&mut self, family: &F, seed: u64, task: (u64, u64)) {
        for (s, &m) in self.searches.iter_mut().zip(&self.members) {
            *s = family.continued_search(m).map(|plan| TaskSearch {
                plan,
                seed,
                task,
                made: 0,
            });
        }
    }

    /// After a checkpoint's sums were put back into the task: the draws
    /// of its continued searches made so far are those owed for its
    /// mutations (the saved rounds made them, and their weights are in
    /// the saved running estimates), so a resumed run reports the
    /// uninterrupted run's draws.
    pub fn recount_searches(&mut self) {
        let mutations: u64 = self.mutations.iter().sum();
        for s in self.searches.iter_mut().flatten() {
            s.made = s.owed(mutations) * s.plan.unit;
        }
    }

    /// Adds the draws of the continued searches made by this task to
    /// `draws` (per member).
    pub fn add_search_draws(&self, draws: &mut [u64]) {
        for (s, &m) in self.searches.iter().zip(&self.members) {
            if let Some(s) = s {
                draws[m] += s.made;
            }
        }
    }

    /// Whether every unit has done its share.
    pub fn done(&self) -> bool {
        match &self.units {
            Units::Chains(c) => c.iter().all(|s| s.remaining == Some(0)),
            Units::Replicas(r) => r.iter().all(|s| s.remaining == Some(0)),
        }
    }

    /// One round: up to [`ROUND`] mutations of every chain (sweeps of
    /// every replica set). Returns `false` when `abort` (polled between
    /// units) cut it short.
    pub fn run_round(
        &mut self,
        family: &F,
        weights: &[Weights],
        abort: &(dyn Fn() -> bool + Sync),
        observer: &dyn Observer,
    ) -> bool {
        let Task {
            members,
            films,
            running,
            mutations,
            ratios,
            filmed,
            counts,
            units,
            searches,
        } = self;
        // The continued searches owe units for the mutations since the
        // task's start; those of the rounds before this one are made (a
        // round cut short ends the run), also after a checkpoint's resume.
        let before: u64 = mutations.iter().sum();
        match units {
            Units::Chains(chains) => {
                let member = members[0];
                let target = family.target(member);
                let w = &weights[member];
                let mut sink = MemberSink {
                    film: films[0].as_mut(),
                    running: &mut running[0],
                    ratio: &mut ratios[0],
                };
                for slot in chains.iter_mut() {
                    if abort() {
                        return false;
                    }
                    let n = slot.remaining.map_or(ROUND, |r| r.min(ROUND));
                    for _ in 0..n {
                        slot.chain
                            .step_with(target, |t| observe(family, t, w, &mut sink, counts));
                    }
                    if let Some(r) = slot.remaining.as_mut() {
                        *r -= n;
                    }
                    mutations[0] += n;
                    observer.progress(n);
                }
            }
            Units::Replicas(sets) => {
                let levels = members.len() as u64;
                let round = (ROUND / levels).max(1);
                let shares: Vec<f64> = members.iter().map(|&m| family.sweep_share(m)).collect();
                for slot in sets.iter_mut() {
                    if abort() {
                        return false;
                    }
                    let n = slot.remaining.map_or(round, |r| r.min(round));
                    let mut observe_level =
                        |level: usize, t: &Transition<'_, F::State, PathSample>| {
                            let mut sink = MemberSink {
                                film: films[level].as_mut(),
                                running: &mut running[level],
                                ratio: &mut ratios[level],
                            };
                            observe(family, t, &weights[members[level]], &mut sink, counts);
                            share_independent_draw(family, members, level, t, running);
                            if !filmed.is_empty() {
                                observe_filmed(family, members, level, t, filmed);
                            }
                        };
                    let mut done = 0;
                    for _ in 0..n {
                        let i = slot.sweeps;
                        let active = |l: usize| mutates_in_sweep(shares[l], i);
                        slot.set
                            .sweep_observed_active_levels(&active, &mut observe_level);
                        for (l, m) in mutations.iter_mut().enumerate() {
                            if active(l) {
                                *m += 1;
                                done += 1;
                            }
                        }
                        slot.sweeps += 1;
                    }
                    if let Some(r) = slot.remaining.as_mut() {
                        *r -= n;
                    }
                    observer.progress(done);
                }
            }
        }
        let after: u64 = mutations.iter().sum();
        for (level, search) in searches.iter_mut().enumerate() {
            let Some(s) = search else { continue };
            for u in s.owed(before)..s.owed(after) {
                if abort() {
                    return false;
                }
                let weighted = family.search_unit(members[level], s.seed, s.first(u));
                let zeros = s.plan.unit.saturating_sub(weighted.len() as u64);
                weighted.iter().for_each(|&lw| running[level].add(lw));
                (0..zeros).for_each(|_| running[level].add(f64::NEG_INFINITY));
                s.made += s.plan.unit;
            }
        }
        true
    }

    /// Adds this task's chain statistics into `stats` (per member) and its
    /// exchange counts into `exchange`.
    pub fn collect_statistics(
        &self,
        stats: &mut [Option<ChainStatistics>],
        exchange: &mut Option<ExchangeSummary>,
    ) {
        let mut add = |member: usize, s: &ChainStatistics| match stats[member].as_mut() {
            Some(cs) => cs.merge(s),
            None => stats[member] = Some(s.clone()),
        };
        match &self.units {
            Units::Chains(chains) => chains
                .iter()
                .for_each(|c| add(self.members[0], c.chain.stats())),
            Units::Replicas(sets) => {
                for slot in sets {
                    (0..slot.set.levels())
                        .for_each(|l| add(self.members[l], slot.set.chain_statistics(l)));
                    exchange
                        .get_or_insert_with(|| {
                            ExchangeSummary::new(slot.set.statistics().move_name.clone())
                        })
                        .add(&slot.set);
                }
            }
        }
    }
}

/// Whether a member of sweep share `share` mutates in sweep `sweep`
/// ([`ChainFamily::sweep_share`]): `⌊(i+1)r⌋ > ⌊ir⌋`, always for `r ≥ 1`.
pub(crate) fn mutates_in_sweep(share: f64, sweep: u64) -> bool {
    share >= 1.0 || ((sweep + 1) as f64 * share).floor() > (sweep as f64 * share).floor()
}

/// An independent proposal of level `level` of a replica set (member
/// `members[level]`) is a draw from the reference measure for every
/// member of the set: where the family computes the other members'
/// densities from the payload, it updates their running normalisation too.
fn share_independent_draw<F: ChainFamily>(
    family: &F,
    members: &[usize],
    level: usize,
    t: &Transition<'_, F::State, PathSample>,
    running: &mut [RunningNormalization],
) {
    let Some(y) = t.proposal else { return };
    if !family.is_independent(t.component) {
        return;
    }
    let reference = family.reference_log_density(&y.state);
    for (slot, r) in running.iter_mut().enumerate() {
        if slot != level
            && let Some(ln_q) = family.member_log_density(members[slot], &y.payload)
        {
            r.add(ln_q - reference);
        }
    }
}

/// The sums of [`super::Normalization::Filmed`] for one transition of
/// level `level`: its states' shares `q̃/q` (expected-value weights) for
/// that level, and an independent proposal's `q̃/p₀` for every level
/// (a draw from the reference measure for all of them).
fn observe_filmed<F: ChainFamily>(
    family: &F,
    members: &[usize],
    level: usize,
    t: &Transition<'_, F::State, PathSample>,
    filmed: &mut [FilmedSums],
) {
    let member = members[level];
    let mut state = |weight: f64, log_density: f64, payload: &PathSample| {
        if weight > 0.0
            && log_density > f64::NEG_INFINITY
            && let Some(ln_filmed) = family.filmed_log_density(member, payload)
        {
            filmed[level].add_state(weight, ln_filmed - log_density);
        }
    };
    state(1.0 - t.alpha, t.current.log_density, &t.current.payload);
    if let Some(y) = t.proposal {
        state(t.alpha, y.log_density, &y.payload);
        if family.is_independent(t.component) {
            let reference = family.reference_log_density(&y.state);
            for (slot, f) in filmed.iter_mut().enumerate() {
                if let Some(ln_filmed) = family.filmed_log_density(members[slot], &y.payload) {
                    f.add_draw(ln_filmed - reference);
                }
            }
        }
    }
}

/// Runs one round of every task in parallel; `false` when stopped early.
pub(crate) fn run_round<F: ChainFamily>(
    tasks: &mut [Task<'_, F>],
    family: &F,
    weights: &[Weights],
    stop: &(dyn Fn() -> bool + Sync),
    observer: &dyn Observer,
) -> bool
where
    F::Kernel: Send,
{
    use rayon::prelude::*;
    let aborted = AtomicBool::new(false);
    let abort = || {
        if aborted.load(Ordering::Relaxed) || stop() {
            aborted.store(true, Ordering::Relaxed);
            true
        } else {
            false
        }
    };
    tasks.par_iter_mut().for_each(|task| {
        task.run_round(family, weights, &abort, observer);
    });
    !aborted.load(Ordering::Relaxed)
}

/// Per-depth acceptance summed over tasks.
pub(crate) fn per_depth<'a>(
    tasks: impl Iterator<Item = &'a TransitionCounts>,
) -> Vec<DepthAcceptance> {
    let mut out: Vec<DepthAcceptance> = Vec::new();
    for t in tasks {
        let d = &t.per_depth;
        if out.len() < d.len() {
            out.resize(d.len(), DepthAcceptance::default());
        }
        for (o, a) in out.iter_mut().zip(d) {
            o.proposed += a.proposed;
            o.accepted += a.accepted;
        }
    }
    out
}
