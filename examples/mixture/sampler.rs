//! Building and running the chains.
//!
//! One function per algorithm family: [`run`] dispatches on the sampler
//! kind. Replica exchange belongs here as another arm of that match, with
//! its own driver that spends the budget over all levels.

use mcmc_core::chain::{Algorithm, Chain};
use mcmc_core::kernel::{AdaptiveCovariance, GaussianRandomWalk, Kernel, TorusStep};
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::mtm::{Lambda, MultipleTry};
use mcmc_core::rng::ChainRng;
use mcmc_core::runner::{run_chains, with_threads};
use mcmc_core::sample::Sample;
use mcmc_core::stats::ChainStatistics;

use super::cli::{KernelKind, SamplerKind};
use super::error::ExampleError;
use super::plan::RunPlan;
use super::space::{Coordinates, StateTarget};
use super::startup::initial_sample;
use super::target::GaussianMixture;

/// What one chain hands back.
#[derive(Clone, Debug)]
pub struct ChainRun {
    /// Post-burn-in draws in the target's coordinates, one vector per
    /// coordinate (`draws[i][t]`).
    pub draws: Vec<Vec<f64>>,
    /// Post-burn-in draws nearest each component's mean.
    pub visits: Vec<u64>,
    /// Target evaluations spent, start-up included.
    pub evaluations: u64,
    /// Statistics of the post-burn-in steps only.
    pub kept: ChainStatistics,
    /// Statistics of all steps.
    pub all: ChainStatistics,
}

type BoxedKernel = Box<dyn Kernel<Vec<f64>>>;

fn kernel(plan: &RunPlan, dim: usize) -> Result<BoxedKernel, ExampleError> {
    let err = |e: mcmc_core::CoreError| ExampleError::usage(format!("kernel: {e}"));
    Ok(match plan.kernel {
        KernelKind::Gaussian => Box::new(GaussianRandomWalk::isotropic(plan.scale).map_err(err)?),
        KernelKind::Adaptive => Box::new(AdaptiveCovariance::new(dim, plan.scale).map_err(err)?),
        KernelKind::Kelemen => Box::new(TorusStep::kelemen()),
    })
}

/// Runs every chain of `plan` in parallel; results in chain order, the same
/// for any thread count.
pub fn run(plan: &RunPlan, mixture: &GaussianMixture) -> Result<Vec<ChainRun>, ExampleError> {
    let coordinates = Coordinates::for_kernel(plan.kernel, mixture);
    let target = StateTarget {
        mixture,
        coordinates: &coordinates,
    };
    with_threads(plan.threads, || {
        run_chains(plan.chains, plan.seed, |_, rng| {
            run_chain(plan, &target, rng)
        })
    })
    .into_iter()
    .collect()
}

fn run_chain(
    plan: &RunPlan,
    target: &StateTarget<'_>,
    mut rng: ChainRng,
) -> Result<ChainRun, ExampleError> {
    let start = initial_sample(target, plan.startup_candidates, &mut rng)?;
    let kernel = kernel(plan, target.mixture.dim())?;
    match plan.sampler {
        SamplerKind::Mh => drive(plan, target, start, MetropolisHastings::new(kernel), rng),
        SamplerKind::Mtm => {
            // λ = 1/q: every kernel offered here is symmetric, and this choice
            // needs no proposal density.
            let mtm = MultipleTry::new(kernel, plan.tries, Lambda::InverseProposal)
                .map_err(|e| ExampleError::usage(format!("multiple-try: {e}")))?;
            drive(plan, target, start, mtm, rng)
        }
    }
}

/// Burn-in (adapting), freeze, then record `plan.draws` states.
fn drive<A: Algorithm<Vec<f64>, ()>>(
    plan: &RunPlan,
    target: &StateTarget<'_>,
    start: Sample<Vec<f64>>,
    algorithm: A,
    rng: ChainRng,
) -> Result<ChainRun, ExampleError> {
    let mixture = target.mixture;
    let dim = mixture.dim();
    let mut chain = Chain::from_sample(start, algorithm, rng)
        .map_err(|e| ExampleError::run(format!("chain start: {e}")))?;
    for _ in 0..plan.burn_in_steps {
        chain.step(target);
    }
    chain.freeze();
    let at_burn_in = chain.stats().clone();
    let mut draws = vec![Vec::with_capacity(plan.draws); dim];
    let mut visits = vec![0; mixture.len()];
    let mut x = Vec::with_capacity(dim);
    for _ in 0..plan.draws {
        chain.step(target);
        target.coordinates.to_target(chain.state(), &mut x);
        for (d, v) in draws.iter_mut().zip(&x) {
            d.push(*v);
        }
        visits[mixture.nearest_component(&x)] += 1;
    }
    let all = chain.stats().clone();
    // The chain counts the evaluation of its initial state, which the
    // start-up already paid for.
    let evaluations = plan.startup_candidates as u64 + all.evaluations.saturating_sub(1);
    Ok(ChainRun {
        draws,
        visits,
        evaluations,
        kept: difference(&all, &at_burn_in),
        all,
    })
}

/// The counts of `later` that happened after `earlier`.
fn difference(later: &ChainStatistics, earlier: &ChainStatistics) -> ChainStatistics {
    let mut d = later.clone();
    d.steps -= earlier.steps;
    d.accepted -= earlier.accepted;
    d.evaluations -= earlier.evaluations;
    d.invalid_density -= earlier.invalid_density;
    d.outside_support -= earlier.outside_support;
    d.failed -= earlier.failed;
    for (a, b) in d.components.iter_mut().zip(&earlier.components) {
        a.proposed -= b.proposed;
        a.accepted -= b.accepted;
        a.sum_alpha -= b.sum_alpha;
    }
    d
}
