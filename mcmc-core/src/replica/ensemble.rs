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

/// What a [`ReplicaExchange`] carries from one sweep to the next besides
/// its inputs ([`ReplicaExchange::progress`], [`ReplicaExchange::restore`]).
#[derive(Clone, Debug)]
pub struct ReplicaProgress<S, P> {
    /// Every level's chain: its sample, random stream and statistics.
    pub chains: Vec<ChainState<S, P>>,
    /// The rest, as opaque words: the exchange stream, the index process,
    /// the exchange statistics, the burn-in flag, the move's state.
    pub words: Vec<u64>,
}

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

    /// The algorithm of `level`, mutably: for a caller that saves and
    /// restores its kernel's adaptation beside [`ReplicaExchange::progress`]
    /// (which does not hold the algorithms).
    pub fn algorithm_mut(&mut self, level: usize) -> &mut A {
        &mut self.algorithms[level]
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

    /// The run's progress, for a checkpoint: every level's chain (its
    /// sample, stream and statistics) and, as words, the exchange stream,
    /// the index process, the exchange statistics, the burn-in flag and
    /// the move's own state. `None` when the move cannot be saved
    /// ([`ExchangeMove::state_words`]). The algorithms are not in it:
    /// kernels without adaptation (or frozen ones) are rebuilt by the
    /// caller from the same inputs.
    pub fn progress(&self) -> Option<ReplicaProgress<S, F::Payload>> {
        let mut words = crate::rng::rng_words(&self.rng).to_vec();
        self.index.to_words(&mut words);
        self.stats.to_words(&mut words);
        words.push(u64::from(self.frozen));
        words.extend(self.exchange.state_words()?);
        Some(ReplicaProgress {
            chains: self.chains.clone(),
            words,
        })
    }

    /// Continues the run `progress` was taken from
    /// ([`ReplicaExchange::progress`]) in this ensemble, built from the
    /// same family, algorithms, move and seed: the following sweeps are
    /// the saved run's, bit for bit. Refuses (and changes nothing) a
    /// progress of another number of levels or one whose words do not
    /// fit.
    pub fn restore(&mut self, progress: ReplicaProgress<S, F::Payload>) -> Result<()> {
        let m = self.levels();
        let bad = |why: &str| invalid("progress", why.to_string());
        if progress.chains.len() != m {
            return Err(bad(&format!(
                "holds {} levels, the ensemble has {m}",
                progress.chains.len()
            )));
        }
        let mut input = &progress.words[..];
        let cut = || bad("its words are cut short or corrupt");
        let rng = crate::checkpoint::take_words(&mut input, 4)
            .and_then(|w| crate::rng::rng_from_words(w.try_into().ok()?))
            .ok_or_else(cut)?;
        let index = IndexProcess::from_words(m, &mut input).ok_or_else(cut)?;
        let mut stats = self.stats.clone();
        stats.read_words(&mut input).ok_or_else(cut)?;
        let frozen = match crate::checkpoint::take_words(&mut input, 1) {
            Some(&[f]) if f <= 1 => f == 1,
            _ => return Err(cut()),
        };
        if frozen != self.frozen {
            return Err(bad(
                "it was saved after burn-in and the ensemble is not (or the reverse)",
            ));
        }
        if !self.exchange.restore_words(input) {
            return Err(bad("the exchange move's state does not fit this move"));
        }
        self.chains = progress.chains;
        self.rng = rng;
        self.index = index;
        self.stats = stats;
        self.cache.clear();
        Ok(())
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::GaussianRandomWalk;
    use crate::mh::MetropolisHastings;
    use crate::replica::{
        EvenOdd, IsPermutation, NeighbourSwap, PowerFamily, betas_from_temperatures,
        geometric_temperatures, kernel_scales,
    };

    type Payload = crate::replica::Tempered<()>;
    type Move = Box<dyn ExchangeMove<Vec<f64>, Payload>>;
    type Ensemble = ReplicaExchange<
        Vec<f64>,
        PowerFamily<fn(&[f64]) -> f64>,
        MetropolisHastings<GaussianRandomWalk, Vec<f64>, Payload>,
    >;

    /// Two modes at ±4 on 4 levels up to T = 20, with `exchange`.
    fn ensemble(exchange: fn() -> Move) -> Ensemble {
        let ln_l: fn(&[f64]) -> f64 =
            |x| crate::math::log_sum_exp2(-0.5 * (x[0] - 4.0).powi(2), -0.5 * (x[0] + 4.0).powi(2));
        let temps = geometric_temperatures(4, 20.0).unwrap();
        let family = PowerFamily::without_prior(ln_l, betas_from_temperatures(&temps)).unwrap();
        let algorithms = kernel_scales(1.0, &temps)
            .into_iter()
            .map(|s| MetropolisHastings::new(GaussianRandomWalk::isotropic(s).unwrap()))
            .collect();
        ReplicaExchange::new(family, vec![vec![4.0]], algorithms, exchange(), 7).unwrap()
    }

    /// Every level's state, density and stream, the statistics and the
    /// index process, exactly.
    fn fingerprint(re: &Ensemble) -> (Vec<u64>, ReplicaStatistics, IndexProcess) {
        let mut bits = Vec::new();
        for c in &re.chains {
            bits.extend(c.current.state.iter().map(|x| x.to_bits()));
            bits.push(c.current.log_density.to_bits());
            bits.extend(crate::rng::rng_words(&c.rng));
            bits.extend([c.stats.steps, c.stats.accepted]);
        }
        (bits, re.stats.clone(), re.index.clone())
    }

    #[test]
    fn a_restored_ensemble_continues_the_saved_run_bit_for_bit() {
        let moves: [fn() -> Move; 3] = [
            || Box::new(EvenOdd::new()),
            || Box::new(NeighbourSwap::new()),
            || Box::new(IsPermutation::new(4).unwrap()),
        ];
        for exchange in moves {
            let mut whole = ensemble(exchange);
            (0..300).for_each(|_| whole.sweep());
            let mut first = ensemble(exchange);
            // An odd count: the even–odd move's parity must carry over.
            (0..151).for_each(|_| first.sweep());
            let saved = first.progress().expect("these moves can be saved");
            let mut resumed = ensemble(exchange);
            resumed.restore(saved.clone()).unwrap();
            (151..300).for_each(|_| resumed.sweep());
            let name = whole.statistics().move_name.clone();
            assert!(fingerprint(&resumed) == fingerprint(&whole), "{name}");
            assert!(whole.statistics().overall_acceptance() > 0.0, "{name}");
            // Control: the same progress with the exchange stream put back
            // to its start must not give the same run.
            let mut control = ensemble(exchange);
            let mut restarted = saved;
            let fresh = crate::rng::stream_rng(7, EXCHANGE_STREAM);
            restarted.words[..4].copy_from_slice(&crate::rng::rng_words(&fresh));
            control.restore(restarted).unwrap();
            (151..300).for_each(|_| control.sweep());
            assert!(
                fingerprint(&control) != fingerprint(&whole),
                "{name}: control agreed"
            );
        }
    }

    #[test]
    fn a_progress_that_does_not_fit_is_refused_and_changes_nothing() {
        let mut source = ensemble(|| Box::new(EvenOdd::new()));
        (0..5).for_each(|_| source.sweep());
        let saved = source.progress().unwrap();
        let mut target = ensemble(|| Box::new(NeighbourSwap::new()));
        let before = fingerprint(&target);
        // The even–odd move's sweep counter does not fit the neighbour move.
        assert!(target.restore(saved.clone()).is_err());
        let mut cut = saved.clone();
        cut.words.truncate(10);
        assert!(target.restore(cut).is_err());
        let mut short = saved;
        short.chains.pop();
        assert!(target.restore(short).is_err());
        assert!(fingerprint(&target) == before);
    }
}
