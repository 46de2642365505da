//! Cost of one NUTS leapfrog step against the cost of the gradient alone
//! (issue 19, "per-leapfrog cost"; figures in docs/performance.md).
//!
//! Target: the 100-d standard normal (a gradient of 100 multiply-adds, so
//! the tree builder's own work dominates). `nuts 50 transitions` runs 50
//! transitions from a fixed start with a fixed step size (0.35) and the
//! unit metric; they take the same leapfrog steps every time, and the
//! group's throughput is set to that number, so criterion reports leapfrog
//! steps per second. `gradient` is one gradient evaluation; the tree
//! builder's overhead per leapfrog step is `1/throughput − gradient`.
//!
//! Run: `cargo bench --profile test -p mcmc-core --bench nuts_leapfrog -- --warm-up-time 1 --measurement-time 5`
//! (the test profile: opt-level 3 without the release profile's fat LTO).

use std::hint::black_box;

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use mcmc_core::gradient::{Differentiable, GradientPayload, GradientTarget};
use mcmc_core::kernel::Nuts;
use mcmc_core::prelude::*;

/// Standard normal in `d` dimensions with its gradient.
#[derive(Clone, Copy)]
struct StdNormal(usize);

impl GradientTarget for StdNormal {
    fn dim(&self) -> usize {
        self.0
    }
    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        let mut lp = 0.0;
        for (gi, xi) in g.iter_mut().zip(x) {
            *gi = -xi;
            lp -= 0.5 * xi * xi;
        }
        lp
    }
}

const D: usize = 100;
const TRANSITIONS: usize = 50;

type NutsChain = Chain<
    Vec<f64>,
    GradientPayload,
    MetropolisHastings<Nuts<StdNormal>, Vec<f64>, GradientPayload>,
>;

fn chain() -> NutsChain {
    let g = StdNormal(D);
    let start: Vec<f64> = (0..D).map(|i| ((i as f64) * 0.37).sin()).collect();
    let nuts = Nuts::new(g, 0.35).unwrap();
    Chain::new(
        &Differentiable(g),
        start,
        MetropolisHastings::new(nuts),
        stream_rng(5, 0),
    )
    .unwrap()
}

fn run(chain: &mut NutsChain) -> u64 {
    let t = Differentiable(StdNormal(D));
    for _ in 0..TRANSITIONS {
        chain.step(&t);
    }
    chain.algorithm().kernel().statistics().leapfrog_steps
}

fn benches(c: &mut Criterion) {
    let leapfrogs = run(&mut chain());
    let mut g = c.benchmark_group("nuts std normal 100-d");
    let x = vec![0.3; D];
    let mut grad = vec![0.0; D];
    g.throughput(Throughput::Elements(1));
    g.bench_function("gradient", |b| {
        b.iter(|| StdNormal(D).log_density_gradient(black_box(&x), &mut grad))
    });
    g.throughput(Throughput::Elements(leapfrogs));
    g.bench_function("nuts 50 transitions", |b| {
        b.iter_batched(chain, |mut c| black_box(run(&mut c)), BatchSize::SmallInput)
    });
    g.finish();
    eprintln!("nuts: {leapfrogs} leapfrog steps in {TRANSITIONS} transitions");
}

criterion_group!(nuts, benches);
criterion_main!(nuts);
