//! The `mixture` example: samples a Gaussian mixture described in JSON and
//! reports moments and convergence diagnostics.
//!
//! ```text
//! cargo run --release --example mixture -- --target FILE.json \
//!     --sampler mh|mtm --kernel gaussian|kelemen|adaptive --scale S \
//!     --chains C --evaluations N --seed K --json [--burn-in F] [--tries K] [--threads T]
//! ```
//!
//! # Target file
//!
//! `{"components":[{"weight":w,"mean":[..],"cov":[[..]]} or
//! {"weight":w,"mean":[..],"sigma":s}], "bounds":[[lo,hi],..]}`. Weights are
//! positive and normalised by their sum; every component gives exactly one of
//! `cov` (symmetric positive definite, `d × d`) and `sigma` (isotropic).
//! `bounds` is optional: outside the box `ln π = −∞`. Unknown fields are
//! errors. Examples are in `examples/mixture/targets/`.
//!
//! # What a run does
//!
//! - **Budget.** `--evaluations N` is the total number of target
//!   evaluations over all chains. Each chain gets `B = ⌊N/C⌋` (the remainder
//!   is left unused so that chains have equal length), spends
//!   `max(1, min(256, ⌊B/20⌋))` of it on start-up candidates and the rest on
//!   steps costing 1 evaluation (MH) or `2k − 1` (MTM with `k` tries). The
//!   report's `evaluations` is what was actually spent. Every kept draw is
//!   stored for the rank-based diagnostics, so runs that would keep more than
//!   250 million coordinates (2 GB) are refused.
//! - **Start points.** Start-up importance resampling per chain, see
//!   [`startup`].
//! - **Burn-in.** The first `⌊F · steps⌋` steps of each chain (`F = 1/3`
//!   unless `--burn-in F`) are discarded; the adaptive kernel adapts only
//!   during them and is frozen afterwards.
//! - **Chains** run in parallel with `mcmc_core::runner::run_chains`; chain
//!   `c` draws from the stream `(seed, c)`, so the output (but `seconds`)
//!   does not depend on `--threads`.
//! - **Kelemen.** The torus small step needs bounds: the chain moves on the
//!   unit torus `[0,1)^d` and `x_i = lo_i + u_i (hi_i − lo_i)` (see
//!   [`space::Coordinates`]). Because the torus wraps, a step may cross from
//!   one face of the box to the opposite one; the step is symmetric, so this
//!   is still a valid Metropolis–Hastings chain for the truncated target.
//!   Without bounds the run is refused.
//!
//! # Output
//!
//! See [`report::Report`]: `evaluations`, `seconds`, per-coordinate `mean`,
//! `second_moment`, `mcse_mean`, `ess_bulk`, `ess_tail`, `rhat` (from
//! `mcmc_core::diagnostics`, pooled over chains), `acceptance`,
//! `component_visits`, and a few more fields describing the run.
//!
//! # Errors
//!
//! Invalid flags or target files: one line on stderr, exit code 2.
//! Failures while sampling: one line, exit code 1.
//!
//! # Extending
//!
//! Replica exchange is meant to join as `--sampler replica` (a variant of
//! [`cli::SamplerKind`], its flags on [`cli::Args`], its cost per step in
//! [`plan::RunPlan`], and its driver as a new arm in [`sampler::run`]),
//! spending `--evaluations` over all levels.

pub mod cli;
pub mod error;
pub mod plan;
pub mod report;
pub mod sampler;
pub mod space;
pub mod startup;
pub mod target;

use std::ffi::OsString;
use std::time::Instant;

use clap::Parser;
use clap::error::ErrorKind;

pub use error::ExampleError;
pub use report::Report;
pub use target::GaussianMixture;

use cli::Args;
use plan::RunPlan;

/// Parses `args` (the first is the program name), loads the target, samples
/// and returns the report.
pub fn run_args<I, T>(args: I) -> Result<(Args, Report), ExampleError>
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let args = Args::try_parse_from(args).map_err(|e| ExampleError::from_clap(&e))?;
    let report = run(&args)?;
    Ok((args, report))
}

/// Runs the example with parsed flags.
pub fn run(args: &Args) -> Result<Report, ExampleError> {
    let mixture = GaussianMixture::from_file(&args.target)?;
    let plan = RunPlan::new(args, &mixture)?;
    let start = Instant::now();
    let runs = sampler::run(&plan, &mixture)?;
    let seconds = start.elapsed().as_secs_f64();
    Report::new(&plan, &runs, seconds)
}

/// The whole command: what to print on stdout on success (the report, or
/// clap's help/version text), or the error to print and exit with.
pub fn run_cli<I, T>(args: I) -> Result<String, ExampleError>
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let args = match Args::try_parse_from(args) {
        Ok(a) => a,
        Err(e) if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) => {
            return Ok(e.render().to_string());
        }
        Err(e) => return Err(ExampleError::from_clap(&e)),
    };
    let report = run(&args)?;
    Ok(if args.json {
        report.to_json() + "\n"
    } else {
        report.to_text()
    })
}
