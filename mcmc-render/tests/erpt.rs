//! `erpt` (energy redistribution path tracing): agreement with path
//! tracing on the repo's tilted Cornell box, bit-identical images for any
//! thread count, the partial image on a stop, and its statistics.
//!
//! # Tolerances
//!
//! As `tests/path_space_mlt.rs`: `K` replicates with distinct fixed seeds
//! against 48 PT replicates of 256 spp; `σ` is the standard error of the
//! difference of the means (K ≥ 30 on both sides: normal quantiles); a
//! channel passes within 4σ and 1%, and the budget must give 5σ < 1%
//! (`MeanAgreement::resolves`). The control scales the replicates by 1.01
//! and must fail.

mod common;

use common::{image_mean, mc_reps, pt_of, repo_scene_tilted};
use mcmc_core::runner::with_threads;
use mcmc_render::color::Rgb;
use mcmc_render::integrators::RunSettings;
use mcmc_render::integrators::erpt::Erpt;
use mcmc_render::integrators::registry::{self, IntegratorSettings};
use mcmc_render::observer::{NoObserver, Observer};
use mcmc_render::scene::Scene;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, Ordering};

const RES: u32 = 16;
const DEPTH: u32 = 5;

fn cornell() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-box.xml", RES, DEPTH))
}

fn pt_reference() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| mc_reps(cornell(), &pt_of(cornell()), 256, 48, 1000))
}

/// `erpt` at Mitsuba's defaults with `passes` camera samples per pixel.
fn erpt(scene: &Scene, passes: u32, seed: u64) -> mcmc_render::integrators::Rendered {
    erpt_with(Erpt::default(), scene, passes, seed)
}

/// `erpt` with settings `e` at the scene's depth, 4000 luminance walks
/// and `passes` camera samples per pixel.
fn erpt_with(
    mut e: Erpt,
    scene: &Scene,
    passes: u32,
    seed: u64,
) -> mcmc_render::integrators::Rendered {
    e.depth.max_depth = i64::from(scene.integrator.max_depth);
    e.luminance_samples = 4000;
    let run = RunSettings {
        spp: Some(passes),
        seed,
        ..RunSettings::default()
    };
    e.render(scene, &run, &AtomicBool::new(false), &NoObserver)
        .expect("erpt runs")
}

/// 32 replicates of `PASSES` passes.
const PASSES: u32 = 64;

fn erpt_replicates() -> &'static [[f64; 3]] {
    static REPS: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    REPS.get_or_init(|| {
        (0..32)
            .map(|k| {
                let out = erpt(cornell(), PASSES, 31_000 + k);
                assert_eq!(out.statistics["nonfinite_contributions"], 0);
                image_mean(&out.image)
            })
            .collect()
    })
}

/// Ignored: 6 minutes on the loaded shared machine (passed once,
/// 2026-11-25: within 4σ and 1%, 5σ < 1%;
/// `cargo test -p mcmc-render --test erpt -- --ignored`).
#[test]
#[ignore]
fn erpt_agrees_with_pt_on_the_cornell_box() {
    common::assert_agrees_to_one_percent("erpt", pt_reference(), erpt_replicates());
}

/// Ignored with the agreement test whose replicates it scales.
#[test]
#[ignore]
fn a_one_percent_bias_is_rejected() {
    common::assert_one_percent_bias_is_rejected("erpt", pt_reference(), erpt_replicates());
}

/// `erpt` with Mitsuba's direct-lighting pass (`direct_samples`): paths
/// of one and two segments path traced at `DIRECT_SPP` spp, the seeds,
/// the luminance estimate and the chains on three segments or more;
/// `DIRECT_REPS` replicates of `DIRECT_PASSES` passes. Without the pass's
/// image, or with the chains still taking short paths, the mean would be
/// off by the direct light (most of the image).
fn erpt_direct_replicates() -> &'static [[f64; 3]] {
    static REPS: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    REPS.get_or_init(|| {
        (0..DIRECT_REPS)
            .map(|k| {
                let e = Erpt {
                    direct_samples: i64::from(DIRECT_SPP),
                    ..Erpt::default()
                };
                let out = erpt_with(e, cornell(), DIRECT_PASSES, 61_000 + k);
                assert_eq!(out.statistics["nonfinite_contributions"], 0);
                let pass = &out.statistics["direct_pass"];
                assert_eq!(pass["samples_per_pixel"], DIRECT_SPP, "direct pass cut");
                image_mean(&out.image)
            })
            .collect()
    })
}

/// Sizing of [`erpt_direct_replicates`]. Probes (session 21): 32
/// replicates of 16 passes with a 64-spp pass gave σ 0.25% in red (5σ
/// 1.24%: not resolved; −0.51%, z −2.1); 32 of 40 passes with 128 spp
/// 0.195% (5σ 0.97%, too close); 48 of 40 passes with 128 spp (these)
/// 0.149%, 0.127%, 0.142% (5σ ≤ 0.74%).
const DIRECT_REPS: u64 = 48;
const DIRECT_PASSES: u32 = 40;
const DIRECT_SPP: u32 = 128;

/// `erpt` with the direct pass agrees with PT on the Cornell box to 1%
/// (4σ and 1%, 5σ < 1%; the module's tolerances, unpaired: the pass's
/// image and the chains' are not those of an `erpt` run without it).
/// Ignored for its run time (110 s wall with its control, 44 CPU-s, at
/// load ≈ 9; passed once, session 21: rel −0.26%, −0.16%, −0.19%, the
/// control rejected at +0.74% to +0.84%): `cargo test -p mcmc-render
/// --profile test --test erpt -- --ignored direct_pass --nocapture` runs
/// it with its control.
#[test]
#[ignore]
fn erpt_with_a_direct_pass_agrees_with_pt_on_the_cornell_box() {
    common::assert_agrees_to_one_percent(
        "erpt + direct pass",
        pt_reference(),
        erpt_direct_replicates(),
    );
}

/// The control: the same replicates × 1.01 must fail. Ignored with them.
#[test]
#[ignore]
fn a_one_percent_bias_is_rejected_with_a_direct_pass() {
    common::assert_one_percent_bias_is_rejected(
        "erpt + direct pass",
        pt_reference(),
        erpt_direct_replicates(),
    );
}

/// Image means of the PT replicates and of the tested integrator's.
type Replicates = (Vec<[f64; 3]>, Vec<[f64; 3]>);

/// The tilted glossy-glass box (gold glossy, glass sphere: Dirac
/// vertices in the seeds and the chains) with 128 PT replicates of 2048
/// spp (blue's SE ≈ 0.07%, as in `path_space_mlt.rs`) and `GLOSSY_REPS`
/// `erpt` replicates of `GLOSSY_PASSES` passes, shared by the agreement
/// test and its control. A pass is an unbiased image for any deposit
/// energy (module docs of `erpt`: chains start in proportion to `lum f`
/// and MH keeps it), so replicates of few passes add no start-up bias and
/// only the total number of passes sets σ.
fn glossy_glass() -> &'static Replicates {
    static REPS: OnceLock<Replicates> = OnceLock::new();
    REPS.get_or_init(|| {
        let scene = repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH);
        let pt = mc_reps(&scene, &pt_of(&scene), 2048, 128, 1000);
        let reps = (0..GLOSSY_REPS)
            .map(|k| {
                let out = erpt(&scene, GLOSSY_PASSES, 41_000 + k);
                assert_eq!(out.statistics["nonfinite_contributions"], 0);
                image_mean(&out.image)
            })
            .collect();
        (pt, reps)
    })
}

/// `erpt` replicates on the glossy-glass box: sized from session 19's
/// probe of 256 replicates (4096 passes), where `erpt`'s blue spread
/// 29.7% per pass (red 22%, green 24%). A total σ of 0.18% (5σ = 0.9%)
/// with PT's 0.07% needs 0.166% from `erpt`, i.e. (29.7 / 0.166)² ≈
/// 32 000 passes: 2048 replicates of 16 (the probe's 256 are its first).
const GLOSSY_REPS: u64 = 2048;
/// Passes per glossy-glass replicate.
const GLOSSY_PASSES: u32 = 16;

/// `erpt` agrees with PT on the glossy-glass box to 1% (4σ and 1%, 5σ <
/// 1%). Ignored for its run time (`cargo test -p mcmc-render --profile
/// test --test erpt -- --ignored on_the_glossy_glass_box --nocapture` runs
/// it with its control). **Not run at this size** (≈ 16 min of CPU: the
/// probe took 157 s of CPU, ≈ 36 s of it PT's). Session 19's probes
/// (2026-11-27, 2 cores, load 6.5–9) failed, as they had to, on the
/// resolution check: 64 replicates (1024 passes) read rel −0.77%,
/// −0.98%, −1.14% (R/G/B), σ 0.64%, 0.70%, 0.90% (66 s CPU; blue beyond
/// 1%, so the agreement check failed too); 256 replicates (4096 passes,
/// the first 64 the same) −0.46%, −0.63%, −0.82%, σ 0.35%, 0.37%, 0.47%
/// (within 4σ and 1%; 157 s CPU): 1.3–1.7σ low
/// on every channel (the channels are correlated), so a bias of ≈ −0.5%
/// is suspected, not shown. The full size passed (session 19, 17:46 UTC,
/// load ~1.9): −0.06%, −0.05%, +0.04%, σ 0.14%, 0.15%, 0.19% (5σ 0.95% on
/// blue), the control failing; 1092 s CPU, 620 s wall: the probes' low
/// reading was noise. Those runs had session 19's defaults (the lens
/// perturbation alone) and streams; since session 20 `erpt()` runs
/// Mitsuba's mixture, each chain on its own stream: not re-run (the
/// paired test below compares the two mixtures on the same seeds).
#[test]
#[ignore]
fn erpt_agrees_with_pt_on_the_glossy_glass_box() {
    let (pt, reps) = glossy_glass();
    common::assert_agrees_to_one_percent("erpt glossy-glass", pt, reps);
}

/// The control of the glossy-glass agreement: the same `erpt` replicates
/// scaled by 1.01 must fail it. Ignored with the replicates it scales.
#[test]
#[ignore]
fn a_one_percent_bias_is_rejected_on_the_glossy_glass_box() {
    let (pt, reps) = glossy_glass();
    common::assert_one_percent_bias_is_rejected("erpt glossy-glass", pt, reps);
}

/// The image mean and the means of the four quadrants (top left, top
/// right, bottom left, bottom right) of a `RES`×`RES` image.
fn regions(img: &[Rgb]) -> [[f64; 3]; 5] {
    let quadrant = |q: u32| -> Vec<bool> {
        (0..RES * RES)
            .map(|i| (i % RES >= RES / 2) as u32 + 2 * (i / RES >= RES / 2) as u32 == q)
            .collect()
    };
    let mut out = [image_mean(img); 5];
    for q in 0..4 {
        out[q as usize + 1] = common::masked_mean(img, Some(&quadrant(q)));
    }
    out
}

/// Region means ([`regions`]) of paired `erpt` replicates on the
/// glossy-glass box: with the lens perturbation alone (the mixture
/// session 19's 1% agreement with PT ran) and at the defaults (Mitsuba
/// 0.6's: lens, caustic and multi-chain perturbations, session 20).
type Paired = (Vec<[[f64; 3]; 5]>, Vec<[[f64; 3]; 5]>);

/// Replicate `i` of both mixtures runs seed `51_000 + i`: each chain
/// draws from its own stream, so both see the same seeds, seed energies
/// and chain counts, and differ by the chains' redistribution alone; the
/// paired difference is free of the seeds' noise (29.7% per pass on blue,
/// which makes the unpaired test cost ≈ 32 000 passes). `PAIRED_REPS`
/// replicates of 16 passes each.
fn paired_glossy_glass() -> &'static Paired {
    static REPS: OnceLock<Paired> = OnceLock::new();
    REPS.get_or_init(|| {
        let scene = repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH);
        let lens_only = || Erpt {
            caustic_perturbation: 0.0,
            multi_chain_perturbation: 0.0,
            ..Erpt::default()
        };
        let d = Erpt::default();
        assert_eq!(
            (
                d.lens_perturbation,
                d.caustic_perturbation,
                d.multi_chain_perturbation
            ),
            (1.0, 1.0, 1.0),
            "the defaults are Mitsuba's"
        );
        let run = |e: Erpt, k: u64| {
            let out = erpt_with(e, &scene, GLOSSY_PASSES, 51_000 + k);
            assert_eq!(out.statistics["nonfinite_contributions"], 0);
            regions(&out.image)
        };
        (0..PAIRED_REPS)
            .map(|k| (run(lens_only(), k), run(Erpt::default(), k)))
            .unzip()
    })
}

/// Paired replicates of 16 passes. Session 20 ran 256 (273 s of CPU, 2
/// cores, load 6–7): every region agreed within 4σ and 1% (largest |z|
/// 2.4: top left, green and blue −0.21%, −0.23%), and all but the bottom
/// right quadrant resolved 1% (image σ 0.02–0.03%, quadrants 0.05–0.15%),
/// which missed by a little (σ 0.21%, 0.20%, 0.22%: 5σ 1.02–1.09%), so
/// both tests failed on resolution. 384 replicates scale its 5σ to
/// 0.83–0.89%; not run at this size.
const PAIRED_REPS: u64 = 384;

/// The names of [`regions`].
const REGIONS: [&str; 5] = [
    "image",
    "top left",
    "top right",
    "bottom left",
    "bottom right",
];

/// `erpt` at its defaults (Mitsuba 0.6's mixture) agrees with `erpt` with
/// the lens perturbation alone on the same seeds, in the image mean and in
/// each quadrant's, to 1% (4σ and 1%, 5σ < 1%; σ of the paired
/// difference). With session 19's 1% agreement of the lens-only mixture
/// with PT on this scene, this puts the defaults within 1% + 1% of PT in
/// the image mean; the quadrants check the redistribution itself, which
/// the image mean cannot see (every step deposits the same luminance, so
/// both images hold the seeds' total). Ignored for its run time (≈ 410 s
/// of CPU at `PAIRED_REPS`): `cargo test -p mcmc-render --profile test
/// --test erpt -- --ignored paired --nocapture` runs it with its control.
#[test]
#[ignore]
fn erpt_defaults_agree_paired_with_the_lens_perturbation_alone() {
    let (lens, all) = paired_glossy_glass();
    for (r, name) in REGIONS.iter().enumerate() {
        let a: Vec<[f64; 3]> = lens.iter().map(|x| x[r]).collect();
        let b: Vec<[f64; 3]> = all.iter().map(|x| x[r]).collect();
        common::assert_paired_agreement_to_one_percent(&format!("erpt paired, {name}"), &a, &b);
    }
}

/// The control of the paired agreement: the defaults' replicates × 1.01
/// must fail it in every region. Ignored with the replicates it scales.
#[test]
#[ignore]
fn a_one_percent_bias_is_rejected_paired() {
    let (lens, all) = paired_glossy_glass();
    for (r, name) in REGIONS.iter().enumerate() {
        let a: Vec<[f64; 3]> = lens.iter().map(|x| x[r]).collect();
        let b: Vec<[f64; 3]> = all.iter().map(|x| x[r]).collect();
        common::assert_paired_one_percent_bias_is_rejected(&format!("erpt paired, {name}"), &a, &b);
    }
}

#[test]
fn erpt_images_are_bit_identical_across_thread_counts() {
    let scene = repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH);
    // The manifold perturbation off and on, and the direct pass on.
    for (manifold, direct) in [("0", "-1"), ("1", "-1"), ("0", "4")] {
        let bits = |threads: usize, seed: u64| -> Vec<u32> {
            let integ = registry::configure(
                None,
                Some("erpt"),
                &[
                    ("luminance_samples".into(), "1000".into()),
                    ("manifold_perturbation".into(), manifold.into()),
                    ("direct_samples".into(), direct.into()),
                ],
            )
            .expect("erpt");
            let run = RunSettings {
                spp: Some(2),
                seed,
                ..RunSettings::default()
            };
            let out = with_threads(threads, || {
                integ.render(&scene, &run, &AtomicBool::new(false), &NoObserver)
            })
            .expect("erpt runs");
            assert!(image_mean(&out.image)[1] > 0.0, "black image");
            for key in [
                "passes",
                "chains",
                "mutations",
                "acceptance_per_component",
                "deposit_energy",
            ] {
                assert!(out.statistics.contains_key(key), "{key} missing");
            }
            check_mutation_types(&out.statistics);
            assert_eq!(
                out.statistics.contains_key("direct_pass"),
                direct != "-1",
                "direct pass {direct}"
            );
            out.image
                .iter()
                .flat_map(|p| [p.r.to_bits(), p.g.to_bits(), p.b.to_bits()])
                .collect()
        };
        let one = bits(1, 42);
        let case = format!("manifold {manifold}, direct pass {direct}");
        assert!(one == bits(2, 42), "{case}: 1 vs 2 threads differ");
        assert!(one != bits(2, 43), "{case}: seed ignored");
    }
}

/// Sets the stop flag at the first snapshot (after the first pass).
struct StopAfterFirst<'a>(&'a AtomicBool);

impl Observer for StopAfterFirst<'_> {
    fn snapshot(&self, _image: &dyn Fn() -> Vec<Rgb>, _samples: u64) {
        self.0.store(true, Ordering::Relaxed);
    }
}

#[test]
fn a_stop_writes_the_partial_image() {
    let stop = AtomicBool::new(false);
    let e = Erpt {
        luminance_samples: 1000,
        ..Erpt::default()
    };
    let run = RunSettings {
        spp: Some(1000),
        seed: 3,
        ..RunSettings::default()
    };
    let out = e
        .render(cornell(), &run, &stop, &StopAfterFirst(&stop))
        .expect("erpt runs");
    assert!(out.interrupted, "not marked interrupted");
    assert_eq!(out.statistics["passes"], 1);
    assert!(image_mean(&out.image)[1] > 0.0, "no partial image");
}

#[test]
fn erpt_refuses_unbuilt_mutations_and_zero_depth() {
    for (k, v) in [
        ("max_depth", "0"),
        ("num_chains", "0"),
        ("chain_length", "0"),
        ("direct_samples", "0"),
        ("direct_samples", "-2"),
    ] {
        let err = registry::configure(None, Some("erpt"), &[(k.into(), v.into())]);
        assert!(err.is_err(), "{k} = {v} accepted");
    }
    // The direct pass has the paths of up to two segments: the chains
    // need longer ones.
    let set = |d: &str| {
        registry::configure(
            None,
            Some("erpt"),
            &[
                ("direct_samples".into(), "16".into()),
                ("max_depth".into(), d.into()),
            ],
        )
    };
    assert!(set("2").is_err(), "direct pass with max_depth 2 accepted");
    assert!(set("3").is_ok() && set("-1").is_ok());
    assert!(registry::configure(None, Some("erpt"), &[]).is_ok());
}

/// The sidecar's `mutation_types` adds up: per type, its proposals are the
/// sum of its components' in `acceptance_per_component` (the mutation and
/// its failure reasons), its accepted those of its component 0, its
/// invalid the failures; over types, the proposals are the mutations; and
/// some proposals of each type were timed.
fn check_mutation_types(stats: &serde_json::Map<String, serde_json::Value>) {
    let types = stats["mutation_types"].as_array().expect("mutation_types");
    let components = stats["acceptance_per_component"]
        .as_array()
        .expect("components");
    let count = |v: &serde_json::Value, k: &str| v[k].as_u64().expect(k);
    let mut total = 0;
    for t in types {
        let name = t["name"].as_str().expect("name");
        let own: Vec<_> = components
            .iter()
            .filter(|c| {
                let n = c["name"].as_str().expect("name");
                n == name || n.starts_with(&format!("{name}: "))
            })
            .collect();
        let proposed: u64 = own.iter().map(|c| count(c, "proposed")).sum();
        assert_eq!(count(t, "proposals"), proposed, "{name}");
        assert_eq!(count(t, "accepted"), count(own[0], "accepted"), "{name}");
        assert_eq!(
            count(t, "invalid"),
            proposed - count(own[0], "proposed"),
            "{name}"
        );
        assert!(count(t, "timed_proposals") > 0, "{name}: nothing timed");
        assert!(t["proposals_per_second"].as_f64().expect("rate") > 0.0);
        total += proposed;
    }
    assert_eq!(total, stats["mutations"].as_u64().expect("mutations"));
}
