//! Cost of one Metropolis–Hastings / multiple-try step against the cost of
//! the target alone (issue 2, "Measured, not asserted"; figures in
//! docs/performance.md).
//!
//! For each target the group holds `target` (one evaluation), `mh step`
//! (Gaussian random walk, one evaluation per step), `uniform mh step` (the
//! uniform box walk of the same variance per coordinate) and `mtm k=8 step`
//! (λ = 1/q, 15 evaluations per step). The sampler's overhead per step is
//! `step − evaluations × target`.
//!
//! Run: `cargo bench -p mcmc-benches --bench mh -- --warm-up-time 1 --measurement-time 3`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use mcmc_benches::{DENSE_SCALE, dense_gaussian, dense_precision, standard_normal, standard_scale};
use mcmc_core::prelude::*;

/// Benchmarks `target`, MH steps with the Gaussian and the uniform walk and
/// an MTM (k = 8) step on it.
fn group<T: Fn(&[f64]) -> f64>(c: &mut Criterion, name: &str, d: usize, scale: f64, target: T) {
    let mut g = c.benchmark_group(name);
    let state = vec![0.3; d];
    g.bench_function("target", |b| b.iter(|| target(black_box(&state))));

    let mh = MetropolisHastings::new(GaussianRandomWalk::isotropic(scale).unwrap());
    let mut chain = Chain::new(&target, vec![0.0; d], mh, stream_rng(1, 0)).unwrap();
    g.bench_function("mh step", |b| b.iter(|| black_box(chain.step(&target))));

    // Half-width σ√3: the variance σ² of the Gaussian walk's steps.
    let walk = UniformRandomWalk::new(scale * 3f64.sqrt()).unwrap();
    let mut chain = Chain::new(
        &target,
        vec![0.0; d],
        MetropolisHastings::new(walk),
        stream_rng(1, 0),
    )
    .unwrap();
    g.bench_function("uniform mh step", |b| {
        b.iter(|| black_box(chain.step(&target)))
    });

    let kernel = GaussianRandomWalk::isotropic(scale).unwrap();
    let mtm = MultipleTry::new(kernel, 8, Lambda::InverseProposal).unwrap();
    let mut chain = Chain::new(&target, vec![0.0; d], mtm, stream_rng(1, 1)).unwrap();
    g.bench_function("mtm k=8 step", |b| {
        b.iter(|| black_box(chain.step(&target)))
    });
    g.finish();
}

fn benches(c: &mut Criterion) {
    group(
        c,
        "standard normal 1-d",
        1,
        standard_scale(1),
        standard_normal,
    );
    group(
        c,
        "standard normal 100-d",
        100,
        standard_scale(100),
        standard_normal,
    );
    let precision = dense_precision(100);
    group(
        c,
        "dense gaussian 100-d",
        100,
        DENSE_SCALE,
        |x: &[f64]| dense_gaussian(&precision, x),
    );
}

criterion_group!(mh, benches);
criterion_main!(mh);
