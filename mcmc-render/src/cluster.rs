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
