//! How the evaluation budget is split into start-up, burn-in and kept draws.

use super::cli::{Args, DEFAULT_TRIES, KernelKind, MoveKind, SamplerKind};
use super::error::ExampleError;
use super::target::GaussianMixture;

/// Most start-up candidates a chain draws.
const MAX_STARTUP_CANDIDATES: u64 = 256;
/// At most one twentieth of a chain's budget goes to start-up.
const STARTUP_SHARE: u64 = 20;
/// The split diagnostics need at least 4 draws per chain.
const MIN_DRAWS: u64 = 4;
/// Most coordinates kept in memory over all chains (2 GB of `f64`): every
/// post-burn-in draw is stored for the rank-based diagnostics.
const MAX_STORED_VALUES: u64 = 250_000_000;

/// Everything a run needs, validated against the target.
#[derive(Clone, Debug, PartialEq)]
pub struct RunPlan {
    /// Transition algorithm.
    pub sampler: SamplerKind,
    /// Proposal kernel.
    pub kernel: KernelKind,
    /// Random-walk scale.
    pub scale: f64,
    /// Tries per multiple-try step (1 for Metropolis–Hastings).
    pub tries: usize,
    /// Number of chains.
    pub chains: usize,
    /// Seed of the chains' streams.
    pub seed: u64,
    /// Worker threads (0: rayon's default).
    pub threads: usize,
    /// Start-up candidates per chain.
    pub startup_candidates: usize,
    /// Target evaluations per step: 1 (MH) or `2k − 1` (MTM).
    pub evaluations_per_step: u64,
    /// Burn-in steps per chain (adaptation runs only during these).
    pub burn_in_steps: usize,
    /// Kept steps per chain, each recorded as one draw.
    pub draws: usize,
    /// Replica exchange: the ladder and the move (`None` for MH and MTM).
    pub replica: Option<ReplicaPlan>,
}

/// Starting top temperature of an adaptive ladder.
pub const ADAPTIVE_INITIAL_T_MAX: f64 = 1000.0;

/// The ladder and exchange move of a replica-exchange run.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplicaPlan {
    /// Temperatures `T_1 = 1 … T_M` (the starting ladder when adaptive).
    pub temperatures: Vec<f64>,
    /// Whether the ladder is tuned during burn-in.
    pub adaptive: bool,
    /// The exchange move.
    pub exchange: MoveKind,
}

fn parse_ladder(text: &str, exchange: MoveKind) -> Result<ReplicaPlan, ExampleError> {
    let bad = |why: &str| {
        ExampleError::usage(format!(
            "--ladder {text}: {why} (expected geometric:M:Tmax or adaptive:M)"
        ))
    };
    let parts: Vec<&str> = text.split(':').collect();
    let levels = |s: &str| -> Result<usize, ExampleError> {
        let m: usize = s.parse().map_err(|_| bad("M must be a whole number"))?;
        if !(1..=64).contains(&m) {
            return Err(bad("M must lie in 1..=64"));
        }
        Ok(m)
    };
    let (temperatures, adaptive) = match parts.as_slice() {
        ["geometric", m, t] => {
            let t_max: f64 = t.parse().map_err(|_| bad("Tmax must be a number"))?;
            let temps = mcmc_core::replica::geometric_temperatures(levels(m)?, t_max)
                .map_err(|e| bad(&e.to_string()))?;
            (temps, false)
        }
        ["adaptive", m] => {
            let m = levels(m)?;
            if m < 2 {
                return Err(bad("an adaptive ladder needs at least 2 levels"));
            }
            if !matches!(exchange, MoveKind::Neighbour | MoveKind::EvenOdd) {
                return Err(ExampleError::usage(
                    "--ladder adaptive:M tunes from neighbour swap rates: use --move neighbour or even-odd",
                ));
            }
            let temps = mcmc_core::replica::geometric_temperatures(m, ADAPTIVE_INITIAL_T_MAX)
                .map_err(|e| bad(&e.to_string()))?;
            (temps, true)
        }
        _ => return Err(bad("unknown form")),
    };
    Ok(ReplicaPlan {
        temperatures,
        adaptive,
        exchange,
    })
}

impl RunPlan {
    /// Splits `--evaluations` evenly over the chains (the remainder of the
    /// division is left unused so that all chains have equal length); each
    /// chain spends `max(1, min(256, B/20))` evaluations of its budget `B` on
    /// start-up candidates and the rest on steps, the first `--burn-in`
    /// fraction of which is discarded.
    pub fn new(args: &Args, mixture: &GaussianMixture) -> Result<Self, ExampleError> {
        let tries = match (args.sampler, args.tries) {
            (SamplerKind::Mtm, t) => t.unwrap_or(DEFAULT_TRIES),
            (SamplerKind::Mh | SamplerKind::Replica, None) => 1,
            (SamplerKind::Mh | SamplerKind::Replica, Some(_)) => {
                return Err(ExampleError::usage("--tries applies only to --sampler mtm"));
            }
        };
        let replica = match (args.sampler, &args.ladder) {
            (SamplerKind::Replica, Some(l)) => Some(parse_ladder(
                l,
                args.exchange.unwrap_or(MoveKind::Neighbour),
            )?),
            (SamplerKind::Replica, None) => {
                return Err(ExampleError::usage(
                    "--sampler replica needs --ladder geometric:M:Tmax or adaptive:M",
                ));
            }
            (_, Some(_)) => {
                return Err(ExampleError::usage(
                    "--ladder applies only to --sampler replica",
                ));
            }
            (_, None) if args.exchange.is_some() => {
                return Err(ExampleError::usage(
                    "--move applies only to --sampler replica",
                ));
            }
            (_, None) => None,
        };
        if args.kernel == KernelKind::Kelemen && mixture.bounds().is_none() {
            return Err(ExampleError::usage(
                "--kernel kelemen needs \"bounds\" in the target file: the small step lives on the unit torus that the bounds box is mapped to",
            ));
        }
        // A replica sweep evaluates every level once; exchanges reuse the
        // cached ln π (tempering a cached value costs no evaluation).
        let evaluations_per_step = match &replica {
            Some(r) => r.temperatures.len() as u64,
            None => 2 * tries - 1,
        };
        let per_chain = args.evaluations / args.chains;
        let startup = (per_chain / STARTUP_SHARE).clamp(1, MAX_STARTUP_CANDIDATES);
        // A ladder evaluates each level's initial state once.
        let initial = replica.as_ref().map_or(0, |r| r.temperatures.len() as u64);
        let steps = per_chain.saturating_sub(startup + initial) / evaluations_per_step;
        // Truncation towards zero: the burn-in is the floor of F·steps.
        let burn_in = (args.burn_in * steps as f64) as u64;
        let draws = steps - burn_in;
        if draws < MIN_DRAWS {
            return Err(ExampleError::usage(format!(
                "--evaluations {} over {} chains leaves {draws} draws per chain after start-up and burn-in; at least {MIN_DRAWS} are needed (raise --evaluations or lower --chains)",
                args.evaluations, args.chains
            )));
        }
        let stored = draws
            .saturating_mul(args.chains)
            .saturating_mul(mixture.dim() as u64);
        if stored > MAX_STORED_VALUES {
            return Err(ExampleError::usage(format!(
                "--evaluations {} would keep {stored} coordinates of draws in memory; at most {MAX_STORED_VALUES} are allowed (lower --evaluations or raise --burn-in)",
                args.evaluations
            )));
        }
        let too_big = |_| ExampleError::usage("--evaluations is too large for this machine");
        Ok(RunPlan {
            sampler: args.sampler,
            kernel: args.kernel,
            scale: args.scale,
            tries: usize::try_from(tries).map_err(too_big)?,
            chains: usize::try_from(args.chains).map_err(too_big)?,
            seed: args.seed,
            threads: usize::try_from(args.threads).map_err(too_big)?,
            startup_candidates: usize::try_from(startup).map_err(too_big)?,
            evaluations_per_step,
            burn_in_steps: usize::try_from(burn_in).map_err(too_big)?,
            draws: usize::try_from(draws).map_err(too_big)?,
            replica,
        })
    }
}
