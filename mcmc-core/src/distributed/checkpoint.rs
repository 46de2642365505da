//! Checkpoint files of distributed runs: how a generator's state is saved
//! and read back (the runs decide what goes in; the file pieces are
//! [`crate::checkpoint`]'s).
//!
//! A checkpoint is written by rank 0 alone (atomically, see
//! [`crate::checkpoint`]); it is read by rank 0 and broadcast, so the
//! other ranks need no shared file system.

use super::DistributedError;
use super::comm::{Traffic, all_gather_u64, broadcast_bytes};
use crate::checkpoint::{read_optional, write_bytes};
use crate::rng::ChainRng;
use mpi::topology::{Communicator, SimpleCommunicator};
use std::path::Path;

/// First word of a replica-exchange checkpoint ("mcmcRE02": the exchange
/// stream's state words are saved, so a resume costs no replay of it).
pub(crate) const REPLICA_MAGIC: u64 = u64::from_le_bytes(*b"mcmcRE02");

/// First word of the earlier format, which saved only the exchange
/// stream's position (a forged position of 2^63 made a resume replay the
/// stream for centuries); refused with a message that says so.
pub(crate) const REPLICA_MAGIC_V1: u64 = u64::from_le_bytes(*b"mcmcRE01");

/// The four state words of a generator ([`crate::rng::rng_words`]).
pub(crate) fn rng_words(rng: &ChainRng) -> Vec<u64> {
    crate::rng::rng_words(rng).to_vec()
}

/// The generator with state `words` (from [`rng_words`]).
pub(crate) fn rng_from_words(words: &[u64]) -> Result<ChainRng, DistributedError> {
    <[u64; 4]>::try_from(words)
        .ok()
        .and_then(crate::rng::rng_from_words)
        .ok_or_else(|| {
            DistributedError::Checkpoint(format!(
                "a generator state must be 4 words, not all zero (got {words:?})"
            ))
        })
}

/// The file at `path` as rank 0 reads it, on every rank (collective):
/// `None` when there is none; an unreadable file is the same error on
/// every rank (rank 0's own message there).
pub(crate) fn read_on_rank_0(
    comm: &SimpleCommunicator,
    traffic: &mut Traffic,
    path: &Path,
) -> Result<Option<Vec<u8>>, DistributedError> {
    // Rank 0's file, prefixed by a status byte: 0 none, 1 unreadable, 2 read.
    let (own_error, message) = if comm.rank() == 0 {
        match read_optional(path) {
            Ok(None) => (None, vec![0u8]),
            Ok(Some(mut b)) => {
                b.insert(0, 2);
                (None, b)
            }
            Err(e) => (Some(e), vec![1u8]),
        }
    } else {
        (None, Vec::new())
    };
    let mut message = broadcast_bytes(comm, traffic, &message);
    match message.first() {
        Some(0) => Ok(None),
        Some(2) => {
            message.remove(0);
            Ok(Some(message))
        }
        _ => Err(DistributedError::Checkpoint(own_error.unwrap_or_else(
            || "rank 0 could not read the checkpoint (its error is printed there)".into(),
        ))),
    }
}

/// Writes `bytes` (rank 0's; `None` on the other ranks) to `path` on rank
/// 0 (collective): every rank returns the same result.
pub(crate) fn write_on_rank_0(
    comm: &SimpleCommunicator,
    traffic: &mut Traffic,
    path: &Path,
    bytes: Option<Vec<u8>>,
) -> Result<(), DistributedError> {
    let written = bytes.map_or(Ok(()), |b| write_bytes(path, &b));
    let failed = all_gather_u64(comm, traffic, written.is_err() as u64);
    match written {
        Err(e) => Err(DistributedError::Checkpoint(e)),
        Ok(()) if failed[0] != 0 => Err(DistributedError::Checkpoint(
            "rank 0 could not write the checkpoint (its error is printed there)".into(),
        )),
        Ok(()) => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::stream_rng;
    use rand::Rng;

    #[test]
    fn a_generator_continues_from_its_saved_state() {
        let mut a = stream_rng(5, 3);
        for _ in 0..17 {
            a.next_u64();
        }
        let mut b = rng_from_words(&rng_words(&a)).unwrap();
        let (x, y): (Vec<u64>, Vec<u64>) = (0..100).map(|_| (a.next_u64(), b.next_u64())).unzip();
        assert_eq!(x, y);
        // Control: a state one draw behind gives other numbers.
        let mut c = stream_rng(5, 3);
        for _ in 0..16 {
            c.next_u64();
        }
        let mut d = rng_from_words(&rng_words(&c)).unwrap();
        assert_ne!(d.next_u64(), x[0]);
        assert!(rng_from_words(&[0, 0, 0, 0]).is_err());
        assert!(rng_from_words(&[1, 2, 3]).is_err());
    }
}
