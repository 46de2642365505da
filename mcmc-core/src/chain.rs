//! A chain: its current sample, its random stream, its statistics and the
//! algorithm that moves it.

use crate::error::{CoreError, Result};
use crate::rng::ChainRng;
use crate::sample::Sample;
use crate::stats::{ChainStatistics, Outcome};
use crate::target::{DensityClass, Target};

/// One transition, as seen by observers: the state before the step, the
/// proposal, and the acceptance probability. Expected values ("Rao–
/// Blackwellised" estimates) weight the proposal by `alpha` and the current
/// state by `1 − alpha`, whatever the decision.
#[derive(Debug)]
pub struct Transition<'a, S, P> {
    /// The state before the step.
    pub current: &'a Sample<S, P>,
    /// The proposal, or `None` when the kernel failed to make one.
    pub proposal: Option<&'a Sample<S, P>>,
    /// Acceptance probability `α ∈ [0, 1]`.
    pub alpha: f64,
    /// Whether the proposal was accepted.
    pub accepted: bool,
    /// Kernel component that proposed.
    pub component: usize,
}

/// What one step did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepInfo {
    /// Acceptance probability.
    pub alpha: f64,
    /// How the step ended.
    pub outcome: Outcome,
    /// Kernel component that proposed.
    pub component: usize,
}

impl StepInfo {
    /// True when the chain moved to the proposal.
    pub fn accepted(&self) -> bool {
        self.outcome == Outcome::Accepted
    }
}

/// The parts of a chain an algorithm updates.
#[derive(Clone, Debug)]
pub struct ChainState<S, P> {
    /// The current sample.
    pub current: Sample<S, P>,
    /// The chain's random stream.
    pub rng: ChainRng,
    /// Run statistics.
    pub stats: ChainStatistics,
}

/// A transition algorithm: Metropolis–Hastings, multiple-try, delayed
/// rejection, … Each keeps its own kernel(s) and scratch space.
pub trait Algorithm<S, P> {
    /// Names of the kernel components, for the statistics.
    fn component_names(&self) -> Vec<String>;

    /// Moves the chain by one step, reporting the transition to `observer`.
    fn step<T: Target<S, Payload = P>>(
        &mut self,
        chain: &mut ChainState<S, P>,
        target: &T,
        observer: &mut dyn FnMut(&Transition<'_, S, P>),
    ) -> StepInfo;

    /// Stops any adaptation (end of warm-up).
    fn freeze(&mut self);

    /// Checks that a chain may start at `state` (its kernels'
    /// [`Kernel::check_state`](crate::kernel::Kernel::check_state)).
    fn check_initial(&self, _state: &S) -> Result<()> {
        Ok(())
    }
}

/// A Markov chain: state, stream, statistics and algorithm.
///
/// ```
/// use mcmc_core::prelude::*;
/// let target = |x: &[f64]| -0.5 * x.iter().map(|v| v * v).sum::<f64>();
/// let mh = MetropolisHastings::new(GaussianRandomWalk::isotropic(1.0).unwrap());
/// let mut chain = Chain::new(&target, vec![0.0; 3], mh, stream_rng(7, 0)).unwrap();
/// for _ in 0..100 {
///     chain.step(&target);
/// }
/// assert_eq!(chain.stats().steps, 100);
/// ```
#[derive(Clone, Debug)]
pub struct Chain<S, P, A> {
    state: ChainState<S, P>,
    algorithm: A,
}

impl<S, P, A: Algorithm<S, P>> Chain<S, P, A> {
    /// Starts a chain at `initial`. Refuses an initial state whose log density
    /// is not finite.
    pub fn new<T: Target<S, Payload = P>>(
        target: &T,
        initial: S,
        algorithm: A,
        rng: ChainRng,
    ) -> Result<Self> {
        let current = Sample::evaluate(target, initial);
        Self::from_sample(current, algorithm, rng)
    }

    /// Starts a chain at an already evaluated sample (e.g. from start-up
    /// resampling). Refuses a non-finite log density and a state the
    /// algorithm's kernels cannot move (e.g. of the wrong dimension).
    pub fn from_sample(current: Sample<S, P>, algorithm: A, rng: ChainRng) -> Result<Self> {
        algorithm.check_initial(&current.state)?;
        if DensityClass::of(current.log_density) != DensityClass::Finite {
            return Err(CoreError::NonFiniteInitialState {
                log_density: current.log_density,
            });
        }
        let mut stats = ChainStatistics::new(algorithm.component_names());
        stats.evaluations = 1;
        Ok(Chain {
            state: ChainState {
                current,
                rng,
                stats,
            },
            algorithm,
        })
    }

    /// One step.
    #[inline]
    pub fn step<T: Target<S, Payload = P>>(&mut self, target: &T) -> StepInfo {
        self.algorithm.step(&mut self.state, target, &mut |_| {})
    }

    /// One step, with the transition passed to `observer` (for expected
    /// values or splatting both states).
    #[inline]
    pub fn step_with<T: Target<S, Payload = P>>(
        &mut self,
        target: &T,
        mut observer: impl FnMut(&Transition<'_, S, P>),
    ) -> StepInfo {
        self.algorithm.step(&mut self.state, target, &mut observer)
    }

    /// The current sample.
    pub fn current(&self) -> &Sample<S, P> {
        &self.state.current
    }

    /// The current state.
    pub fn state(&self) -> &S {
        &self.state.current.state
    }

    /// Mutable access to the chain's parts (exchange moves swap samples).
    pub fn parts_mut(&mut self) -> &mut ChainState<S, P> {
        &mut self.state
    }

    /// Run statistics.
    pub fn stats(&self) -> &ChainStatistics {
        &self.state.stats
    }

    /// The algorithm.
    pub fn algorithm(&self) -> &A {
        &self.algorithm
    }

    /// The algorithm, mutably (e.g. to inspect or tune a kernel).
    pub fn algorithm_mut(&mut self) -> &mut A {
        &mut self.algorithm
    }

    /// Stops adaptation: from here on the chain is an exact Markov chain.
    pub fn freeze(&mut self) {
        self.algorithm.freeze();
    }

    /// The chain's random stream, to read its state (checkpoints).
    pub fn rng(&self) -> &ChainRng {
        &self.state.rng
    }

    /// The chain's random stream.
    pub fn rng_mut(&mut self) -> &mut ChainRng {
        &mut self.state.rng
    }
}
