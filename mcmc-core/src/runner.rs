//! Running many chains in parallel on rayon.
//!
//! Chain `c` always draws from `stream_rng(seed, c)` and results are
//! collected in chain order, so a run is bit-identical for any number of
//! threads.

use crate::rng::{ChainRng, stream_rng};
use rayon::prelude::*;

/// Runs `work(c, rng_c)` for chains `c = 0..chains` in parallel and returns
/// the results in chain order.
///
/// ```
/// use mcmc_core::runner::run_chains;
/// use rand::Rng;
/// let a = run_chains(4, 9, |_, mut rng| rng.next_u64());
/// let b = run_chains(4, 9, |_, mut rng| rng.next_u64());
/// assert_eq!(a, b);
/// ```
pub fn run_chains<R: Send>(
    chains: usize,
    seed: u64,
    work: impl Fn(usize, ChainRng) -> R + Sync + Send,
) -> Vec<R> {
    run_chain_range(0..chains, seed, work)
}

/// Runs `work(c, rng_c)` for the chains `c` in `range` only (one process's
/// share of a distributed run), in parallel, with the same streams as
/// [`run_chains`], and returns the results in chain order.
pub fn run_chain_range<R: Send>(
    range: std::ops::Range<usize>,
    seed: u64,
    work: impl Fn(usize, ChainRng) -> R + Sync + Send,
) -> Vec<R> {
    range
        .into_par_iter()
        .map(|c| work(c, stream_rng(seed, c as u64)))
        .collect()
}

/// Runs `f` on a dedicated pool of `threads` threads (0 = rayon's default).
pub fn with_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    match rayon::ThreadPoolBuilder::new().num_threads(threads).build() {
        Ok(pool) => pool.install(f),
        Err(_) => f(),
    }
}
