//! Distributed runs over MPI (cargo feature `mpi`, rsmpi over the system's
//! MPI library; see `docs/distributed.md`).
//!
//! - [`run_chains_distributed`]: independent chains sharded by rank in
//!   contiguous blocks ([`share`]); chain `c` draws from
//!   `stream_rng(seed, c)` exactly as in [`crate::runner::run_chains`], and
//!   rank 0 gets the results in chain order.
//!   [`run_resumable_distributed`] is its resumable form
//!   ([`crate::resume`]): checkpointed by rank 0, continued on any number
//!   of ranks.
//! - [`DistributedReplicaExchange`]: replica exchange with the levels
//!   spread over ranks in contiguous blocks, for the deterministic even–odd
//!   and the neighbour-sweep schedules. Each level mutates with its own
//!   stream and algorithm (the same `Algorithm::step` on the same
//!   `LevelTarget` as [`crate::replica::ReplicaExchange`]); swap partners
//!   on different ranks exchange two log densities each way, and the
//!   states only when the swap is accepted (as Pigeons does); the swap
//!   decision is [`crate::replica::swap_log_acceptance`] with
//!   [`crate::mh::accept`].
//!
//! **Determinism.** Both runners give bit-identical results for any
//! number of ranks and threads, and the same results as the single-process
//! [`crate::runner::run_chains`] and [`crate::replica::ReplicaExchange`]
//! (with [`crate::replica::EvenOdd`] or [`crate::replica::NeighbourSwap`])
//! for the same seed. The swap uniforms come from the single-process
//! exchange stream: every rank keeps a copy and learns the position of its
//! pairs' uniforms from how many uniforms the lower-level pairs used
//! (one all-gather of a counter per even–odd sweep; the neighbour sweep
//! passes the position down with the swap decision).
//!
//! **Failures.** Every run starts with a handshake: ranks whose set-up
//! failed, or whose inputs (levels, seed, initial densities at every
//! level) or executable differ from rank 0's, make every rank return the
//! same [`DistributedError`] instead of waiting for each other.

mod chains;
mod checkpoint;
mod comm;
mod replica;
mod wire;

pub use crate::checkpoint::{FNV_OFFSET, fnv1a};
pub use chains::{RankOutcome, run_chains_distributed, run_resumable_distributed};
pub use comm::{Traffic, agree, all_gather_u64, broadcast_bytes, gather_bytes, share};
pub use mpi;
pub use replica::{DistributedReplicaExchange, DistributedSchedule};
pub use wire::{Wire, decode, encode};

use crate::error::CoreError;

/// What can go wrong in a distributed run.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum DistributedError {
    /// A set-up error of the library on this rank.
    #[error(transparent)]
    Core(#[from] CoreError),
    /// Another rank's set-up failed.
    #[error("rank {rank} failed: {reason}")]
    Rank {
        /// The failing rank.
        rank: usize,
        /// Its error.
        reason: String,
    },
    /// A rank's inputs or executable differ from rank 0's.
    #[error(
        "rank {rank} has a different {what} than rank 0 (all ranks must run the same binary on the same inputs)"
    )]
    Mismatch {
        /// The first differing rank.
        rank: usize,
        /// What differs.
        what: String,
    },
    /// A message could not be decoded.
    #[error("malformed message: {0}")]
    Wire(String),
    /// A checkpoint could not be written, read or used.
    #[error("checkpoint: {0}")]
    Checkpoint(String),
}
