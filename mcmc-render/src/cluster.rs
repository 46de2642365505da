//! The processes of a distributed render, as the render drivers see them.
//!
//! A run launched with `mpirun` under the cargo feature `mpi` installs one
//! [`Cluster`] for the whole process ([`install`], done by the command
//! line; see `docs/distributed.md`). The two render drivers — the
//! per-pixel one ([`crate::render::render`]: `pt`, `lt`, `bdpt`, …) and
//! the Markov-chain one ([`crate::markov::run`]) — then split their fixed
//! work units by rank with [`owns`] and reduce them on rank 0 in unit
//! order, so the image is the one a single process makes. Without an
//! installed cluster (the default build, and every library caller)
//! [`current`] is `None` and nothing changes.

use crate::film::{Film, Filter};
use rayon::prelude::*;
use serde_json::Value;
use std::sync::{Arc, OnceLock};

/// What one work unit sends to rank 0: its films (`None` for a member it
/// did not film), and the numbers and counts its driver reduces with them.
#[derive(Clone, Debug)]
pub struct Parcel {
    /// The unit's index in the driver's fixed list of units.
    pub unit: usize,
    /// Its films.
    pub films: Vec<Option<Film>>,
    /// Real numbers (sent bit-exactly).
    pub numbers: Vec<f64>,
    /// Counters.
    pub counts: Vec<u64>,
}

impl Parcel {
    /// Appends the parcel's bytes to `out` (little-endian: the unit, each
    /// film as a presence flag, its `[width, height, x0, y0, w, h]` and
    /// accumulators as f32 bits, then the numbers as f64 bits and the
    /// counts, each list after its length), for checkpoint files.
    pub fn encode(&self, out: &mut Vec<u8>) {
        let word = |v: u64, out: &mut Vec<u8>| out.extend_from_slice(&v.to_le_bytes());
        word(self.unit as u64, out);
        word(self.films.len() as u64, out);
        for film in &self.films {
            let Some(f) = film else {
                word(0, out);
                continue;
            };
            word(1, out);
            for d in [f.width, f.height, f.x0, f.y0, f.w, f.h] {
                word(u64::from(d), out);
            }
            let (samples, splats) = f.accumulators();
            for floats in [samples.as_flattened(), splats.as_flattened()] {
                word(floats.len() as u64, out);
                floats
                    .iter()
                    .for_each(|x| out.extend_from_slice(&x.to_bits().to_le_bytes()));
            }
        }
        word(self.numbers.len() as u64, out);
        self.numbers.iter().for_each(|x| word(x.to_bits(), out));
        word(self.counts.len() as u64, out);
        self.counts.iter().for_each(|&c| word(c, out));
    }

    /// The parcel [`Parcel::encode`] wrote at the front of `input`
    /// (advanced past it), its films rebuilt with `filter`.
    pub fn decode(input: &mut &[u8], filter: &Arc<Filter>) -> Result<Parcel, String> {
        fn take<'a>(input: &mut &'a [u8], n: usize) -> Result<&'a [u8], String> {
            if input.len() < n {
                return Err("truncated".into());
            }
            let (head, rest) = input.split_at(n);
            *input = rest;
            Ok(head)
        }
        let word = |input: &mut &[u8]| -> Result<u64, String> {
            Ok(u64::from_le_bytes(
                take(input, 8)?.try_into().expect("8 bytes"),
            ))
        };
        // A length that cannot fit in what is left is corrupt.
        let len = |input: &mut &[u8], unit: usize| -> Result<usize, String> {
            let n = word(input)?;
            usize::try_from(n)
                .ok()
                .filter(|&n| n.saturating_mul(unit) <= input.len())
                .ok_or_else(|| format!("a length of {n} overruns the data"))
        };
        let unit = word(input)? as usize;
        let mut films = Vec::new();
        for _ in 0..len(input, 8)? {
            if word(input)? == 0 {
                films.push(None);
                continue;
            }
            let mut dims = [0u32; 6];
            for d in &mut dims {
                *d = u32::try_from(word(input)?).map_err(|_| "a film size overflows")?;
            }
            let mut floats = || -> Result<Vec<f32>, String> {
                let n = len(input, 4)?;
                Ok(take(input, 4 * n)?
                    .chunks_exact(4)
                    .map(|b| f32::from_bits(u32::from_le_bytes(b.try_into().expect("4 bytes"))))
                    .collect())
            };
            let (samples, splats) = (floats()?, floats()?);
            if samples.len() % 4 != 0 || splats.len() % 3 != 0 {
                return Err("a film's accumulators are cut".into());
            }
            let samples = samples.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]);
            let splats = splats.chunks_exact(3).map(|c| [c[0], c[1], c[2]]);
            films.push(Some(Film::from_accumulators(
                dims,
                filter.clone(),
                samples.collect(),
                splats.collect(),
            )?));
        }
        let numbers = (0..len(input, 8)?)
            .map(|_| word(input).map(f64::from_bits))
            .collect::<Result<_, _>>()?;
        let counts = (0..len(input, 8)?)
            .map(|_| word(input))
            .collect::<Result<_, _>>()?;
        Ok(Parcel {
            unit,
            films,
            numbers,
            counts,
        })
    }
}

/// The collective operations the drivers need. Every rank calls them in
/// the same order.
pub trait Cluster: Send + Sync {
    /// This process's rank, `0..size`.
    fn rank(&self) -> usize;
    /// Number of ranks.
    fn size(&self) -> usize;
    /// Every rank's parcels on rank 0, sorted by unit (films rebuilt with
    /// `filter`); `None` on the other ranks.
    fn gather(&self, parcels: Vec<Parcel>, filter: &Arc<Filter>) -> Option<Vec<Parcel>>;
    /// Every rank's `value` on rank 0, in rank order; `None` elsewhere.
    fn gather_json(&self, value: Value) -> Option<Vec<Value>>;
    /// Whether `flag` is set on any rank (every rank gets the answer).
    fn any(&self, flag: bool) -> bool;
    /// Payload bytes this rank has sent so far.
    fn bytes_sent(&self) -> u64;
    /// Rank 0's `values` on every rank (the others' are ignored).
    fn broadcast_u64s(&self, values: Vec<u64>) -> Vec<u64>;
    /// Every rank's `values` (bit-exactly), concatenated in rank order, on
    /// every rank.
    fn all_gather_f64s(&self, values: Vec<f64>) -> Vec<f64>;
}

static CLUSTER: OnceLock<&'static dyn Cluster> = OnceLock::new();

/// Makes `cluster` the process's cluster (once; later calls are ignored
/// and return `false`).
pub fn install(cluster: &'static dyn Cluster) -> bool {
    CLUSTER.set(cluster).is_ok()
}

/// The installed cluster, if this is a distributed run.
pub fn current() -> Option<&'static dyn Cluster> {
    CLUSTER.get().copied()
}

/// Whether this rank renders work unit `unit`: units are dealt out
/// round-robin (unit `u` to rank `u mod size`), which spreads the costly
/// parts of an image (a light, a caustic) over the ranks. Always true
/// without a cluster.
pub fn owns(cluster: Option<&dyn Cluster>, unit: usize) -> bool {
    cluster.is_none_or(|c| unit % c.size() == c.rank())
}

/// A unit's reduced counters: its parcel's `numbers` and `counts`.
pub type Counters = (Vec<f64>, Vec<u64>);

/// Adds the work units' films into `film` in unit order and returns their
/// counters in the same order: this process's units, or on a cluster
/// every rank's, on rank 0 (the other ranks add nothing and get an empty
/// list). Collective on a cluster: every rank calls it.
pub fn reduce_units<'a>(
    film: &mut Film,
    units: impl Iterator<Item = (usize, &'a Film, Counters)>,
    filter: &Arc<Filter>,
) -> Vec<Counters> {
    let Some(cluster) = current() else {
        return units
            .map(|(_, f, counters)| {
                film.add_film(f);
                counters
            })
            .collect();
    };
    let parcels = units
        .map(|(unit, f, (numbers, counts))| Parcel {
            unit,
            films: vec![Some(f.clone())],
            numbers,
            counts,
        })
        .collect();
    let Some(all) = cluster.gather(parcels, filter) else {
        return Vec::new();
    };
    all.into_iter()
        .map(|p| {
            if let Some(f) = &p.films[0] {
                film.add_film(f);
            }
            (p.numbers, p.counts)
        })
        .collect()
}

/// `f(i)` (`width` numbers each) for `i` in `0..n`, flattened in order
/// and evaluated in parallel. On a cluster each rank evaluates a
/// contiguous block of `i` and every rank gets them all (bit-exactly):
/// the work (the Markov driver's start-up candidates, `erpt`'s luminance
/// walks) is split, not repeated, and every rank holds the same numbers
/// (each depends on `i` alone) as one process. Collective on a cluster.
pub fn evaluate_split(n: usize, width: usize, f: impl Fn(usize) -> Vec<f64> + Sync) -> Vec<f64> {
    let cluster = current();
    let (rank, size) = cluster.map_or((0, 1), |c| (c.rank(), c.size()));
    let block = n * rank / size..n * (rank + 1) / size;
    // Collected per index, then joined: a `flat_map_iter` collect (the
    // former way) kept two cores ≈ 1.25 busy on the start-up's candidates
    // and took 1.9× the wall time (session 33).
    let local: Vec<f64> = block
        .into_par_iter()
        .map(|i| {
            let v = f(i);
            debug_assert_eq!(v.len(), width);
            v
        })
        .collect::<Vec<Vec<f64>>>()
        .concat();
    match cluster {
        Some(c) => c.all_gather_f64s(local),
        None => local,
    }
}

/// [`evaluate_split`] for records of any length: `f(i)` for `i` in
/// `0..n`, in order, evaluated in parallel and, on a cluster, split over
/// the ranks in contiguous blocks with every rank getting them all
/// (bit-exactly; each record travels behind its length). Collective on a
/// cluster.
pub fn evaluate_split_records(n: usize, f: impl Fn(usize) -> Vec<f64> + Sync) -> Vec<Vec<f64>> {
    let cluster = current();
    let (rank, size) = cluster.map_or((0, 1), |c| (c.rank(), c.size()));
    let block = n * rank / size..n * (rank + 1) / size;
    let local: Vec<Vec<f64>> = block.into_par_iter().map(&f).collect();
    let Some(c) = cluster else {
        return local;
    };
    let flat: Vec<f64> = local
        .iter()
        .flat_map(|r| std::iter::once(r.len() as f64).chain(r.iter().copied()))
        .collect();
    let all = c.all_gather_f64s(flat);
    let mut records = Vec::with_capacity(n);
    let mut rest = &all[..];
    while let Some((&len, tail)) = rest.split_first() {
        let (record, tail) = tail.split_at(len as usize);
        records.push(record.to_vec());
        rest = tail;
    }
    records
}

/// Every rank's `words`, concatenated in rank order, on every rank
/// (bit-exactly: sent as the f64s of their bits, which MPI copies as
/// bytes); without a cluster, `words` itself. Collective on a cluster.
pub fn all_gather_words(words: Vec<u64>) -> Vec<u64> {
    match current() {
        Some(c) => (c.all_gather_f64s(words.into_iter().map(f64::from_bits).collect()))
            .into_iter()
            .map(f64::to_bits)
            .collect(),
        None => words,
    }
}

/// Whether `flag` is set on this process or, on a cluster, on any rank: a
/// decision (stop now, a pass was cut) every rank must take alike.
/// Collective on a cluster: every rank calls it the same number of times.
pub fn any_rank(flag: bool) -> bool {
    current().map_or(flag, |c| c.any(flag))
}

/// Whether this process writes the outputs: rank 0, or the only process.
pub fn is_root() -> bool {
    current().is_none_or(|c| c.rank() == 0)
}

/// `statistics` (a JSON object) with, in a distributed run, `"ranks"`:
/// every rank's `own` statistics (plus its rank and bytes sent) in rank
/// order, on rank 0. A collective: every rank calls it.
pub fn with_ranks(statistics: Value, own: Value) -> Value {
    let (Some(c), Value::Object(mut m)) = (current(), statistics.clone()) else {
        return statistics;
    };
    let mut own = match own {
        Value::Object(o) => o,
        v => [("value".to_string(), v)].into_iter().collect(),
    };
    own.insert("rank".into(), c.rank().into());
    own.insert("bytes_sent".into(), c.bytes_sent().into());
    if let Some(all) = c.gather_json(Value::Object(own)) {
        m.insert("ranks".into(), Value::Array(all));
    }
    Value::Object(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Fake(usize, usize);
    impl Cluster for Fake {
        fn rank(&self) -> usize {
            self.0
        }
        fn size(&self) -> usize {
            self.1
        }
        fn gather(&self, _: Vec<Parcel>, _: &Arc<Filter>) -> Option<Vec<Parcel>> {
            None
        }
        fn gather_json(&self, _: Value) -> Option<Vec<Value>> {
            None
        }
        fn any(&self, flag: bool) -> bool {
            flag
        }
        fn bytes_sent(&self) -> u64 {
            0
        }
        fn broadcast_u64s(&self, values: Vec<u64>) -> Vec<u64> {
            values
        }
        fn all_gather_f64s(&self, values: Vec<f64>) -> Vec<f64> {
            values
        }
    }

    #[test]
    fn units_are_dealt_round_robin_and_cover_everything_once() {
        for size in 1..5 {
            for unit in 0..13 {
                let owners = (0..size)
                    .filter(|&r| owns(Some(&Fake(r, size)), unit))
                    .count();
                assert_eq!(owners, 1);
            }
        }
        assert!(owns(None, 7));
        assert!(!owns(Some(&Fake(1, 3)), 3));
    }
}
