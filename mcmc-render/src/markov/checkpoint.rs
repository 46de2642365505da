//! Checkpoints of the Markov-chain driver: between two whole rounds every
//! task's films, running normalisations, counters and every chain's exact
//! state (its current sample with its payload, its random stream, its
//! statistics) go to a file, so that a run stopped by a time limit,
//! Ctrl-C or a lost process continues where it was and ends with the bits
//! of the uninterrupted run: the restored chains draw the same numbers and
//! splat into the same accumulators in the same order. See
//! `docs/distributed.md`.
//!
//! The start-up (bootstrap, chain allocation, start states) is not in the
//! file: it is a function of the inputs, which the file's fingerprint
//! ties it to, and a resumed run makes it again before it restores the
//! tasks. Families opt in with [`ChainFamily::checkpointable`]: states that
//! encode exactly and kernels without state of their own; replica sets
//! also need an exchange move that can be saved
//! ([`mcmc_core::replica::ExchangeMove::state_words`]), and their records
//! hold every level's chain and the set's own progress
//! ([`mcmc_core::replica::ReplicaProgress`]). Only rank 0 of a distributed
//! run reads and writes the file; it broadcasts what it read.

use super::ChainFamily;
use super::distribute::TaskSums;
use super::work::{Task, Units};
use crate::checkpoint::{strip_checksum, write_sealed};
use crate::cluster::Parcel;
use crate::color::Rgb;
use crate::film::Filter;
use crate::pss::{PathSample, Splat};
use mcmc_core::chain::ChainState;
use mcmc_core::kernel::Kernel;
use mcmc_core::rng::{ChainRng, rng_from_words, rng_words};
use mcmc_core::sample::Sample;
use mcmc_core::stats::ChainStatistics;
use std::path::Path;
use std::sync::Arc;

/// First bytes of a Markov-chain checkpoint file (format version 4,
/// session 20: version 3's records with each chain's kernel state after
/// its statistics; version 3 had version 2's replica sets and a checksum
/// at the end).
const MAGIC: &[u8; 8] = b"mcmcMC04";

/// First bytes of a file of format version 3 (no kernel states): still
/// read, its chains' kernels taken as without state.
const MAGIC_V3: &[u8; 8] = b"mcmcMC03";

/// First bytes of a file of format version 2 (no checksum), refused.
const MAGIC_V2: &[u8; 8] = b"mcmcMC02";

/// One chain as saved: by the Markov-chain driver (`S`: its state's
/// words, as the family encodes them, [`ChainFamily::state_words`]; `P`:
/// its path sample) and by `smcmc` (a tile's point and its values in the
/// tile, [`crate::smcmc::checkpoint::TileRecord`]).
#[derive(Clone, Debug)]
pub struct ChainRecord<S = Vec<u64>, P = PathSample> {
    /// Its current state.
    pub state: S,
    /// `ln π` of the current state.
    pub log_density: f64,
    /// The current state's payload.
    pub payload: P,
    /// The chain's random stream ([`mcmc_core::rng::rng_words`]).
    pub rng: [u64; 4],
    /// Its statistics (the component names are the kernel's; not saved).
    pub stats: ChainStatistics,
    /// Its kernel's own state ([`mcmc_core::kernel::Kernel::state_words`]:
    /// the adaptive small step's adaptation; empty for kernels without
    /// state). In a replica set, the kernel of the level the chain is at
    /// (since session 21: the levels' kernels stay at their levels).
    pub kernel: Vec<u64>,
}

impl<S, P: Clone> ChainRecord<S, P> {
    /// The record of a chain at `current` (its state saved as `state`)
    /// with the stream `rng`, statistics `stats` and kernel `kernel`.
    pub(crate) fn new<T, K: Kernel<T, P> + ?Sized>(
        state: S,
        current: &Sample<T, P>,
        (rng, stats): (&ChainRng, &ChainStatistics),
        kernel: &K,
    ) -> Self {
        let mut kernel_words = Vec::new();
        kernel.state_words(&mut kernel_words);
        ChainRecord {
            state,
            log_density: current.log_density,
            payload: current.payload.clone(),
            rng: rng_words(rng),
            stats: stats.clone(),
            kernel: kernel_words,
        }
    }

    /// Puts the saved stream and statistics into `parts` (a chain built
    /// afresh from the same inputs, whose kernel's component names they
    /// keep). `who` names the chain in the error ("a chain's").
    pub(crate) fn restore<T>(&self, parts: &mut ChainState<T, P>, who: &str) -> Result<(), String> {
        if parts.stats.components.len() != self.stats.components.len() {
            return Err(format!("{who} kernel has other components"));
        }
        parts.rng = rng_from_words(self.rng).ok_or_else(|| format!("{who} stream is all zero"))?;
        let mut stats = self.stats.clone();
        for (k, old) in stats.components.iter_mut().zip(&parts.stats.components) {
            k.name.clone_from(&old.name);
        }
        parts.stats = stats;
        Ok(())
    }

    /// Puts the saved kernel state back with `restore` (a fresh kernel's
    /// [`Kernel::restore_words`]; a kernel without state takes no words).
    /// `who` names the chain in the error.
    pub(crate) fn restore_kernel(
        &self,
        restore: impl FnOnce(&mut &[u64]) -> bool,
        who: &str,
    ) -> Result<(), String> {
        let mut words = &self.kernel[..];
        match restore(&mut words) && words.is_empty() {
            true => Ok(()),
            false => Err(format!("{who} kernel state does not decode")),
        }
    }
}

/// One replica set as saved, besides its levels' chains.
#[derive(Clone, Debug)]
pub struct SetRecord {
    /// Sweeps done.
    pub sweeps: u64,
    /// The set's own progress ([`mcmc_core::replica::ReplicaProgress`]'s
    /// words: exchange stream, index process, exchange statistics, move).
    pub words: Vec<u64>,
}

/// One task as saved: what it adds to the image (its films, running
/// normalisations, mutation counts, ratio sums, per-depth counts,
/// `normalization=filmed`'s sums, as the distributed reduction sends them) and its chains in order (of a task
/// of replica sets: every set's levels, set after set).
#[derive(Clone, Debug)]
pub struct TaskRecord {
    /// The task's sums (the parcel a cluster's reduction sends).
    pub sums: Parcel,
    /// Its chains.
    pub chains: Vec<ChainRecord>,
    /// Its replica sets (empty for a task of independent chains).
    pub sets: Vec<SetRecord>,
}

/// A Markov-chain render's progress: every task, in task order.
#[derive(Clone, Debug)]
pub struct ChainProgress {
    /// The tasks.
    pub tasks: Vec<TaskRecord>,
}

impl ChainProgress {
    /// Mutations done, all tasks.
    pub fn mutations(&self) -> u64 {
        self.tasks
            .iter()
            .flat_map(|t| sums_of(&t.sums).mutations.into_owned())
            .fold(0, u64::saturating_add)
    }

    /// The progress as bytes (the body of a checkpoint file of the
    /// current format).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = (self.tasks.len() as u64).to_le_bytes().to_vec();
        for t in &self.tasks {
            parcel_of(t).encode(&mut out);
        }
        out
    }

    /// The progress [`ChainProgress::to_bytes`] wrote, films rebuilt with
    /// `filter` (`kernels`: the chains' records hold kernel states, as
    /// from format 4 on).
    pub fn from_bytes(
        mut bytes: &[u8],
        filter: &Arc<Filter>,
        kernels: bool,
    ) -> Result<ChainProgress, String> {
        let n = bytes
            .split_first_chunk::<8>()
            .map(|(n, rest)| {
                bytes = rest;
                u64::from_le_bytes(*n)
            })
            .ok_or("truncated")?;
        let tasks = (0..n)
            .map(|_| record_of(Parcel::decode(&mut bytes, filter)?, kernels))
            .collect::<Result<_, String>>()?;
        if !bytes.is_empty() {
            return Err(format!("{} bytes after the last task", bytes.len()));
        }
        Ok(ChainProgress { tasks })
    }
}

/// Saves `progress` for the inputs `fingerprint` to `path` (atomically: a
/// run killed while writing keeps the previous checkpoint): the magic, the
/// fingerprint, the progress, then an FNV-1a checksum of all before it.
pub fn save(path: &Path, fingerprint: u64, progress: &ChainProgress) -> Result<(), String> {
    let mut out = MAGIC.to_vec();
    out.extend_from_slice(&fingerprint.to_le_bytes());
    out.extend(progress.to_bytes());
    write_sealed(path, out)
}

/// The progress saved at `path` for the inputs `fingerprint` and an image
/// of `size` (films rebuilt with `filter`): `None` when there is no file;
/// an error (one line) when it is not a regular file (refused before it
/// is opened: a FIFO would block, a device never end), too long to read
/// (twice its length must fit in the available memory: the decoded
/// progress takes about as many bytes as the file, every length in it
/// being bounded by the bytes that follow), or when [`progress_from_bytes`]
/// refuses its bytes.
pub fn load(
    path: &Path,
    fingerprint: u64,
    size: (u32, u32),
    filter: &Arc<Filter>,
) -> Result<Option<ChainProgress>, String> {
    read_bytes(path)?
        .map(|bytes| progress_from_bytes(&bytes, path, fingerprint, size, filter))
        .transpose()
}

/// The bytes of the checkpoint at `path` (this driver's, or `smcmc`'s):
/// `None` when there is no file; an error (one line) when it is not a
/// regular file (refused before it is opened) or too long to read (twice
/// its length must fit in the available memory).
pub(crate) fn read_bytes(path: &Path) -> Result<Option<Vec<u8>>, String> {
    let len = match std::fs::metadata(path) {
        Ok(m) => m.len(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(format!("cannot read checkpoint {}: {e}", path.display())),
    };
    crate::resources::regular_file(path).map_err(|e| format!("checkpoint: {e}"))?;
    crate::resources::check_memory(
        &format!("checkpoint {} ({len} bytes)", path.display()),
        2 * u128::from(len),
    )?;
    let bytes = std::fs::read(path)
        .map_err(|e| format!("cannot read checkpoint {}: {e}", path.display()))?;
    Ok(Some(bytes))
}

/// `body` (the bytes of checkpoint `bytes` after its magic) without its
/// fingerprint and checksum, once both are checked: refused (one line
/// naming `path`) when the checksum (FNV-1a of all bytes before its last
/// 8) does not match — a flipped bit, a cut or a file written over — or
/// the fingerprint is not `fingerprint` (another render's file).
pub(crate) fn checked_body<'a>(
    bytes: &[u8],
    body: &'a [u8],
    path: &Path,
    fingerprint: u64,
) -> Result<&'a [u8], String> {
    let bad = |why: &str| format!("checkpoint {}: {why}", path.display());
    let body = strip_checksum(bytes, body).map_err(bad)?;
    let Some((fp, body)) = body.split_first_chunk::<8>() else {
        return Err(bad("truncated"));
    };
    if u64::from_le_bytes(*fp) != fingerprint {
        return Err(bad(
            "written by another render (scene, defines, integrator, its settings or seed differ)",
        ));
    }
    Ok(body)
}

/// The progress a checkpoint's bytes hold (`path` names it in messages):
/// refused, with one line, when they are not a Markov-chain checkpoint (or
/// one of the earlier format), are damaged (the checksum does not match: a
/// flipped bit, a cut or a file written over), belong to another render
/// or hold films of another size. Whether the tasks fit the run is
/// checked when the run restores them.
pub fn progress_from_bytes(
    bytes: &[u8],
    path: &Path,
    fingerprint: u64,
    size: (u32, u32),
    filter: &Arc<Filter>,
) -> Result<ChainProgress, String> {
    let bad = |why: &str| format!("checkpoint {}: {why}", path.display());
    if bytes.starts_with(MAGIC_V2) {
        return Err(bad(
            "of an earlier format (mcmcMC02, without a checksum); delete it to start afresh",
        ));
    }
    let (body, kernels) = match (bytes.strip_prefix(MAGIC), bytes.strip_prefix(MAGIC_V3)) {
        (Some(body), _) => (body, true),
        (None, Some(body)) => (body, false),
        (None, None) => return Err(bad("not a checkpoint of mcmc-render's Markov-chain driver")),
    };
    let body = checked_body(bytes, body, path, fingerprint)?;
    let progress = ChainProgress::from_bytes(body, filter, kernels).map_err(|e| bad(&e))?;
    for f in progress
        .tasks
        .iter()
        .flat_map(|t| t.sums.films.iter().flatten())
    {
        if (f.width, f.height) != size {
            return Err(bad(&format!(
                "holds a {}×{} image, the scene is {}×{}",
                f.width, f.height, size.0, size.1
            )));
        }
    }
    for t in &progress.tasks {
        let counts = &sums_of(&t.sums).counts;
        let pixels = u64::from(size.0) * u64::from(size.1);
        if !counts.samples.is_empty()
            && (counts.width != size.0 || counts.samples.len() as u64 != pixels)
        {
            return Err(bad(&format!(
                "holds a sample-count image of {} counts {} wide, the scene is {}×{}",
                counts.samples.len(),
                counts.width,
                size.0,
                size.1
            )));
        }
    }
    Ok(progress)
}

/// The record of a local task (`id`: its index among all tasks).
pub(crate) fn record_of_task<F: ChainFamily>(
    family: &F,
    task: &Task<'_, F>,
    id: usize,
) -> TaskRecord {
    let (chains, sets) = match &task.units {
        Units::Chains(chains) => {
            let records = chains.iter().map(|slot| {
                let c = &slot.chain;
                let state = state_words(family, &c.current().state);
                let kernel = c.algorithm().kernel();
                ChainRecord::new(state, c.current(), (c.rng(), c.stats()), kernel)
            });
            (records.collect(), Vec::new())
        }
        Units::Replicas(slots) => {
            let mut chains = Vec::new();
            let mut sets = Vec::new();
            for slot in slots {
                let progress = slot
                    .set
                    .progress()
                    .expect("the driver refuses checkpoints of moves that cannot be saved");
                // Each level's kernel (its adaptive small step's state)
                // with the chain at that level: kernels stay at their
                // levels while the states are exchanged.
                chains.extend(progress.chains.iter().enumerate().map(|(level, c)| {
                    let state = state_words(family, &c.current.state);
                    let kernel = slot.set.algorithm(level).kernel();
                    ChainRecord::new(state, &c.current, (&c.rng, &c.stats), kernel)
                }));
                sets.push(SetRecord {
                    sweeps: slot.sweeps,
                    words: progress.words,
                });
            }
            (chains, sets)
        }
    };
    TaskRecord {
        sums: TaskSums::of(task).parcel(id),
        chains,
        sets,
    }
}

/// `state` as `family` encodes it.
fn state_words<F: ChainFamily>(family: &F, state: &F::State) -> Vec<u64> {
    let mut words = Vec::new();
    family.state_words(state, &mut words);
    words
}

/// Puts `saved` back into the chain `parts` (built afresh from the same
/// inputs, whose kernel's component names it keeps).
fn restore_chain<F: ChainFamily>(
    family: &F,
    parts: &mut ChainState<F::State, PathSample>,
    saved: &ChainRecord,
) -> Result<(), String> {
    let mut words = &saved.state[..];
    let state = family
        .state_from_words(&mut words)
        .filter(|_| words.is_empty())
        .ok_or("a chain's state does not decode")?;
    saved.restore(parts, CHAIN)?;
    parts.current.state = state;
    parts.current.log_density = saved.log_density;
    parts.current.payload = saved.payload.clone();
    Ok(())
}

/// How a restore's errors name a chain of the Markov-chain driver.
const CHAIN: &str = "a chain's";

/// Puts `record` back into `task` (built afresh by the driver from the
/// same inputs): its sums, and every chain's state, stream and
/// statistics (and every replica set's own progress); a chain's (set's)
/// remaining budget is what the fresh task gave it less the mutations
/// (sweeps) it had done.
pub(crate) fn restore_task<F: ChainFamily>(
    family: &F,
    task: &mut Task<'_, F>,
    record: &TaskRecord,
) -> Result<(), String> {
    let sums = sums_of(&record.sums);
    let misfit = |units: &str, n: usize| {
        format!(
            "a task of {} chains of members {:?} does not fit the run's task of {n} {units} of members {:?}",
            record.chains.len(),
            sums.members,
            task.members
        )
    };
    match &mut task.units {
        Units::Chains(chains) => {
            if *sums.members != task.members
                || record.chains.len() != chains.len()
                || !record.sets.is_empty()
            {
                return Err(misfit("chains", chains.len()));
            }
            for (slot, saved) in chains.iter_mut().zip(&record.chains) {
                restore_chain(family, slot.chain.parts_mut(), saved)?;
                let kernel = slot.chain.algorithm_mut().kernel_mut();
                saved.restore_kernel(|w| kernel.restore_words(w), CHAIN)?;
                slot.remaining = slot.remaining.map(|r| r.saturating_sub(saved.stats.steps));
            }
        }
        Units::Replicas(slots) => {
            let levels = task.members.len();
            if *sums.members != task.members
                || record.sets.len() != slots.len()
                || record.chains.len() != slots.len() * levels
            {
                return Err(misfit("replica sets", slots.len()));
            }
            let saved_chains = record.chains.chunks_exact(levels);
            for ((slot, set), saved) in slots.iter_mut().zip(&record.sets).zip(saved_chains) {
                let mut progress =
                    (slot.set.progress()).ok_or("the run's exchange move cannot be restored")?;
                for (level, (parts, saved)) in progress.chains.iter_mut().zip(saved).enumerate() {
                    restore_chain(family, parts, saved)?;
                    let kernel = slot.set.algorithm_mut(level).kernel_mut();
                    saved.restore_kernel(|w| kernel.restore_words(w), CHAIN)?;
                }
                progress.words.clone_from(&set.words);
                slot.set.restore(progress).map_err(|e| e.to_string())?;
                slot.sweeps = set.sweeps;
                slot.remaining = slot.remaining.map(|r| r.saturating_sub(set.sweeps));
            }
        }
    }
    task.films = sums.films.into_owned();
    task.running = sums.running.into_owned();
    task.mutations = sums.mutations.into_owned();
    task.ratios = sums.ratios.into_owned();
    if sums.filmed.len() != task.filmed.len() {
        return Err("a task's filmed sums do not fit the run's normalisation".into());
    }
    task.filmed = sums.filmed.into_owned();
    task.counts = sums.counts.into_owned();
    task.recount_searches();
    Ok(())
}

/// A record's sums as the reduction reads them.
fn sums_of(parcel: &Parcel) -> TaskSums<'static> {
    TaskSums::from_parcel(parcel.clone())
}

/// A record as one parcel: its sums' films and numbers; counts: the
/// sums' count, the sums' counts, then the chains' words (each chain's
/// kernel state last, after its length), then the replica sets' (their
/// count, then each set's sweeps and words).
pub(crate) fn parcel_of(record: &TaskRecord) -> Parcel {
    let mut counts = vec![record.sums.counts.len() as u64];
    counts.extend(&record.sums.counts);
    counts.push(record.chains.len() as u64);
    for c in &record.chains {
        counts.push(c.state.len() as u64);
        counts.extend(&c.state);
        counts.push(c.log_density.to_bits());
        counts.extend([u64::from(c.payload.depth), c.payload.splats.len() as u64]);
        for s in &c.payload.splats {
            let floats = [s.p.x, s.p.y, s.l.r, s.l.g, s.l.b];
            counts.extend(floats.map(|x| u64::from(x.to_bits())));
            counts.push(u64::from(s.class));
        }
        counts.extend(c.rng);
        stats_words(&c.stats, &mut counts);
        counts.push(c.kernel.len() as u64);
        counts.extend(&c.kernel);
    }
    counts.push(record.sets.len() as u64);
    for set in &record.sets {
        counts.extend([set.sweeps, set.words.len() as u64]);
        counts.extend(&set.words);
    }
    Parcel {
        unit: record.sums.unit,
        films: record.sums.films.clone(),
        numbers: record.sums.numbers.clone(),
        counts,
    }
}

/// Appends `stats`' counters to `out`, bit-exactly (the component names
/// are not written: the receiver knows its kernel's).
pub(crate) fn stats_words(stats: &ChainStatistics, out: &mut Vec<u64>) {
    out.extend([
        stats.steps,
        stats.accepted,
        stats.evaluations,
        stats.invalid_density,
        stats.outside_support,
        stats.failed,
        stats.components.len() as u64,
    ]);
    for k in &stats.components {
        out.extend([k.proposed, k.accepted, k.sum_alpha.to_bits()]);
    }
}

/// The statistics [`stats_words`] wrote, read word by word from `next`,
/// with empty component names.
pub(crate) fn stats_from_words(
    next: &mut impl FnMut() -> Result<u64, String>,
) -> Result<ChainStatistics, String> {
    let mut stats = ChainStatistics::new(Vec::new());
    [
        stats.steps,
        stats.accepted,
        stats.evaluations,
        stats.invalid_density,
        stats.outside_support,
        stats.failed,
    ] = [next()?, next()?, next()?, next()?, next()?, next()?];
    for _ in 0..next()? {
        stats
            .components
            .push(mcmc_core::stats::ComponentStatistics {
                name: String::new(),
                proposed: next()?,
                accepted: next()?,
                sum_alpha: f64::from_bits(next()?),
            });
    }
    // Counters past 2^53 come only from a forged file; they would
    // overflow when the resumed chain counts on.
    let counters = [stats.steps, stats.accepted, stats.evaluations]
        .into_iter()
        .chain([stats.invalid_density, stats.outside_support, stats.failed])
        .chain(
            stats
                .components
                .iter()
                .flat_map(|k| [k.proposed, k.accepted]),
        );
    if let Some(k) = counters
        .into_iter()
        .find(|&k| k > crate::checkpoint::MAX_COUNT)
    {
        return Err(format!("a chain's counter {k} exceeds 2^53"));
    }
    Ok(stats)
}

/// The record [`parcel_of`] made (`kernels`: with the chains' kernel
/// states, as from format 4 on).
pub(crate) fn record_of(p: Parcel, kernels: bool) -> Result<TaskRecord, String> {
    let mut words = &p.counts[..];
    let mut next = || -> Result<u64, String> {
        let (&w, rest) = words.split_first().ok_or("a task's record is cut")?;
        words = rest;
        Ok(w)
    };
    let f32_of = |w: u64| f32::from_bits(w as u32);
    let n = next()?;
    let sums_counts = (0..n).map(|_| next()).collect::<Result<Vec<_>, _>>()?;
    let mut chains = Vec::new();
    for _ in 0..next()? {
        let state = (0..next()?).map(|_| next()).collect::<Result<_, _>>()?;
        let log_density = f64::from_bits(next()?);
        // Metropolis–Hastings never accepts a NaN or +∞ density.
        if log_density.is_nan() || log_density == f64::INFINITY {
            return Err("a chain's density is not a number or infinite".into());
        }
        let depth = u32::try_from(next()?).map_err(|_| "a path depth overflows")?;
        let splats = (0..next()?)
            .map(|_| {
                let [x, y, r, g, b, class] = [next()?, next()?, next()?, next()?, next()?, next()?];
                let (p, l) = (
                    glam::Vec2::new(f32_of(x), f32_of(y)),
                    Rgb::new(f32_of(r), f32_of(g), f32_of(b)),
                );
                // A chain's current sample was accepted, so it is finite.
                if !(p.is_finite() && l.is_finite()) {
                    return Err("a chain's path sample is not finite".to_string());
                }
                Ok(Splat {
                    p,
                    l,
                    class: u8::try_from(class).map_err(|_| "a path class overflows")?,
                })
            })
            .collect::<Result<_, String>>()?;
        let rng = [next()?, next()?, next()?, next()?];
        // The kernel's component names are put back by `restore_task`.
        let stats = stats_from_words(&mut next)?;
        let kernel = match kernels {
            true => (0..next()?).map(|_| next()).collect::<Result<_, _>>()?,
            false => Vec::new(),
        };
        chains.push(ChainRecord {
            state,
            log_density,
            payload: PathSample { splats, depth },
            rng,
            stats,
            kernel,
        });
    }
    let mut sets = Vec::new();
    for _ in 0..next()? {
        let sweeps = next()?;
        let words = (0..next()?).map(|_| next()).collect::<Result<_, _>>()?;
        sets.push(SetRecord { sweeps, words });
    }
    if !words.is_empty() {
        return Err("a task's record has trailing words".into());
    }
    let sums = Parcel {
        counts: sums_counts,
        ..p
    };
    // The sums are read again (`sums_of`) wherever they are used: checked
    // here, once, so that those reads cannot fail.
    TaskSums::try_from_parcel(sums.clone())?;
    Ok(TaskRecord { sums, chains, sets })
}

/// Restores this process's `tasks` (`ids[i]`: local task `i`'s index
/// among `all` tasks) from the progress `checkpoint` was opened with, read
/// by rank 0 and broadcast to the others. Returns the mutations the run
/// resumed from (`None`: nothing to resume, a fresh start). Collective on
/// a cluster.
pub(crate) fn resume<F: ChainFamily>(
    family: &F,
    checkpoint: &crate::checkpoint::Checkpoint,
    cluster: Option<&dyn crate::cluster::Cluster>,
    tasks: &mut [Task<'_, F>],
    ids: &[usize],
    all: usize,
    filter: &Arc<Filter>,
) -> Result<Option<u64>, String> {
    let progress = match cluster {
        None => checkpoint.chains.clone(),
        Some(c) => {
            // Bytes as words: the byte count, then 8 bytes a word.
            let words = match (&checkpoint.chains, c.rank()) {
                (Some(p), 0) => {
                    let bytes = p.to_bytes();
                    let mut w = vec![bytes.len() as u64];
                    w.extend(bytes.chunks(8).map(|b| {
                        let mut word = [0u8; 8];
                        word[..b.len()].copy_from_slice(b);
                        u64::from_le_bytes(word)
                    }));
                    w
                }
                _ => Vec::new(),
            };
            let words = c.broadcast_u64s(words);
            match words.split_first() {
                None => None,
                Some(_) if c.rank() == 0 => checkpoint.chains.clone(),
                Some((&n, rest)) => {
                    let mut bytes: Vec<u8> = rest.iter().flat_map(|w| w.to_le_bytes()).collect();
                    bytes.truncate(n as usize);
                    Some(Arc::new(ChainProgress::from_bytes(&bytes, filter, true)?))
                }
            }
        }
    };
    let Some(progress) = progress else {
        return Ok(None);
    };
    if progress.tasks.len() != all {
        return Err(format!(
            "the checkpoint holds {} tasks, the run has {all}",
            progress.tasks.len()
        ));
    }
    for (task, &id) in tasks.iter_mut().zip(ids) {
        restore_task(family, task, &progress.tasks[id])?;
    }
    Ok(Some(progress.mutations()))
}

/// Saves every task (this process's `tasks`, `ids` as for [`resume`]) to
/// `checkpoint`'s file: rank 0 gathers the others' records and writes.
/// Collective on a cluster.
pub(crate) fn save_tasks<F: ChainFamily>(
    family: &F,
    checkpoint: &crate::checkpoint::Checkpoint,
    cluster: Option<&dyn crate::cluster::Cluster>,
    tasks: &[Task<'_, F>],
    ids: &[usize],
    filter: &Arc<Filter>,
) -> Result<(), String> {
    let records = tasks
        .iter()
        .zip(ids)
        .map(|(t, &id)| record_of_task(family, t, id));
    let tasks = match cluster {
        None => records.collect(),
        Some(c) => {
            let parcels = records.map(|r| parcel_of(&r)).collect();
            match c.gather(parcels, filter) {
                Some(all) => (all.into_iter())
                    .map(|p| record_of(p, true))
                    .collect::<Result<_, _>>()?,
                None => return Ok(()),
            }
        }
    };
    save(
        &checkpoint.path,
        checkpoint.fingerprint,
        &ChainProgress { tasks },
    )
}
