//! Inverse samplers (Otsu et al. 2017 §4.2, spec seed001 §2): for each
//! sampling routine of BDPT's subpath sampler that maps random numbers to
//! a path decision, the numbers that make it produce a given decision.
//! The fused state space ([`crate::fused_space`]) maps whole paths back to
//! multiplexed primary samples with them.
//!
//! Every function here inverts the forward routine it names *as that
//! routine computes*, with the same conventions (φ ranges, barycentric
//! order, concentric rather than polar disks, the same frames). Where the
//! forward map is many-to-one (light selection, the Russian-roulette
//! decision, a BSDF's lobe choice, the MMLT technique bin), the inverse
//! draws the number uniformly inside the preimage interval ([`in_interval`])
//! from a fresh uniform `xi`: the pushforward of uniform numbers through
//! forward-then-inverse is then uniform again, which is what keeps the
//! fused chain's acceptance ratio free of any Jacobian of the inverse
//! (spec seed001 §2.4). Numbers the forward routine ignores (the pinhole's
//! lens numbers, a point light's position numbers, a Dirac lobe's
//! direction numbers, roulette numbers when roulette is off) are fresh
//! uniforms, chosen by the caller.
//!
//! The BSDF inverses are [`crate::bsdf::Bsdf::invert`]; the camera's is
//! [`crate::camera::Camera::invert`]; the spot light's cone is
//! [`crate::light::SpotProfile::invert`]; the tabulated environment map's
//! is [`crate::distribution::Distribution2d::invert`], through
//! [`crate::environment::Environment::invert`] for an environment's
//! direction ([`infinite_direction_to_square`]); the disk a light walk from
//! an emitter at infinity starts on is
//! [`crate::light::Lights::infinite_origin_to_square`]; next-event
//! estimation's cone sampling of sphere emitters seen from outside is
//! [`crate::light::Lights::sphere_cone_to_square`].

use crate::bsdf::diffuse::cosine_hemisphere_to_square;
use crate::frame::Frame;
use crate::geometry::{Surface, SurfacePoint};
use crate::light::{Light, Lights};
use crate::sampling::{ONE_MINUS_EPSILON, to_unit_f32};
use crate::scene::Scene;
use glam::{DVec3, Vec2, Vec3};
use std::f64::consts::PI;

/// Relative margin kept from both ends of a preimage interval, so that a
/// number drawn inside it selects the same branch after rounding to `f32`
/// (the paper's `[0, F − ε)`, spec seed001 §6). It makes the inverse's
/// density on the interval `1/(1 − 2·MARGIN)` instead of 1: a relative
/// error of 2e-6 per stochastic coordinate in the acceptance ratio.
pub const MARGIN: f64 = 1e-6;

/// A number uniform in `[lo, hi)` (shrunk by [`MARGIN`] at both ends) from
/// the fresh uniform `xi`, or `None` when the interval is too narrow to
/// hold an `f32` strictly inside it.
pub fn in_interval(lo: f32, hi: f32, xi: f64) -> Option<f32> {
    let (l, h) = (f64::from(lo), f64::from(hi));
    if !(h > l) {
        return None;
    }
    let w = h - l;
    let u = (l + w * (MARGIN + xi * (1.0 - 2.0 * MARGIN))) as f32;
    (u >= lo && u < hi && u <= ONE_MINUS_EPSILON).then_some(u)
}

/// `φ / 2π` for an angle `φ` from `atan2`, wrapped into `[0, 1)` (the
/// forward routines compute `φ = 2π u`).
pub fn angle_to_unit(phi: f64) -> f32 {
    let u = phi / (2.0 * PI);
    to_unit_f32(if u < 0.0 { u + 1.0 } else { u })
}

/// Inverse of [`crate::warp::uniform_sphere`]: `z = 1 − 2u₀`, `φ = 2πu₁`.
pub fn uniform_sphere_to_square(w: Vec3) -> (f32, f32) {
    let w = w.as_dvec3().normalize_or_zero();
    (
        to_unit_f32(((1.0 - w.z) * 0.5).clamp(0.0, 1.0)),
        angle_to_unit(w.y.atan2(w.x)),
    )
}

/// Inverse of [`crate::warp::concentric_disk`] (Shirley–Chiu, by wedges).
pub fn disk_to_square(d: Vec2) -> (f32, f32) {
    // The hemisphere inverse reads only (x, y): the disk point.
    cosine_hemisphere_to_square(Vec3::new(d.x, d.y, 0.0))
}

/// Inverse of [`crate::warp::uniform_triangle`] (`b₀ = 1 − √u₀`,
/// `b₁ = u₁ √u₀`) given the barycentrics `(b₁, b₂)` of a point.
pub fn triangle_to_square(b1: f64, b2: f64) -> (f32, f32) {
    let su = (b1 + b2).clamp(0.0, 1.0);
    let u1 = if su > 0.0 { b1 / su } else { 0.5 };
    (to_unit_f32(su * su), to_unit_f32(u1.clamp(0.0, 1.0)))
}

/// Barycentrics `(b₁, b₂)` of `p` in the triangle `(a, b, c)`, in `f64`
/// (the dot-product solve), and the squared distance of `p` from the
/// triangle's plane point with those barycentrics clamped into it.
fn barycentrics(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> Option<(f64, f64, f64)> {
    let (e1, e2, d) = (b - a, c - a, p - a);
    let (d00, d01, d11) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d20, d21) = (d.dot(e1), d.dot(e2));
    let den = d00 * d11 - d01 * d01;
    if !(den > 0.0) {
        return None;
    }
    let b1 = (d11 * d20 - d01 * d21) / den;
    let b2 = (d00 * d21 - d01 * d20) / den;
    // Distance to the triangle (clamped barycentrics), to pick the triangle
    // of a mesh that holds `p`.
    let (c1, c2) = (b1.clamp(0.0, 1.0), b2.clamp(0.0, 1.0));
    let s = c1 + c2;
    let (c1, c2) = if s > 1.0 { (c1 / s, c2 / s) } else { (c1, c2) };
    let q = a + e1 * c1 + e2 * c2;
    Some((b1, b2, (p - q).length_squared()))
}

/// Inverse of the light selection [`Lights::select`]: a number that picks
/// light `i`, uniform in its interval from the fresh uniform `xi`.
pub fn light_selection(lights: &Lights, i: u32, xi: f64) -> Option<f32> {
    if i as usize >= lights.lights.len() {
        return None;
    }
    let (lo, hi) = lights.selection_interval(i);
    in_interval(lo, hi, xi)
}

/// Inverse of the Russian-roulette decision "continue when `u < q`": a
/// number uniform in `[0, q)` (continued) or `[q, 1)` (stopped).
pub fn roulette(q: f32, continued: bool, xi: f64) -> Option<f32> {
    let q = q.clamp(0.0, 1.0);
    if continued {
        in_interval(0.0, q, xi)
    } else {
        in_interval(q, 1.0, xi)
    }
}

/// Inverse of the raster position of MMLT's and the path-space walks'
/// camera sample (`p = u · (w, h)`, `crate::pss::raster_of`).
pub fn raster_to_square(scene: &Scene, raster: Vec2) -> (f32, f32) {
    let (w, h) = (scene.film.width as f64, scene.film.height as f64);
    (
        to_unit_f32((f64::from(raster.x) / w).clamp(0.0, 1.0)),
        to_unit_f32((f64::from(raster.y) / h).clamp(0.0, 1.0)),
    )
}

/// Inverse of the position sampling of area light `light` (uniform by
/// area: a mesh's triangle by its area CDF with the first number reused
/// inside the triangle, then [`crate::warp::uniform_triangle`]; spheres
/// [`crate::warp::uniform_sphere`]; disks [`crate::warp::concentric_disk`]
/// in object space): the numbers `u_pos` that produce the point `p`, or
/// `None` when `light` is not an area light or the point is not on it.
/// Meshes are searched triangle by triangle for the one holding the point
/// in the plane of its geometric normal (emitter meshes are small; a
/// light-walk origin carries no primitive index).
pub fn area_point_to_square(scene: &Scene, light: u32, sp: &SurfacePoint) -> Option<(f32, f32)> {
    let p = sp.p;
    let Light::Area { shape, tri_cdf, .. } = scene.lights.lights.get(light as usize)? else {
        return None;
    };
    let surface = &scene.geometry.shapes.get(*shape as usize)?.surface;
    match surface {
        Surface::Mesh(m) => {
            let pd = p.as_dvec3();
            let mut best: Option<(usize, f64, f64, f64)> = None;
            for (i, t) in m.indices.iter().enumerate() {
                let [a, b, c] = t.map(|v| m.positions[v as usize].as_dvec3());
                // A point on an edge lies on two triangles: the one whose
                // plane matches the point's geometric normal holds it.
                let facing = (b - a)
                    .cross(c - a)
                    .normalize_or_zero()
                    .dot(sp.ng.as_dvec3());
                if let Some((b1, b2, d2)) = barycentrics(pd, a, b, c)
                    && facing.abs() > 0.999
                    && best.is_none_or(|(_, _, _, e)| d2 < e)
                {
                    best = Some((i, b1, b2, d2));
                }
            }
            let (i, b1, b2, d2) = best?;
            // Not on the mesh (beyond f32 rounding of a point on it).
            let scale = m.positions[m.indices[i][0] as usize].as_dvec3().length() + 1.0;
            if d2 > (1e-4 * scale).powi(2) {
                return None;
            }
            let (u0, u1) = triangle_to_square(b1, b2);
            let lo = if i == 0 { 0.0 } else { tri_cdf[i - 1] };
            let hi = *tri_cdf.get(i)?;
            // The forward map rescales u₀ ∈ [lo, hi) to the triangle's u₀.
            let u = f64::from(lo) + f64::from(hi - lo) * f64::from(u0);
            let u = to_unit_f32(u.clamp(f64::from(lo), f64::from(hi)));
            Some((u, u1))
        }
        Surface::Sphere { center, radius, .. } => {
            if !(*radius > 0.0) {
                return None;
            }
            Some(uniform_sphere_to_square((p - *center) / *radius))
        }
        Surface::Disk { to_local, .. } => {
            let l = to_local.transform_point3(p);
            Some(disk_to_square(Vec2::new(l.x, l.y)))
        }
    }
}

/// Inverse of the emitted-direction sampling of light `light` from its
/// point `sp` (area lights: cosine about the shading normal through the
/// concentric map; point lights: uniform sphere or the spot's cone): the
/// numbers `u_dir` that produce unit `dir`, or `None` when the light
/// cannot emit along it.
pub fn emission_direction_to_square(
    scene: &Scene,
    light: u32,
    sp: &SurfacePoint,
    dir: Vec3,
) -> Option<(f32, f32)> {
    match scene.lights.lights.get(light as usize)? {
        Light::Area { .. } => {
            let local = Frame::from_normal(sp.ns).to_local(dir);
            // The forward map reaches the rim (z → 0); a grazing direction
            // can come back a rounding error below it.
            (local.z > -1e-5).then(|| cosine_hemisphere_to_square(local))
        }
        Light::Point { spot: Some(s), .. } => s.invert(dir),
        Light::Point { spot: None, .. } => Some(uniform_sphere_to_square(dir)),
        Light::Directional { .. } | Light::Environment(_) => None,
    }
}

/// Inverse of next-event estimation's light point ([`Lights::sample_direct`]
/// from `from`, BDPT's `s = 1` technique): the numbers `u_pos` that sample
/// point `sp` of light `light`. Point lights ignore them (`Some(None)`:
/// the caller draws fresh ones); sphere lights seen from outside are
/// sampled in their cone ([`Lights::sphere_cone_to_square`]), `None` when
/// the point is not on the cap that sampling reaches.
pub fn direct_point_to_square(
    scene: &Scene,
    light: u32,
    from: Vec3,
    sp: &SurfacePoint,
) -> Option<Option<(f32, f32)>> {
    match scene.lights.lights.get(light as usize)? {
        Light::Point { .. } => Some(None),
        Light::Area {
            sphere: Some((center, radius)),
            ..
        } => match Lights::sphere_cone_to_square(*center, *radius, from, sp.p) {
            Some(cone) => cone.map(Some),
            // From inside, next-event estimation samples by area.
            None => area_point_to_square(scene, light, sp).map(Some),
        },
        Light::Area { .. } => area_point_to_square(scene, light, sp).map(Some),
        Light::Directional { .. } | Light::Environment(_) => None,
    }
}

/// Inverse of the direction sampling of emitter at infinity `light`, both
/// as a light walk's emission (`u_dir` of [`Lights::sample_emission`]) and
/// as next-event estimation's light sample (`u_pos` of
/// [`Lights::sample_direct`]), which draw it with the same numbers: the
/// numbers that sample the unit direction `w` from the scene towards the
/// emitter. A directional light ignores them (`Some(None)`: the caller
/// draws fresh ones); `None` when `light` is not at infinity or the
/// environment's density vanishes at `w`.
pub fn infinite_direction_to_square(
    scene: &Scene,
    light: u32,
    w: Vec3,
) -> Option<Option<(f32, f32)>> {
    match scene.lights.lights.get(light as usize)? {
        Light::Directional { .. } => Some(None),
        Light::Environment(env) => env.invert(w).map(Some),
        Light::Area { .. } | Light::Point { .. } => None,
    }
}
