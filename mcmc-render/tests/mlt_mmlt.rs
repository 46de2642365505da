//! Multiplexed MLT: thread-count determinism. Agreement of PSSMLT over
//! BDPT and of MMLT with path tracing on the repo's Cornell variants is
//! `agree_mlt.rs`.

mod common;

use common::mmlt_depths;
use mcmc_core::runner::with_threads;
use mcmc_render::integrators::pssmlt::{
    NoMltObserver, Normalization, PssmltSettings, render_family,
};
use mcmc_render::scene::Scene;
use std::collections::HashMap;
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// The test fixture (`tests/scenes/cornell-box.xml`) with the emitter in view.
fn cornell(res: u32, max_depth: u32) -> Scene {
    let mut defines = HashMap::new();
    defines.insert("res".to_string(), res.to_string());
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/scenes/cornell-box.xml");
    let mut s = Scene::load(&path, &defines).expect("cornell box loads");
    s.integrator.max_depth = max_depth;
    s
}

#[test]
fn mmlt_is_bit_identical_across_thread_counts() {
    let scene = cornell(16, 4);
    let bits = |threads: usize, seed: u64| -> Vec<u32> {
        let st = PssmltSettings {
            bootstrap: 2000,
            chains: 64,
            mutations_per_pixel: Some(8),
            seed,
            normalization: Normalization::Running,
            ..PssmltSettings::default()
        };
        let stop = AtomicBool::new(false);
        let r = with_threads(threads, || {
            render_family(&scene, mmlt_depths(&scene), &st, &stop, &NoMltObserver)
        })
        .expect("mmlt runs");
        r.image()
            .iter()
            .flat_map(|p| [p.r.to_bits(), p.g.to_bits(), p.b.to_bits()])
            .collect()
    };
    let one = bits(1, 42);
    assert!(one == bits(2, 42), "1 vs 2 threads differ");
    assert!(one == bits(5, 42), "1 vs 5 threads differ");
    assert!(one != bits(2, 43), "seed ignored");
}
