//! Independent chains sharded by rank, and their resumable form.

use super::DistributedError;
use super::checkpoint::{read_on_rank_0, write_on_rank_0};
use super::comm::{Traffic, agree, all_gather_u64, gather_bytes, share};
use super::wire::{Wire, decode, encode};
use crate::checkpoint::{FNV_OFFSET, chains_fingerprint, decode_chains, encode_chains, fnv1a};
use crate::resume::{
    Checkpointed, Checkpointing, Progress, ResumableChain, iterations_done, restore_all, save_all,
};
use crate::rng::ChainRng;
use crate::runner::run_chain_range;
use mpi::topology::{Communicator, SimpleCommunicator};
use rayon::prelude::*;
use std::time::Instant;

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

/// What [`run_resumable_distributed`] returns on a rank: the run's
/// outputs and progress on rank 0 (`None` on the others), and the rank's
/// traffic.
pub type RankOutcome<T> = (Option<Checkpointed<T>>, Traffic);

/// [`crate::resume::run_resumable`] over ranks: each rank makes, advances
/// and saves the chains of its block [`share`]`(chains, size, rank)`, and
/// the run continues from `checkpointing.path` on any number of ranks.
/// Rank 0 alone reads the file (and broadcasts it) and writes it (with
/// every rank's chains, gathered in chain order: the file of the single
/// process run); the outputs are gathered on rank 0 in chain order, so
/// they are bit-identical to the single-process run's, for any number of
/// ranks and threads and however the run was cut into sessions.
///
/// Between blocks every rank reports whether it still has iterations to
/// make and whether its [`Stop`](crate::resume::Stop) fired (its deadline,
/// its flag: a Ctrl-C to any rank), and rank 0 whether a checkpoint is
/// due (its clock alone decides): all ranks stop, save and go on together.
///
/// Returns, on rank 0, the outputs (when the run got to its end) and the
/// progress (`None` on the other ranks), and this rank's traffic. Errors
/// are the same on every rank: a handshake as in [`run_chains_distributed`]
/// (`make` failing on a rank, another chain count, seed, kind of chain,
/// fingerprint or executable), and the checkpoint's errors (wrapped in
/// [`DistributedError::Core`], as [`crate::resume::run_resumable`]
/// returns them; a chain that does not restore names itself on its rank).
pub fn run_resumable_distributed<C, Comm>(
    comm: &Comm,
    chains: usize,
    seed: u64,
    make: impl Fn(usize, ChainRng) -> crate::Result<C> + Sync + Send,
    checkpointing: &Checkpointing,
) -> Result<RankOutcome<C::Output>, DistributedError>
where
    C: ResumableChain,
    C::Output: Wire,
    Comm: Communicator,
{
    let comm = comm.duplicate();
    let mut traffic = Traffic::default();
    let (rank, size) = (comm.rank() as usize, comm.size() as usize);
    let path = &checkpointing.path;
    let fingerprint = chains_fingerprint(C::KIND, chains, seed, checkpointing.fingerprint);
    let owned = share(chains, size, rank);
    let local = run_chain_range(owned.clone(), seed, make)
        .into_iter()
        .collect::<crate::Result<Vec<C>>>();
    let mut local = agree(
        &comm,
        &mut traffic,
        "chain count, seed, kind of chain or input fingerprint",
        local.map(|c| (c, fingerprint)).map_err(Into::into),
    )?;
    if let Some(bytes) = read_on_rank_0(&comm, &mut traffic, path)? {
        // The same bytes on every rank: the same verdict.
        let words = decode_chains(path, &bytes, fingerprint, chains)?;
        let restored = restore_all(path, &mut local, &words[owned.clone()], owned.start);
        let votes = all_gather_u64(&comm, &mut traffic, restored.is_err() as u64);
        restored?;
        if let Some(r) = votes.iter().position(|&v| v != 0) {
            return Err(DistributedError::Rank {
                rank: r,
                reason: "a chain of its block did not restore (it prints which)".into(),
            });
        }
    }
    let sum = |comm: &SimpleCommunicator, traffic: &mut Traffic, v: u64| -> u64 {
        all_gather_u64(comm, traffic, v).iter().sum()
    };
    let resumed_from = sum(&comm, &mut traffic, iterations_done(&local));
    let total = sum(&comm, &mut traffic, local.iter().map(C::total).sum());
    let save = |comm: &SimpleCommunicator, traffic: &mut Traffic, local: &[C]| {
        let blocks = gather_bytes(comm, traffic, &encode(&save_all(local)));
        let bytes = blocks.map(|blocks| {
            let all: Vec<Vec<u64>> = blocks
                .iter()
                .flat_map(|b| decode::<Vec<Vec<u64>>>(b).expect("a rank's chains"))
                .collect();
            encode_chains(fingerprint, &all)
        });
        write_on_rank_0(comm, traffic, path, bytes)
    };
    let block = checkpointing.block.max(1);
    let (mut session, mut saved) = (0, Instant::now());
    loop {
        let unfinished = local.iter().any(|c| c.done() < c.total());
        let stop = checkpointing.stop.requested(session);
        let due = rank == 0 && session > 0 && saved.elapsed() >= checkpointing.every;
        let report = unfinished as u64 | (stop as u64) << 1 | (due as u64) << 2;
        let reports = all_gather_u64(&comm, &mut traffic, report);
        if reports.iter().all(|r| r & 1 == 0) {
            break;
        }
        if reports.iter().any(|r| r & 2 != 0) {
            save(&comm, &mut traffic, &local)?;
            let done = sum(&comm, &mut traffic, iterations_done(&local));
            let progress = Progress {
                resumed_from,
                done,
                total,
            };
            let out = (rank == 0).then_some(Checkpointed {
                outputs: None,
                progress,
            });
            return Ok((out, traffic));
        }
        if reports[0] & 4 != 0 {
            save(&comm, &mut traffic, &local)?;
            saved = Instant::now();
        }
        local.par_iter_mut().for_each(|c| c.advance(block));
        session += block;
    }
    // The end is saved too (a run started again returns at once).
    save(&comm, &mut traffic, &local)?;
    let outputs: Vec<C::Output> = local.into_iter().map(C::finish).collect();
    let Some(blocks) = gather_bytes(&comm, &mut traffic, &encode(&outputs)) else {
        return Ok((None, traffic));
    };
    let mut all = Vec::with_capacity(chains);
    for block in blocks {
        all.extend(decode::<Vec<C::Output>>(&block)?);
    }
    let progress = Progress {
        resumed_from,
        done: total,
        total,
    };
    Ok((
        Some(Checkpointed {
            outputs: Some(all),
            progress,
        }),
        traffic,
    ))
}
