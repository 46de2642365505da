//! The inverse samplers of `mcmc_render::inverse` (spec seed001 §2, §11):
//! forward ∘ inverse is the identity on the numbers each routine uses, over
//! 1e5 random inputs per routine plus the extremes (0 and 1 − ε, grazing
//! emission directions), and where the forward map is many-to-one (light
//! selection, roulette) the inverse's pushforward of uniform numbers is
//! uniform (chi-square), with a control inverse that is not and must fail.
//! Emitters at infinity (issue 18 × 13): the environment's direction
//! (tabulated map, `constant`), a directional light's (no numbers) and the
//! disk a light walk from infinity starts on.

mod common;

use common::{chi_square_p_value, load_str, repo_scene, sky_scene};
use glam::{Vec2, Vec3};
use mcmc_render::inverse::{
    area_point_to_square, direct_point_to_square, disk_to_square, emission_direction_to_square,
    infinite_direction_to_square, light_selection, raster_to_square, roulette, triangle_to_square,
    uniform_sphere_to_square,
};
use mcmc_render::light::Light;
use mcmc_render::sampling::{IndependentSource, ONE_MINUS_EPSILON, RandomSource};
use mcmc_render::scene::Scene;
use mcmc_render::warp;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

const N: usize = 100_000;

/// `N` uniform pairs, the first ones at the corners (0 and 1 − ε).
fn inputs(seed: u64) -> Vec<(f32, f32)> {
    let e = ONE_MINUS_EPSILON;
    let mut v = vec![(0.0, 0.0), (0.0, e), (e, 0.0), (e, e), (0.5, e), (e, 0.5)];
    let mut src = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(seed));
    while v.len() < N {
        v.push(src.next_2d());
    }
    v
}

/// Distance on the circle of `[0, 1)` (φ/2π wraps).
fn circ(a: f32, b: f32) -> f32 {
    let d = (a - b).abs();
    d.min(1.0 - d)
}

/// Emitters of every kind with different powers: a cube mesh (12
/// triangles, the area CDF reused), a sphere, a disk, an isotropic point
/// light and a spot light, in a closed box, with a thin lens.
fn emitters() -> Scene {
    load_str(
        r#"<scene version="3.0.0">
    <sensor type="thinlens">
        <float name="fov" value="50"/>
        <float name="aperture_radius" value="0.1"/>
        <float name="focus_distance" value="4"/>
        <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
        <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="16"/></film>
    </sensor>
    <shape type="cube">
        <transform name="to_world"><scale value="0.3"/><rotate x="1" y="1" z="0" angle="30"/><translate x="-1" y="1" z="0"/></transform>
        <emitter type="area"><rgb name="radiance" value="2, 3, 1"/></emitter>
    </shape>
    <shape type="sphere">
        <point name="center" x="1" y="1" z="-1"/><float name="radius" value="0.25"/>
        <emitter type="area"><rgb name="radiance" value="5"/></emitter>
    </shape>
    <shape type="disk">
        <transform name="to_world"><scale value="0.4"/><rotate x="1" angle="70"/><translate x="0" y="-1" z="-0.5"/></transform>
        <emitter type="area"><rgb name="radiance" value="1, 1, 4"/></emitter>
    </shape>
    <emitter type="point"><rgb name="intensity" value="3"/><point name="position" x="0" y="0.5" z="1"/></emitter>
    <emitter type="spot">
        <rgb name="intensity" value="20"/><float name="cutoff_angle" value="30"/><float name="beam_width" value="18"/>
        <transform name="to_world"><lookat origin="-1.5, 1, 1.5" target="0.3, 0, -0.5" up="0, 1, 0"/></transform>
    </emitter>
    <shape type="cube">
        <transform name="to_world"><scale value="3"/></transform>
        <boolean name="flip_normals" value="true"/>
        <bsdf type="diffuse"/>
    </shape>
</scene>"#,
    )
}

#[test]
fn warps_round_trip() {
    let (mut worst_s, mut worst_d, mut worst_t) = (0.0f32, 0.0f32, 0.0f32);
    for &u in &inputs(1) {
        // Sphere: u₁ is meaningless at the poles.
        let w = warp::uniform_sphere(u);
        let b = uniform_sphere_to_square(w);
        let w2 = warp::uniform_sphere(b);
        assert!(
            (w2 - w).length() < 1e-5,
            "sphere {u:?} -> {w} -> {b:?} -> {w2}"
        );
        if (1.0 - w.z * w.z) > 1e-6 {
            worst_s = worst_s.max((b.0 - u.0).abs()).max(circ(b.1, u.1));
        }
        // Concentric disk: the centre has no angle.
        let d = warp::concentric_disk(u);
        let b = disk_to_square(d);
        let d2 = warp::concentric_disk(b);
        assert!((d2 - d).length() < 1e-5, "disk {u:?} -> {d} -> {b:?}");
        if d.length() > 1e-3 {
            worst_d = worst_d.max((b.0 - u.0).abs()).max((b.1 - u.1).abs());
        }
        // Triangle: u₁ is meaningless at the vertex b₀ = 1.
        let (_, b1, b2) = warp::uniform_triangle(u);
        let b = triangle_to_square(f64::from(b1), f64::from(b2));
        let (_, c1, c2) = warp::uniform_triangle(b);
        assert!(
            (c1 - b1).abs() < 1e-6 && (c2 - b2).abs() < 1e-6,
            "triangle {u:?}"
        );
        if u.0 > 1e-6 {
            worst_t = worst_t.max((b.0 - u.0).abs()).max((b.1 - u.1).abs());
        }
    }
    eprintln!("max |u' - u|: sphere {worst_s:e}, disk {worst_d:e}, triangle {worst_t:e}");
    assert!(worst_s < 1e-4 && worst_d < 1e-4 && worst_t < 1e-4);
}

/// Emission samples of every light kind: the inverse's numbers give the
/// same light, point and direction back, and equal the forward numbers on
/// the dimensions the light uses (position: area lights; direction: all).
#[test]
fn emission_round_trips_on_every_emitter_kind() {
    let scene = emitters();
    let lights = &scene.lights;
    let mut rng = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(7));
    let mut src = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(8));
    let mut per_light = vec![0usize; lights.lights.len()];
    let mut worst = 0.0f32;
    let dirs = inputs(3);
    for (k, &u_pos) in inputs(2).iter().enumerate() {
        let u_sel = src.next_1d();
        // Every tenth direction grazes the emitter (the disk's rim).
        let mut u_dir = dirs[k];
        if k % 10 == 0 {
            let r = 1.0 - 1e-4 * u_dir.0;
            u_dir = ((0.5 + 0.5 * r).min(ONE_MINUS_EPSILON), u_dir.1);
        }
        let Some(es) = lights.sample_emission(&scene.geometry, u_sel, u_pos, u_dir) else {
            continue;
        };
        let (i, _) = lights.select(u_sel).unwrap();
        per_light[i as usize] += 1;
        let xi = f64::from(rng.next_1d());
        let sel = light_selection(lights, i, xi).expect("selection inverse");
        let area = matches!(lights.lights[i as usize], Light::Area { .. });
        let pos = if area {
            area_point_to_square(&scene, i, &es.p).expect("position inverse")
        } else {
            (0.25, 0.75) // unused by point lights: any numbers
        };
        let Some(dir) = emission_direction_to_square(&scene, i, &es.p, es.dir) else {
            panic!(
                "light {i}: no direction inverse for {u_dir:?} -> {:?}",
                es.dir
            );
        };
        let back = lights
            .sample_emission(&scene.geometry, sel, pos, dir)
            .expect("forward of the inverse");
        assert_eq!(lights.select(sel).unwrap().0, i);
        let scale = es.p.p.length() + 1.0;
        assert!(
            (back.p.p - es.p.p).length() < 1e-5 * scale,
            "light {i}: {:?} vs {:?} (u_pos {u_pos:?} -> {pos:?})",
            back.p.p,
            es.p.p
        );
        // At grazing angles the cosine warp is ill-conditioned (dz/du ~ 1/z
        // at the disk's rim): one f32 step of u moves z by ~1e-4 there.
        let tol = if es.dir.dot(es.p.ns).abs() < 1e-2 {
            1e-3
        } else {
            // f32 warps (atan2, square roots): ~1e-5 observed.
            5e-5
        };
        assert!(
            (back.dir - es.dir).length() < tol,
            "light {i} direction {:?} vs {:?}",
            back.dir,
            es.dir
        );
        if area && u_pos.0 > 1e-5 && u_pos.0 < 1.0 - 1e-5 {
            // The sphere's and the disk's u₁ is an angle (wraps); the
            // cube's u₀ is rescaled through the triangle CDF (f32).
            worst = worst.max((pos.0 - u_pos.0).abs()).max(circ(pos.1, u_pos.1));
        }
        if (0.5 - u_dir.0).abs() + (0.5 - u_dir.1).abs() > 1e-3 {
            worst = worst.max((dir.0 - u_dir.0).abs()).max(circ(dir.1, u_dir.1));
        }
    }
    eprintln!("samples per light {per_light:?}, max |u' - u| {worst:e}");
    assert!(per_light.iter().all(|&n| n > 1000), "{per_light:?}");
    assert!(worst < 2e-4, "{worst}");
}

/// Emitters at infinity: light walks from the environment map and the
/// directional light of `envmap-spheres.xml` and from the `constant` sky
/// and sun of the sky scene, and next-event samples of both environments
/// from points in the scene. The inverses give the same light, direction
/// and disk origin back, and the forward numbers on the dimensions used:
/// the disk point for every emitter at infinity (recovered from a point
/// `x_1` anywhere along the walk's first ray, as the inverse path sampler
/// sees it), the direction numbers for the environments (a directional
/// light ignores them: fresh numbers must give its one direction). The
/// map's inverse is exact inside a cell (piecewise linear CDFs); what
/// remains is `f32` rounding of the lat-long angles, ~1e-6 of a turn,
/// amplified near the poles, where `u₁` (the azimuth) is ill-defined and
/// not compared. Tolerances: directions and origins to 5e-5 (relative to
/// the disk radius; the f32 warps, as for area lights), numbers to 2e-4.
#[test]
fn emitters_at_infinity_round_trip() {
    let sky = sky_scene(8, 4, false);
    let map = repo_scene("envmap-spheres.xml", 8);
    let mut counts = [0usize; 4];
    let mut worst = 0.0f32;
    for (scene, seed) in [(&map, 21u64), (&sky, 22)] {
        let lights = &scene.lights;
        let r = lights.scene_radius();
        let mut src = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(seed));
        let dirs = inputs(seed + 100);
        for (k, &u_pos) in inputs(seed).iter().enumerate() {
            let u_sel = src.next_1d();
            let u_dir = dirs[k];
            let (i, _) = lights.select(u_sel).unwrap();
            let directional = matches!(lights.lights[i as usize], Light::Directional { .. });
            // Light walks (s ≥ 2): origin on the disk, direction −ω.
            if let Some(es) = lights.sample_emission(&scene.geometry, u_sel, u_pos, u_dir) {
                assert!(es.at_infinity, "light {i} is not at infinity");
                let omega = -es.dir;
                let x1 = es.p.p + es.dir * (2.0 * r * src.next_1d());
                let pos = lights
                    .infinite_origin_to_square(es.dir, x1)
                    .unwrap_or_else(|| panic!("no disk inverse for {u_pos:?}"));
                let dir = match infinite_direction_to_square(scene, i, omega) {
                    Some(Some(d)) => d,
                    Some(None) => {
                        assert!(directional, "light {i} ignores its direction numbers");
                        src.next_2d()
                    }
                    None => panic!("light {i}: no direction inverse for {u_dir:?}"),
                };
                let sel = light_selection(lights, i, f64::from(src.next_1d())).unwrap();
                let back = lights
                    .sample_emission(&scene.geometry, sel, pos, dir)
                    .expect("forward of the inverse");
                let dp = (back.p.p - es.p.p).length() / r;
                let dd = (back.dir - es.dir).length();
                assert!(
                    dp < 5e-5 && dd < 5e-5,
                    "light {i}: {u_pos:?} {u_dir:?} -> {pos:?} {dir:?}: origin moved {dp:e}, direction {dd:e}"
                );
                if warp::concentric_disk(u_pos).length() > 1e-3 {
                    worst = worst
                        .max((pos.0 - u_pos.0).abs())
                        .max((pos.1 - u_pos.1).abs());
                }
                // Away from the poles (the map's ±y, the sphere's ±z) the
                // azimuth number is defined; it wraps (the map's u₀, the
                // sphere's u₁); for the polar one `circ` equals |u' − u|
                // below ½, far above the bound.
                if !directional && omega.y.abs() < 0.999 && omega.z.abs() < 0.999 {
                    worst = worst.max(circ(dir.0, u_dir.0)).max(circ(dir.1, u_dir.1));
                }
                counts[usize::from(directional)] += 1;
            }
            // Next-event estimation (s = 1) from a point in the scene.
            let from = Vec3::new(
                2.0 * src.next_1d() - 1.0,
                src.next_1d(),
                2.0 * src.next_1d() - 1.0,
            );
            let Some(ds) = lights.sample_direct(&scene.geometry, from, u_sel, u_pos) else {
                continue;
            };
            assert!(ds.at_infinity);
            match infinite_direction_to_square(scene, i, ds.wi) {
                Some(Some(b)) => {
                    let back = lights
                        .sample_direct(&scene.geometry, from, u_sel, b)
                        .expect("forward of the inverse");
                    assert!((back.wi - ds.wi).length() < 5e-5, "{u_pos:?} -> {b:?}");
                    counts[2] += 1;
                }
                Some(None) => {
                    assert!(directional);
                    counts[3] += 1;
                }
                None => panic!("light {i}: no next-event inverse for {u_pos:?}"),
            }
        }
    }
    eprintln!(
        "emission from environments {}, from directional lights {}, next-event environment {}, directional {}; max |u' - u| {worst:e}",
        counts[0], counts[1], counts[2], counts[3]
    );
    assert!(counts.iter().all(|&n| n > 10_000), "{counts:?}");
    assert!(worst < 2e-4, "{worst}");
    // A point outside the disk's cylinder has no origin.
    let r = map.lights.scene_radius();
    assert!(
        map.lights
            .infinite_origin_to_square(Vec3::Y, Vec3::new(3.0 * r, 0.0, 0.0))
            .is_none()
    );
}

/// Next-event estimation's light points (BDPT's `s = 1`): area lights
/// round trip, and so does the sphere seen from outside (cone sampling)
/// in both of its branches: wide cones from points in the box, tiny cones
/// (`sin² θmax < 1e-3`, uniform in `sin² θ`) from points 20–40 away.
/// Point lights use no numbers. Tolerances: positions to 1e-5 of the
/// scene scale (f32 warps, as the other emitters), except where the cone
/// map is ill-conditioned: at its silhouette (`u₀ → 1`, where
/// `dα/du₀ ~ 1/√(1 − u₀)`) one f32 step of `u₀` moves the point by
/// ~√ε·r, so there 1e-3 of the radius; numbers come back to 1e-4 where
/// the map is well-conditioned (`u₀ < 0.999`, azimuth away from the
/// cone's axis).
#[test]
fn direct_light_points_round_trip() {
    let scene = emitters();
    let lights = &scene.lights;
    let mut src = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(9));
    let (mut area, mut cones, mut tiny, mut cone_refused) = (0usize, 0usize, 0usize, 0usize);
    let (mut worst_pos, mut worst_u) = (0.0f32, 0.0f32);
    for (k, &u) in inputs(4).iter().enumerate() {
        let box_point = Vec3::new(
            2.0 * src.next_1d() - 1.0,
            2.0 * src.next_1d() - 1.0,
            2.0 * src.next_1d() - 1.0,
        );
        let far = k % 4 == 3;
        let from = if far {
            box_point.normalize_or(Vec3::Z) * (20.0 + 20.0 * src.next_1d())
        } else {
            box_point
        };
        let u_sel = src.next_1d();
        let Some(ds) = lights.sample_direct(&scene.geometry, from, u_sel, u) else {
            continue;
        };
        let (i, _) = lights.select(u_sel).unwrap();
        let cone = match lights.lights[i as usize] {
            Light::Area {
                sphere: Some((c, r)),
                ..
            } => ((from - c).length_squared() > r * r * 1.0001).then_some((c, r)),
            _ => None,
        };
        match direct_point_to_square(&scene, i, from, &ds.p) {
            Some(Some(b)) => {
                let Some(back) = lights.sample_direct(&scene.geometry, from, u_sel, b) else {
                    panic!("light {i} from {from}: {:?} {u:?} -> {b:?}", ds.p.p);
                };
                let d = (back.p.p - ds.p.p).length();
                let Some((c, r)) = cone else {
                    assert!(d < 1e-5 * (ds.p.p.length() + 1.0));
                    area += 1;
                    continue;
                };
                cones += 1;
                let sin2_max = r * r / (from - c).length_squared();
                tiny += usize::from(sin2_max < 1e-3);
                if u.0 < 0.999 {
                    assert!(
                        d < 1e-5 * (ds.p.p.length() + 1.0),
                        "cone from {from}: {u:?} -> {b:?}, moved {d}"
                    );
                    worst_pos = worst_pos.max(d / (ds.p.p.length() + 1.0));
                    // The azimuth is undefined on the axis.
                    let off_axis = (ds.p.p - c).normalize().dot((from - c).normalize()) < 0.9999;
                    let du = (b.0 - u.0)
                        .abs()
                        .max(if off_axis { circ(b.1, u.1) } else { 0.0 });
                    assert!(du < 1e-4, "cone numbers {u:?} -> {b:?}");
                    worst_u = worst_u.max(du);
                } else {
                    assert!(
                        d < 1e-3 * r,
                        "cone rim from {from}: {u:?} -> {b:?}, moved {d}"
                    );
                }
            }
            Some(None) => assert!(matches!(lights.lights[i as usize], Light::Point { .. })),
            None => {
                assert!(cone.is_some(), "light {i} refused from {from}");
                cone_refused += 1;
            }
        }
    }
    eprintln!(
        "area round trips {area}, cone round trips {cones} ({tiny} tiny cones, {cone_refused} refused); worst position {worst_pos:.2e}, numbers {worst_u:.2e}"
    );
    assert!(area > 5000 && cones > 2000 && tiny > 500);
    // A point the forward map produced lies on the reachable cap; only
    // f32 rounding at the silhouette may put it beyond.
    assert!(cone_refused as f64 <= 1e-3 * cones as f64);
}

/// Chi-square p-value of numbers in [0, 1) against the uniform law, on 64
/// bins (the last one is the helper's "rest" cell).
fn uniform_p_value(us: &[f32]) -> f64 {
    let mut h = vec![0u64; 64];
    for &u in us {
        h[((u * 64.0) as usize).min(63)] += 1;
    }
    chi_square_p_value(&h[..63], &[1.0 / 64.0; 63], us.len())
}

/// Light selection is many-to-one: forward then inverse (a fresh uniform
/// inside the selected light's interval) must give uniform numbers again,
/// and the same light. A control that puts the number at the interval's
/// midpoint (a valid preimage, wrong density) must fail the test.
#[test]
fn light_selection_inverse_pushes_uniform_to_uniform() {
    let scene = emitters();
    let lights = &scene.lights;
    let mut src = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(11));
    let mut rng = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(12));
    let (mut good, mut control) = (Vec::with_capacity(N), Vec::with_capacity(N));
    for _ in 0..N {
        let (i, _) = lights.select(src.next_1d()).unwrap();
        let u = light_selection(lights, i, f64::from(rng.next_1d())).unwrap();
        assert_eq!(lights.select(u).unwrap().0, i);
        good.push(u);
        let (lo, hi) = lights.selection_interval(i);
        control.push(0.5 * (lo + hi));
    }
    let p = uniform_p_value(&good);
    let p_control = uniform_p_value(&control);
    eprintln!("selection: p = {p:.3}, control p = {p_control:e}");
    // Fixed seeds: p > 1e-3 is a false-alarm rate of 1e-3 for a correct
    // inverse; the control's histogram has 5 occupied bins of 64.
    assert!(p > 1e-3 && p_control < 1e-9);
}

/// Russian roulette: the inverse of "continue when u < q" reproduces the
/// decision and pushes uniform numbers to uniform ones, for q near 0, ½,
/// 1; the control (always the interval's left end) fails.
#[test]
fn roulette_inverse_pushes_uniform_to_uniform() {
    let mut src = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(13));
    let mut rng = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(14));
    for q in [1e-3f32, 0.5, 0.95, 1.0] {
        let (mut good, mut control) = (Vec::with_capacity(N), Vec::with_capacity(N));
        for _ in 0..N {
            let u = src.next_1d();
            let cont = u < q;
            let v = roulette(q, cont, f64::from(rng.next_1d())).unwrap();
            assert_eq!(v < q, cont, "q {q}");
            good.push(v);
            control.push(if cont { 0.0 } else { q });
        }
        let p = uniform_p_value(&good);
        let pc = uniform_p_value(&control);
        eprintln!("roulette q = {q}: p = {p:.3}, control p = {pc:e}");
        assert!(p > 1e-3 && pc < 1e-9, "q {q}");
    }
}

/// The camera sample: raster position (uniform over the image, as MMLT
/// draws it) and the thin lens's point round trip through the camera's
/// inverse.
#[test]
fn camera_raster_and_lens_round_trip() {
    let scene = emitters();
    let cam = &scene.camera;
    let (w, h) = (scene.film.width as f32, scene.film.height as f32);
    let lens = inputs(6);
    let mut worst = 0.0f32;
    for (k, &u) in inputs(5).iter().enumerate() {
        let raster = Vec2::new(
            (u.0 * w).min(w * (1.0 - f32::EPSILON)),
            (u.1 * h).min(h * (1.0 - f32::EPSILON)),
        );
        let ray = cam.generate_ray_lens(raster, lens[k]);
        let (r2, ul) = cam.invert(ray.o, ray.d).expect("camera inverse");
        let back = raster_to_square(&scene, r2);
        assert!((r2 - raster).length() < 2e-3, "{raster} vs {r2}");
        let ray2 = cam.generate_ray_lens(r2, ul);
        assert!((ray2.o - ray.o).length() < 1e-5 && (ray2.d - ray.d).length() < 1e-5);
        worst = worst.max((back.0 - u.0).abs()).max((back.1 - u.1).abs());
    }
    eprintln!("raster max |u' - u| {worst:e}");
    assert!(worst < 1e-4);
}

/// BSDF inverses at the extremes the fused chain meets: roughness 1e-4
/// and 1 (GGX and Beckmann, conductors and dielectrics) and η = 1.001
/// (smooth and rough glass, where Fresnel reflection is ~1e-7 and the
/// reflection interval nearly empty). Sampling with the inverse's numbers
/// (the lobe number drawn inside its interval, as the fused inverse does)
/// gives the same lobe and direction back; the direction numbers come back
/// to a tolerance set by the map's conditioning (~1/α² at small α, where u
/// is ill-conditioned but the direction is what matters).
#[test]
fn bsdf_inverses_at_extreme_roughness_and_eta_near_one() {
    use mcmc_render::bsdf::{Bsdf, BsdfDesc, MicrofacetKind, TransportMode};
    use mcmc_render::color::Rgb;
    use mcmc_render::inverse::in_interval;
    let mut models: Vec<(String, BsdfDesc)> = Vec::new();
    for kind in [MicrofacetKind::Ggx, MicrofacetKind::Beckmann] {
        for alpha in [1e-4f32, 1.0] {
            models.push((
                format!("roughconductor {kind:?} {alpha}"),
                BsdfDesc::RoughConductor {
                    distribution: kind,
                    alpha_u: alpha,
                    alpha_v: alpha,
                    eta: Rgb::splat(0.2),
                    k: Rgb::splat(3.0),
                    specular_reflectance: Rgb::WHITE,
                },
            ));
            for eta in [1.5f32, 1.001] {
                models.push((
                    format!("roughdielectric {kind:?} {alpha} eta {eta}"),
                    BsdfDesc::RoughDielectric {
                        distribution: kind,
                        alpha_u: alpha,
                        alpha_v: alpha,
                        int_ior: eta,
                        ext_ior: 1.0,
                        specular_reflectance: Rgb::WHITE,
                        specular_transmittance: Rgb::WHITE,
                    },
                ));
            }
        }
    }
    models.push((
        "dielectric eta 1.001".into(),
        BsdfDesc::Dielectric {
            int_ior: 1.001,
            ext_ior: 1.0,
            specular_reflectance: Rgb::WHITE,
            specular_transmittance: Rgb::WHITE,
        },
    ));
    let mut src = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(21));
    for (name, desc) in models {
        let b = Bsdf::from_desc(&desc).unwrap_or_else(|e| panic!("{name}: {e}"));
        let (mut n, mut worst, mut none) = (0usize, 0.0f32, 0usize);
        for i in 0..N {
            // Grazing to normal incidence, both sides.
            let (a, c) = src.next_2d();
            let cos = if i % 10 == 0 {
                1e-3 * a + 1e-4
            } else {
                a.max(1e-4)
            };
            let sin = (1.0 - cos * cos).sqrt();
            let phi = std::f32::consts::TAU * c;
            let mut wo = Vec3::new(sin * phi.cos(), sin * phi.sin(), cos);
            if i % 2 == 1 && !name.starts_with("roughconductor") {
                wo.z = -wo.z;
            }
            let ul = src.next_1d();
            let u = src.next_2d();
            let Some(s) = b.sample(wo, ul, u, TransportMode::Radiance) else {
                continue;
            };
            let Some(inv) = b.invert(wo, s.wi, 0.5) else {
                none += 1;
                continue;
            };
            let Some(ul2) = in_interval(inv.u_lobe.0, inv.u_lobe.1, f64::from(src.next_1d()))
            else {
                none += 1;
                continue;
            };
            let Some(again) = b.sample(
                wo,
                ul2,
                if inv.u_used { inv.u } else { u },
                TransportMode::Radiance,
            ) else {
                none += 1;
                continue;
            };
            assert_eq!(again.wi.z > 0.0, s.wi.z > 0.0, "{name}: lobe changed");
            worst = worst.max((again.wi - s.wi).length());
            n += 1;
        }
        eprintln!("{name}: {n} round trips, {none} failed, max |Δwi| {worst:e}");
        // A failed inverse is a counted round-trip failure in the chain; it
        // must stay rare, except at α = 1e-4 where f32 cannot resolve the
        // lobe (measured and reported in docs/fused.md, not asserted).
        if !name.contains(" 0.0001") {
            assert!(none * 1000 <= N, "{name}: {none} without inverse");
            assert!(worst < 2e-3, "{name}: |Δwi| {worst}");
        }
    }
}
