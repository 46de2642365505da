//! The ensemble runner: one chain per level, mutating in parallel between
//! exchange moves, bit-identical for any thread count.

use super::context::{DensityCache, ExchangeContext};
use super::family::{LevelTarget, ReplicaFamily};
use super::stats::{IndexProcess, ReplicaStatistics};
use super::{ExchangeMove, Jump, Schedule};
use crate::chain::{Algorithm, ChainState, Transition};
use crate::error::{CoreError, Result, invalid};
use crate::rng::{ChainRng, stream_rng};
use crate::sample::Sample;
use crate::stats::ChainStatistics;
use crate::target::DensityClass;
use rayon::prelude::*;

/// A sweep observer of level 0's transitions.
pub type Observer<'a, S, P> = dyn FnMut(&Transition<'_, S, P>) + Send + 'a;

/// A sweep observer of every level's transitions, with the level.
pub type LevelObserver<'a, S, P> = dyn FnMut(usize, &Transition<'_, S, P>) + Send + 'a;

/// `(partner, α, accepted)` of an attempted jump.
type JumpRecord = Option<(usize, f64, bool)>;

/// Stream index of the exchange moves' generator (levels use `0..M`).
pub(crate) const EXCHANGE_STREAM: u64 = 0xE7C4_A4E0_0000_0000;

/// Replica exchange over a [`ReplicaFamily`]: level `l` is a chain with its
/// own mutation algorithm `A` (e.g. [`crate::mh::MetropolisHastings`] with a
/// kernel scaled for the level), and one [`ExchangeMove`] exchanges states
/// between levels.
///
/// ```
/// use mcmc_core::prelude::*;
/// use mcmc_core::replica::*;
/// // Two modes at ±4; the hot level (β = 0.05) crosses between them.
/// let ln_l = |x: &[f64]| {
///     let a = -0.5 * (x[0] - 4.0).powi(2);
///     let b = -0.5 * (x[0] + 4.0).powi(2);
///     mcmc_core::math::log_sum_exp2(a, b)
/// };
/// let temps = geometric_temperatures(4, 20.0).unwrap();
/// let family = PowerFamily::without_prior(ln_l, betas_from_temperatures(&temps)).unwrap();
/// let algorithms = kernel_scales(1.0, &temps)
///     .into_iter()
///     .map(|s| MetropolisHastings::new(GaussianRandomWalk::isotropic(s).unwrap()))
///     .collect();
/// let mut re = ReplicaExchange::new(
///     family, vec![vec![4.0]], algorithms, Box::new(EvenOdd::new()), 7,
/// ).unwrap();
/// let mut negative = 0;
/// for _ in 0..2000 {
///     re.sweep();
///     negative += (re.current(0).state[0] < 0.0) as usize;
/// }
/// assert!(negative > 200 && negative < 1800);
/// println!("swap acceptance per neighbour pair: {:?}", re.statistics().neighbour_acceptance());
/// ```
pub struct ReplicaExchange<S, F: ReplicaFamily<S>, A> {
    pub(crate) family: F,
    pub(crate) chains: Vec<ChainState<S, F::Payload>>,
    pub(crate) algorithms: Vec<A>,
    exchange: Box<dyn ExchangeMove<S, F::Payload>>,
    rng: ChainRng,
    index: IndexProcess,
    pub(crate) stats: ReplicaStatistics,
    cache: DensityCache,
    frozen: bool,
}

impl<S, F, A> ReplicaExchange<S, F, A>
where
    S: Clone + Send,
    F: ReplicaFamily<S> + Sync,
    F::Payload: Send + Sync,
    A: Algorithm<S, F::Payload> + Send,
{
    /// An ensemble with one algorithm per level. `initial` holds one state
    /// per level, or a single state used for every level; each must have a
    /// finite density at its level. Level `l` draws from
    /// `stream_rng(seed, l)`, exchanges from a separate stream.
    pub fn new(
        family: F,
        initial: Vec<S>,
        algorithms: Vec<A>,
        exchange: Box<dyn ExchangeMove<S, F::Payload>>,
        seed: u64,
    ) -> Result<Self> {
        let m = family.levels();
        let chains = level_chains(&family, &initial, &algorithms, seed, 0..m)?;
        exchange.check_levels(m)?;
        let name = exchange.name();
        Ok(ReplicaExchange {
            family,
            chains,
            algorithms,
            exchange,
            rng: stream_rng(seed, EXCHANGE_STREAM),
            index: IndexProcess::new(m),
            stats: ReplicaStatistics::new(m, name),
            cache: DensityCache::new(m),
            frozen: false,
        })
    }

    /// Number of levels `M`.
    pub fn levels(&self) -> usize {
        self.chains.len()
    }

    /// The family.
    pub fn family(&self) -> &F {
        &self.family
    }

    /// The sample currently at `level` (level 0 is `π_1`).
    pub fn current(&self, level: usize) -> &Sample<S, F::Payload> {
        &self.chains[level].current
    }

    /// The mutation statistics of `level`'s chain.
    pub fn chain_statistics(&self, level: usize) -> &ChainStatistics {
        &self.chains[level].stats
    }

    /// The algorithm of `level`.
    pub fn algorithm(&self, level: usize) -> &A {
        &self.algorithms[level]
    }

    /// Exchange statistics.
    pub fn statistics(&self) -> &ReplicaStatistics {
        &self.stats
    }

    /// The index process (which replica is at which level; round trips).
    pub fn index_process(&self) -> &IndexProcess {
        &self.index
    }

    /// The exchange move.
    pub fn exchange_move(&self) -> &dyn ExchangeMove<S, F::Payload> {
        &*self.exchange
    }

    /// Bytes held by the exchange move (stores, tables).
    pub fn exchange_memory_bytes(&self) -> usize {
        self.exchange.memory_bytes()
    }

    /// End of burn-in: freezes kernel adaptation and the move's energy
    /// levels (the equi-energy sampler starts storing states).
    pub fn freeze(&mut self) {
        for a in &mut self.algorithms {
            a.freeze();
        }
        self.exchange.freeze();
        self.frozen = true;
    }

    /// One sweep: every level mutates once and the exchange move runs on
    /// its schedule.
    pub fn sweep(&mut self) {
        self.sweep_observed(&mut |_| {});
    }

    /// One sweep, reporting level 0's mutation transition (for
    /// Rao–Blackwellised estimates of `π_1`) to `observer`. Equi-energy
    /// jumps are not reported; read [`ReplicaExchange::current`] after the
    /// sweep for the state.
    pub fn sweep_observed(&mut self, observer: &mut Observer<'_, S, F::Payload>) {
        self.sweep_scheduled(|re, level| match level {
            None => re.mutate_all(observer),
            Some(level) => re.mutate_one(level, observer),
        });
    }

    /// One sweep on the calling thread that reports every level's mutation
    /// transition, with its level, to `observer` (a renderer splats each
    /// level into its own film). Same streams, same result as
    /// [`ReplicaExchange::sweep`]; equi-energy jumps are not reported.
    pub fn sweep_observed_levels(&mut self, observer: &mut LevelObserver<'_, S, F::Payload>) {
        self.sweep_observed_active_levels(&|_| true, observer);
    }

    /// [`ReplicaExchange::sweep_observed_levels`] in which only the levels
    /// with `active(level)` mutate; the others keep their sample (and draw
    /// nothing from their streams), while the exchange move runs on its
    /// schedule as usual. Every mutation and every exchange leaves the
    /// product target invariant, so any choice of resting levels does
    /// (a renderer gives cheap-to-film levels fewer mutations this way).
    pub fn sweep_observed_active_levels(
        &mut self,
        active: &dyn Fn(usize) -> bool,
        observer: &mut LevelObserver<'_, S, F::Payload>,
    ) {
        self.sweep_scheduled(|re, level| match level {
            None => (0..re.levels())
                .filter(|&l| active(l))
                .for_each(|l| re.mutate_reporting(l, observer)),
            Some(level) if active(level) => re.mutate_reporting(level, observer),
            Some(_) => {}
        });
    }

    /// A sweep in the exchange move's schedule; `mutate(self, None)`
    /// mutates every level, `mutate(self, Some(l))` level `l`.
    fn sweep_scheduled(&mut self, mut mutate: impl FnMut(&mut Self, Option<usize>)) {
        let m = self.levels();
        match self.exchange.schedule() {
            Schedule::AfterAllMutations => {
                mutate(self, None);
                self.run_exchange(None);
            }
            Schedule::BeforeEachMutation => {
                for level in (0..m).rev() {
                    self.run_exchange(Some(level));
                    mutate(self, Some(level));
                }
            }
            Schedule::AfterEachMutation => {
                for level in (0..m).rev() {
                    mutate(self, Some(level));
                    self.run_exchange(Some(level));
                }
            }
        }
        self.end_sweep();
    }

    fn end_sweep(&mut self) {
        self.cache.clear();
        let mut cx = ExchangeContext {
            family: &self.family,
            chains: &mut self.chains,
            rng: &mut self.rng,
            index: &mut self.index,
            stats: &mut self.stats,
            cache: &mut self.cache,
            frozen: self.frozen,
        };
        self.exchange.end_sweep(&mut cx);
        cx.probe_neighbours();
        self.stats.end_sweep();
    }

    fn mutate_reporting(&mut self, level: usize, observer: &mut LevelObserver<'_, S, F::Payload>) {
        let jump = step_level(
            &self.family,
            &*self.exchange,
            level,
            &mut self.chains[level],
            &mut self.algorithms[level],
            &mut |t| observer(level, t),
        );
        self.record_jump(level, jump);
    }

    fn run_exchange(&mut self, level: Option<usize>) {
        // Mutations changed states since the last exchange.
        self.cache.clear();
        let mut cx = ExchangeContext {
            family: &self.family,
            chains: &mut self.chains,
            rng: &mut self.rng,
            index: &mut self.index,
            stats: &mut self.stats,
            cache: &mut self.cache,
            frozen: self.frozen,
        };
        self.exchange.exchange(level, &mut cx);
    }

    fn mutate_one(&mut self, level: usize, observer: &mut Observer<'_, S, F::Payload>) {
        // Only level 0's transitions are reported.
        let mut ignore = |_: &Transition<'_, S, F::Payload>| {};
        let observer: &mut Observer<'_, S, F::Payload> =
            if level == 0 { observer } else { &mut ignore };
        let jump = step_level(
            &self.family,
            &*self.exchange,
            level,
            &mut self.chains[level],
            &mut self.algorithms[level],
            observer,
        );
        self.record_jump(level, jump);
    }

    fn mutate_all(&mut self, observer: &mut Observer<'_, S, F::Payload>) {
        if rayon::current_num_threads() <= 1 {
            // No parallelism to gain: skip rayon's dispatch, which costs
            // more than a cheap target's mutations. Same streams, same result.
            for level in 0..self.levels() {
                self.mutate_one(level, observer);
            }
            return;
        }
        let family = &self.family;
        let exchange = &*self.exchange;
        let (first_chain, other_chains) = self.chains.split_at_mut(1);
        let (first_alg, other_algs) = self.algorithms.split_at_mut(1);
        // Level 0 runs beside the others so that its observer need not be
        // shared between threads; every level draws from its own stream, so
        // the result does not depend on the thread count.
        let (j0, rest): (JumpRecord, Vec<JumpRecord>) = rayon::join(
            || {
                step_level(
                    family,
                    exchange,
                    0,
                    &mut first_chain[0],
                    &mut first_alg[0],
                    observer,
                )
            },
            || {
                other_chains
                    .par_iter_mut()
                    .zip(other_algs.par_iter_mut())
                    .enumerate()
                    .map(|(i, (c, a))| step_level(family, exchange, i + 1, c, a, &mut |_| {}))
                    .collect()
            },
        );
        self.record_jump(0, j0);
        for (i, j) in rest.into_iter().enumerate() {
            self.record_jump(i + 1, j);
        }
    }

    fn record_jump(&mut self, level: usize, jump: JumpRecord) {
        if let Some((partner, alpha, accepted)) = jump {
            self.stats.record_pair(level, partner, alpha, accepted);
            self.stats.move_attempts += 1;
            if accepted {
                self.stats.move_changes += 1;
                self.stats.touch(level);
            }
            // ln π_{partner}(u) for the ratio, and the evaluation of the
            // accepted stored state at its new level.
            self.stats.evaluations +=
                (!self.family.cross_densities_are_cheap()) as u64 + accepted as u64;
        }
    }
}

/// The chains of levels `levels` (a sub-range of the family's levels when
/// the ensemble is spread over processes), after checking `initial` (one
/// state per level or a single one) and `algorithms` (one per level):
/// level `l` starts at its initial state with `stream_rng(seed, l)`.
pub(crate) fn level_chains<S, F, A>(
    family: &F,
    initial: &[S],
    algorithms: &[A],
    seed: u64,
    levels: std::ops::Range<usize>,
) -> Result<Vec<ChainState<S, F::Payload>>>
where
    S: Clone,
    F: ReplicaFamily<S>,
    A: Algorithm<S, F::Payload>,
{
    let m = family.levels();
    if m == 0 {
        return Err(invalid(
            "family",
            "a replica family needs at least one level",
        ));
    }
    if algorithms.len() != m {
        return Err(invalid(
            "algorithms",
            format!(
                "need one mutation algorithm per level ({m}), got {}",
                algorithms.len()
            ),
        ));
    }
    if initial.len() != m && initial.len() != 1 {
        return Err(invalid(
            "initial",
            format!(
                "need one initial state per level ({m}) or a single one, got {}",
                initial.len()
            ),
        ));
    }
    let mut chains = Vec::with_capacity(levels.len());
    for level in levels {
        let state = initial[if initial.len() == 1 { 0 } else { level }].clone();
        let e = family.evaluate(level, &state);
        if DensityClass::of(e.log_density) != DensityClass::Finite {
            return Err(CoreError::NonFiniteInitialState {
                log_density: e.log_density,
            });
        }
        let mut stats = ChainStatistics::new(algorithms[level].component_names());
        stats.evaluations = 1;
        chains.push(ChainState {
            current: Sample {
                state,
                log_density: e.log_density,
                payload: e.payload,
            },
            rng: stream_rng(seed, level as u64),
            stats,
        });
    }
    Ok(chains)
}

/// Mutates one level, or lets the move's jump replace the mutation.
/// Returns `(partner, α, accepted)` when a jump was attempted.
fn step_level<S, F, A>(
    family: &F,
    exchange: &dyn ExchangeMove<S, F::Payload>,
    level: usize,
    chain: &mut ChainState<S, F::Payload>,
    algorithm: &mut A,
    observer: &mut Observer<'_, S, F::Payload>,
) -> JumpRecord
where
    F: ReplicaFamily<S> + Sync,
    A: Algorithm<S, F::Payload>,
{
    match exchange.jump(level, &chain.current, family, &mut chain.rng) {
        Jump::None => {
            algorithm.step(chain, &LevelTarget { family, level }, observer);
            None
        }
        Jump::Rejected { partner, alpha } => Some((partner, alpha, false)),
        Jump::Accepted {
            partner,
            alpha,
            sample,
        } => {
            chain.current = sample;
            Some((partner, alpha, true))
        }
    }
}
