//! Overhead of spreading replica exchange over MPI ranks, on the 20-mode
//! 2-d Gaussian mixture (Liang & Wong 2001, case (a): equal weights,
//! σ = 0.1), with deterministic even–odd swaps.
//!
//! ```sh
//! cargo build -p mcmc-core --features mpi --profile test --example mpi_overhead
//! B=target/debug/examples/mpi_overhead
//! mpirun -n 1 --allow-run-as-root $B --threads 2 --sweeps 200000   # one process, 2 threads
//! mpirun -n 2 --allow-run-as-root $B --threads 1 --sweeps 200000   # two processes, 1 thread each
//! ```
//!
//! With `-n 1` the single-process `ReplicaExchange` runs (on `--threads`
//! rayon threads); with more ranks `DistributedReplicaExchange` runs, each
//! rank on `--threads` threads. `--explore N` makes every level take `N`
//! Metropolis–Hastings steps per sweep (Pigeons' exploration length);
//! `--levels M` uses `M` geometric temperatures from 1 to 60 (default: the
//! five of Liang & Wong, 1, 2.8, 7.7, 21.6, 60). Rank 0 prints one JSON
//! line: wall seconds, sweeps per second, the bytes and messages each rank
//! sent per sweep, and a checksum of level 0's draws (equal for every
//! layout: the runs are bit-identical).

use mcmc_core::chain::{Algorithm, ChainState, StepInfo, Transition};
use mcmc_core::distributed::mpi::topology::Communicator;
use mcmc_core::distributed::mpi::traits::*;
use mcmc_core::distributed::{DistributedReplicaExchange, DistributedSchedule, mpi};
use mcmc_core::prelude::*;
use mcmc_core::replica::{
    EvenOdd, PowerFamily, ReplicaExchange, Tempered, betas_from_temperatures,
    geometric_temperatures, kernel_scales,
};
use std::time::Instant;

/// Component means of the 20-mode mixture (Liang & Wong 2001).
const MEANS: [[f64; 2]; 20] = [
    [2.18, 5.76],
    [8.67, 9.59],
    [4.24, 8.48],
    [8.41, 1.68],
    [3.93, 8.82],
    [3.25, 3.47],
    [1.70, 0.50],
    [4.59, 5.60],
    [6.91, 5.81],
    [6.87, 5.40],
    [5.41, 2.65],
    [2.70, 7.88],
    [4.98, 3.70],
    [1.14, 2.39],
    [8.33, 9.50],
    [4.93, 1.50],
    [1.83, 0.09],
    [2.26, 0.31],
    [5.54, 6.86],
    [1.69, 8.11],
];

fn log_mixture(x: &[f64]) -> f64 {
    const S2: f64 = 0.1 * 0.1;
    let mut t = [0.0; 20];
    for (ti, m) in t.iter_mut().zip(&MEANS) {
        *ti = -((x[0] - m[0]).powi(2) + (x[1] - m[1]).powi(2)) / (2.0 * S2);
    }
    mcmc_core::math::log_sum_exp(&t)
}

/// `n` steps of the inner algorithm per sweep.
struct Explore<A> {
    inner: A,
    n: usize,
}

impl<S, P, A: Algorithm<S, P>> Algorithm<S, P> for Explore<A> {
    fn component_names(&self) -> Vec<String> {
        self.inner.component_names()
    }
    fn step<T: Target<S, Payload = P>>(
        &mut self,
        chain: &mut ChainState<S, P>,
        target: &T,
        observer: &mut dyn FnMut(&Transition<'_, S, P>),
    ) -> StepInfo {
        let mut last = self.inner.step(chain, target, observer);
        for _ in 1..self.n {
            last = self.inner.step(chain, target, observer);
        }
        last
    }
    fn freeze(&mut self) {
        self.inner.freeze();
    }
}

type Alg = Explore<MetropolisHastings<GaussianRandomWalk, Vec<f64>, Tempered<()>>>;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let flag = |name: &str, default: usize| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .map_or(default, |v| v.parse().expect("a number after the flag"))
    };
    let sweeps = flag("--sweeps", 100_000);
    let threads = flag("--threads", 1);
    let explore = flag("--explore", 1);
    let levels = flag("--levels", 0);
    let universe = mpi::initialize().expect("MPI initialised once");
    let world = universe.world();
    let (rank, size) = (world.rank() as usize, world.size() as usize);
    let temps = if levels == 0 {
        vec![1.0, 2.8, 7.7, 21.6, 60.0]
    } else {
        geometric_temperatures(levels, 60.0).expect("temperatures")
    };
    let family = PowerFamily::without_prior(
        log_mixture as fn(&[f64]) -> f64,
        betas_from_temperatures(&temps),
    )
    .expect("family");
    // Proposal scale ∝ √T (0.25 at T = 1), as kernel_scales gives.
    let algorithms: Vec<Alg> = kernel_scales(0.25, &temps)
        .into_iter()
        .map(|s| Explore {
            inner: MetropolisHastings::new(GaussianRandomWalk::isotropic(s).expect("scale")),
            n: explore,
        })
        .collect();
    let start = vec![vec![0.5, 0.5]];
    const SEED: u64 = 2001;
    // The global pool: a rank's ensemble holds its communicator, which may
    // not move to another thread, so it cannot run inside `with_threads`.
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build_global()
        .expect("one global pool");
    world.barrier();
    let t0 = Instant::now();
    let (checksum, traffic) = {
        let mut sum = 0.0f64;
        if size == 1 {
            let mut re =
                ReplicaExchange::new(family, start, algorithms, Box::new(EvenOdd::new()), SEED)
                    .expect("ensemble");
            for _ in 0..sweeps {
                re.sweep();
                sum += re.current(0).state[0];
            }
            (sum, None)
        } else {
            let mut re = DistributedReplicaExchange::new(
                &world,
                family,
                start,
                algorithms,
                DistributedSchedule::EvenOdd,
                SEED,
                0,
            )
            .unwrap_or_else(|e| {
                eprintln!("mpi_overhead: {e}");
                std::process::exit(2)
            });
            for _ in 0..sweeps {
                re.sweep();
                if let Some(s) = re.current(0) {
                    sum += s.state[0];
                }
            }
            (sum, Some(re.traffic()))
        }
    };
    world.barrier();
    let seconds = t0.elapsed().as_secs_f64();
    // Per-rank traffic, gathered on rank 0.
    let mine = traffic.map_or([0u64; 3], |t| [t.bytes, t.messages, t.collectives]);
    let mut all = vec![0u64; 3 * size];
    world.all_gather_into(&mine[..], &mut all[..]);
    if rank == 0 {
        let per_sweep = |k: usize| -> Vec<f64> {
            (0..size)
                .map(|r| all[3 * r + k] as f64 / sweeps as f64)
                .collect()
        };
        println!(
            "{{\"ranks\":{size},\"threads\":{threads},\"levels\":{},\"explore\":{explore},\"sweeps\":{sweeps},\"seconds\":{seconds:.3},\"sweeps_per_second\":{:.0},\"bytes_per_sweep\":{:?},\"messages_per_sweep\":{:?},\"collectives_per_sweep\":{:?},\"checksum\":{checksum:e}}}",
            temps.len(),
            sweeps as f64 / seconds,
            per_sweep(0),
            per_sweep(1),
            per_sweep(2),
        );
    }
}
