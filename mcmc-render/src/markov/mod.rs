//! The Markov-chain render driver: every Metropolis-type integrator runs on
//! it.
//!
//! An integrator describes a [`ChainFamily`]: the state its chains move in
//! (a primary-sample point, a path, a fused pair), one target per family
//! member (one for PSSMLT, one per path depth for MMLT, one per replica
//! level or tile for the integrators to come), the `mcmc-core` kernel of
//! each member, and how to draw an independent candidate. The driver owns
//! everything else:
//!
//! - **Start-up**: `N` independent candidates per member give
//!   `b_d = (1/N) Σ I_d(x_i)/p₀(x_i)` and the chain starts, resampled
//!   `∝ I_d/p₀` (`mcmc_core::startup::Bootstrap`), which removes start-up
//!   bias (spec seed000 §3.6). Chains go to members in proportion to
//!   `b_d^γ` and stay with their member.
//! - **Estimator** (expected values, spec seed000 §3.7): every mutation
//!   splats the proposal `y` with weight `α/I(y)` and the current state
//!   `x` with `(1−α)/I(x)` into its member's film ([`estimator`]); with
//!   Kelemen's MIS the weights are `(α + [independent])/(I(y)/b + p_ind)`
//!   and `(1−α)/(I(x)/b + p_ind)`.
//! - **Normalisation** per member: the bootstrap `b_d`, or the running
//!   estimate over the bootstrap and every independent proposal so far
//!   (`mcmc_core::startup::RunningNormalization`, the default: its
//!   standard error keeps shrinking, the bootstrap's does not). The image
//!   is `Σ_d scale_d · film_d / (M_d / pixels)`, with `M_d` the mutations
//!   member `d` actually ran. (pbrt-v4 instead scales one film by
//!   `b = Σ_d b_d` over all mutations, which is right only if every
//!   member's share of the mutations equals `b_d / b`; with chains drawn at
//!   random, and time budgets cutting rounds short, it is not, and each
//!   depth's brightness is then off by the relative error of its chain
//!   count, a bias that more mutations do not remove.)
//! - **Budgets and stopping**: mutations per pixel or a time budget; a stop
//!   flag (Ctrl-C) ends the run after the chains' current round, keeping
//!   everything done.
//! - **NaN handling**: a NaN or infinite contribution is rejected by
//!   `mcmc-core` and counted; the coordinates of the first one are kept
//!   for `--replay`.
//! - **Statistics**: acceptance per kernel component and per path depth,
//!   `b_d` by both estimates with standard errors, per-member mutations.
//!
//! # Parallelism and determinism
//!
//! The chains are cut into about [`ChainSettings::tasks`] tasks (a number
//! independent of the thread count), each holding chains of one family
//! member; each task owns its chains, one film and its counters, and runs
//! its chains one after another in rounds. Films and counters are summed in
//! task order, the bootstrap is evaluated in parallel but collected in
//! candidate order, and every chain draws from its own stream, so one seed
//! gives a bit-identical image for any number of threads.
//!
//! On a cluster ([`crate::cluster`], `mpirun` with the feature `mpi`) the
//! tasks are dealt out to the ranks and reduced on rank 0 in the same task
//! order, so the image is also bit-identical for any number of ranks (see
//! `distribute`).

pub mod checkpoint;
mod distribute;
pub mod estimator;
pub mod report;
mod startup;
mod work;

use crate::color::Rgb;
use crate::deadline::Deadline;
use crate::film::{Film, Filter};
use crate::integrators::RunSettings;
use crate::observer::Observer;
use crate::pss::{PATH_CLASSES, PathSample};
use crate::scene::Scene;
pub use estimator::{DepthAcceptance, FamilyResult, develop};
use estimator::{MemberTotals, Weights, sum_images};
use glam::Vec2;
use mcmc_core::chain::Chain;
use mcmc_core::kernel::Kernel;
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::replica::population_annealing::{PopulationAnnealing, anneal_until};
use mcmc_core::replica::{ExchangeMove, ReplicaExchange};
use mcmc_core::rng::{splitmix64, stream_rng};
use mcmc_core::startup::{Bootstrap, RunningNormalization};
use mcmc_core::stats::ChainStatistics;
use mcmc_core::target::Target;
use serde::Serialize;
pub(crate) use startup::STARTUP_ROUND;
pub use startup::StartupCut;
pub(crate) use startup::draw_in_rounds;
use startup::{
    RESAMPLE_STREAM, allocate_chains, candidate_log_weights, index_bootstrap,
    shared_candidate_log_weights, shares_evaluation,
};
use std::ops::Range;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use thiserror::Error;
use work::{ChainSlot, Members, ReplicaSlot, Task, Units};

/// Why a Markov-chain render could not run.
#[derive(Debug, Error)]
pub enum MltError {
    /// Every bootstrap path carried zero (or invalid) contribution.
    #[error(
        "the scene looks black: all {candidates} bootstrap paths have zero contribution ({invalid} NaN/inf); nothing to render with MLT"
    )]
    BlackScene {
        /// Bootstrap size.
        candidates: usize,
        /// Candidates with a NaN or infinite contribution.
        invalid: usize,
    },
    /// A member of a replica ladder had no contributing bootstrap
    /// candidate, so its chains cannot start.
    #[error(
        "member {member} of the replica ladder had no contributing bootstrap path, so its chains cannot start (raise `bootstrap`)"
    )]
    EmptyMember {
        /// The member.
        member: usize,
    },
    /// A setting is out of range.
    #[error("invalid MLT setting: {0}")]
    Setting(String),
    /// An error from `mcmc-core`.
    #[error(transparent)]
    Core(#[from] mcmc_core::CoreError),
}

crate::choice! {
    /// How each member's image is scaled.
    pub enum Normalization {
        /// `b_d` from the start-up bootstrap (pbrt-v4).
        Bootstrap = "bootstrap",
        /// Running estimate over the bootstrap and all independent proposals
        /// so far (the default: lower variance, see [`ChainSettings`]).
        Running = "running",
        /// For ladders whose members share one evaluation (RELT): member 0
        /// by the running estimate, then `b_d = b_{d−1} · E[q_d/q_{d−1}]`
        /// over member `d − 1`'s chain states (Kitaoka et al. Eq. 10),
        /// with standard errors from the spread between tasks.
        Ratios = "ratios",
        /// As `running`, but a member whose film holds only part of its
        /// target ([`ChainFamily::filmed_log_density`]: RELT's full and
        /// indirect replicas, whose `L0` the specific replica films) is
        /// scaled by `b̃_d / E_{p_d}[q̃_d/q_d]`: the uniform draws' mean of
        /// the filmed part `q̃_d` over its chains' mean share of it, so a
        /// chain that under-visits the unfilmed part (a mode it rarely
        /// reaches) does not inflate its image (docs/relt.md, sessions
        /// 23–24). The draws are those of a replica set's independent
        /// proposals: without an exchange move (no replica sets) and for
        /// a member that films all of its target it is `running`.
        Filmed = "filmed",
    }
}

/// Stream offset of the start-up candidates: candidate `i` of a run draws
/// from stream `CANDIDATE_STREAM + i` (chain `c` draws from stream `c`).
pub const CANDIDATE_STREAM: u64 = 1 << 40;

crate::settings! {
    /// The driver's parameters, as integrators expose them.
    pub struct ChainParams {
        /// Bootstrap candidates per member for start-up bias elimination and b.
        pub bootstrap: usize = 100_000, check crate::settings::check::count;
        /// Number of Markov chains.
        pub chains: usize = 1000, check crate::settings::check::count;
        /// Mutations per pixel (auto: 100, or until the time budget is spent).
        pub mutations_per_pixel: Option<u64> = None, check crate::settings::check::auto_or_at_least_one;
        /// Image normalisation: running (bootstrap and every large step; lower variance), bootstrap (pbrt-v4's b*), ratios (ladders of shared evaluations: relt) or filmed (running over the filmed part of each target, divided by the chains' share of it: relt).
        pub normalization: Normalization = Normalization::Running;
        /// Kelemen's MIS combination of large steps.
        pub kelemen_mis: bool = false;
        /// Chains go to family members in proportion to b_d^γ (1: pbrt-v4's share; 0: equal).
        pub depth_allocation: f64 = 1.0, check crate::settings::check::non_negative;
    }
}

impl ChainParams {
    /// Mutations per pixel under `run`: the setting, or 100 without a
    /// time budget; `None`: until the budget is spent.
    pub fn mutations_per_pixel(&self, run: &RunSettings) -> Option<u64> {
        match (self.mutations_per_pixel, run.time_budget) {
            (Some(m), _) => Some(m),
            (None, Some(_)) => None,
            (None, None) => Some(100),
        }
    }

    /// The mutations a run on `scene` will do (`None`: until the budget is spent).
    pub fn planned_mutations(&self, scene: &Scene, run: &RunSettings) -> Option<u64> {
        let pixels = u64::from(scene.film.width) * u64::from(scene.film.height);
        self.mutations_per_pixel(run).map(|m| m * pixels)
    }

    /// The driver settings for `mutation` under `run`'s budget and seed.
    pub fn chain_settings<M>(&self, mutation: M, run: &RunSettings) -> ChainSettings<M> {
        ChainSettings {
            mutation,
            bootstrap: self.bootstrap,
            chains: self.chains,
            mutations_per_pixel: self.mutations_per_pixel(run),
            time_budget: run.time_budget,
            seed: run.seed,
            mis_large_steps: self.kelemen_mis,
            normalization: self.normalization,
            tasks: 16,
            preview_every: run.snapshot_every,
            depth_allocation_exponent: self.depth_allocation,
            checkpoint: run.checkpoint.clone(),
            clock_started: None,
        }
    }
}

/// What a Metropolis integrator gives the driver: a family of targets over
/// one state space, their kernels and the independent draws of start-up.
pub trait ChainFamily: Sync {
    /// Where the chains move (e.g. `mcmc_core::space::TorusPoint`).
    type State: Clone + Send;
    /// The target of one member; its payload is the path's splats.
    type Target: Target<Self::State, Payload = PathSample> + Sync;
    /// The kernel configuration the settings carry (e.g. [`crate::pss::Mutation`]).
    type Mutation: Clone + Sync;
    /// The kernel of one chain.
    type Kernel: Kernel<Self::State, PathSample> + Send;

    /// Number of members (targets).
    fn members(&self) -> usize;
    /// The target of member `member`.
    fn target(&self, member: usize) -> &Self::Target;
    /// A new kernel for a chain of `member`.
    fn kernel(&self, mutation: &Self::Mutation, member: usize) -> Result<Self::Kernel, MltError>;
    /// The probability that the kernel proposes independently (from the
    /// reference measure): Kelemen's MIS weights need it.
    fn independent_probability(&self, mutation: &Self::Mutation) -> f64;
    /// Whether kernel component `component` is an independent proposal
    /// from the reference measure (a large step): its `ln I − ln p₀`
    /// enters the running normalisation and it counts in Kelemen's MIS.
    fn is_independent(&self, component: usize) -> bool;
    /// Independent candidate `index` of the start-up, drawn from the
    /// reference measure with the streams of `seed`.
    fn candidate(&self, seed: u64, index: u64) -> Self::State;
    /// `ln p₀(x)`, the reference density of independent draws (0 on
    /// primary sample space).
    fn reference_log_density(&self, state: &Self::State) -> f64;
    /// The importance weight `ln I_d(x) − ln p₀(x)` of a candidate and
    /// its payload, whose splats over `p₀(x)` are an independent estimate
    /// of the member's image (the start-up image, [`MltResult::image`]).
    fn weighed_candidate(&self, member: usize, state: &Self::State) -> (f64, PathSample) {
        let e = self.target(member).evaluate(state);
        (e.log_density - self.reference_log_density(state), e.payload)
    }
    /// Numbers that reproduce a state (the NaN dump for `--replay`), if
    /// the space has them.
    fn coordinates(&self, state: &Self::State) -> Option<Vec<f64>>;
    /// The exchange move of a family whose members are the levels of a
    /// replica ladder (tempered targets, roughened scenes), made anew for
    /// each replica set. With a move, chains come in replica sets of one
    /// chain per member, and each set runs `mcmc-core`'s
    /// [`ReplicaExchange`]; without one (the default), every chain stays
    /// with its member.
    fn exchange_move(&self) -> Option<Box<dyn ExchangeMove<Self::State, PathSample>>> {
        None
    }
    /// The replica groups of a family with an exchange move: contiguous,
    /// disjoint ranges of members covering them all, each one ladder
    /// (tempered MMLT: the levels of one path depth). A replica set holds
    /// one chain per member of its group and exchanges stay within it;
    /// with [`ChainFamily::member_log_density`], one evaluation of a
    /// group's first member serves the whole group (not other groups).
    /// Replica sets go to groups in proportion to the bootstrap `b̂` of
    /// each group's first member (as chains go to MMLT's depths). Default:
    /// one group of all members.
    fn replica_groups(&self) -> Vec<Range<usize>> {
        std::iter::once(0..self.members()).collect()
    }
    /// Whether the run can go on without member `member` when the
    /// bootstrap finds it no light: its caller then drops it on
    /// [`MltError::EmptyMember`] and runs the others (relt's replicas
    /// beyond the uniform one). A start-up cut by the deadline or Ctrl-C
    /// does not wait for such a member's light. Default: no.
    fn droppable(&self, _member: usize) -> bool {
        false
    }
    /// The weight of member `member`'s image in the final image: 1 (the
    /// default) for members whose targets split the image (the depths of
    /// MMLT); 0 for members that only help the others mix (the hot levels
    /// of a ladder), which are then not filmed.
    fn image_weight(&self, _member: usize) -> f64 {
        1.0
    }
    /// `ln q_member(x)` from a state's payload alone, for families whose
    /// targets are all functions of one shared evaluation (RELT's path
    /// classes). Returning `Some` promises that a payload serves every
    /// member unchanged; the driver then evaluates each start-up candidate
    /// once for all members, exchanges trace no rays, and every independent
    /// proposal of a replica set updates every member's running
    /// normalisation. `None` (the default): each member evaluates its own
    /// target.
    fn member_log_density(&self, _member: usize, _payload: &PathSample) -> Option<f64> {
        None
    }
    /// `ln q̃_member(x)`: the part of `q_member` over what the member's
    /// film holds, for a member that films less than its target (RELT's
    /// full and indirect replicas hold `L0`, which the specific replica
    /// alone films); used by [`Normalization::Filmed`]. `None` (the
    /// default): the member films all of its target.
    fn filmed_log_density(&self, _member: usize, _payload: &PathSample) -> Option<f64> {
        None
    }
    /// Per-class splat factors of member `member` for a state with payload
    /// `payload` (a splat of class `c` gets `α · factors[c]` before the
    /// member's scale `b_d`), given every member's bootstrap `b̂`: MIS over
    /// members, or classes reserved to one member. `None` (the default):
    /// the expected-value factor `1/I(x)` for every splat. Not combined
    /// with Kelemen's MIS.
    fn class_weights(
        &self,
        _member: usize,
        _payload: &PathSample,
        _b_hat: &[f64],
    ) -> Option<[f64; PATH_CLASSES]> {
        None
    }
    /// The share of its replica set's sweeps in which member `member`
    /// mutates, in `(0, 1]`; only replica sets (families with an exchange
    /// move) use it. Default 1: every member mutates in every sweep. A
    /// member of share `r` mutates in sweep `i` iff `⌊(i+1)r⌋ > ⌊ir⌋`
    /// (evenly spaced and deterministic, so a run stays bit-identical for
    /// any thread count) and rests otherwise, while exchanges run as usual.
    /// Its image is its film over its own mutations, so a family whose
    /// splat weights are MIS over members should count the shares in
    /// (the `n_k` of the multi-sample estimator).
    fn sweep_share(&self, _member: usize) -> f64 {
        1.0
    }
    /// Start-up by population annealing over the members, in order
    /// (`mcmc_core::replica::population_annealing`): member 0's particles
    /// are resampled from its bootstrap, every later member's are annealed
    /// from the previous one with the members' kernels; they start the
    /// chains and give `b̂_k = b̂_0 · Π ratios`. For ladders whose members
    /// are ordered easy to hard (RELT). `None` (the default): every member
    /// starts from its own bootstrap.
    fn annealing(&self) -> Option<Annealing> {
        None
    }
    /// Whether runs of this family with `mutation` can be checkpointed
    /// ([`checkpoint`]): its states encode exactly
    /// ([`ChainFamily::state_words`]) and its kernels keep no state of
    /// their own, or write it ([`mcmc_core::kernel::Kernel::state_words`]:
    /// the adaptive small step, saved with each independent chain and,
    /// since session 21, with each level of a replica set). A family with
    /// an exchange move also needs a move that can be saved (the driver
    /// checks [`ExchangeMove::state_words`]). Default: no.
    fn checkpointable(&self, _mutation: &Self::Mutation) -> bool {
        false
    }
    /// Appends `state`'s exact encoding to `out` without changing it (a
    /// lazily grown state must not grow), for checkpoints.
    fn state_words(&self, _state: &Self::State, _out: &mut Vec<u64>) {}
    /// The state [`ChainFamily::state_words`] wrote at the front of
    /// `input` (advanced past it); `None` when it is not one.
    fn state_from_words(&self, _input: &mut &[u64]) -> Option<Self::State> {
        None
    }
    /// A member's own search of independent draws beyond the bootstrap
    /// (RELT's search for the specific replica's rare paths), run once at
    /// start-up: its weighted draws start the member's chains (resampled
    /// in place of the bootstrap's or annealing's starts, when any carries
    /// weight) and join the member's running normalisation and `b̂` (or
    /// replace them: [`Search::replaces_bootstrap`]); the black-scene check
    /// and the reported `bootstrap_b` include them. `None` (the default):
    /// no search.
    ///
    /// A search that can be long stops at the start-up's `cut` (its
    /// [`StartupCut::due`] is collective: every rank asks it alike) once
    /// a draw carries weight, and reports the draws it made.
    fn search(&self, _member: usize, _seed: u64, _cut: &StartupCut) -> Option<Search> {
        None
    }
    /// A member's search continued while the chains run, if any: after
    /// each whole round, every task makes [`ContinuedSearch::per_mutation`]
    /// draws per mutation it ran (rounded down to whole units, counted
    /// from its first mutation) by [`ChainFamily::search_unit`] and adds
    /// their weights to its running estimate of the member's `b_d`, which
    /// thus keeps pooling draws (the member's `b̂` of the MIS weights stays
    /// the start-up's). The draws are a function of the task's mutation
    /// count, so the image stays bit-identical for any thread count and
    /// checkpoints need nothing more. `None` (the default): no search
    /// during the run.
    fn continued_search(&self, _member: usize) -> Option<ContinuedSearch> {
        None
    }
    /// Whether member `member`'s running estimate of `b_d` takes only the
    /// draws made for it (its start-up, its search and its continued
    /// search), not its chains' independent proposals (whose density need
    /// not be the reference measure's then): the bootstrap normalisation
    /// then takes the running estimate, a start-up that went on while the
    /// chains ran (`mlt`'s unconnectable chains). Default: no.
    fn running_is_search_only(&self, _member: usize) -> bool {
        false
    }
    /// One unit of the member's continued search: the candidates `first ..
    /// first + unit` ([`ContinuedSearch::unit`]); returns `ln w` of those
    /// with a weight `w > 0` (the others weigh 0), such that the sum of
    /// the unit's weights is an unbiased estimate of `unit · b_d`.
    fn search_unit(&self, _member: usize, _seed: u64, _first: u64) -> Vec<f64> {
        Vec::new()
    }
}

/// A member's search continued during the run ([`ChainFamily::continued_search`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContinuedSearch {
    /// Draws per chain mutation (of the task that makes them).
    pub per_mutation: f64,
    /// Draws per unit (≥ 1): draws are made, and merged, in whole units.
    pub unit: u64,
    /// Candidate index of the first draw: unit `u` of task `t` (of `T`)
    /// starts at `first_index + (u·T + t)·unit`.
    pub first_index: u64,
}

/// The result of [`ChainFamily::search`]: `draws` independent draws from
/// the reference measure, each with a weight `w ≥ 0` whose mean over all
/// `draws` is an unbiased estimate of the member's `b_d` (a draw left out
/// of `weighted` has `w = 0`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Search {
    /// Draws made.
    pub draws: u64,
    /// The draws with `w > 0`: the candidate index (for
    /// [`ChainFamily::candidate`]) and `ln w`.
    pub weighted: Vec<(u64, f64)>,
    /// For draws that each yield several weighted states (every technique
    /// of a BDPT sample, `mlt`'s `bdpt_startup`): `ln` of each draw's
    /// total weight, whose mean over `draws` estimates `b_d` (draws left
    /// out weigh 0); the states in `weighted` then weigh `w` for the
    /// resampling of starts only. Empty: every entry of `weighted` is one
    /// draw.
    pub per_draw: Vec<f64>,
    /// The search replaces the member's bootstrap (its running estimate
    /// and its starts) instead of joining it.
    pub replaces_bootstrap: bool,
    /// The draws' own image splats, `(x, y, r, g, b)` at raster `(x, y)`,
    /// in draw order (a BDPT draw's techniques weighted by the balance
    /// heuristic): filmed and divided by `draws`, an independent estimate
    /// of the member's image, written when a search that replaces the
    /// bootstrap is stopped before the chains move (empty: none).
    pub image_splats: Vec<[f32; 5]>,
}

/// Stream offset of the resampling of searched starts.
const SEARCH_RESAMPLE_STREAM: u64 = RESAMPLE_STREAM + (1 << 20);

impl Search {
    /// The draws as a running estimate of `b_d`.
    fn running(&self) -> RunningNormalization {
        let mut r = RunningNormalization::new();
        let per_draw: Vec<f64> = if self.per_draw.is_empty() {
            self.weighted.iter().map(|w| w.1).collect()
        } else {
            self.per_draw.clone()
        };
        per_draw.iter().for_each(|&lw| r.add(lw));
        let zeros = self.draws.saturating_sub(per_draw.len() as u64);
        (0..zeros).for_each(|_| r.add(f64::NEG_INFINITY));
        r
    }

    /// `n` start states resampled from the weighted draws (`None` when no
    /// draw carries weight), as the driver starts `member`'s chains.
    pub fn starts<F: ChainFamily>(
        &self,
        family: &F,
        n: usize,
        seed: u64,
        member: usize,
    ) -> Result<Option<Vec<F::State>>, MltError> {
        let log_w: Vec<f64> = self.weighted.iter().map(|w| w.1).collect();
        if n == 0 || !log_w.iter().any(|w| w.is_finite()) {
            return Ok(None);
        }
        let boot = index_bootstrap(&log_w, 0)?;
        let mut rng = stream_rng(seed, SEARCH_RESAMPLE_STREAM + member as u64);
        Ok(Some(
            boot.resample(n, &mut rng)?
                .into_iter()
                .map(|x| family.candidate(seed, self.weighted[x.state].0))
                .collect(),
        ))
    }
}

/// Population annealing settings of a start-up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Annealing {
    /// Particles (≥ 1).
    pub particles: usize,
    /// Metropolis–Hastings steps per particle and member.
    pub sweeps: usize,
}

/// One member's population-annealing estimate, as reported.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct AnnealedMember {
    /// `b_k / b_{k−1}` (1 for member 0).
    pub ratio: f64,
    /// Its relative standard error.
    pub relative_error: f64,
    /// Acceptance of the member's MH sweeps (NaN for member 0).
    pub acceptance: f64,
    /// MH steps made at the member over all particles (0 for member 0):
    /// `particles · sweeps`, or fewer when the time budget cut the sweeps.
    pub steps: u64,
}

/// One member's start-up search, as reported.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SearchSummary {
    /// Independent draws made.
    pub draws: u64,
    /// Draws with a positive weight.
    pub weighted: u64,
    /// Chains started from them (0: the member kept its other starts).
    pub started_chains: usize,
    /// Draws made while the chains ran ([`ChainFamily::continued_search`]).
    pub run_draws: u64,
}

/// Stream offset from which the annealing's seed is derived.
const ANNEALING_STREAM: u64 = 1 << 43;

/// Population annealing over `family`'s members from `count` particles
/// resampled from member 0's bootstrap; its MH sweeps stop once `cut`
/// says so ([`annealing_cut`]: the start-up's deadline or a stop; the
/// chains get what is left).
fn anneal_members<F: ChainFamily>(
    family: &F,
    mutation: &F::Mutation,
    boot: &Bootstrap<usize, ()>,
    (settings, cut): (Annealing, &(dyn Fn() -> bool + Sync)),
    seed: u64,
) -> Result<PopulationAnnealing<F::State, PathSample>, MltError> {
    for d in 0..family.members() {
        family.kernel(mutation, d)?;
    }
    let mut rng = stream_rng(seed, ANNEALING_STREAM);
    let initial = boot
        .resample(settings.particles.max(1), &mut rng)?
        .into_iter()
        .map(|x| {
            let state = family.candidate(seed, x.state as u64);
            let e = family.target(0).evaluate(&state);
            mcmc_core::sample::Sample {
                state,
                log_density: e.log_density,
                payload: e.payload,
            }
        })
        .collect();
    Ok(anneal_until(
        &Members::all(family),
        initial,
        |k| MetropolisHastings::new(family.kernel(mutation, k).expect("checked above")),
        settings.sweeps,
        splitmix64(seed ^ splitmix64(ANNEALING_STREAM)),
        cut,
    )?)
}

/// Exchange counts summed over a run's replica sets.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ExchangeSummary {
    /// The exchange move's name.
    pub name: String,
    /// Sweeps of all sets.
    pub sweeps: u64,
    /// Round trips of replicas between the first and last level.
    pub round_trips: u64,
    /// Attempted pairs `(i, j)`, `i ≤ j`, with their counts.
    pub pairs: Vec<ExchangePair>,
}

/// Exchanges between two levels of a replica set (members, with one
/// replica group; with several, the counts of equal levels are summed
/// over the groups).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ExchangePair {
    /// Lower level.
    pub i: usize,
    /// Upper level (`i` itself counts identity draws of importance-sampled moves).
    pub j: usize,
    /// Exchanges attempted.
    pub attempted: u64,
    /// Exchanges accepted.
    pub accepted: u64,
    /// Mean acceptance probability.
    pub mean_alpha: f64,
}

impl ExchangeSummary {
    fn new(name: String) -> Self {
        ExchangeSummary {
            name,
            sweeps: 0,
            round_trips: 0,
            pairs: Vec::new(),
        }
    }

    /// Adds the counts of one replica set.
    fn add<S: Clone + Send, F, A>(&mut self, set: &ReplicaExchange<S, F, A>)
    where
        F: mcmc_core::replica::ReplicaFamily<S> + Sync,
        F::Payload: Send + Sync,
        A: mcmc_core::chain::Algorithm<S, F::Payload> + Send,
    {
        let stats = set.statistics();
        self.sweeps += stats.sweeps;
        self.round_trips += set.index_process().total_round_trips();
        for (i, j, p) in stats.attempted_pairs() {
            self.add_pair(ExchangePair {
                i,
                j,
                attempted: p.attempted,
                accepted: p.accepted,
                mean_alpha: p.sum_alpha / p.attempted as f64,
            });
        }
    }

    /// Adds the counts of one pair of levels.
    fn add_pair(&mut self, p: ExchangePair) {
        match self.pairs.iter_mut().find(|q| (q.i, q.j) == (p.i, p.j)) {
            Some(q) => {
                let total = q.attempted as f64 + p.attempted as f64;
                q.mean_alpha =
                    (q.mean_alpha * q.attempted as f64 + p.mean_alpha * p.attempted as f64) / total;
                q.attempted += p.attempted;
                q.accepted += p.accepted;
            }
            None => self.pairs.push(p),
        }
        self.pairs.sort_by_key(|q| (q.i, q.j));
    }
}

/// The driver's settings (pbrt-v4's `mlt` defaults where they apply),
/// generic over the family's kernel configuration.
#[derive(Clone, Debug)]
pub struct ChainSettings<M> {
    /// Kernel configuration.
    pub mutation: M,
    /// Bootstrap candidates per member (default 100 000).
    pub bootstrap: usize,
    /// Number of chains (default 1000).
    pub chains: usize,
    /// Mutations per pixel (default 100); `None` with a time budget means
    /// "until the budget is spent".
    pub mutations_per_pixel: Option<u64>,
    /// Wall-clock budget.
    pub time_budget: Option<Duration>,
    /// Seed of every stream.
    pub seed: u64,
    /// Kelemen's MIS combination of independent proposals.
    pub mis_large_steps: bool,
    /// Scaling of each member's image. The default is the running
    /// estimate: on a held-out door scene PSSMLT's bootstrap `b*` from
    /// 100 000 candidates had a 4% standard error (image means at −5%,
    /// +5%, +5% for three seeds against ±1% with the running estimate).
    pub normalization: Normalization,
    /// Fixed number of work units the chains are grouped into.
    pub tasks: usize,
    /// Time between snapshots ([`Observer::snapshot`]).
    pub preview_every: Duration,
    /// Chains go to family members in proportion to `b_d^γ`, `γ` this
    /// exponent: 1 (default) is pbrt-v4's share (what a single chain over
    /// all depths spends per depth); 0 gives every member the same number.
    pub depth_allocation_exponent: f64,
    /// Save the tasks to, and resume them from, a checkpoint (families that
    /// are [`ChainFamily::checkpointable`]).
    pub checkpoint: Option<crate::checkpoint::Checkpoint>,
    /// When the run's clock started, if before [`run`] is called: a
    /// caller's earlier attempt at the same render (relt's run before it
    /// dropped a replica). The time budget, its start-up share and
    /// `seconds` count from it; `None` (the default): from the call.
    pub clock_started: Option<Instant>,
}

impl<M: Default> Default for ChainSettings<M> {
    fn default() -> Self {
        ChainSettings {
            mutation: M::default(),
            bootstrap: 100_000,
            chains: 1000,
            mutations_per_pixel: Some(100),
            time_budget: None,
            seed: 0,
            mis_large_steps: false,
            normalization: Normalization::Running,
            tasks: 16,
            preview_every: RunSettings::DEFAULT_SNAPSHOT_EVERY,
            depth_allocation_exponent: 1.0,
            checkpoint: None,
            clock_started: None,
        }
    }
}

/// The outcome of a Markov-chain render.
#[derive(Clone, Debug)]
pub struct MltResult {
    /// Per member of the family (one for PSSMLT, one per depth for MMLT).
    pub families: Vec<FamilyResult>,
    /// Mutations done.
    pub mutations: u64,
    /// Mutations per pixel (all members).
    pub mutations_per_pixel: f64,
    /// The sum of the members' scales (`b` unless MIS).
    pub scale: f64,
    /// The standard error of [`MltResult::scale`] (members independent).
    pub scale_standard_error: f64,
    /// When the chains made no mutation (a stop during the start-up), the
    /// start-up candidates' independent estimate of the image, `Σ_d
    /// (1/N) Σ_j f(x_dj)/p₀(x_dj)` over the `N` candidates drawn per member
    /// (per replica group where members share an evaluation, with the
    /// members' class factors: see `startup::image_factors`); `None`
    /// otherwise.
    pub startup_image: Option<Vec<Rgb>>,
    /// Bootstrap `b* = Σ_d b_d` and its standard error.
    pub bootstrap_b: (f64, f64),
    /// Running `⟨b⟩ = Σ_d ⟨b_d⟩` (bootstrap and large steps) and its
    /// standard error.
    pub running_b: (f64, f64),
    /// Statistics of all chains (per kernel component, NaN/inf count).
    pub chain_stats: ChainStatistics,
    /// Statistics of each member's chains (`None`: it ran none).
    pub member_stats: Vec<Option<ChainStatistics>>,
    /// Exchange counts, for families with an exchange move.
    pub exchange: Option<ExchangeSummary>,
    /// Population annealing per member, for families that anneal.
    pub annealing: Option<Vec<AnnealedMember>>,
    /// Each member's own start-up search ([`ChainFamily::search`]), if any.
    pub searches: Vec<Option<SearchSummary>>,
    /// Acceptance per path depth (index = depth).
    pub per_depth: Vec<DepthAcceptance>,
    /// Bootstrap candidates with a NaN/inf contribution.
    pub bootstrap_invalid: usize,
    /// Bootstrap candidates drawn per member: the setting, or fewer when
    /// the time budget or Ctrl-C cut the start-up.
    pub bootstrap_candidates: usize,
    /// The coordinates of the first NaN/inf proposal, if any.
    pub first_nonfinite: Option<Vec<f64>>,
    /// Seconds spent in the bootstrap.
    pub bootstrap_seconds: f64,
    /// Seconds spent in total.
    pub seconds: f64,
    /// Stopped by Ctrl-C or the time budget before the requested mutations.
    pub interrupted: bool,
    /// Per pixel, the chain samples that fell there (expected-value
    /// weights, all members), row-major.
    pub sample_counts: Vec<f64>,
    /// In a distributed run, every rank's share and statistics (rank 0;
    /// empty otherwise).
    pub ranks: Vec<serde_json::Value>,
    /// With a checkpoint: the mutations it resumed from, and the first
    /// error writing it, if any.
    pub checkpoint: Option<(u64, Option<String>)>,
}

impl MltResult {
    /// The sample-count image as an RGB layer (`<out>.samples.exr`) and
    /// its max/median ratio (NaN when the median is 0).
    pub fn sample_count_layer(&self) -> (Vec<Rgb>, f64) {
        let layer = self
            .sample_counts
            .iter()
            .map(|&c| Rgb::splat(c as f32))
            .collect();
        let mut sorted = self.sample_counts.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
        let max = sorted.last().copied().unwrap_or(0.0);
        (layer, if median > 0.0 { max / median } else { f64::NAN })
    }

    /// The developed image, row-major: the sum of the members' images,
    /// or, when the chains made no mutation (stopped during the
    /// start-up), the start-up's image ([`MltResult::startup_image`]).
    pub fn image(&self) -> Vec<Rgb> {
        match &self.startup_image {
            Some(image) => image.clone(),
            None => sum_images(self.families.iter().map(FamilyResult::image)),
        }
    }
}

/// The root of the summed variances.
fn quadrature(errors: impl Iterator<Item = f64>) -> f64 {
    errors.map(|e| e * e).sum::<f64>().sqrt()
}

/// The start-up of every member: its bootstrap and the running estimate
/// seeded with its candidates.
struct Startup {
    /// The members share one evaluation ([`ChainFamily::member_log_density`]).
    shared: bool,
    boots: Vec<Bootstrap<usize, ()>>,
    running: Vec<RunningNormalization>,
    invalid: usize,
    /// Candidates drawn per member (the setting unless cut).
    drawn: usize,
}

/// Bootstraps every member with `count` candidates each (member `d`'s
/// are indices `d·count..`), fewer if the `cut` comes first
/// ([`startup::draw_in_rounds`]). A family whose members share one
/// evaluation ([`ChainFamily::member_log_density`]) instead weighs the
/// same candidates for every member of a replica group, each traced once.
fn start_up<F: ChainFamily>(
    family: &F,
    count: usize,
    seed: u64,
    cut: &StartupCut,
    mut image: Option<&mut Film>,
) -> Result<Startup, MltError> {
    let members = family.members();
    let exchange = family.exchange_move().is_some();
    let groups: Vec<Range<usize>> = if exchange {
        family.replica_groups()
    } else {
        std::iter::once(0..members).collect()
    };
    // Group `g`'s candidates are those its first member would get
    // unshared (indices `g.start·count ..`).
    let shared = groups
        .iter()
        .all(|g| shares_evaluation(family, g, seed, g.start * count));
    // A cut start-up must still be able to start the run (the checks
    // after it): light in some member and, with an exchange move, in
    // every member of a group that needs it (a droppable member's want of
    // light ends the run for its caller to drop it).
    let lit = |log_w: &[Vec<f64>]| {
        let positive: Vec<bool> = log_w
            .iter()
            .map(|row| row.iter().any(|w| w.is_finite()))
            .collect();
        positive.contains(&true)
            && (!exchange
                || groups.iter().all(|g| {
                    !(groups.len() == 1 || positive[g.start])
                        || g.clone().all(|m| positive[m] || family.droppable(m))
                }))
    };
    let weights = if shared {
        startup::weights_in_rounds(members, count, cut, lit, |range, log_w| {
            for g in &groups {
                let group = (g.clone(), g.start * count);
                let film = image.as_deref_mut();
                shared_candidate_log_weights(family, group, range.clone(), seed, (log_w, film));
            }
        })
    } else {
        candidate_log_weights(family, count, seed, cut, lit, image)
    };
    let mut boots: Vec<Bootstrap<usize, ()>> = Vec::with_capacity(members);
    let mut invalid = 0;
    if shared {
        for g in &groups {
            let first = boots.len();
            for d in g.clone() {
                boots.push(index_bootstrap(&weights.log_w[d], g.start * count)?);
            }
            // A NaN path is invalid for every member of its group: count it once.
            invalid += boots[first].invalid_candidates();
        }
    } else {
        for (d, w) in weights.log_w.iter().enumerate() {
            boots.push(index_bootstrap(w, d * count)?);
        }
        invalid = boots.iter().map(|b| b.invalid_candidates()).sum();
    }
    let running = weights.log_w[..boots.len()]
        .iter()
        .map(|w| {
            let mut r = RunningNormalization::new();
            w.iter().for_each(|&lw| r.add(lw));
            r
        })
        .collect();
    Ok(Startup {
        shared,
        boots,
        running,
        invalid,
        drawn: weights.drawn,
    })
}

/// The joint bootstrap of a family with `count` candidates per member
/// (candidate `j` belongs to member `j / count`) and the candidates'
/// importance weights `ln I − ln p₀`. Its `b*` is the mean over all
/// candidates.
pub fn bootstrap<F: ChainFamily>(
    family: &F,
    count: usize,
    seed: u64,
) -> Result<(Bootstrap<usize, ()>, Vec<f64>), MltError> {
    if count == 0 {
        return Err(MltError::Setting(
            "the bootstrap needs at least one candidate".into(),
        ));
    }
    let log_w = candidate_log_weights(family, count, seed, &StartupCut::NEVER, |_| false, None)
        .log_w
        .concat();
    Ok((index_bootstrap(&log_w, 0)?, log_w))
}

/// Runs `family` on `scene` to `settings`' budget.
pub fn run<F: ChainFamily>(
    scene: &Scene,
    family: &F,
    settings: &ChainSettings<F::Mutation>,
    stop: &AtomicBool,
    observer: &dyn Observer,
) -> Result<MltResult, MltError> {
    let members = family.members();
    if members == 0 {
        return Err(MltError::Setting("no path sampler".into()));
    }
    if settings.chains == 0 || settings.tasks == 0 {
        return Err(MltError::Setting(
            "chains and tasks must be at least 1".into(),
        ));
    }
    if settings.bootstrap == 0 {
        return Err(MltError::Setting(
            "the bootstrap needs at least one candidate".into(),
        ));
    }
    if settings.mutations_per_pixel.is_none() && settings.time_budget.is_none() {
        return Err(MltError::Setting(
            "give a number of mutations per pixel or a time budget".into(),
        ));
    }
    let gamma = settings.depth_allocation_exponent;
    if !gamma.is_finite() || gamma < 0.0 {
        return Err(MltError::Setting(format!(
            "the depth allocation exponent must be finite and ≥ 0, got {gamma}"
        )));
    }
    family.kernel(&settings.mutation, 0)?;
    // Replica sets are saved with their exchange move's state: a move
    // with more (stores of past states) cannot be.
    let unsaved_move = || {
        family
            .exchange_move()
            .is_some_and(|m| m.state_words().is_none())
    };
    if settings.checkpoint.is_some()
        && (unsaved_move() || !family.checkpointable(&settings.mutation))
    {
        return Err(MltError::Setting(format!(
            "these chains cannot be checkpointed (only those of {}, with exchange moves that keep no stores of past states)",
            crate::checkpoint::CHAIN_INTEGRATORS.join(", ")
        )));
    }
    check_memory(scene, family, settings)?;
    let start = settings.clock_started.unwrap_or_else(Instant::now);
    let deadline = Deadline::new(start, settings.time_budget);
    let out_of_time = || deadline.passed();
    let (width, height) = (scene.film.width, scene.film.height);
    let pixels = width as u64 * height as u64;

    // Start-up bias elimination, per member.
    let seed = settings.seed;
    let count = settings.bootstrap;
    // The start-up stops at its share of the budget or on Ctrl-C (not
    // when checkpointed) once it can start the chains, which get the rest.
    let startup_end = startup_end(start, settings.time_budget);
    let cut = StartupCut::new(startup_end, stop, settings.checkpoint.is_some());
    let filter = Arc::new(Filter::new(scene.film.filter, width, height));
    // The candidates' own image, written if the chains never move (a stop
    // during the start-up). Every rank of a cluster films it: the ranks
    // evaluate blocks of candidates, and what they send must not depend
    // on the rank (a rank that left its splats out sent rank 0 records
    // without them).
    let mut startup_film = Some(Film::new_splat_only(width, height, filter.clone()));
    let Startup {
        shared,
        boots,
        running: boot_running,
        invalid,
        drawn,
    } = start_up(family, count, seed, &cut, startup_film.as_mut())?;
    // Both read the other members' densities off a member's payload.
    let ladder_only = match settings.normalization {
        Normalization::Ratios => Some("ratios"),
        Normalization::Filmed => Some("filmed"),
        Normalization::Running | Normalization::Bootstrap => None,
    };
    if let Some(name) = ladder_only
        && !shared
    {
        return Err(MltError::Setting(format!(
            "normalization={name} needs a ladder whose members share one evaluation (relt); use running or bootstrap"
        )));
    }
    let mut bootstrap_b: Vec<(f64, f64)> =
        boots.iter().map(|b| (b.b(), b.standard_error())).collect();
    let exchange = family.exchange_move().is_some();
    let groups = if exchange {
        checked_groups(family.replica_groups(), members)?
    } else {
        Vec::new()
    };
    // A group whose first member sees no light is left out (a path depth
    // that carries nothing); in any other group every member needs light.
    for g in &groups {
        if (groups.len() == 1 || bootstrap_b[g.start].0 > 0.0)
            && let Some(member) = g.clone().find(|&m| bootstrap_b[m].0 <= 0.0)
        {
            return Err(MltError::EmptyMember { member });
        }
    }
    // Population annealing, if the family asks for it, replaces the
    // members' `b̂` and start states.
    let annealed = match family.annealing() {
        Some(a) => Some(anneal_members(
            family,
            &settings.mutation,
            &boots[0],
            (
                a,
                &annealing_cut(startup_end, stop, settings.checkpoint.is_some()),
            ),
            seed,
        )?),
        None => None,
    };
    if let Some(pa) = &annealed {
        let b0 = bootstrap_b[0].0;
        for (k, b) in bootstrap_b.iter_mut().enumerate() {
            let v = b0 * pa.log_b(k).exp();
            *b = (v, v * pa.relative_error(k));
        }
    }
    // The members' own searches: more draws for their running `b_d` and
    // `b̂` (or all of them, for a search that replaces the bootstrap),
    // before the check for a black scene.
    let mut boot_running = boot_running;
    let mut member_searches: Vec<Option<Search>> =
        (0..members).map(|d| family.search(d, seed, &cut)).collect();
    let mut startup_draws = drawn as u64;
    // Whether a search that replaces its member's bootstrap has filmed.
    let mut searched_film = false;
    for (d, search) in member_searches.iter_mut().enumerate() {
        if let Some(search) = search {
            if search.replaces_bootstrap {
                // Its bootstrap (a token candidate) is no image; the
                // search's own draws are. The members' searches are summed
                // on one film, each scaled to the first one's draws (a
                // cut may leave them with different counts): the film over
                // those draws is the sum of the members' estimates.
                if !searched_film {
                    startup_film = Some(Film::new_splat_only(width, height, filter.clone()));
                    startup_draws = search.draws;
                    searched_film = true;
                }
                let scale = startup_draws as f32 / search.draws.max(1) as f32;
                if let Some(film) = startup_film.as_mut() {
                    for [x, y, r, g, b] in std::mem::take(&mut search.image_splats) {
                        film.splat(Vec2::new(x, y), Rgb::new(r, g, b) * scale);
                    }
                }
                boot_running[d] = search.running();
            } else {
                boot_running[d].merge(&search.running());
            }
            bootstrap_b[d] = (boot_running[d].b(), boot_running[d].standard_error());
        }
    }
    let b_star: f64 = bootstrap_b.iter().map(|b| b.0).sum();
    if b_star == 0.0 || !b_star.is_finite() {
        return Err(MltError::BlackScene {
            candidates: drawn * members,
            invalid,
        });
    }
    let b_star_se = quadrature(bootstrap_b.iter().map(|b| b.1));
    let shares: Vec<f64> = bootstrap_b
        .iter()
        .map(|&(b, _)| if b > 0.0 { b.powf(gamma) } else { 0.0 })
        .collect();
    // With an exchange move every set holds one chain per member of its
    // group; the sets go to the groups by their first members' shares.
    let sets_of_group = match groups.len() {
        0 => Vec::new(),
        1 => vec![(settings.chains / members).max(1)],
        n => {
            let sets = (settings.chains / members.div_ceil(n)).max(1);
            let group_shares: Vec<f64> = groups.iter().map(|g| shares[g.start]).collect();
            allocate_chains(sets, &group_shares)
        }
    };
    let chains_of = if exchange {
        let mut n = vec![0; members];
        for (g, &sets) in groups.iter().zip(&sets_of_group) {
            n[g.clone()].fill(sets);
        }
        n
    } else {
        allocate_chains(settings.chains, &shares)
    };
    let mut starts: Vec<Vec<F::State>> = Vec::with_capacity(members);
    for (d, boot) in boots.iter().enumerate() {
        let n = chains_of[d];
        starts.push(match &annealed {
            // Spread over the member's (resampled, moved) particles.
            Some(pa) => {
                let ps = &pa.levels[d].particles;
                (0..n).map(|i| ps[i * ps.len() / n].state.clone()).collect()
            }
            None if n == 0 => Vec::new(),
            // The search's starts take their place below.
            None if member_searches[d]
                .as_ref()
                .is_some_and(|s| s.replaces_bootstrap) =>
            {
                Vec::new()
            }
            None => {
                let mut rng = stream_rng(seed, RESAMPLE_STREAM + 1 + d as u64);
                boot.resample(n, &mut rng)?
                    .into_iter()
                    .map(|x| family.candidate(seed, x.state as u64))
                    .collect()
            }
        });
    }
    // The members' own searches' starts, in place of the bootstrap's.
    let mut searches: Vec<Option<SearchSummary>> = vec![None; members];
    for (d, search) in member_searches.iter().enumerate() {
        if let Some(search) = search {
            let resampled = search.starts(family, chains_of[d], seed, d)?;
            searches[d] = Some(SearchSummary {
                draws: search.draws,
                weighted: search.weighted.len() as u64,
                started_chains: resampled.as_ref().map_or(0, Vec::len),
                run_draws: 0,
            });
            if let Some(s) = resampled {
                starts[d] = s;
            }
        }
    }
    let bootstrap_seconds = start.elapsed().as_secs_f64();

    let total = settings.mutations_per_pixel.map(|m| m * pixels);
    let new_film = || Film::new(width, height, filter.clone());
    // On a cluster this rank runs only the tasks dealt to it, and builds
    // only their chains: a chain's start is evaluated when it is built,
    // and an evaluation may have effects beyond its value (`mcmc-pg`
    // online records every traced path), which must happen once in all.
    let cluster = crate::cluster::current();
    let owned = |t: usize| crate::cluster::owns(cluster, t);
    let tasks = if exchange {
        replica_tasks(
            family,
            settings,
            (&starts, &groups, &sets_of_group),
            total,
            &new_film,
            &owned,
        )
    } else {
        chain_tasks(family, settings, &starts, total, &new_film, &owned)
    };
    // A rank whose chains failed to start stops every rank (the others
    // would wait for it in the first collective).
    let mut tasks = match cluster {
        Some(c) if c.any(tasks.is_err()) => tasks.and(Err(MltError::Setting(
            "another rank's chains failed to start (its own error is printed by that rank)".into(),
        )))?,
        _ => tasks?,
    };
    let all_tasks = tasks.len();
    for (t, task) in tasks.iter_mut().enumerate() {
        task.plan_searches(family, seed, (t as u64, all_tasks as u64));
        if settings.normalization == Normalization::Filmed {
            task.filmed = vec![estimator::FilmedSums::default(); task.members.len()];
        }
    }
    let task_ids: Vec<usize> = (0..tasks.len()).filter(|&t| owned(t)).collect();
    if cluster.is_some() {
        let mut t = 0;
        tasks.retain(|_| {
            t += 1;
            owned(t - 1)
        });
    }

    // A checkpoint's tasks replace the fresh ones (same inputs, same tasks).
    let resumed = match &settings.checkpoint {
        Some(ck) => checkpoint::resume(
            family, ck, cluster, &mut tasks, &task_ids, all_tasks, &filter,
        )
        .map_err(|e| MltError::Setting(format!("checkpoint {}: {e}", ck.path.display())))?,
        None => None,
    };
    if resumed.is_some() {
        observer.progress(tasks.iter().flat_map(|t| &t.mutations).sum());
    }
    let mut checkpoint_error: Option<String> = None;

    let p_independent = family.independent_probability(&settings.mutation);
    let b_hat: Arc<[f64]> = bootstrap_b.iter().map(|b| b.0).collect();
    let weights: Vec<Weights> = (0..members)
        .map(|member| Weights {
            mis: settings.mis_large_steps,
            p_independent,
            member,
            b_hat: b_hat.clone(),
        })
        .collect();
    let image_weights: Vec<f64> = (0..members).map(|d| family.image_weight(d)).collect();
    // Snapshots and the final image gather the same per-member films.
    let gather = |tasks: &[distribute::TaskSums]| {
        let mut totals = MemberTotals {
            films: (0..members).map(|_| new_film()).collect(),
            running: boot_running.clone(),
            mutations: vec![0; members],
            bootstrap_b: &bootstrap_b,
            chains: &chains_of,
            image_weights: &image_weights,
            mis: settings.mis_large_steps,
            normalization: settings.normalization,
            search_only: (0..members)
                .map(|d| family.running_is_search_only(d))
                .collect(),
            ratios: vec![Vec::new(); members],
            filmed: vec![Vec::new(); members],
        };
        for t in tasks {
            for (i, &m) in t.members.iter().enumerate() {
                totals.ratios[m].push(t.ratios[i]);
                if let Some(f) = t.filmed.get(i) {
                    totals.filmed[m].push(f.clone());
                }
                if let Some(film) = &t.films[i] {
                    totals.films[m].add_film(film);
                }
                totals.running[m].merge(&t.running[i]);
                totals.mutations[m] += t.mutations[i];
            }
        }
        totals.results()
    };
    let stopped = || stop.load(Ordering::Relaxed) || out_of_time();
    let mut interrupted = false;
    let mut last_preview = Instant::now();
    // Checkpoints: whole rounds only (a round cut short has some chains a
    // round ahead of others, and the films' additions would come in
    // another order); at the end, when stopped, and in between at most
    // once per `CHECKPOINT_EVERY` and 20 writes' time (≤ 5% of the run).
    let mut round_complete = false;
    let (mut last_save, mut save_cost) = (Instant::now(), Duration::ZERO);
    loop {
        // On a cluster every rank leaves the loop in the same round: when
        // all ranks' tasks are done, or when any rank was stopped.
        let (local_done, stop_now) = (tasks.iter().all(Task::done), stopped());
        let (all_done, stop_now) = match cluster {
            Some(c) => (!c.any(!local_done), c.any(stop_now)),
            None => (local_done, stop_now),
        };
        if let Some(ck) = &settings.checkpoint {
            let due = last_save.elapsed() >= CHECKPOINT_EVERY.max(20 * save_cost);
            let (complete, due) = match cluster {
                Some(c) => (!c.any(!round_complete), c.any(due && c.rank() == 0)),
                None => (round_complete, due),
            };
            if complete && (due || all_done || stop_now) {
                let t = Instant::now();
                let saved = checkpoint::save_tasks(family, ck, cluster, &tasks, &task_ids, &filter);
                if let Err(e) = saved {
                    checkpoint_error.get_or_insert(e);
                }
                (last_save, save_cost) = (Instant::now(), t.elapsed());
            }
        }
        if all_done {
            break;
        }
        if stop_now {
            interrupted = true;
            break;
        }
        // A round cut short by the stop flag is seen at the loop's top.
        round_complete =
            local_done || work::run_round(&mut tasks, family, &weights, &stopped, observer);
        if !round_complete && cluster.is_none() {
            interrupted = true;
            break;
        }
        if last_preview.elapsed() >= settings.preview_every {
            last_preview = Instant::now();
            let families = gather(&local_sums(&tasks));
            let mutations = families.iter().map(|f| f.mutations).sum();
            observer.snapshot(
                &|| sum_images(families.iter().map(FamilyResult::image)),
                mutations,
            );
        }
    }

    let mut member_stats: Vec<Option<ChainStatistics>> = vec![None; members];
    let mut exchange_summary = None;
    let mut run_draws = vec![0u64; members];
    for t in &tasks {
        t.collect_statistics(&mut member_stats, &mut exchange_summary);
        t.add_search_draws(&mut run_draws);
    }
    // Rank 0 of a cluster reduces every rank's tasks; the others keep
    // their own (their results are not written).
    let all_sums = cluster.and_then(|c| distribute::gather_tasks(c, &tasks, &task_ids, &filter));
    let sums: Vec<distribute::TaskSums> = match all_sums {
        Some(all) => all,
        None => local_sums(&tasks),
    };
    let families = gather(&sums);
    let mutations: u64 = families.iter().map(|f| f.mutations).sum();
    let mut ranks = Vec::new();
    if let Some(c) = cluster {
        let local_mutations = tasks.iter().flat_map(|t| &t.mutations).sum();
        let mut report = distribute::rank_report(
            &member_stats,
            &exchange_summary,
            tasks.len(),
            local_mutations,
            start.elapsed().as_secs_f64(),
        );
        // Each rank's draws of the continued searches, summed below.
        report["search_draws"] = serde_json::json!(run_draws);
        let report = crate::cluster::with_ranks(serde_json::json!({}), report);
        if let Some(all) = report.get("ranks").and_then(|r| r.as_array()) {
            (member_stats, exchange_summary) = distribute::merge_reports(all, members);
            run_draws = vec![0; members];
            for r in all {
                for (d, n) in run_draws.iter_mut().enumerate() {
                    *n += r["search_draws"][d].as_u64().unwrap_or(0);
                }
            }
            ranks = all.clone();
        }
        debug_assert!(c.rank() != 0 || !ranks.is_empty());
    }
    let mut chain_stats: Option<ChainStatistics> = None;
    for s in member_stats.iter().flatten() {
        match chain_stats.as_mut() {
            Some(cs) => cs.merge(s),
            None => chain_stats = Some(s.clone()),
        }
    }
    let first_nonfinite = sums.iter().find_map(|t| t.counts.first_nonfinite.clone());
    let mut sample_counts = vec![0.0f64; pixels as usize];
    for t in &sums {
        for (c, &v) in sample_counts.iter_mut().zip(&t.counts.samples) {
            *c += f64::from(v);
        }
    }
    for (summary, &n) in searches.iter_mut().zip(&run_draws) {
        if let Some(s) = summary {
            s.run_draws = n;
        }
    }
    let running_b = (
        families.iter().map(|f| f.running_b.0).sum(),
        quadrature(families.iter().map(|f| f.running_b.1)),
    );
    Ok(MltResult {
        scale: families.iter().map(|f| f.image_weight * f.scale).sum(),
        scale_standard_error: quadrature(
            families
                .iter()
                .map(|f| f.image_weight * f.scale_standard_error),
        ),
        per_depth: work::per_depth(sums.iter().map(|t| &*t.counts)),
        families,
        mutations,
        mutations_per_pixel: mutations as f64 / pixels as f64,
        startup_image: startup_film
            .filter(|_| mutations == 0)
            .map(|film| develop(&film, startup_draws, 1.0)),
        bootstrap_b: (b_star, b_star_se),
        running_b,
        chain_stats: chain_stats.unwrap_or_else(|| ChainStatistics::new(Vec::new())),
        member_stats,
        exchange: exchange_summary,
        annealing: annealed.map(|pa| {
            pa.levels
                .iter()
                .map(|l| AnnealedMember {
                    ratio: l.log_ratio.exp(),
                    relative_error: l.ratio_relative_error,
                    acceptance: l.acceptance,
                    steps: l.steps,
                })
                .collect()
        }),
        searches,
        bootstrap_invalid: invalid,
        bootstrap_candidates: drawn,
        first_nonfinite,
        bootstrap_seconds,
        seconds: start.elapsed().as_secs_f64(),
        interrupted,
        sample_counts,
        ranks,
        checkpoint: settings
            .checkpoint
            .as_ref()
            .map(|_| (resumed.unwrap_or(0), checkpoint_error)),
    })
}

/// The share of a time budget past which a start-up sized by a setting
/// (the bootstrap's draws, a family's search, the population annealing)
/// stops once it can start the chains: they get at least the rest. (At
/// the whole budget, a large `bootstrap` under a short `--time` left the
/// chains no time and the image black.)
pub const STARTUP_SHARE: f64 = 0.5;

/// The end of a start-up that began its run at `start` under the time
/// budget `budget`: [`STARTUP_SHARE`] of the budget (never without one).
/// The Markov driver's, `smcmc`'s and `erpt`'s start-ups end there.
pub fn startup_end(start: Instant, budget: Option<Duration>) -> Deadline {
    Deadline::new(start, budget.map(|b| b.mul_f64(STARTUP_SHARE)))
}

/// The deadline of a run's start-up beyond the bootstrap (the population
/// annealing's sweeps, a family's own search): `deadline` (the driver
/// passes its start-up's, at [`STARTUP_SHARE`] of the budget),
/// unless the run is `checkpointed` — a resumed run makes the start-up
/// again, and its `b̂` and starts must be the saved run's — in which case
/// the start-up runs to its end whatever the time budget (which goes on
/// counting from the run's start).
pub fn startup_deadline(deadline: Deadline, checkpointed: bool) -> Deadline {
    if checkpointed {
        Deadline::NEVER
    } else {
        deadline
    }
}

/// When the population annealing's sweeps stop: at the start-up's
/// deadline ([`startup_deadline`]) or on a stop (Ctrl-C; neither when
/// `checkpointed`: the resume must redo the same annealing). On a cluster
/// of several ranks every rank anneals and all must end with the same
/// particles: there the ranks agree when the annealing starts
/// (collective) whether any has passed the deadline or been stopped —
/// then no sweep runs — and otherwise it runs to its end (a particle
/// checks before each step, in parallel, where the ranks cannot agree).
/// Before session 34 a stop did not cut it: with `annealing_sweeps` at
/// 10^9 a Ctrl-C went unanswered for more than 10 minutes.
fn annealing_cut(
    deadline: Deadline,
    stop: &AtomicBool,
    checkpointed: bool,
) -> impl Fn() -> bool + Sync + '_ {
    let deadline = startup_deadline(deadline, checkpointed);
    let stop = (!checkpointed).then_some(stop);
    let stopped = move || stop.is_some_and(|s| s.load(Ordering::Relaxed));
    let (deadline, local_stop) = match crate::cluster::current() {
        Some(c) if c.size() > 1 => match c.any(deadline.passed() || stopped()) {
            true => (Deadline::new(Instant::now(), Some(Duration::ZERO)), false),
            false => (Deadline::NEVER, false),
        },
        _ => (deadline, true),
    };
    move || deadline.passed() || (local_stop && stopped())
}

/// Least time between two checkpoints of a run (besides the one at its
/// end or when it is stopped).
pub(crate) const CHECKPOINT_EVERY: Duration = Duration::from_secs(1);

/// The sums of this process's tasks, borrowed.
fn local_sums<'a, F: ChainFamily>(tasks: &'a [Task<'_, F>]) -> Vec<distribute::TaskSums<'a>> {
    tasks.iter().map(distribute::TaskSums::of).collect()
}

/// Bytes per bootstrap candidate and member (its log weight, the
/// bootstrap's sample and cumulative weight) and per chain (state, kernel,
/// statistics; measured ≈ 1 KB for PSSMLT).
const BYTES_PER_CANDIDATE: u128 = 48;
pub(crate) const BYTES_PER_CHAIN: u128 = 2048;
/// Bytes per population-annealing particle and member (its state with the
/// primary-sample coordinates, density and path sample; every member's
/// population is kept for the report). An estimate of the same kind as
/// [`BYTES_PER_CHAIN`].
const BYTES_PER_PARTICLE: u128 = 1024;

/// Refuses a run whose bootstrap, chains and films would not fit in the
/// memory available.
fn check_memory<F: ChainFamily>(
    scene: &Scene,
    family: &F,
    settings: &ChainSettings<F::Mutation>,
) -> Result<(), MltError> {
    let members = family.members() as u128;
    let (w, h) = (scene.film.width, scene.film.height);
    // (+ 1: the start-up's own film, the image if the chains never move.)
    let films = (settings.tasks as u64 + 2) * family.members() as u64 + 1;
    let particles = family.annealing().map_or(0, |a| a.particles);
    let bytes = settings.bootstrap as u128 * members * BYTES_PER_CANDIDATE
        + settings.chains as u128 * BYTES_PER_CHAIN
        + particles as u128 * members * BYTES_PER_PARTICLE
        + crate::resources::film_bytes(w, h, films);
    let annealing = match particles {
        0 => String::new(),
        n => format!(" and {n} annealing particles × {members} members"),
    };
    crate::resources::check_memory(
        &format!(
            "a Markov-chain render of {w}×{h} with {} bootstrap candidates × {members} members and {} chains{annealing}",
            settings.bootstrap, settings.chains
        ),
        bytes,
    )
    .map_err(MltError::Setting)
}

/// `total` split over `n` parts, part `k`'s share (the first `total % n`
/// parts take one more).
fn share(total: u64, n: usize, k: usize) -> u64 {
    let n = n as u64;
    total / n + u64::from((k as u64) < total % n)
}

/// Independent chains, numbered member by member, grouped into tasks of
/// one member each (about `settings.tasks` in all) in contiguous blocks;
/// only the tasks `owned` accepts (by index) get their chains, the others
/// stay empty.
fn chain_tasks<'f, F: ChainFamily>(
    family: &'f F,
    settings: &ChainSettings<F::Mutation>,
    starts: &[Vec<F::State>],
    total: Option<u64>,
    new_film: &dyn Fn() -> Film,
    owned: &dyn Fn(usize) -> bool,
) -> Result<Vec<Task<'f, F>>, MltError> {
    let seed = settings.seed;
    let mut tasks: Vec<Task<F>> = Vec::new();
    let mut c = 0usize;
    for (d, member_starts) in starts.iter().enumerate() {
        let n = member_starts.len();
        if n == 0 {
            continue;
        }
        let k = ((settings.tasks * n + settings.chains / 2) / settings.chains).clamp(1, n);
        let first = tasks.len();
        for _ in 0..k {
            tasks.push(Task::new(
                vec![d],
                family,
                new_film,
                Units::Chains(Vec::new()),
            ));
        }
        for (i, start) in member_starts.iter().enumerate() {
            let task = first + i * k / n;
            if owned(task) {
                let chain = Chain::new(
                    family.target(d),
                    start.clone(),
                    MetropolisHastings::new(family.kernel(&settings.mutation, d)?),
                    stream_rng(seed, c as u64),
                )?;
                let Units::Chains(chains) = &mut tasks[task].units else {
                    unreachable!("chain tasks hold chains");
                };
                chains.push(ChainSlot {
                    chain,
                    remaining: total.map(|t| share(t, settings.chains, c)),
                });
            }
            c += 1;
        }
    }
    Ok(tasks)
}

/// Stream offset from which replica set `k`'s seed is derived (its level
/// `l` then draws from `stream_rng(set seed, l)`).
const REPLICA_SET_STREAM: u64 = 1 << 42;

/// The replica groups of a family, checked: non-empty, contiguous and
/// covering the `members` in order.
fn checked_groups(
    groups: Vec<Range<usize>>,
    members: usize,
) -> Result<Vec<Range<usize>>, MltError> {
    let mut next = 0;
    for g in &groups {
        if g.start != next || g.is_empty() {
            return Err(MltError::Setting(format!(
                "replica groups must be non-empty contiguous ranges covering the {members} members in order, got {groups:?}"
            )));
        }
        next = g.end;
    }
    if next != members {
        return Err(MltError::Setting(format!(
            "replica groups must cover the {members} members, got {groups:?}"
        )));
    }
    Ok(groups)
}

/// Where [`replica_tasks`]' sets start and how they are grouped: the start
/// states per member, the members of each group, the sets of each group.
type ReplicaLayout<'a, S> = (&'a [Vec<S>], &'a [Range<usize>], &'a [usize]);

/// `sets_of_group[g]` replica sets for every group `g` (set `k` of a group
/// starts its level `l`, member `m = g.start + l`, from `starts[m][k]`),
/// numbered group after group, in about `settings.tasks` tasks of
/// contiguous sets of one group each (tasks in proportion to the group's
/// sets); the mutations are shared out as sweeps of one mutation per
/// member of a set. Only the tasks `owned` accepts get their sets.
fn replica_tasks<'f, F: ChainFamily>(
    family: &'f F,
    settings: &ChainSettings<F::Mutation>,
    (starts, groups, sets_of_group): ReplicaLayout<'_, F::State>,
    total: Option<u64>,
    new_film: &dyn Fn() -> Film,
    owned: &dyn Fn(usize) -> bool,
) -> Result<Vec<Task<'f, F>>, MltError> {
    let seed = settings.seed;
    let all_sets: usize = sets_of_group.iter().sum();
    let set_size = family.members().div_ceil(groups.len());
    let shares: Vec<f64> = (0..family.members())
        .map(|m| family.sweep_share(m))
        .collect();
    if let Some(r) = shares.iter().find(|r| !(**r > 0.0 && **r <= 1.0)) {
        return Err(MltError::Setting(format!(
            "a member's share of the sweeps must be in (0, 1], got {r}"
        )));
    }
    // Mutations per sweep of a set: the set size unless members rest.
    let per_sweep: f64 = groups[0].clone().map(|m| shares[m]).sum();
    let sweeps = total.map(|t| {
        if per_sweep == set_size as f64 {
            t.div_ceil(set_size as u64)
        } else {
            (t as f64 / per_sweep).ceil() as u64
        }
    });
    let mut tasks: Vec<Task<F>> = Vec::new();
    let mut set = 0;
    for (g, &sets) in groups.iter().zip(sets_of_group) {
        if sets == 0 {
            continue;
        }
        let k = ((settings.tasks * sets + all_sets / 2) / all_sets).clamp(1, sets);
        let first_task = tasks.len();
        for _ in 0..k {
            tasks.push(Task::new(
                g.clone().collect(),
                family,
                new_film,
                Units::Replicas(Vec::new()),
            ));
        }
        // `i` numbers the set within its group: it picks the task and,
        // per member, the start state (`starts[m][i]`).
        #[allow(clippy::needless_range_loop)]
        for i in 0..sets {
            let task = first_task + i * k / sets;
            if !owned(task) {
                set += 1;
                continue;
            }
            let initial = g.clone().map(|m| starts[m][i].clone()).collect();
            let algorithms = g
                .clone()
                .map(|m| {
                    Ok(MetropolisHastings::new(
                        family.kernel(&settings.mutation, m)?,
                    ))
                })
                .collect::<Result<_, MltError>>()?;
            let exchange = family
                .exchange_move()
                .ok_or_else(|| MltError::Setting("the family's exchange move vanished".into()))?;
            let set_seed = splitmix64(seed ^ splitmix64(REPLICA_SET_STREAM + set as u64));
            let ladder = Members {
                family,
                first: g.start,
                levels: g.len(),
            };
            let ensemble = ReplicaExchange::new(ladder, initial, algorithms, exchange, set_seed)?;
            let Units::Replicas(slots) = &mut tasks[task].units else {
                unreachable!("replica tasks hold replica sets");
            };
            slots.push(ReplicaSlot {
                set: ensemble,
                sweeps: 0,
                remaining: sweeps.map(|t| share(t, all_sets, set)),
            });
            set += 1;
        }
    }
    Ok(tasks)
}
