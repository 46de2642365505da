//! Walks that grow path-space subpaths, on BDPT's walk code
//! ([`crate::integrators::bdpt`]): from the emitters, from the camera, or
//! onward from a vertex a mutation keeps. Russian roulette is off (a
//! mutation asks for an exact number of vertices), and the densities the
//! walks write are not used: [`super::Path::evaluate`] recomputes them in
//! the path state's convention.

use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::frame::Frame;
use crate::geometry::Ray;
use crate::integrators::bdpt::{generate_camera_subpath, generate_light_subpath, random_walk};
use crate::integrators::path_vertex::{Vertex, VertexKind};
use crate::light::Light;
use crate::sampling::{IndependentSource, RandomSource};
use crate::scene::Scene;
use crate::warp;
use glam::Vec2;
use mcmc_core::rng::ChainRng;

/// The [`RandomSource`] of a chain's mutations: its own generator.
pub type ChainSource<'a> = IndependentSource<&'a mut ChainRng>;

/// A light walk of `count` vertices from the emitters (emitter point
/// first, chosen as BDPT chooses it) into `out`; returns the number
/// written (fewer when the walk escapes or is absorbed).
pub fn light_walk(
    scene: &Scene,
    source: &mut dyn RandomSource,
    count: usize,
    out: &mut Vec<Vertex>,
) -> usize {
    generate_light_subpath(scene, source, count, None, out)
}

/// A camera walk of `count` vertices from the camera (the lens point
/// first) through a raster position uniform over the image into `out`;
/// returns the number written.
pub fn camera_walk(
    scene: &Scene,
    source: &mut dyn RandomSource,
    count: usize,
    out: &mut Vec<Vertex>,
) -> usize {
    let (w, h) = (scene.film.width as f32, scene.film.height as f32);
    let (ux, uy) = source.next_2d();
    let raster = Vec2::new(
        (ux * w).min(w * (1.0 - f32::EPSILON)),
        (uy * h).min(h * (1.0 - f32::EPSILON)),
    );
    generate_camera_subpath(scene, raster, source, count, None, out)
}

/// A walk onward from the kept vertex `from` (an emitter point, an emitter
/// at infinity, or a surface vertex; `behind` is its neighbour on the side
/// the walk comes from, `None` at an emitter): `out` gets `from` (with its
/// `delta` flag set by the lobe sampled there) followed by up to `count`
/// new vertices. `mode` is importance for walks towards the camera,
/// radiance towards the emitters. From an emitter at infinity (a light
/// walk only) the walk starts on the disk of
/// [`crate::light::Lights::infinite_origin`] and travels along `−ω`, as a
/// light walk from the emitters does. Returns the number of new vertices
/// (fewer than `count` when the walk escapes or is absorbed; 0 when
/// `from` cannot start a walk). A radiance walk that escapes into an
/// environment ends with a vertex at infinity, counted: the caller
/// decides whether it may stand where it is (only as `x_0`).
pub fn extend_walk(
    scene: &Scene,
    from: &Vertex,
    behind: Option<&Vertex>,
    count: usize,
    mode: TransportMode,
    source: &mut dyn RandomSource,
    out: &mut Vec<Vertex>,
) -> usize {
    out.clear();
    out.push(*from);
    if count == 0 {
        return 0;
    }
    let (ray, beta) = match from.kind {
        VertexKind::Light => {
            let Some(dir) = emission_direction(scene, from, source.next_2d()) else {
                return 0;
            };
            let ray = if from.on_surface() {
                from.sp.spawn_ray(dir)
            } else {
                Ray::new(from.p(), dir)
            };
            (ray, Rgb::WHITE)
        }
        VertexKind::Surface => {
            let Some(wb) = behind.and_then(|b| from.direction_to(b)) else {
                return 0;
            };
            let u_lobe = source.next_1d();
            let u = source.next_2d();
            let frame = scene.shading_frame(&from.sp);
            let Some(bs) = scene
                .bsdf_at(&from.sp)
                .sample(frame.to_local(wb), u_lobe, u, mode)
            else {
                return 0;
            };
            if !(bs.pdf > 0.0) || bs.weight.is_black() {
                return 0;
            }
            out[0].delta = bs.is_delta;
            (from.sp.spawn_ray(frame.to_world(bs.wi)), bs.weight)
        }
        VertexKind::Infinite if mode == TransportMode::Importance => {
            let dir = -from.wo;
            let origin = scene.lights.infinite_origin(dir, source.next_2d());
            (Ray::new(origin, dir), Rgb::WHITE)
        }
        VertexKind::Camera | VertexKind::Infinite => return 0,
    };
    random_walk(scene, ray, source, mode, beta, 1.0, count, None, out)
}

/// True when a camera walk can end on an emitter of `scene`: an area
/// light, or the environment when the walk escapes. Otherwise every path
/// needs a light-walk vertex (`s ≥ 1`).
pub fn camera_walks_reach_emitters(scene: &Scene) -> bool {
    scene.lights.environment().is_some()
        || scene
            .lights
            .lights
            .iter()
            .any(|l| matches!(l, Light::Area { .. }))
}

/// A direction leaving emitter point `x0`, sampled as light walks sample
/// it (cosine about the shading normal for area lights, uniform or in the
/// spot cone for point lights; the density is [`Vertex::pdf_light`]).
fn emission_direction(scene: &Scene, x0: &Vertex, u: (f32, f32)) -> Option<glam::Vec3> {
    match &scene.lights.lights[x0.light as usize] {
        Light::Area { .. } => {
            Some(Frame::from_normal(x0.sp.ns).to_world(warp::cosine_hemisphere(u)))
        }
        Light::Point { spot: Some(s), .. } => Some(s.sample(u).0),
        Light::Point { spot: None, .. } => Some(warp::uniform_sphere(u)),
        Light::Directional { .. } | Light::Environment(_) => None,
    }
}
