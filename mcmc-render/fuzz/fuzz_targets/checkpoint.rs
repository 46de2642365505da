//! Render checkpoints (`render --checkpoint FILE`): both readers, then the
//! resumed render, as the command runs it. The per-pixel driver's file
//! (`pt`): a path tracer continues the progress for one more pass in a
//! 4×3 scene. The Markov-chain driver's file: `pssmlt` (2 chains, 100
//! mutations per pixel, so rounds of 256, 256 and 88 mutations a chain)
//! restores its tasks and runs to the end in the same scene.
//!
//! Each reader first compares the file's fingerprint and image size with
//! the run's; the target takes the fingerprint from the input (the word
//! after the magic) and the size from the scene, so that the fuzzer gets
//! past them to the rest. Both formats (per-pixel `mcmcPX03`, whose reader
//! still takes `mcmcPX02`, the seeds' format; Markov-chain `mcmcMC04`,
//! whose reader still takes `mcmcMC03`) end
//! with an FNV-1a checksum of what precedes it, which the
//! target writes into the input's last eight bytes before either reader
//! sees it (damaged checksums are refused first and are tested in
//! `tests/checkpoint.rs`).
#![no_main]
use libfuzzer_sys::fuzz_target;
use mcmc_render::checkpoint::{Checkpoint, progress_from_bytes};
use mcmc_render::film::Filter;
use mcmc_render::integrators::RunSettings;
use mcmc_render::integrators::registry;
use mcmc_render::markov::checkpoint::progress_from_bytes as chain_progress_from_bytes;
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

/// 64-bit FNV-1a, the checkpoints' checksum.
fn fnv1a(bytes: &[u8]) -> u64 {
    (bytes.iter()).fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

fn out_dir() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| tempfile::tempdir().expect("a temporary directory"))
        .path()
}

fuzz_target!(|data: &[u8]| {
    let mut data = data.to_vec();
    if let Some(body) = data.len().checked_sub(8) {
        let checksum = fnv1a(&data[..body]);
        data[body..].copy_from_slice(&checksum.to_le_bytes());
    }
    let data = &data[..];
    let fingerprint = data
        .get(8..16)
        .map_or(0, |b| u64::from_le_bytes(b.try_into().expect("8 bytes")));
    let scene = scene();
    let size = (scene.film.width, scene.film.height);
    let path = Path::new("fuzz.ckpt");
    let mut checkpoint = Checkpoint {
        path: out_dir().join("run.ckpt"),
        fingerprint,
        resume: None,
        chains: None,
    };
    let (integrator, spp) = if let Ok(progress) = progress_from_bytes(data, path, fingerprint, size)
    {
        let spp = u32::try_from(progress.spp_done + 1).unwrap_or(u32::MAX);
        checkpoint.resume = Some(Arc::new(progress));
        (
            registry::configure(None, Some("pt"), &[]).expect("pt"),
            Some(spp),
        )
    } else {
        let filter = Arc::new(Filter::new(scene.film.filter, size.0, size.1));
        let Ok(progress) = chain_progress_from_bytes(data, path, fingerprint, size, &filter) else {
            return;
        };
        checkpoint.chains = Some(Arc::new(progress));
        let sets = [
            ("bootstrap", "1000"),
            ("chains", "2"),
            ("mutations_per_pixel", "100"),
        ]
        .map(|(k, v)| (k.to_string(), v.to_string()));
        let integrator = registry::configure(None, Some("pssmlt"), &sets).expect("pssmlt");
        (integrator, None)
    };
    let run = RunSettings {
        spp,
        checkpoint: Some(checkpoint),
        ..RunSettings::default()
    };
    let _ = integrator.render(scene, &run, &AtomicBool::new(false), &NoObserver);
});
