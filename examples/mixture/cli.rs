//! Command-line flags.

use std::path::PathBuf;

use clap::{Parser, ValueEnum};

/// Which transition algorithm drives the chains.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SamplerKind {
    /// Metropolis–Hastings: one target evaluation per step.
    Mh,
    /// Multiple-try Metropolis with `--tries k`: `2k − 1` evaluations per step.
    Mtm,
    /// Replica exchange over a temperature ladder (`--ladder`, `--move`):
    /// one evaluation per level per sweep; a chain is a whole ladder.
    Replica,
}

/// The exchange move of `--sampler replica`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum MoveKind {
    /// Neighbour swaps, hottest pair first, after each level's mutation.
    Neighbour,
    /// Deterministic even–odd (non-reversible) neighbour swaps.
    EvenOdd,
    /// Importance-sampled permutations of all levels (subset DP).
    IsPermutation,
    /// Importance-sampled swaps.
    IsSwap,
    /// Original equi-energy moves (8 rings).
    Eem,
    /// Frequent equi-energy moves (8 rings).
    FrequentEem,
    /// The equi-energy sampler (8 rings, p_EEJ = 0.1), jumps enabled once
    /// every ring set is filled (the thesis).
    Ees,
    /// The equi-energy sampler with Kou et al.'s rule: a jump needs only the
    /// current ring's set to be non-empty.
    EesKou,
    /// The adaptive equi-energy sampler (16 quantile rings, p_EEJ = 0.1,
    /// at most 10 000 stored states per ring).
    AdaptiveEes,
}

impl MoveKind {
    /// The name used on the command line and in the report.
    pub fn name(self) -> &'static str {
        match self {
            MoveKind::Neighbour => "neighbour",
            MoveKind::EvenOdd => "even-odd",
            MoveKind::IsPermutation => "is-permutation",
            MoveKind::IsSwap => "is-swap",
            MoveKind::Eem => "eem",
            MoveKind::FrequentEem => "frequent-eem",
            MoveKind::Ees => "ees",
            MoveKind::EesKou => "ees-kou",
            MoveKind::AdaptiveEes => "adaptive-ees",
        }
    }
}

/// Which proposal kernel the sampler uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum KernelKind {
    /// Isotropic Gaussian random walk with standard deviation `--scale` per coordinate.
    Gaussian,
    /// Kelemen's exponential small step (`s1 = 1/1024`, `s2 = 1/64`) on the
    /// unit torus that the target's `bounds` box is mapped to (needs `bounds`).
    Kelemen,
    /// Adaptive covariance (Haario et al.), fixed safety component of scale
    /// `--scale`; adapts during burn-in, frozen afterwards.
    Adaptive,
}

impl SamplerKind {
    /// The name used on the command line and in the report.
    pub fn name(self) -> &'static str {
        match self {
            SamplerKind::Mh => "mh",
            SamplerKind::Mtm => "mtm",
            SamplerKind::Replica => "replica",
        }
    }
}

impl KernelKind {
    /// The name used on the command line and in the report.
    pub fn name(self) -> &'static str {
        match self {
            KernelKind::Gaussian => "gaussian",
            KernelKind::Kelemen => "kelemen",
            KernelKind::Adaptive => "adaptive",
        }
    }
}

/// Samples a Gaussian mixture described in a JSON file and reports moments
/// and convergence diagnostics.
#[derive(Clone, Debug, Parser)]
#[command(name = "mixture", version, about)]
pub struct Args {
    /// The mixture: `{"components":[{"weight":w,"mean":[..],"cov":[[..]]}` or
    /// `{"weight":w,"mean":[..],"sigma":s}], "bounds":[[lo,hi],..]}` (bounds
    /// optional).
    #[arg(long, value_name = "FILE.json")]
    pub target: PathBuf,

    /// Transition algorithm.
    #[arg(long, value_enum, default_value_t = SamplerKind::Mh)]
    pub sampler: SamplerKind,

    /// Proposal kernel.
    #[arg(long, value_enum, default_value_t = KernelKind::Gaussian)]
    pub kernel: KernelKind,

    /// Standard deviation per coordinate of the Gaussian random walk (for
    /// `adaptive`: of its fixed component; ignored by `kelemen`).
    #[arg(long, value_name = "S", default_value_t = 1.0, value_parser = positive_finite)]
    pub scale: f64,

    /// Number of independent chains (R-hat is computed across them).
    #[arg(long, value_name = "C", default_value_t = 4, value_parser = clap::value_parser!(u64).range(1..=4096))]
    pub chains: u64,

    /// Total budget of target evaluations over all chains, start-up included.
    #[arg(long, value_name = "N", default_value_t = 100_000, value_parser = clap::value_parser!(u64).range(1..))]
    pub evaluations: u64,

    /// Seed: chain c draws from the stream (seed, c).
    #[arg(long, value_name = "K", default_value_t = 0)]
    pub seed: u64,

    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,

    /// Fraction of each chain's steps discarded as burn-in, in [0, 1).
    #[arg(long, value_name = "F", default_value_t = 1.0 / 3.0, value_parser = fraction)]
    pub burn_in: f64,

    /// Tries per multiple-try step (only with --sampler mtm; default 4).
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u64).range(1..=1024))]
    pub tries: Option<u64>,

    /// Temperature ladder of `--sampler replica`: `geometric:M:Tmax` (M levels,
    /// T from 1 to Tmax, log-evenly spaced) or `adaptive:M` (starts geometric
    /// up to T = 1000 and is tuned during burn-in to equalise swap rejection,
    /// Syed et al. 2021; needs `--move neighbour` or `even-odd`). Level l's
    /// random-walk scale is `--scale·√T_l` (Kelemen steps: s1, s2 × √T_l).
    #[arg(long, value_name = "LADDER")]
    pub ladder: Option<String>,

    /// Exchange move of `--sampler replica` (default: neighbour).
    #[arg(long = "move", value_enum, value_name = "MOVE")]
    pub exchange: Option<MoveKind>,

    /// Worker threads (0: one per core). The result does not depend on it.
    #[arg(long, value_name = "T", default_value_t = 0, value_parser = clap::value_parser!(u64).range(0..=1024))]
    pub threads: u64,
}

/// Default number of tries for multiple-try Metropolis.
pub const DEFAULT_TRIES: u64 = 4;

fn positive_finite(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err("must be finite and positive".into())
    }
}

fn fraction(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if (0.0..1.0).contains(&v) {
        Ok(v)
    } else {
        Err("must lie in [0, 1)".into())
    }
}
