//! Checkpoint and resume of the per-pixel driver (`pt`, `lt`, `bdpt`; the
//! three kinds of pass: tiles, light-path chunks, both): a render stopped
//! after a few passes and resumed from its checkpoint ends with exactly
//! the bits of the uninterrupted render. The command line's `--checkpoint`
//! and the distributed case (stopped on some number of ranks, resumed on
//! another) are checked by `.ci/run`.
//!
//! Control: resuming from the saved film but restarting the pass count at
//! 0 (so the later passes reuse the first passes' random streams) must not
//! give the uninterrupted image, or the comparison could not tell.
//!
//! The Markov-chain driver (`pssmlt`, `mmlt`, and the replica sets of
//! `tempered-pssmlt` and `tempered-mmlt`): a render stopped after two of
//! its rounds and resumed ends with the uninterrupted render's bits,
//! statistics included. Control: the same checkpoint with every chain's
//! random stream put back to where it started (all other state kept) must
//! differ.

mod common;

use common::{bdpt_of, lt_of, pt_of, repo_scene};
use mcmc_render::checkpoint::{Checkpoint, load};
use mcmc_render::color::Rgb;
use mcmc_render::integrators::registry;
use mcmc_render::integrators::{Integrator, Rendered, RunSettings};
use mcmc_render::markov::checkpoint::{ChainProgress, load as load_chains};
use mcmc_render::observer::{NoObserver, Observer};
use mcmc_render::render::{RenderSettings, render, render_checkpointed};
use mcmc_render::scene::Scene;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};

/// Samples per pixel: passes of 1, 2, 4 and 3 (light paths: capped at 4).
const SPP: u32 = 10;

/// Sets `stop` at the `after`-th snapshot (end of a pass): the next pass
/// does not start, as with Ctrl-C or a time limit between passes.
struct StopAfter<'a> {
    stop: &'a AtomicBool,
    after: u32,
    seen: AtomicU32,
}

impl Observer for StopAfter<'_> {
    fn snapshot(&self, _image: &dyn Fn() -> Vec<Rgb>, _samples: u64) {
        if self.seen.fetch_add(1, Ordering::SeqCst) + 1 == self.after {
            self.stop.store(true, Ordering::SeqCst);
        }
    }
}

fn bits(img: &[Rgb]) -> Vec<u32> {
    img.iter()
        .flat_map(|c| [c.r.to_bits(), c.g.to_bits(), c.b.to_bits()])
        .collect()
}

/// The interrupted-and-resumed image, the uninterrupted one and the
/// control's (resumed with the pass count reset).
fn images(scene: &Scene, integ: &dyn Integrator, name: &str) -> [Vec<u32>; 3] {
    let settings = RenderSettings {
        spp: Some(SPP),
        time_budget: None,
        seed: 11,
    };
    let path = std::env::temp_dir().join(format!(
        "mcmc-render-checkpoint-{name}-{}.ckpt",
        std::process::id()
    ));
    let _ = std::fs::remove_file(&path);
    let size = (scene.film.width, scene.film.height);
    let fresh = Checkpoint {
        path: path.clone(),
        fingerprint: 42,
        resume: None,
        chains: None,
    };
    // Stopped after two passes (1 + 2 spp).
    let stop = AtomicBool::new(false);
    let observer = StopAfter {
        stop: &stop,
        after: 2,
        seen: AtomicU32::new(0),
    };
    let first = render_checkpointed(scene, integ, &settings, Some(&fresh), &stop, &observer);
    assert!(first.interrupted, "{name}: the first run was not stopped");
    assert_eq!(first.spp_done, 3, "{name}");
    let progress = load(&path, 42, size).unwrap().expect("a checkpoint");
    assert_eq!((progress.pass, progress.spp_done), (2, 3), "{name}");
    // The control's copy (the resumed run rewrites the file as it goes).
    let mut restarted = load(&path, 42, size).unwrap().expect("a checkpoint");
    restarted.pass = 0;
    let resume = |progress| Checkpoint {
        resume: Some(Arc::new(progress)),
        ..fresh.clone()
    };
    let go = AtomicBool::new(false);
    let resumed = render_checkpointed(
        scene,
        integ,
        &settings,
        Some(&resume(progress)),
        &go,
        &NoObserver,
    );
    assert!(!resumed.interrupted, "{name}");
    assert_eq!(resumed.spp_done, SPP as u64, "{name}");
    assert_eq!(resumed.checkpoint, Some((3, None)), "{name}");
    let whole = render(scene, integ, &settings, &go, &NoObserver);
    // Control: the same film, but the later passes start over at pass 0.
    let control = render_checkpointed(
        scene,
        integ,
        &settings,
        Some(&resume(restarted)),
        &go,
        &NoObserver,
    );
    std::fs::remove_file(&path).unwrap();
    [resumed.image(), whole.image(), control.image()].map(|i| bits(&i))
}

#[test]
fn a_stopped_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 40);
    for (name, integ) in [
        ("pt", Box::new(pt_of(&scene)) as Box<dyn Integrator>),
        ("lt", Box::new(lt_of(&scene))),
        ("bdpt", Box::new(bdpt_of(&scene))),
    ] {
        let [resumed, whole, control] = images(&scene, integ.as_ref(), name);
        assert!(resumed == whole, "{name}: resumed image differs");
        assert!(control != whole, "{name}: control agreed");
    }
}

/// A Markov render as the command line runs it, with `sets` (the driver's
/// and the integrator's settings), checkpointed at `path`; snapshots after
/// every round (so `observer` can stop it between rounds).
fn chains_render(
    scene: &Scene,
    (name, sets): (&str, &[(&str, &str)]),
    path: &std::path::Path,
    progress: Option<ChainProgress>,
    stop: &AtomicBool,
    observer: &dyn Observer,
) -> Rendered {
    let sets: Vec<(String, String)> = (sets.iter())
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    let integ = registry::configure(None, Some(name), &sets).expect(name);
    let run = RunSettings {
        seed: 5,
        snapshot_every: std::time::Duration::ZERO,
        checkpoint: Some(Checkpoint {
            path: path.to_path_buf(),
            fingerprint: 7,
            resume: None,
            chains: progress.map(Arc::new),
        }),
        ..RunSettings::default()
    };
    integ.render(scene, &run, stop, observer).expect(name)
}

/// `name` with `sets` on `scene`, stopped after two whole rounds (of
/// `round` mutations in all) and resumed, against the uninterrupted
/// render of `total` mutations: the image and the statistics must be
/// equal bit for bit, and the control (the checkpoint with every chain's
/// stream put back to its start) must differ.
fn check_markov_resume(
    scene: &Scene,
    (name, sets): (&str, &[(&str, &str)]),
    round: u64,
    total: u64,
) {
    let (w, h) = (scene.film.width, scene.film.height);
    let filter = Arc::new(mcmc_render::film::Filter::new(scene.film.filter, w, h));
    let path = std::env::temp_dir().join(format!(
        "mcmc-render-checkpoint-{name}-{}.ckpt",
        std::process::id()
    ));
    let _ = std::fs::remove_file(&path);
    let load = || {
        load_chains(&path, 7, (w, h), &filter)
            .unwrap()
            .expect("a checkpoint")
    };
    let job = (name, sets);
    // Stopped after two whole rounds.
    let stop = AtomicBool::new(false);
    let observer = StopAfter {
        stop: &stop,
        after: 2,
        seen: AtomicU32::new(0),
    };
    let first = chains_render(scene, job, &path, None, &stop, &observer);
    assert!(first.interrupted, "{name}: the first run was not stopped");
    let saved = load();
    assert_eq!(saved.mutations(), 2 * round, "{name}: not two whole rounds");
    // The control's copy: every chain's stream back at its start.
    let mut restarted = load();
    for (c, chain) in restarted
        .tasks
        .iter_mut()
        .flat_map(|t| &mut t.chains)
        .enumerate()
    {
        chain.rng = mcmc_core::rng::rng_words(&mcmc_core::rng::stream_rng(5, c as u64));
    }
    let go = AtomicBool::new(false);
    let resumed = chains_render(scene, job, &path, Some(saved), &go, &NoObserver);
    assert!(!resumed.interrupted, "{name}");
    assert_eq!(
        resumed.statistics["checkpoint"]["resumed_from_mutations"],
        2 * round,
        "{name}"
    );
    // The finished run's checkpoint holds all the work.
    assert_eq!(load().mutations(), total, "{name}");
    let _ = std::fs::remove_file(&path);
    let whole = chains_render(scene, job, &path, None, &go, &NoObserver);
    let _ = std::fs::remove_file(&path);
    let control = chains_render(scene, job, &path, Some(restarted), &go, &NoObserver);
    std::fs::remove_file(&path).unwrap();
    assert!(
        bits(&resumed.image) == bits(&whole.image),
        "{name}: resumed image differs"
    );
    for key in [
        "mutations",
        "acceptance",
        "b_running",
        "acceptance_per_depth",
        "families",
        "exchange",
    ] {
        assert_eq!(
            resumed.statistics.get(key),
            whole.statistics.get(key),
            "{name}: {key}"
        );
    }
    assert!(
        bits(&control.image) != bits(&whole.image),
        "{name}: control agreed"
    );
}

#[test]
fn a_stopped_markov_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 40);
    // 40×40 × 24 mutations per pixel over 48 chains: 800 mutations a
    // chain, i.e. rounds of 256, 256, 256 and 32.
    let sets = [
        ("bootstrap", "4000"),
        ("chains", "48"),
        ("mutations_per_pixel", "24"),
        ("max_depth", "5"),
    ];
    for name in ["pssmlt", "mmlt"] {
        check_markov_resume(&scene, (name, &sets), 48 * 256, 40 * 40 * 24);
    }
}

#[test]
fn a_stopped_tempered_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 24);
    // 24×24 × 24 mutations per pixel over 16 chains, i.e. 4 replica sets
    // of 4 levels: 864 sweeps a set, in rounds of 64 sweeps (256 / 4
    // levels), so a round is 4 sets × 256 mutations. The even–odd move's
    // sweep parity and the IS permutations' stream must carry over.
    for (name, exchange) in [
        ("tempered-pssmlt", "is_permutation"),
        ("tempered-mmlt", "even_odd"),
    ] {
        let sets = [
            ("bootstrap", "1000"),
            ("chains", "16"),
            ("mutations_per_pixel", "24"),
            ("max_depth", "5"),
            ("levels", "4"),
            ("exchange", exchange),
        ];
        check_markov_resume(&scene, (name, &sets), 4 * 256, 24 * 24 * 24);
    }
}
