//! `mept` (path-space MLT with the manifold perturbation) agrees with path
//! tracing to 1% of the image mean per channel on the repo's tilted
//! Cornell box; its images are bit-identical for any thread count; the
//! registered name is `mlt` with `manifold_perturbation` = 1.
//!
//! # Tolerances
//!
//! As `tests/path_space_mlt.rs` (same scene, same PT reference, same
//! check): `K` replicates with distinct fixed seeds, each with its own
//! bootstrap and chains; `σ` is the standard error of the difference of
//! the means (K ≥ 30 on both sides, so normal quantiles apply); a channel
//! passes within 4σ and 1%, and the budget must give 5σ < 1%
//! (`MeanAgreement::resolves`). The control scales the replicates by 1.01
//! and must fail. The glossy/glass box (Dirac chains through the glass
//! sphere, where the walk and the generalised geometry term matter) is an
//! ignored test of minutes.

mod common;

use common::{MeanAgreement, image_mean, mc_reps, pt_of, repo_scene_tilted};
use mcmc_core::runner::with_threads;
use mcmc_render::integrators::RunSettings;
use mcmc_render::integrators::mept::Mept;
use mcmc_render::integrators::registry;
use mcmc_render::markov::{ChainSettings, Normalization};
use mcmc_render::observer::NoObserver;
use mcmc_render::path_space::{PathFamily, PathMutations};
use mcmc_render::scene::Scene;
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

const RES: u32 = 16;
const DEPTH: u32 = 5;

fn cornell() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-box.xml", RES, DEPTH))
}

/// PT replicates: 48 × 256 spp (as `path_space_mlt.rs`).
fn pt_reference() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| mc_reps(cornell(), &pt_of(cornell()), 256, 48, 1000))
}

/// The `mept` mixture: the bidirectional mutation and the manifold
/// perturbation, weight 1 each, and the independent proposal at 0.3
/// (what `mept`'s defaults select).
fn mept_mutations() -> PathMutations {
    Mept::default().mlt.mutations()
}

/// Image means of `k` runs of the `mept` chains (running normalisation).
fn mept_reps(
    scene: &Scene,
    bootstrap: usize,
    chains: usize,
    mpp: u64,
    k: u64,
    seed0: u64,
) -> Vec<[f64; 3]> {
    let max = scene.integrator.max_depth;
    let family = PathFamily::new(scene, (max != u32::MAX).then_some(max as usize));
    let stop = AtomicBool::new(false);
    (0..k)
        .map(|s| {
            let settings = ChainSettings {
                mutation: mept_mutations(),
                bootstrap,
                chains,
                mutations_per_pixel: Some(mpp),
                seed: seed0 + s,
                normalization: Normalization::Running,
                ..ChainSettings::default()
            };
            let r = mcmc_render::markov::run(scene, &family, &settings, &stop, &NoObserver)
                .expect("mept runs");
            assert_eq!(r.chain_stats.invalid_density, 0, "NaN/inf paths");
            image_mean(&r.image())
        })
        .collect()
}

/// 48 replicates of 300 000 candidates, 512 chains, 1024 mutations per
/// pixel (the `mlt` test's budget: `b`'s spread between seeds dominates).
fn mept_replicates() -> &'static [[f64; 3]] {
    static MEPT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    MEPT.get_or_init(|| mept_reps(cornell(), 300_000, 512, 1024, 48, 21_000))
}

#[test]
fn mept_is_mlt_with_the_manifold_perturbation_on() {
    let m = mept_mutations();
    assert_eq!(m.manifold_perturbation, 1.0);
    assert_eq!(m.independent, 0.3);
    assert_eq!(m.lens_perturbation, 0.0);
    assert_eq!(Mept::default().mlt.chain.bootstrap, 1_000_000);
    assert_eq!(
        PathMutations {
            manifold_perturbation: 0.0,
            independent: 0.0,
            lens_perturbation: 1.0,
            ..m
        },
        mcmc_render::integrators::mlt::Mlt::default().mutations()
    );
    let integ = registry::configure(None, Some("mept"), &[("max_depth".into(), "4".into())])
        .expect("mept is registered");
    assert_eq!(integ.name(), "mept");
    let json = integ.settings_json();
    assert_eq!(json["manifold_perturbation"], 1.0);
    assert_eq!(json["independent_mutation"], 0.3);
    assert!(
        registry::configure(
            None,
            Some("mept"),
            &[("manifold_perturbation".into(), "-1".into())]
        )
        .is_err()
    );
}

#[test]
fn mept_agrees_with_pt_on_the_cornell_box() {
    let a = MeanAgreement::new(pt_reference(), mept_replicates());
    eprintln!("mept: rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "mept disagrees with PT: {a:?}"
    );
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
}

#[test]
fn a_one_percent_bias_is_rejected() {
    let biased: Vec<[f64; 3]> = mept_replicates()
        .iter()
        .map(|m| m.map(|v| v * 1.01))
        .collect();
    let a = MeanAgreement::new(pt_reference(), &biased);
    eprintln!("mept x1.01: rel {:?}\n  {a:?}", a.rel());
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
    assert!(!a.failures(4.0, 0.01).is_empty(), "a 1% bias passed: {a:?}");
}

#[test]
fn mept_images_are_bit_identical_across_thread_counts() {
    let scene = repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH);
    let bits = |threads: usize, seed: u64| -> Vec<u32> {
        let integ = registry::configure(
            None,
            Some("mept"),
            &[
                ("bootstrap".into(), "2000".into()),
                ("chains".into(), "64".into()),
                ("mutations_per_pixel".into(), "8".into()),
            ],
        )
        .expect("mept");
        let run = RunSettings {
            seed,
            ..RunSettings::default()
        };
        let out = with_threads(threads, || {
            integ.render(&scene, &run, &AtomicBool::new(false), &NoObserver)
        })
        .expect("mept runs");
        assert!(image_mean(&out.image)[1] > 0.0, "black image");
        let stats = serde_json::to_string(&out.statistics).unwrap();
        assert!(stats.contains("manifold perturbation"), "{stats}");
        out.image
            .iter()
            .flat_map(|p| [p.r.to_bits(), p.g.to_bits(), p.b.to_bits()])
            .collect()
    };
    let one = bits(1, 42);
    assert!(one == bits(2, 42), "1 vs 2 threads differ");
    assert!(one != bits(2, 43), "seed ignored");
}

/// The glossy-glass box (gold glossy, glass sphere: caustics and paths
/// seen through the sphere, where the manifold walk and the generalised
/// geometry term enter the ratio). Ignored: minutes
/// (`cargo test -p mcmc-render --test path_space_mept -- --ignored`).
/// Run once (2026-11-25, 260 s on the loaded machine): rel −0.16%,
/// −0.18%, −0.16% (R/G/B) with σ of the difference 0.23%, 0.24%, 0.35%:
/// within 1σ, but 5σ on blue is 1.7% > 1.5%, so the resolution assertion
/// fails (as `mlt`'s own glossy-glass test would at this budget: blue is
/// the noisiest channel for both); it needs about twice the replicates.
#[test]
#[ignore]
fn mept_agrees_with_pt_on_the_glossy_glass_box() {
    let scene = repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH);
    let pt = mc_reps(&scene, &pt_of(&scene), 256, 128, 1000);
    let reps = mept_reps(&scene, 300_000, 512, 1024, 96, 23_000);
    let a = MeanAgreement::new(&pt, &reps);
    eprintln!("mept glossy-glass: rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.failures(4.0, 0.015).is_empty(),
        "mept disagrees with PT: {a:?}"
    );
    assert!(a.resolves(5.0, 0.015), "noise too large for 1.5%: {a:?}");
}
