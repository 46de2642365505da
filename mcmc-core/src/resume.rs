//! Multi-chain runs that survive a stop: every chain an explicit state
//! ([`ResumableChain`]) advanced in blocks, the whole run saved to one file
//! every so often and when it stops, and continued from that file with the
//! bits of the run that was never stopped.
//!
//! [`crate::runner::run_chains`] runs an opaque closure per
//! chain, which cannot be saved; [`run_resumable`] runs chains that can
//! write what their future depends on (position, generator, kernel and
//! adaptation state, results so far) as words and read it back. Chain `c`
//! is made from `stream_rng(seed, c)` as in `run_chains`, and chains never
//! interact, so how the iterations are cut into blocks, sessions and
//! threads changes nothing in the result. [`crate::fit::sample_nuts_resumable`]
//! is a NUTS fit on it; `docs/user-guide-hmc.md` has a recipe.

use crate::checkpoint::write_bytes;
use crate::checkpoint::{chains_fingerprint, decode_chains, encode_chains, read_optional};
use crate::error::{CoreError, Result};
use crate::rng::ChainRng;
use crate::runner::run_chains;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// A chain whose whole state can be saved as words and restored: what a
/// resumable run advances in blocks.
pub trait ResumableChain: Send + Sync {
    /// What a finished chain gives.
    type Output: Send;

    /// A short name of the kind of chain (and of its words' layout), part
    /// of the checkpoint's fingerprint: a file of another kind is refused.
    const KIND: &'static str;

    /// Iterations the chain makes in all.
    fn total(&self) -> u64;

    /// Iterations made so far.
    fn done(&self) -> u64;

    /// Makes the next `n` iterations (fewer when fewer are left). Making
    /// `a` then `b` iterations must give the bits of making `a + b`.
    fn advance(&mut self, n: u64);

    /// Appends everything the chain's future and output depend on (its
    /// state, generator, kernel and adaptation state, results so far).
    fn save(&self, out: &mut Vec<u64>);

    /// Restores the words [`Self::save`] wrote (all of `words`) into a
    /// chain made with the same inputs; the error says, in a few words,
    /// why they are not such a state (the chain is then not to be used).
    fn restore(&mut self, words: &[u64]) -> std::result::Result<(), String>;

    /// The chain's result (after its last iteration).
    fn finish(self) -> Self::Output;
}

/// When a run stops before its end (it saves its checkpoint first): any of
/// a wall-clock deadline, a flag set from elsewhere (a Ctrl-C handler, a
/// job scheduler's signal) and a number of iterations per chain in this
/// session. Looked at between blocks. The default never stops.
#[derive(Clone, Debug, Default)]
pub struct Stop {
    deadline: Option<Instant>,
    flag: Option<Arc<AtomicBool>>,
    iterations: Option<u64>,
}

impl Stop {
    /// Never stops.
    pub fn never() -> Self {
        Stop::default()
    }

    /// Also stops once `budget` has passed (from now).
    pub fn after(mut self, budget: Duration) -> Self {
        self.deadline = Some(Instant::now() + budget);
        self
    }

    /// Also stops once `flag` is set.
    pub fn on_flag(mut self, flag: Arc<AtomicBool>) -> Self {
        self.flag = Some(flag);
        self
    }

    /// Also stops once every chain has made `n` iterations in this session
    /// (the block in which it is reached is completed).
    pub fn after_iterations(mut self, n: u64) -> Self {
        self.iterations = Some(n);
        self
    }

    /// Whether to stop after `iterations` per chain in this session.
    pub(crate) fn requested(&self, iterations: u64) -> bool {
        self.deadline.is_some_and(|d| Instant::now() >= d)
            || self
                .flag
                .as_ref()
                .is_some_and(|f| f.load(Ordering::Relaxed))
            || self.iterations.is_some_and(|n| iterations >= n)
    }
}

/// Where and how often a resumable run saves itself, and when it stops.
#[derive(Clone, Debug)]
pub struct Checkpointing {
    /// The checkpoint file: continued from when it exists, rewritten
    /// (through a temporary file renamed over it) every [`Self::every`],
    /// when the run stops and at its end.
    pub path: PathBuf,
    /// Iterations each chain makes between two looks at the clock and at
    /// [`Self::stop`] (at least 1; default 100). On MPI ranks the ranks
    /// meet between blocks: make a block take milliseconds, not
    /// microseconds (oversubscribed ranks meet slowly).
    pub block: u64,
    /// Time between two checkpoints (zero: after every block; default 60 s).
    pub every: Duration,
    /// When to stop early (default: never).
    pub stop: Stop,
    /// Any number describing inputs the chains' settings do not (a hash of
    /// the data, say): a file written for another is refused. 0 if none.
    pub fingerprint: u64,
}

impl Checkpointing {
    /// Checkpoints to `path` with the defaults.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Checkpointing {
            path: path.into(),
            block: 100,
            every: Duration::from_secs(60),
            stop: Stop::never(),
            fingerprint: 0,
        }
    }
}

/// How far a resumable run got, in iterations summed over its chains.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Progress {
    /// Iterations the checkpoint it continued held (0 for a fresh run).
    pub resumed_from: u64,
    /// Iterations made when it returned.
    pub done: u64,
    /// Iterations of the whole run.
    pub total: u64,
}

/// What a resumable run returns: the chains' outputs when it finished,
/// `None` when it stopped first (its checkpoint then holds the work done).
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpointed<T> {
    /// One output per chain, in chain order, when the run finished.
    pub outputs: Option<Vec<T>>,
    /// How far it got.
    pub progress: Progress,
}

/// Runs `chains` chains, chain `c` made by `make(c, stream_rng(seed, c))`,
/// in blocks of `checkpointing.block` iterations in parallel on rayon,
/// continuing from `checkpointing.path` when it exists and saving to it
/// as [`Checkpointing`] says. The outputs are bit-identical to those of
/// the same chains run without a stop, for any number of threads and
/// however the run was cut into sessions.
///
/// Errors: `make`'s, and [`CoreError::Checkpoint`] for a file that cannot
/// be written or read, of another run (seed, chain count, kind of chain,
/// `checkpointing.fingerprint`), of another format version, damaged
/// (checksum), cut, or whose chains' words do not restore.
///
/// ```
/// use mcmc_core::resume::{Checkpointing, ResumableChain, Stop, run_resumable};
/// use rand::Rng;
/// // A chain that sums `n` draws of its stream.
/// struct Sum { rng: mcmc_core::rng::ChainRng, done: u64, sum: u64 }
/// impl ResumableChain for Sum {
///     type Output = u64;
///     const KIND: &'static str = "sum";
///     fn total(&self) -> u64 { 1000 }
///     fn done(&self) -> u64 { self.done }
///     fn advance(&mut self, n: u64) {
///         for _ in 0..n.min(1000 - self.done) {
///             self.sum = self.sum.wrapping_add(self.rng.next_u64() >> 8);
///             self.done += 1;
///         }
///     }
///     fn save(&self, out: &mut Vec<u64>) {
///         out.extend(mcmc_core::rng::rng_words(&self.rng));
///         out.extend([self.done, self.sum]);
///     }
///     fn restore(&mut self, w: &[u64]) -> Result<(), String> {
///         let [a, b, c, d, done, sum] = w.try_into().map_err(|_| "6 words".to_string())?;
///         self.rng = mcmc_core::rng::rng_from_words([a, b, c, d]).ok_or("a zero generator")?;
///         (self.done, self.sum) = (done, sum);
///         Ok(())
///     }
///     fn finish(self) -> u64 { self.sum }
/// }
/// let make = |_: usize, rng| Ok(Sum { rng, done: 0, sum: 0 });
/// let path = std::env::temp_dir().join(format!("sum-{}.ckpt", std::process::id()));
/// let _ = std::fs::remove_file(&path);
/// let mut ck = Checkpointing::new(&path);
/// ck.block = 64;
/// ck.stop = Stop::never().after_iterations(300); // a budget: stops after 320
/// let first = run_resumable(3, 5, make, &ck).unwrap();
/// assert!(first.outputs.is_none() && first.progress.done == 3 * 320);
/// ck.stop = Stop::never();
/// let resumed = run_resumable(3, 5, make, &ck).unwrap();
/// assert_eq!(resumed.progress.resumed_from, 3 * 320);
/// let _ = std::fs::remove_file(&path);
/// let whole = run_resumable(3, 5, make, &ck).unwrap();
/// assert_eq!(resumed.outputs, whole.outputs);
/// # let _ = std::fs::remove_file(&path);
/// ```
pub fn run_resumable<C: ResumableChain>(
    chains: usize,
    seed: u64,
    make: impl Fn(usize, ChainRng) -> Result<C> + Sync + Send,
    checkpointing: &Checkpointing,
) -> Result<Checkpointed<C::Output>> {
    let mut states: Vec<C> = run_chains(chains, seed, make)
        .into_iter()
        .collect::<Result<_>>()?;
    let path = &checkpointing.path;
    let fingerprint = chains_fingerprint(C::KIND, chains, seed, checkpointing.fingerprint);
    if let Some(bytes) = read_optional(path).map_err(CoreError::Checkpoint)? {
        let words = decode_chains(path, &bytes, fingerprint, chains)?;
        restore_all(path, &mut states, &words, 0)?;
    }
    let resumed_from = iterations_done(&states);
    let save = |states: &[C]| {
        write_bytes(path, &encode_chains(fingerprint, &save_all(states)))
            .map_err(CoreError::Checkpoint)
    };
    let block = checkpointing.block.max(1);
    let (mut session, mut saved) = (0, Instant::now());
    while states.iter().any(|c| c.done() < c.total()) {
        if checkpointing.stop.requested(session) {
            save(&states)?;
            return Ok(Checkpointed {
                outputs: None,
                progress: progress(resumed_from, &states),
            });
        }
        states.par_iter_mut().for_each(|c| c.advance(block));
        session += block;
        if saved.elapsed() >= checkpointing.every {
            save(&states)?;
            saved = Instant::now();
        }
    }
    // The end is saved too: a run started again on a finished file
    // returns its outputs without a step.
    save(&states)?;
    let progress = progress(resumed_from, &states);
    Ok(Checkpointed {
        outputs: Some(states.into_iter().map(C::finish).collect()),
        progress,
    })
}

/// Every chain's words, in order (in parallel: a chain's draws so far may
/// be long).
pub(crate) fn save_all<C: ResumableChain>(states: &[C]) -> Vec<Vec<u64>> {
    states
        .par_iter()
        .map(|c| {
            let mut w = Vec::new();
            c.save(&mut w);
            w
        })
        .collect()
}

/// Restores `states` (chains `first..`) from their words; the first chain
/// that fails names itself in a one-line error.
pub(crate) fn restore_all<C: ResumableChain>(
    path: &Path,
    states: &mut [C],
    words: &[Vec<u64>],
    first: usize,
) -> Result<()> {
    let failed: Vec<Option<String>> = states
        .par_iter_mut()
        .zip(words)
        .map(|(c, w)| c.restore(w).err())
        .collect();
    match failed
        .into_iter()
        .enumerate()
        .find_map(|(i, e)| Some((i, e?)))
    {
        Some((i, why)) => Err(CoreError::Checkpoint(format!(
            "{} is corrupt or of another input: chain {}: {why}",
            path.display(),
            first + i
        ))),
        None => Ok(()),
    }
}

/// Iterations made, summed over `states`.
pub(crate) fn iterations_done<C: ResumableChain>(states: &[C]) -> u64 {
    states.iter().map(C::done).sum()
}

fn progress<C: ResumableChain>(resumed_from: u64, states: &[C]) -> Progress {
    Progress {
        resumed_from,
        done: iterations_done(states),
        total: states.iter().map(C::total).sum(),
    }
}
