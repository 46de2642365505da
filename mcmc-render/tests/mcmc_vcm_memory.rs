//! `mcmc-vcm`'s memory estimate (`McmcVcmSettings::memory_bytes`, checked
//! before a render allocates anything sized by its settings or the film)
//! against the heap its renders really take.
//!
//! The process's allocator counts every byte allocated and freed
//! (`peak_alloc`), so this test is alone in its binary: another test
//! running beside it would count too. Renders run on a one-thread pool, so
//! the order of allocations, and with it the peak, is the same in every run
//! (no timing enters). The count is of the heap (what the estimate
//! describes), not the resident set: the program's code, stacks and the
//! allocator's own overhead are not in it.

mod common;

use common::repo_scene_tilted;
use mcmc_render::integrators::RunSettings;
use mcmc_render::integrators::mcmc_vcm::{LightChains, McmcVcmSettings};
use mcmc_render::integrators::vcm::{VcmMode, VcmSettings};
use mcmc_render::observer::NoObserver;
use mcmc_render::scene::Scene;
use peak_alloc::PeakAlloc;
use std::sync::atomic::AtomicBool;

#[global_allocator]
static HEAP: PeakAlloc = PeakAlloc;

/// The peak heap (bytes above what was allocated before) of `iterations`
/// iterations of `s` on `scene`, on one thread, and the estimate for it.
fn measure(scene: &Scene, s: &McmcVcmSettings, iterations: u32) -> (u128, u128) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool");
    let estimate = s.memory_bytes(scene).total();
    let run = RunSettings {
        spp: Some(iterations),
        seed: 7,
        ..RunSettings::default()
    };
    let integrator = s.integrator(scene);
    let base = HEAP.current_usage();
    HEAP.reset_peak_usage();
    let out = pool.install(|| integrator.render(scene, &run, &AtomicBool::new(false), &NoObserver));
    let peak = HEAP.peak_usage() - base;
    assert_eq!(out.statistics["iterations"], u64::from(iterations));
    (peak as u128, estimate)
}

/// The estimate of sessions 15 and 16: two 12-byte images per pixel and
/// 256 bytes per chain pair, and 56 bytes per candidate.
fn old_estimate(scene: &Scene, s: &McmcVcmSettings) -> u128 {
    let pixels = u128::from(scene.film.width) * u128::from(scene.film.height);
    s.units as u128 * (pixels * 24 + 256) + s.candidates as u128 * 56
}

/// Settings on `scene`: its depth, a fixed radius 0.1 (merging on), the
/// given chain pairs and candidates.
fn settings(scene: &Scene, units: usize, candidates: usize) -> McmcVcmSettings {
    let mut vcm = VcmSettings {
        mode: VcmMode::Vcm,
        radius: Some(0.1),
        alpha: 1.0,
        ..VcmSettings::default()
    };
    vcm.depth.max_depth = i64::from(scene.integrator.max_depth);
    McmcVcmSettings {
        light_chains: LightChains::Both,
        units,
        candidates,
        vcm,
        ..McmcVcmSettings::default()
    }
}

/// Each part of the estimate against a render where it dominates, on the
/// tilted Cornell box (`max_depth` 5): the camera subpaths and films (32×32,
/// the default 8 pairs and 10 000 candidates, 2 iterations), many chain
/// pairs (4×4 with 3000 pairs: the fuzzer's case, more pairs than pixels)
/// and many candidates (8×8, 100 000). Every peak must lie below the
/// estimate, and the estimate within 4× of the peak (an estimate far above
/// it refuses runs that fit). Control: the estimate of sessions 15–16 lies
/// below the peak of the many-pairs run (it missed what a pair holds
/// besides its images), so this test would have caught it.
#[test]
fn the_memory_estimate_covers_the_heap_a_render_takes() {
    let cases = [
        ("camera subpaths", 32, 8, 10_000, 2),
        ("chain pairs", 4, 3000, 1000, 1),
        ("candidates", 8, 1, 100_000, 1),
    ];
    let mut control = None;
    for (what, res, units, candidates, iterations) in cases {
        let scene = repo_scene_tilted("cornell-box.xml", res, 5);
        let s = settings(&scene, units, candidates);
        let (peak, estimate) = measure(&scene, &s, iterations);
        let parts = s.memory_bytes(&scene);
        eprintln!(
            "{what}: peak {peak} B, estimate {estimate} B ({:.2}×; {parts:?}), old estimate {} B",
            estimate as f64 / peak as f64,
            old_estimate(&scene, &s)
        );
        assert!(
            peak <= estimate,
            "{what}: peak {peak} > estimate {estimate}"
        );
        assert!(
            estimate <= 4 * peak,
            "{what}: estimate {estimate} > 4 × peak {peak}"
        );
        if what == "chain pairs" {
            control = Some((peak, old_estimate(&scene, &s)));
        }
    }
    let (peak, old) = control.expect("the chain-pair case ran");
    assert!(
        old < peak,
        "control: the old estimate {old} B covers the peak {peak} B"
    );
}
