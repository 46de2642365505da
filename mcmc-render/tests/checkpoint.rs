//! Checkpoint and resume of the per-pixel driver (`pt`, `lt`, `bdpt`; the
//! three kinds of pass: tiles, light-path chunks, both): a render stopped
//! after a few passes and resumed from its checkpoint ends with exactly
//! the bits of the uninterrupted render. The command line's `--checkpoint`
//! and the distributed case (stopped on some number of ranks, resumed on
//! another) are checked by `.ci/run`.
//!
//! Control: resuming from the saved film but restarting the pass count at
//! 0 (so the later passes reuse the first passes' random streams) must not
//! give the uninterrupted image, or the comparison could not tell. A
//! damaged checkpoint or one of the earlier format is refused with one
//! line.
//!
//! The Markov-chain driver (`pssmlt`, `mmlt`, and the replica sets of
//! `tempered-pssmlt`, `tempered-mmlt` and `relt`): a render stopped after
//! two of its rounds and resumed ends with the uninterrupted render's
//! bits, statistics included. Control: the same checkpoint with every
//! chain's random stream put back to where it started (all other state
//! kept) must differ. RELT's start-up (annealing, search) is not cut by
//! the time budget when checkpointed (control: it is without), and
//! damaged, foreign or misfitting checkpoints are refused with one line.
//!
//! `erpt` (pass by pass, in the per-pixel driver's format): stopped after
//! two of four passes and resumed, the same bits and statistics as the
//! uninterrupted render; control: the pass count put back to 0 differs.
//! The same for `vcm`'s iterations and the passes of `guided`'s last
//! iteration (session 19; control for `guided`: the pass count two back),
//! and pre-trained `mcmc-pg`'s chains (session 19, as `pssmlt`'s).
//!
//! Session 20: `mlt` and `mept` (path-space chains, every path saved bit
//! for bit; control: the chains' streams put back), a forged or foreign
//! path-space checkpoint refused with one line, and `mcmc-vcm` (format 3:
//! two films, its chains' streams and adaptive small steps; controls: the
//! streams replaced, the small steps put back to their start), and
//! `pssmlt`/`mmlt` with the adaptive small step (each chain's adaptation
//! saved with it, format `mcmcMC04`; controls: the streams, the small
//! steps put back).
//!
//! Session 21 (ckptb): online `mcmc-pg` (its last iteration's chains; the
//! training made again on resume), the adaptive small step in replica
//! sets (each level's adaptation; controls as for `pssmlt`) and
//! `regularization_stages` > 1 (a file per stage; control: the stopped
//! stage's streams put back).

mod common;

use common::{bdpt_of, lt_of, pt_of, repo_scene, repo_scene_tilted};
use mcmc_render::checkpoint::{Checkpoint, Progress, load};
use mcmc_render::color::Rgb;
use mcmc_render::integrators::registry;
use mcmc_render::integrators::{Integrator, Rendered, RunSettings};
use mcmc_render::markov::checkpoint::{ChainProgress, load as load_chains};
use mcmc_render::observer::{NoObserver, Observer};
use mcmc_render::render::{RenderResult, RenderSettings, render, render_checkpointed};
use mcmc_render::scene::Scene;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::time::Duration;

/// Samples per pixel: passes of 1, 2, 4 and 3 (light paths: capped at 4).
const SPP: u32 = 10;

/// Sets `stop` at the `after`-th snapshot (end of a pass): the next pass
/// does not start, as with Ctrl-C or a time limit between passes.
struct StopAfter<'a> {
    stop: &'a AtomicBool,
    after: u32,
    seen: AtomicU32,
}

impl<'a> StopAfter<'a> {
    /// Sets `stop` at the `after`-th snapshot.
    fn new(stop: &'a AtomicBool, after: u32) -> Self {
        StopAfter {
            stop,
            after,
            seen: AtomicU32::new(0),
        }
    }
}

impl Observer for StopAfter<'_> {
    fn snapshot(&self, _image: &dyn Fn() -> Vec<Rgb>, _samples: u64) {
        if self.seen.fetch_add(1, Ordering::SeqCst) + 1 == self.after {
            self.stop.store(true, Ordering::SeqCst);
        }
    }
}

/// A checkpoint file's path in the temporary directory, named for `tag`,
/// with any stale file of an earlier run removed. Unique to this call:
/// the tests run in parallel in one process, and two of them once shared
/// a path (the same integrator, both `check_markov_resume`), so one read
/// the other's finished file as its own ("not two whole rounds").
fn fresh_checkpoint_path(tag: &str) -> std::path::PathBuf {
    static CALLS: AtomicU32 = AtomicU32::new(0);
    let call = CALLS.fetch_add(1, Ordering::Relaxed);
    let path = std::env::temp_dir().join(format!(
        "mcmc-render-checkpoint-{tag}-{}-{call}.ckpt",
        std::process::id()
    ));
    let _ = std::fs::remove_file(&path);
    path
}

fn bits(img: &[Rgb]) -> Vec<u32> {
    img.iter()
        .flat_map(|c| [c.r.to_bits(), c.g.to_bits(), c.b.to_bits()])
        .collect()
}

/// The settings of every per-pixel render here.
fn settings() -> RenderSettings {
    RenderSettings {
        spp: Some(SPP),
        time_budget: None,
        seed: 11,
    }
}

/// `integ`'s render checkpointed to a fresh temporary file named for
/// `name` and stopped after two passes (1 + 2 spp): the checkpoint (not
/// resuming) and the stopped run.
fn stopped_after_two_passes(
    scene: &Scene,
    integ: &dyn Integrator,
    name: &str,
) -> (Checkpoint, RenderResult) {
    let path = fresh_checkpoint_path(name);
    let fresh = Checkpoint {
        path,
        fingerprint: 42,
        resume: None,
        chains: None,
    };
    let stop = AtomicBool::new(false);
    let observer = StopAfter::new(&stop, 2);
    let first = render_checkpointed(scene, integ, &settings(), Some(&fresh), &stop, &observer);
    (fresh, first)
}

/// The interrupted-and-resumed image, the uninterrupted one and the
/// control's (resumed with the pass count reset).
fn images(scene: &Scene, integ: &dyn Integrator, name: &str) -> [Vec<u32>; 3] {
    let settings = settings();
    let size = (scene.film.width, scene.film.height);
    let (fresh, first) = stopped_after_two_passes(scene, integ, name);
    let path = fresh.path.clone();
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

/// The per-pixel driver's checkpoint (format 3, `mcmcPX03`, as format 2
/// before it) ends with an FNV-1a checksum: a flipped bit (here in the
/// non-finite count, which the reader's consistency checks alone would
/// accept), a flipped accumulator bit or a cut file is refused as damaged, and a file of format 1
/// (`mcmcPX01`, no checksum) as of an earlier format, each with one line.
/// Control: the intact file loads and holds the passes saved.
#[test]
fn a_damaged_or_old_per_pixel_checkpoint_is_refused_with_one_line() {
    let scene = repo_scene("cornell-box.xml", 8);
    let size = (scene.film.width, scene.film.height);
    let (fresh, first) = stopped_after_two_passes(&scene, &pt_of(&scene), "pt-damaged");
    let path = fresh.path;
    assert!(first.interrupted);
    let good = std::fs::read(&path).unwrap();
    let refused = |bytes: &[u8], why: &str| {
        std::fs::write(&path, bytes).unwrap();
        let e = load(&path, 42, size).unwrap_err();
        assert!(e.contains(why) && !e.contains('\n'), "{why}: {e}");
    };
    // Word 3 (after the magic) is the non-finite count: 0 → 1.
    let mut count = good.clone();
    count[8 + 3 * 8] ^= 1;
    refused(&count, "damaged");
    let mut accumulator = good.clone();
    accumulator[good.len() / 2] ^= 0x10;
    refused(&accumulator, "damaged");
    refused(&good[..good.len() - 8], "damaged");
    // Format 1's magic on the file without its checksum.
    let mut v1 = good[..good.len() - 8].to_vec();
    v1[..8].copy_from_slice(b"mcmcPX01");
    refused(&v1, "of an earlier format (mcmcPX01");
    // Control: the file itself loads.
    std::fs::write(&path, &good).unwrap();
    let progress = load(&path, 42, size).unwrap().expect("a checkpoint");
    assert_eq!(
        (progress.pass, progress.spp_done, progress.nonfinite),
        (2, 3, 0)
    );
    std::fs::remove_file(&path).unwrap();
}

/// An integrator's own render (`name` configured with `sets`), `spp`
/// samples per pixel, checkpointed to a fresh temporary file and stopped
/// at its `after`-th snapshot; then resumed from that file. Asserts that
/// the resumed render ends with the uninterrupted render's image and
/// `keys` of its statistics bit for bit and records `resumed_from`, and
/// that the control — the saved file changed by `rewind` — gives another
/// image. Returns the saved progress and the integrator, for the callers'
/// checks of what the file holds and of refusals.
fn check_per_pixel_resume(
    scene: &Scene,
    (name, sets): (&str, &[(&str, &str)]),
    (spp, after): (u32, u32),
    rewind: impl Fn(&mut Progress),
    keys: &[&str],
    (resumed_from, at): (&str, u64),
) -> (Progress, Box<dyn registry::Configured>) {
    let size = (scene.film.width, scene.film.height);
    let integ = configured((name, sets));
    let path = fresh_checkpoint_path(name);
    let run = |resume: Option<Progress>| RunSettings {
        spp: Some(spp),
        seed: 9,
        checkpoint: Some(Checkpoint {
            path: path.clone(),
            fingerprint: 42,
            resume: resume.map(Arc::new),
            chains: None,
        }),
        ..RunSettings::default()
    };
    let stop = AtomicBool::new(false);
    let observer = StopAfter::new(&stop, after);
    let first = integ.render(scene, &run(None), &stop, &observer).unwrap();
    assert!(first.interrupted, "{name}: the first run was not stopped");
    let saved = || load(&path, 42, size).unwrap().expect("a checkpoint");
    // Copies for the control and the caller (the resumed run rewrites the
    // file as it goes).
    let (kept, mut rewound) = (saved(), saved());
    rewind(&mut rewound);
    let go = AtomicBool::new(false);
    let resumed = integ
        .render(scene, &run(Some(saved())), &go, &NoObserver)
        .unwrap();
    let whole_run = RunSettings {
        checkpoint: None,
        ..run(None)
    };
    let whole = integ.render(scene, &whole_run, &go, &NoObserver).unwrap();
    let control = integ
        .render(scene, &run(Some(rewound)), &go, &NoObserver)
        .unwrap();
    std::fs::remove_file(&path).unwrap();
    assert!(!resumed.interrupted, "{name}");
    assert_eq!(resumed.statistics["checkpoint"][resumed_from], at, "{name}");
    assert_resumed_as_whole(name, [&resumed, &whole, &control], keys);
    (kept, integ)
}

/// Asserts that `resumed` ended with `whole`'s image and `keys` of its
/// statistics bit for bit, and that `control` did not end with its image.
fn assert_resumed_as_whole(name: &str, [resumed, whole, control]: [&Rendered; 3], keys: &[&str]) {
    assert!(
        bits(&resumed.image) == bits(&whole.image),
        "{name}: resumed image differs"
    );
    for &key in keys {
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

/// `erpt` checkpointed after every pass (session 18): a render stopped
/// after two of its four passes and resumed from its file ends with the
/// uninterrupted render's image and statistics (passes, mutations, seeds,
/// chains, acceptance, the luminance estimate) bit for bit. Control: the
/// same file with the pass count put back to 0 (so the resumed passes
/// redraw the first passes' streams) must give another image.
#[test]
fn a_stopped_erpt_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 16);
    let sets = [("luminance_samples", "2000"), ("chain_length", "10")];
    let keys = [
        "passes",
        "mutations",
        "seeds",
        "chains",
        "acceptance",
        "acceptance_per_component",
        "luminance_samples",
        "mean_pixel_luminance",
        "deposit_energy",
    ];
    let restart = |p: &mut Progress| (p.pass, p.spp_done) = (0, 0);
    let (saved, _) = check_per_pixel_resume(
        &scene,
        ("erpt", &sets),
        (4, 2),
        restart,
        &keys,
        ("resumed_from_passes", 2),
    );
    assert_eq!((saved.pass, saved.spp_done), (2, 2));
}

/// `vcm` checkpointed after every iteration (session 19): a render stopped
/// after two of its four iterations and resumed from its file ends with
/// the uninterrupted render's image and statistics (iterations, technique
/// energies, light vertices, the last radius) bit for bit. Control: the
/// same file with the iteration count put back to 0 (so the resumed
/// iterations redraw the first iterations' streams and radii) must give
/// another image. A file whose vcm words are cut is refused with one line.
/// A render resumed from `cut` (a checkpoint of `name` with its words
/// cut short) must be refused with one line naming the integrator.
fn assert_cut_checkpoint_is_refused(
    scene: &Scene,
    integ: &dyn registry::Configured,
    name: &str,
    cut: Progress,
) {
    let run = RunSettings {
        spp: Some(4),
        seed: 9,
        checkpoint: Some(Checkpoint {
            path: fresh_checkpoint_path(&format!("{name}-cut")),
            fingerprint: 42,
            resume: Some(Arc::new(cut)),
            chains: None,
        }),
        ..RunSettings::default()
    };
    let refused = integ
        .render(scene, &run, &AtomicBool::new(false), &NoObserver)
        .unwrap_err()
        .to_string();
    let want = format!("not a checkpoint of {name}");
    assert!(
        refused.contains(&want) && !refused.contains('\n'),
        "{refused}"
    );
}

#[test]
fn a_stopped_vcm_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 24);
    let keys = [
        "iterations",
        "energy_shares",
        "light_vertices_per_iteration",
        "nonfinite_samples",
        "radius_final",
    ];
    let restart = |p: &mut Progress| (p.pass, p.spp_done) = (0, 0);
    let (saved, vcm) = check_per_pixel_resume(
        &scene,
        ("vcm", &[]),
        (4, 2),
        restart,
        &keys,
        ("resumed_from_iterations", 2),
    );
    assert_eq!((saved.pass, saved.spp_done, saved.extra.len()), (2, 2, 6));
    let mut cut = saved;
    cut.extra.pop();
    assert_cut_checkpoint_is_refused(&scene, vcm.as_ref(), "vcm", cut);
}

/// Where `mcmc-vcm`'s checkpoint words keep every chain's random stream
/// (4 words) and its kernel's state (θ, proposals, acceptances, frozen),
/// found by the layout `McmcVcm::saved_words` documents: the MIS scale,
/// 3 restart weights, the skipped iterations, the tally's counters (a
/// count, the numbers, a count, the counts), 8 running sums, the batch
/// count and 8 words a batch, the pair count, then per pair its counters,
/// whose counts start with the length of its chains' part: per chain its
/// kind, stream, state length and state.
fn mcmc_vcm_chains(words: &[u64]) -> Vec<(usize, usize)> {
    let skip = |i: usize| i + 1 + words[i] as usize;
    let mut i = skip(skip(5));
    i += 8;
    i += 1 + 8 * words[i] as usize;
    let pairs = words[i];
    i += 1;
    let mut out = Vec::new();
    for _ in 0..pairs {
        i = skip(i);
        let (end, tail_end) = (skip(i), i + 2 + words[i + 1] as usize);
        let mut j = i + 2;
        while j < tail_end {
            out.push((j + 1, j + 6));
            j += 6 + words[j + 5] as usize;
        }
        i = end;
    }
    assert_eq!(i, words.len(), "the layout of mcmc-vcm's words changed");
    out
}

/// `mcmc-vcm` checkpointed after every iteration (session 20, in format 3:
/// its two films and, as its words, the MIS scale, restart weights,
/// running normalisation with its batches, tally, and per chain pair the
/// report, each chain's stream and adaptive small step): a render stopped
/// after two of its four iterations and resumed ends with the
/// uninterrupted render's image and statistics bit for bit. Two controls
/// must give another image: every chain's stream replaced by another
/// (all else kept), and every chain's small step put back to its start
/// (θ = 0.5, no proposals counted). A file with a word cut is refused
/// with one line.
#[test]
fn a_stopped_mcmc_vcm_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 16);
    let sets = [("candidates", "500")];
    let keys = [
        "iterations",
        "energy_shares",
        "chains",
        "exchange_attempts",
        "exchange_rate",
        "exchange_mean_alpha",
        "b_vis",
        "b_vis_standard_error",
        "b_con",
        "b_con_standard_error",
        "light_density_scale",
        "restart_weight_ess",
        "skipped_iterations",
        "nonfinite_samples",
        "normalisation_samples",
        "visibility_chain_steps",
    ];
    let job = ("mcmc-vcm", &sets[..]);
    let at = ("resumed_from_iterations", 2);
    let other_streams = |p: &mut Progress| {
        for (r, _) in mcmc_vcm_chains(&p.extra) {
            let rng = mcmc_core::rng::stream_rng(9, r as u64);
            p.extra[r..r + 4].copy_from_slice(&mcmc_core::rng::rng_words(&rng));
        }
    };
    let (saved, integ) = check_per_pixel_resume(&scene, job, (4, 2), other_streams, &keys, at);
    let fresh_steps = |p: &mut Progress| {
        for (_, k) in mcmc_vcm_chains(&p.extra) {
            p.extra[k..k + 3].copy_from_slice(&[0.5f64.to_bits(), 0, 0]);
        }
    };
    check_per_pixel_resume(&scene, job, (4, 2), fresh_steps, &keys, at);
    // Two films, and more words than format 2's 256 (8 pairs of two chains).
    assert_eq!(
        (saved.pass, saved.spp_done, saved.more_films.len()),
        (2, 2, 1)
    );
    assert_eq!(mcmc_vcm_chains(&saved.extra).len(), 16);
    assert!(saved.extra.len() > 256, "{}", saved.extra.len());
    use mcmc_render::integrators::mcmc_vcm::check_checkpoint;
    assert!(check_checkpoint(&saved, integ.as_any(), &scene).is_ok());
    let mut cut = saved;
    cut.extra.pop();
    let e = check_checkpoint(&cut, integ.as_any(), &scene).unwrap_err();
    assert!(
        e.contains("not a checkpoint of mcmc-vcm") && !e.contains('\n'),
        "{e}"
    );
    assert_cut_checkpoint_is_refused(&scene, integ.as_ref(), "mcmc-vcm", cut);
}

/// `guided` checkpointed after every pass of its last iteration (session
/// 19): 100 spp on a 16×16 box are iterations of 1, 2, 4, 8 and 16 spp
/// (one pass each) and a last one of 69 in passes of 16. A render stopped
/// after its 7th pass (two of the last iteration's) and resumed — the
/// SD-tree trained again — ends with the uninterrupted render's image and
/// sample counts bit for bit. Control: the same file with its pass count
/// two back (the resumed passes redraw the streams of the saved ones; the
/// samples per pixel are unchanged) must give another image. A checkpoint
/// given to a run of another budget, or to a run without one, is refused
/// with one line.
#[test]
fn a_stopped_guided_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 16);
    let keys = [
        "spp",
        "spp_total",
        "spp_per_iteration",
        "records_per_iteration",
        "nonfinite_samples",
        "tree_nodes",
    ];
    let (saved, _) = check_per_pixel_resume(
        &scene,
        ("guided", &[]),
        (100, 7),
        |p: &mut Progress| p.pass -= 2,
        &keys,
        ("resumed_from_spp", 63),
    );
    // 7 passes, 31 + 32 spp; iteration 6 from 31 spp, 69 long, 32 done.
    assert_eq!((saved.pass, saved.spp_done), (7, 63));
    assert_eq!(saved.extra, [6, 31, 69, 32]);
    let one_line = |e: String, why: &str| {
        assert!(e.contains(why) && !e.contains('\n'), "{why}: {e}");
    };
    use mcmc_render::integrators::guided::check_checkpoint;
    one_line(
        check_checkpoint(&saved, Some(99)).unwrap_err(),
        "resume with the --spp",
    );
    one_line(
        check_checkpoint(&saved, None).unwrap_err(),
        "only with a sample budget",
    );
}

/// `mcmc-pg` pre-trained (session 19): its chains saved as `pssmlt`'s
/// between rounds, the SD-tree trained again on resume. 24×24 × 32
/// mutations per pixel: 4 spp of training (1/8), then 28 a pixel over 12
/// chains, 1344 a chain: rounds of 256 (five) and 64. Stopped after two
/// rounds and resumed: image and statistics as the uninterrupted run's;
/// control: every chain's stream put back to its start. (Online training
/// is checkpointed since session 21, tested below.)
#[test]
fn a_stopped_pretrained_mcmc_pg_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 24);
    let sets = [
        ("bootstrap", "2000"),
        ("chains", "12"),
        ("mutations_per_pixel", "32"),
    ];
    check_markov_resume(&scene, ("mcmc-pg", &sets), 12 * 256, 24 * 24 * 28);
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
    try_chains_render(scene, (name, sets), path, progress, stop, observer).expect(name)
}

/// `name` configured with `sets` (as the command line's `--set`).
fn configured((name, sets): (&str, &[(&str, &str)])) -> Box<dyn registry::Configured> {
    let sets: Vec<(String, String)> = (sets.iter())
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    registry::configure(None, Some(name), &sets).expect(name)
}

/// [`chains_render`], its error as the command line prints it (also
/// `smcmc`'s render: its checkpoints are whole iterations, and it
/// snapshots after each).
fn try_chains_render(
    scene: &Scene,
    job: (&str, &[(&str, &str)]),
    path: &std::path::Path,
    progress: Option<ChainProgress>,
    stop: &AtomicBool,
    observer: &dyn Observer,
) -> Result<Rendered, String> {
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
    (configured(job).render(scene, &run, stop, observer)).map_err(|e| e.to_string())
}

/// `job` on `scene` checkpointed at `path` and stopped at its `after`-th
/// snapshot, i.e. after `after` rounds (the stopped render).
fn stopped_chains_render(
    scene: &Scene,
    job: (&str, &[(&str, &str)]),
    path: &std::path::Path,
    after: u32,
) -> Rendered {
    let stop = AtomicBool::new(false);
    let observer = StopAfter::new(&stop, after);
    let first = chains_render(scene, job, path, None, &stop, &observer);
    assert!(
        first.interrupted,
        "{}: the first run was not stopped",
        job.0
    );
    first
}

/// The Markov-chain checkpoint at `path` read for `scene`'s image with
/// `fingerprint` (`chains_render`'s is 7).
fn load_for(
    scene: &Scene,
    path: &std::path::Path,
    fingerprint: u64,
) -> Result<Option<ChainProgress>, String> {
    let (w, h) = (scene.film.width, scene.film.height);
    let filter = Arc::new(mcmc_render::film::Filter::new(scene.film.filter, w, h));
    load_chains(path, fingerprint, (w, h), &filter)
}

/// The chains a [`chains_render`] of `scene` saved at `path`.
fn saved_chains(scene: &Scene, path: &std::path::Path) -> ChainProgress {
    load_for(scene, path, 7).unwrap().expect("a checkpoint")
}

/// `progress` with every chain's stream put back to its start (chain `c`'s
/// to stream `c` of `seed`), all else kept: a control's checkpoint.
fn streams_put_back(progress: &mut ChainProgress, seed: u64) {
    let chains = progress.tasks.iter_mut().flat_map(|t| &mut t.chains);
    for (c, chain) in chains.enumerate() {
        chain.rng = mcmc_core::rng::rng_words(&mcmc_core::rng::stream_rng(seed, c as u64));
    }
}

/// `name` with `sets` on `scene`, stopped after two whole rounds (of
/// `round` mutations in all) and resumed, against the uninterrupted
/// render of `total` mutations: the image and the statistics must be
/// equal bit for bit, and the control (the checkpoint with every chain's
/// stream put back to its start) must differ. Returns the resumed and
/// the uninterrupted render, for an integrator's own statistics.
fn check_markov_resume(
    scene: &Scene,
    (name, sets): (&str, &[(&str, &str)]),
    round: u64,
    total: u64,
) -> (Rendered, Rendered) {
    let path = fresh_checkpoint_path(name);
    let load = || saved_chains(scene, &path);
    let job = (name, sets);
    // Stopped after two whole rounds.
    stopped_chains_render(scene, job, &path, 2);
    let saved = load();
    assert_eq!(saved.mutations(), 2 * round, "{name}: not two whole rounds");
    // The control's copy: every chain's stream back at its start.
    let mut restarted = load();
    streams_put_back(&mut restarted, 5);
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
    let keys = [
        "mutations",
        "acceptance",
        "b_running",
        "acceptance_per_depth",
        "families",
        "exchange",
        "searches",
        "annealing",
    ];
    assert_resumed_as_whole(name, [&resumed, &whole, &control], &keys);
    (resumed, whole)
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

/// The adaptive small step (session 20): `pssmlt` and `mmlt` with
/// `small_step=adaptive`, each chain's adaptation (θ, proposals,
/// acceptances) saved with it (`ChainRecord::kernel`), stopped after two
/// of four rounds and resumed: image and statistics as the uninterrupted
/// run's; controls: every chain's stream put back to its start, and every
/// chain's θ put back to its start (0.5) with its counts (all else kept):
/// each must differ.
#[test]
fn a_stopped_adaptive_markov_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 24);
    // 24×24 × 16 mutations per pixel over 9 chains: 1024 a chain, i.e.
    // four rounds of 256.
    let sets = [
        ("bootstrap", "2000"),
        ("chains", "9"),
        ("mutations_per_pixel", "16"),
        ("max_depth", "5"),
        ("small_step", "adaptive"),
    ];
    for name in ["pssmlt", "mmlt"] {
        check_markov_resume(&scene, (name, &sets), 9 * 256, 24 * 24 * 16);
        check_small_steps_are_saved(&scene, (name, &sets));
    }
}

/// The controls and refusal of a checkpointed run `job` with the adaptive
/// small step: its run stopped after two rounds, resumed with every
/// chain's θ put back to its start (0.5) with its counts (all else kept),
/// must end with another image than the uninterrupted run's; resumed with
/// one chain's small-step words cut to three, it is refused with one line.
fn check_small_steps_are_saved(scene: &Scene, job: (&str, &[(&str, &str)])) {
    let name = job.0;
    let path = fresh_checkpoint_path(&format!("adaptive-{name}"));
    stopped_chains_render(scene, job, &path, 2);
    let saved = saved_chains(scene, &path);
    let mut fresh_steps = saved.clone();
    for chain in fresh_steps.tasks.iter_mut().flat_map(|t| &mut t.chains) {
        // θ, proposals, acceptances, frozen: the small step's words.
        assert_eq!(chain.kernel.len(), 4, "{name}");
        chain.kernel[..3].copy_from_slice(&[0.5f64.to_bits(), 0, 0]);
    }
    let mut cut = saved;
    cut.tasks[0].chains[0].kernel.pop();
    let go = AtomicBool::new(false);
    let e = try_chains_render(scene, job, &path, Some(cut), &go, &NoObserver).unwrap_err();
    assert!(
        e.contains("kernel state does not decode") && !e.contains('\n'),
        "{name}: {e}"
    );
    let control = chains_render(scene, job, &path, Some(fresh_steps), &go, &NoObserver);
    let _ = std::fs::remove_file(&path);
    let whole = chains_render(scene, job, &path, None, &go, &NoObserver);
    std::fs::remove_file(&path).unwrap();
    assert!(
        bits(&control.image) != bits(&whole.image),
        "{name}: the small steps' control agreed"
    );
}

/// The replica-set renders' settings here (on a 24×24 box): 24 mutations
/// per pixel over 16 chains, i.e. 4 replica sets of 4 levels, with the
/// exchange move `exchange` and `more`.
fn tempered_sets<'a>(exchange: &'a str, more: &[(&'a str, &'a str)]) -> Vec<(&'a str, &'a str)> {
    let sets = [
        ("bootstrap", "1000"),
        ("chains", "16"),
        ("mutations_per_pixel", "24"),
        ("max_depth", "5"),
        ("levels", "4"),
        ("exchange", exchange),
    ];
    sets.into_iter().chain(more.iter().copied()).collect()
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
        let sets = tempered_sets(exchange, &[]);
        check_markov_resume(&scene, (name, &sets), 4 * 256, 24 * 24 * 24);
    }
}

/// RELT on the 16×16 glossy-glass box (its four replicas all start): 16
/// chains, i.e. 4 replica sets of the 4 replicas in 4 tasks; a small
/// annealing and L0 search, the search continued during the run (its
/// draws go into each task's running `b_4`), the uniform replica resting
/// every other sweep and one random neighbour pair per sweep (drawn from
/// the set's exchange stream).
const RELT: [(&str, &str); 9] = [
    ("bootstrap", "4000"),
    ("chains", "16"),
    ("mutations_per_pixel", "32"),
    ("max_depth", "5"),
    ("annealing_particles", "500"),
    ("l0_search", "20000"),
    ("l0_search_rate", "0.5"),
    ("uniform_share", "0.5"),
    ("exchange", "random_neighbour"),
];

#[test]
fn a_stopped_relt_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene_tilted("cornell-glossy-glass.xml", 16, 5);
    // 16×16 × 32 = 8192 mutations at 3.5 a sweep (the uniform replica in
    // the odd sweeps): ⌈8192/3.5⌉ = 2341 sweeps, 586 + 3 × 585 over the
    // sets, i.e. 586·3 + 293 + 3·(585·3 + 292) = 8192 mutations. A round
    // is 64 sweeps (256 / 4 levels) of 3.5 mutations in each of 4 sets.
    check_markov_resume(&scene, ("relt", &RELT), 4 * 224, 16 * 16 * 32);
}

/// `mlt`'s settings in the path-space tests: 16×16 × 16 mutations per
/// pixel over 4 chains, 1024 a chain, i.e. four rounds of 256; the
/// specular-chain pass (16 spp, rendered again on resume) stays on.
const MLT: [(&str, &str); 4] = [
    ("bootstrap", "2000"),
    ("chains", "4"),
    ("mutations_per_pixel", "16"),
    ("max_depth", "5"),
];

/// `mlt` and `mept` (session 20): path-space chains, each chain's path
/// saved with every vertex field bit for bit
/// (`path_space::state::Path::to_words`), stopped after two of four
/// rounds and resumed: image and statistics as the uninterrupted run's;
/// control: every chain's stream put back to its start. `mlt` with its
/// defaults (bidirectional mutation and lens perturbation) on the Cornell
/// box; `mept` (manifold perturbation, independent proposals, the BDPT
/// start-up) on the glossy-glass box, where the manifold perturbation
/// has specular vertices to move.
#[test]
fn a_stopped_path_space_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 16);
    check_markov_resume(&scene, ("mlt", &MLT), 4 * 256, 16 * 16 * 16);
    let glass = repo_scene_tilted("cornell-glossy-glass.xml", 16, 5);
    check_markov_resume(&glass, ("mept", &MLT), 4 * 256, 16 * 16 * 16);
}

/// A path-space checkpoint whose paths are not the scene's own is refused
/// with one line before a mutation reads them: a path whose stored `f(x)`
/// its evaluation does not reproduce (the checksum, recomputed by a
/// forger, cannot see it), a vertex on an emitter the scene does not have
/// (it would index past the emitters), and `pssmlt`'s chains given to
/// `mlt`. Control: the checkpoint itself resumes.
#[test]
fn a_forged_or_foreign_path_space_checkpoint_is_refused_with_one_line() {
    let scene = repo_scene("cornell-box.xml", 16);
    let path = fresh_checkpoint_path("mlt-forged");
    let after_one = |name: &str| {
        let _ = std::fs::remove_file(&path);
        stopped_chains_render(&scene, (name, &MLT), &path, 1);
        saved_chains(&scene, &path)
    };
    let saved = after_one("mlt");
    let go = AtomicBool::new(false);
    let resume = |progress: ChainProgress, name: &str| {
        try_chains_render(
            &scene,
            (name, &MLT),
            &path,
            Some(progress),
            &go,
            &NoObserver,
        )
    };
    let refused = |progress: ChainProgress, name: &str, why: &str| {
        let e = resume(progress, name).map(|_| ()).unwrap_err();
        assert!(e.contains(why) && !e.contains('\n'), "{why}: {e}");
    };
    // The first chain's path: its vertex count, 14 words a vertex, then
    // f(x) (r and g in its first word) and the raster position.
    let state = &saved.tasks[0].chains[0].state;
    let vertices = state[0] as usize;
    assert_eq!(state.len(), 1 + 14 * vertices + 3);
    let mut brighter = saved.clone();
    brighter.tasks[0].chains[0].state[1 + 14 * vertices] ^= 1 << 20;
    refused(brighter, "mlt", "a chain's state does not decode");
    let mut no_emitter = saved.clone();
    // x_0's emitter: the low half of its 14th word.
    no_emitter.tasks[0].chains[0].state[14] = (state[14] & !0xffff_ffff) | 999;
    refused(no_emitter, "mlt", "a chain's state does not decode");
    refused(after_one("pssmlt"), "mlt", "checkpoint");
    // Control: the genuine checkpoint resumes and finishes.
    let done = resume(saved, "mlt").unwrap();
    assert_eq!(
        done.statistics["checkpoint"]["resumed_from_mutations"],
        4 * 256
    );
    std::fs::remove_file(&path).unwrap();
}

/// A RELT render of `RELT` with `run`'s budget and checkpoint.
fn relt_render(
    scene: &Scene,
    sets: &[(&str, &str)],
    run: &RunSettings,
) -> Result<Rendered, String> {
    let go = AtomicBool::new(false);
    let integ = configured(("relt", sets));
    (integ.render(scene, run, &go, &NoObserver)).map_err(|e| e.to_string())
}

#[test]
fn a_checkpointed_relt_start_up_is_not_cut_by_the_time_budget() {
    // A budget spent before the run starts: with a checkpoint the search
    // and the annealing still run to their end (a resumed run makes the
    // start-up again and must get the same b̂ and replica sets); without
    // one (the control) the budget cuts both at once.
    let scene = repo_scene_tilted("cornell-glossy-glass.xml", 16, 5);
    let path = fresh_checkpoint_path("relt-startup");
    let run = |checkpoint: bool| RunSettings {
        seed: 5,
        time_budget: Some(Duration::ZERO),
        checkpoint: checkpoint.then(|| Checkpoint {
            path: path.clone(),
            fingerprint: 7,
            resume: None,
            chains: None,
        }),
        ..RunSettings::default()
    };
    let with = relt_render(&scene, &RELT, &run(true)).unwrap();
    let without = relt_render(&scene, &RELT, &run(false)).unwrap();
    assert!(with.interrupted && without.interrupted);
    // No whole round ran, so nothing was saved.
    assert!(!path.exists());
    let draws = |r: &Rendered| r.statistics["searches"][3]["draws"].as_u64().unwrap();
    let steps = |r: &Rendered| -> Vec<u64> {
        (r.statistics["annealing"].as_array().unwrap().iter())
            .map(|a| a["steps"].as_u64().unwrap())
            .collect()
    };
    assert_eq!(draws(&with), 20_000);
    assert_eq!(steps(&with), vec![0, 500, 500, 500]);
    assert_eq!(draws(&without), 0);
    assert_eq!(steps(&without), vec![0, 0, 0, 0]);
}

#[test]
fn a_damaged_foreign_or_misfitting_markov_checkpoint_is_refused_with_one_line() {
    let scene = repo_scene_tilted("cornell-glossy-glass.xml", 16, 5);
    let path = fresh_checkpoint_path("relt-damaged");
    // A checkpoint after one round.
    stopped_chains_render(&scene, ("relt", &RELT), &path, 1);
    let good = std::fs::read(&path).unwrap();
    let progress = saved_chains(&scene, &path);
    let refused = |bytes: &[u8], fingerprint: u64, why: &str| {
        std::fs::write(&path, bytes).unwrap();
        let e = load_for(&scene, &path, fingerprint).unwrap_err();
        assert!(e.contains(why) && !e.contains('\n'), "{why}: {e}");
    };
    // One bit flipped in the middle (in a film or a chain), the last word
    // cut, another render's fingerprint, the earlier format.
    let mut flipped = good.clone();
    flipped[good.len() / 2] ^= 0x10;
    refused(&flipped, 7, "damaged");
    refused(&good[..good.len() - 8], 7, "damaged");
    refused(&good, 8, "another render");
    let mut v2 = good.clone();
    v2[..8].copy_from_slice(b"mcmcMC02");
    refused(&v2, 7, "earlier format");
    // Not a regular file: refused before it is read (`/dev/zero` never
    // ends), with one line.
    for special in [std::path::Path::new("/dev/zero"), &std::env::temp_dir()] {
        let e = load_for(&scene, special, 7).unwrap_err();
        assert!(e.contains("not a regular file") && !e.contains('\n'), "{e}");
    }
    // Control: the file itself loads.
    std::fs::write(&path, &good).unwrap();
    assert!(load_for(&scene, &path, 7).unwrap().is_some());
    // A checkpoint of 4 replica sets given to a run of 5: one line.
    let mut five = RELT;
    five[1] = ("chains", "20");
    let run = RunSettings {
        seed: 5,
        checkpoint: Some(Checkpoint {
            path: path.clone(),
            fingerprint: 7,
            resume: None,
            chains: Some(Arc::new(progress)),
        }),
        ..RunSettings::default()
    };
    let e = relt_render(&scene, &five, &run).unwrap_err();
    assert!(e.contains("checkpoint") && !e.contains('\n'), "{e}");
    std::fs::remove_file(&path).unwrap();
}

/// `fused`'s settings in its tests: 16×16 × 16 mutations per pixel over 4
/// chains (MMLT's depths 1–5), four rounds of 256 a chain; the
/// path-space probability `auto`, so the pilot is made again on resume.
const FUSED: [(&str, &str); 4] = [
    ("bootstrap", "2000"),
    ("chains", "4"),
    ("mutations_per_pixel", "16"),
    ("max_depth", "5"),
];

/// `fused` (session 21): each chain's state saved as its primary sample
/// (the cached path re-traced from it on resume) and its kernel's own
/// state (the current path's round-trip outcome, whether its scratch
/// exists, its counts), stopped after two of four rounds and resumed:
/// image, statistics and the `fused` block's tallies as the uninterrupted
/// run's. Controls: every chain's stream put back to its start
/// (`check_markov_resume`), and every kernel's state put back to a fresh
/// kernel's (round trip not checked, no scratch: what resuming without
/// the kernel's words would do) — each must differ.
#[test]
fn a_stopped_fused_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 16);
    let (resumed, whole) = check_markov_resume(&scene, ("fused", &FUSED), 4 * 256, 16 * 16 * 16);
    for key in [
        "proposals",
        "inversions",
        "rejected_before_conversion",
        "acceptance_path_space",
        "round_trip_failures",
    ] {
        assert_eq!(
            resumed.statistics["fused"][key], whole.statistics["fused"][key],
            "fused: {key}"
        );
    }
    let tallies = |r: &Rendered| -> Vec<serde_json::Value> {
        let depths = r.statistics["fused"]["per_depth"].as_array().unwrap();
        (depths.iter())
            .map(|d| {
                serde_json::json!([
                    d["pss_proposals"],
                    d["path_proposals"],
                    d["path_inversions"],
                    d["path_efficiency"]
                ])
            })
            .collect()
    };
    assert_eq!(tallies(&resumed), tallies(&whole));
    let path = fresh_checkpoint_path("fused-kernels");
    stopped_chains_render(&scene, ("fused", &FUSED), &path, 2);
    let mut fresh_kernels = saved_chains(&scene, &path);
    let mut checked = 0;
    for chain in fresh_kernels.tasks.iter_mut().flat_map(|t| &mut t.chains) {
        // p_pss, p_tc, round trip (0: not checked), scratch (0: none),
        // 11 counts, no small-step words.
        assert_eq!(chain.kernel.len(), 15);
        checked += u64::from(chain.kernel[2] != 0) + chain.kernel[3];
        chain.kernel[2..4].copy_from_slice(&[0, 0]);
    }
    assert!(checked > 0, "no chain had checked a round trip");
    let go = AtomicBool::new(false);
    let control = chains_render(
        &scene,
        ("fused", &FUSED),
        &path,
        Some(fresh_kernels),
        &go,
        &NoObserver,
    );
    std::fs::remove_file(&path).unwrap();
    assert!(
        bits(&control.image) != bits(&whole.image),
        "fused: the kernels' control agreed"
    );
}

/// `fused` with `conversion=lazy` (session 25): a chain whose state was
/// reached by path-space moves and not yet mapped back is saved as its
/// path (its point is stale), and its kernel saves the conversion a
/// primary-sample move last made of such a state (its path, its outcome
/// and the point it gave) and the deferred-conversion counts. Stopped
/// after two of four rounds and resumed: image, statistics and the
/// `fused` block's counts as the uninterrupted run's. The checkpoint must
/// hold unconverted states and kept conversions (else it tests nothing).
/// Controls: every chain's stream put back to its start
/// (`check_markov_resume`), and every kernel's kept conversion dropped
/// (what resuming without those words would do: the next primary-sample
/// move converts again with new fresh uniforms) — each must differ; an
/// unconverted state whose `ln π` is not its path's is refused with one
/// line.
#[test]
fn a_stopped_lazy_fused_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 16);
    let mut sets = FUSED.to_vec();
    sets.push(("conversion", "lazy"));
    let (resumed, whole) = check_markov_resume(&scene, ("fused", &sets), 4 * 256, 16 * 16 * 16);
    for key in [
        "proposals",
        "inversions",
        "deferred_conversions",
        "deferred_conversion_failures",
        "acceptance_path_space",
        "round_trip_failures",
    ] {
        assert_eq!(
            resumed.statistics["fused"][key], whole.statistics["fused"][key],
            "fused lazy: {key}"
        );
    }
    assert!(whole.statistics["fused"]["deferred_conversions"].as_u64() > Some(0));
    let path = fresh_checkpoint_path("fused-lazy-kernels");
    stopped_chains_render(&scene, ("fused", &sets), &path, 2);
    let mut dropped = saved_chains(&scene, &path);
    // A forged unconverted state (its `ln π` not its path's) is refused.
    let mut forged = dropped.clone();
    let state = (forged.tasks.iter_mut().flat_map(|t| &mut t.chains))
        .map(|c| &mut c.state)
        .find(|s| s[0] == u64::MAX - 1)
        .expect("an unconverted state");
    *state.last_mut().unwrap() ^= 1 << 40;
    let go = AtomicBool::new(false);
    let e = try_chains_render(
        &scene,
        ("fused", &sets),
        &path,
        Some(forged),
        &go,
        &NoObserver,
    )
    .map(|_| ())
    .unwrap_err();
    assert!(
        e.contains("a chain's state does not decode") && !e.contains('\n'),
        "{e}"
    );
    let (mut unconverted, mut kept) = (0, 0);
    for chain in dropped.tasks.iter_mut().flat_map(|t| &mut t.chains) {
        unconverted += u32::from(chain.state[0] == u64::MAX - 1);
        // p_pss, p_tc, round trip, scratch, 11 counts, no small-step
        // words, then lazy conversion's: 2 counts and the kept
        // conversion's outcome (0: none), its path and point.
        assert!(chain.kernel.len() >= 18);
        if chain.kernel[17] != 0 {
            kept += 1;
            chain.kernel.truncate(18);
            chain.kernel[17] = 0;
        }
    }
    eprintln!(
        "fused lazy: {unconverted} unconverted states and {kept} kept conversions of {} chains saved; {} deferred conversions in the run",
        dropped.tasks.iter().map(|t| t.chains.len()).sum::<usize>(),
        whole.statistics["fused"]["deferred_conversions"]
    );
    assert!(
        unconverted > 0 && kept > 0,
        "{unconverted} unconverted states, {kept} kept conversions"
    );
    let control = chains_render(
        &scene,
        ("fused", &sets),
        &path,
        Some(dropped),
        &go,
        &NoObserver,
    );
    std::fs::remove_file(&path).unwrap();
    assert!(
        bits(&control.image) != bits(&whole.image),
        "fused lazy: the kept conversions' control agreed"
    );
}

/// A `fused` checkpoint whose states or kernels are not the run's is
/// refused with one line before a chain steps: a state whose stored `ln π`
/// its re-trace does not reproduce, one traced for a depth the family
/// does not have, a kernel saved with another path-space probability
/// (another pilot's choice). Control: the checkpoint itself resumes.
#[test]
fn a_forged_fused_checkpoint_is_refused_with_one_line() {
    let scene = repo_scene("cornell-box.xml", 16);
    let path = fresh_checkpoint_path("fused-forged");
    stopped_chains_render(&scene, ("fused", &FUSED), &path, 1);
    let saved = saved_chains(&scene, &path);
    let go = AtomicBool::new(false);
    let resume = |progress: ChainProgress| {
        try_chains_render(
            &scene,
            ("fused", &FUSED),
            &path,
            Some(progress),
            &go,
            &NoObserver,
        )
    };
    let refused = |progress: ChainProgress, why: &str| {
        let e = resume(progress).map(|_| ()).unwrap_err();
        assert!(e.contains(why) && !e.contains('\n'), "{why}: {e}");
    };
    // A traced chain: its depth first, its `ln π` last.
    let (t, c) = (saved.tasks.iter().enumerate())
        .find_map(|(t, task)| {
            let c = task.chains.iter().position(|c| c.state[0] != u64::MAX)?;
            Some((t, c))
        })
        .expect("a traced chain");
    let mut brighter = saved.clone();
    *brighter.tasks[t].chains[c].state.last_mut().unwrap() ^= 1 << 40;
    refused(brighter, "a chain's state does not decode");
    let mut deeper = saved.clone();
    deeper.tasks[t].chains[c].state[0] = 99;
    refused(deeper, "a chain's state does not decode");
    let mut other_pilot = saved.clone();
    let p = &mut other_pilot.tasks[t].chains[c].kernel[0];
    *p = (f64::from_bits(*p) + 0.125).to_bits();
    refused(other_pilot, "a chain's kernel state does not decode");
    // Control: the genuine checkpoint resumes and finishes.
    let done = resume(saved).unwrap();
    assert_eq!(
        done.statistics["checkpoint"]["resumed_from_mutations"],
        4 * 256
    );
    std::fs::remove_file(&path).unwrap();
}

/// `smcmc`'s settings in its tests: 16 iterations on a 12×12 image (144
/// tiles), an exchange round every other iteration (8 rounds: both
/// directions, both parities).
const SMCMC: [(&str, &str); 2] = [("mutations_per_pixel", "16"), ("max_depth", "5")];

/// An `smcmc` render of `SMCMC` checkpointed at `path` (resuming from it
/// if it exists; snapshots after every iteration, so `observer` can stop
/// it at an iteration's end).
fn smcmc_render(
    scene: &Scene,
    path: &std::path::Path,
    stop: &AtomicBool,
    observer: &dyn Observer,
) -> Result<Rendered, String> {
    try_chains_render(scene, ("smcmc", &SMCMC), path, None, stop, observer)
}

/// Sets `stop` after `after` tile steps (`progress` calls), in the
/// middle of an iteration.
struct StopAfterSteps<'a> {
    stop: &'a AtomicBool,
    after: u64,
    seen: std::sync::atomic::AtomicU64,
}

impl Observer for StopAfterSteps<'_> {
    fn progress(&self, done: u64) {
        if self.seen.fetch_add(done, Ordering::SeqCst) + done >= self.after {
            self.stop.store(true, Ordering::SeqCst);
        }
    }
}

/// An `smcmc` checkpoint's header and tiles.
fn smcmc_tiles(
    scene: &Scene,
    path: &std::path::Path,
) -> (
    mcmc_render::smcmc::checkpoint::Header,
    Vec<mcmc_render::smcmc::checkpoint::TileRecord>,
) {
    use mcmc_render::smcmc::checkpoint::{TileRecord, load};
    let size = (scene.film.width, scene.film.height);
    let (header, words) = load(path, 7, size).unwrap().expect("a checkpoint");
    let spread = (header.slots * header.cells) as usize;
    let mut input = &words[..];
    let tiles = (0..size.0 * size.1)
        .map(|_| TileRecord::from_words(&mut input, spread).unwrap())
        .collect();
    assert!(input.is_empty());
    (header, tiles)
}

/// `tiles` saved at `path` with `header` (as the run saves them).
fn save_smcmc_tiles(
    path: &std::path::Path,
    header: &mcmc_render::smcmc::checkpoint::Header,
    tiles: &[mcmc_render::smcmc::checkpoint::TileRecord],
) {
    let mut words = Vec::new();
    for t in tiles {
        t.words(&mut words);
    }
    mcmc_render::smcmc::checkpoint::save(path, 7, header, &words).unwrap();
}

/// `smcmc` (session 21, its own format `mcmcSM01`): stopped at the end of
/// its third iteration (after one exchange round), resumed and stopped
/// again in the middle of its fifth (a run saves its first whole
/// iteration at once, the fourth, but not the cut fifth: the file holds
/// four), then resumed to the end: image and
/// statistics as the uninterrupted run's, bit for bit. Control: the
/// three-iteration checkpoint with every tile chain's stream replaced
/// (all else kept) must give another image.
#[test]
fn a_stopped_smcmc_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 12);
    let path = fresh_checkpoint_path("smcmc");
    let stop = AtomicBool::new(false);
    let at_three = StopAfter::new(&stop, 3);
    let first = smcmc_render(&scene, &path, &stop, &at_three).unwrap();
    assert!(first.interrupted);
    let (header, saved) = smcmc_tiles(&scene, &path);
    assert_eq!((header.iterations, header.rounds), (3, 1));
    assert!(saved.iter().any(|t| t.chain.is_some()));
    // Stopped again 1.5 iterations later, in the middle of the fifth.
    let stop = AtomicBool::new(false);
    let mid_fifth = StopAfterSteps {
        stop: &stop,
        after: 3 * 144 + 216,
        seen: Default::default(),
    };
    let second = smcmc_render(&scene, &path, &stop, &mid_fifth).unwrap();
    assert!(second.interrupted);
    assert_eq!(
        second.statistics["checkpoint"]["resumed_from_iterations"],
        3
    );
    assert_eq!(smcmc_tiles(&scene, &path).0.iterations, 4);
    let go = AtomicBool::new(false);
    let resumed = smcmc_render(&scene, &path, &go, &NoObserver).unwrap();
    assert!(!resumed.interrupted);
    assert_eq!(
        resumed.statistics["checkpoint"]["resumed_from_iterations"],
        4
    );
    assert_eq!(smcmc_tiles(&scene, &path).0.iterations, 16);
    std::fs::remove_file(&path).unwrap();
    let whole = smcmc_render(&scene, &path, &go, &NoObserver).unwrap();
    assert!(
        bits(&resumed.image) == bits(&whole.image),
        "smcmc: resumed image differs"
    );
    for key in [
        "iterations",
        "mutations",
        "acceptance",
        "acceptance_per_component",
        "exchange",
        "initialised_tiles_at_start",
        "initialised_tiles",
        "large_step_samples",
        "solver",
    ] {
        assert_eq!(
            resumed.statistics[key], whole.statistics[key],
            "smcmc: {key}"
        );
    }
    let mut other_streams = saved;
    for (s, t) in other_streams.iter_mut().enumerate() {
        if let Some(c) = &mut t.chain {
            c.rng = mcmc_core::rng::rng_words(&mcmc_core::rng::stream_rng(5, s as u64));
        }
    }
    save_smcmc_tiles(&path, &header, &other_streams);
    let control = smcmc_render(&scene, &path, &go, &NoObserver).unwrap();
    std::fs::remove_file(&path).unwrap();
    assert!(
        bits(&control.image) != bits(&whole.image),
        "smcmc: control agreed"
    );
}

/// An `smcmc` checkpoint that is not the run's is refused with one line:
/// damaged (a bit flipped), of another render, a tile whose saved `ln π̃`
/// its state's evaluation does not give (the checksum recomputed, as a
/// forger would), its last word cut (checksum recomputed), a tile with
/// another step count than the iterations. Control: the file itself
/// resumes.
#[test]
fn a_damaged_or_forged_smcmc_checkpoint_is_refused_with_one_line() {
    let scene = repo_scene("cornell-box.xml", 12);
    let size = (scene.film.width, scene.film.height);
    let path = fresh_checkpoint_path("smcmc-forged");
    let stop = AtomicBool::new(false);
    let at_two = StopAfter::new(&stop, 2);
    smcmc_render(&scene, &path, &stop, &at_two).unwrap();
    let good = std::fs::read(&path).unwrap();
    let (header, tiles) = smcmc_tiles(&scene, &path);
    let go = AtomicBool::new(false);
    let refused = |why: &str| {
        let e = smcmc_render(&scene, &path, &go, &NoObserver)
            .map(|_| ())
            .unwrap_err();
        assert!(e.contains(why) && !e.contains('\n'), "{why}: {e}");
    };
    let mut flipped = good.clone();
    flipped[good.len() / 2] ^= 0x10;
    std::fs::write(&path, &flipped).unwrap();
    refused("damaged");
    let load = mcmc_render::smcmc::checkpoint::load;
    std::fs::write(&path, &good).unwrap();
    let e = load(&path, 8, size).unwrap_err();
    assert!(e.contains("another render") && !e.contains('\n'), "{e}");
    let lit = tiles.iter().position(|t| t.chain.is_some()).unwrap();
    let mut brighter = tiles.clone();
    let c = brighter[lit].chain.as_mut().unwrap();
    c.log_density += 1.0;
    save_smcmc_tiles(&path, &header, &brighter);
    refused("evaluation differs");
    let mut words = Vec::new();
    tiles.iter().for_each(|t| t.words(&mut words));
    words.pop();
    mcmc_render::smcmc::checkpoint::save(&path, 7, &header, &words).unwrap();
    refused("cut");
    let mut behind = tiles.clone();
    behind[0].steps -= 1;
    save_smcmc_tiles(&path, &header, &behind);
    refused("steps");
    // Control: the file itself resumes and finishes.
    std::fs::write(&path, &good).unwrap();
    let done = smcmc_render(&scene, &path, &go, &NoObserver).unwrap();
    assert_eq!(done.statistics["checkpoint"]["resumed_from_iterations"], 2);
    std::fs::remove_file(&path).unwrap();
}

/// `mcmc-pg` with online training (session 21): only the last iteration,
/// the one that makes the image, saves its chains; the training
/// iterations before it are made again on resume (not cut by the clock).
/// 24×24 × 32 mutations per pixel: training iterations of 1, 2, 4 and 8
/// mutations per pixel, then the last of 17 (9792 mutations over 12
/// chains, 816 a chain: rounds of 256, 256, 256 and 48). Stopped after
/// two of the last iteration's rounds and resumed: image and statistics
/// as the uninterrupted run's; control: every chain's stream put back.
#[test]
fn a_stopped_online_mcmc_pg_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 24);
    let sets = [
        ("training", "online"),
        ("bootstrap", "2000"),
        ("chains", "12"),
        ("mutations_per_pixel", "32"),
    ];
    check_markov_resume(&scene, ("mcmc-pg", &sets), 12 * 256, 24 * 24 * 17);
}

/// The adaptive small step in replica sets (session 21): every level's
/// kernel keeps its adaptation at its level while the states are
/// exchanged, and is saved with the chain at that level
/// (`ChainRecord::kernel`). `tempered-pssmlt` with even–odd swaps and
/// `tempered-mmlt` with IS permutations, 4 replica sets of 4 levels on a
/// 24×24 box, stopped after two rounds of 14 and resumed: image and
/// statistics as the uninterrupted run's; controls: the streams put back,
/// and every level's θ put back to 0.5 with its counts, must each differ;
/// a cut small-step record is refused with one line.
#[test]
fn a_stopped_adaptive_tempered_render_resumed_from_its_checkpoint_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 24);
    for (name, exchange) in [
        ("tempered-pssmlt", "even_odd"),
        ("tempered-mmlt", "is_permutation"),
    ] {
        let sets = tempered_sets(exchange, &[("small_step", "adaptive")]);
        check_markov_resume(&scene, (name, &sets), 4 * 256, 24 * 24 * 24);
        check_small_steps_are_saved(&scene, (name, &sets));
    }
}

/// `regularization_stages` > 1 (session 21): each stage a run of its own
/// with its own file (`FILE`, then `FILE.stage1`). `tempered-pssmlt` with
/// 2 stages on a 24×24 box, 4 replica sets of 4 levels: stage 0 of 8
/// mutations per pixel (288 sweeps a set: 5 rounds), stage 1 of 16.
/// Stopped after two rounds of stage 1 and resumed: stage 0 from its
/// finished file, stage 1 continued; image and statistics (the stages'
/// samples among them) as the uninterrupted run's. Control: the stage-1
/// file with every chain's stream put back must differ. Stage 1's file
/// given as stage 0's is refused with one line (each stage's file is tied
/// to its index).
#[test]
fn a_stopped_staged_tempered_render_resumed_from_its_checkpoints_ends_bit_identical() {
    let scene = repo_scene("cornell-box.xml", 24);
    let staged = [
        ("regularization", "geometric"),
        ("regularization_stages", "2"),
    ];
    let sets = tempered_sets("even_odd", &staged);
    let job = ("tempered-pssmlt", &sets[..]);
    let path = fresh_checkpoint_path("staged");
    let stage1 = std::path::PathBuf::from(format!("{}.stage1", path.display()));
    let clear = || [&path, &stage1].map(|p| std::fs::remove_file(p).is_ok());
    clear();
    stopped_chains_render(&scene, job, &path, 5 + 2);
    // The stage-1 file is tied to its stage: refused as stage 0's.
    let e = load_for(&scene, &stage1, 7).unwrap_err();
    assert!(e.contains("another render") && !e.contains('\n'), "{e}");
    let stage0 = saved_chains(&scene, &path);
    assert_eq!(stage0.mutations(), 24 * 24 * 8, "stage 0 finished");
    // Stage 1's file, read as the run reads it.
    let fresh = Checkpoint {
        path: path.clone(),
        fingerprint: 7,
        resume: None,
        chains: None,
    };
    let stage1_checkpoint = mcmc_render::staged::stage_checkpoint(&fresh, 1, &scene).unwrap();
    assert_eq!(stage1_checkpoint.path, stage1);
    let stage1_fp = stage1_checkpoint.fingerprint;
    let saved = Arc::unwrap_or_clone(stage1_checkpoint.chains.expect("stage 1's file"));
    assert_eq!(saved.mutations(), 2 * 4 * 256, "stage 1: two rounds");
    let mut restarted = saved.clone();
    streams_put_back(&mut restarted, 9);
    let go = AtomicBool::new(false);
    let resumed = chains_render(&scene, job, &path, Some(stage0.clone()), &go, &NoObserver);
    let ck = &resumed.statistics["checkpoint"];
    assert_eq!(ck["resumed_from_mutations"], 24 * 24 * 8 + 2 * 4 * 256);
    assert_eq!(ck["total_mutations"], 24 * 24 * 24);
    // The control: stage 0 as saved, stage 1's streams put back.
    mcmc_render::markov::checkpoint::save(&stage1, stage1_fp, &restarted).unwrap();
    let control = chains_render(&scene, job, &path, Some(stage0), &go, &NoObserver);
    clear();
    let whole = chains_render(&scene, job, &path, None, &go, &NoObserver);
    clear();
    assert!(
        bits(&resumed.image) == bits(&whole.image),
        "resumed image differs"
    );
    for key in ["mutations", "acceptance", "b_running", "exchange", "stages"] {
        let strip = |v: Option<&serde_json::Value>| {
            // The stages' seconds are timings, not results.
            let mut v = v.cloned();
            if let Some(serde_json::Value::Array(stages)) = &mut v {
                stages.iter_mut().for_each(|s| s["seconds"] = 0.into());
            }
            v
        };
        assert_eq!(
            strip(resumed.statistics.get(key)),
            strip(whole.statistics.get(key)),
            "{key}"
        );
    }
    assert!(bits(&control.image) != bits(&whole.image), "control agreed");
}
