//! Vertex connection and merging (`vcm`) against BDPT, its MIS weights,
//! and its determinism.
//!
//! # Agreement tolerances
//!
//! As in `agree_mlt.rs`: each estimator runs as `K` = 24 independent
//! replicates (fixed seeds); the standard error of an image mean is
//! sd(replicate means)/√K, and `σ` that of the difference of the two
//! means. A channel passes when the difference lies within 4σ (Student's t
//! with 23 degrees of freedom per mean: false-alarm rate ≈ 5e-4 per
//! channel) and within 1%, and the budget must make 5σ < 1% so that a 1%
//! discrepancy is detectable; the control shows that a 1% bias is caught.
//!
//! # Scenes
//!
//! The repo's Cornell box and glossy/glass box at 16×16, `max_depth` 5,
//! camera tilted so that the emitter is out of view (see
//! `common::repo_scene_tilted_text`). At 16×16 SmallVCM's automatic radius
//! (0.3% of the scene's radius) is far below a pixel and merging would
//! carry almost nothing, so the agreement tests set `radius = 0.1` (5.7%
//! of the scene's radius, 0.055 after the 128 iterations) with SmallVCM's
//! reduction `alpha = 0.75` and check that merging carries a real share of
//! the energy (measured 3% on the Cornell box, where connections take most
//! diffuse paths). The default tests take about 12 s.

mod common;

use common::{MeanAgreement, bdpt_of, image_mean, mc_reps, repo_scene_tilted};
use mcmc_render::bsdf::TransportMode;
use mcmc_render::color::Rgb;
use mcmc_render::integrators::bdpt::{MisHeuristic, generate_camera_subpath, mis_weight};
use mcmc_render::integrators::path_vertex::{Vertex, VertexKind};
use mcmc_render::integrators::vcm::{
    LightVertex, MisFactors, VcmMode, VcmSettings, partial_mis, weight_connection, weight_direct,
    weight_emission, weight_light_trace, weight_merge_at,
};
use mcmc_render::integrators::{Rendered, RunSettings, registry};
use mcmc_render::observer::NoObserver;
use mcmc_render::sampling::IndependentSource;
use mcmc_render::scene::Scene;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

const RES: u32 = 16;
const DEPTH: u32 = 5;
const REPS: u64 = 24;
const ITERATIONS: u32 = 128;

fn cornell() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-box.xml", RES, DEPTH))
}

fn glossy_glass() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH))
}

/// VCM settings with the scene's depth, `mode`, radius 0.1 and α = 0.75.
fn settings(scene: &Scene, mode: VcmMode) -> VcmSettings {
    let mut s = VcmSettings {
        mode,
        radius: Some(0.1),
        alpha: 0.75,
        ..VcmSettings::default()
    };
    s.depth.max_depth = i64::from(scene.integrator.max_depth);
    s.depth.rr_depth = scene.integrator.rr_depth;
    s
}

/// One run of `iterations` iterations.
fn run(scene: &Scene, s: &VcmSettings, iterations: u32, seed: u64) -> Rendered {
    let run = RunSettings {
        spp: Some(iterations),
        seed,
        ..RunSettings::default()
    };
    let out = s
        .integrator(scene)
        .render(scene, &run, &AtomicBool::new(false), &NoObserver);
    assert_eq!(out.statistics["iterations"], u64::from(iterations));
    assert_eq!(out.statistics["nonfinite_samples"], 0);
    out
}

/// Image means of `REPS` runs, and the mean share of merging.
fn vcm_reps(scene: &Scene, s: &VcmSettings, seed0: u64) -> (Vec<[f64; 3]>, f64) {
    vcm_reps_of(scene, s, seed0, REPS, ITERATIONS)
}

/// Image means of `reps` runs of `iterations`, and the mean share of merging.
fn vcm_reps_of(
    scene: &Scene,
    s: &VcmSettings,
    seed0: u64,
    reps: u64,
    iterations: u32,
) -> (Vec<[f64; 3]>, f64) {
    let mut merge = 0.0;
    let means = (0..reps)
        .map(|k| {
            let out = run(scene, s, iterations, seed0 + k);
            merge += out.statistics["energy_shares"]["merge"].as_f64().unwrap();
            image_mean(&out.image)
        })
        .collect();
    (means, merge / reps as f64)
}

/// BDPT replicates of a scene (128 spp each).
fn bdpt_reps(scene: &Scene, seed0: u64) -> Vec<[f64; 3]> {
    mc_reps(scene, &bdpt_of(scene), ITERATIONS, REPS, seed0)
}

fn cornell_bdpt() -> &'static [[f64; 3]] {
    static R: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    R.get_or_init(|| bdpt_reps(cornell(), 100))
}

fn cornell_vcm() -> &'static (Vec<[f64; 3]>, f64) {
    static R: OnceLock<(Vec<[f64; 3]>, f64)> = OnceLock::new();
    R.get_or_init(|| vcm_reps(cornell(), &settings(cornell(), VcmMode::Vcm), 200))
}

/// Asserts agreement within 4σ and 1%, with 5σ < 1%.
fn check(what: &str, reference: &[[f64; 3]], test: &[[f64; 3]]) {
    let a = MeanAgreement::new(reference, test);
    eprintln!("{what}: rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "{what} disagrees with bdpt: {a:?}"
    );
    assert!(
        a.resolves(5.0, 0.01),
        "{what}: noise too large for 1%: {a:?}"
    );
}

#[test]
fn vcm_agrees_with_bdpt_on_the_cornell_box() {
    let (reps, merge) = cornell_vcm();
    eprintln!("merge share {merge}");
    assert!(
        *merge > 0.01,
        "merging carries too little to be tested: {merge}"
    );
    check("vcm", cornell_bdpt(), reps);
}

/// The control of an agreement: `test`'s estimates biased by +1% must
/// fail the same 4σ-and-1% check against `reference`.
fn assert_one_percent_bias_detected(what: &str, reference: &[[f64; 3]], test: &[[f64; 3]]) {
    let biased: Vec<[f64; 3]> = test.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let a = MeanAgreement::new(reference, &biased);
    assert!(
        !a.failures(4.0, 0.01).is_empty(),
        "{what}: 1% bias not detected: {a:?}"
    );
}

/// The control: the same VCM estimates biased by +1% must fail.
#[test]
fn a_one_percent_bias_is_detected() {
    assert_one_percent_bias_detected("vcm", cornell_bdpt(), &cornell_vcm().0);
}

#[test]
fn bpt_mode_reproduces_bdpt() {
    let (reps, merge) = vcm_reps(cornell(), &settings(cornell(), VcmMode::Bpt), 300);
    assert_eq!(merge, 0.0);
    check("vcm mode=bpt", cornell_bdpt(), &reps);
}

/// BDPT replicates of the glossy/glass box for the ignored tests: 96 × 512
/// spp (σ of the difference to VCM ≈ 0.1–0.2% of the mean).
fn glossy_glass_bdpt() -> &'static [[f64; 3]] {
    static R: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    R.get_or_init(|| mc_reps(glossy_glass(), &bdpt_of(glossy_glass()), 512, 96, 400))
}

/// The glossy/glass box (caustic through the glass sphere, glossy gold):
/// noisier, 96 × 512 iterations (about 4 minutes with the next test); run
/// with `cargo test -p mcmc-render --test vcm -- --ignored`.
#[test]
#[ignore]
fn vcm_agrees_with_bdpt_on_the_glossy_glass_box() {
    let s = settings(glossy_glass(), VcmMode::Vcm);
    let (reps, merge) = vcm_reps_of(glossy_glass(), &s, 500, 96, 512);
    eprintln!("merge share {merge}");
    check("vcm glossy-glass", glossy_glass_bdpt(), &reps);
}

/// `mode=bpt` on the glossy/glass box.
#[test]
#[ignore]
fn bpt_mode_reproduces_bdpt_on_the_glossy_glass_box() {
    let s = settings(glossy_glass(), VcmMode::Bpt);
    let (reps, _) = vcm_reps_of(glossy_glass(), &s, 600, 96, 512);
    check("vcm mode=bpt glossy-glass", glossy_glass_bdpt(), &reps);
}

/// `light_subpaths` = 4 (each camera subpath connects to four light
/// subpaths, light tracing counts 1/4, merging over all, MIS with the
/// light-subpath techniques' densities ×4) and 0.5 (two camera subpaths
/// share a light subpath) agree with `bdpt` as the default does: 24
/// replicates each of the default's 128 iterations, within 4σ and 1% with
/// 5σ < 1% (σ from the 24 replicates of each side, `MeanAgreement`);
/// control: the same estimates ×1.01 must fail. The same iterations, so
/// the same radius schedule: merging's bias grows with the radius (the
/// default reads +0.3% here, 4 +0.35 to +0.53%; 32 iterations at 4 read
/// +0.5 to +1.0%, a larger radius, not a normalisation error: `mode=bpt`
/// at 32 read −0.1 to −0.24%).
#[test]
fn more_or_fewer_light_subpaths_agree_with_bdpt() {
    for (light_subpaths, seed0) in [(4.0, 700), (0.5, 800)] {
        let mut s = settings(cornell(), VcmMode::Vcm);
        s.light_subpaths = light_subpaths;
        let (reps, merge) = vcm_reps(cornell(), &s, seed0);
        assert!(merge > 0.01, "merge share {merge}");
        let what = format!("vcm light_subpaths={light_subpaths}");
        check(&what, cornell_bdpt(), &reps);
        assert_one_percent_bias_detected(&what, cornell_bdpt(), &reps);
    }
}

/// `light_subpaths` sets the light subpaths of an iteration
/// (`light_subpaths × pixels`, rounded: 640 of 2.5 on 16×16, at least one)
/// and a value outside (0, 1024] is one line of error, not a run.
#[test]
fn light_subpaths_set_an_iterations_light_subpaths() {
    for (light_subpaths, per_iteration) in [(1.0, 256), (2.5, 640), (1e-4, 1)] {
        let mut s = settings(cornell(), VcmMode::Vcm);
        s.light_subpaths = light_subpaths;
        let out = run(cornell(), &s, 2, 5);
        assert_eq!(
            out.statistics["light_subpaths_per_iteration"],
            per_iteration
        );
    }
    for bad in ["0", "-1", "nan", "inf", "1025"] {
        let set = [("light_subpaths".to_string(), bad.to_string())];
        let e = registry::configure(None, Some("vcm"), &set).err();
        assert!(e.is_some_and(|e| !e.contains('\n')), "light_subpaths={bad}");
    }
}

/// One seed gives the same bits on 1 and 3 threads, with one light
/// subpath per pixel and with 2.5 (uneven shares over the light units,
/// two or three connections per camera subpath).
#[test]
fn images_do_not_depend_on_the_thread_count() {
    for light_subpaths in [1.0, 2.5] {
        images_do_not_depend_on_the_thread_count_at(light_subpaths);
    }
}

fn images_do_not_depend_on_the_thread_count_at(light_subpaths: f64) {
    let scene = glossy_glass();
    let mut s = settings(scene, VcmMode::Vcm);
    s.light_subpaths = light_subpaths;
    let render = |threads: usize| -> Vec<Rgb> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| run(scene, &s, 3, 9).image)
    };
    let (a, b) = (render(1), render(3));
    assert!(a.iter().any(|p| p.r > 0.0));
    for (i, (p, q)) in a.iter().zip(&b).enumerate() {
        assert_eq!(
            (p.r.to_bits(), p.g.to_bits(), p.b.to_bits()),
            (q.r.to_bits(), q.g.to_bits(), q.b.to_bits()),
            "pixel {i}"
        );
    }
}

/// The light subpath a light walk would have made of the full path
/// `z[0..=n]` read backwards (`z[n]` on an emitter): vertices, forward and
/// reverse area densities and specular flags as `generate_light_subpath`
/// sets them.
fn reversed(scene: &Scene, z: &[Vertex]) -> Vec<Vertex> {
    let n = z.len() - 1;
    let mut y: Vec<Vertex> = Vec::with_capacity(n);
    let mut origin = Vertex::light(scene, z[n].light, z[n].sp, Rgb::WHITE, 0.0);
    origin.pdf_fwd = origin.pdf_light_origin(scene);
    y.push(origin);
    for k in 1..n {
        let src = &z[n - k];
        // The direction the camera walk sampled, reversed (recomputing it
        // from the positions would add rounding the walk never saw).
        let wo = -z[n - k + 1].wo;
        let mut v = Vertex::surface(scene, src.sp, wo, Rgb::WHITE);
        v.delta = src.delta;
        y.push(v);
    }
    for k in 1..n {
        let (prev, rest) = y.split_at_mut(k);
        let v = &mut rest[0];
        v.pdf_fwd = if k == 1 {
            prev[0].pdf_light(scene, v)
        } else if prev[k - 1].delta {
            0.0
        } else {
            prev[k - 1].pdf(scene, Some(&prev[k - 2]), v, TransportMode::Importance)
        };
    }
    // p← of vertex k is set when the walk leaves vertex k + 1 towards k + 2.
    for k in 0..n.saturating_sub(2) {
        y[k].pdf_rev = if y[k + 1].delta {
            0.0
        } else {
            y[k + 1].pdf(scene, Some(&y[k + 2]), &y[k], TransportMode::Radiance)
        };
    }
    y
}

/// Every technique's MIS weight for a full path (camera subpath `z` that
/// ends on an emitter): their sum, and the largest difference of a
/// connection's weight to BDPT's in `bpt` mode.
///
/// `light_radius` is the radius the light subpath's quantities are built
/// with (the control builds them with another radius than the joins').
fn weights(scene: &Scene, z: &[Vertex], mode: VcmMode, light_radius: f32) -> (f32, f32) {
    let f = MisFactors::new(mode, MisHeuristic::Power, 0.05, 4096.0);
    let f_light = MisFactors::new(mode, MisHeuristic::Power, light_radius, 4096.0);
    let n = z.len() - 1;
    let y = reversed(scene, z);
    let (mut zmis, mut ymis) = (Vec::new(), Vec::new());
    partial_mis(scene, z, &f, &mut zmis);
    partial_mis(scene, &y, &f_light, &mut ymis);
    let connectible = |v: &Vertex| v.is_connectible(scene) && !v.delta;
    let light_vertex = |i: usize| LightVertex {
        v: y[i],
        mis: ymis[i],
        to_prev: y[i].convert_density(1.0, &y[i - 1]),
        depth: i as u32,
    };
    let mut sum = weight_emission(scene, &f, z, &zmis, n);
    let mut worst_bdpt = 0.0f32;
    // Next-event estimation from z[n − 1].
    if n >= 2 && connectible(&z[n - 1]) {
        sum += weight_direct(scene, &f, &y[0], &z[..n], &zmis, n - 1);
    }
    // Light prefix y[..=i] (y[i] = z[j]) with camera prefix z[..j]:
    // light tracing (j = 1) or a connection (j ≥ 2).
    for i in 1..n {
        let j = n - i;
        if !connectible(&y[i])
            || !connectible(&z[j - 1])
            || (j >= 2 && z[j - 1].kind != VertexKind::Surface)
        {
            continue;
        }
        let lv = light_vertex(i);
        let w = if j == 1 {
            weight_light_trace(scene, &f, &lv, &z[0])
        } else {
            weight_connection(scene, &f, &lv, &z[..j], &zmis, j - 1)
        };
        sum += w;
        if mode == VcmMode::Bpt {
            let b = mis_weight(
                scene,
                &z[..j],
                &y[..=i],
                i + 1,
                j,
                None,
                MisHeuristic::Power,
            );
            if j >= 2 {
                worst_bdpt = worst_bdpt.max((w - b).abs());
            }
        }
    }
    // Merges at every connectible interior vertex z[j] = y[n − j].
    if mode.merges() {
        for j in 1..n {
            if connectible(&z[j]) {
                let lv = light_vertex(n - j);
                sum += weight_merge_at(scene, &f, &lv, &z[..=j], &zmis, j);
            }
        }
    }
    (sum, worst_bdpt)
}

/// On random full paths (camera subpaths of up to 8 vertices that end on
/// the emitter, in the glossy/glass box: diffuse, glossy and specular
/// vertices), the weights of all techniques sum to one, with merging and
/// without; without merging the connections' weights are BDPT's.
#[test]
fn mis_weights_over_all_techniques_sum_to_one() {
    let scene = repo_scene_tilted("cornell-glossy-glass.xml", RES, 8);
    let mut src = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(17));
    let mut z = Vec::new();
    let (mut errors, mut worst_bdpt, mut control) = (Vec::new(), 0.0f32, 0.0f32);
    for k in 0..400_000u32 {
        let raster = glam::Vec2::new((k % RES) as f32 + 0.5, ((k / RES) % RES) as f32 + 0.5);
        let n = generate_camera_subpath(&scene, raster, &mut src, 8, None, &mut z);
        if n < 3 || !z[n - 1].is_light() || z[n - 1].le(&scene, &z[n - 2]).is_black() {
            continue;
        }
        for mode in [VcmMode::Vcm, VcmMode::Bpt] {
            let (sum, bdpt) = weights(&scene, &z[..n], mode, 0.05);
            errors.push((sum - 1.0).abs());
            worst_bdpt = worst_bdpt.max(bdpt);
        }
        // Control: light-side quantities built with twice the joins' radius.
        let (sum, _) = weights(&scene, &z[..n], VcmMode::Vcm, 0.1);
        control = control.max((sum - 1.0).abs());
    }
    errors.sort_by(f32::total_cmp);
    let paths = errors.len() / 2;
    let quantile = |q: f64| errors[((errors.len() - 1) as f64 * q) as usize];
    eprintln!(
        "{paths} paths; |Σw − 1|: median {:e}, 99% {:e}, max {:e}; worst |w − w_bdpt| {worst_bdpt:e}; control {control:e}",
        quantile(0.5),
        quantile(0.99),
        quantile(1.0)
    );
    // f32 densities whose ratios span many decades (glossy lobes, short
    // segments near corners): the median is at rounding level, a few
    // paths lose a few 1e-4.
    assert!(quantile(0.5) < 1e-5, "median error {}", quantile(0.5));
    assert!(quantile(0.99) < 1e-4, "99% quantile {}", quantile(0.99));
    assert!(quantile(1.0) < 1e-2, "largest error {}", quantile(1.0));
    assert!(paths > 1000, "only {paths} paths");
    assert!(
        control > 0.01,
        "the control's weights still sum to one: {control}"
    );
    assert!(
        worst_bdpt < 1e-3,
        "bpt weights differ from bdpt's by {worst_bdpt}"
    );
}

/// A repo scene at 16×16 (a 16×16 window of a 32×24 frame for the
/// thin-lens scene), `max_depth` 5.
fn feature_scene(file: &str) -> Scene {
    let mut defines: std::collections::HashMap<String, String> = [("max_depth", "5")]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    let frame: &[(&str, &str)] = if file == "dof-spheres.xml" {
        &[
            ("width", "32"),
            ("height", "24"),
            ("crop_x", "9"),
            ("crop_y", "4"),
            ("crop_width", "16"),
            ("crop_height", "16"),
        ]
    } else {
        &[("width", "16"), ("height", "16")]
    };
    for (k, v) in frame {
        defines.insert(k.to_string(), v.to_string());
    }
    Scene::load(&common::repo_scene_path(file), &defines).expect("scene loads")
}

/// Every emitter and BSDF kind BDPT handles: an environment map with a
/// textured rough-plastic mesh with interpolated normals
/// (`env-textured-plastic.xml`), a spot light (`spot-floor.xml`), and a
/// thin lens under a sky (`dof-spheres.xml`): `vcm` with a merge radius of
/// 5% of the scene's radius (α = 0.75) agrees with BDPT as above.
#[test]
fn vcm_agrees_with_bdpt_on_environment_spot_light_textures_and_thin_lens() {
    for (k, file) in [
        "env-textured-plastic.xml",
        "spot-floor.xml",
        "dof-spheres.xml",
    ]
    .into_iter()
    .enumerate()
    {
        let scene = feature_scene(file);
        let mut s = settings(&scene, VcmMode::Vcm);
        s.radius = None;
        s.radius_factor = 0.05;
        let seed = 1000 * (k as u64 + 1);
        let bdpt = bdpt_reps(&scene, seed);
        let (reps, merge) = vcm_reps(&scene, &s, seed + 500);
        eprintln!("{file}: merge share {merge}");
        check(&format!("vcm {file}"), &bdpt, &reps);
    }
}
