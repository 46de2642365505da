//! Independent chains sharded by rank.

use super::DistributedError;
use super::comm::{FNV_OFFSET, Traffic, agree, fnv1a, gather_bytes, share};
use super::wire::{Wire, decode, encode};
use crate::rng::ChainRng;
use crate::runner::run_chain_range;
use mpi::topology::Communicator;

/// Runs `work(c, rng_c)` for chains `c = 0..chains`, each rank the chains
/// of its block [`share`]`(chains, size, rank)` (in parallel on its rayon
/// threads), with the streams of [`crate::runner::run_chains`]. Returns the
/// results in chain order on rank 0 (`Some`), `None` on the other ranks,
/// and the traffic this rank caused: bit-identical to `run_chains(chains,
/// seed, work)` for any number of ranks and threads.
///
/// Ranks called with a different `chains`, `seed` or `fingerprint` (any
/// number describing the rest of the input, e.g. a hash of the data; 0 if
/// none) or from a different executable all return
/// [`DistributedError::Mismatch`] before running anything.
pub fn run_chains_distributed<R, C>(
    comm: &C,
    chains: usize,
    seed: u64,
    fingerprint: u64,
    work: impl Fn(usize, ChainRng) -> R + Sync + Send,
) -> Result<(Option<Vec<R>>, Traffic), DistributedError>
where
    R: Wire + Send,
    C: Communicator,
{
    let comm = comm.duplicate();
    let mut traffic = Traffic::default();
    let mut fp = FNV_OFFSET;
    for v in [chains as u64, seed, fingerprint] {
        fp = fnv1a(&v.to_le_bytes(), fp);
    }
    agree(
        &comm,
        &mut traffic,
        "chain count, seed or input fingerprint",
        Ok(((), fp)),
    )?;
    let (rank, size) = (comm.rank() as usize, comm.size() as usize);
    let local = run_chain_range(share(chains, size, rank), seed, work);
    let Some(blocks) = gather_bytes(&comm, &mut traffic, &encode(&local)) else {
        return Ok((None, traffic));
    };
    let mut out = Vec::with_capacity(chains);
    for block in blocks {
        out.extend(decode::<Vec<R>>(&block)?);
    }
    Ok((Some(out), traffic))
}
