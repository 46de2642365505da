//! Command-line flags.

use std::path::PathBuf;

use clap::{Parser, ValueEnum};

/// Which transition algorithm drives the chains.
///
/// Replica exchange is meant to join here as a third variant (`replica`),
/// with its own flags (`--ladder`, `--move`) on [`Args`] and its own driver
/// in the sampler module.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SamplerKind {
    /// Metropolis–Hastings: one target evaluation per step.
    Mh,
    /// Multiple-try Metropolis with `--tries k`: `2k − 1` evaluations per step.
    Mtm,
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
    /// The mixture: {"components":[{"weight":w,"mean":[..],"cov":[[..]]} or
    /// {"weight":w,"mean":[..],"sigma":s}], "bounds":[[lo,hi],..] (optional)}.
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
