//! Building and running the chains.
//!
//! One function per algorithm family: [`run`] dispatches on the sampler
//! kind. Replica exchange belongs here as another arm of that match, with
//! its own driver that spends the budget over all levels.

use mcmc_core::chain::{Algorithm, Chain};
use mcmc_core::kernel::{AdaptiveCovariance, GaussianRandomWalk, Kernel, TorusStep};
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::mtm::{Lambda, MultipleTry};
use mcmc_core::replica::{
    AdaptiveEquiEnergy, EquiEnergyMove, EquiEnergySampler, EvenOdd, ExchangeMove,
    FrequentEquiEnergy, IsPermutation, IsSwap, JumpRule, NeighbourSwap, PowerFamily,
    ReplicaExchange, RingRange, Tempered, betas_from_temperatures,
};
use mcmc_core::rng::ChainRng;
use mcmc_core::runner::{run_chains, with_threads};
use mcmc_core::sample::Sample;
use mcmc_core::space::SmallStep;
use mcmc_core::stats::ChainStatistics;
use rand::Rng as _;

use super::cli::{KernelKind, MoveKind, SamplerKind};
use super::error::ExampleError;
use super::plan::ReplicaPlan;
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
    /// Replica exchange: exchanges per level pair over the kept sweeps.
    pub swaps: Vec<PairSwaps>,
    /// Replica exchange: the final temperatures (tuned when adaptive).
    pub temperatures: Vec<f64>,
}

/// Exchange counts between two levels of one ladder (post-burn-in).
#[derive(Clone, Debug, PartialEq)]
pub struct PairSwaps {
    /// Lower level (0 = the target).
    pub i: usize,
    /// Higher level.
    pub j: usize,
    /// Exchanges attempted.
    pub attempted: u64,
    /// Exchanges accepted.
    pub accepted: u64,
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
        SamplerKind::Replica => {
            let replica = plan
                .replica
                .as_ref()
                .ok_or_else(|| ExampleError::run("replica plan missing"))?;
            drive_replica(plan, replica, target, start, rng)
        }
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
        swaps: Vec::new(),
        temperatures: Vec::new(),
    })
}

/// Level `l`'s kernel: the base kernel with its scale times `√T_l`
/// (Kelemen: `s1`, `s2` times `√T_l`, `s2` kept below ½).
fn level_kernel(
    plan: &RunPlan,
    dim: usize,
    temperature: f64,
) -> Result<Box<dyn Kernel<Vec<f64>, Tempered<()>> + Send>, ExampleError> {
    let err = |e: mcmc_core::CoreError| ExampleError::usage(format!("kernel: {e}"));
    let root = temperature.sqrt();
    Ok(match plan.kernel {
        KernelKind::Gaussian => {
            Box::new(GaussianRandomWalk::isotropic(plan.scale * root).map_err(err)?)
        }
        KernelKind::Adaptive => {
            Box::new(AdaptiveCovariance::new(dim, plan.scale * root).map_err(err)?)
        }
        KernelKind::Kelemen => {
            let s2 = (root / 64.0).min(0.45);
            let s1 = (root / 1024.0).min(s2 / 16.0);
            Box::new(TorusStep::new(SmallStep::Kelemen { s1, s2 }).map_err(err)?)
        }
    })
}

fn exchange_move(
    kind: MoveKind,
    levels: usize,
) -> Result<Box<dyn ExchangeMove<Vec<f64>, Tempered<()>>>, ExampleError> {
    let err = |e: mcmc_core::CoreError| ExampleError::usage(format!("--move {}: {e}", kind.name()));
    Ok(match kind {
        MoveKind::Neighbour => Box::new(NeighbourSwap::new()),
        MoveKind::EvenOdd => Box::new(EvenOdd::new()),
        MoveKind::IsPermutation => Box::new(IsPermutation::new(levels).map_err(err)?),
        MoveKind::IsSwap => Box::new(IsSwap::new()),
        MoveKind::Eem => Box::new(EquiEnergyMove::new(8, RingRange::Observed).map_err(err)?),
        MoveKind::FrequentEem => {
            Box::new(FrequentEquiEnergy::new(8, RingRange::Observed).map_err(err)?)
        }
        MoveKind::Ees => {
            Box::new(EquiEnergySampler::new(levels, 8, 0.1, RingRange::Observed).map_err(err)?)
        }
        MoveKind::EesKou => Box::new(
            EquiEnergySampler::new(levels, 8, 0.1, RingRange::Observed)
                .map_err(err)?
                .with_jump_rule(JumpRule::CurrentRingFilled),
        ),
        MoveKind::AdaptiveEes => {
            Box::new(AdaptiveEquiEnergy::new(levels, 16, 0.1, 10_000).map_err(err)?)
        }
    })
}

/// A whole ladder as one "chain": burn-in sweeps (tuning the ladder first
/// when adaptive), freeze, then one draw of level 1 per sweep.
fn drive_replica(
    plan: &RunPlan,
    replica: &ReplicaPlan,
    target: &StateTarget<'_>,
    start: Sample<Vec<f64>>,
    mut rng: ChainRng,
) -> Result<ChainRun, ExampleError> {
    let mixture = target.mixture;
    let dim = mixture.dim();
    let levels = replica.temperatures.len();
    let run_err = |e: mcmc_core::CoreError| ExampleError::run(format!("replica exchange: {e}"));
    let family =
        PowerFamily::without_prior(*target, betas_from_temperatures(&replica.temperatures))
            .map_err(run_err)?;
    let algorithms = replica
        .temperatures
        .iter()
        .map(|&t| Ok(MetropolisHastings::new(level_kernel(plan, dim, t)?)))
        .collect::<Result<Vec<_>, ExampleError>>()?;
    let mut ensemble = ReplicaExchange::new(
        family,
        vec![start.state],
        algorithms,
        exchange_move(replica.exchange, levels)?,
        rng.next_u64(),
    )
    .map_err(run_err)?;
    let mut burned = 0usize;
    if replica.adaptive && plan.burn_in_steps >= 2 {
        // One plain sweep first, so that even–odd swaps have tried both
        // parities before the first tuning round; then rounds of 1, 2, 4, …
        // sweeps, as many as fit in the burn-in.
        ensemble.sweep();
        let rounds = (usize::BITS - plan.burn_in_steps.leading_zeros()).saturating_sub(1);
        ensemble.tune_schedule(rounds).map_err(run_err)?;
        burned = 1 + (1usize << rounds) - 1;
    }
    for _ in burned..plan.burn_in_steps {
        ensemble.sweep();
    }
    ensemble.freeze();
    let at_burn_in = ensemble.chain_statistics(0).clone();
    let pairs_before = ensemble.statistics().attempted_pairs();
    let mut draws = vec![Vec::with_capacity(plan.draws); dim];
    let mut visits = vec![0; mixture.len()];
    let mut x = Vec::with_capacity(dim);
    for _ in 0..plan.draws {
        ensemble.sweep();
        target
            .coordinates
            .to_target(&ensemble.current(0).state, &mut x);
        for (d, v) in draws.iter_mut().zip(&x) {
            d.push(*v);
        }
        visits[mixture.nearest_component(&x)] += 1;
    }
    let all = ensemble.chain_statistics(0).clone();
    let evaluations = plan.startup_candidates as u64
        + (0..levels)
            .map(|l| ensemble.chain_statistics(l).evaluations)
            .sum::<u64>();
    let before = |i: usize, j: usize| {
        pairs_before
            .iter()
            .find(|p| p.0 == i && p.1 == j)
            .map_or((0, 0), |p| (p.2.attempted, p.2.accepted))
    };
    let swaps = ensemble
        .statistics()
        .attempted_pairs()
        .into_iter()
        .filter(|p| p.0 != p.1)
        .map(|(i, j, s)| {
            let (a0, c0) = before(i, j);
            PairSwaps {
                i,
                j,
                attempted: s.attempted - a0,
                accepted: s.accepted - c0,
            }
        })
        .collect();
    Ok(ChainRun {
        draws,
        visits,
        evaluations,
        kept: difference(&all, &at_burn_in),
        all,
        swaps,
        temperatures: ensemble.family().betas().iter().map(|b| 1.0 / b).collect(),
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
