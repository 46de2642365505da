//! End-to-end renders checked against analytic answers and against each
//! other: furnace tests (PT and LT, at several scene scales), PT vs LT with
//! disk and sphere emitters, and bit-identical images across thread counts.
//! PT against LT on the repo's Cornell variants is `agree_pt_lt.rs`.
//!
//! Tolerances come from standard errors measured in the test itself: a
//! scene is rendered as K = [`BATCHES`] independent batches (different
//! seeds), the standard error of the image mean is sd(batch means)/√K, and a
//! result passes when it lies within 4 standard errors. With the standard
//! error itself estimated, (mean − truth)/se follows Student's t with K − 1
//! degrees of freedom: for K = 32 the false-failure rate of the 4-se bound
//! is about 4e-4 per check (for K = 8 it was about 5e-3, and the checks
//! flipped whenever the random streams changed). The seeds are fixed, so
//! the test is deterministic.

mod common;

use common::{furnace_sphere, image_mean, load_str as load, mean_se, point_light_on_a_plane};
use mcmc_render::color::Rgb;
use mcmc_render::integrators::Integrator;
use mcmc_render::integrators::lt::LightTracer;
use mcmc_render::integrators::pt::PathTracer;
use mcmc_render::observer::NoObserver;
use mcmc_render::render::{RenderSettings, render};
use mcmc_render::scene::Scene;
use std::collections::HashMap;
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// Independent batches per estimate (see the module documentation).
const BATCHES: u64 = 32;

fn render_image(
    scene: &Scene,
    integ: &dyn Integrator,
    spp: u32,
    seed: u64,
    threads: usize,
) -> Vec<Rgb> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let settings = RenderSettings {
        spp: Some(spp),
        time_budget: None,
        seed,
    };
    let stop = AtomicBool::new(false);
    let r = pool.install(|| render(scene, integ, &settings, &stop, &NoObserver));
    assert_eq!(r.spp_done, spp as u64);
    assert_eq!(r.stats.nonfinite, 0, "non-finite samples");
    r.image()
}

/// Mean and standard error (per channel) of the image mean over `k` independent batches.
fn batched_mean(scene: &Scene, integ: &dyn Integrator, spp: u32, k: u64) -> ([f64; 3], [f64; 3]) {
    let means: Vec<[f64; 3]> = (0..k)
        .map(|seed| image_mean(&render_image(scene, integ, spp, 1000 + seed, 2)))
        .collect();
    mean_se(&means)
}

/// The same with a cube made of triangles (exercises triangle hits and
/// triangle-mesh light sampling).
fn furnace_cube(albedo: f32, le: f32) -> String {
    format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="70"/>
        <transform name="to_world"><lookat origin="0.1,0.2,-0.3" target="0.5,0.4,1" up="0,1,0"/></transform>
        <film type="hdrfilm">
            <integer name="width" value="16"/><integer name="height" value="12"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <shape type="cube">
        <transform name="to_world"><scale value="2"/><rotate y="1" angle="30"/></transform>
        <boolean name="flip_normals" value="true"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="{albedo}"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="{le}"/></emitter>
    </shape>
</scene>"#
    )
}

fn check_furnace(scene: &Scene, expected: f64, what: &str) {
    let it = scene.integrator;
    let pt = PathTracer {
        max_depth: it.max_depth,
        rr_depth: it.rr_depth,
    };
    let lt = LightTracer {
        max_depth: it.max_depth,
        rr_depth: it.rr_depth,
    };
    // Light tracing spreads each path over the whole image, so it needs
    // more paths per pixel for the same standard error.
    for (name, integ, spp) in [
        ("pt", &pt as &dyn Integrator, 16),
        ("lt", &lt as &dyn Integrator, 256),
    ] {
        let (mean, se) = batched_mean(scene, integ, spp / 4, BATCHES);
        for c in 0..3 {
            let err = (mean[c] - expected).abs();
            assert!(
                err < 4.0 * se[c] + 1e-5 * expected,
                "{what} {name} channel {c}: mean {} expected {expected} (se {})",
                mean[c],
                se[c]
            );
            // The test must be able to see a 2% error.
            assert!(
                4.0 * se[c] < 0.02 * expected,
                "{what} {name}: se {} too large",
                se[c]
            );
        }
    }
}

#[test]
fn furnace_sphere_matches_le_over_one_minus_albedo() {
    // L = Le / (1 − a) = 1 / 0.5 = 2; unbounded depth with Russian roulette.
    check_furnace(
        &load(&furnace_sphere([0.0; 3], 1.0, 0.5, 1.0)),
        2.0,
        "unit sphere",
    );
}

#[test]
fn furnace_holds_at_large_and_small_scales() {
    // Same furnace far from the origin and huge, then tiny: a fixed
    // self-intersection epsilon would either leak or shadow one of them.
    check_furnace(
        &load(&furnace_sphere([3.0e4, -2.0e4, 1.0e4], 5.0e3, 0.3, 0.7)),
        1.0,
        "large sphere",
    );
    check_furnace(
        &load(&furnace_sphere([1.0e-3, 2.0e-3, -1.0e-3], 1.0e-4, 0.3, 0.7)),
        1.0,
        "tiny sphere",
    );
}

#[test]
fn furnace_triangle_cube() {
    check_furnace(&load(&furnace_cube(0.6, 0.8)), 2.0, "cube");
}

fn cornell(res: u32, look_y: f32) -> Scene {
    let mut defines = HashMap::new();
    defines.insert("res".to_string(), res.to_string());
    defines.insert("look_y".to_string(), look_y.to_string());
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/scenes/cornell-box.xml");
    Scene::load(&path, &defines).expect("cornell box loads")
}

#[test]
fn images_are_bit_identical_across_thread_counts() {
    let scene = cornell(40, 0.0);
    let it = scene.integrator;
    let pt = PathTracer {
        max_depth: it.max_depth,
        rr_depth: it.rr_depth,
    };
    let lt = LightTracer {
        max_depth: it.max_depth,
        rr_depth: it.rr_depth,
    };
    for integ in [&pt as &dyn Integrator, &lt as &dyn Integrator] {
        let one = render_image(&scene, integ, 5, 42, 1);
        let three = render_image(&scene, integ, 5, 42, 3);
        let eight = render_image(&scene, integ, 5, 42, 8);
        let bits = |img: &[Rgb]| -> Vec<u32> {
            img.iter()
                .flat_map(|p| [p.r.to_bits(), p.g.to_bits(), p.b.to_bits()])
                .collect()
        };
        assert!(
            bits(&one) == bits(&three),
            "{}: 1 vs 3 threads differ",
            integ.name()
        );
        assert!(
            bits(&one) == bits(&eight),
            "{}: 1 vs 8 threads differ",
            integ.name()
        );
        // And a different seed gives a different image (the seed is used).
        let other = render_image(&scene, integ, 5, 43, 2);
        assert!(bits(&one) != bits(&other), "{}: seed ignored", integ.name());
    }
}

/// A diffuse plane under a point light, seen by a narrow camera: direct
/// light only, so every pixel has the closed form
/// `L = ρ/π · I cos θ / d² = ρ/π · I h / d³` at the plane point it sees.
#[test]
fn point_light_on_a_plane_matches_the_closed_form() {
    let (scene, expected) = point_light_on_a_plane();
    let it = scene.integrator;
    let pt = PathTracer {
        max_depth: it.max_depth,
        rr_depth: it.rr_depth,
    };
    let lt = LightTracer {
        max_depth: it.max_depth,
        rr_depth: it.rr_depth,
    };
    for (name, integ, spp) in [
        ("pt", &pt as &dyn Integrator, 16),
        // Most light paths leave the narrow view, hence many more.
        ("lt", &lt as &dyn Integrator, 2048),
    ] {
        let (mean, se) = batched_mean(&scene, integ, spp / 4, BATCHES);
        for c in 0..3 {
            assert!(
                (mean[c] - expected).abs() < 4.0 * se[c] + 1e-4 * expected,
                "{name} channel {c}: {} vs {expected} (se {})",
                mean[c],
                se[c]
            );
            // The test must be able to see a 2% error.
            assert!(
                4.0 * se[c] < 0.02 * expected,
                "{name}: se {} too large",
                se[c]
            );
        }
    }
}

/// Disk and sphere emitters (sampled by area from the path tracer, and as
/// light-path origins by the light tracer) and a disk hit by rays: the two
/// integrators must agree on the image mean within their noise.
#[test]
fn pt_and_lt_agree_with_disk_and_sphere_emitters() {
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
    let it = scene.integrator;
    let pt = PathTracer {
        max_depth: it.max_depth,
        rr_depth: it.rr_depth,
    };
    let lt = LightTracer {
        max_depth: it.max_depth,
        rr_depth: it.rr_depth,
    };
    let (mp, sp) = batched_mean(&scene, &pt, 16, BATCHES);
    let (ml, sl) = batched_mean(&scene, &lt, 64, BATCHES);
    for c in 0..3 {
        let sigma = (sp[c] * sp[c] + sl[c] * sl[c]).sqrt();
        assert!(
            (ml[c] - mp[c]).abs() < 4.0 * sigma,
            "channel {c}: pt {} ± {}, lt {} ± {}",
            mp[c],
            sp[c],
            ml[c],
            sl[c]
        );
        assert!(
            4.0 * sigma < 0.03 * mp[c],
            "channel {c}: noise too large ({sigma} vs {})",
            mp[c]
        );
    }
}

/// Next-event estimation towards a sphere light (cone sampling) estimates
/// the irradiance of a point facing the sphere's centre exactly:
/// `E = π L sin²θmax` (Lambertian sphere). Also from inside a sphere the
/// area-sampling fallback must give `E = π L`.
#[test]
fn sphere_light_sampling_gives_the_analytic_irradiance() {
    use mcmc_render::sampling::RandomSource;
    struct Lcg(u64);
    impl RandomSource for Lcg {
        fn next_1d(&mut self) -> f32 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((self.0 >> 40) as f32) / (1u64 << 24) as f32
        }
    }
    let scene = load(
        r#"<scene version="3.0.0">
    <sensor type="perspective"/>
    <shape type="sphere">
        <point name="center" x="0" y="0" z="3"/><float name="radius" value="0.5"/>
        <emitter type="area"><rgb name="radiance" value="2"/></emitter>
    </shape>
</scene>"#,
    );
    let n = 200_000;
    for (p, normal, expected) in [
        // Outside: sin²θmax = (0.5/3)².
        (
            glam::Vec3::ZERO,
            glam::Vec3::Z,
            std::f64::consts::PI * 2.0 * (0.5f64 / 3.0).powi(2),
        ),
        // Inside (the sphere emits outwards, so nothing reaches an inner point).
        (glam::Vec3::new(0.0, 0.1, 3.0), glam::Vec3::Z, 0.0),
    ] {
        let mut src = Lcg(9);
        let mut sum = 0.0f64;
        let mut sum2 = 0.0f64;
        for _ in 0..n {
            let u_sel = src.next_1d();
            let u = src.next_2d();
            let v = match scene.lights.sample_direct(&scene.geometry, p, u_sel, u) {
                Some(ds) => (ds.le.r * ds.wi.dot(normal).max(0.0) / ds.pdf) as f64,
                None => 0.0,
            };
            sum += v;
            sum2 += v * v;
        }
        let mean = sum / n as f64;
        let se = ((sum2 / n as f64 - mean * mean).max(0.0) / n as f64).sqrt();
        assert!(
            (mean - expected).abs() <= 4.0 * se + 1e-4 * expected.max(1e-6),
            "E = {mean} ± {se}, expected {expected}"
        );
    }
}
