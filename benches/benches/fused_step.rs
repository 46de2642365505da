//! Cost of one chain step of `fused` against the chains it fuses, on the
//! door scene (`scenes/door-ajar.xml`, 64×48, path depth 4): a `fused`
//! step with its default mixture (half primary-sample, half path-space
//! moves), a `fused` step of each kind alone, an MMLT step (the same
//! primary-sample mutation and target) and a path-space MLT step with the
//! path-space mutations `fused` uses (fixed-length bidirectional and lens
//! perturbation, equal weights). Each chain starts from the same traced
//! bootstrap path and keeps running across iterations, so a sample is
//! the mean cost of a step in the chain's stationary regime, acceptance,
//! rejection and failed proposals included (docs/fused.md, Session 20).
//!
//! Run: `cargo bench -p mcmc-benches --bench fused_step`.

use criterion::{Criterion, criterion_group, criterion_main};
use mcmc_core::chain::Chain;
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::rng::stream_rng;
use mcmc_core::target::Target;
use mcmc_render::fused_space::{
    FusedCounters, FusedKernel, FusedMutation, FusedState, FusedTarget,
};
use mcmc_render::integrators::bdpt::{Bdpt, MisHeuristic};
use mcmc_render::path_space::PathTarget;
use mcmc_render::pss::{MmltDepth, PssTarget, bootstrap_point};
use mcmc_render::scene::Scene;
use std::collections::HashMap;
use std::hint::black_box;
use std::path::Path;
use std::sync::Arc;

/// Path depth (segments) of the chains.
const DEPTH: usize = 4;

fn door() -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/door-ajar.xml");
    let defines = HashMap::from([
        ("width".to_string(), "64".to_string()),
        ("height".to_string(), "48".to_string()),
    ]);
    Scene::load(&path, &defines).expect("door scene loads")
}

fn steps(c: &mut Criterion) {
    let scene = door();
    let depth = MmltDepth {
        bdpt: Bdpt {
            max_depth: 6,
            rr_depth: 5,
            heuristic: MisHeuristic::Power,
        },
        depth: DEPTH,
    };
    let pss_target = PssTarget {
        scene: &scene,
        sampler: depth,
    };
    // The first bootstrap point that carries light: every chain starts there.
    let start = (0..)
        .map(|i| bootstrap_point(1, i))
        .find(|u| pss_target.evaluate(u).log_density.is_finite())
        .expect("a bootstrap path carries light");
    let fused_target = FusedTarget {
        scene: &scene,
        depth,
    };
    let mut g = c.benchmark_group("chain_step/door_depth4");
    for (name, p_path) in [
        ("fused", 0.5),
        ("fused_pss_only", 0.0),
        ("fused_path_only", 1.0),
    ] {
        let mutation = FusedMutation {
            path_probability: p_path,
            ..FusedMutation::default()
        };
        let kernel = FusedKernel::new(
            &scene,
            depth,
            &mutation,
            Arc::new(FusedCounters::new(DEPTH)),
        )
        .expect("kernel");
        let mut chain = Chain::new(
            &fused_target,
            FusedState::untraced(&scene, start.clone()),
            MetropolisHastings::new(kernel),
            stream_rng(7, 0),
        )
        .expect("chain");
        g.bench_function(name, |b| b.iter(|| black_box(chain.step(&fused_target))));
    }
    let mutation = FusedMutation::default();
    let mut mmlt = Chain::new(
        &pss_target,
        start.clone(),
        MetropolisHastings::new(mutation.pss.kernel().expect("kernel")),
        stream_rng(7, 0),
    )
    .expect("chain");
    g.bench_function("mmlt", |b| b.iter(|| black_box(mmlt.step(&pss_target))));
    let path_target = PathTarget::default();
    let kernel = (mutation.path_mutations())
        .kernel_between(DEPTH, Some(DEPTH))
        .expect("kernel");
    let mut mlt = Chain::new(
        &path_target,
        FusedState::traced(&scene, &depth, start).path,
        MetropolisHastings::new(kernel),
        stream_rng(7, 0),
    )
    .expect("chain");
    g.bench_function("path_space_mlt", |b| {
        b.iter(|| black_box(mlt.step(&path_target)))
    });
    g.finish();
}

criterion_group!(benches, steps);
criterion_main!(benches);
