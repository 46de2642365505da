//! The SD-tree's sampling distribution and the `guided` integrator.
//!
//! - The tree's density integrates to one over the sphere (midpoint
//!   quadrature on a grid finer than its deepest leaf, so exact up to
//!   rounding) and matches a histogram of its samples (chi-square), with a
//!   control whose expected counts come from a density off by 5% in one
//!   quadrant, which must be rejected.
//! - `guided` agrees with `pt` on the repo's Cornell variants to 1% of the
//!   image mean per channel (replicate means, Student's t; the derivation
//!   is at [`check`]), with a control scaled by 1.01 that must fail.
//! - One seed gives the same image and tree on 1 and 2 threads.

mod common;

use common::{MeanAgreement, image_mean, mc_reps, pt_of, repo_scene, repo_scene_tilted};
use glam::Vec3;
use mcmc_render::guiding::{RecordBuffer, SdTree, direction_to_square, square_to_direction};
use mcmc_render::integrators::guided::GuidedSettings;
use mcmc_render::integrators::registry::IntegratorSettings;
use mcmc_render::integrators::{DepthParams, Rendered, RunSettings};
use mcmc_render::observer::NoObserver;
use mcmc_render::sampling::{IndependentSource, RandomSource};
use mcmc_render::scene::Scene;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use statrs::distribution::{ChiSquared, ContinuousCDF, StudentsT};
use std::f64::consts::PI;
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

fn source(seed: u64) -> IndependentSource<Xoshiro256PlusPlus> {
    IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(seed))
}

/// A tree trained for three iterations on records from a lobe around
/// `axis` (density ∝ exp(κ(cos − 1)), κ = 8) plus a uniform floor, with
/// values that favour the lobe: one spatial leaf holds all the records.
/// Returns the tree and the point whose leaf was trained.
fn trained_tree() -> (SdTree, Vec3) {
    let mut tree = SdTree::new((Vec3::ZERO, Vec3::ONE), 0);
    let p = Vec3::splat(0.5);
    let axis = Vec3::new(0.3, -0.5, 0.81).normalize();
    let mut src = source(5);
    for k in 1..=3 {
        let mut b = RecordBuffer::default();
        let leaf = tree.leaf_at(p);
        for _ in 0..40_000 {
            let d = square_to_direction(src.next_2d());
            let c = d.dot(axis) as f64;
            let value = (8.0 * (c - 1.0)).exp() * 10.0 + 0.05 + 0.02 * d.x.abs() as f64;
            b.push(leaf, d, value as f32);
        }
        tree.merge([&b]);
        // A large c: no spatial split; ρ = 0.01 as the paper.
        tree.end_iteration(k, 1e12, 0.01);
    }
    (tree, p)
}

/// Grid cells per side of the square for quadrature (2¹¹): finer than any
/// leaf of the trained tree (checked), so the midpoint rule is exact.
const GRID: usize = 2048;

#[test]
fn the_tree_density_integrates_to_one_over_the_sphere() {
    let (tree, p) = trained_tree();
    let size = tree.size();
    assert!(
        size.max_quadtree_depth >= 4 && size.max_quadtree_depth <= 11,
        "depth {} (the quadrature needs ≤ 11, the test a refined tree)",
        size.max_quadtree_depth
    );
    let leaf = tree.leaf_at(p);
    assert!(tree.is_trained(leaf));
    // ∫ pdf dω over the sphere = 4π ∫∫ pdf(map(x, y)) dx dy.
    let mut sum = 0.0f64;
    let mut max = 0.0f64;
    for i in 0..GRID {
        for j in 0..GRID {
            let x = ((i as f64 + 0.5) / GRID as f64) as f32;
            let y = ((j as f64 + 0.5) / GRID as f64) as f32;
            let v = tree.pdf(leaf, square_to_direction((x, y))) as f64;
            max = max.max(v);
            sum += v;
        }
    }
    let integral = sum * 4.0 * PI / (GRID * GRID) as f64;
    eprintln!("∫pdf = {integral}, max pdf {max}, {size:?}");
    assert!((integral - 1.0).abs() < 1e-5, "∫pdf dω = {integral}");
    // Guiding learnt the lobe: the density is far from uniform.
    assert!(max > 10.0 / (4.0 * PI));
}

/// Expected cell masses on a `n`×`n` grid of the square from `density`
/// (per steradian), by the midpoint rule on the quadrature grid.
fn cell_masses(n: usize, density: impl Fn(Vec3, (f32, f32)) -> f64) -> Vec<f64> {
    let mut masses = vec![0.0f64; n * n];
    let per = GRID / n;
    let w = 4.0 * PI / (GRID * GRID) as f64;
    for i in 0..GRID {
        for j in 0..GRID {
            let x = ((i as f64 + 0.5) / GRID as f64) as f32;
            let y = ((j as f64 + 0.5) / GRID as f64) as f32;
            masses[(i / per) * n + j / per] += density(square_to_direction((x, y)), (x, y)) * w;
        }
    }
    masses
}

/// Chi-square p-value of `observed` counts against `masses` (cells with
/// an expected count below 5 pooled).
fn chi_square_p(observed: &[u64], masses: &[f64], n: u64) -> f64 {
    let total: f64 = masses.iter().sum();
    let mut kept = Vec::new();
    let mut pooled = (0.0f64, 0u64);
    for (&m, &o) in masses.iter().zip(observed) {
        let e = m / total * n as f64;
        if e < 5.0 {
            pooled.0 += e;
            pooled.1 += o;
        } else {
            kept.push((e, o));
        }
    }
    if pooled.0 > 0.0 {
        kept.push(pooled);
    }
    let chi2: f64 = kept
        .iter()
        .map(|&(e, o)| (o as f64 - e).powi(2) / e.max(1e-300))
        .sum();
    ChiSquared::new(kept.len() as f64 - 1.0).unwrap().sf(chi2)
}

#[test]
fn tree_samples_match_its_density_and_a_wrong_density_is_rejected() {
    let (tree, p) = trained_tree();
    let leaf = tree.leaf_at(p);
    const N: u64 = 1_000_000;
    const CELLS: usize = 32;
    let mut observed = vec![0u64; CELLS * CELLS];
    let mut src = source(99);
    let mut border = 0u64;
    for _ in 0..N {
        let (d, pdf) = tree.sample(leaf, src.next_2d());
        assert!((d.length() - 1.0).abs() < 1e-5);
        // The returned density is the density at the returned direction,
        // except where the direction's round trip through the map crosses
        // a leaf border (counted below).
        assert!(pdf > 0.0);
        if (pdf - tree.pdf(leaf, d)).abs() > 1e-4 * pdf {
            border += 1;
        }
        let (x, y) = direction_to_square(d);
        let (i, j) = ((x * CELLS as f32) as usize, (y * CELLS as f32) as usize);
        observed[i.min(CELLS - 1) * CELLS + j.min(CELLS - 1)] += 1;
    }
    // Leaf borders are 2^-6 apart at the deepest: a round-trip error of
    // ~1e-7 crosses one for ~1e-5 of the samples.
    assert!(border * 10_000 < N, "{border} samples changed leaf");
    let masses = cell_masses(CELLS, |d, _| tree.pdf(leaf, d) as f64);
    let p_value = chi_square_p(&observed, &masses, N);
    eprintln!("chi-square p = {p_value:.3e}");
    assert!(
        p_value > 1e-3,
        "samples do not follow the density: p = {p_value:.3e}"
    );

    // Control: a density 5% too high in the quadrant that holds the lobe
    // (cos θ ≥ 0, φ ≥ π), renormalised.
    let wrong = cell_masses(CELLS, |d, (x, y)| {
        let f = if x >= 0.5 && y >= 0.5 { 1.05 } else { 1.0 };
        tree.pdf(leaf, d) as f64 * f
    });
    let p_wrong = chi_square_p(&observed, &wrong, N);
    eprintln!("control p = {p_wrong:.3e}");
    assert!(
        p_wrong < 1e-6,
        "a 5% error in one quadrant passed: p = {p_wrong:.3e}"
    );
}

const RES: u32 = 16;
const DEPTH: u32 = 5;

/// `guided` with the scene's depth settings.
fn guided_of(scene: &Scene, nee: bool) -> GuidedSettings {
    GuidedSettings {
        nee,
        depth: DepthParams {
            max_depth: i64::from(scene.integrator.max_depth),
            rr_depth: scene.integrator.rr_depth,
        },
        ..GuidedSettings::default()
    }
}

/// One `guided` render of `spp` samples per pixel in all.
fn guided_render(scene: &Scene, g: &GuidedSettings, spp: u32, seed: u64) -> Rendered {
    let run = RunSettings {
        spp: Some(spp),
        seed,
        ..RunSettings::default()
    };
    let r = g
        .render(scene, &run, &AtomicBool::new(false), &NoObserver)
        .expect("guided renders");
    assert!(!r.interrupted);
    assert_eq!(r.statistics["nonfinite_samples"], 0);
    r
}

/// Image means of `k` `guided` renders.
fn guided_reps(scene: &Scene, g: &GuidedSettings, spp: u32, k: u64, seed0: u64) -> Vec<[f64; 3]> {
    (0..k)
        .map(|s| image_mean(&guided_render(scene, g, spp, seed0 + s).image))
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
/// Each estimator is `K` independent replicates; the standard error of a
/// mean is sd/√K, and `σ = √(se_pt² + se_guided²)` that of the
/// difference. The difference must lie within `z·σ` with `z` the Student's
/// t quantile for a 1e-3 two-sided false-alarm rate at the smaller
/// replicate count's degrees of freedom (conservative for the difference),
/// and within 1%; and the budgets must resolve 1%: `(z + 1)·σ < 1%`, so
/// that a 1% discrepancy fails the `z·σ` check with probability ≥ 0.84.
fn check(what: &str, pt: &[[f64; 3]], test: &[[f64; 3]]) {
    let z = t_quantile(pt.len().min(test.len()));
    let a = MeanAgreement::new(pt, test);
    eprintln!("{what}: z {z:.2}, rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.failures(z, 0.01).is_empty(),
        "{what} disagrees with PT: {a:?}"
    );
    assert!(
        a.resolves(z + 1.0, 0.01),
        "{what}: noise too large for 1%: {a:?}"
    );
}

/// The tilted Cornell box (emitter out of view, as `agree_mlt.rs`).
fn cornell() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-box.xml", RES, DEPTH))
}

/// The tilted glossy-glass box (glass, rough gold: delta and glossy lobes).
fn glossy_glass() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH))
}

/// PT replicates of the tilted box: 48 × 256 spp.
fn pt_cornell() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| mc_reps(cornell(), &pt_of(cornell()), 256, 48, 1000))
}

/// `guided` with NEE: 16 replicates of 1023 spp (the last iteration's
/// 512 make the image). Measured: SE 0.08–0.10% per channel (spread
/// between replicates 0.3–0.4%).
fn guided_nee_cornell() -> &'static [[f64; 3]] {
    static G: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    G.get_or_init(|| guided_reps(cornell(), &guided_of(cornell(), true), 1023, 16, 6000))
}

#[test]
fn guided_with_nee_agrees_with_pt_on_the_cornell_box() {
    check("guided+nee", pt_cornell(), guided_nee_cornell());
}

#[test]
fn a_one_percent_bias_is_rejected() {
    let biased: Vec<[f64; 3]> = guided_nee_cornell()
        .iter()
        .map(|m| m.map(|v| v * 1.01))
        .collect();
    let z = t_quantile(biased.len());
    let a = MeanAgreement::new(pt_cornell(), &biased);
    eprintln!("guided+nee x1.01: rel {:?}\n  {a:?}", a.rel());
    assert!(a.resolves(z + 1.0, 0.01), "noise too large for 1%: {a:?}");
    assert!(
        !a.failures(z, 0.01).is_empty(),
        "a 1% bias passed the check: {a:?}"
    );
}

/// Without NEE (the default) the box's small emitter is found only by
/// the sampled directions: at 16 × 4095 spp the SE was 0.34% (too large
/// for 1%), so this runs 32 × 16383 spp, ~5 min of one core (ignored;
/// `cargo test -p mcmc-render --test guided -- --ignored`).
#[test]
#[ignore]
fn guided_without_nee_agrees_with_pt_on_the_cornell_box() {
    let g = guided_reps(cornell(), &guided_of(cornell(), false), 16383, 32, 5000);
    check("guided", pt_cornell(), &g);
}

/// The glossy-glass box needs 4× PT's budget and 32 × 8191 guided spp to
/// resolve 1% (at 48 × 256 and 16 × 2047 σ was 0.27%; at 48 × 1024 and
/// 16 × 8191 blue's σ was 0.20%, (z + 1)σ = 1.02%): ~5 min of one core
/// (ignored, as the glossy-glass MMLT tests of `agree_mlt.rs`).
#[test]
#[ignore]
fn guided_agrees_with_pt_on_the_glossy_glass_box() {
    let pt = mc_reps(glossy_glass(), &pt_of(glossy_glass()), 1024, 48, 2000);
    let g = guided_reps(
        glossy_glass(),
        &guided_of(glossy_glass(), true),
        8191,
        32,
        7000,
    );
    check("guided+nee glossy-glass", &pt, &g);
}

#[test]
fn one_seed_gives_the_same_image_and_tree_on_any_thread_count() {
    // 48×48: four tiles; 15 spp: iterations of 1, 2, 4 and 8 spp, so three
    // trained trees are used. The plastic box has a Dirac coating over a
    // diffuse base (mixed lobes); NEE on and off.
    let scene = repo_scene("cornell-plastic.xml", 48);
    for nee in [false, true] {
        let g = guided_of(&scene, nee);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| guided_render(&scene, &g, 15, 3))
        };
        let (a, b) = (run(1), run(2));
        assert_eq!(
            a.statistics["spp_per_iteration"],
            serde_json::json!([1, 2, 4, 8])
        );
        assert!(a.image.iter().any(|p| p.r > 0.0));
        for key in ["tree", "records_per_iteration", "spp"] {
            assert_eq!(a.statistics[key], b.statistics[key], "{key}");
        }
        for (i, (p, q)) in a.image.iter().zip(&b.image).enumerate() {
            assert_eq!(
                (p.r.to_bits(), p.g.to_bits(), p.b.to_bits()),
                (q.r.to_bits(), q.g.to_bits(), q.b.to_bits()),
                "pixel {i}, nee {nee}"
            );
        }
    }
}
