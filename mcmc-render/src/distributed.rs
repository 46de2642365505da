//! The MPI [`Cluster`] (cargo feature `mpi`): start-up, the input
//! handshake and the drivers' collectives, on `mcmc-core`'s distributed
//! layer (its byte encoding, gather and start-up agreement). See
//! `docs/distributed.md`.

use crate::cluster::{Cluster, Parcel, install};
use crate::film::{Film, Filter};
use mcmc_core::distributed::mpi::environment::{Threading, Universe, initialize_with_threading};
use mcmc_core::distributed::mpi::topology::{Communicator, SimpleCommunicator};
use mcmc_core::distributed::{
    DistributedError, Traffic, Wire, agree, all_gather_u64, broadcast_bytes, decode, encode,
    gather_bytes,
};
use serde_json::Value;
use std::sync::{Arc, Mutex, OnceLock};

/// The process's MPI cluster, once [`start`] has run.
static MPI: OnceLock<MpiCluster> = OnceLock::new();

/// The MPI environment of a distributed render: MPI is finalised when it
/// is dropped, so the command line holds it until its outputs are written.
pub struct Session {
    _universe: Universe,
}

/// The world communicator with this rank's traffic counters. MPI is
/// initialised with [`Threading::Serialized`] and every call goes through
/// the mutex, so the calls may come from any thread (the drivers run on a
/// rayon worker) but never two at once.
struct World {
    comm: SimpleCommunicator,
    traffic: Traffic,
}

// SAFETY: the communicator is a handle that MPI (initialised at
// `Threading::Serialized` or above) lets any thread use as long as calls
// do not overlap, which the mutex around `World` guarantees.
unsafe impl Send for World {}

/// The MPI cluster of the process.
struct MpiCluster {
    world: Mutex<World>,
    rank: usize,
    size: usize,
}

impl MpiCluster {
    fn with<R>(&self, f: impl FnOnce(&SimpleCommunicator, &mut Traffic) -> R) -> R {
        let mut w = self.world.lock().unwrap_or_else(|e| e.into_inner());
        let World { comm, traffic } = &mut *w;
        f(comm, traffic)
    }
}

/// Starts MPI (a lone process started without `mpirun` is a world of one)
/// and installs its cluster for the drivers.
pub fn start() -> Result<Session, String> {
    let (universe, threading) = initialize_with_threading(Threading::Serialized)
        .ok_or("MPI was already initialised in this process")?;
    if threading < Threading::Serialized {
        return Err(format!(
            "the MPI library offers only {threading:?} threading; distributed renders need Serialized"
        ));
    }
    let comm = universe.world();
    let (rank, size) = (comm.rank() as usize, comm.size() as usize);
    let cluster = MPI.get_or_init(|| MpiCluster {
        world: Mutex::new(World {
            comm,
            traffic: Traffic::default(),
        }),
        rank,
        size,
    });
    install(cluster);
    Ok(Session {
        _universe: universe,
    })
}

/// The start-up handshake of a render (`mcmc-core`'s agreement): every rank
/// reports whether its set-up (`local`) succeeded and a fingerprint of its
/// inputs, as the [`fingerprint`] of their descriptions; ranks that failed
/// or differ make every rank return the same error. `Err((message, own))`:
/// `own` is false on a rank that only learns of another rank's failure.
pub fn agree_on_inputs<T>(local: Result<(T, Vec<String>), String>) -> Result<T, (String, bool)> {
    let cluster = MPI.get().expect("start() comes first");
    let own_failure = local.as_ref().err().cloned();
    let local = local
        .map(|(v, parts)| (v, fingerprint(&parts)))
        .map_err(|e| DistributedError::Rank {
            rank: cluster.rank(),
            reason: e,
        });
    cluster
        .with(|comm, traffic| agree(comm, traffic, "scene, integrator settings or budget", local))
        .map_err(|e| match own_failure {
            // This rank's own set-up error: its message as it was (the
            // agreement wraps it in "rank R failed: …").
            Some(reason) => (reason, true),
            None => (e.to_string(), false),
        })
}

pub use crate::checkpoint::fingerprint;

/// A film on the wire: `[width, height, x0, y0, w, h]`, then the sample
/// accumulators (none for a splat-only film) and the splats, as f32 bits.
struct FilmBytes {
    dims: [u32; 6],
    samples: Vec<[f32; 4]>,
    splats: Vec<[f32; 3]>,
}

fn put_f32s(out: &mut Vec<u8>, values: &[f32]) {
    for v in values {
        out.extend_from_slice(&v.to_bits().to_le_bytes());
    }
}

fn take_f32s<const N: usize>(
    input: &mut &[u8],
    n: usize,
) -> Result<Vec<[f32; N]>, DistributedError> {
    let bytes = n * N * 4;
    if input.len() < bytes {
        return Err(DistributedError::Wire(format!(
            "film message ended: needed {bytes} bytes, had {}",
            input.len()
        )));
    }
    let (head, rest) = input.split_at(bytes);
    *input = rest;
    Ok(head
        .chunks_exact(N * 4)
        .map(|px| {
            std::array::from_fn(|c| {
                f32::from_bits(u32::from_le_bytes(
                    px[4 * c..4 * c + 4].try_into().expect("4 bytes"),
                ))
            })
        })
        .collect())
}

impl Wire for FilmBytes {
    fn put(&self, out: &mut Vec<u8>) {
        for d in self.dims {
            u64::from(d).put(out);
        }
        self.samples.len().put(out);
        put_f32s(out, self.samples.as_flattened());
        self.splats.len().put(out);
        put_f32s(out, self.splats.as_flattened());
    }
    fn take(input: &mut &[u8]) -> Result<Self, DistributedError> {
        let mut dims = [0u32; 6];
        for d in &mut dims {
            let v = u64::take(input)?;
            *d = u32::try_from(v)
                .map_err(|_| DistributedError::Wire(format!("film size {v} overflows")))?;
        }
        let n = usize::take(input)?;
        let samples = take_f32s(input, n)?;
        let n = usize::take(input)?;
        let splats = take_f32s(input, n)?;
        Ok(FilmBytes {
            dims,
            samples,
            splats,
        })
    }
}

/// A parcel on the wire: unit, films (a flag, then the film), numbers, counts.
struct ParcelBytes {
    unit: usize,
    films: Vec<(bool, FilmBytes)>,
    numbers: Vec<f64>,
    counts: Vec<u64>,
}

impl Wire for ParcelBytes {
    fn put(&self, out: &mut Vec<u8>) {
        self.unit.put(out);
        self.films.len().put(out);
        for (present, f) in &self.films {
            present.put(out);
            if *present {
                f.put(out);
            }
        }
        self.numbers.put(out);
        self.counts.put(out);
    }
    fn take(input: &mut &[u8]) -> Result<Self, DistributedError> {
        let unit = usize::take(input)?;
        let n = usize::take(input)?;
        let mut films = Vec::with_capacity(n.min(input.len()));
        for _ in 0..n {
            films.push(if bool::take(input)? {
                (true, FilmBytes::take(input)?)
            } else {
                (
                    false,
                    FilmBytes {
                        dims: [0; 6],
                        samples: Vec::new(),
                        splats: Vec::new(),
                    },
                )
            });
        }
        Ok(ParcelBytes {
            unit,
            films,
            numbers: Vec::take(input)?,
            counts: Vec::take(input)?,
        })
    }
}

fn to_wire(p: &Parcel) -> ParcelBytes {
    ParcelBytes {
        unit: p.unit,
        films: p
            .films
            .iter()
            .map(|f| match f {
                Some(f) => {
                    let (samples, splats) = f.accumulators();
                    (
                        true,
                        FilmBytes {
                            dims: [f.width, f.height, f.x0, f.y0, f.w, f.h],
                            samples: samples.to_vec(),
                            splats: splats.to_vec(),
                        },
                    )
                }
                None => (
                    false,
                    FilmBytes {
                        dims: [0; 6],
                        samples: Vec::new(),
                        splats: Vec::new(),
                    },
                ),
            })
            .collect(),
        numbers: p.numbers.clone(),
        counts: p.counts.clone(),
    }
}

fn from_wire(p: ParcelBytes, filter: &Arc<Filter>) -> Result<Parcel, String> {
    Ok(Parcel {
        unit: p.unit,
        films: p
            .films
            .into_iter()
            .map(|(present, f)| {
                present
                    .then(|| Film::from_accumulators(f.dims, filter.clone(), f.samples, f.splats))
                    .transpose()
            })
            .collect::<Result<_, _>>()?,
        numbers: p.numbers,
        counts: p.counts,
    })
}

impl Cluster for MpiCluster {
    fn rank(&self) -> usize {
        self.rank
    }
    fn size(&self) -> usize {
        self.size
    }
    fn gather(&self, parcels: Vec<Parcel>, filter: &Arc<Filter>) -> Option<Vec<Parcel>> {
        let wire: Vec<ParcelBytes> = parcels.iter().map(to_wire).collect();
        drop(parcels);
        let blocks = self.with(|comm, traffic| gather_bytes(comm, traffic, &encode(&wire)))?;
        let mut all = Vec::new();
        for block in blocks {
            // Every rank runs the same binary (checked at start-up), so a
            // message that does not decode is a bug, not an input error.
            let parcels: Vec<ParcelBytes> =
                decode(&block).unwrap_or_else(|e| panic!("a rank's films: {e}"));
            for p in parcels {
                all.push(from_wire(p, filter).unwrap_or_else(|e| panic!("a rank's film: {e}")));
            }
        }
        all.sort_by_key(|p| p.unit);
        Some(all)
    }
    fn gather_json(&self, value: Value) -> Option<Vec<Value>> {
        let text = value.to_string().into_bytes();
        let blocks = self.with(|comm, traffic| gather_bytes(comm, traffic, &text))?;
        Some(
            blocks
                .iter()
                .map(|b| serde_json::from_slice(b).unwrap_or(Value::Null))
                .collect(),
        )
    }
    fn any(&self, flag: bool) -> bool {
        self.with(|comm, traffic| all_gather_u64(comm, traffic, u64::from(flag)))
            .contains(&1)
    }
    fn bytes_sent(&self) -> u64 {
        self.with(|_, traffic| traffic.bytes)
    }
    fn broadcast_u64s(&self, values: Vec<u64>) -> Vec<u64> {
        let bytes = self.with(|comm, traffic| broadcast_bytes(comm, traffic, &encode(&values)));
        decode(&bytes).unwrap_or_else(|e| panic!("rank 0's numbers: {e}"))
    }
    fn all_gather_f64s(&self, values: Vec<f64>) -> Vec<f64> {
        self.with(|comm, traffic| {
            let all = gather_bytes(comm, traffic, &encode(&values)).map(|blocks| {
                let mut all = Vec::new();
                for b in blocks {
                    all.extend(
                        decode::<Vec<f64>>(&b).unwrap_or_else(|e| panic!("a rank's numbers: {e}")),
                    );
                }
                encode(&all)
            });
            let bytes = broadcast_bytes(comm, traffic, &all.unwrap_or_default());
            decode(&bytes).unwrap_or_else(|e| panic!("rank 0's numbers: {e}"))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::FilterKind;

    #[test]
    fn parcels_round_trip_bit_exactly() {
        let filter = Arc::new(Filter::new(FilterKind::Box, 4, 3));
        let mut f = Film::for_tile(4, 3, 1, 1, 3, 2, filter.clone());
        f.add_sample(
            glam::Vec2::new(1.5, 1.5),
            crate::color::Rgb::new(0.1, -0.0, 3e-39),
        );
        let p = Parcel {
            unit: 5,
            films: vec![None, Some(f.clone())],
            numbers: vec![f64::NEG_INFINITY, 0.1],
            counts: vec![u64::MAX],
        };
        let back: Vec<ParcelBytes> = decode(&encode(&vec![to_wire(&p)])).unwrap();
        let q = from_wire(back.into_iter().next().unwrap(), &filter).unwrap();
        assert_eq!(q.unit, 5);
        assert!(q.films[0].is_none());
        let (a, b) = (
            f.accumulators(),
            q.films[1].as_ref().unwrap().accumulators(),
        );
        let bits = |s: &[[f32; 4]]| {
            s.as_flattened()
                .iter()
                .map(|x| x.to_bits())
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(a.0), bits(b.0));
        assert_eq!(a.1, b.1);
        assert_eq!(q.numbers[0], f64::NEG_INFINITY);
        assert_eq!(q.counts, vec![u64::MAX]);
        assert!(fingerprint(&["ab".into(), "c".into()]) != fingerprint(&["a".into(), "bc".into()]));
    }
}
