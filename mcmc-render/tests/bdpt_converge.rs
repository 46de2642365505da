//! BDPT against path tracing: the image means must agree on the repo's
//! Cornell variants (diffuse; glossy + glass) and on a point-light scene
//! with a mirror and a glass sphere (delta BSDFs, delta light), for both
//! MIS heuristics.
//!
//! Tolerances come from standard errors measured in the test itself: each
//! integrator renders K = [`BATCHES`] independent batches (different seeds);
//! the standard error of the image mean is sd(batch means)/√K, and the
//! difference of the two estimates must lie within 4·√(se_pt² + se_bdpt²).
//! The standard errors are themselves estimates: with K = 32 batches (31
//! degrees of freedom each) the false-failure rate of the 4σ bound is about
//! 4e-4 per channel (Student's t), and the power check below rarely flips on
//! a noisy σ; with the earlier K = 8 batches of four times the samples (the
//! same work) both flipped when the random streams changed. Seeds are
//! fixed, so the test is deterministic. The 1% bound
//! of the issue is checked too, together with a check that the noise is
//! small enough for 1% to be meaningful (4σ < 1%).

mod common;

use common::{
    furnace_sphere, image_mean, load_str as load, mean_se, point_light_on_a_plane,
    repo_scene_tilted_text,
};
use mcmc_render::color::Rgb;
use mcmc_render::integrators::Integrator;
use mcmc_render::integrators::bdpt::{Bdpt, MisHeuristic};
use mcmc_render::integrators::pt::PathTracer;
use mcmc_render::observer::NoObserver;
use mcmc_render::render::{RenderSettings, render};
use mcmc_render::scene::Scene;
use std::sync::atomic::AtomicBool;

/// A repo scene at `res`×`res` with the camera tilted down so that the
/// emitter is out of view (see `common::repo_scene_tilted_text`): the
/// emitter seen directly is technique (0, 2), weight one, exactly path
/// tracing's first hit, and nothing BDPT-specific.
fn repo_scene_text(name: &str, res: u32) -> String {
    repo_scene_tilted_text(name, res, 8)
}

/// Independent batches per estimate (see the module documentation).
const BATCHES: u64 = 32;

/// Renders one image; returns it with the number of dropped non-finite contributions.
fn render_image(scene: &Scene, integ: &dyn Integrator, spp: u32, seed: u64) -> (Vec<Rgb>, u64) {
    let settings = RenderSettings {
        spp: Some(spp),
        time_budget: None,
        seed,
    };
    let stop = AtomicBool::new(false);
    let r = render(scene, integ, &settings, &stop, &NoObserver);
    assert_eq!(r.spp_done, spp as u64);
    (r.image(), r.stats.nonfinite)
}

/// Mean and standard error (per channel) of the image mean over `k` independent batches.
fn batched_mean(scene: &Scene, integ: &dyn Integrator, spp: u32, k: u64) -> ([f64; 3], [f64; 3]) {
    let means: Vec<[f64; 3]> = (0..k)
        .map(|seed| {
            let (img, nonfinite) = render_image(scene, integ, spp, 7000 + seed);
            assert_eq!(nonfinite, 0, "{}: non-finite contributions", integ.name());
            image_mean(&img)
        })
        .collect();
    mean_se(&means)
}

/// Checks BDPT against PT: consistent within 4σ, within `bound` relative,
/// and with 4σ < `bound` (so that an error of `bound` would be detected).
fn check_agreement(
    scene: &Scene,
    what: &str,
    pt_spp: u32,
    bdpt_spp: u32,
    heuristics: &[MisHeuristic],
    bound: f64,
) {
    let it = scene.integrator;
    let pt = PathTracer {
        max_depth: it.max_depth,
        rr_depth: it.rr_depth,
    };
    let (mp, sp) = batched_mean(scene, &pt, pt_spp / 4, BATCHES);
    for &heuristic in heuristics {
        let bdpt = Bdpt {
            max_depth: it.max_depth,
            rr_depth: it.rr_depth,
            heuristic,
        };
        let (mb, sb) = batched_mean(scene, &bdpt, bdpt_spp / 4, BATCHES);
        eprintln!("{what} {heuristic:?}: pt {mp:?} ± {sp:?}\n  bdpt {mb:?} ± {sb:?}");
        for c in 0..3 {
            let sigma = (sp[c] * sp[c] + sb[c] * sb[c]).sqrt();
            let rel = (mb[c] - mp[c]) / mp[c];
            assert!(
                (mb[c] - mp[c]).abs() < 4.0 * sigma,
                "{what} {heuristic:?} channel {c}: pt {} ± {}, bdpt {} ± {}",
                mp[c],
                sp[c],
                mb[c],
                sb[c]
            );
            assert!(
                rel.abs() < bound,
                "{what} {heuristic:?} channel {c}: relative difference {rel}"
            );
            assert!(
                4.0 * sigma < bound * mp[c],
                "{what} {heuristic:?} channel {c}: noise too large to test {bound} (sigma {sigma})"
            );
        }
    }
}

#[test]
fn bdpt_matches_pt_on_the_cornell_box() {
    let scene = load(&repo_scene_text("cornell-box.xml", 32));
    assert_eq!(scene.film.width, 32);
    check_agreement(
        &scene,
        "cornell-box",
        128,
        64,
        &[MisHeuristic::Power, MisHeuristic::Balance],
        0.01,
    );
}

#[test]
fn bdpt_matches_pt_on_the_glossy_glass_cornell_box() {
    // Rough gold (GGX) and a smooth glass sphere: delta vertices on both
    // subpaths, caustics through the sphere (which BDPT finds by light
    // tracing, PT by hitting the area light after the sphere).
    let scene = load(&repo_scene_text("cornell-glossy-glass.xml", 32));
    // The caustic makes both estimators noisier: at a test-sized budget
    // (~30 s) the noise allows a 2% bound, not 1%; the 1% check on this
    // scene is the ignored test below. BDPT dominates the noise of the blue
    // channel: at 128 spp its 4σ was 2.0% of the mean, on the bound itself,
    // so BDPT gets 192 (4σ ≈ 1.7%).
    check_agreement(
        &scene,
        "cornell-glossy-glass",
        512,
        192,
        &[MisHeuristic::Power],
        0.02,
    );
}

#[test]
#[ignore = "long (minutes): the 1% bound on the glossy-glass box"]
fn bdpt_matches_pt_on_the_glossy_glass_cornell_box_to_one_percent() {
    let scene = load(&repo_scene_text("cornell-glossy-glass.xml", 32));
    check_agreement(
        &scene,
        "cornell-glossy-glass",
        1024,
        512,
        &[MisHeuristic::Power],
        0.01,
    );
}

/// The Cornell box lit by a point light under a small diffuse plate, with a
/// mirror sphere and a glass sphere in the plate's shadow. The point light
/// sees no specular surface, so every light path leaves it through a
/// diffuse bounce: path tracing (which cannot find point light → specular
/// paths) is then unbiased and a valid reference, while BDPT exercises its
/// point-light techniques (delta position: no camera-side emitter hits)
/// and specular vertices on both subpaths.
fn point_light_scene(res: u32) -> String {
    let text = repo_scene_text("cornell-box.xml", res);
    let start = text.find(r#"<emitter type="area">"#).expect("area emitter");
    let end = text[start..].find("</emitter>").expect("emitter end") + start + "</emitter>".len();
    let mut text = format!("{}{}", &text[..start], &text[end..]);
    let extra = r#"
    <emitter type="point">
        <point name="position" x="0" y="0.9" z="0"/>
        <rgb name="intensity" value="4, 3.5, 3"/>
    </emitter>
    <shape type="rectangle">
        <transform name="to_world">
            <scale value="0.3"/>
            <rotate x="1" angle="90"/>
            <translate y="0.8"/>
        </transform>
        <ref id="white"/>
    </shape>
    <shape type="sphere">
        <point name="center" x="-0.4" y="-0.7" z="0.1"/>
        <float name="radius" value="0.3"/>
        <bsdf type="conductor"><string name="material" value="none"/></bsdf>
    </shape>
    <shape type="sphere">
        <point name="center" x="0.4" y="-0.7" z="0.3"/>
        <float name="radius" value="0.3"/>
        <bsdf type="dielectric"/>
    </shape>
</scene>"#;
    let close = text.rfind("</scene>").expect("scene end");
    text.replace_range(close.., extra);
    text
}

#[test]
fn bdpt_matches_pt_with_a_point_light_and_delta_bsdfs() {
    let scene = load(&point_light_scene(32));
    assert!(scene.lights.lights.len() == 1, "only the point light emits");
    check_agreement(
        &scene,
        "point-light-specular",
        1024,
        128,
        &[MisHeuristic::Power, MisHeuristic::Balance],
        // Measured noise at this budget (pt σ ≈ 2.2e-4, bdpt ≈ 1.7e-4 on a
        // mean of 0.055) allows a 2.5% bound; see the 1% ignored test above
        // for what a longer budget gives on a delta scene.
        0.025,
    );
}

#[test]
fn non_finite_contributions_are_counted_and_dropped() {
    // An intensity near f32::MAX overflows the light subpath's throughput
    // (I·4π/pmf) to inf, and every product with it to ±inf
    // (and inf·0 to NaN): each such contribution must be counted and left
    // out of the image, which stays finite.
    let text = point_light_scene(8).replace(
        r#"<rgb name="intensity" value="4, 3.5, 3"/>"#,
        r#"<rgb name="intensity" value="3e38, 3e38, 3e38"/>"#,
    );
    let scene = load(&text);
    let it = scene.integrator;
    let bdpt = Bdpt {
        max_depth: it.max_depth,
        rr_depth: it.rr_depth,
        heuristic: MisHeuristic::Power,
    };
    let (img, nonfinite) = render_image(&scene, &bdpt, 4, 1);
    assert!(nonfinite > 0, "no non-finite contribution was counted");
    assert!(
        img.iter().all(|p| p.is_finite()),
        "a non-finite pixel reached the image"
    );
}

#[test]
fn bdpt_images_are_bit_identical_across_thread_counts() {
    // Splats land anywhere, so BDPT renders fixed row chunks into whole-image
    // films summed in chunk order: the thread count must not matter.
    let scene = load(&repo_scene_text("cornell-glossy-glass.xml", 24));
    let it = scene.integrator;
    let bdpt = Bdpt {
        max_depth: it.max_depth,
        rr_depth: it.rr_depth,
        heuristic: MisHeuristic::Power,
    };
    let bits = |threads: usize, seed: u64| -> Vec<u32> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool");
        let (img, _) = pool.install(|| render_image(&scene, &bdpt, 3, seed));
        img.iter()
            .flat_map(|p| [p.r.to_bits(), p.g.to_bits(), p.b.to_bits()])
            .collect()
    };
    let one = bits(1, 5);
    assert!(one == bits(3, 5), "1 vs 3 threads differ");
    assert!(one == bits(8, 5), "1 vs 8 threads differ");
    assert!(one != bits(2, 6), "seed ignored");
}

#[test]
fn bdpt_furnace_matches_le_over_one_minus_albedo() {
    // Inside a closed diffuse sphere of albedo a that emits Le everywhere on
    // its inner side, every pixel is Le / (1 − a) = 2 (unbounded depth with
    // Russian roulette). 4σ bound and a check that 4σ < 1%.
    let scene = load(&furnace_sphere([0.0; 3], 1.0, 0.5, 1.0));
    let it = scene.integrator;
    for heuristic in [MisHeuristic::Power, MisHeuristic::Balance] {
        let bdpt = Bdpt {
            max_depth: it.max_depth,
            rr_depth: it.rr_depth,
            heuristic,
        };
        let (mean, se) = batched_mean(&scene, &bdpt, 16, BATCHES);
        for c in 0..3 {
            assert!(
                (mean[c] - 2.0).abs() < 4.0 * se[c] + 1e-5,
                "{heuristic:?} channel {c}: {} ± {}",
                mean[c],
                se[c]
            );
            assert!(4.0 * se[c] < 0.02, "{heuristic:?}: se {} too large", se[c]);
        }
    }
}

#[test]
fn bdpt_point_light_on_a_plane_matches_the_closed_form() {
    // A diffuse plane under a point light, seen by a narrow camera, direct
    // light only: L = ρ/π · I h / d³ at the plane point a pixel sees (the
    // same closed form as the PT/LT test in tests/render.rs). Techniques
    // (1, 2) and (2, 1) share these paths through MIS.
    let (scene, expected) = point_light_on_a_plane();
    let it = scene.integrator;
    for heuristic in [MisHeuristic::Power, MisHeuristic::Balance] {
        let bdpt = Bdpt {
            max_depth: it.max_depth,
            rr_depth: it.rr_depth,
            heuristic,
        };
        let (mean, se) = batched_mean(&scene, &bdpt, 16, BATCHES);
        eprintln!("{heuristic:?}: {mean:?} ± {se:?}, expected {expected}");
        for c in 0..3 {
            assert!(
                (mean[c] - expected).abs() < 4.0 * se[c] + 1e-4 * expected,
                "{heuristic:?} channel {c}: {} vs {expected} (se {})",
                mean[c],
                se[c]
            );
            assert!(4.0 * se[c] < 0.01 * expected, "se {} too large", se[c]);
        }
    }
}

#[test]
fn bdpt_matches_pt_with_disk_and_sphere_emitters() {
    // Disk and sphere emitters (the same scene as the PT/LT test in
    // tests/render.rs): the light-subpath origins, the s = 1 light samples
    // (cone sampling for the sphere: the MIS densities assume area
    // sampling, which changes the weights' quality, not their sum) and
    // camera hits on curved emitters.
    let scene = load(
        r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="4"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="50"/>
        <transform name="to_world"><lookat origin="0,-3,2.5" target="0,0,0" up="0,0,1"/></transform>
        <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="18"/></film>
    </sensor>
    <shape type="rectangle">
        <transform name="to_world"><scale value="3"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.5, 0.4"/></bsdf>
    </shape>
    <shape type="disk">
        <transform name="to_world">
            <scale x="0.6" y="0.3" z="1"/><rotate x="1" angle="180"/><translate z="1.5"/>
        </transform>
        <emitter type="area"><rgb name="radiance" value="4, 4, 3"/></emitter>
    </shape>
    <shape type="disk">
        <transform name="to_world"><scale value="0.5"/><translate x="0.8" y="0.4" z="0.3"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.7, 0.3"/></bsdf>
    </shape>
    <shape type="sphere">
        <point name="center" x="-1.2" y="2.5" z="0.8"/>
        <float name="radius" value="0.25"/>
        <emitter type="area"><rgb name="radiance" value="6, 2, 2"/></emitter>
    </shape>
    <shape type="cube">
        <transform name="to_world"><scale value="0.3"/><translate x="-0.5" z="0.3"/></transform>
    </shape>
</scene>"#,
    );
    check_agreement(
        &scene,
        "disk-sphere-emitters",
        512,
        256,
        &[MisHeuristic::Power],
        0.01,
    );
}
