//! Vertex connection and merging (Georgiev, Křivánek, Davidovič &
//! Slusallek 2012), organised as SmallVCM is, with the recursive MIS
//! quantities `dVCM`, `dVC`, `dVM` of Georgiev's technical report
//! "Implementing vertex connection and merging" (2012), written here with
//! the area densities of [`super::path_vertex`].
//!
//! # One iteration
//! 1. **Light pass.** `N` light subpaths, `N` the number of pixels, traced
//!    by [`generate_light_subpath`] in [`LIGHT_UNITS`] fixed units. Every
//!    surface vertex whose BSDF is not purely specular is stored as a
//!    [`LightVertex`] with its partial MIS quantities and connected to the
//!    camera (light tracing, splatted).
//! 2. **Range search.** The stored vertices go into a [`HashGrid`] with
//!    this iteration's merge radius `r`.
//! 3. **Camera pass.** One camera subpath per pixel ([`generate_camera_subpath`],
//!    image tiles); at each of its vertices: the emitter found (`s = 0`),
//!    next-event estimation (`s = 1`), a connection to every stored vertex
//!    of the light subpath with the pixel's index, and merging with every
//!    stored vertex within `r` (density estimation with the kernel
//!    `1/(π r²)`, normalised by `N`).
//!
//! Each unit draws from its own generator seeded by `(seed, pass, unit)`,
//! renders into its own film, and the films and the vertex lists are
//! joined in unit order: one seed gives the same image on any thread
//! count.
//!
//! # Checkpoints
//! With `--checkpoint FILE` (session 19) rank 0 saves after every
//! iteration, in the per-pixel driver's format ([`crate::checkpoint`]),
//! the film (camera samples and light-tracing splats), the iterations
//! done and, as the integrator's words, the technique tally (its five
//! energies as bits and the light vertices; the non-finite count in the
//! format's own word). An iteration depends on nothing earlier but its
//! index (its radius, its streams `(seed, 2i)`, `(seed, 2i + 1)`), so a
//! resumed run renders the next iteration into the saved accumulators in
//! the same order and ends with the uninterrupted run's bits.
//!
//! # Radius
//! `radius = auto` takes SmallVCM's rule, `radius_factor` (0.003) times
//! the radius of the scene's bounding sphere. Iteration `i` (from 1)
//! merges with `r_i = r_1 · i^{(α−1)/2}` (Knaus & Zwicker's progressive
//! reduction; `α = 1` keeps `r` fixed, biased but consistent only with
//! reduction).
//!
//! # MIS
//! With `m(x) = x` (balance) or `x²` (power), `η = π r² N`, and area
//! densities `p→` (a vertex's own subpath) and `p←` (the opposite walk),
//! every subpath vertex `i ≥ 1` carries ([`partial_mis`]):
//!
//! - `dVCM_i = 1 / m(p→_i)` (0 after a specular vertex);
//! - `dVC_i = (dVC_{i−1} m(p←_{i−2}) + dVCM_{i−1} + m(η)) / m(p→_i)`;
//! - `dVM_i = (dVM_{i−1} m(p←_{i−2}) + dVCM_{i−1} m(1/η) + 1) / m(p→_i)`;
//!
//! (the `m(η)` and `1` terms only for `i ≥ 2`: no merging at an emitter
//! origin; through a specular vertex `dVC` and `dVM` carry over, the
//! discrete lobe's densities cancelling as in pbrt's BDPT). The origin of
//! a light subpath has `dVCM_0 = 1/m(p→_0)` (the technique that hits the
//! emitter; 0 for point and directional lights), the camera's 0. A
//! technique joining light vertex `i` and camera vertex `j` then needs
//! only the two or four densities the join itself decides, e.g. for a
//! connection
//! `w = 1 / (1 + m(p←_i)(m(η) + dVCM_i + m(p←_{i−1}) dVC_i) + m(p→_j)(m(η) + dVCM_j + m(p→_{j−1}) dVC_j))`,
//! and for a merge `w = 1 / (1 + m(1/η) dVCM_i + m(p←_{i−1}) dVM_i + m(1/η) dVCM_j + m(p→_{j−1}) dVM_j)`.
//! Next-event estimation takes the emitter's light-path origin density
//! for its own (pbrt's convention, as [`super::bdpt`]), so that with
//! merging off the weights are BDPT's. Densities ignore Russian roulette
//! (see [`super::bdpt`]). The technique densities of connections assume
//! one light subpath per camera subpath and `N` light subpaths for light
//! tracing and merging, which is what runs.
//!
//! # Modes
//! `vcm` runs everything; `bpt` only the connection techniques
//! (`m(η) = 0`); `ppm` only merging, at the camera vertices reached by
//! specular scattering alone, weight one, plus emitters seen through
//! specular chains (SmallVCM's `ppm`, extended to BSDFs that mix a
//! specular and a non-specular lobe: the path continues only when the
//! specular lobe was sampled).
//!
//! # Reuse by light-subpath methods
//! The light-side work is free functions over a [`LightVertex`] and a
//! camera vertex with its [`PartialMis`]: [`weight_connection`],
//! [`weight_merge`], [`light_trace`], [`connection`]. A method that
//! samples light subpaths itself (MCMC over VCM's light subpaths) traces
//! one with [`Vcm::trace_light_subpath`], keeps camera subpaths with their
//! [`partial_mis`], and sums the same functions over them: the
//! contribution of one light subpath is then the sum of its light-tracing
//! splats, its connections and its merges.

use super::bdpt::{
    MisHeuristic, SubpathBuffers, generate_camera_subpath, generate_light_subpath, geometry_term,
};
use super::path_vertex::{Vertex, VertexKind};
use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings};
use crate::bsdf::TransportMode;
use crate::bsdf::textured::BsdfAt;
use crate::checkpoint::{Checkpoint, Progress};
use crate::color::Rgb;
use crate::deadline::Deadline;
use crate::film::{Film, Filter};
use crate::frame::Frame;
use crate::hash_grid::HashGrid;
use crate::observer::Observer;
use crate::render::unit_source;
use crate::sampling::RandomSource;
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::cell::RefCell;
use std::f32::consts::PI;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Light-subpath units per iteration (fixed: the image must not depend on
/// the thread count).
pub const LIGHT_UNITS: usize = 8;
/// Tile edge of the camera pass, in pixels.
const TILE: u32 = 32;
/// Light subpaths between two checks of the stop flag.
const STOP_CHECK: usize = 1024;

crate::choice! {
    /// Which techniques run (SmallVCM's algorithms of these names).
    pub enum VcmMode {
        /// Vertex connection and merging: every technique.
        Vcm = "vcm",
        /// Vertex connection only: bidirectional path tracing.
        Bpt = "bpt",
        /// Progressive photon mapping: merging at the first non-specular camera vertex.
        Ppm = "ppm",
    }
}

impl VcmMode {
    /// Connections, next-event estimation and light tracing run.
    pub fn connects(self) -> bool {
        self != VcmMode::Ppm
    }
    /// Merging runs.
    pub fn merges(self) -> bool {
        self != VcmMode::Bpt
    }
}

/// The constants of one iteration's MIS weights.
#[derive(Clone, Copy, Debug)]
pub struct MisFactors {
    /// Balance or power heuristic.
    pub heuristic: MisHeuristic,
    /// `m(η)`, `η = π r² N` (0 without merging).
    pub vm: f32,
    /// `m(1/η)` (0 without connections).
    pub vc: f32,
    /// `m(1/k)`: the factor on the densities of the path-tracing techniques
    /// (emitter found, next-event estimation) relative to those of the
    /// light-subpath techniques (light tracing, connections, merging) when
    /// the light subpaths are drawn with `k` times their tracing density
    /// (MCMC over light subpaths, [`super::mcmc_vcm`]); 1 in `vcm`.
    pub pt: f32,
}

impl MisFactors {
    /// The factors for merge radius `radius` and `light_paths` light subpaths.
    pub fn new(mode: VcmMode, heuristic: MisHeuristic, radius: f32, light_paths: f64) -> Self {
        let eta = (PI as f64 * f64::from(radius) * f64::from(radius) * light_paths) as f32;
        let mut f = MisFactors {
            heuristic,
            vm: 0.0,
            vc: 0.0,
            pt: 1.0,
        };
        if mode.merges() {
            f.vm = f.m(eta);
        }
        if mode.connects() {
            f.vc = f.m(1.0 / eta);
        }
        f
    }

    /// The same factors for light subpaths drawn with `k` times their
    /// tracing density: every light-subpath technique's density is `k`
    /// times its own, the path-tracing techniques' unchanged.
    pub fn with_light_density_scale(mut self, k: f32) -> Self {
        self.pt = self.m(1.0 / k);
        self
    }

    /// The heuristic's power of `x`.
    #[inline]
    pub fn m(&self, x: f32) -> f32 {
        match self.heuristic {
            MisHeuristic::Balance => x,
            MisHeuristic::Power => x * x,
        }
    }
}

/// The recursive MIS quantities of one subpath vertex (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PartialMis {
    /// `dVCM`: the technique that ends the other subpath one vertex earlier.
    pub d_vcm: f32,
    /// `dVC`: every earlier technique, normalised for a connection.
    pub d_vc: f32,
    /// `dVM`: every earlier technique, normalised for a merge.
    pub d_vm: f32,
}

/// Fills `out` with the [`PartialMis`] of every vertex of `path`, a camera
/// subpath (pinhole first) or a light subpath (emitter point first) as
/// [`generate_camera_subpath`] and [`generate_light_subpath`] leave them.
pub fn partial_mis(scene: &Scene, path: &[Vertex], f: &MisFactors, out: &mut Vec<PartialMis>) {
    out.clear();
    let Some(origin) = path.first() else {
        return;
    };
    let light_path = origin.kind != VertexKind::Camera;
    let hit_origin = light_path && !origin.is_delta_light(scene) && origin.pdf_fwd > 0.0;
    // On a light subpath, `dVCM_0` and `dVCM_1` are the two path-tracing
    // techniques (emitter found, next-event estimation): the recursion
    // carries them, scaled by `f.pt`, into every later quantity.
    out.push(PartialMis {
        d_vcm: if hit_origin {
            f.pt / f.m(origin.pdf_fwd)
        } else {
            0.0
        },
        d_vc: 0.0,
        d_vm: 0.0,
    });
    for i in 1..path.len() {
        let prev = out[i - 1];
        let q = if i >= 2 && path[i - 1].delta {
            // No technique connects or merges at a specular vertex; the
            // other terms carry over with the specular lobe's densities
            // taken as solid-angle density 1 each way, as BDPT's
            // `after_specular` takes them.
            let fwd = f.m(path[i - 1].convert_density(1.0, &path[i]));
            let rev = f.m(path[i - 1].convert_density(1.0, &path[i - 2]));
            let k = if fwd > 0.0 { rev / fwd } else { 0.0 };
            PartialMis {
                d_vcm: 0.0,
                d_vc: prev.d_vc * k,
                d_vm: prev.d_vm * k,
            }
        } else {
            let inv = if path[i].pdf_fwd > 0.0 {
                1.0 / f.m(path[i].pdf_fwd)
            } else {
                0.0
            };
            // A merge at vertex i − 1, and p← of vertex i − 2 (set when
            // the walk left vertex i − 1), exist from i = 2 on.
            let (rev, merge) = if i >= 2 {
                (f.m(path[i - 2].pdf_rev), 1.0)
            } else {
                (0.0, 0.0)
            };
            PartialMis {
                d_vcm: if i == 1 && light_path {
                    inv * f.pt
                } else {
                    inv
                },
                d_vc: inv * (prev.d_vc * rev + prev.d_vcm + f.vm * merge),
                d_vm: inv * (prev.d_vm * rev + prev.d_vcm * f.vc + merge),
            }
        };
        out.push(q);
    }
}

/// A stored light-subpath vertex (a surface whose BSDF is not purely specular).
#[derive(Clone, Copy, Debug)]
pub struct LightVertex {
    /// The vertex (its `wo` points back to the previous light vertex).
    pub v: Vertex,
    /// Its MIS quantities.
    pub mis: PartialMis,
    /// Turns a solid-angle density at this vertex towards the previous
    /// light vertex into the area density there.
    pub to_prev: f32,
    /// Segments from the emitter.
    pub depth: u32,
}

/// Solid-angle density of the BSDF at `v` scattering from `wo` into `wi`
/// (unit world directions away from `v`).
fn scatter_pdf(scene: &Scene, v: &Vertex, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
    let frame = scene.shading_frame(&v.sp);
    scene
        .bsdf_at(&v.sp)
        .pdf(frame.to_local(wo), frame.to_local(wi), mode)
}

/// MIS weight of the technique whose camera subpath `z[..=j]` found the
/// emitter `z[j]`.
pub fn weight_emission(
    scene: &Scene,
    f: &MisFactors,
    z: &[Vertex],
    mis: &[PartialMis],
    j: usize,
) -> f32 {
    // Seen directly: no other technique makes the path (BDPT's (1, 1) is
    // not run), weight one.
    if j == 1 {
        return 1.0;
    }
    let e = &z[j];
    let p_rev = f.m(e.pdf_light_origin(scene));
    let p_rev_prev = f.m(e.pdf_light(scene, &z[j - 1]));
    // `dVCM_j`: next-event estimation; `dVC_j`: light-subpath techniques.
    1.0 / (1.0 + p_rev * (mis[j].d_vcm + p_rev_prev * mis[j].d_vc / f.pt))
}

/// Contribution of the technique whose camera subpath `z[..=j]` found an
/// emitter at `z[j]`, MIS weight included (black when `z[j]` emits nothing
/// towards `z[j − 1]`).
pub fn emission(scene: &Scene, f: &MisFactors, z: &[Vertex], mis: &[PartialMis], j: usize) -> Rgb {
    let e = &z[j];
    let le = e.le(scene, &z[j - 1]);
    if le.is_black() {
        return Rgb::BLACK;
    }
    e.beta * le * weight_emission(scene, f, z, mis, j)
}

/// MIS weight of next-event estimation from camera vertex `z[j]` to the
/// emitter vertex `lv` (whose `pdf_fwd` is its light-path origin density).
pub fn weight_direct(
    scene: &Scene,
    f: &MisFactors,
    lv: &Vertex,
    z: &[Vertex],
    mis: &[PartialMis],
    j: usize,
) -> f32 {
    let pt = &z[j];
    let w_light = if lv.is_delta_light(scene) {
        0.0
    } else {
        f.m(pt.pdf(scene, Some(&z[j - 1]), lv, TransportMode::Radiance)) / f.m(lv.pdf_fwd)
    };
    let p_fwd = f.m(lv.pdf_light(scene, pt));
    // The camera side holds light-subpath techniques only.
    let w_camera = camera_side_weight(scene, f, z, mis, j, lv, p_fwd) / f.pt;
    1.0 / (w_light + 1.0 + w_camera)
}

/// The camera side's term of a connection between camera vertex `z[j]`
/// and the vertex `other` of the light side: `p_fwd · (η_VM + dVCM_j +
/// p_fwd_prev · dVC_j)`, where `p_fwd` is the density (already through
/// [`MisFactors::m`]) with which `other`'s side produces `z[j]`, and
/// `p_fwd_prev` the density with which `z[j]`, reached from `other`,
/// produces `z[j − 1]`.
fn camera_side_weight(
    scene: &Scene,
    f: &MisFactors,
    z: &[Vertex],
    mis: &[PartialMis],
    j: usize,
    other: &Vertex,
    p_fwd: f32,
) -> f32 {
    let p_fwd_prev = if j >= 2 {
        f.m(z[j].pdf(scene, Some(other), &z[j - 1], TransportMode::Importance))
    } else {
        0.0
    };
    p_fwd * (f.vm + mis[j].d_vcm + p_fwd_prev * mis[j].d_vc)
}

/// Next-event estimation at camera vertex `z[j]` with the light-sample
/// numbers `u_sel`, `u_pos`: its contribution *without* the MIS weight and
/// the emitter vertex, for [`weight_direct`] (the caller may weigh one
/// sample with more than one set of [`MisFactors`]).
pub fn direct(
    scene: &Scene,
    z: &[Vertex],
    j: usize,
    u_sel: f32,
    u_pos: (f32, f32),
) -> Option<(Rgb, Vertex)> {
    let pt = &z[j];
    let (index, _) = scene.lights.select(u_sel)?;
    let ds = scene
        .lights
        .sample_direct(&scene.geometry, pt.p(), u_sel, u_pos)?;
    let mut lv = if ds.at_infinity {
        Vertex::infinite(index, ds.wi, ds.le / ds.pdf, 0.0)
    } else {
        Vertex::light(scene, index, ds.p, ds.le / ds.pdf, 0.0)
    };
    lv.pdf_fwd = lv.pdf_light_origin(scene);
    let l =
        pt.beta * pt.f(scene, &lv, TransportMode::Radiance) * lv.beta * ds.wi.dot(pt.sp.ns).abs();
    if l.is_black() || !(lv.pdf_fwd > 0.0) || !scene.light_visible(&pt.sp, &ds) {
        return None;
    }
    Some((l, lv))
}

/// MIS weight of connecting light vertex `y` to camera vertex `z[j]`.
pub fn weight_connection(
    scene: &Scene,
    f: &MisFactors,
    y: &LightVertex,
    z: &[Vertex],
    mis: &[PartialMis],
    j: usize,
) -> f32 {
    let (yv, zj) = (&y.v, &z[j]);
    let Some(to_z) = yv.direction_to(zj) else {
        return 0.0;
    };
    let p_rev = f.m(zj.pdf(scene, Some(&z[j - 1]), yv, TransportMode::Radiance));
    let p_rev_prev = f.m(scatter_pdf(scene, yv, to_z, yv.wo, TransportMode::Radiance) * y.to_prev);
    let w_light = p_rev * (f.vm + y.mis.d_vcm + p_rev_prev * y.mis.d_vc);
    let p_fwd = f.m(yv.convert_density(
        scatter_pdf(scene, yv, yv.wo, to_z, TransportMode::Importance),
        zj,
    ));
    let w_camera = camera_side_weight(scene, f, z, mis, j, yv, p_fwd);
    1.0 / (w_light + 1.0 + w_camera)
}

/// Contribution of connecting light vertex `y` to camera vertex `z[j]`
/// (both connectible), MIS weight included.
pub fn connection(
    scene: &Scene,
    f: &MisFactors,
    y: &LightVertex,
    z: &[Vertex],
    mis: &[PartialMis],
    j: usize,
) -> Rgb {
    let (yv, zj) = (&y.v, &z[j]);
    let l = yv.beta
        * yv.f(scene, zj, TransportMode::Importance)
        * zj.f(scene, yv, TransportMode::Radiance)
        * zj.beta;
    if l.is_black() {
        return Rgb::BLACK;
    }
    let g = geometry_term(scene, yv, zj);
    if !(g > 0.0) {
        return Rgb::BLACK;
    }
    l * (g * weight_connection(scene, f, y, z, mis, j))
}

/// Connections of every light vertex in `light` (one subpath's) to camera
/// vertex `z[j]` (connectible) within the depth limit, each times
/// `weight` (one over the light subpaths this camera subpath connects
/// to), added to `l`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn connections_at(
    scene: &Scene,
    f: &MisFactors,
    light: &[LightVertex],
    z: &[Vertex],
    mis: &[PartialMis],
    j: usize,
    max_depth: usize,
    weight: f32,
    l: &mut Rgb,
    tally: &mut Tally,
) {
    for y in light {
        if y.depth as usize + j < max_depth {
            let c = connection(scene, f, y, z, mis, j) * weight;
            if !c.is_black() && tally.take(Technique::Connection, c) {
                *l += c;
            }
        }
    }
}

/// Light tracing: connects light vertex `y` to the camera (a lens point
/// from `source` for a thin lens); the raster position and the weighted
/// contribution (a splat normalised by light subpaths per pixel).
pub fn light_trace(
    scene: &Scene,
    f: &MisFactors,
    y: &LightVertex,
    source: &mut dyn RandomSource,
) -> Option<(Vec2, Rgb)> {
    let yv = &y.v;
    let cs = if scene.camera.has_lens() {
        scene.camera.sample_wi_lens(yv.p(), source.next_2d())?
    } else {
        scene.camera.sample_wi(yv.p())?
    };
    let cam = Vertex::camera(cs.origin, cs.raster, Rgb::splat(cs.we / cs.pdf));
    let l = yv.beta
        * yv.f(scene, &cam, TransportMode::Importance)
        * cam.beta
        * cs.wi.dot(yv.sp.ns).abs();
    if l.is_black()
        || !scene
            .geometry
            .segment_clear(yv.sp.spawn_origin(cs.origin), cs.origin)
    {
        return None;
    }
    Some((cs.raster, l * weight_light_trace(scene, f, y, &cam)))
}

/// MIS weight of connecting light vertex `y` to the camera vertex `cam`
/// (light tracing).
pub fn weight_light_trace(scene: &Scene, f: &MisFactors, y: &LightVertex, cam: &Vertex) -> f32 {
    let yv = &y.v;
    let Some(to_cam) = yv.direction_to(cam) else {
        return 0.0;
    };
    let p_rev = f.m(cam.pdf(scene, None, yv, TransportMode::Radiance));
    let p_rev_prev =
        f.m(scatter_pdf(scene, yv, to_cam, yv.wo, TransportMode::Radiance) * y.to_prev);
    1.0 / (1.0 + p_rev * (f.vm + y.mis.d_vcm + p_rev_prev * y.mis.d_vc))
}

/// MIS weight of merging light vertex `y` at camera vertex `z[j]`, given
/// the camera BSDF's densities towards `y.v.wo` (`pdf_dir`, radiance) and
/// back (`pdf_rev`, importance), both per solid angle.
pub fn weight_merge(
    f: &MisFactors,
    y: &LightVertex,
    mis: &PartialMis,
    to_camera_prev: f32,
    pdf_dir: f32,
    pdf_rev: f32,
) -> f32 {
    let w_light = f.vc * y.mis.d_vcm + f.m(pdf_dir * y.to_prev) * y.mis.d_vm;
    let w_camera = f.vc * mis.d_vcm + f.m(pdf_rev * to_camera_prev) * mis.d_vm;
    1.0 / (w_light + 1.0 + w_camera)
}

/// MIS weight of merging light vertex `y` at camera vertex `z[j]` (the
/// densities evaluated here; the merge loop shares them with the BSDF value).
pub fn weight_merge_at(
    scene: &Scene,
    f: &MisFactors,
    y: &LightVertex,
    z: &[Vertex],
    mis: &[PartialMis],
    j: usize,
) -> f32 {
    let zj = &z[j];
    let pdf_dir = scatter_pdf(scene, zj, zj.wo, y.v.wo, TransportMode::Radiance);
    let pdf_rev = scatter_pdf(scene, zj, y.v.wo, zj.wo, TransportMode::Importance);
    let to_camera_prev = zj.convert_density(1.0, &z[j - 1]);
    weight_merge(f, y, &mis[j], to_camera_prev, pdf_dir, pdf_rev)
}

/// A camera vertex prepared for merging: its BSDF, shading frame and the
/// density conversion towards the previous camera vertex, computed once
/// for all the light vertices merged there.
pub struct MergePoint<'a> {
    bsdf: BsdfAt<'a>,
    frame: Frame,
    /// `wo` in the shading frame.
    wo: Vec3,
    ng: Vec3,
    ns: Vec3,
    to_camera_prev: f32,
}

impl<'a> MergePoint<'a> {
    /// Camera vertex `z[j]` (`j ≥ 1`) of a camera subpath.
    pub fn new(scene: &'a Scene, z: &[Vertex], j: usize) -> Self {
        let zj = &z[j];
        let frame = scene.shading_frame(&zj.sp);
        MergePoint {
            bsdf: scene.bsdf_at(&zj.sp),
            frame,
            wo: frame.to_local(zj.wo),
            ng: zj.sp.ng,
            ns: zj.sp.ns,
            to_camera_prev: zj.convert_density(1.0, &z[j - 1]),
        }
    }

    /// Light vertex `y` merged here, MIS-weighted (weight one for `ppm`),
    /// without the camera throughput and the kernel normalisation
    /// `1/(π r² N)`; `mis` is this camera vertex's.
    pub fn merge(&self, f: &MisFactors, y: &LightVertex, mis: &PartialMis, ppm: bool) -> Rgb {
        let wi_world = y.v.wo;
        let cos_g = self.ng.dot(wi_world).abs();
        if !(cos_g > 0.0) {
            return Rgb::BLACK;
        }
        let wi = self.frame.to_local(wi_world);
        let (fz, pdf_dir) = self.bsdf.eval_pdf(self.wo, wi, TransportMode::Radiance);
        if fz.is_black() {
            return Rgb::BLACK;
        }
        let w = if ppm {
            1.0
        } else {
            let pdf_rev = self.bsdf.pdf(wi, self.wo, TransportMode::Importance);
            weight_merge(f, y, mis, self.to_camera_prev, pdf_dir, pdf_rev)
        };
        // The photon estimates flux per geometric area; the shading
        // cosine's ratio makes the estimate the same integral as a
        // connection's (Veach's adjoint BSDF).
        fz * y.v.beta * (w * self.ns.dot(wi_world).abs() / cos_g)
    }
}

/// Where a technique's energy is counted in the statistics.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Technique {
    /// The camera subpath finds an emitter.
    Emission = 0,
    /// Next-event estimation.
    Direct = 1,
    /// A light vertex connected to the camera.
    LightTrace = 2,
    /// A light vertex connected to a camera vertex.
    Connection = 3,
    /// Vertex merging.
    Merge = 4,
}

/// Names of the techniques, in [`Technique`] order.
pub const TECHNIQUE_NAMES: [&str; 5] = ["emission", "direct", "light_trace", "connection", "merge"];

/// Per-unit counters: luminance summed per technique, dropped non-finite
/// contributions, stored light vertices.
#[derive(Clone, Debug, Default)]
pub(crate) struct Tally {
    pub(crate) energy: [f64; 5],
    pub(crate) nonfinite: u64,
    pub(crate) light_vertices: u64,
}

impl Tally {
    /// Counts `l` for `t`; false (and counted as dropped) when not finite.
    pub(crate) fn take(&mut self, t: Technique, l: Rgb) -> bool {
        if !l.is_finite() {
            self.nonfinite += 1;
            return false;
        }
        self.energy[t as usize] += f64::from(l.luminance());
        true
    }

    /// The counters as a distributed run sends them.
    pub(crate) fn to_counters(&self) -> crate::cluster::Counters {
        (
            self.energy.to_vec(),
            vec![self.nonfinite, self.light_vertices],
        )
    }

    /// The counters [`Self::to_counters`] sent.
    pub(crate) fn from_counters((energy, counts): crate::cluster::Counters) -> Tally {
        Tally {
            energy: std::array::from_fn(|i| energy[i]),
            nonfinite: counts[0],
            light_vertices: counts[1],
        }
    }

    pub(crate) fn add(&mut self, o: &Tally) {
        for (a, b) in self.energy.iter_mut().zip(&o.energy) {
            *a += b;
        }
        self.nonfinite += o.nonfinite;
        self.light_vertices += o.light_vertices;
    }
}

/// Per-thread storage: subpaths and their MIS quantities.
#[derive(Default)]
struct Buffers {
    paths: SubpathBuffers,
    camera_mis: Vec<PartialMis>,
    light_mis: Vec<PartialMis>,
}

thread_local! {
    static BUFFERS: RefCell<Buffers> = RefCell::new(Buffers::default());
}

/// What the camera pass of one iteration reads.
struct IterationData<'a> {
    factors: MisFactors,
    /// `1 / (π r² L)` for `L` light subpaths.
    merge_norm: f32,
    /// Camera subpaths `N` (pixels) and light subpaths `L` of the iteration.
    pixels: usize,
    light_paths: usize,
    vertices: &'a [LightVertex],
    /// End of each light subpath's vertices in `vertices`.
    ends: &'a [u32],
    grid: &'a HashGrid,
}

/// `k = L/N`: the light-subpath techniques' densities with `light_paths`
/// light subpaths per `pixels` camera subpaths, relative to one each.
fn light_density_scale(pixels: usize, light_paths: usize) -> f32 {
    (light_paths as f64 / pixels as f64) as f32
}

/// The vertex connection and merging integrator.
#[derive(Clone, Copy, Debug)]
pub struct Vcm {
    /// Longest path in segments (`u32::MAX` = unbounded).
    pub max_depth: u32,
    /// Depth from which Russian roulette applies.
    pub rr_depth: u32,
    /// Techniques that run.
    pub mode: VcmMode,
    /// MIS heuristic.
    pub heuristic: MisHeuristic,
    /// Merge radius of the first iteration (scene units).
    pub radius: f32,
    /// Radius reduction exponent (1: fixed radius).
    pub alpha: f32,
    /// Light subpaths per iteration per pixel ([`VcmSettings::light_subpaths`]).
    pub light_subpaths: f64,
}

impl Vcm {
    /// Light subpaths `L` per iteration for `pixels` camera subpaths:
    /// `light_subpaths × pixels`, rounded, at least one.
    pub fn light_paths(&self, pixels: usize) -> usize {
        ((self.light_subpaths * pixels as f64).round() as usize).max(1)
    }

    /// The factors of an iteration of radius `radius` with `pixels` camera
    /// and `light_paths` light subpaths: the light-subpath techniques'
    /// densities `k = L/N` times those of one light subpath per camera
    /// subpath (each light subpath is light-traced and stored for merging,
    /// and with `L ≥ N` connected once, so every light-subpath technique has
    /// `L/N` samples per camera subpath; with `L < N` a connection has one,
    /// and the weights, still a partition of unity, are not the
    /// heuristic's for it).
    fn factors(&self, radius: f32, pixels: usize, light_paths: usize) -> MisFactors {
        let f = MisFactors::new(self.mode, self.heuristic, radius, pixels as f64);
        if light_paths == pixels {
            f
        } else {
            f.with_light_density_scale(light_density_scale(pixels, light_paths))
        }
    }

    /// The MIS scale `k = L/N` of the light-subpath techniques' densities
    /// with [`Self::light_paths`] light subpaths per `pixels` camera
    /// subpaths (1 at the default one light subpath per pixel).
    pub fn light_density_scale(&self, pixels: usize) -> f32 {
        light_density_scale(pixels, self.light_paths(pixels))
    }

    /// Merge radius of iteration `i` (from 0), as SmallVCM: `r / (i+1)^{(1−α)/2}`.
    pub fn radius_at(&self, i: u64) -> f32 {
        let r = f64::from(self.radius) / ((i + 1) as f64).powf(0.5 * (1.0 - f64::from(self.alpha)));
        (r as f32).max(1e-7)
    }

    /// Traces one light subpath into `buffers`, appends its stored vertices
    /// to `store` and passes each light-tracing splat to `splat`.
    #[allow(clippy::too_many_arguments)]
    pub fn trace_light_subpath(
        &self,
        scene: &Scene,
        f: &MisFactors,
        source: &mut dyn RandomSource,
        paths: &mut SubpathBuffers,
        light_mis: &mut Vec<PartialMis>,
        store: &mut Vec<LightVertex>,
        mut splat: impl FnMut(Technique, Vec2, Rgb),
    ) {
        let n = generate_light_subpath(
            scene,
            source,
            self.max_depth as usize,
            Some(self.rr_depth),
            &mut paths.light,
        );
        partial_mis(scene, &paths.light[..n], f, light_mis);
        for (i, &mis) in light_mis.iter().enumerate().skip(1) {
            let v = paths.light[i];
            if v.kind != VertexKind::Surface || !v.is_connectible(scene) {
                continue;
            }
            let y = LightVertex {
                v,
                mis,
                to_prev: v.convert_density(1.0, &paths.light[i - 1]),
                depth: i as u32,
            };
            if self.mode.connects()
                && i < self.max_depth as usize
                && let Some((raster, l)) = light_trace(scene, f, &y, source)
            {
                splat(Technique::LightTrace, raster, l);
            }
            store.push(y);
        }
    }

    /// One camera sample through `raster` for light subpath `path`
    /// (index into the iteration's subpaths): its estimate.
    #[allow(clippy::too_many_arguments)]
    fn camera_sample(
        &self,
        scene: &Scene,
        it: &IterationData,
        path: usize,
        raster: Vec2,
        source: &mut dyn RandomSource,
        buffers: &mut Buffers,
        tally: &mut Tally,
    ) -> Rgb {
        let max_depth = self.max_depth as usize;
        let f = &it.factors;
        let n = self.trace_camera_subpath(
            scene,
            f,
            raster,
            source,
            &mut buffers.paths.camera,
            &mut buffers.camera_mis,
        );
        let (z, mis) = (&buffers.paths.camera[..n], &buffers.camera_mis[..]);
        let light = |i: usize| {
            let start = if i == 0 { 0 } else { it.ends[i - 1] as usize };
            &it.vertices[start..it.ends[i] as usize]
        };
        // Camera subpath `path` connects to light subpaths `path`,
        // `path + N`, … below `L` (with `L ≥ N`: every light subpath
        // connects once), or to `path mod L` (`L < N`), each connection
        // weighted one over their count.
        let (first, stride) = if it.light_paths >= it.pixels {
            (path, it.pixels)
        } else {
            (path % it.light_paths, usize::MAX)
        };
        let paired = (first..it.light_paths).step_by(stride);
        let weight = 1.0 / paired.len() as f32;
        let ppm = self.mode == VcmMode::Ppm;
        let mut l = Rgb::BLACK;
        // Every camera vertex before this one scattered specularly.
        let mut specular = true;
        for j in 1..n {
            let zj = &z[j];
            if !self.path_tracing_at(scene, f, z, mis, j, specular, source, &mut l, tally, None) {
                break;
            }
            if zj.is_connectible(scene) {
                if self.mode.connects() {
                    for i in paired.clone() {
                        let light = light(i);
                        connections_at(
                            scene, f, light, z, mis, j, max_depth, weight, &mut l, tally,
                        );
                    }
                }
                if self.mode.merges() && (!ppm || specular) {
                    let c = self.merge(scene, it, z, &mis[j], j);
                    if tally.take(Technique::Merge, c) {
                        l += c;
                    }
                }
            }
            specular &= zj.delta;
            if ppm && !specular {
                break;
            }
        }
        l
    }

    /// Traces one camera subpath through `raster` into `path` and its MIS
    /// quantities into `mis`; returns its vertex count.
    pub fn trace_camera_subpath(
        &self,
        scene: &Scene,
        f: &MisFactors,
        raster: Vec2,
        source: &mut dyn RandomSource,
        path: &mut Vec<Vertex>,
        mis: &mut Vec<PartialMis>,
    ) -> usize {
        let n = generate_camera_subpath(
            scene,
            raster,
            source,
            (self.max_depth as usize).saturating_add(1),
            Some(self.rr_depth),
            path,
        );
        partial_mis(scene, &path[..n], f, mis);
        n
    }

    /// The path-tracing techniques at camera vertex `z[j]`, added to `l`:
    /// the emitter found there and next-event estimation with a fresh light
    /// sample (its numbers drawn at every surface vertex below the depth
    /// limit, used or not: a fixed count per vertex). `specular`: every
    /// camera vertex before `z[j]` scattered specularly (`ppm` mode).
    /// False when the subpath ends at `z[j]` (not a surface). With `alt`,
    /// the same samples weighted with its factors are added to its sum too
    /// (finite values only, not tallied): `mcmc-vcm`'s `con_estimate =
    /// transfer` needs them with the tracing density's weights.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn path_tracing_at(
        &self,
        scene: &Scene,
        f: &MisFactors,
        z: &[Vertex],
        mis: &[PartialMis],
        j: usize,
        specular: bool,
        source: &mut dyn RandomSource,
        l: &mut Rgb,
        tally: &mut Tally,
        mut alt: Option<(&MisFactors, &mut Rgb)>,
    ) -> bool {
        let mut add_alt = |weighted: &dyn Fn(&MisFactors) -> Rgb| {
            if let Some((fa, la)) = alt.as_mut() {
                let c = weighted(fa);
                if c.is_finite() {
                    **la += c;
                }
            }
        };
        let zj = &z[j];
        let ppm = self.mode == VcmMode::Ppm;
        let nee =
            (self.mode.connects() && zj.kind == VertexKind::Surface && j < self.max_depth as usize)
                .then(|| (source.next_1d(), source.next_2d()));
        if zj.is_light() && (!ppm || specular) {
            let c = if ppm {
                zj.le(scene, &z[j - 1]) * zj.beta
            } else {
                emission(scene, f, z, mis, j)
            };
            if tally.take(Technique::Emission, c) {
                *l += c;
            }
            add_alt(&|fa| {
                if ppm {
                    c
                } else {
                    emission(scene, fa, z, mis, j)
                }
            });
        }
        if zj.kind != VertexKind::Surface {
            return false;
        }
        if zj.is_connectible(scene)
            && let Some((u_sel, u_pos)) = nee
            && let Some((c, lv)) = direct(scene, z, j, u_sel, u_pos)
        {
            let weighted = c * weight_direct(scene, f, &lv, z, mis, j);
            if tally.take(Technique::Direct, weighted) {
                *l += weighted;
            }
            add_alt(&|fa| c * weight_direct(scene, fa, &lv, z, mis, j));
        }
        true
    }

    /// Merging at camera vertex `z[j]` with every stored light vertex
    /// within the radius.
    fn merge(
        &self,
        scene: &Scene,
        it: &IterationData,
        z: &[Vertex],
        mis: &PartialMis,
        j: usize,
    ) -> Rgb {
        let at = MergePoint::new(scene, z, j);
        let ppm = self.mode == VcmMode::Ppm;
        let mut sum = Rgb::BLACK;
        it.grid.query(z[j].p(), |index, _| {
            let y = &it.vertices[index as usize];
            if y.depth as usize + j <= self.max_depth as usize {
                sum += at.merge(&it.factors, y, mis, ppm);
            }
        });
        z[j].beta * sum * it.merge_norm
    }

    /// Renders to `run`'s budget: whole iterations, one camera sample per
    /// pixel each; stopping discards the iteration in flight. With a
    /// checkpoint, saves after every iteration and continues from the
    /// progress it holds, which must have passed [`check_checkpoint`] (the
    /// command line and [`VcmSettings`]' render check it).
    pub fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Rendered {
        let (width, height) = (scene.film.width, scene.film.height);
        let pixels = width as usize * height as usize;
        let filter = Arc::new(Filter::new(scene.film.filter, width, height));
        let mut film = Film::new(width, height, filter.clone());
        let start = Instant::now();
        let deadline = Deadline::new(start, run.time_budget);
        let target = run.samples_per_pixel(scene.sample_count).map(u64::from);
        let out_of_time = || deadline.passed();
        let tiles: Vec<(u32, u32, u32, u32)> = (0..height.div_ceil(TILE))
            .flat_map(|ty| {
                (0..width.div_ceil(TILE)).map(move |tx| {
                    let (x0, y0) = (tx * TILE, ty * TILE);
                    (x0, y0, (x0 + TILE).min(width), (y0 + TILE).min(height))
                })
            })
            .collect();
        let mut units: Vec<(Film, Vec<LightVertex>, Vec<u32>, Tally)> = (0..LIGHT_UNITS)
            .map(|_| {
                let f = Film::new_splat_only(width, height, filter.clone());
                (f, Vec::new(), Vec::new(), Tally::default())
            })
            .collect();
        let mut vertices: Vec<LightVertex> = Vec::new();
        // L light subpaths per iteration; a light-tracing splat (normalised
        // for one light subpath per pixel) counts N/L.
        let light_paths = self.light_paths(pixels);
        let light_trace_weight = (pixels as f64 / light_paths as f64) as f32;
        let mut ends: Vec<u32> = Vec::with_capacity(light_paths);
        let mut grid = HashGrid::default();
        let mut tally = Tally::default();
        let mut interrupted = false;
        // Distributed (`crate::cluster`): every rank traces every light
        // subpath (the camera pass needs them all) but keeps the splats of
        // its light units only, renders its tiles, and rank 0 adds the
        // units' films in unit order (light units, then tiles), as here.
        let cluster = crate::cluster::current();
        let resumed_from = run.checkpoint.as_ref().and_then(|c| {
            let (done, saved) = resume_point(c, &filter);
            if let Some((f, t)) = saved {
                (film, tally) = (f, t);
            }
            done
        });
        let mut iterations = resumed_from.unwrap_or(0);
        let mut checkpoint_error: Option<String> = None;
        let mut rank_units = 0u64;
        while target.is_none_or(|t| iterations < t) && self.max_depth > 0 {
            let stopping = stop.load(Ordering::Relaxed) || out_of_time();
            if cluster.map_or(stopping, |c| c.any(stopping)) {
                interrupted = true;
                break;
            }
            let radius = self.radius_at(iterations);
            let factors = self.factors(radius, pixels, light_paths);
            let aborted = AtomicBool::new(false);
            let check_abort = || {
                if stop.load(Ordering::Relaxed) || out_of_time() {
                    aborted.store(true, Ordering::Relaxed);
                }
                aborted.load(Ordering::Relaxed)
            };

            // Light pass: unit u traces subpaths [u·L/U, (u+1)·L/U).
            units.par_iter_mut().enumerate().for_each(
                |(u, (splats, store, unit_ends, unit_tally))| {
                    splats.clear();
                    store.clear();
                    unit_ends.clear();
                    *unit_tally = Tally::default();
                    let mut src = unit_source(run.seed, 2 * iterations, u as u64);
                    let range = light_paths * u / LIGHT_UNITS..light_paths * (u + 1) / LIGHT_UNITS;
                    BUFFERS.with_borrow_mut(|b| {
                        for (k, _) in range.enumerate() {
                            if k % STOP_CHECK == 0 && check_abort() {
                                return;
                            }
                            self.trace_light_subpath(
                                scene,
                                &factors,
                                &mut src,
                                &mut b.paths,
                                &mut b.light_mis,
                                store,
                                |t, raster, l| {
                                    let l = l * light_trace_weight;
                                    if unit_tally.take(t, l) {
                                        splats.splat(raster, l);
                                    }
                                },
                            );
                            unit_ends.push(store.len() as u32);
                        }
                    });
                    unit_tally.light_vertices = store.len() as u64;
                },
            );
            // On a cluster the ranks agree after the camera pass (whose
            // tiles then return at once).
            if cluster.is_none() && aborted.load(Ordering::Relaxed) {
                interrupted = true;
                break;
            }
            vertices.clear();
            ends.clear();
            for (_, store, unit_ends, _) in &units {
                let offset = vertices.len() as u32;
                vertices.extend_from_slice(store);
                ends.extend(unit_ends.iter().map(|e| e + offset));
            }
            if self.mode.merges() {
                grid.build(vertices.iter().map(|y| y.v.p()), radius);
            }
            let data = IterationData {
                factors,
                merge_norm: 1.0 / (PI * radius * radius * light_paths as f32),
                pixels,
                light_paths,
                vertices: &vertices,
                ends: &ends,
                grid: &grid,
            };

            // Camera pass: tiles, camera subpath of pixel (x, y) paired
            // with light subpath y·width + x.
            let results: Vec<(usize, Film, Tally)> = tiles
                .par_iter()
                .enumerate()
                .filter(|&(t, _)| crate::cluster::owns(cluster, t))
                .map(|(t, &(x0, y0, x1, y1))| {
                    let mut tile = Film::for_tile(width, height, x0, y0, x1, y1, filter.clone());
                    let mut unit_tally = Tally::default();
                    if check_abort() {
                        return (t, tile, unit_tally);
                    }
                    let mut src = unit_source(run.seed, 2 * iterations + 1, t as u64);
                    BUFFERS.with_borrow_mut(|b| {
                        for y in y0..y1 {
                            for x in x0..x1 {
                                let u = src.next_2d();
                                let raster = Vec2::new(x as f32 + u.0, y as f32 + u.1);
                                let path = (y * width + x) as usize;
                                let l = self.camera_sample(
                                    scene,
                                    &data,
                                    path,
                                    raster,
                                    &mut src,
                                    b,
                                    &mut unit_tally,
                                );
                                tile.add_sample(raster, l);
                            }
                        }
                    });
                    observer.progress(u64::from((x1 - x0) * (y1 - y0)));
                    (t, tile, unit_tally)
                })
                .collect();
            let local = aborted.load(Ordering::Relaxed);
            if cluster.map_or(local, |c| c.any(local)) {
                interrupted = true;
                break;
            }
            let light = units
                .iter()
                .enumerate()
                .map(|(u, (f, _, _, ut))| (u, f, ut));
            let camera = results.iter().map(|(t, f, ut)| (LIGHT_UNITS + t, f, ut));
            let mine = light
                .filter(|&(u, ..)| crate::cluster::owns(cluster, u))
                .chain(camera)
                .map(|(u, f, ut)| (u, f, ut.to_counters()));
            rank_units += ((0..units.len())
                .filter(|&u| crate::cluster::owns(cluster, u))
                .count()
                + results.len()) as u64;
            for c in crate::cluster::reduce_units(&mut film, mine, &filter) {
                tally.add(&Tally::from_counters(c));
            }
            iterations += 1;
            if let Some(c) = &run.checkpoint
                && crate::cluster::is_root()
                && checkpoint_error.is_none()
            {
                let mut progress = Progress::of(iterations, iterations, tally.nonfinite, &film);
                progress.extra = saved_words(&tally);
                checkpoint_error = crate::checkpoint::save(&c.path, c.fingerprint, &progress).err();
            }
            observer.snapshot(
                &|| film.develop(iterations as f64),
                iterations * pixels as u64,
            );
        }
        let seconds = start.elapsed().as_secs_f64();
        let mut rendered = self.report(
            &film,
            iterations,
            seconds,
            interrupted,
            pixels,
            &tally,
            scene,
        );
        if let Some(c) = &run.checkpoint {
            rendered.statistics.insert(
                "checkpoint".into(),
                c.statistics("iterations", resumed_from, iterations, &checkpoint_error),
            );
        }
        if let serde_json::Value::Object(m) = crate::cluster::with_ranks(
            serde_json::Value::Object(std::mem::take(&mut rendered.statistics)),
            serde_json::json!({"units": rank_units, "seconds": seconds}),
        ) {
            rendered.statistics = m;
        }
        rendered
    }

    /// The registry's result with the JSON statistics.
    #[allow(clippy::too_many_arguments)]
    fn report(
        &self,
        film: &Film,
        iterations: u64,
        seconds: f64,
        interrupted: bool,
        pixels: usize,
        tally: &Tally,
        scene: &Scene,
    ) -> Rendered {
        let samples = iterations * pixels as u64;
        let per_second = |n: f64| if seconds > 0.0 { n / seconds } else { 0.0 };
        let total: f64 = tally.energy.iter().sum();
        let shares: serde_json::Map<String, serde_json::Value> = TECHNIQUE_NAMES
            .iter()
            .zip(&tally.energy)
            .map(|(name, e)| {
                let share = if total > 0.0 { e / total } else { 0.0 };
                (name.to_string(), share.into())
            })
            .collect();
        let last_radius = self.radius_at(iterations.saturating_sub(1));
        let statistics = serde_json::json!({
            "iterations": iterations,
            "spp": iterations,
            "iterations_per_second": per_second(iterations as f64),
            "samples_per_second": per_second(samples as f64),
            "mode": self.mode.name(),
            "radius_initial": self.radius,
            "radius_final": last_radius,
            "alpha": self.alpha,
            "light_subpaths_per_iteration": self.light_paths(pixels),
            "light_vertices_per_iteration": if iterations > 0 { tally.light_vertices as f64 / iterations as f64 } else { 0.0 },
            "energy_shares": shares,
            "nonfinite_samples": tally.nonfinite,
            "bvh_build_seconds": scene.geometry.build_time.as_secs_f64(),
            "triangles": scene.geometry.triangles,
        });
        Rendered {
            image: film.develop(iterations as f64),
            seconds,
            samples,
            interrupted,
            statistics: match statistics {
                serde_json::Value::Object(m) => m,
                _ => serde_json::Map::new(),
            },
            nonfinite_dump: None,
            layers: Vec::new(),
            summary: format!(
                "{iterations} iterations in {seconds:.2} s ({:.2} it/s, radius {:.3e} → {last_radius:.3e}){}",
                per_second(iterations as f64),
                self.radius,
                if interrupted { ", stopped early" } else { "" }
            ),
        }
    }
}

/// `vcm`'s words in a checkpoint ([`Progress::extra`]): the tally's
/// technique energies (as bits, in [`Technique`] order) and its light
/// vertices (the non-finite count is the format's own word).
fn saved_words(tally: &Tally) -> Vec<u64> {
    let mut out: Vec<u64> = tally.energy.iter().map(|e| e.to_bits()).collect();
    out.push(tally.light_vertices);
    out
}

/// The tally a `vcm` checkpoint's `progress` holds: refused (one line)
/// unless a `vcm` run could have written it: one sample per pixel an
/// iteration, the words [`saved_words`] writes, finite energies and
/// counts within 2^53.
fn saved_tally(progress: &Progress) -> Result<Tally, String> {
    if progress.spp_done != progress.pass {
        return Err(format!(
            "holds {} iterations and {} samples per pixel: not a checkpoint of vcm (one sample an iteration)",
            progress.pass, progress.spp_done
        ));
    }
    let words = &progress.extra;
    if words.len() != TECHNIQUE_NAMES.len() + 1 {
        return Err(format!(
            "holds {} words of the integrator's, vcm keeps {}: not a checkpoint of vcm",
            words.len(),
            TECHNIQUE_NAMES.len() + 1
        ));
    }
    let energy: [f64; 5] = std::array::from_fn(|i| f64::from_bits(words[i]));
    let light_vertices = words[TECHNIQUE_NAMES.len()];
    if energy.iter().any(|e| !e.is_finite()) || light_vertices > crate::checkpoint::MAX_COUNT {
        return Err(format!(
            "impossible tally: energies {energy:?}, {light_vertices} light vertices (finite energies, at most 2^53 vertices)"
        ));
    }
    Ok(Tally {
        energy,
        nonfinite: progress.nonfinite,
        light_vertices,
    })
}

/// Checks that a checkpoint's `progress` is one a `vcm` run wrote (one
/// line if not). The command line checks it on rank 0 before the ranks'
/// start-up handshake, so that a bad file stops every rank with one
/// error; [`VcmSettings`]' render checks it too.
pub fn check_checkpoint(progress: &Progress) -> Result<(), String> {
    saved_tally(progress).map(|_| ())
}

/// Where a checkpointed run starts: the iterations done (`None`: a fresh
/// start), and on rank 0 (the only rank that adds into them) the film
/// rebuilt with `filter` and the tally; on a cluster every rank is told
/// the iterations (a broadcast). Collective on a cluster. The progress
/// must have passed [`check_checkpoint`].
fn resume_point(
    checkpoint: &Checkpoint,
    filter: &Arc<Filter>,
) -> (Option<u64>, Option<(Film, Tally)>) {
    let local = checkpoint.resume.as_ref().map(|p| {
        let film = p
            .film(filter.clone())
            .expect("the command line checked the checkpoint against the scene");
        let tally = saved_tally(p).expect("checked before the render (check_checkpoint)");
        (p.pass, film, tally)
    });
    let words = local.as_ref().map_or(Vec::new(), |l| vec![l.0]);
    let words = match crate::cluster::current() {
        Some(c) => c.broadcast_u64s(words),
        None => words,
    };
    (words.first().copied(), local.map(|(_, f, t)| (f, t)))
}

/// `radius` is `auto` or > 0.
fn check_radius(v: &Option<f64>) -> Result<(), String> {
    match v {
        Some(r) if !(*r > 0.0) => Err("must be `auto` or > 0".into()),
        _ => Ok(()),
    }
}

/// `alpha` lies in (0, 1].
fn check_alpha(v: &f64) -> Result<(), String> {
    if *v > 0.0 && *v <= 1.0 {
        Ok(())
    } else {
        Err("must lie in (0, 1]".into())
    }
}

/// [`VcmSettings::light_subpaths`]: finite, positive and at most
/// [`MAX_LIGHT_SUBPATHS`] (a bound that keeps an iteration's light
/// subpaths far from overflowing its counts).
fn check_light_subpaths(v: &f64) -> Result<(), String> {
    if *v > 0.0 && *v <= MAX_LIGHT_SUBPATHS {
        Ok(())
    } else {
        Err(format!("must lie in (0, {MAX_LIGHT_SUBPATHS}]"))
    }
}

/// The largest [`VcmSettings::light_subpaths`].
const MAX_LIGHT_SUBPATHS: f64 = 1024.0;

crate::settings! {
    /// Vertex connection and merging settings, as the registry fills them.
    pub struct VcmSettings {
        /// Techniques: vcm (all), bpt (connections only) or ppm (merging at the first non-specular camera vertex).
        pub mode: VcmMode = VcmMode::Vcm;
        /// Merge radius of the first iteration, in scene units; `auto`: radius_factor × the scene's bounding-sphere radius (SmallVCM's rule).
        pub radius: Option<f64> = None, check check_radius;
        /// The fraction of the scene's bounding-sphere radius that `radius = auto` takes (SmallVCM: 0.003).
        pub radius_factor: f64 = 0.003, check crate::settings::check::positive;
        /// Radius reduction: iteration i (from 1) merges with radius·i^((alpha−1)/2); 1 keeps the radius fixed (SmallVCM: 0.75).
        pub alpha: f64 = 0.75, check check_alpha;
        /// MIS heuristic over the techniques: power (β = 2) or balance.
        pub heuristic: MisHeuristic = MisHeuristic::Power;
        /// Light subpaths per iteration per pixel (1: as many as camera subpaths, SmallVCM's N); each is light-traced and stored for merging; camera subpath p connects to light subpaths p, p+N, … (at least 1), or to p mod L (below 1).
        pub light_subpaths: f64 = 1.0, check check_light_subpaths;
        flatten {
            /// Path depth.
            pub depth: DepthParams = DepthParams::default();
        }
    }
}

impl VcmSettings {
    /// The integrator these settings describe for `scene` (the automatic
    /// radius depends on the scene's size).
    pub fn integrator(&self, scene: &Scene) -> Vcm {
        let radius = self
            .radius
            .unwrap_or(self.radius_factor * f64::from(scene.lights.scene_radius()));
        Vcm {
            max_depth: self.depth.limit(),
            rr_depth: self.depth.rr_depth,
            mode: self.mode,
            heuristic: self.heuristic,
            radius: radius as f32,
            alpha: self.alpha as f32,
            light_subpaths: self.light_subpaths,
        }
    }
}

impl IntegratorSettings for VcmSettings {
    const NAME: &'static str = "vcm";
    const DESCRIPTION: &'static str = "Vertex connection and merging (SmallVCM): light subpaths per iteration, connections and merging, MIS-weighted.";

    fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError> {
        if let Some(p) = run.checkpoint.as_ref().and_then(|c| c.resume.as_ref()) {
            check_checkpoint(p).map_err(RenderError::Invalid)?;
        }
        Ok(self.integrator(scene).render(scene, run, stop, observer))
    }
}
