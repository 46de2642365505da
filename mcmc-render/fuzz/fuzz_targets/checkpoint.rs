//! Render checkpoints (`render --checkpoint FILE`): the reader, then the
//! resumed render, as the command runs it: a path tracer continues the
//! progress for one more pass in a 4×3 scene.
//!
//! The reader first compares the file's fingerprint and image size with
//! the run's; the target takes both from the input (its first word and the
//! scene's size), so that the fuzzer gets past them to the rest.
#![no_main]
use libfuzzer_sys::fuzz_target;
use mcmc_render::checkpoint::{Checkpoint, progress_from_bytes};
use mcmc_render::integrators::RunSettings;
use mcmc_render::integrators::registry;
use mcmc_render::observer::NoObserver;
use mcmc_render::scene::Scene;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, OnceLock};

/// A 4×3 Cornell box (the repository's, with a smaller film).
fn scene() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let text = include_str!("../../../scenes/cornell-box.xml")
            .replace("name=\"width\" value=\"256\"", "name=\"width\" value=\"4\"")
            .replace(
                "name=\"height\" value=\"256\"",
                "name=\"height\" value=\"3\"",
            );
        let scene = Scene::load_str(&text, Path::new("cornell-box.xml"), Path::new("."))
            .expect("the Cornell box loads");
        assert_eq!((scene.film.width, scene.film.height), (4, 3));
        scene
    })
}

fn out_dir() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("a temporary directory"))
        .path()
}

fuzz_target!(|data: &[u8]| {
    let fingerprint = data
        .get(8..16)
        .map_or(0, |b| u64::from_le_bytes(b.try_into().expect("8 bytes")));
    let scene = scene();
    let size = (scene.film.width, scene.film.height);
    let path = Path::new("fuzz.ckpt");
    let Ok(progress) = progress_from_bytes(data, path, fingerprint, size) else {
        return;
    };
    let spp = u32::try_from(progress.spp_done + 1).unwrap_or(u32::MAX);
    let checkpoint = Checkpoint {
        path: out_dir().join("run.ckpt"),
        fingerprint,
        resume: Some(Arc::new(progress)),
    };
    let integrator = registry::configure(None, Some("pt"), &[]).expect("pt");
    let run = RunSettings {
        spp: Some(spp),
        checkpoint: Some(checkpoint),
        ..RunSettings::default()
    };
    let _ = integrator.render(scene, &run, &AtomicBool::new(false), &NoObserver);
});
