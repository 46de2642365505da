//! The manifold walk of `mcmc_render::manifold` on three scenes: a plane
//! mirror, a curved mirror (a sphere) and a glass sphere (refraction in
//! and out, η = 1.5), each above a diffuse floor.
//!
//! - the Newton walk reaches targets around the endpoint with the endpoint
//!   within 1e-5 of the chain length and every half-vector constraint
//!   below 1e-5 (recomputed here from the positions);
//! - the reverse walk brings every vertex back (and a control with a loose
//!   forward tolerance is caught by the reverse check);
//! - the generalised geometry term equals a finite-difference Jacobian of
//!   ray-traced chains within 1e-3, and controls (a wrong η, a curved
//!   mirror treated as flat, a dropped Jacobian block) miss it by more;
//! - failures are classified (escaped, occluded).

use glam::{DMat2, DVec2, DVec3, Vec3};
use mcmc_render::geometry::Ray;
use mcmc_render::manifold::constraint::{
    ConstraintBlocks, constraint_values, generalized_geometry, geometry_term, tangent_map_with,
};
use mcmc_render::manifold::walk::{
    WalkConfig, WalkFailure, WalkStats, trace, trace_with_offsets, walk, walk_reversible,
};
use mcmc_render::manifold::{ManifoldVertex, Role, Specular, chain_length};
use mcmc_render::scene::Scene;
use std::path::Path;

/// A scene with a 10×10 diffuse floor at z = 0 (shape 0), a diffuse
/// ceiling at z = 4 facing down (shape 1), and `body`'s shapes (2, …).
fn scene(body: &str) -> Scene {
    scene_in(Path::new("."), body)
}

/// [`scene`] with files resolved in `dir`.
fn scene_in(dir: &Path, body: &str) -> Scene {
    let text = format!(
        r#"<scene version="3.0.0"><sensor type="perspective"/>
        <shape type="rectangle"><transform name="to_world"><scale x="5" y="5" z="1"/></transform>
            <bsdf type="diffuse"/></shape>
        <shape type="rectangle"><transform name="to_world"><scale x="5" y="5" z="1"/>
            <rotate x="1" angle="180"/><translate z="4"/></transform><bsdf type="diffuse"/></shape>
        {body}</scene>"#
    );
    Scene::load_str(&text, Path::new("manifold.xml"), dir).expect("scene loads")
}

/// Shape 2: a mirror in the plane x = 2 facing −x, 4×4; shape 3: a
/// 0.6×0.6 diffuse square at z = 0.6 around (−0.1, 1.3), an occluder.
fn plane_mirror() -> Scene {
    scene(
        r#"<shape type="rectangle"><transform name="to_world"><scale value="2"/>
            <rotate y="1" angle="-90"/><translate x="2" z="1"/></transform>
            <bsdf type="conductor"><string name="material" value="none"/></bsdf></shape>
           <shape type="rectangle"><transform name="to_world"><scale value="0.3"/>
            <translate x="-0.1" y="1.3" z="0.6"/></transform><bsdf type="diffuse"/></shape>"#,
    )
}

/// Shape 2: a mirror sphere of radius 1 at (0, 0, 1.5).
fn sphere_mirror() -> Scene {
    scene(
        r#"<shape type="sphere"><point name="center" x="0" y="0" z="1.5"/><float name="radius" value="1"/>
            <bsdf type="conductor"><string name="material" value="none"/></bsdf></shape>"#,
    )
}

/// Shape 2: a glass sphere (η = 1.5) of radius 1 at (0, 0, 1.5).
fn glass_sphere() -> Scene {
    scene(
        r#"<shape type="sphere"><point name="center" x="0" y="0" z="1.5"/><float name="radius" value="1"/>
            <bsdf type="dielectric"><float name="int_ior" value="1.5"/><float name="ext_ior" value="1"/></bsdf></shape>"#,
    )
}

/// The surface vertex hit by a ray from `o` towards `to`.
fn surface_vertex(s: &Scene, o: Vec3, to: Vec3, role: Role) -> ManifoldVertex {
    let ray = Ray::new(o, (to - o).normalize());
    let hit = s.geometry.intersect(&ray).expect("hit");
    let sp = s.geometry.surface_point(&ray, &hit);
    ManifoldVertex::at_hit(&s.geometry, &hit, sp, role).expect("regular point")
}

/// A chain from `anchor` through the point `aim` with the given roles.
fn chain_through(
    s: &Scene,
    anchor: ManifoldVertex,
    aim: Vec3,
    roles: &[Role],
) -> Vec<ManifoldVertex> {
    let dir = (aim.as_dvec3() - anchor.p()).normalize();
    let chain = trace(s, &anchor, dir, roles).expect("initial chain traces");
    assert_eq!(
        chain.last().unwrap().sp.shape,
        0,
        "the chain ends on the floor"
    );
    chain
}

const MIRROR: Role = Role::Specular(Specular::Reflect);
const GLASS: Role = Role::Specular(Specular::Refract { eta: 1.5 });

/// The three test chains: (name, scene, chain).
fn cases() -> Vec<(&'static str, Scene, Vec<ManifoldVertex>)> {
    let mut out = Vec::new();
    // Ceiling → plane mirror → floor.
    let s = plane_mirror();
    let a = surface_vertex(
        &s,
        Vec3::new(-1.0, 0.3, 3.0),
        Vec3::new(-1.0, 0.3, 4.0),
        Role::Endpoint,
    );
    let c = chain_through(&s, a, Vec3::new(2.0, 0.2, 2.0), &[MIRROR, Role::Endpoint]);
    out.push(("plane mirror", s, c));
    // Ceiling → mirror sphere → floor.
    let s = sphere_mirror();
    let a = surface_vertex(
        &s,
        Vec3::new(2.5, 0.3, 3.0),
        Vec3::new(2.5, 0.3, 4.0),
        Role::Endpoint,
    );
    let c = chain_through(&s, a, Vec3::new(0.97, 0.1, 1.69), &[MIRROR, Role::Endpoint]);
    out.push(("sphere mirror", s, c));
    // Ceiling → glass sphere (in, out) → floor.
    let s = glass_sphere();
    let a = surface_vertex(
        &s,
        Vec3::new(0.5, 0.3, 3.0),
        Vec3::new(0.5, 0.3, 4.0),
        Role::Endpoint,
    );
    let c = chain_through(
        &s,
        a,
        Vec3::new(0.3, 0.2, 2.4),
        &[GLASS, GLASS, Role::Endpoint],
    );
    out.push(("glass sphere", s, c));
    out
}

/// Largest half-vector constraint of a chain.
fn max_constraint(chain: &[ManifoldVertex]) -> f64 {
    constraint_values(chain)
        .expect("constraints defined")
        .iter()
        .map(|c| c.length())
        .fold(0.0, f64::max)
}

/// Targets on the floor around the endpoint, within `radius`, from a
/// fixed-seed generator.
fn targets(end: DVec3, radius: f64, n: usize) -> Vec<DVec3> {
    let mut next = uniforms(0x2545_f491_4f6c_dd1d);
    (0..n)
        .map(|_| {
            let (r, phi) = (radius * next().sqrt(), std::f64::consts::TAU * next());
            DVec3::new(end.x + r * phi.cos(), end.y + r * phi.sin(), 0.0)
        })
        .collect()
}

#[test]
fn walks_converge_onto_the_manifold_and_reverse_to_the_start() {
    let config = WalkConfig::default();
    for (name, s, chain) in cases() {
        let len = chain_length(&chain);
        assert!(
            max_constraint(&chain) < 1e-5,
            "{name}: start off the manifold"
        );
        let end = chain.last().unwrap().p();
        let mut stats = WalkStats::default();
        // The glass sphere's chains lie near the focus of the ball lens,
        // where the Jacobian changes fast (a fold at 0.2 from the start):
        // its targets stay closer.
        let radius = if name == "glass sphere" { 0.1 } else { 0.25 };
        for target in targets(end, radius, 20) {
            let result = walk(&s, &chain, target, &config);
            stats.record(&result);
            let w = result.unwrap_or_else(|f| panic!("{name}: walk to {target} failed: {f:?}"));
            let reached = (w.chain.last().unwrap().p() - target).length();
            assert!(
                reached <= 1e-5 * len,
                "{name}: endpoint {reached} from the target"
            );
            let c = max_constraint(&w.chain);
            assert!(c <= 1e-5, "{name}: constraint {c} after the walk");
            // Back to the start: every vertex returns.
            let back = walk(&s, &w.chain, end, &config).expect("reverse walk converges");
            let moved = back
                .chain
                .iter()
                .zip(&chain)
                .map(|(a, b)| (a.p() - b.p()).length())
                .fold(0.0, f64::max);
            assert!(
                moved <= 1e-4 * len,
                "{name}: reverse walk {moved} from the start"
            );
            assert!(walk_reversible(&s, &chain, target, &config).is_ok());
        }
        assert_eq!(stats.converged, 20);
        // Newton converges fast: a handful of projections per walk.
        assert!(
            stats.iterations <= 20 * 12,
            "{name}: {} projections",
            stats.iterations
        );
    }
}

/// Control for the reverse check: a forward walk stopped at 1e-2 of the
/// chain length leaves the path 1e-2 off, so walking back (with the same
/// loose tolerance) cannot land within 1e-6 of the start.
#[test]
fn reverse_check_rejects_an_inexact_return() {
    let loose = WalkConfig {
        tolerance: 3e-2,
        reverse_tolerance: 1e-6,
        ..WalkConfig::default()
    };
    for (name, s, chain) in cases() {
        let end = chain.last().unwrap().p();
        let target = end + DVec3::new(0.2, -0.1, 0.0);
        assert!(walk(&s, &chain, target, &loose).is_ok(), "{name}");
        assert_eq!(
            walk_reversible(&s, &chain, target, &loose).unwrap_err(),
            WalkFailure::NotReversible,
            "{name}"
        );
    }
}

/// `dσ⊥(x_0)/dA(x_{k+1})` by central differences: directions at the anchor
/// `ω(a, b) = normalize(ω_0 + a e_1 + b e_2)` (orthonormal at a = b = 0, so
/// `da db` is the solid angle there) traced to the floor, the endpoint's
/// displacement taken in its tangent basis.
///
/// Error: O(h²) truncation with h = 1e-3 rad (≤ 1e-5 relative for these
/// curvatures) plus the `f32` hit points' rounding, ~2e-7 absolute over a
/// displacement of ~2h·(distance ≈ 3) = 6e-3, i.e. ~4e-5 relative per
/// column: both far below the 1e-3 the test allows.
fn fd_geometry(s: &Scene, chain: &[ManifoldVertex]) -> f64 {
    let anchor = &chain[0];
    let roles: Vec<Role> = chain[1..].iter().map(|v| v.role).collect();
    let offsets: Vec<DVec2> = chain[1..].iter().map(|v| v.offset).collect();
    let w0 = (chain[1].p() - anchor.p()).normalize();
    let e1 = w0.any_orthonormal_vector();
    let e2 = w0.cross(e1);
    let end = chain.last().unwrap().geo;
    let h = 1e-3;
    let at = |a: f64, b: f64| {
        let d = (w0 + e1 * a + e2 * b).normalize();
        let c = trace_with_offsets(s, anchor, d, &roles, &offsets).expect("traces");
        assert_eq!(c.last().unwrap().sp.shape, end_shape(chain));
        c.last().unwrap().p()
    };
    let col = |a: f64, b: f64| {
        let dp = at(h * a, h * b) - at(-h * a, -h * b);
        DVec2::new(dp.dot(end.s), dp.dot(end.t)) / (2.0 * h)
    };
    let j = DMat2::from_cols(col(1.0, 0.0), col(0.0, 1.0));
    let cos0 = if anchor.on_surface() {
        anchor.geo.ng.dot(w0).abs()
    } else {
        1.0
    };
    cos0 / j.determinant().abs()
}

fn end_shape(chain: &[ManifoldVertex]) -> u32 {
    chain.last().unwrap().sp.shape
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

/// G from the tangent map with the blocks edited (the controls).
fn edited_geometry(
    chain: &[ManifoldVertex],
    edit: impl Fn(ConstraintBlocks) -> ConstraintBlocks,
) -> f64 {
    let x = tangent_map_with(chain, edit).expect("regular");
    geometry_term(&chain[0], &chain[1]) * x[0].determinant().abs()
}

#[test]
fn generalized_geometry_matches_finite_differences() {
    for (name, s, chain) in cases() {
        let fd = fd_geometry(&s, &chain);
        let g = generalized_geometry(&chain).expect("regular chain");
        assert!(
            rel(g, fd) < 1e-3,
            "{name}: G {g} vs finite differences {fd}"
        );
        // Also after a walk, at another point of the manifold.
        let target = chain.last().unwrap().p() + DVec3::new(-0.06, 0.05, 0.0);
        let moved = walk(&s, &chain, target, &WalkConfig::default())
            .expect("walks")
            .chain;
        let (g, fd) = (
            generalized_geometry(&moved).unwrap(),
            fd_geometry(&s, &moved),
        );
        assert!(rel(g, fd) < 1e-3, "{name} after a walk: G {g} vs {fd}");
        // Every chain here starts and ends outside any medium: the term
        // is symmetric (étendue), so the reversed chain gives it too.
        let reversed: Vec<ManifoldVertex> = chain.iter().rev().copied().collect();
        let g_rev = generalized_geometry(&reversed).unwrap();
        let g = generalized_geometry(&chain).unwrap();
        assert!(rel(g_rev, g) < 1e-4, "{name}: reversed {g_rev} vs {g}");
    }
}

/// The plane mirror has a closed form: unfolding the reflection, the chain
/// is one straight segment of length `d_01 + d_12`, so
/// `G = |cos θ_0| |cos θ_2| / (d_01 + d_12)²` (exact up to rounding).
#[test]
fn plane_mirror_geometry_term_is_the_unfolded_one() {
    let (_, _, chain) = cases().remove(0);
    let (d01, d12) = (
        (chain[1].p() - chain[0].p()).length(),
        (chain[2].p() - chain[1].p()).length(),
    );
    let cos0 = chain[0]
        .geo
        .ng
        .dot((chain[1].p() - chain[0].p()) / d01)
        .abs();
    let cos2 = chain[2]
        .geo
        .ng
        .dot((chain[1].p() - chain[2].p()) / d12)
        .abs();
    let want = cos0 * cos2 / (d01 + d12).powi(2);
    let g = generalized_geometry(&chain).unwrap();
    assert!(rel(g, want) < 1e-6, "G {g} vs {want}");
}

/// Controls: each removes or changes one genuine factor and must miss the
/// finite-difference value by more than the 1e-3 the test allows.
#[test]
fn generalized_geometry_controls_fail() {
    let cases = cases();
    // The curved mirror treated as flat (its normal's derivatives dropped).
    let (_, s, chain) = &cases[1];
    let fd = fd_geometry(s, chain);
    let mut flat = chain.clone();
    flat[1].geo.dnds = DVec3::ZERO;
    flat[1].geo.dndt = DVec3::ZERO;
    let g = generalized_geometry(&flat).unwrap();
    assert!(rel(g, fd) > 1e-2, "flat mirror: {g} vs {fd}");
    // The glass sphere: a wrong η (1.45 instead of 1.5) in the Jacobian.
    let (_, s, chain) = &cases[2];
    let fd = fd_geometry(s, chain);
    let mut wrong = chain.clone();
    for v in &mut wrong[1..3] {
        v.role = Role::Specular(Specular::Refract { eta: 1.45 });
    }
    let g = generalized_geometry(&wrong).unwrap();
    assert!(rel(g, fd) > 1e-2, "wrong eta: {g} vs {fd}");
    // The glass sphere: the coupling of the exit vertex to the entry vertex
    // (the sub-diagonal block) dropped.
    let g = edited_geometry(chain, |b| ConstraintBlocks {
        prev: DMat2::ZERO,
        ..b
    });
    assert!(rel(g, fd) > 1e-2, "dropped block: {g} vs {fd}");
    // And the glass sphere without its curvature.
    let mut flat = chain.clone();
    for v in &mut flat[1..3] {
        v.geo.dnds = DVec3::ZERO;
        v.geo.dndt = DVec3::ZERO;
    }
    let g = generalized_geometry(&flat).unwrap();
    assert!(rel(g, fd) > 1e-2, "flat glass: {g} vs {fd}");
}

/// The pinhole-like anchor (a point off surfaces) through the mirror sphere.
#[test]
fn point_anchor_walks_and_matches_finite_differences() {
    let s = sphere_mirror();
    let anchor = ManifoldVertex::point(Vec3::new(2.5, 0.3, 3.5));
    let chain = chain_through(
        &s,
        anchor,
        Vec3::new(0.97, 0.1, 1.69),
        &[MIRROR, Role::Endpoint],
    );
    let (g, fd) = (
        generalized_geometry(&chain).unwrap(),
        fd_geometry(&s, &chain),
    );
    assert!(rel(g, fd) < 1e-3, "G {g} vs {fd}");
    let target = chain.last().unwrap().p() + DVec3::new(0.1, 0.1, 0.0);
    let w = walk_reversible(&s, &chain, target, &WalkConfig::default()).expect("walks");
    assert!(max_constraint(&w.chain) < 1e-5);
}

/// Failures are classified: a target the mirror cannot reach (the ray
/// towards where the mirror would have to be meets the floor past its
/// edge) and one behind the occluder; both are `Occluded` (a ray reached
/// another shape than its vertex's), counted in the statistics.
#[test]
fn failures_are_classified() {
    let (_, s, chain) = cases().remove(0);
    let config = WalkConfig::default();
    let mut stats = WalkStats::default();
    // Beyond the mirror's edge (|y| ≤ 2 on the mirror): the mirror point
    // of the path to (−1, 4.5, 0) would be at y = 2.4.
    let far = DVec3::new(-1.0, 4.5, 0.0);
    let r = walk(&s, &chain, far, &config);
    stats.record(&r);
    assert_eq!(r.unwrap_err(), WalkFailure::Occluded);
    // Under the occluder: the path to (−1, 1.5, 0) reflects at (2, 0.9, 2)
    // and its last segment crosses z = 0.6 at (−0.1, 1.32).
    let hidden = DVec3::new(-1.0, 1.5, 0.0);
    let r = walk(&s, &chain, hidden, &config);
    stats.record(&r);
    assert_eq!(r.unwrap_err(), WalkFailure::Occluded);
    // A reachable target next to it still converges.
    let r = walk(&s, &chain, DVec3::new(-1.0, 0.4, 0.0), &config);
    stats.record(&r);
    assert!(r.is_ok());
    assert_eq!((stats.walks, stats.converged), (3, 1));
    assert_eq!(stats.failures_of(WalkFailure::Occluded), 2);
}

/// Descriptors from the renderer's path vertices: a smooth dielectric
/// vertex refracts (η from the BSDF) or reflects depending on where the
/// next vertex lies, a mirror reflects, a diffuse vertex is an endpoint
/// (also when flagged delta: its BSDF has no Dirac lobe to follow), the
/// pinhole is a point.
#[test]
fn descriptors_from_path_vertices() {
    use mcmc_render::color::Rgb;
    use mcmc_render::integrators::path_vertex::Vertex;
    let s = glass_sphere();
    let at = |o: Vec3, to: Vec3| {
        let ray = Ray::new(o, (to - o).normalize());
        let hit = s.geometry.intersect(&ray).expect("hit");
        (hit, s.geometry.surface_point(&ray, &hit))
    };
    // The top of the glass sphere, reached from above.
    let (hit, sp) = at(Vec3::new(0.3, 0.2, 4.0), Vec3::new(0.3, 0.2, 0.0));
    assert_eq!(sp.shape, 2);
    let mut v = Vertex::surface(&s, sp, Vec3::Z, Rgb::WHITE);
    v.delta = true;
    let inside = Vec3::new(0.0, 0.0, 1.5);
    let above = sp.p + Vec3::new(0.5, 0.0, 1.0);
    let refract = ManifoldVertex::from_path_vertex(&s, &v, Some(&hit), inside).unwrap();
    assert_eq!(refract.role, GLASS);
    let reflect = ManifoldVertex::from_path_vertex(&s, &v, Some(&hit), above).unwrap();
    assert_eq!(reflect.role, MIRROR);
    assert!((reflect.p() - sp.p.as_dvec3()).length() == 0.0);
    // Without the hit, it is located again: the same descriptor.
    let again = ManifoldVertex::from_path_vertex(&s, &v, None, inside).unwrap();
    assert_eq!(again.role, GLASS);
    assert!((again.geo.dnds - refract.geo.dnds).length() < 1e-6);
    assert!((again.geo.s - refract.geo.s).length() < 1e-6);
    // The diffuse floor.
    let (hit, sp) = at(Vec3::new(3.0, 0.0, 1.0), Vec3::new(3.0, 0.0, 0.0));
    let mut floor = Vertex::surface(&s, sp, Vec3::Z, Rgb::WHITE);
    let d = ManifoldVertex::from_path_vertex(&s, &floor, Some(&hit), above).unwrap();
    assert_eq!(d.role, Role::Endpoint);
    floor.delta = true;
    assert!(ManifoldVertex::from_path_vertex(&s, &floor, Some(&hit), above).is_none());
    // The pinhole.
    let cam = Vertex::camera(Vec3::new(0.0, -3.0, 1.0), glam::Vec2::ZERO, Rgb::WHITE);
    let p = ManifoldVertex::from_path_vertex(&s, &cam, None, sp.p).unwrap();
    assert!(!p.on_surface() && p.role == Role::Endpoint);
    // A mirror sphere's vertex reflects.
    let s = sphere_mirror();
    let ray = Ray::new(Vec3::new(0.3, 0.2, 4.0), -Vec3::Z);
    let hit = s.geometry.intersect(&ray).unwrap();
    let sp = s.geometry.surface_point(&ray, &hit);
    let mut v = Vertex::surface(&s, sp, Vec3::Z, Rgb::WHITE);
    v.delta = true;
    let m = ManifoldVertex::from_path_vertex(&s, &v, Some(&hit), above).unwrap();
    assert_eq!(m.role, MIRROR);
}

/// The glass sphere and a plane mirror at x = 3 facing −x (shape 3): a
/// path ceiling → glass (in, out) → floor → mirror → ceiling, whose middle
/// non-specular vertex is the floor's (index 3).
fn glass_and_mirror_path() -> (Scene, Vec<ManifoldVertex>) {
    let s = scene(
        r#"<shape type="sphere"><point name="center" x="0" y="0" z="1.5"/><float name="radius" value="1"/>
            <bsdf type="dielectric"><float name="int_ior" value="1.5"/><float name="ext_ior" value="1"/></bsdf></shape>
           <shape type="rectangle"><transform name="to_world"><scale value="2"/>
            <rotate y="1" angle="-90"/><translate x="3" z="1.5"/></transform>
            <bsdf type="conductor"><string name="material" value="none"/></bsdf></shape>"#,
    );
    let a = surface_vertex(
        &s,
        Vec3::new(0.5, 0.3, 3.0),
        Vec3::new(0.5, 0.3, 4.0),
        Role::Endpoint,
    );
    let mut path = chain_through(
        &s,
        a,
        Vec3::new(0.3, 0.2, 2.4),
        &[GLASS, GLASS, Role::Endpoint],
    );
    let b = path[3];
    let dir = (DVec3::new(3.0, 0.0, 1.5) - b.p()).normalize();
    let rest = trace(&s, &b, dir, &[MIRROR, Role::Endpoint]).expect("second chain");
    assert_eq!(rest[1].sp.shape, 3);
    assert_eq!(rest[2].sp.shape, 1, "the path ends on the ceiling");
    path.extend(&rest[1..]);
    (s, path)
}

/// A direction in the cone of half-angle `max` around `axis`, uniform in
/// solid angle, from two uniform numbers; the cone's density is
/// `1 / (2π (1 − cos max))`.
fn cone_direction(axis: DVec3, max: f64, u: f64, v: f64) -> DVec3 {
    let cos = 1.0 - u * (1.0 - max.cos());
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let e1 = axis.any_orthonormal_vector();
    let e2 = axis.cross(e1);
    let phi = std::f64::consts::TAU * v;
    axis * cos + (e1 * phi.cos() + e2 * phi.sin()) * sin
}

/// Uniform numbers from a fixed-seed xorshift.
fn uniforms(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The manifold perturbation's proposal density against a histogram of
/// its proposals: directions uniform in a cone of 0.03 rad around the
/// current one at the ceiling vertex, traced through the glass sphere to
/// the floor. Cells: a 4×4 grid of squares inside the image of the cone,
/// plus everything else. Expected counts `N ∫_cell p_A dA` by the midpoint
/// rule (6×6 points per cell), the density at each point from the chain
/// the walk finds ending there. Pearson's χ² with 16 degrees of freedom
/// must stay below 39.25 (the 0.999 quantile); the density with the
/// chain's Jacobian dropped (the glass treated as absent: `G(x_a ↔ x_1)`
/// alone) and with a wrong η (1.45) must exceed it.
#[test]
fn perturbation_density_matches_a_histogram_of_proposals() {
    use mcmc_render::manifold::perturbation::proposal_density;
    let (s, path) = glass_and_mirror_path();
    let chain: Vec<ManifoldVertex> = path[..=3].to_vec();
    let (x_a, x_b) = (chain[0].p(), chain[3].p());
    let axis = (chain[1].p() - x_a).normalize();
    let max = 0.03f64;
    let cone_pdf = 1.0 / (std::f64::consts::TAU * (1.0 - max.cos()));
    let config = WalkConfig::default();
    // The density at a floor point q, for a density function `density`
    // of the walked chain: zero outside the cone.
    let at = |q: DVec3, density: &dyn Fn(&[ManifoldVertex]) -> f64| {
        let w = walk(&s, &chain, q, &config).expect("quadrature point reachable");
        let dir = (w.chain[1].p() - x_a).normalize();
        if dir.dot(axis) >= max.cos() {
            density(&w.chain)
        } else {
            0.0
        }
    };
    // Cells: the square of half-width `half` around x_b, inside the image
    // of the cone: 0.55 × the cone's smallest image radius, from the
    // endpoint's Jacobian by central differences of traced chains.
    let roles: Vec<Role> = chain[1..].iter().map(|v| v.role).collect();
    let end = |d: DVec3| trace(&s, &chain[0], d, &roles).unwrap()[3].p();
    let (e1, e2) = (
        axis.any_orthonormal_vector(),
        axis.cross(axis.any_orthonormal_vector()),
    );
    let h = 1e-4;
    let j1 = (end((axis + e1 * h).normalize()) - end((axis - e1 * h).normalize())) / (2.0 * h);
    let j2 = (end((axis + e2 * h).normalize()) - end((axis - e2 * h).normalize())) / (2.0 * h);
    let jm = DMat2::from_cols(DVec2::new(j1.x, j1.y), DVec2::new(j2.x, j2.y));
    // Smallest singular value of the 2×2 map.
    let (a, b) = (
        jm.x_axis.length_squared() + jm.y_axis.length_squared(),
        jm.determinant(),
    );
    let sigma_min = ((a - (a * a - 4.0 * b * b).max(0.0).sqrt()) / 2.0).sqrt();
    let half = 0.55 * max * sigma_min;
    let (grid, sub) = (4usize, 6usize);
    let cell = 2.0 * half / grid as f64;
    let corner = DVec3::new(x_b.x - half, x_b.y - half, 0.0);
    // Precondition: every cell corner is reached from inside the cone.
    for i in 0..=grid {
        for j in 0..=grid {
            let q = corner + DVec3::new(i as f64 * cell, j as f64 * cell, 0.0);
            assert!(
                at(q, &|_| 1.0) > 0.0,
                "cell corner {q} outside the cone's image"
            );
        }
    }
    let expected = |density: &dyn Fn(&[ManifoldVertex]) -> f64| -> Vec<f64> {
        let mut p = Vec::new();
        for i in 0..grid {
            for j in 0..grid {
                let mut sum = 0.0;
                for k in 0..sub {
                    for l in 0..sub {
                        let q = corner
                            + DVec3::new(
                                (i as f64 + (k as f64 + 0.5) / sub as f64) * cell,
                                (j as f64 + (l as f64 + 0.5) / sub as f64) * cell,
                                0.0,
                            );
                        sum += at(q, density);
                    }
                }
                p.push(sum / (sub * sub) as f64 * cell * cell);
            }
        }
        p
    };
    let reported = |c: &[ManifoldVertex]| proposal_density(c, cone_pdf).unwrap();
    let dropped = |c: &[ManifoldVertex]| {
        let cos_a = c[0].geo.ng.dot((c[1].p() - c[0].p()).normalize()).abs();
        cone_pdf * geometry_term(&c[0], &c[1]) / cos_a
    };
    let wrong_eta = |c: &[ManifoldVertex]| {
        let mut c = c.to_vec();
        for v in &mut c[1..3] {
            v.role = Role::Specular(Specular::Refract { eta: 1.45 });
        }
        proposal_density(&c, cone_pdf).unwrap()
    };
    // The histogram.
    let n = 100_000usize;
    let mut counts = vec![0u64; grid * grid + 1];
    let mut next = uniforms(0x9e37_79b9_7f4a_7c15);
    for _ in 0..n {
        let d = cone_direction(axis, max, next(), next());
        let c = mcmc_render::manifold::walk::propagate(&s, &chain, d).expect("traces");
        let q = c[3].p() - corner;
        let (i, j) = ((q.x / cell).floor(), (q.y / cell).floor());
        let k = if (0.0..grid as f64).contains(&i) && (0.0..grid as f64).contains(&j) {
            i as usize * grid + j as usize
        } else {
            grid * grid
        };
        counts[k] += 1;
    }
    let chi2 = |p: &[f64]| {
        let rest = 1.0 - p.iter().sum::<f64>();
        p.iter()
            .chain(std::iter::once(&rest))
            .zip(&counts)
            .map(|(&p, &c)| {
                let e = p * n as f64;
                (c as f64 - e).powi(2) / e
            })
            .sum::<f64>()
    };
    let good = chi2(&expected(&reported));
    assert!(good < 39.25, "chi2 {good}");
    let bad = chi2(&expected(&dropped));
    assert!(bad > 39.25, "dropped Jacobian: chi2 {bad}");
    let bad_eta = chi2(&expected(&wrong_eta));
    assert!(bad_eta > 39.25, "wrong eta: chi2 {bad_eta}");
}

/// The whole perturbation: new directions at the ceiling vertex, the glass
/// chain traced to a new floor point, the mirror chain walked to it. The
/// end vertex stays, the first chain is exact (ray traced), the walked
/// chain meets its constraint to the walk's tolerance (its end is the
/// traced `x_b'` within 1e-5 of the chain length, which moves the mirror's
/// half-vector by at most that over the segment length: ≤ 1e-4 here).
#[test]
fn perturbation_proposals_stay_on_the_manifold() {
    use mcmc_render::manifold::perturbation::{proposal_density, propose};
    let (s, path) = glass_and_mirror_path();
    let axis = (path[1].p() - path[0].p()).normalize();
    let max = 0.03f64;
    let cone_pdf = 1.0 / (std::f64::consts::TAU * (1.0 - max.cos()));
    let mut next = uniforms(7);
    for _ in 0..200 {
        let d = cone_direction(axis, max, next(), next());
        let p = propose(&s, &path, 3, d, cone_pdf, &WalkConfig::default()).expect("proposal");
        assert_eq!(p.path.len(), path.len());
        assert_eq!(p.path[5].p(), path[5].p());
        assert_eq!(p.path[0].p(), path[0].p());
        assert!(max_constraint(&p.path[..=3]) < 1e-5);
        let c = max_constraint(&p.path[3..]);
        assert!(c < 1e-4, "walked chain constraint {c}");
        let density = proposal_density(&p.path[..=3], cone_pdf).unwrap();
        assert_eq!(p.density, density);
    }
}

/// Shape 2: a curved mirror as a triangle mesh with (analytic) vertex
/// normals: the patch `x = 2 + 0.1 (y² + (z − 2)²)`, |y| ≤ 1, 1 ≤ z ≤ 3,
/// facing −x, 8×8 cells, written to an OBJ file (without normals and
/// with `face_normals`, so that the loader computes none: faceted).
fn mesh_mirror(dir: &Path, vertex_normals: bool) -> Scene {
    let n = 8;
    let mut obj = String::new();
    for j in 0..=n {
        for i in 0..=n {
            let (y, z) = (
                -1.0 + 2.0 * i as f64 / n as f64,
                1.0 + 2.0 * j as f64 / n as f64,
            );
            let x = 2.0 + 0.1 * (y * y + (z - 2.0) * (z - 2.0));
            obj += &format!("v {x} {y} {z}\n");
            let nrm = DVec3::new(-1.0, 0.2 * y, 0.2 * (z - 2.0)).normalize();
            obj += &format!("vn {} {} {}\n", nrm.x, nrm.y, nrm.z);
        }
    }
    for j in 0..n {
        for i in 0..n {
            let k = j * (n + 1) + i + 1;
            let (a, b, c, d) = (k, k + 1, k + n + 2, k + n + 1);
            for [p, q, r] in [[a, b, c], [a, c, d]] {
                obj += &if vertex_normals {
                    format!("f {p}//{p} {q}//{q} {r}//{r}\n")
                } else {
                    format!("f {p} {q} {r}\n")
                };
            }
        }
    }
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("mirror.obj"), obj).unwrap();
    scene_in(
        dir,
        &format!(
            r#"<shape type="obj"><string name="filename" value="mirror.obj"/>
            <boolean name="face_normals" value="{}"/>
            <bsdf type="conductor"><string name="material" value="none"/></bsdf></shape>"#,
            !vertex_normals
        ),
    )
}

/// A curved mirror made of triangles with interpolated (shading) normals:
/// the walk follows the shading normals (its constraint and its
/// reflection use them), so `G` matches the finite differences of traced
/// chains when the derivatives of the interpolated normals enter the
/// Jacobian, and misses them without; walks converge across triangle
/// edges (where the normal field is continuous but not smooth).
#[test]
fn mesh_mirror_with_vertex_normals() {
    let dir = std::env::temp_dir().join(format!("mcmc-render-manifold-{}", std::process::id()));
    let s = mesh_mirror(&dir, true);
    let a = surface_vertex(
        &s,
        Vec3::new(-1.0, 0.3, 3.0),
        Vec3::new(-1.0, 0.3, 4.0),
        Role::Endpoint,
    );
    // Inside the triangle of cell y ∈ [0, 0.25], z ∈ [2, 2.25], 0.028 from
    // its diagonal: the finite differences (±3.6e-3 on the mirror) stay
    // inside it.
    let aim = Vec3::new(2.0017, 0.11, 2.07);
    let chain = chain_through(&s, a, aim, &[MIRROR, Role::Endpoint]);
    assert!(
        chain[1].geo.ns.dot(chain[1].geo.ng) < 1.0 - 1e-6,
        "shading normal differs"
    );
    let (g, fd) = (
        generalized_geometry(&chain).unwrap(),
        fd_geometry(&s, &chain),
    );
    assert!(rel(g, fd) < 1e-3, "G {g} vs {fd}");
    let mut flat = chain.clone();
    flat[1].geo.dnds = DVec3::ZERO;
    flat[1].geo.dndt = DVec3::ZERO;
    let g_flat = generalized_geometry(&flat).unwrap();
    assert!(rel(g_flat, fd) > 1e-2, "flat normals: {g_flat} vs {fd}");
    let end = chain.last().unwrap().p();
    let len = chain_length(&chain);
    for target in targets(end, 0.3, 10) {
        let w = walk_reversible(&s, &chain, target, &WalkConfig::default())
            .unwrap_or_else(|f| panic!("walk to {target}: {f:?}"));
        assert!((w.chain[2].p() - target).length() <= 1e-5 * len);
        assert!(max_constraint(&w.chain) <= 1e-5);
    }
    // The same mesh without vertex normals is a faceted mirror: G is the
    // plane mirror's, with no curvature, and agrees with its own finite
    // differences.
    let s = mesh_mirror(&dir, false);
    let a = surface_vertex(
        &s,
        Vec3::new(-1.0, 0.3, 3.0),
        Vec3::new(-1.0, 0.3, 4.0),
        Role::Endpoint,
    );
    let chain = chain_through(&s, a, aim, &[MIRROR, Role::Endpoint]);
    assert_eq!(chain[1].geo.dnds, DVec3::ZERO);
    let (g, fd) = (
        generalized_geometry(&chain).unwrap(),
        fd_geometry(&s, &chain),
    );
    assert!(rel(g, fd) < 1e-3, "faceted: G {g} vs {fd}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A chain that ends inside the glass: ceiling → refraction into the glass
/// sphere → a diffuse disk inside it (r = 0.5 at z = 1.3, facing up).
/// `G` matches the finite differences, and the reversed chain's term is
/// smaller by (η_inside/η_outside)² = 2.25 (étendue `η² dA dσ⊥` is
/// conserved: `G(ceiling → disk) = (η_disk/η_ceiling)² G(disk → ceiling)`).
#[test]
fn refraction_into_a_medium_scales_the_reversed_term_by_eta_squared() {
    let s = scene(
        r#"<shape type="sphere"><point name="center" x="0" y="0" z="1.5"/><float name="radius" value="1"/>
            <bsdf type="dielectric"><float name="int_ior" value="1.5"/><float name="ext_ior" value="1"/></bsdf></shape>
           <shape type="disk"><transform name="to_world"><scale value="0.5"/><translate z="1.3"/></transform>
            <bsdf type="diffuse"/></shape>"#,
    );
    let a = surface_vertex(
        &s,
        Vec3::new(0.5, 0.3, 3.0),
        Vec3::new(0.5, 0.3, 4.0),
        Role::Endpoint,
    );
    let dir = (DVec3::new(0.3, 0.2, 2.4) - a.p()).normalize();
    let chain = trace(&s, &a, dir, &[GLASS, Role::Endpoint]).expect("traces");
    assert_eq!(chain[2].sp.shape, 3, "the chain ends on the disk");
    let (g, fd) = (
        generalized_geometry(&chain).unwrap(),
        fd_geometry(&s, &chain),
    );
    assert!(rel(g, fd) < 1e-3, "G {g} vs {fd}");
    let reversed: Vec<ManifoldVertex> = chain.iter().rev().copied().collect();
    let g_rev = generalized_geometry(&reversed).unwrap();
    assert!(
        rel(g / g_rev, 2.25) < 1e-4,
        "G {g}, reversed {g_rev}: ratio {}",
        g / g_rev
    );
    // The walk moves the endpoint on the disk (polar parameterisation).
    let target = chain[2].p() + DVec3::new(0.05, -0.04, 0.0);
    let w = walk_reversible(&s, &chain, target, &WalkConfig::default()).expect("walks");
    assert!(max_constraint(&w.chain) < 1e-5);
}

/// Offset manifolds (glossy vertices treated as specular): the mirror
/// sphere's and the glass sphere's vertices keep fixed half-vector offsets
/// in their normal's frame. Chains traced with the offsets lie on their
/// offset manifold; `set_offsets` recovers the offsets; `G` matches the
/// finite differences of chains traced with the same offsets; walks
/// converge and reverse. Control: the Jacobian with the frame turning by
/// the minimal rotation (`ds = −n (s·dn)`, which the offset frame does not
/// follow) misses the finite differences — for a zero offset the two rules
/// agree on the manifold, for a non-zero one they do not.
#[test]
fn offset_manifolds_for_glossy_vertices() {
    use mcmc_render::manifold::constraint::offset_frame;
    use mcmc_render::manifold::set_offsets;
    let mirror = sphere_mirror();
    let a = surface_vertex(
        &mirror,
        Vec3::new(2.5, 0.3, 3.0),
        Vec3::new(2.5, 0.3, 4.0),
        Role::Endpoint,
    );
    let dir = (DVec3::new(0.97, 0.1, 1.69) - a.p()).normalize();
    let offsets = [DVec2::new(0.06, -0.04), DVec2::ZERO];
    let m_chain =
        trace_with_offsets(&mirror, &a, dir, &[MIRROR, Role::Endpoint], &offsets).unwrap();
    let glass = glass_sphere();
    let a = surface_vertex(
        &glass,
        Vec3::new(0.5, 0.3, 3.0),
        Vec3::new(0.5, 0.3, 4.0),
        Role::Endpoint,
    );
    let dir = (DVec3::new(0.3, 0.2, 2.4) - a.p()).normalize();
    let offsets = [DVec2::new(0.08, 0.05), DVec2::new(-0.06, 0.07), DVec2::ZERO];
    let g_chain =
        trace_with_offsets(&glass, &a, dir, &[GLASS, GLASS, Role::Endpoint], &offsets).unwrap();
    for (name, s, chain) in [("mirror", &mirror, m_chain), ("glass", &glass, g_chain)] {
        assert_eq!(
            chain.last().unwrap().sp.shape,
            0,
            "{name}: ends on the floor"
        );
        assert!(
            max_constraint(&chain) < 1e-5,
            "{name}: off its offset manifold"
        );
        let mut again = chain.clone();
        set_offsets(&mut again).unwrap();
        for (x, y) in again.iter().zip(&chain) {
            assert!(
                (x.offset - y.offset).length() < 1e-5,
                "{name}: offsets recovered"
            );
        }
        let (g, fd) = (
            generalized_geometry(&chain).unwrap(),
            fd_geometry(s, &chain),
        );
        assert!(rel(g, fd) < 1e-3, "{name}: G {g} vs {fd}");
        // Control: the minimal-rotation frame rule in ∂c_i/∂x_i.
        let minimal = |k: usize, b: ConstraintBlocks| {
            let (p, v, q) = (chain[k - 1].p(), &chain[k], chain[k + 1].p());
            let Role::Specular(Specular::Refract { eta }) = v.role else {
                // Mirror: h ∝ ω_i + ω_o.
                return swap_frame_rule(v, (p - v.p()).normalize() + (q - v.p()).normalize(), b);
            };
            let n = v.geo.ns;
            let side = |w: DVec3| if w.dot(n) >= 0.0 { 1.0 } else { eta };
            let (wi, wo) = ((p - v.p()).normalize(), (q - v.p()).normalize());
            swap_frame_rule(v, wi * side(wi) + wo * side(wo), b)
        };
        let count = std::cell::Cell::new(0usize);
        let g_min = edited_geometry(&chain, |b| {
            count.set(count.get() + 1);
            minimal(count.get(), b)
        });
        assert!(
            rel(g_min, fd) > 1e-2,
            "{name}: minimal rotation {g_min} vs {fd}"
        );
        // Walks on the offset manifold.
        let end = chain.last().unwrap().p();
        let len = chain_length(&chain);
        for target in targets(end, 0.05, 5) {
            let w = walk_reversible(s, &chain, target, &WalkConfig::default())
                .unwrap_or_else(|f| panic!("{name}: walk to {target}: {f:?}"));
            assert!((w.chain.last().unwrap().p() - target).length() <= 1e-5 * len);
            assert!(
                max_constraint(&w.chain) <= 1e-5,
                "{name}: constraint after the walk"
            );
        }
    }

    /// `b` with the frame's change replaced by the minimal rotation: the
    /// offset frame's change `h·ds` (by central differences of
    /// `offset_frame`) taken out, `−(h·n)(s·dn)` put in.
    fn swap_frame_rule(v: &ManifoldVertex, big_h: DVec3, b: ConstraintBlocks) -> ConstraintBlocks {
        let n = v.geo.ns;
        let h = big_h.normalize() * big_h.dot(n).signum();
        let (s, t) = offset_frame(n);
        let term = |dn: DVec3, rule_offset: bool| {
            if rule_offset {
                let e = 1e-6;
                let (sp, tp) = offset_frame((n + dn * e).normalize());
                let (sm, tm) = offset_frame((n - dn * e).normalize());
                DVec2::new(h.dot(sp - sm), h.dot(tp - tm)) / (2.0 * e)
            } else {
                -DVec2::new(s.dot(dn), t.dot(dn)) * h.dot(n)
            }
        };
        let col = |c: DVec2, dn: DVec3| c - term(dn, true) + term(dn, false);
        ConstraintBlocks {
            cur: DMat2::from_cols(col(b.cur.x_axis, v.geo.dnds), col(b.cur.y_axis, v.geo.dndt)),
            ..b
        }
    }
}
