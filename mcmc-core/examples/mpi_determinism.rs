//! Distributed runs against single-process runs, bit for bit.
//!
//! ```sh
//! cargo build -p mcmc-core --features mpi --profile test --example mpi_determinism
//! mpirun -n 3 --oversubscribe --allow-run-as-root target/debug/examples/mpi_determinism
//! ```
//!
//! Runs, on `K` ranks, (1) independent chains sharded by rank and (2)
//! replica exchange with 7 levels spread over the ranks, with the
//! even–odd and the neighbour schedules; rank 0 then runs the same with
//! the single-process `run_chains` and `ReplicaExchange` and compares every
//! level-0 draw, the final sample and replica of every level, and the
//! neighbour swap counts, bit for bit; as a control, a single-process run
//! with another seed must differ, and every neighbour pair must have
//! accepted swaps (so states crossed every rank boundary). Exit status 0
//! when all agree, 1 on a mismatch, 2 when the distributed set-up refused
//! to run.
//!
//! `--corrupt-rank R` gives rank `R` a different hottest temperature (a
//! mismatched input); the run must then stop with one error on rank 0.
//! `--die-rank R` makes rank `R` exit after the multi-chain part; `mpirun`
//! must then stop the whole job with a non-zero status instead of hanging.
//!
//! Checkpoints: (3) each schedule's run is interrupted after 230 sweeps
//! with a checkpoint written every 50 (the last 30 sweeps are lost, as in
//! a kill), resumed from the checkpoint in a fresh ensemble and finished;
//! the sweeps after the resume, the final levels and the pair counts must
//! equal the single-process run's. `--checkpoint FILE` (with `--sweeps N`,
//! `--every E`) runs only that: each schedule resumes from `FILE.<schedule>`
//! if it exists, checkpoints every `E` sweeps and at the end compares with
//! one process, so a run killed at any moment (`timeout -s TERM`) and
//! started again, on any number of ranks, must still agree.
//!
//! Resumable chains (`run_resumable_distributed`): (4) 10 random-walk
//! chains stopped after 120 of 300 iterations per chain, resumed from the
//! file and finished, must equal `run_chains` of the same chains run
//! without a stop (each chain's output is a hash of every draw, its last
//! state and `ln π`). `--chains-checkpoint FILE` (with `--steps N`
//! iterations per chain, `--every-ms M` between checkpoints) runs only
//! that, resuming from `FILE` if it exists, and prints where it resumed
//! from (`resumed from R of T iterations`); a resumed run (R > 0) is then
//! compared with one process, so a run killed at any moment and started
//! again on another number of ranks must still agree.

use mcmc_core::checkpoint::{FNV_OFFSET, fnv1a};
use mcmc_core::distributed::mpi::topology::Communicator;
use mcmc_core::distributed::{
    DistributedError, DistributedReplicaExchange, DistributedSchedule, mpi, run_chains_distributed,
    run_resumable_distributed,
};
use mcmc_core::prelude::*;
use mcmc_core::replica::{
    EvenOdd, ExchangeMove, NeighbourSwap, PowerFamily, ReplicaExchange, Tempered,
    betas_from_temperatures, geometric_temperatures, kernel_scales,
};
use mcmc_core::resume::{Checkpointing as ChainCheckpointing, ResumableChain, Stop};
use mcmc_core::rng::{rng_from_words, rng_words};
use mcmc_core::runner::run_chains;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

const SEED: u64 = 20;
const LEVELS: usize = 7;

/// Four well-separated modes in 2-d: without exchanges, level 0 stays in
/// one of them, so swaps shape every draw.
fn log_target(x: &[f64]) -> f64 {
    const MODES: [[f64; 2]; 4] = [[-4.0, -4.0], [-4.0, 4.0], [4.0, -4.0], [4.0, 4.0]];
    let terms: Vec<f64> = MODES
        .iter()
        .map(|m| -((x[0] - m[0]).powi(2) + (x[1] - m[1]).powi(2)) / (2.0 * 0.3 * 0.3))
        .collect();
    mcmc_core::math::log_sum_exp(&terms)
}

type Alg = MetropolisHastings<GaussianRandomWalk, Vec<f64>, Tempered<()>>;
type Family = PowerFamily<fn(&[f64]) -> f64>;

fn ensemble(t_max: f64) -> (Family, Vec<Alg>) {
    let temps = geometric_temperatures(LEVELS, t_max).expect("temperatures");
    let family = PowerFamily::without_prior(
        log_target as fn(&[f64]) -> f64,
        betas_from_temperatures(&temps),
    )
    .expect("family");
    let algorithms = kernel_scales(0.3, &temps)
        .into_iter()
        .map(|s| MetropolisHastings::new(GaussianRandomWalk::isotropic(s).expect("scale")))
        .collect();
    (family, algorithms)
}

/// What a replica-exchange run produced: level-0 state after every sweep,
/// final `(state, ln π, replica)` of every level, neighbour pair counts.
#[derive(Debug, PartialEq)]
struct Record {
    draws: Vec<u64>,
    finals: Vec<u64>,
    pairs: Vec<(u64, u64, u64)>,
}

fn bits(x: &[f64]) -> impl Iterator<Item = u64> + '_ {
    x.iter().map(|v| v.to_bits())
}

fn single_process(schedule: DistributedSchedule, sweeps: usize, seed: u64) -> Record {
    let (family, algorithms) = ensemble(50.0);
    let mv: Box<dyn ExchangeMove<Vec<f64>, Tempered<()>>> = match schedule {
        DistributedSchedule::EvenOdd => Box::new(EvenOdd::new()),
        DistributedSchedule::Neighbour => Box::new(NeighbourSwap::new()),
    };
    let mut re = ReplicaExchange::new(family, vec![vec![3.9, 4.1]], algorithms, mv, seed)
        .expect("single-process ensemble");
    let mut draws = Vec::new();
    for _ in 0..sweeps {
        re.sweep();
        draws.extend(bits(&re.current(0).state));
    }
    let mut finals = Vec::new();
    for l in 0..LEVELS {
        let s = re.current(l);
        finals.extend(bits(&s.state));
        finals.push(s.log_density.to_bits());
        finals.push(re.index_process().replica_at(l) as u64);
    }
    let pairs = (0..LEVELS - 1)
        .map(|i| {
            let p = re.statistics().pair(i, i + 1);
            (p.attempted, p.accepted, p.sum_alpha.to_bits())
        })
        .collect();
    Record {
        draws,
        finals,
        pairs,
    }
}

/// Checkpointing of a distributed run: resume from `path` when it exists,
/// write it after every `every` sweeps; `stop_after`: leave after that
/// many sweeps, as if killed (the sweeps after the last checkpoint are lost).
struct Checkpointing {
    path: PathBuf,
    every: usize,
    stop_after: Option<usize>,
}

/// A distributed run: on rank 0 the sweep it started from (0, or where a
/// checkpoint left off) and its record from there; `None` on the other
/// ranks and when stopped early.
fn distributed<C: Communicator>(
    world: &C,
    schedule: DistributedSchedule,
    sweeps: usize,
    t_max: f64,
    checkpointing: Option<&Checkpointing>,
) -> std::result::Result<Option<(usize, Record)>, DistributedError> {
    let (family, algorithms) = ensemble(t_max);
    let mut re = DistributedReplicaExchange::new(
        world,
        family,
        vec![vec![3.9, 4.1]],
        algorithms,
        schedule,
        SEED,
        temperature_fingerprint(t_max),
    )?;
    let mut first = 0;
    if let Some(c) = checkpointing
        && re.resume(&c.path)?
    {
        first = re.sweeps() as usize;
    }
    let mut draws = Vec::new();
    for sweep in first..sweeps {
        if let Some(c) = checkpointing {
            if c.stop_after == Some(sweep) {
                return Ok(None);
            }
            if sweep > first && sweep % c.every == 0 {
                re.checkpoint(&c.path)?;
            }
        }
        re.sweep();
        if let Some(s) = re.current(0) {
            draws.extend(bits(&s.state));
        }
    }
    let levels = re.gather_levels();
    let pairs = re.gather_pair_statistics();
    let (Some(levels), Some(pairs)) = (levels, pairs) else {
        return Ok(None);
    };
    let mut finals = Vec::new();
    for (s, replica) in levels {
        finals.extend(bits(&s.state));
        finals.push(s.log_density.to_bits());
        finals.push(replica as u64);
    }
    let pairs = pairs
        .iter()
        .map(|p| (p.attempted, p.accepted, p.sum_alpha.to_bits()))
        .collect();
    Ok(Some((
        first,
        Record {
            draws,
            finals,
            pairs,
        },
    )))
}

/// The mismatches of a resumed run (from sweep `first`) against one process.
fn compare_resumed(
    schedule: DistributedSchedule,
    sweeps: usize,
    first: usize,
    dist: &Record,
) -> Vec<String> {
    let single = single_process(schedule, sweeps, SEED);
    let mut out = Vec::new();
    for (what, ok) in [
        (
            "level-0 draws after the resume",
            dist.draws[..] == single.draws[2 * first..],
        ),
        ("final levels", dist.finals == single.finals),
        ("pair statistics", dist.pairs == single.pairs),
    ] {
        if !ok {
            out.push(format!("{schedule:?} resumed at sweep {first}: {what}"));
        }
    }
    out
}

/// Sweeps of the in-process interrupt-and-resume check.
const SWEEPS_RESUMED: usize = 400;

/// The temperatures' bits, hashed: the input every rank must share that the
/// densities at the start cannot show (they are all 0 at a mode's centre).
fn temperature_fingerprint(t_max: f64) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for t in geometric_temperatures(LEVELS, t_max).expect("temperatures") {
        t.to_bits().hash(&mut h);
    }
    h.finish()
}

fn chain_work(c: usize, rng: ChainRng) -> Vec<f64> {
    let mh = MetropolisHastings::new(GaussianRandomWalk::isotropic(0.5).expect("scale"));
    let start = vec![c as f64 - 2.0, 1.0];
    let mut chain = Chain::new(&log_target, start, mh, rng).expect("chain");
    let mut out = Vec::new();
    for _ in 0..200 {
        chain.step(&log_target);
        out.extend_from_slice(&chain.current().state);
    }
    out
}

type WalkAlg = MetropolisHastings<GaussianRandomWalk, Vec<f64>, ()>;

/// A random-walk chain on the four modes as a resumable state: its chain
/// (state, `ln π`, generator), iterations done, and an FNV-1a hash of
/// every draw's bits so far (the draws themselves would not fit in memory
/// for long runs).
struct WalkChain {
    chain: Chain<Vec<f64>, (), WalkAlg>,
    done: u64,
    total: u64,
    hash: u64,
}

impl WalkChain {
    fn new(c: usize, rng: ChainRng, total: u64) -> mcmc_core::Result<Self> {
        let mh = MetropolisHastings::new(GaussianRandomWalk::isotropic(0.5)?);
        let start = vec![c as f64 - 2.0, 1.0];
        Ok(WalkChain {
            chain: Chain::new(&log_target, start, mh, rng)?,
            done: 0,
            total,
            hash: FNV_OFFSET,
        })
    }
}

impl ResumableChain for WalkChain {
    /// The hash of the draws, the last state's bits and its `ln π`'s.
    type Output = Vec<u64>;
    const KIND: &'static str = "mpi-determinism-walk";

    fn total(&self) -> u64 {
        self.total
    }
    fn done(&self) -> u64 {
        self.done
    }
    fn advance(&mut self, n: u64) {
        for _ in 0..n.min(self.total - self.done) {
            self.chain.step(&log_target);
            for x in self.chain.state() {
                self.hash = fnv1a(&x.to_bits().to_le_bytes(), self.hash);
            }
            self.done += 1;
        }
    }
    fn save(&self, out: &mut Vec<u64>) {
        out.extend([self.done, self.hash]);
        out.extend(rng_words(self.chain.rng()));
        out.extend(bits(self.chain.state()));
    }
    fn restore(&mut self, words: &[u64]) -> std::result::Result<(), String> {
        let [done, hash, r0, r1, r2, r3, x0, x1] = words
            .try_into()
            .map_err(|_| format!("{} words, not 8", words.len()))?;
        if done > self.total {
            return Err(format!("{done} of {} iterations", self.total));
        }
        let rng = rng_from_words([r0, r1, r2, r3]).ok_or("a zero generator")?;
        let state = vec![f64::from_bits(x0), f64::from_bits(x1)];
        let current = Sample::evaluate(&log_target, state);
        if !current.log_density.is_finite() {
            return Err("a state outside the support".into());
        }
        let parts = self.chain.parts_mut();
        (parts.current, parts.rng) = (current, rng);
        (self.done, self.hash) = (done, hash);
        Ok(())
    }
    fn finish(self) -> Vec<u64> {
        let mut out = vec![self.hash];
        out.extend(bits(self.chain.state()));
        out.push(self.chain.current().log_density.to_bits());
        out
    }
}

/// Resumable chains of the `--chains-checkpoint` run and of check (4).
const WALKS: usize = 10;

/// The walks run to their end in one process, without a stop.
fn walks_single(steps: u64) -> Vec<Vec<u64>> {
    run_chains(WALKS, SEED, |c, rng| {
        let mut w = WalkChain::new(c, rng, steps).expect("walk");
        w.advance(steps);
        w.finish()
    })
}

/// Where a walks run resumed from, its total iterations, its outputs
/// (when it finished).
type WalksRun = (u64, u64, Option<Vec<Vec<u64>>>);

/// The walks on the ranks of `world`, through `path`: on rank 0 where the
/// run resumed from and the outputs when it finished.
fn walks_distributed<C: Communicator>(
    world: &C,
    steps: u64,
    path: &Path,
    (block, every): (u64, Duration),
    stop: Stop,
) -> std::result::Result<Option<WalksRun>, DistributedError> {
    let mut ck = ChainCheckpointing::new(path);
    (ck.block, ck.every, ck.stop) = (block, every, stop);
    let make = |c: usize, rng: ChainRng| WalkChain::new(c, rng, steps);
    let (out, _) = run_resumable_distributed(world, WALKS, SEED, make, &ck)?;
    Ok(out.map(|r| (r.progress.resumed_from, r.progress.total, r.outputs)))
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let flag = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .map(|v| v.parse::<usize>().expect("a number after the flag"))
    };
    let sweeps = flag("--sweeps").unwrap_or(400);
    let every = flag("--every").unwrap_or(50).max(1);
    let checkpoint_file = args
        .iter()
        .position(|a| a == "--checkpoint")
        .and_then(|i| args.get(i + 1))
        .map(PathBuf::from);
    let corrupt = flag("--corrupt-rank");
    let die = flag("--die-rank");
    let Some(universe) = mpi::initialize() else {
        eprintln!("mpi_determinism: MPI was already initialised");
        return ExitCode::from(2);
    };
    let world = universe.world();
    let (rank, size) = (world.rank() as usize, world.size() as usize);
    let mut mismatches = Vec::new();

    if let Some(file) = checkpoint_file {
        return resume_only(&world, &file, sweeps, every);
    }
    let chains_file = args
        .iter()
        .position(|a| a == "--chains-checkpoint")
        .and_then(|i| args.get(i + 1))
        .map(PathBuf::from);
    if let Some(file) = chains_file {
        let steps = flag("--steps").unwrap_or(1_000_000) as u64;
        let every = Duration::from_millis(flag("--every-ms").unwrap_or(500) as u64);
        return walks_resume_only(&world, &file, steps, every);
    }

    // (1) Independent chains.
    const CHAINS: usize = 10;
    match run_chains_distributed(&world, CHAINS, SEED, 0, chain_work) {
        Err(e) => {
            if rank == 0 {
                eprintln!("mpi_determinism: error: {e}");
            }
            return ExitCode::from(2);
        }
        Ok((Some(dist), _)) => {
            if dist != run_chains(CHAINS, SEED, chain_work) {
                mismatches.push("multi-chain draws".to_string());
            }
        }
        Ok((None, _)) => {}
    }

    // A rank that dies mid-run (the others wait in the next collective):
    // mpirun must stop the job with a non-zero status.
    if die == Some(rank) {
        eprintln!("mpi_determinism: rank {rank} exits on purpose (--die-rank)");
        std::process::exit(3);
    }

    // (2) Replica exchange, both schedules.
    for schedule in [DistributedSchedule::EvenOdd, DistributedSchedule::Neighbour] {
        let t_max = if corrupt == Some(rank) { 60.0 } else { 50.0 };
        match distributed(&world, schedule, sweeps, t_max, None) {
            Err(e) => {
                if rank == 0 {
                    eprintln!("mpi_determinism: error: {e}");
                }
                return ExitCode::from(2);
            }
            Ok(Some((_, dist))) => {
                let single = single_process(schedule, sweeps, SEED);
                // Control: another seed must give other draws, or the
                // comparison could not tell anything apart.
                let control = single_process(schedule, sweeps, SEED + 1);
                if dist.draws == control.draws || dist.finals == control.finals {
                    mismatches.push(format!("{schedule:?}: control with another seed agreed"));
                }
                if dist.draws.len() != 2 * sweeps {
                    mismatches.push(format!(
                        "{schedule:?}: {} level-0 coordinates",
                        dist.draws.len()
                    ));
                }
                for (what, ok) in [
                    ("level-0 draws", dist.draws == single.draws),
                    ("final levels", dist.finals == single.finals),
                    ("pair statistics", dist.pairs == single.pairs),
                ] {
                    if !ok {
                        mismatches.push(format!("{schedule:?} {what}"));
                    }
                }
                // Every neighbour pair (so every boundary between ranks) must
                // have accepted swaps, or their transport went untested.
                if single.pairs.iter().any(|p| p.1 == 0) {
                    mismatches.push(format!("{schedule:?}: a neighbour pair accepted no swap"));
                }
            }
            Ok(None) => {}
        }
    }

    // (3) Interrupted after 230 sweeps (checkpoints every 50), resumed.
    for schedule in [DistributedSchedule::EvenOdd, DistributedSchedule::Neighbour] {
        // Only rank 0 reads and writes the file.
        let path = std::env::temp_dir().join(format!(
            "mpi_determinism_{schedule:?}_{}.ckpt",
            std::process::id()
        ));
        let _ = std::fs::remove_file(&path);
        let mut c = Checkpointing {
            path,
            every: 50,
            stop_after: Some(230),
        };
        let run = |c: &Checkpointing| distributed(&world, schedule, SWEEPS_RESUMED, 50.0, Some(c));
        let resumed = run(&c).and_then(|_| {
            c.stop_after = None;
            run(&c)
        });
        let _ = std::fs::remove_file(&c.path);
        match resumed {
            Err(e) => {
                if rank == 0 {
                    eprintln!("mpi_determinism: error: {e}");
                }
                return ExitCode::from(2);
            }
            Ok(Some((first, dist))) => {
                if first != 200 {
                    mismatches.push(format!("{schedule:?}: resumed at sweep {first}, not 200"));
                }
                mismatches.extend(compare_resumed(schedule, SWEEPS_RESUMED, first, &dist));
            }
            Ok(None) => {}
        }
    }

    // (4) Resumable chains: stopped after 120 iterations per chain,
    // resumed from the file (on the same ranks), finished.
    let path =
        std::env::temp_dir().join(format!("mpi_determinism_walks_{}.ckpt", std::process::id()));
    let _ = std::fs::remove_file(&path);
    let stop = Stop::never().after_iterations(120);
    let often = (20, Duration::ZERO);
    let resumed = walks_distributed(&world, 300, &path, often, stop)
        .and_then(|_| walks_distributed(&world, 300, &path, often, Stop::never()));
    let _ = std::fs::remove_file(&path);
    match resumed {
        Err(e) => {
            if rank == 0 {
                eprintln!("mpi_determinism: error: {e}");
            }
            return ExitCode::from(2);
        }
        Ok(Some((from, _, outputs))) => {
            if from != 120 * WALKS as u64 {
                mismatches.push(format!("resumable chains resumed from {from}, not 1200"));
            }
            if outputs != Some(walks_single(300)) {
                mismatches.push("resumable chains' outputs after the resume".into());
            }
            // Control: another number of iterations gives other outputs.
            if outputs == Some(walks_single(299)) {
                mismatches.push("resumable chains: control with 299 iterations agreed".into());
            }
        }
        Ok(None) => {}
    }
    report(
        rank,
        size,
        sweeps,
        mismatches,
        "multi-chain, resumable chains and replica exchange (even-odd, neighbour",
    )
}

/// `--chains-checkpoint FILE`: the walks of `steps` iterations per chain,
/// resumed from `FILE` when it exists, checkpointed every `every`,
/// compared with one process at the end.
fn walks_resume_only<C: Communicator>(
    world: &C,
    file: &Path,
    steps: u64,
    every: Duration,
) -> ExitCode {
    let rank = world.rank() as usize;
    // Blocks of 50 000 iterations (~15 ms a chain): the ranks meet
    // between blocks, and oversubscribed ranks meet slowly.
    match walks_distributed(world, steps, file, (50_000, every), Stop::never()) {
        Err(e) => {
            if rank == 0 {
                eprintln!("mpi_determinism: error: {e}");
            }
            ExitCode::from(2)
        }
        Ok(Some((from, total, outputs))) => {
            println!("mpi_determinism: resumable chains resumed from {from} of {total} iterations");
            // A fresh run is the one a test kills: it leaves at once
            // (after its last checkpoint, a kill would leave a finished
            // file, and the resume would test nothing).
            if from == 0 {
                return ExitCode::SUCCESS;
            }
            if outputs == Some(walks_single(steps)) {
                println!(
                    "mpi_determinism: {} rank(s): resumable chains ({WALKS} x {steps} iterations) bit-identical to one process",
                    world.size()
                );
                ExitCode::SUCCESS
            } else {
                eprintln!(
                    "mpi_determinism: MISMATCH: resumable chains' outputs against one process"
                );
                ExitCode::from(1)
            }
        }
        Ok(None) => ExitCode::SUCCESS,
    }
}

/// Prints the outcome on rank 0; the exit status.
fn report(
    rank: usize,
    size: usize,
    sweeps: usize,
    mismatches: Vec<String>,
    what: &str,
) -> ExitCode {
    if rank != 0 {
        return ExitCode::SUCCESS;
    }
    if mismatches.is_empty() {
        println!(
            "mpi_determinism: {size} rank(s) x {} thread(s): {what}; {LEVELS} levels, {sweeps} sweeps) bit-identical to one process",
            rayon::current_num_threads()
        );
        ExitCode::SUCCESS
    } else {
        eprintln!(
            "mpi_determinism: {size} rank(s): MISMATCH against one process: {}",
            mismatches.join(", ")
        );
        ExitCode::from(1)
    }
}

/// `--checkpoint FILE`: both schedules, each resumed from `FILE.<schedule>`
/// when it exists, checkpointed every `every` sweeps, compared at the end.
fn resume_only<C: Communicator>(world: &C, file: &Path, sweeps: usize, every: usize) -> ExitCode {
    let rank = world.rank() as usize;
    let mut mismatches = Vec::new();
    for schedule in [DistributedSchedule::EvenOdd, DistributedSchedule::Neighbour] {
        let mut path = file.as_os_str().to_owned();
        path.push(format!(".{schedule:?}"));
        let c = Checkpointing {
            path: path.into(),
            every,
            stop_after: None,
        };
        match distributed(world, schedule, sweeps, 50.0, Some(&c)) {
            Err(e) => {
                if rank == 0 {
                    eprintln!("mpi_determinism: error: {e}");
                }
                return ExitCode::from(2);
            }
            Ok(Some((first, dist))) => {
                eprintln!("mpi_determinism: {schedule:?} started at sweep {first}");
                mismatches.extend(compare_resumed(schedule, sweeps, first, &dist));
            }
            Ok(None) => {}
        }
    }
    report(
        rank,
        world.size() as usize,
        sweeps,
        mismatches,
        "checkpointed replica exchange (even-odd, neighbour",
    )
}
