//! Cost of one Metropolis–Hastings / multiple-try step against the cost of
//! the target alone (issue 2, "Measured, not asserted"; figures in
//! docs/performance.md).
//!
//! For each dimension the group holds `target` (one evaluation), `mh step`
//! (Gaussian random walk, one evaluation per step) and `mtm k=8 step`
//! (λ = 1/q, 15 evaluations per step). The sampler's overhead per step is
//! `step − evaluations × target`.
//!
//! Run: `cargo bench -p mcmc-benches --bench mh -- --warm-up-time 1 --measurement-time 3`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use mcmc_core::prelude::*;

/// Standard normal log density (unnormalised): `d` multiply-adds.
fn standard_normal(x: &[f64]) -> f64 {
    -0.5 * x.iter().map(|v| v * v).sum::<f64>()
}

/// Random-walk scale giving acceptance near 0.23–0.44 on `N(0, I_d)`.
fn scale(d: usize) -> f64 {
    2.4 / (d as f64).sqrt()
}

fn bench_isotropic(c: &mut Criterion, d: usize) {
    let target = |x: &[f64]| standard_normal(x);
    let mut g = c.benchmark_group(format!("standard normal {d}-d"));
    let state = vec![0.3; d];
    g.bench_function("target", |b| b.iter(|| target(black_box(&state))));

    let mh = MetropolisHastings::new(GaussianRandomWalk::isotropic(scale(d)).unwrap());
    let mut chain = Chain::new(&target, vec![0.0; d], mh, stream_rng(1, 0)).unwrap();
    g.bench_function("mh step", |b| b.iter(|| black_box(chain.step(&target))));

    let kernel = GaussianRandomWalk::isotropic(scale(d)).unwrap();
    let mtm = MultipleTry::new(kernel, 8, Lambda::InverseProposal).unwrap();
    let mut chain = Chain::new(&target, vec![0.0; d], mtm, stream_rng(1, 1)).unwrap();
    g.bench_function("mtm k=8 step", |b| {
        b.iter(|| black_box(chain.step(&target)))
    });
    g.finish();
}

/// A 100-d Gaussian with a dense precision matrix: `d²` multiply-adds per
/// evaluation, a target whose cost is closer to a real posterior's.
fn bench_dense(c: &mut Criterion) {
    let d = 100;
    // Precision = the AR(1) correlation matrix ρ^|i−j| / (1 − ρ²): positive definite and dense.
    let rho: f64 = 0.5;
    let precision: Vec<f64> = (0..d * d)
        .map(|k| {
            let (i, j) = (k / d, k % d);
            rho.powi((i as i32 - j as i32).abs()) / (1.0 - rho * rho)
        })
        .collect();
    let target = move |x: &[f64]| {
        let mut q = 0.0;
        for (i, xi) in x.iter().enumerate() {
            let row = &precision[i * d..(i + 1) * d];
            q += xi * row.iter().zip(x).map(|(p, xj)| p * xj).sum::<f64>();
        }
        -0.5 * q
    };
    let mut g = c.benchmark_group("dense gaussian 100-d");
    let state = vec![0.3; d];
    g.bench_function("target", |b| b.iter(|| target(black_box(&state))));
    let mh = MetropolisHastings::new(GaussianRandomWalk::isotropic(0.1).unwrap());
    let mut chain = Chain::new(&target, vec![0.0; d], mh, stream_rng(2, 0)).unwrap();
    g.bench_function("mh step", |b| b.iter(|| black_box(chain.step(&target))));
    let kernel = GaussianRandomWalk::isotropic(0.1).unwrap();
    let mtm = MultipleTry::new(kernel, 8, Lambda::InverseProposal).unwrap();
    let mut chain = Chain::new(&target, vec![0.0; d], mtm, stream_rng(2, 1)).unwrap();
    g.bench_function("mtm k=8 step", |b| {
        b.iter(|| black_box(chain.step(&target)))
    });
    g.finish();
}

fn benches(c: &mut Criterion) {
    bench_isotropic(c, 1);
    bench_isotropic(c, 100);
    bench_dense(c);
}

criterion_group!(mh, benches);
criterion_main!(mh);
