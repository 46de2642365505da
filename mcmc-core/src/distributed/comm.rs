//! The few message patterns the distributed runners use, over rsmpi:
//! byte messages to a neighbour, a pairwise exchange, a gather of byte
//! blocks on rank 0, and the start-up agreement check. Every helper counts
//! the bytes and messages it sends, for the communication-volume figures.

use super::DistributedError;
use crate::checkpoint::{FNV_OFFSET, fnv1a};
use mpi::point_to_point::{Destination, Source, send_receive_into_with_tags};
use mpi::topology::{Communicator, Rank, SimpleCommunicator};
use mpi::traits::*;
use std::ops::Range;
use std::sync::OnceLock;

/// Bytes and messages a rank has sent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Traffic {
    /// Point-to-point messages sent (a pairwise exchange counts one).
    pub messages: u64,
    /// Payload bytes of those messages.
    pub bytes: u64,
    /// Collective operations joined (all-gathers, gathers).
    pub collectives: u64,
}

/// The contiguous block of `0..n` owned by `rank` of `size`: the first
/// `n mod size` ranks get one item more, so blocks differ by at most one.
pub fn share(n: usize, size: usize, rank: usize) -> Range<usize> {
    let (base, extra) = (n / size, n % size);
    let start = rank * base + rank.min(extra);
    start..start + base + (rank < extra) as usize
}

/// Message tags (one per message kind, so that kinds never match each
/// other whatever the order of sends).
pub(crate) mod tag {
    pub const DENSITIES: i32 = 11;
    pub const DECISION: i32 = 12;
    pub const STATE: i32 = 13;
    pub const POSITION: i32 = 14;
    pub const LENGTH: i32 = 15;
}

pub(crate) fn send_bytes(
    comm: &SimpleCommunicator,
    traffic: &mut Traffic,
    to: usize,
    tag: i32,
    bytes: &[u8],
) {
    comm.process_at_rank(to as Rank).send_with_tag(bytes, tag);
    traffic.messages += 1;
    traffic.bytes += bytes.len() as u64;
}

pub(crate) fn receive_bytes(comm: &SimpleCommunicator, from: usize, tag: i32) -> Vec<u8> {
    comm.process_at_rank(from as Rank)
        .receive_vec_with_tag::<u8>(tag)
        .0
}

/// Sends `bytes` to `partner` and receives its message of kind `tag`
/// simultaneously (no ordering between the two sides, so no deadlock).
pub(crate) fn exchange_bytes(
    comm: &SimpleCommunicator,
    traffic: &mut Traffic,
    partner: usize,
    tag: i32,
    bytes: &[u8],
) -> Vec<u8> {
    let p = comm.process_at_rank(partner as Rank);
    let mut len = 0u64;
    send_receive_into_with_tags(
        &(bytes.len() as u64),
        &p,
        tag::LENGTH,
        &mut len,
        &p,
        tag::LENGTH,
    );
    let mut buf = vec![0u8; len as usize];
    send_receive_into_with_tags(bytes, &p, tag, &mut buf[..], &p, tag);
    traffic.messages += 1;
    traffic.bytes += 8 + bytes.len() as u64;
    buf
}

/// Exchanges two numbers with `partner` (both sides send two): the swap
/// densities, without the length handshake of [`exchange_bytes`].
pub(crate) fn exchange_pair(
    comm: &SimpleCommunicator,
    traffic: &mut Traffic,
    partner: usize,
    own: [f64; 2],
) -> [f64; 2] {
    let p = comm.process_at_rank(partner as Rank);
    let mut other = [0.0f64; 2];
    send_receive_into_with_tags(
        &own[..],
        &p,
        tag::DENSITIES,
        &mut other[..],
        &p,
        tag::DENSITIES,
    );
    traffic.messages += 1;
    traffic.bytes += 16;
    other
}

/// Every rank's `value`, in rank order.
pub fn all_gather_u64(comm: &SimpleCommunicator, traffic: &mut Traffic, value: u64) -> Vec<u64> {
    let mut out = vec![0u64; comm.size() as usize];
    comm.all_gather_into(&value, &mut out[..]);
    traffic.collectives += 1;
    out
}

/// Gathers every rank's byte block on rank 0, in rank order (`None` on the
/// other ranks).
pub fn gather_bytes(
    comm: &SimpleCommunicator,
    traffic: &mut Traffic,
    bytes: &[u8],
) -> Option<Vec<Vec<u8>>> {
    let root = comm.process_at_rank(0);
    traffic.collectives += 1;
    if comm.rank() == 0 {
        let size = comm.size() as usize;
        let mut lens = vec![0u64; size];
        root.gather_into_root(&(bytes.len() as u64), &mut lens[..]);
        let mut out = Vec::with_capacity(size);
        out.push(bytes.to_vec());
        for (r, &len) in lens.iter().enumerate().skip(1) {
            let mut buf = vec![0u8; len as usize];
            comm.process_at_rank(r as Rank)
                .receive_into_with_tag(&mut buf[..], tag::STATE);
            out.push(buf);
        }
        Some(out)
    } else {
        root.gather_into(&(bytes.len() as u64));
        root.send_with_tag(bytes, tag::STATE);
        traffic.messages += 1;
        traffic.bytes += bytes.len() as u64;
        None
    }
}

/// Rank 0's `bytes` on every rank (collective; the other ranks pass
/// anything, e.g. an empty slice): the length, then the bytes.
pub fn broadcast_bytes(comm: &SimpleCommunicator, traffic: &mut Traffic, bytes: &[u8]) -> Vec<u8> {
    let root = comm.process_at_rank(0);
    let mut len = bytes.len() as u64;
    root.broadcast_into(&mut len);
    let mut buf = if comm.rank() == 0 {
        bytes.to_vec()
    } else {
        vec![0u8; len as usize]
    };
    root.broadcast_into(&mut buf[..]);
    traffic.collectives += 2;
    if comm.rank() == 0 {
        traffic.bytes += len * (comm.size() as u64 - 1);
    }
    buf
}

/// A fingerprint of the running executable (0 when it cannot be read), so
/// that ranks started from different builds refuse to run together.
pub(crate) fn binary_fingerprint() -> u64 {
    static FP: OnceLock<u64> = OnceLock::new();
    *FP.get_or_init(|| {
        std::env::current_exe()
            .and_then(std::fs::read)
            .map(|b| fnv1a(&b, FNV_OFFSET))
            .unwrap_or(0)
    })
}

/// The start-up handshake every distributed run makes: each rank reports
/// whether its local set-up succeeded and a fingerprint of its inputs (and
/// of its executable); every rank gets every report, so all of them return
/// the same error instead of some waiting forever for a partner that gave
/// up. `local` is this rank's set-up result, `what` names the inputs.
pub fn agree<T>(
    comm: &SimpleCommunicator,
    traffic: &mut Traffic,
    what: &str,
    local: Result<(T, u64), DistributedError>,
) -> Result<T, DistributedError> {
    let binary = binary_fingerprint();
    let (status, fp) = match &local {
        Ok((_, fp)) => (0u64, *fp),
        Err(_) => (1, 0),
    };
    let statuses = all_gather_u64(comm, traffic, status);
    let fps = all_gather_u64(comm, traffic, fp);
    let binaries = all_gather_u64(comm, traffic, binary);
    let local = match local {
        Err(e) => {
            return Err(DistributedError::Rank {
                rank: comm.rank() as usize,
                reason: e.to_string(),
            });
        }
        Ok((v, _)) => v,
    };
    if let Some(r) = statuses.iter().position(|&s| s != 0) {
        return Err(DistributedError::Rank {
            rank: r,
            reason: "its set-up failed (its own error is printed by that rank)".into(),
        });
    }
    if let Some(r) = binaries.iter().position(|&b| b != binaries[0]) {
        return Err(DistributedError::Mismatch {
            rank: r,
            what: "executable".into(),
        });
    }
    if let Some(r) = fps.iter().position(|&f| f != fps[0]) {
        return Err(DistributedError::Mismatch {
            rank: r,
            what: what.into(),
        });
    }
    Ok(local)
}

#[cfg(test)]
mod tests {
    use super::share;

    #[test]
    fn shares_cover_everything_once_and_differ_by_at_most_one() {
        for n in 0..20 {
            for size in 1..6 {
                let blocks: Vec<_> = (0..size).map(|r| share(n, size, r)).collect();
                assert_eq!(blocks[0].start, 0);
                assert_eq!(blocks[size - 1].end, n);
                for w in blocks.windows(2) {
                    assert_eq!(w[0].end, w[1].start);
                }
                let lens: Vec<_> = blocks.iter().map(|b| b.len()).collect();
                assert!(lens.iter().max().unwrap() - lens.iter().min().unwrap() <= 1);
            }
        }
        assert_eq!(share(7, 3, 0), 0..3);
        assert_eq!(share(7, 3, 2), 5..7);
    }
}
