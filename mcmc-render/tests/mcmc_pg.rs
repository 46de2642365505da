//! The `mcmc-pg` integrator (PSSMLT over the SD-tree guided tracer).
//!
//! - The pre-trained variant agrees with `pt` on the tilted Cornell box to
//!   1% of the image mean per channel (replicate means, Student's t; the
//!   derivation is at [`check`]); the same replicates scaled by 1.01 must
//!   fail. Ignored (longer): the online variant on the same box, both
//!   variants on the glossy-glass box (with their ×1.01 controls).
//! - One seed gives the same image, tree and statistics on 1 and 2 threads
//!   (both variants), and the statistics hold the per-iteration
//!   acceptance.
//! - Bad settings are one line naming the parameter.
//! - The order-free record sums of the online variant match the ordered
//!   merge and do not depend on order or split.

mod common;

use common::{
    MeanAgreement, image_mean, mc_reps, pt_of, registry_image_bits, repo_scene, repo_scene_tilted,
};
use mcmc_core::runner::with_threads;
use mcmc_render::integrators::guided::GuidedSettings;
use mcmc_render::integrators::mcmc_pg::{McmcPg, TrainingMode};
use mcmc_render::integrators::registry::{self, IntegratorSettings};
use mcmc_render::integrators::{DepthParams, Rendered, RunSettings};
use mcmc_render::markov::ChainParams;
use mcmc_render::observer::NoObserver;
use mcmc_render::scene::Scene;
use statrs::distribution::{ContinuousCDF, StudentsT};
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

const RES: u32 = 16;
const DEPTH: u32 = 5;
/// Replicates of the pre-trained agreement test.
const REPS: u64 = 24;

/// `mcmc-pg` with `training`, the scene's depth, next-event estimation
/// on (see [`budget`]) and a test budget.
fn settings(scene: &Scene, training: TrainingMode, chain: ChainParams) -> McmcPg {
    McmcPg {
        training,
        guiding: GuidedSettings {
            nee: true,
            depth: DepthParams {
                max_depth: i64::from(scene.integrator.max_depth),
                rr_depth: scene.integrator.rr_depth,
            },
            ..GuidedSettings::default()
        },
        chain,
        ..McmcPg::default()
    }
}

/// The agreement budget: 20 000 bootstrap candidates, 256 chains, 1024
/// mutations per pixel in all (pre-trained: 128 spp of training, 896
/// mutations per pixel of MCMC, ≈ 2.3e5 mutations at 16×16). With NEE:
/// without it (the thesis's setting, the default) the small emitter is
/// found only by sampled directions and the per-replicate spread of the
/// image mean was measured at ≈ 7% (σ ≈ 1.9% with 16 replicates), far
/// from resolving 1% in the default suite's time (its agreement within
/// that noise is recorded in docs/path-guiding.md).
fn budget() -> ChainParams {
    ChainParams {
        bootstrap: 20_000,
        chains: 256,
        mutations_per_pixel: Some(1024),
        ..ChainParams::default()
    }
}

/// One render with `seed`.
fn render(scene: &Scene, s: &McmcPg, seed: u64) -> Rendered {
    let run = RunSettings {
        seed,
        ..RunSettings::default()
    };
    let r = s
        .render(scene, &run, &AtomicBool::new(false), &NoObserver)
        .expect("mcmc-pg renders");
    assert!(!r.interrupted);
    assert_eq!(r.statistics["nonfinite_contributions"], 0);
    r
}

/// Image means of `k` renders (seeds `seed0..seed0 + k`).
fn reps(scene: &Scene, s: &McmcPg, k: u64, seed0: u64) -> Vec<[f64; 3]> {
    (0..k)
        .map(|i| image_mean(&render(scene, s, seed0 + i).image))
        .collect()
}

/// Two-sided Student's t quantile for a false-alarm rate of 1e-3 per
/// channel with `k` replicates (k − 1 degrees of freedom).
fn t_quantile(k: usize) -> f64 {
    StudentsT::new(0.0, 1.0, (k - 1) as f64)
        .unwrap()
        .inverse_cdf(1.0 - 5e-4)
}

/// Asserts agreement of replicate means with the PT replicates.
///
/// Each estimator is `K` independent replicates (own seeds, so own tree,
/// bootstrap and chains for mcmc-pg); the standard error of a mean is
/// sd/√K and `σ = √(se_pt² + se_pg²)` that of the difference: the MCSE of
/// the whole estimator, including the variance of `b` and of the tree.
/// The difference must lie within `z·σ`, `z` the Student's t quantile for
/// a two-sided false-alarm rate of 1e-3 at the smaller replicate count's
/// degrees of freedom (conservative for the difference), and within 1%;
/// and `(z + 1)·σ < 1%` is required, so that a 1% bias lies at least
/// `z + 1` standard errors out and fails the `z·σ` check with probability
/// ≥ 0.84 (the control below checks that it does).
fn check(what: &str, pt: &[[f64; 3]], test: &[[f64; 3]]) -> MeanAgreement {
    let z = t_quantile(pt.len().min(test.len()));
    let a = MeanAgreement::new(pt, test);
    eprintln!("{what}: z {z:.2}, rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.resolves(z + 1.0, 0.01),
        "{what}: noise too large for 1%: {a:?}"
    );
    assert!(
        a.failures(z, 0.01).is_empty(),
        "{what} disagrees with PT: {a:?}"
    );
    a
}

/// The tilted Cornell box (emitter out of view, as `agree_mlt.rs`).
fn cornell() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-box.xml", RES, DEPTH))
}

/// PT replicates of the tilted box: 48 × 256 spp (per-replicate spread
/// ≈ 0.7% per channel, so SE ≈ 0.1%).
fn pt_cornell() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| mc_reps(cornell(), &pt_of(cornell()), 256, 48, 1000))
}

/// Pre-trained replicates on the tilted box, shared by the agreement test
/// and its control.
fn pretrained_cornell() -> &'static [[f64; 3]] {
    static PG: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PG.get_or_init(|| {
        // 24 replicates: at 16 the measured σ of red was 0.20%, so that
        // (z + 1)σ = 1.02% did not resolve 1%; at 24, ≈ 0.17% and 0.8%.
        let s = settings(cornell(), TrainingMode::Pretrained, budget());
        reps(cornell(), &s, REPS, 5000)
    })
}

#[test]
fn pretrained_agrees_with_pt_on_the_cornell_box() {
    check("mcmc-pg pretrained", pt_cornell(), pretrained_cornell());
}

#[test]
#[ignore = "about a minute of CPU: run with --ignored"]
fn online_agrees_with_pt_on_the_cornell_box() {
    // Iterations of 1, 2, …, 512 mutations per pixel, then 1025 in the
    // last, which alone makes the image (at 1024 in all, the last held
    // 513 and σ was 0.30%: not resolving 1%). 5000 bootstrap candidates
    // per iteration.
    let chain = ChainParams {
        bootstrap: 5000,
        mutations_per_pixel: Some(2048),
        ..budget()
    };
    let s = settings(cornell(), TrainingMode::Online, chain);
    let pg = reps(cornell(), &s, 16, 6000);
    check("mcmc-pg online", pt_cornell(), &pg);
}

#[test]
fn a_one_percent_bias_is_rejected() {
    // The control: the pre-trained replicates scaled by 1.01 must fail
    // the same check.
    let biased: Vec<[f64; 3]> = pretrained_cornell()
        .iter()
        .map(|m| m.map(|v| v * 1.01))
        .collect();
    let z = t_quantile(REPS as usize);
    let a = MeanAgreement::new(pt_cornell(), &biased);
    eprintln!("x1.01: rel {:?}\n  {a:?}", a.rel());
    assert!(a.resolves(z + 1.0, 0.01), "noise too large for 1%: {a:?}");
    assert!(
        !a.failures(z, 0.01).is_empty(),
        "a 1% bias passed the check: {a:?}"
    );
}

/// The tilted glossy-glass box (`path_space_mlt.rs`'s) and its PT
/// replicates, 128 × 2048 spp (blue's SE ≈ 0.07%), shared by the
/// glossy-glass tests.
fn glossy_glass() -> &'static (Scene, Vec<[f64; 3]>) {
    static GG: OnceLock<(Scene, Vec<[f64; 3]>)> = OnceLock::new();
    GG.get_or_init(|| {
        let scene = repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH);
        let pt = mc_reps(&scene, &pt_of(&scene), 2048, 128, 1000);
        (scene, pt)
    })
}

/// Pre-trained replicates on the glossy-glass box: 64 × 4096 mutations
/// per pixel. Sizing: the run of 2026-11-26 (docs/path-guiding.md), 48
/// replicates against 48 × 2048 spp of PT, gave σ 0.15%, 0.16%, 0.20%
/// (R/G/B); PT's blue share was ≈ 0.115%
/// (2.25% per 256-spp replicate, `path_space_mlt.rs`), so `mcmc-pg`'s was
/// √(0.20² − 0.115²) ≈ 0.164% (1.13% per replicate). 64 replicates give
/// ≈ 0.142% and, with PT's 0.07%, σ ≈ 0.16%: 5σ ≈ 0.8% < 1%
/// (`common::assert_agrees_to_one_percent`).
fn pretrained_glossy_glass() -> &'static [[f64; 3]] {
    static PG: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PG.get_or_init(|| {
        let scene = &glossy_glass().0;
        let chain = ChainParams {
            mutations_per_pixel: Some(4096),
            ..budget()
        };
        let s = settings(scene, TrainingMode::Pretrained, chain);
        reps(scene, &s, 64, 7000)
    })
}

/// Pre-trained `mcmc-pg` agrees with PT on the glossy-glass box to 1%
/// (4σ and 1%, 5σ < 1%), and the same replicates × 1.01 fail. Ignored
/// (≈ 5 min of CPU): `cargo test -p mcmc-render --test mcmc_pg
/// pretrained_agrees_with_pt_on_the_glossy -- --ignored --nocapture`.
/// Passed (session 20, 2026-11-27, 2 cores, load 8–11; 646 s wall, 258 s
/// CPU): −0.24%, −0.28%, −0.32% (σ 0.12%, 0.12%, 0.15%), the control
/// rejected at z +4.4 … +6.4.
#[test]
#[ignore = "several minutes of CPU: glossy-glass box, run with --ignored"]
fn pretrained_agrees_with_pt_on_the_glossy_glass_box() {
    let (pt, pg) = (&glossy_glass().1, pretrained_glossy_glass());
    common::assert_agrees_to_one_percent("mcmc-pg pretrained glossy-glass", pt, pg);
    common::assert_one_percent_bias_is_rejected("mcmc-pg pretrained glossy-glass", pt, pg);
}

/// Online `mcmc-pg` on the glossy-glass box, the budget of
/// `online_agrees_with_pt_on_the_cornell_box` (2048 mutations per pixel,
/// the last iteration of 1025 makes the image). Sizing: a probe of 8
/// replicates through the CLI (session 20, one thread, load ≈ 9) spread
/// 1.49%, 1.43%, 1.90% (R/G/B) per replicate, so (1.90/0.166)² ≈ 131
/// replicates for σ ≈ 0.18% with PT's; 136. With the ×1.01 control.
/// Ignored (≈ 20 min of CPU; **not run**): `cargo test -p mcmc-render
/// --test mcmc_pg online_agrees_with_pt_on_the_glossy -- --ignored
/// --nocapture`.
#[test]
#[ignore = "about 20 minutes of CPU: run with --ignored"]
fn online_agrees_with_pt_on_the_glossy_glass_box() {
    let (scene, pt) = glossy_glass();
    let chain = ChainParams {
        bootstrap: 5000,
        mutations_per_pixel: Some(2048),
        ..budget()
    };
    let s = settings(scene, TrainingMode::Online, chain);
    let pg = reps(scene, &s, 136, 8000);
    common::assert_agrees_to_one_percent("mcmc-pg online glossy-glass", pt, &pg);
    common::assert_one_percent_bias_is_rejected("mcmc-pg online glossy-glass", pt, &pg);
}

#[test]
fn one_seed_gives_the_same_image_on_any_thread_count() {
    // The plastic box (a Dirac coating over a diffuse base); online: four
    // iterations (1, 2, 4 and 9 mutations per pixel), so the records of
    // three iterations of chains, spread over the threads, make trees.
    let scene = repo_scene("cornell-plastic.xml", RES);
    for training in ["pretrained", "online"] {
        let sets = [
            ("training", training),
            ("bootstrap", "2000"),
            ("chains", "64"),
            ("mutations_per_pixel", "16"),
        ];
        let one = with_threads(1, || registry_image_bits("mcmc-pg", &sets, &scene, 4));
        let two = with_threads(2, || registry_image_bits("mcmc-pg", &sets, &scene, 4));
        assert!(one.iter().any(|&b| f32::from_bits(b) > 0.0), "{training}");
        assert!(one == two, "{training}: 1 vs 2 threads differ");
    }
}

#[test]
fn statistics_hold_the_acceptance_per_iteration() {
    let scene = repo_scene("cornell-plastic.xml", RES);
    let chain = ChainParams {
        bootstrap: 2000,
        chains: 64,
        mutations_per_pixel: Some(16),
        ..ChainParams::default()
    };
    let online = render(
        &scene,
        &settings(&scene, TrainingMode::Online, chain.clone()),
        2,
    );
    let st = &online.statistics;
    let its = st["iterations"].as_array().expect("iterations");
    assert_eq!(its.len(), 4, "{st:?}");
    for (k, it) in its.iter().enumerate() {
        assert_eq!(it["iteration"], k as u64 + 1);
        let large = it["acceptance_large"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&large), "{it:?}");
        // Every iteration but the last records its paths.
        assert_eq!(
            it["records"].as_u64().unwrap() > 0,
            k + 1 < its.len(),
            "{it:?}"
        );
    }
    assert_eq!(st["acceptance_large"], its[3]["acceptance_large"]);
    assert!(st["tree_memory_bytes"].as_u64().unwrap() > 0);
    let share = st["training_time_share"].as_f64().unwrap();
    assert!(share > 0.0 && share < 1.0, "{share}");

    let pre = render(
        &scene,
        &settings(&scene, TrainingMode::Pretrained, chain),
        2,
    );
    let st = &pre.statistics;
    // 16 mutations per pixel: 2 spp of training, one iteration (3·1 > 2
    // makes the first the last, as in `guided`).
    assert_eq!(
        st["pretraining"]["spp_per_iteration"],
        serde_json::json!([2])
    );
    assert_eq!(st["iterations"].as_array().unwrap().len(), 1);
    assert!(st["acceptance_small"].as_f64().unwrap() > 0.0);
}

#[test]
fn bad_settings_are_one_line() {
    for (name, value) in [
        ("training", "sometimes"),
        ("training_share", "1"),
        ("tree_probability", "1.5"),
        ("large_step_probability", "2"),
    ] {
        let sets = [(name.to_string(), value.to_string())];
        let err = registry::configure(None, Some("mcmc-pg"), &sets)
            .err()
            .unwrap_or_else(|| panic!("{name}={value} accepted"));
        assert!(!err.contains('\n'), "{err}");
        assert!(err.contains(name), "{err}");
    }
    // A cross-parameter check (s1 < s2) is one line too.
    let sets = [
        ("s1".to_string(), "0.1".to_string()),
        ("s2".to_string(), "0.01".to_string()),
    ];
    let err = registry::configure(None, Some("mcmc-pg"), &sets)
        .err()
        .expect("s1 > s2 accepted");
    assert!(!err.contains('\n'), "{err}");
}

#[test]
fn exact_record_sums_match_merge_and_ignore_order() {
    // Records in one spatial leaf: a lobe plus a floor, values spanning
    // six decades (and some zeros, which count but carry nothing).
    use glam::Vec3;
    use mcmc_render::guiding::{ExactRecords, RecordBuffer, SdTree, square_to_direction};
    use mcmc_render::sampling::{IndependentSource, RandomSource};
    use rand::SeedableRng;
    let mut src = IndependentSource::new(rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(3));
    let records: Vec<(Vec3, f32)> = (0..20_000)
        .map(|i| {
            let u = src.next_2d();
            let d = square_to_direction(u);
            let v = if i % 7 == 0 {
                0.0
            } else {
                (8.0 * (d.z - 1.0)).exp() * 1e3 + 1e-3 * (1.0 + d.x.abs())
            };
            (d, v)
        })
        .collect();
    let p = Vec3::splat(0.5);
    let fresh = || SdTree::new((Vec3::ZERO, Vec3::ONE), 0);
    // Reference: the ordered merge.
    let mut merged = fresh();
    let mut b = RecordBuffer::default();
    for &(d, v) in &records {
        b.push(merged.leaf_at(p), d, v);
    }
    merged.merge([&b]);
    // Exact sums: three parts holding the records in two different
    // splits and orders.
    let exact = |order: &[usize], cut: usize| {
        let mut t = fresh();
        let leaf = t.leaf_at(p);
        let mut parts = vec![ExactRecords::default(), ExactRecords::default()];
        for (k, &i) in order.iter().enumerate() {
            let mut b = RecordBuffer::default();
            b.push(leaf, records[i].0, records[i].1);
            t.accumulate(&mut b, &mut parts[usize::from(k >= cut)]);
        }
        assert_eq!(parts[0].len() + parts[1].len(), records.len() as u64);
        t.merge_exact(parts);
        t
    };
    let forward: Vec<usize> = (0..records.len()).collect();
    let backward: Vec<usize> = forward.iter().rev().copied().collect();
    let mut a = exact(&forward, 5000);
    let mut c = exact(&backward, 12_345);
    for t in [&mut merged, &mut a, &mut c] {
        // A large c: no spatial split; ρ as the paper.
        t.end_iteration(1, 1e12, 0.01);
    }
    assert_eq!(a.size(), merged.size());
    let leaf = a.leaf_at(p);
    assert!(a.is_trained(leaf));
    let mut range = (f32::INFINITY, 0.0f32);
    for i in 0..2000 {
        let u = (
            (i as f32 + 0.5) / 2000.0,
            ((i * 733) % 2000) as f32 / 2000.0,
        );
        let d = square_to_direction(u);
        let (pa, pc, pm) = (a.pdf(leaf, d), c.pdf(leaf, d), merged.pdf(leaf, d));
        // Order-free: bit for bit.
        assert_eq!(pa.to_bits(), pc.to_bits(), "direction {i}");
        // Against the f64 merge: the fixed point (2⁻⁴⁰ per record) and the
        // summation order change the energies by ~1e-12 relative, below
        // the f32 density's resolution except at rounding boundaries.
        assert!(
            (pa - pm).abs() <= 1e-6 * pm.max(1e-6),
            "direction {i}: {pa} vs {pm}"
        );
        range = (range.0.min(pa), range.1.max(pa));
    }
    // The trained density is far from uniform (the lobe was learnt).
    assert!(range.1 > 100.0 * range.0, "{range:?}");
}
