//! Path-space MLT (`mlt`, Veach's bidirectional mutation) agrees with path
//! tracing on the repo's tilted Cornell box to 1% of the image mean, per
//! channel; its images are bit-identical for any thread count; the
//! integrator refuses mutations that do not exist yet. Under a sky
//! (emitters at infinity) `mlt` and `fused` agree with path tracing.
//!
//! # Tolerances
//!
//! As `tests/agree_mlt.rs` (same scene, same PT reference, same check):
//! `K` replicates with distinct fixed seeds, each with its own bootstrap and
//! chains; the standard error of the difference of the means is `σ`, a
//! channel passes within 4σ and 1%, and the budgets give 5σ < 1%. No
//! path-space mutation is an independent proposal, so `b` rests on the
//! bootstrap alone: its relative spread between seeds sets the budget.
//! The control scales the `mlt` replicates by 1.01 and must fail.

mod common;

use common::{
    Budget, MeanAgreement, Mlt, image_mean, mc_reps, mean_se, mlt_reps, pt_of, repo_scene_tilted,
    sky_scene,
};
use mcmc_core::runner::with_threads;
use mcmc_render::integrators::RunSettings;
use mcmc_render::integrators::mlt::Mlt as MltSettings;
use mcmc_render::integrators::registry::{self, IntegratorSettings};
use mcmc_render::markov::{ChainSettings, Normalization};
use mcmc_render::observer::NoObserver;
use mcmc_render::path_space::{PathFamily, PathMutations};
use mcmc_render::scene::Scene;
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

const RES: u32 = 16;
const DEPTH: u32 = 5;

/// The tilted box.
fn cornell() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-box.xml", RES, DEPTH))
}

/// PT replicates: 48 × 256 spp (as `agree_mlt.rs`: SE ≈ 0.1%).
fn pt_reference() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| mc_reps(cornell(), &pt_of(cornell()), 256, 48, 1000))
}

/// `mlt` replicates: 32 runs of 300 000 bootstrap candidates, 512 chains,
/// 1024 mutations per pixel. Measured at 100 000 candidates and 256
/// mutations per pixel: `b` spreads 1.2% between seeds (≈ 3.8/√candidates)
/// and the channels 1.4% (the chains' split adds ≈ 1.2% at 65 000
/// mutations), so here σ ≈ √(0.69² + 0.6²)/√32 % ≈ 0.16% per channel and
/// 5σ ≈ 0.8% < 1%.
fn mlt_replicates() -> &'static [[f64; 3]] {
    static MLT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    let budget = Budget {
        bootstrap: 300_000,
        chains: 512,
        mpp: 1024,
    };
    MLT.get_or_init(|| mlt_reps(cornell(), Mlt::PathSpace, budget, 32, 9000))
}

#[test]
fn mlt_agrees_with_pt_on_the_cornell_box() {
    common::assert_agrees_to_one_percent("mlt", pt_reference(), mlt_replicates());
}

#[test]
fn a_one_percent_bias_is_rejected() {
    common::assert_one_percent_bias_is_rejected("mlt", pt_reference(), mlt_replicates());
}

#[test]
fn mlt_images_are_bit_identical_across_thread_counts() {
    let scene = cornell();
    let family = PathFamily::new(scene, Some(DEPTH as usize));
    for fixed_length in [false, true] {
        let bits = |threads: usize, seed: u64| -> Vec<u32> {
            let settings = ChainSettings {
                mutation: PathMutations {
                    fixed_length,
                    ..PathMutations::default()
                },
                bootstrap: 2000,
                chains: 64,
                mutations_per_pixel: Some(8),
                seed,
                normalization: Normalization::Running,
                ..ChainSettings::default()
            };
            let stop = AtomicBool::new(false);
            let r = with_threads(threads, || {
                mcmc_render::markov::run(scene, &family, &settings, &stop, &NoObserver)
            })
            .expect("mlt runs");
            assert!(image_mean(&r.image())[1] > 0.0, "black image");
            r.image()
                .iter()
                .flat_map(|p| [p.r.to_bits(), p.g.to_bits(), p.b.to_bits()])
                .collect()
        };
        let one = bits(1, 42);
        assert!(
            one == bits(2, 42),
            "fixed {fixed_length}: 1 vs 2 threads differ"
        );
        assert!(
            one == bits(3, 42),
            "fixed {fixed_length}: 1 vs 3 threads differ"
        );
        assert!(one != bits(2, 43), "fixed {fixed_length}: seed ignored");
    }
}

#[test]
fn every_mutation_is_accepted_and_bad_weights_are_refused_with_one_line() {
    // Every mutation of the issue is built (tests/path_space_perturbations.rs,
    // tests/path_space_manifold.rs): a weight of 1 is accepted, a negative
    // or non-finite one refused with one line naming it.
    let names = [
        "lens_perturbation",
        "caustic_perturbation",
        "multi_chain_perturbation",
        "lens_subpath_mutation",
        "manifold_perturbation",
        "independent_mutation",
    ];
    assert!(registry::configure(None, Some("mlt"), &[]).is_ok());
    for name in names {
        assert!(
            registry::configure(None, Some("mlt"), &[(name.into(), "1".into())]).is_ok(),
            "{name} = 1 refused"
        );
        for bad in ["-1", "inf"] {
            let err = registry::configure(None, Some("mlt"), &[(name.into(), bad.into())])
                .err()
                .unwrap_or_else(|| panic!("{name} = {bad} accepted"));
            let text = err.to_string();
            assert!(
                text.contains(name) && !text.contains('\n'),
                "{name} = {bad}: {text}"
            );
        }
    }
}

/// Image means of the PT replicates and of the tested integrator's.
type Replicates = (Vec<[f64; 3]>, Vec<[f64; 3]>);

/// The tilted glossy-glass box (gold glossy, glass sphere: Dirac vertices
/// in the paths) with its PT replicates and `mlt`'s, shared by the
/// agreement test and its control below.
///
/// Sizing (session 19). Measured on 2026-11-25 with 128 PT replicates at
/// 256 spp and 96 `mlt` replicates of the budget below: σ of the
/// difference 0.22%, 0.23%, 0.31% (R/G/B), 5σ = 1.55% on blue. PT's own
/// share follows from `path_space_perturbations`' table (σ_mlt/σ_pt =
/// 1.7 on this scene, σ = 0.32% on blue at 96 × 512 spp): PT's blue
/// spreads 2.25% per replicate of 256 spp, so its SE was 0.20% and
/// `mlt`'s √(0.31² − 0.20²) = 0.24% (2.3% per replicate). Replicates
/// scale as σ²: PT at 128 × 2048 spp gives 0.07% (its samples are ~10×
/// cheaper than a replicate's mutations), and `mlt` needs
/// √(0.18² − 0.07²) = 0.166% for a total σ of 0.18% (5σ = 0.9%, a 10%
/// margin for the noise of σ's estimate, ≈ 1/√(2K) = 5%): 96 × (0.24 /
/// 0.166)² ≈ 200, rounded up to 224 (expected σ 0.17%). The replicate's
/// budget is session 13's (300 000 candidates, 512 chains, 1024
/// mutations per pixel): a cheaper one with more replicates would be
/// cheaper only if its start-up bias did not grow, which this session
/// had no time to measure.
fn glossy_glass() -> &'static Replicates {
    static REPS: OnceLock<Replicates> = OnceLock::new();
    REPS.get_or_init(|| {
        let scene = repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH);
        let pt = mc_reps(&scene, &pt_of(&scene), 2048, 128, 1000);
        let budget = Budget {
            bootstrap: 300_000,
            chains: 512,
            mpp: 1024,
        };
        let mlt = mlt_reps(&scene, Mlt::PathSpace, budget, 224, 9000);
        (pt, mlt)
    })
}

/// `mlt` agrees with PT on the glossy-glass box to 1% (4σ and 1%, and 5σ
/// < 1%; sizing at `glossy_glass`). Ignored for its run time
/// (`cargo test -p mcmc-render --profile test --test path_space_mlt --
/// --ignored on_the_glossy_glass_box --nocapture` runs it with its
/// control). Passed once (session 19, 2026-11-27, 2 cores, load 1.7):
/// rel +0.14%, +0.09%, +0.08% (R/G/B), σ of the difference 0.13%, 0.13%,
/// 0.19% (PT 0.05/0.05/0.07%, `mlt` 0.12/0.12/0.17%), so 5σ = 0.94% on
/// blue (a 6% margin: `mlt`'s blue spreads 2.6% per replicate, not the
/// 2.3% assumed); the ×1.01 control fails on every channel (5.7–8.9σ).
/// Both tests together: 128 s wall, 198 s CPU (`/usr/bin/time -v`).
/// On 2026-11-25, at 96 replicates and 1.5%: rel +0.14%, +0.20%, +0.12%.
#[test]
#[ignore]
fn mlt_agrees_with_pt_on_the_glossy_glass_box() {
    let (pt, mlt) = glossy_glass();
    common::assert_agrees_to_one_percent("mlt glossy-glass", pt, mlt);
}

/// The control of the glossy-glass agreement: the same `mlt` replicates
/// scaled by 1.01 must fail it. Ignored with the replicates it scales.
#[test]
#[ignore]
fn a_one_percent_bias_is_rejected_on_the_glossy_glass_box() {
    let (pt, mlt) = glossy_glass();
    common::assert_one_percent_bias_is_rejected("mlt glossy-glass", pt, mlt);
}

#[test]
fn mlt_with_a_direct_pass_agrees_with_pt_on_the_cornell_box() {
    // The integrator as the CLI runs it, with Mitsuba's direct-lighting
    // pass: paths of one and two segments by PT at 128 spp, the chains on
    // three segments or more (300 000 candidates, 512 chains, 512
    // mutations per pixel), 32 replicates. Without the pass's image, or
    // with the chains still sampling short paths, the mean would be off by
    // the direct light (most of the image). Measured with 32 replicates
    // and 1024 mutations per pixel: σ 0.13%, 0.12%, 0.14% per channel.
    // With the lens perturbation on by default (session 10), 24 replicates
    // of 512 gave σ 0.21% in red (−0.11%, +0.17%, +0.17%): 5σ was 1.03%,
    // hence 32 (σ ≈ 0.18%). The mixture is the one this was sized for,
    // bidirectional and lens (the defaults up to session 20): with
    // Mitsuba's (caustic and multi-chain on, the defaults since), the 32
    // replicates read −0.15%, +0.13%, +0.03% but σ 0.23% in red (5σ
    // 1.17%, against ≈ 0.18% with bidirectional and lens): on this box,
    // which has no Dirac vertex, every multi-chain proposal fails its
    // pattern. The default mixture's 1% agreement is
    // `mlt_with_all_perturbations_agrees_with_pt_on_the_glass_box`.
    let scene = cornell();
    let stop = AtomicBool::new(false);
    let reps: Vec<[f64; 3]> = (0..32)
        .map(|k| {
            let mut mlt = MltSettings::default();
            mlt.depth.max_depth = DEPTH as i64;
            mlt.direct_samples = 128;
            mlt.caustic_perturbation = 0.0;
            mlt.multi_chain_perturbation = 0.0;
            mlt.chain.bootstrap = 300_000;
            mlt.chain.chains = 512;
            mlt.chain.mutations_per_pixel = Some(512);
            let run = RunSettings {
                seed: 12_000 + k,
                ..RunSettings::default()
            };
            let out = mlt
                .render(scene, &run, &stop, &NoObserver)
                .expect("mlt runs");
            assert!(out.statistics.contains_key("direct_pass"));
            image_mean(&out.image)
        })
        .collect();
    let a = MeanAgreement::new(pt_reference(), &reps);
    eprintln!("mlt + direct pass: rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "mlt disagrees with PT: {a:?}"
    );
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
}

/// `k` runs of `mlt` with the independent proposal (weight 0.3 against the
/// bidirectional mutation's 1: p = 0.23, ≈ 120 000 fresh paths per run
/// besides the 100 000 candidates, 512 chains, 2048 mutations per pixel):
/// each run's running/bootstrap standard-error ratio and image mean.
fn independent_proposal_runs(k: u64) -> (Vec<f64>, Vec<[f64; 3]>) {
    let scene = cornell();
    let family = PathFamily::new(scene, Some(DEPTH as usize));
    let stop = AtomicBool::new(false);
    (0..k)
        .map(|k| {
            let settings = ChainSettings {
                mutation: PathMutations {
                    independent: 0.3,
                    ..PathMutations::default()
                },
                bootstrap: 100_000,
                chains: 512,
                mutations_per_pixel: Some(2048),
                seed: 15_000 + k,
                normalization: Normalization::Running,
                ..ChainSettings::default()
            };
            let r = mcmc_render::markov::run(scene, &family, &settings, &stop, &NoObserver)
                .expect("mlt runs");
            assert_eq!(r.chain_stats.invalid_density, 0, "NaN/inf paths");
            (r.running_b.1 / r.bootstrap_b.1, image_mean(&r.image()))
        })
        .unzip()
}

/// The running normalisation's standard error must fall below the
/// bootstrap's: √(100k/220k) ≈ 0.67 of it expected, asserted < 0.8. The
/// ratio is a ratio of sample counts more than a random quantity, so four
/// runs tell 0.67 from 1; the image's agreement with PT under the
/// independent proposal needs 32 and is the ignored test below (its
/// exactness is checked by default in `path_space_perturbations`'
/// `independent_proposal_keeps_exact_start_states_exact`). Session 14: the
/// 32-run version took 165 s of the default suite.
#[test]
fn independent_proposals_refine_the_normalisation() {
    let (ratios, _) = independent_proposal_runs(4);
    check_refined_normalisation(&ratios);
}

fn check_refined_normalisation(ratios: &[f64]) {
    eprintln!("running/bootstrap standard error per run: {ratios:.3?}");
    let mean_ratio = ratios.iter().sum::<f64>() / ratios.len() as f64;
    assert!(
        mean_ratio < 0.8,
        "the running estimate did not improve: {mean_ratio}"
    );
}

/// The same runs agree with PT to 1% (32 replicates; 4σ and 1%, 5σ < 1%).
/// About 3 minutes on the loaded machine: `cargo test -p mcmc-render
/// --test path_space_mlt -- --ignored independent`.
#[test]
#[ignore]
fn independent_proposals_agree_with_pt_on_the_cornell_box() {
    let (ratios, reps) = independent_proposal_runs(32);
    check_refined_normalisation(&ratios);
    let a = MeanAgreement::new(pt_reference(), &reps);
    eprintln!("mlt + independent: rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "mlt disagrees with PT: {a:?}"
    );
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
}

/// `mlt` with the lens perturbation (weight 1, beside the bidirectional
/// mutation's 1; the mixture that won on door-ajar at equal time,
/// `docs/path-space.md`) agrees with PT on the tilted Cornell box to 1%:
/// the method and budget of `mlt_agrees_with_pt_on_the_cornell_box` (32
/// replicates of 300 000 candidates, 512 chains, 1024 mutations per
/// pixel; 4σ and 1%, 5σ < 1%), and the 1% control. Ignored for its run
/// time (≈ 2 min on the loaded machine).
#[test]
#[ignore]
fn mlt_with_the_lens_perturbation_agrees_with_pt_on_the_cornell_box() {
    let scene = cornell();
    let family = PathFamily::new(scene, Some(DEPTH as usize));
    let stop = AtomicBool::new(false);
    let reps: Vec<[f64; 3]> = (0..32)
        .map(|k| {
            let settings = ChainSettings {
                mutation: PathMutations {
                    lens_perturbation: 1.0,
                    ..PathMutations::default()
                },
                bootstrap: 300_000,
                chains: 512,
                mutations_per_pixel: Some(1024),
                seed: 17_000 + k,
                normalization: Normalization::Running,
                ..ChainSettings::default()
            };
            let r = mcmc_render::markov::run(scene, &family, &settings, &stop, &NoObserver)
                .expect("mlt runs");
            assert_eq!(r.chain_stats.invalid_density, 0, "NaN/inf paths");
            image_mean(&r.image())
        })
        .collect();
    let a = MeanAgreement::new(pt_reference(), &reps);
    eprintln!("mlt + lens: rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "mlt + lens disagrees with PT: {a:?}"
    );
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
    let biased: Vec<[f64; 3]> = reps.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let b = MeanAgreement::new(pt_reference(), &biased);
    assert!(!b.failures(4.0, 0.01).is_empty(), "a 1% bias passed: {b:?}");
}

/// Sets the stop flag (Ctrl-C's) at the chains' first snapshot.
struct StopAtFirstSnapshot<'a>(&'a AtomicBool);

impl mcmc_render::observer::Observer for StopAtFirstSnapshot<'_> {
    fn snapshot(&self, _image: &dyn Fn() -> Vec<mcmc_render::color::Rgb>, _samples: u64) {
        self.0.store(true, std::sync::atomic::Ordering::Relaxed);
    }
}

/// A stop (Ctrl-C's flag, set at the first snapshot) ends `mlt` with the
/// partial image, marked interrupted and normalised: its mean luminance
/// is the bootstrap's `b` (plus the specular-chain pass) whatever share
/// of the mutations ran, so it must be within 5% of PT's (100 000
/// candidates: `b` spreads 1.2% between seeds, see `mlt_replicates`, so
/// 5% is ≈ 4σ; luminance, because the split between the channels depends
/// on where the few chains are after so few mutations). Control: fewer than half of the
/// requested mutations may have run, so an image scaled by the share
/// done (a partial image normalised by the full budget) would be off by
/// more than 50%.
#[test]
fn a_stop_writes_the_normalised_partial_image() {
    let stop = AtomicBool::new(false);
    let mut mlt = MltSettings::default();
    mlt.depth.max_depth = DEPTH as i64;
    mlt.chain.bootstrap = 100_000;
    mlt.chain.chains = 64;
    mlt.chain.mutations_per_pixel = Some(4096);
    let requested = 4096 * (RES * RES) as u64;
    let run = RunSettings {
        seed: 5,
        snapshot_every: std::time::Duration::ZERO,
        ..RunSettings::default()
    };
    let out = mlt
        .render(cornell(), &run, &stop, &StopAtFirstSnapshot(&stop))
        .expect("mlt runs");
    assert!(out.interrupted, "not marked interrupted");
    let done = out.statistics["mutations"].as_u64().expect("mutations");
    eprintln!("{done} of {requested} mutations");
    assert!(done > 0 && done < requested / 2, "{done} of {requested}");
    let (pt, _) = mean_se(pt_reference());
    let mean = image_mean(&out.image);
    let lum = |m: [f64; 3]| 0.2126 * m[0] + 0.7152 * m[1] + 0.0722 * m[2];
    let rel = lum(mean) / lum(pt) - 1.0;
    eprintln!("partial image's mean luminance against PT's: {rel:+.4}");
    assert!(rel.abs() < 0.05, "the partial image is off by {rel}");
}

// ---------------------------------------------------------------------
// Under a sky (issue 13: emitters at infinity in path space).
//
// `common::sky_scene` at 16×16, paths of up to 4 segments: a constant sky
// (seen directly above the horizon: the specular-chain pass's `L E`) and
// a directional sun over a diffuse floor, a diffuse and a rough metal
// sphere. Every light path starts at infinity, so the image tests the
// whole of it: `x_0` in solid angle, the disk walk, the escaped camera
// walk as `x_0`, the reconnections of the lens perturbation to `ω`. The
// metal sphere is rough for PT's sake: with a mirror, PT cannot sample
// the sun's reflection onto the floor (see `sky_scene`), and its image is
// 0.27% low in red. The mirror variant (Dirac vertices beside `x_0`, the
// specular-chain pass through the mirror) is checked against BDPT in the
// ignored test.
//
// Tolerances: each replicate is an independent run (its own seed,
// start-up and chains), so the K replicate means of each side are i.i.d.
// and the standard error of the difference of the two means is
// σ = √(s²_pt/K_pt + s²/K). (mean difference)/σ is then approximately
// Student-t with at least min(K_pt, K) − 1 degrees of freedom (Welch's
// dof lie between that and K_pt + K − 2), so a channel passes within
// t·σ, t the two-sided 1e-3 quantile at that dof, and within the bound;
// the budget must resolve the bound (t·σ < bound), so that a bias of the
// bound fails with probability ≥ 1/2. The control scales the replicates
// by 1 + bound and must fail.
// ---------------------------------------------------------------------

/// The sky scene, 16×16, depth 4.
fn sky() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let scene = sky_scene(RES, 4, false);
        assert!(scene.lights.has_emitter_at_infinity());
        scene
    })
}

/// PT replicates under the sky: `k` × `spp`.
fn sky_pt(spp: u32, k: u64) -> Vec<[f64; 3]> {
    mc_reps(sky(), &pt_of(sky()), spp, k, 3000)
}

/// The 24 PT replicates of 128 spp under the sky that the default-suite
/// sky tests share (computed once per test binary).
fn sky_pt_128() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| sky_pt(128, 24))
}

/// The sky scene with the mirror sphere, 16×16, depth 4.
fn sky_mirror() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| sky_scene(RES, 4, true))
}

/// Image means of `k` runs of registered integrator `name` under the sky
/// as the command line runs it, with `sets` (seeds `seed0..`).
fn sky_reps(
    scene: &Scene,
    name: &str,
    sets: &[(&str, &str)],
    spp: Option<u32>,
    k: u64,
    seed0: u64,
) -> Vec<[f64; 3]> {
    let sets: Vec<(String, String)> = sets
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    let stop = AtomicBool::new(false);
    (0..k)
        .map(|i| {
            let integ = registry::configure(scene.integrator_element.as_ref(), Some(name), &sets)
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            let run = RunSettings {
                spp,
                seed: seed0 + i,
                ..RunSettings::default()
            };
            let out = integ
                .render(scene, &run, &stop, &NoObserver)
                .unwrap_or_else(|e| panic!("{name} under a sky: {e}"));
            image_mean(&out.image)
        })
        .collect()
}

/// The two-sided 1e-3 Student-t quantile for the smaller side's `K − 1`
/// degrees of freedom (see the tolerances above).
fn t_quantile(pt: &[[f64; 3]], test: &[[f64; 3]]) -> f64 {
    use statrs::distribution::{ContinuousCDF, StudentsT};
    let dof = (pt.len().min(test.len()) - 1) as f64;
    StudentsT::new(0.0, 1.0, dof)
        .expect("dof > 0")
        .inverse_cdf(1.0 - 0.0005)
}

/// The sky check of `name`'s replicates against the reference's to `bound`: agree
/// within t·σ and the bound, resolve the bound, and the control (the
/// replicates scaled by `1 + bound`) fails.
fn check_sky(name: &str, pt: &[[f64; 3]], reps: &[[f64; 3]], bound: f64) {
    let t = t_quantile(pt, reps);
    let a = MeanAgreement::new(pt, reps);
    eprintln!("{name} under a sky: t = {t:.2}, rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.failures(t, bound).is_empty(),
        "{name} disagrees with PT under a sky: {a:?}"
    );
    assert!(
        a.resolves(t, bound),
        "{name}: noise too large for {bound}: {a:?}"
    );
    let biased: Vec<[f64; 3]> = reps.iter().map(|m| m.map(|v| v * (1.0 + bound))).collect();
    let b = MeanAgreement::new(pt, &biased);
    assert!(
        !b.failures(t, bound).is_empty(),
        "{name}: a bias of {bound} passed: {b:?}"
    );
}

/// `mlt` as the CLI runs it (its defaults: bidirectional mutation and lens
/// perturbation, the specular-chain pass, which takes the sky seen
/// directly and in the mirror) under the sky, 16 replicates of 20 000
/// candidates, 128 chains, 256 mutations per pixel, against 24 PT
/// replicates of 128 spp, to 3% (t₁₅ = 4.07; see the tolerances above).
#[test]
fn mlt_agrees_with_pt_under_a_sky() {
    let pt = sky_pt_128();
    let sets = [
        ("bootstrap", "20000"),
        ("chains", "128"),
        ("mutations_per_pixel", "256"),
    ];
    let mlt = sky_reps(sky(), "mlt", &sets, None, 16, 21_000);
    check_sky("mlt", pt, &mlt, 0.03);
}

/// `fused` (issue 18 × 13: its inverse path sampler maps paths from
/// infinity back to primary samples) as the CLI runs it (`auto`
/// path-space probability with its pilot, bidirectional mutation and lens
/// perturbation) under the sky, 16 replicates of 20 000 candidates, 128
/// chains, 128 mutations per pixel, against the same 24 PT replicates, to
/// 3%: as for `mlt` above, each replicate is an independent run, the
/// difference of the two means has standard error σ = √(s²_pt/24 +
/// s²/16), and a channel passes within t·σ (t₁₅ = 4.07, two-sided 1e-3)
/// and 3%; `check_sky` asserts that t·σ < 3% (a 3% bias then fails with
/// probability ≥ ½) and that the replicates scaled by 1.03 (the control)
/// fail. Measured (test profile, 2 cores, load 4.5): t·σ = 1.0–1.3% of
/// the mean per channel (the spread is the start-up's: 256 mutations per
/// pixel gave 1.0–1.2%), 2.3 s with the PT replicates it shares with the
/// `mlt` test above.
#[test]
fn fused_agrees_with_pt_under_a_sky() {
    let pt = sky_pt_128();
    let sets = [
        ("bootstrap", "20000"),
        ("chains", "128"),
        ("mutations_per_pixel", "128"),
    ];
    let fused = sky_reps(sky(), "fused", &sets, None, 16, 26_000);
    check_sky("fused", pt, &fused, 0.03);
}

/// `mlt`, `mept` and `erpt` under the sky to 1% (method above; 48 PT
/// replicates of 1024 spp, 32 of each integrator), and `mlt` on the mirror
/// variant against 48 BDPT replicates of 256 spp. Ignored for its run
/// time: `cargo test -p mcmc-render --test path_space_mlt -- --ignored
/// under_a_sky`.
#[test]
#[ignore]
fn mlt_mept_and_erpt_agree_with_pt_under_a_sky_to_one_percent() {
    let pt = sky_pt(1024, 48);
    let mlt = sky_reps(
        sky(),
        "mlt",
        &[
            ("bootstrap", "200000"),
            ("chains", "512"),
            ("mutations_per_pixel", "2048"),
        ],
        None,
        32,
        22_000,
    );
    check_sky("mlt", &pt, &mlt, 0.01);
    let mept = sky_reps(
        sky(),
        "mept",
        &[
            ("bootstrap", "50000"),
            ("chains", "512"),
            ("mutations_per_pixel", "2048"),
        ],
        None,
        32,
        23_000,
    );
    check_sky("mept", &pt, &mept, 0.01);
    let erpt = sky_reps(
        sky(),
        "erpt",
        &[("luminance_samples", "4000")],
        Some(16),
        32,
        24_000,
    );
    check_sky("erpt", &pt, &erpt, 0.01);
    let bdpt = mc_reps(sky_mirror(), &common::bdpt_of(sky_mirror()), 256, 48, 4000);
    let mirror = sky_reps(
        sky_mirror(),
        "mlt",
        &[
            ("bootstrap", "200000"),
            ("chains", "512"),
            ("mutations_per_pixel", "2048"),
        ],
        None,
        32,
        25_000,
    );
    check_sky("mlt, mirror sphere, against BDPT", &bdpt, &mirror, 0.01);
}
