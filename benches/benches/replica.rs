//! Replica-exchange benchmarks.
//!
//! - `permutation_dp/M`: one importance-sampled permutation (fill the subset
//!   DP table, then draw) for M = 2 … 20; `brute_force/M`: the same draw by
//!   enumerating all M! permutations, M = 2 … 9.
//! - `sweep_<family>/<move>`: one sweep at M = 8 on a cheap 2-d Gaussian,
//!   single-threaded (global rayon pool of one thread), for every exchange move and for a no-op move (the cost
//!   of the 8 mutations alone). `power`: cross-level densities are free
//!   (`β ln L`); `general`: each cross-level density is a full evaluation.
//!
//! ```text
//! cargo bench -p mcmc-benches --bench replica
//! ```

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use mcmc_core::kernel::GaussianRandomWalk;
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::replica::permutation_dp::{
    DEFAULT_MAX_TABLE_BYTES, PermutationDp, brute_force_sample,
};
use mcmc_core::replica::*;
use mcmc_core::rng::{stream_rng, uniform};
use std::hint::black_box;
use std::time::Duration;

fn random_matrix(m: usize, seed: u64) -> Vec<f64> {
    let mut rng = stream_rng(seed, 0);
    (0..m * m).map(|_| 10.0 * uniform(&mut rng) - 5.0).collect()
}

fn permutations(c: &mut Criterion) {
    let mut g = c.benchmark_group("permutation_dp");
    g.warm_up_time(Duration::from_millis(300));
    g.measurement_time(Duration::from_secs(2));
    g.sample_size(20);
    for m in 2..=20usize {
        let matrix = random_matrix(m, m as u64);
        let mut dp = PermutationDp::new(m, DEFAULT_MAX_TABLE_BYTES).unwrap();
        let mut rng = stream_rng(1, m as u64);
        let mut source = vec![0; m];
        g.bench_with_input(BenchmarkId::from_parameter(m), &m, |b, _| {
            b.iter(|| {
                dp.prepare(black_box(&matrix)).unwrap();
                dp.sample(|| uniform(&mut rng), &mut source);
                black_box(&source);
            })
        });
    }
    // A tempered-ladder-like matrix (own-level entries typical, others up
    // to 1500 nats lower): the linear path with negligible entries dropped.
    let mut rng = stream_rng(4, 0);
    let tempered: Vec<f64> = (0..64)
        .map(|k| {
            if k / 8 == k % 8 {
                -uniform(&mut rng)
            } else {
                -1500.0 * uniform(&mut rng)
            }
        })
        .collect();
    // An identity far below the best permutation: the log-space path.
    let mut wide = random_matrix(8, 99);
    wide[0] = -2000.0;
    for (name, matrix) in [("8-tempered", tempered), ("8-log-space", wide)] {
        let mut dp = PermutationDp::new(8, DEFAULT_MAX_TABLE_BYTES).unwrap();
        let mut rng = stream_rng(2, 0);
        let mut source = vec![0; 8];
        g.bench_function(name, |b| {
            b.iter(|| {
                dp.prepare(black_box(&matrix)).unwrap();
                dp.sample(|| uniform(&mut rng), &mut source);
                black_box(&source);
            })
        });
    }
    g.finish();

    let mut g = c.benchmark_group("brute_force");
    g.warm_up_time(Duration::from_millis(300));
    g.measurement_time(Duration::from_secs(2));
    g.sample_size(10);
    for m in 2..=9usize {
        let matrix = random_matrix(m, m as u64);
        let mut rng = stream_rng(3, m as u64);
        g.bench_with_input(BenchmarkId::from_parameter(m), &m, |b, _| {
            b.iter(|| black_box(brute_force_sample(m, black_box(&matrix), uniform(&mut rng))))
        });
    }
    g.finish();
}

/// An exchange move that does nothing: the sweep's cost is the mutations'.
struct NoExchange;

impl<S, P> ExchangeMove<S, P> for NoExchange {
    fn name(&self) -> String {
        "none".into()
    }
    fn schedule(&self) -> Schedule {
        Schedule::AfterAllMutations
    }
    fn exchange(&mut self, _: Option<usize>, _: &mut ExchangeContext<'_, S, P>) {}
}

const MOVES: [&str; 9] = [
    "mutations-only",
    "neighbour",
    "even-odd",
    "is-permutation",
    "is-swap",
    "eem",
    "frequent-eem",
    "ees",
    "adaptive-ees",
];

fn make_move<P: Clone + Send + Sync + 'static>(kind: &str) -> Box<dyn ExchangeMove<Vec<f64>, P>> {
    match kind {
        "mutations-only" => Box::new(NoExchange),
        "neighbour" => Box::new(NeighbourSwap::new()),
        "even-odd" => Box::new(EvenOdd::new()),
        "is-permutation" => Box::new(IsPermutation::new(8).unwrap()),
        "is-swap" => Box::new(IsSwap::new()),
        "eem" => Box::new(EquiEnergyMove::new(8, RingRange::Observed).unwrap()),
        "frequent-eem" => Box::new(FrequentEquiEnergy::new(8, RingRange::Observed).unwrap()),
        "ees" => Box::new(EquiEnergySampler::new(8, 8, 0.1, RingRange::Observed).unwrap()),
        "adaptive-ees" => Box::new(AdaptiveEquiEnergy::new(8, 16, 0.1, 10_000).unwrap()),
        _ => unreachable!(),
    }
}

fn algs<P>(scales: &[f64]) -> Vec<MetropolisHastings<GaussianRandomWalk, Vec<f64>, P>> {
    scales
        .iter()
        .map(|&s| MetropolisHastings::new(GaussianRandomWalk::isotropic(s).unwrap()))
        .collect()
}

fn gaussian(x: &[f64]) -> f64 {
    -0.5 * (x[0] * x[0] + x[1] * x[1])
}

fn sweeps(c: &mut Criterion) {
    // One thread: the figures are sequential costs, free of scheduling noise
    // on a shared machine (the result is the same for any thread count).
    let _ = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build_global();
    let temps = geometric_temperatures(8, 2500.0).unwrap();
    let scales = kernel_scales(1.0, &temps);
    for family_kind in ["power", "general"] {
        let mut g = c.benchmark_group(format!("sweep_{family_kind}"));
        g.warm_up_time(Duration::from_millis(300));
        g.measurement_time(Duration::from_secs(2));
        for kind in MOVES {
            {
                if family_kind == "power" {
                    let family = PowerFamily::without_prior(
                        gaussian as fn(&[f64]) -> f64,
                        betas_from_temperatures(&temps),
                    )
                    .unwrap();
                    let mut re = ReplicaExchange::new(
                        family,
                        vec![vec![0.0, 0.0]],
                        algs(&scales),
                        make_move(kind),
                        1,
                    )
                    .unwrap();
                    for _ in 0..500 {
                        re.sweep();
                    }
                    re.freeze();
                    for _ in 0..500 {
                        re.sweep();
                    }
                    g.bench_function(kind, |b| b.iter(|| re.sweep()));
                } else {
                    let t = temps.clone();
                    let family = FnFamily::new(8, move |l: usize, x: &Vec<f64>| gaussian(x) / t[l]);
                    let mut re = ReplicaExchange::new(
                        family,
                        vec![vec![0.0, 0.0]],
                        algs(&scales),
                        make_move(kind),
                        1,
                    )
                    .unwrap();
                    for _ in 0..500 {
                        re.sweep();
                    }
                    re.freeze();
                    for _ in 0..500 {
                        re.sweep();
                    }
                    g.bench_function(kind, |b| b.iter(|| re.sweep()));
                }
            }
        }
        g.finish();
    }
}

criterion_group!(benches, permutations, sweeps);
criterion_main!(benches);
