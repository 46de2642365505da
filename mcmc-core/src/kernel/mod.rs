//! Mutation kernels: proposals `y ~ q(x → ·)` that report
//! `ln q(y → x) − ln q(x → y)`, so one acceptance routine serves symmetric,
//! independent and asymmetric moves alike.
//!
//! A kernel writes its proposal into a caller-owned [`Sample`] (reusing its
//! allocation) and returns a [`Proposal`]. Kernels may adapt through
//! [`Kernel::observe`]; adaptation must diminish, and [`Kernel::freeze`]
//! stops it so that sampling after warm-up is an exact Markov chain.

mod adaptive_covariance;
mod finite;
mod gaussian;
#[cfg(test)]
mod geweke;
pub mod hessian;
pub mod hmc;
mod independent;
pub mod mala;
pub mod metric;
mod mixture;
pub mod nuts;
mod phase_pool;
mod torus_step;
mod uniform;

pub use adaptive_covariance::AdaptiveCovariance;
pub use finite::FiniteProposal;
pub use gaussian::GaussianRandomWalk;
pub use hessian::H2mc;
pub use hmc::{Boundary, GradientKernelStatistics, Hmc, Trajectory};
pub use independent::Independent;
pub use mala::Mala;
pub use metric::Metric;
pub use mixture::Mixture;
pub use nuts::{MIN_INITIAL_STEP, Nuts, NutsDrawStatistics};
pub use torus_step::{AdaptiveTorusStep, TorusStep};
pub use uniform::UniformRandomWalk;

use crate::rng::ChainRng;
use crate::sample::Sample;

/// What a kernel reports about the proposal it wrote.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Proposal {
    /// `ln q(y → x) − ln q(x → y)`; 0 for symmetric kernels.
    pub log_q_ratio: f64,
    /// Which component made the proposal (for per-component statistics).
    pub component: usize,
    /// True when the kernel already evaluated the target at `y` and filled
    /// the proposal's `log_density` and `payload` (e.g. HMC).
    pub evaluated: bool,
    /// True when no proposal could be made (it counts as a rejection).
    pub failed: bool,
}

impl Proposal {
    /// A proposal from a symmetric kernel.
    #[inline]
    pub fn symmetric(component: usize) -> Self {
        Proposal::with_ratio(0.0, component)
    }

    /// A proposal with the given `ln q(y→x) − ln q(x→y)`.
    #[inline]
    pub fn with_ratio(log_q_ratio: f64, component: usize) -> Self {
        Proposal {
            log_q_ratio,
            component,
            evaluated: false,
            failed: false,
        }
    }

    /// A failed proposal: rejected without evaluating the target.
    #[inline]
    pub fn failed(component: usize) -> Self {
        Proposal {
            log_q_ratio: f64::NEG_INFINITY,
            component,
            evaluated: false,
            failed: true,
        }
    }
}

/// What a chain tells its kernel after each step.
#[derive(Debug)]
pub struct StepObservation<'a, S> {
    /// The component that proposed (meaningful when `own` is true).
    pub component: usize,
    /// Acceptance probability of the step.
    pub alpha: f64,
    /// Whether the proposal was accepted.
    pub accepted: bool,
    /// True when this kernel made the proposal (false for the other
    /// components of a mixture).
    pub own: bool,
    /// The chain's state after the step.
    pub state: &'a S,
}

/// One possible outcome of a kernel on a finite space, for exact tests.
#[derive(Clone, Debug, PartialEq)]
pub struct Enumerated<S> {
    /// The proposed state.
    pub state: S,
    /// Probability of this outcome (component choice included).
    pub probability: f64,
    /// The `log_q_ratio` the kernel reports for this outcome.
    pub log_q_ratio: f64,
    /// The component that makes it.
    pub component: usize,
}

/// A mutation kernel over states `S` whose samples carry payload `P`.
pub trait Kernel<S, P = ()> {
    /// Writes a proposal from `current` into `proposal.state` (and, if the
    /// kernel evaluates the target itself, its density and payload).
    fn propose(
        &mut self,
        current: &Sample<S, P>,
        proposal: &mut Sample<S, P>,
        rng: &mut ChainRng,
    ) -> Proposal;

    /// `ln q(from → to)`, when the kernel can evaluate it (multiple-try
    /// Metropolis and delayed rejection need it for asymmetric kernels).
    fn log_proposal_density(&self, _from: &Sample<S, P>, _to: &S) -> Option<f64> {
        None
    }

    /// True when `q(x → y) = q(y → x)` for all states.
    fn is_symmetric(&self) -> bool {
        false
    }

    /// Called after every step of a chain that uses this kernel.
    fn observe(&mut self, _observation: &StepObservation<'_, S>) {}

    /// Stops adaptation (end of warm-up).
    fn freeze(&mut self) {}

    /// Names of the components, for statistics; one entry per component.
    fn component_names(&self) -> Vec<String>;

    /// Checks that a chain may start at `state` with this kernel (e.g. the
    /// state's dimension matches the kernel's); called by
    /// [`Chain::from_sample`](crate::chain::Chain::from_sample). The default
    /// accepts every state.
    fn check_state(&self, _state: &S) -> crate::Result<()> {
        Ok(())
    }

    /// Every outcome of one proposal with its probability, on finite spaces.
    /// `None` when the kernel cannot enumerate.
    fn enumerate(&self, _from: &Sample<S, P>) -> Option<Vec<Enumerated<S>>> {
        None
    }

    /// Appends the kernel's own state (what its adaptation has learnt) to
    /// `out`, bit for bit, for checkpoints: a kernel restored from these
    /// words ([`Kernel::restore_words`]) makes the proposals the saved one
    /// would have made. The default, for kernels without state of their
    /// own, appends nothing; of the adaptive kernels
    /// [`AdaptiveTorusStep`], [`Hmc`] and [`Nuts`] (step size, metric and
    /// warm-up) write their state so far (the others' runs cannot be
    /// checkpointed).
    fn state_words(&self, _out: &mut Vec<u64>) {}

    /// Restores the state [`Kernel::state_words`] wrote at the front of
    /// `input` (advanced past it) into this kernel, built with the same
    /// settings; false when the words are not such a state (the kernel,
    /// then perhaps partly restored, is not to be used). The default reads
    /// nothing.
    fn restore_words(&mut self, _input: &mut &[u64]) -> bool {
        true
    }
}

impl<S, P, K: Kernel<S, P> + ?Sized> Kernel<S, P> for Box<K> {
    fn propose(
        &mut self,
        current: &Sample<S, P>,
        proposal: &mut Sample<S, P>,
        rng: &mut ChainRng,
    ) -> Proposal {
        (**self).propose(current, proposal, rng)
    }
    fn log_proposal_density(&self, from: &Sample<S, P>, to: &S) -> Option<f64> {
        (**self).log_proposal_density(from, to)
    }
    fn is_symmetric(&self) -> bool {
        (**self).is_symmetric()
    }
    fn observe(&mut self, observation: &StepObservation<'_, S>) {
        (**self).observe(observation)
    }
    fn freeze(&mut self) {
        (**self).freeze()
    }
    fn component_names(&self) -> Vec<String> {
        (**self).component_names()
    }
    fn enumerate(&self, from: &Sample<S, P>) -> Option<Vec<Enumerated<S>>> {
        (**self).enumerate(from)
    }
    fn state_words(&self, out: &mut Vec<u64>) {
        (**self).state_words(out)
    }
    fn restore_words(&mut self, input: &mut &[u64]) -> bool {
        (**self).restore_words(input)
    }
}
