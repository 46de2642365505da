//! Bidirectional path tracing (Veach & Guibas 1995; Veach 1997 ch. 10),
//! following pbrt-v4's `bdpt` integrator: one camera subpath and one light
//! subpath per sample, every pair of prefixes connected, each technique
//! `(s, t)` (`s` light vertices, `t` camera vertices) weighted by multiple
//! importance sampling computed from forward and reverse area densities with
//! Veach's ratio chain.
//!
//! Techniques:
//! - `s = 0`: the camera subpath itself hits an emitter;
//! - `s = 1`: the camera vertex is connected to a freshly sampled light point
//!   (next-event estimation);
//! - `t = 1`: a light vertex is connected to the pinhole and **splatted**
//!   where it lands on the film (light tracing);
//! - otherwise the two subpath ends are joined by a visibility-tested segment.
//!
//! `(1, 1)` is skipped (it duplicates `(0, 2)`, the emitter seen directly).
//!
//! # Depth
//! As in [`super::pt`] (Mitsuba): `max_depth` counts path segments, and a
//! technique `(s, t)` builds a path of `s + t − 1` segments, so only
//! techniques with `s + t − 1 ≤ max_depth` run. Camera subpaths hold at
//! most `max_depth + 1` vertices, light subpaths at most `max_depth`.
//! Russian roulette follows [`super::pt`]: after the BSDF sample at the
//! `k`-th surface vertex of a subpath, with `k ≥ rr_depth`, the walk
//! continues with probability `min(max(β)·η², 0.95)` (η² only on camera
//! subpaths, as in [`super::lt`]). MIS densities ignore the roulette, which
//! keeps the weights a partition of unity and the estimator unbiased.
//!
//! # Order in which random numbers are consumed
//!
//! Each sample switches [`Stream`]s; a source without streams draws all
//! numbers from one sequence in the order below.
//! 1. [`Stream::Camera`]: `next_2d` for the position inside the pixel (when
//!    the integrator picks the raster position), `next_2d` for the lens
//!    point (thin-lens cameras only), then for every camera
//!    surface vertex from which the walk may continue, 4 numbers:
//!    `next_1d` lobe, `next_2d` direction, `next_1d` Russian roulette.
//! 2. [`Stream::Light`]: `next_1d` emitter choice, `next_2d` position,
//!    `next_2d` direction, then 4 numbers per light surface vertex from which
//!    the walk may continue (as above).
//! 3. [`Stream::Connection`]: for every technique `(1, t)` that is within
//!    the depth limit, in order of increasing `t`: `next_1d` emitter choice
//!    and `next_2d` position, drawn even when the camera vertex cannot be
//!    connected. The pinhole connection (`t = 1`) consumes no numbers; with
//!    a thin lens it draws `next_2d` for the lens point, when the light
//!    vertex can be connected.
//!
//! Multiplexed MLT (Hachisuka et al. 2014) calls [`generate_camera_subpath`]
//! and [`generate_light_subpath`] with prescribed lengths and then
//! [`connect`] for one technique; PSSMLT over BDPT calls
//! [`Bdpt::sample_all`], which returns every technique of one sample.

use super::path_vertex::{ConnectionBsdfs, SceneBsdfs, Vertex, shading_correction};
use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings};
use super::{FilmSink, Integrator, SampleDomain, SampleStats, rr_probability};
use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::geometry::Ray;
use crate::observer::Observer;
use crate::sampling::{RandomSource, Stream};
use crate::scene::Scene;
use glam::Vec2;
use std::cell::RefCell;
use std::sync::atomic::AtomicBool;

crate::choice! {
    /// How techniques are weighted against each other.
    pub enum MisHeuristic {
        /// Veach's balance heuristic `p_i / Σ p_j`.
        Balance = "balance",
        /// Veach's power heuristic with β = 2, `p_i² / Σ p_j²` (pbrt's default).
        Power = "power",
    }
}

/// Bidirectional path tracer settings.
#[derive(Clone, Copy, Debug)]
pub struct Bdpt {
    /// Longest path in segments (`u32::MAX` = unbounded).
    pub max_depth: u32,
    /// Depth from which Russian roulette applies.
    pub rr_depth: u32,
    /// MIS heuristic.
    pub heuristic: MisHeuristic,
}

/// Reusable vertex storage for one thread: subpaths are written into these
/// buffers, which only grow, so sampling does not allocate once they have
/// reached the longest subpath seen.
#[derive(Clone, Debug, Default)]
pub struct SubpathBuffers {
    /// Camera subpath, pinhole first.
    pub camera: Vec<Vertex>,
    /// Light subpath, emitter point first.
    pub light: Vec<Vertex>,
}

/// One technique's contribution.
#[derive(Clone, Copy, Debug)]
pub struct Connection {
    /// Contribution, MIS weight included.
    pub l: Rgb,
    /// The MIS weight alone.
    pub weight: f32,
    /// Raster position: the camera subpath's for `t ≥ 2`, where the pinhole
    /// connection lands for `t = 1`.
    pub raster: Vec2,
    /// True for `t = 1`: the contribution is a splat (normalised by the
    /// number of light subpaths per pixel), not part of the pixel's sample.
    pub splat: bool,
    /// Light vertices of the technique.
    pub s: usize,
    /// Camera vertices of the technique (the path has `s + t − 1` segments).
    pub t: usize,
    /// The endpoint the connection sampled: the light vertex for `s = 1`,
    /// the camera vertex for `t = 1` (the fused state space rebuilds the
    /// path from it).
    pub sampled: Option<Vertex>,
}

/// Russian roulette setting for a walk: `Some(rr_depth)` or `None` (off,
/// which prescribed-length subpaths need).
pub type Roulette = Option<u32>;

/// Extends `path` (whose last vertex is the walk's origin) by tracing `ray`
/// and sampling BSDFs, adding at most `max_surface` vertices. Returns the
/// number added.
#[allow(clippy::too_many_arguments)]
pub(crate) fn random_walk(
    scene: &Scene,
    mut ray: Ray,
    source: &mut dyn RandomSource,
    mode: TransportMode,
    mut beta: Rgb,
    pdf_dir: f32,
    max_surface: usize,
    roulette: Roulette,
    path: &mut Vec<Vertex>,
) -> usize {
    let mut pdf_fwd = pdf_dir;
    let mut eta_scale = 1.0f32;
    let mut bounces = 0usize;
    while bounces < max_surface {
        let Some(its) = scene.intersect(&ray) else {
            // A camera subpath that leaves the scene ends on the
            // environment, if there is one (technique s = 0 sees it).
            if mode == TransportMode::Radiance
                && let Some(env) = scene.lights.environment()
            {
                let prev = path.len() - 1;
                let mut v = Vertex::infinite(env, ray.d, beta, 0.0);
                v.pdf_fwd = path[prev].convert_density(pdf_fwd, &v);
                path.push(v);
                bounces += 1;
            }
            break;
        };
        let sp = its.sp;
        let prev = path.len() - 1;
        let mut v = Vertex::surface(scene, sp, -ray.d, beta);
        v.pdf_fwd = path[prev].convert_density(pdf_fwd, &v);
        path.push(v);
        let cur = prev + 1;
        bounces += 1;
        if bounces >= max_surface {
            break;
        }

        let u_lobe = source.next_1d();
        let u_dir = source.next_2d();
        let u_rr = source.next_1d();
        let bsdf = scene.bsdf_at(&sp);
        let frame = scene.shading_frame(&sp);
        let wo = frame.to_local(-ray.d);
        let Some(bs) = bsdf.sample(wo, u_lobe, u_dir, mode) else {
            break;
        };
        if !(bs.pdf > 0.0) || bs.weight.is_black() {
            break;
        }
        let wi_world = frame.to_world(bs.wi);
        let pdf_rev = if bs.is_delta {
            // Specular vertices have no density: MIS skips them (pbrt).
            path[cur].delta = true;
            pdf_fwd = 0.0;
            0.0
        } else {
            pdf_fwd = bs.pdf;
            bsdf.pdf(bs.wi, wo, mode.flip())
        };
        beta *= bs.weight;
        match mode {
            TransportMode::Radiance => eta_scale *= bs.eta * bs.eta,
            TransportMode::Importance => {
                beta *= shading_correction(-ray.d, wi_world, sp.ng, sp.ns);
            }
        }
        let rev = path[cur].convert_density(pdf_rev, &path[prev]);
        path[prev].pdf_rev = rev;
        ray = sp.spawn_ray(wi_world);
        if let Some(rr_depth) = roulette
            && bounces >= rr_depth as usize
        {
            let q = rr_probability(beta, eta_scale);
            if !(u_rr < q) {
                break;
            }
            beta = beta / q;
        }
        if beta.is_black() {
            break;
        }
    }
    bounces
}

/// Generates a camera subpath of at most `max_vertices` vertices (pinhole
/// or lens point included) through raster position `raster` into `path`;
/// returns its length. Consumes 2 numbers for the lens point (thin-lens
/// cameras only), then 4 per surface vertex from which the walk continues
/// (the pixel position is the caller's).
pub fn generate_camera_subpath(
    scene: &Scene,
    raster: Vec2,
    source: &mut dyn RandomSource,
    max_vertices: usize,
    roulette: Roulette,
    path: &mut Vec<Vertex>,
) -> usize {
    path.clear();
    if max_vertices == 0 {
        return 0;
    }
    let camera = &scene.camera;
    let ray = if camera.has_lens() {
        camera.generate_ray_lens(raster, source.next_2d())
    } else {
        camera.generate_ray(raster)
    };
    path.push(Vertex::camera(ray.o, raster, Rgb::WHITE));
    let (_, pdf_dir) = camera.pdf_we(ray.o, ray.d);
    if !(pdf_dir > 0.0) {
        return 1;
    }
    random_walk(
        scene,
        ray,
        source,
        TransportMode::Radiance,
        Rgb::WHITE,
        pdf_dir,
        max_vertices - 1,
        roulette,
        path,
    );
    path.len()
}

/// Generates a light subpath of at most `max_vertices` vertices (emitter
/// point included) into `path`; returns its length (0 when the scene has no
/// emitter). Always consumes the 5 emission numbers first.
pub fn generate_light_subpath(
    scene: &Scene,
    source: &mut dyn RandomSource,
    max_vertices: usize,
    roulette: Roulette,
    path: &mut Vec<Vertex>,
) -> usize {
    path.clear();
    if max_vertices == 0 {
        return 0;
    }
    let u_sel = source.next_1d();
    let u_pos = source.next_2d();
    let u_dir = source.next_2d();
    let Some((light, _)) = scene.lights.select(u_sel) else {
        return 0;
    };
    let Some(es) = scene
        .lights
        .sample_emission(&scene.geometry, u_sel, u_pos, u_dir)
    else {
        return 0;
    };
    if !(es.pdf_pos > 0.0 && es.pdf_dir > 0.0) {
        return 0;
    }
    // The density `random_walk` turns into the first hit's area density:
    // solid angle from a point on an emitter, the origin disk's area
    // density from an emitter at infinity (see `Vertex::convert_density`).
    let first_pdf = if es.at_infinity {
        let mut v = Vertex::infinite(light, -es.dir, es.le / es.pdf_pos, 0.0);
        v.pdf_fwd = v.pdf_light_origin(scene);
        path.push(v);
        scene.lights.infinite_disk_pdf()
    } else {
        path.push(Vertex::light(
            scene,
            light,
            es.p,
            es.le / es.pdf_pos,
            es.pdf_pos,
        ));
        es.pdf_dir
    };
    let ray = if es.is_delta || es.at_infinity {
        Ray::new(es.p.p, es.dir)
    } else {
        es.p.spawn_ray(es.dir)
    };
    random_walk(
        scene,
        ray,
        source,
        TransportMode::Importance,
        es.weight,
        first_pdf,
        max_vertices - 1,
        roulette,
        path,
    );
    path.len()
}

/// `1/d² · |cos| · |cos|` between two vertices (shading normals; no cosine
/// at a vertex that is not on a surface), times their mutual visibility.
pub fn geometry_term(scene: &Scene, a: &Vertex, b: &Vertex) -> f32 {
    let g = unoccluded_geometry_term(a, b);
    if g > 0.0 && scene.geometry.visible(&a.sp, &b.sp) {
        g
    } else {
        0.0
    }
}

/// [`geometry_term`] without the visibility test.
#[inline(always)]
fn unoccluded_geometry_term(a: &Vertex, b: &Vertex) -> f32 {
    let d = b.p() - a.p();
    let d2 = d.length_squared();
    if !(d2 > 0.0) {
        return 0.0;
    }
    let w = d / d2.sqrt();
    let mut g = 1.0 / d2;
    if a.on_surface() {
        g *= a.sp.ns.dot(w).abs();
    }
    if b.on_surface() {
        g *= b.sp.ns.dot(w).abs();
    }
    g
}

/// Evaluates technique `(s, t)` on the first `s` vertices of `light` and the
/// first `t` vertices of `camera`: the unweighted contribution times its MIS
/// weight. Requires `t ≥ 1`, `s ≤ light.len()`, `t ≤ camera.len()` and
/// `(s, t) ≠ (1, 1)`; returns `None` otherwise or when the contribution is
/// zero. For `s = 1` it draws 3 numbers (`next_1d` emitter, `next_2d`
/// position) from `source` before anything else, whatever the outcome;
/// for `t = 1` with a thin lens, 2 (the lens point) once the light vertex
/// is found connectible.
pub fn connect(
    scene: &Scene,
    camera: &[Vertex],
    light: &[Vertex],
    s: usize,
    t: usize,
    source: &mut dyn RandomSource,
    heuristic: MisHeuristic,
) -> Option<Connection> {
    connect_among(scene, camera, light, s, t, source, heuristic, 1)
}

/// [`connect`] with the MIS weight renormalised over the techniques with at
/// least `min_camera` camera vertices ([`mis_weight_among`]; `None` when
/// `t < min_camera`): stratified MCMC's BDPT shifts use `min_camera = 2`
/// and so compute the one weight they need, not the full one as well.
#[allow(clippy::too_many_arguments)]
pub fn connect_among(
    scene: &Scene,
    camera: &[Vertex],
    light: &[Vertex],
    s: usize,
    t: usize,
    source: &mut dyn RandomSource,
    heuristic: MisHeuristic,
    min_camera: usize,
) -> Option<Connection> {
    let mut out = [None];
    connect_in_among(
        scene,
        &SceneBsdfs,
        camera,
        light,
        s,
        t,
        source,
        heuristic,
        min_camera,
        &mut out,
    );
    out[0]
}

/// [`connect`] under every level of `bsdfs` at once: `out[k]` receives the
/// technique's contribution with the BSDFs of level `k` at the two
/// connected vertices (contribution and MIS weight), or `None`. The
/// subpaths, the sampled light or camera point and the visibility test
/// (done once, when some level carries light) are shared by all levels.
/// With a thin lens the lens numbers are drawn when the light vertex is
/// connectible under some level. `out.len()` must be `bsdfs.levels()`.
#[allow(clippy::too_many_arguments)]
pub fn connect_in<B: ConnectionBsdfs>(
    scene: &Scene,
    bsdfs: &B,
    camera: &[Vertex],
    light: &[Vertex],
    s: usize,
    t: usize,
    source: &mut dyn RandomSource,
    heuristic: MisHeuristic,
    out: &mut [Option<Connection>],
) {
    connect_in_among(scene, bsdfs, camera, light, s, t, source, heuristic, 1, out);
}

/// [`connect_in`] with the MIS weight renormalised over the techniques with
/// at least `min_camera` camera vertices (nothing when `t < min_camera`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn connect_in_among<B: ConnectionBsdfs>(
    scene: &Scene,
    bsdfs: &B,
    camera: &[Vertex],
    light: &[Vertex],
    s: usize,
    t: usize,
    source: &mut dyn RandomSource,
    heuristic: MisHeuristic,
    min_camera: usize,
    out: &mut [Option<Connection>],
) {
    out.fill(None);
    if t == 0 || t < min_camera || t > camera.len() || s > light.len() || (s == 1 && t == 1) {
        return;
    }
    // The levels differ only in the BSDFs at the two connected vertices
    // `x^L_s` (s ≥ 2) and `x^C_t` (t ≥ 2); with s = 1 or t = 1 that end is
    // a sampled endpoint, and with s = 0 nothing is connected (the emitted
    // radiance and the emitter's densities in the MIS weight are the
    // scene's). When no connected vertex changes with the level (e.g.
    // both diffuse), every level's value and MIS weight are level 0's
    // bits: evaluate one level and copy it.
    let same = s == 0
        || ((s < 2 || light[s - 1].is_same_at_every_level(scene, bsdfs))
            && (t < 2 || camera[t - 1].is_same_at_every_level(scene, bsdfs)));
    let all = out.len();
    let levels = if same { 1 } else { all };
    let mut raster = camera[0].raster;
    let mut sampled: Option<Vertex> = None;
    // Per level: the unweighted contribution (black where it carries none).
    let mut l = [Rgb::BLACK; MAX_CONNECTION_LEVELS];
    let l = &mut l[..levels];
    if s == 0 {
        let pt = &camera[t - 1];
        if t < 2 || !pt.is_light() {
            return;
        }
        l.fill(pt.le(scene, &camera[t - 2]) * pt.beta);
    } else if t == 1 {
        let qs = &light[s - 1];
        let connectible: [bool; MAX_CONNECTION_LEVELS] =
            std::array::from_fn(|k| k < levels && qs.is_connectible_in(scene, bsdfs, k));
        if !connectible.contains(&true) {
            return;
        }
        let cs = if scene.camera.has_lens() {
            scene.camera.sample_wi_lens(qs.p(), source.next_2d())
        } else {
            scene.camera.sample_wi(qs.p())
        };
        let Some(cs) = cs else {
            return;
        };
        raster = cs.raster;
        let cam = Vertex::camera(cs.origin, cs.raster, Rgb::splat(cs.we / cs.pdf));
        for (k, lk) in l.iter_mut().enumerate() {
            if !connectible[k] {
                continue;
            }
            *lk = qs.beta * qs.f_in(scene, bsdfs, k, &cam, TransportMode::Importance) * cam.beta;
            if qs.on_surface() {
                *lk *= cs.wi.dot(qs.sp.ns).abs();
            }
        }
        if l.iter().all(|lk| lk.is_black())
            || !scene
                .geometry
                .segment_clear(qs.sp.spawn_origin(cs.origin), cs.origin)
        {
            return;
        }
        sampled = Some(cam);
    } else if s == 1 {
        let u_sel = source.next_1d();
        let u_pos = source.next_2d();
        let pt = &camera[t - 1];
        let connectible: [bool; MAX_CONNECTION_LEVELS] =
            std::array::from_fn(|k| k < levels && pt.is_connectible_in(scene, bsdfs, k));
        if !connectible.contains(&true) {
            return;
        }
        let Some((index, _)) = scene.lights.select(u_sel) else {
            return;
        };
        let Some(ds) = scene
            .lights
            .sample_direct(&scene.geometry, pt.p(), u_sel, u_pos)
        else {
            return;
        };
        let mut lv = if ds.at_infinity {
            Vertex::infinite(index, ds.wi, ds.le / ds.pdf, 0.0)
        } else {
            Vertex::light(scene, index, ds.p, ds.le / ds.pdf, 0.0)
        };
        lv.pdf_fwd = lv.pdf_light_origin(scene);
        for (k, lk) in l.iter_mut().enumerate() {
            if !connectible[k] {
                continue;
            }
            *lk = pt.beta * pt.f_in(scene, bsdfs, k, &lv, TransportMode::Radiance) * lv.beta;
            if pt.on_surface() {
                *lk *= ds.wi.dot(pt.sp.ns).abs();
            }
        }
        if l.iter().all(|lk| lk.is_black()) || !scene.light_visible(&pt.sp, &ds) {
            return;
        }
        sampled = Some(lv);
    } else {
        let qs = &light[s - 1];
        let pt = &camera[t - 1];
        for (k, lk) in l.iter_mut().enumerate() {
            if !qs.is_connectible_in(scene, bsdfs, k) || !pt.is_connectible_in(scene, bsdfs, k) {
                continue;
            }
            *lk = qs.beta
                * qs.f_in(scene, bsdfs, k, pt, TransportMode::Importance)
                * pt.f_in(scene, bsdfs, k, qs, TransportMode::Radiance)
                * pt.beta;
        }
        if l.iter().all(|lk| lk.is_black()) {
            return;
        }
        let g = unoccluded_geometry_term(qs, pt);
        let g = if g > 0.0 && scene.geometry.visible(&qs.sp, &pt.sp) {
            g
        } else {
            0.0
        };
        for lk in l.iter_mut() {
            *lk *= g;
        }
    }
    for (k, (o, &lk)) in out[..levels].iter_mut().zip(l.iter()).enumerate() {
        if lk.is_black() {
            continue;
        }
        let weight = mis_weight_among(
            scene,
            bsdfs,
            k,
            camera,
            light,
            s,
            t,
            sampled.as_ref(),
            heuristic,
            min_camera,
        );
        *o = Some(Connection {
            l: lk * weight,
            weight,
            raster,
            splat: t == 1,
            s,
            t,
            sampled,
        });
    }
    if levels < all {
        let first = out[0];
        out[1..].fill(first);
    }
}

/// Most levels [`connect_in`] evaluates at once.
pub const MAX_CONNECTION_LEVELS: usize = 16;

/// MIS weight of technique `(s, t)` for the path made of `light[..s]` and
/// `camera[..t]` (pbrt-v4's `MISWeight`). `sampled` replaces the light
/// endpoint when `s = 1`, the camera endpoint when `t = 1`. The ratio
/// `r_i = p_i / p_{s,t}` of every other technique's density to this one's is
/// built vertex by vertex from `pdf_rev / pdf_fwd`; the densities at the two
/// connected vertices and their predecessors are recomputed for this
/// connection. Zero densities (specular vertices) are replaced by one in the
/// ratios, and techniques that would connect to a specular vertex or start
/// from a point light's position by a camera hit are left out.
pub fn mis_weight(
    scene: &Scene,
    camera: &[Vertex],
    light: &[Vertex],
    s: usize,
    t: usize,
    sampled: Option<&Vertex>,
    heuristic: MisHeuristic,
) -> f32 {
    mis_weight_in(
        scene,
        &SceneBsdfs,
        0,
        camera,
        light,
        s,
        t,
        sampled,
        heuristic,
    )
}

/// [`mis_weight`] with the BSDFs of level `level` of `bsdfs` at the two
/// connected vertices: every technique's density through them is the
/// roughened one (spec seed000 §5.2.1, tempered path space), the densities
/// stored along the subpaths are the scene's.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn mis_weight_in<B: ConnectionBsdfs>(
    scene: &Scene,
    bsdfs: &B,
    level: usize,
    camera: &[Vertex],
    light: &[Vertex],
    s: usize,
    t: usize,
    sampled: Option<&Vertex>,
    heuristic: MisHeuristic,
) -> f32 {
    mis_weight_among(
        scene, bsdfs, level, camera, light, s, t, sampled, heuristic, 1,
    )
}

/// [`mis_weight_in`] renormalised over the techniques with at least
/// `min_camera` camera vertices (`1`: all of them; `2`: no light tracing,
/// as stratified MCMC's BDPT shift needs, spec seed003 §11.1). The
/// technique `(s, t)` itself must have `t ≥ min_camera`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn mis_weight_among<B: ConnectionBsdfs>(
    scene: &Scene,
    bsdfs: &B,
    level: usize,
    camera: &[Vertex],
    light: &[Vertex],
    s: usize,
    t: usize,
    sampled: Option<&Vertex>,
    heuristic: MisHeuristic,
    min_camera: usize,
) -> f32 {
    mis_weight_selected(
        scene,
        bsdfs,
        level,
        camera,
        light,
        s,
        t,
        sampled,
        heuristic,
        min_camera,
        &[],
    )
}

/// [`mis_weight_among`] for one-sample MIS with technique selection
/// (spec seed003 §1, §11.3): technique `(s', t')` of the path's length is
/// picked with probability `select[s']`, so its density is
/// `select[s'] · p_{s',t'}` in every ratio (`r_i · select[s_i]/select[s]`).
/// `select` is indexed by the number of light vertices and covers every
/// technique of the path's length (`s + t` entries); a zero entry leaves
/// the technique out. An empty `select` means 1 for every technique (the
/// same bits as [`mis_weight_among`] always had).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn mis_weight_selected<B: ConnectionBsdfs>(
    scene: &Scene,
    bsdfs: &B,
    level: usize,
    camera: &[Vertex],
    light: &[Vertex],
    s: usize,
    t: usize,
    sampled: Option<&Vertex>,
    heuristic: MisHeuristic,
    min_camera: usize,
    select: &[f32],
) -> f32 {
    // The selection ratio of technique `s'` to this one (1 without selection).
    let ratio = |s_other: usize| select[s_other] / select[s];
    if s + t == 2 {
        return 1.0;
    }
    let remap0 = |f: f32| if f != 0.0 { f } else { 1.0 };
    let power = |r: f32| match heuristic {
        MisHeuristic::Balance => r,
        MisHeuristic::Power => r * r,
    };
    let endpoint = |path: &[Vertex], n: usize, use_sampled: bool| -> Vertex {
        match (use_sampled, sampled) {
            (true, Some(v)) => *v,
            _ => path[n - 1],
        }
    };
    let qs = (s > 0).then(|| endpoint(light, s, s == 1));
    let pt = endpoint(camera, t, t == 1);
    let qs_minus = (s > 1).then(|| &light[s - 2]);
    let pt_minus = (t > 1).then(|| &camera[t - 2]);

    // Densities at the connection, as the opposite subpath would produce them.
    let pt_rev = match &qs {
        Some(qs) => qs.pdf_in(
            scene,
            bsdfs,
            level,
            qs_minus,
            &pt,
            TransportMode::Importance,
        ),
        None => pt.pdf_light_origin(scene),
    };
    let pt_minus_rev = pt_minus.map(|pm| match &qs {
        Some(qs) => pt.pdf_in(scene, bsdfs, level, Some(qs), pm, TransportMode::Importance),
        None => pt.pdf_light(scene, pm),
    });
    let qs_rev = qs
        .as_ref()
        .map(|q| pt.pdf_in(scene, bsdfs, level, pt_minus, q, TransportMode::Radiance));
    let qs_minus_rev = match (&qs, qs_minus) {
        (Some(q), Some(qm)) => {
            Some(q.pdf_in(scene, bsdfs, level, Some(&pt), qm, TransportMode::Radiance))
        }
        _ => None,
    };

    let mut sum = 0.0f32;
    // Techniques with fewer camera vertices.
    let mut ri = 1.0f32;
    for i in (1..t).rev() {
        let (rev, fwd, delta) = if i == t - 1 {
            (
                pt_rev,
                after_specular(&camera[i - 1], &pt, pt.pdf_fwd),
                false,
            )
        } else if i + 2 == t {
            (
                pt_minus_rev.unwrap_or(camera[i].pdf_rev),
                after_specular(&camera[i - 1], &camera[i], camera[i].pdf_fwd),
                camera[i].delta,
            )
        } else {
            (
                after_specular(&camera[i + 1], &camera[i], camera[i].pdf_rev),
                after_specular(&camera[i - 1], &camera[i], camera[i].pdf_fwd),
                camera[i].delta,
            )
        };
        ri *= remap0(rev) / remap0(fwd);
        if i >= min_camera && !delta && !camera[i - 1].delta {
            sum += power(if select.is_empty() {
                ri
            } else {
                ri * ratio(s + t - i)
            });
        }
    }
    // Techniques with fewer light vertices.
    let mut ri = 1.0f32;
    for i in (0..s).rev() {
        let (v, rev) = if i + 1 == s {
            let q = qs.expect("s > 0");
            (q, qs_rev.unwrap_or(q.pdf_rev))
        } else if i + 2 == s {
            (light[i], qs_minus_rev.unwrap_or(light[i].pdf_rev))
        } else {
            (
                light[i],
                after_specular(&light[i + 1], &light[i], light[i].pdf_rev),
            )
        };
        let fwd = if i > 0 {
            after_specular(&light[i - 1], &v, v.pdf_fwd)
        } else {
            v.pdf_fwd
        };
        ri *= remap0(rev) / remap0(fwd);
        let delta = i + 1 != s && v.delta;
        let delta_prev = if i > 0 {
            light[i - 1].delta
        } else {
            v.is_delta_light(scene)
        };
        if !delta && !delta_prev {
            sum += power(if select.is_empty() { ri } else { ri * ratio(i) });
        }
    }
    let w = 1.0 / (1.0 + sum);
    if w.is_finite() { w } else { 0.0 }
}

/// The area density at `to` of sampling it from `from`: `stored` unless
/// `from` is specular, whose scattering has no density (the walk stores
/// 0). There the Dirac lobe counts as solid-angle density 1 in either
/// direction, converted to area at `to` like any other density: the
/// Dirac factors of two techniques cancel, the geometry of the edges does
/// not (Veach's thesis §10.3.5; SmallVCM's recursion does the same).
/// Counting the *area* density as 1 instead (pbrt-v4's `remap0` of the
/// stored 0) makes the weights depend on the scene's scale; on the glass
/// ball's caustic seen on SmallVCM's floor it made BDPT's variance there
/// 9× SmallVCM's (docs/vcm.md).
#[inline(always)]
pub fn after_specular(from: &Vertex, to: &Vertex, stored: f32) -> f32 {
    if from.delta {
        from.convert_density(1.0, to)
    } else {
        stored
    }
}

impl Bdpt {
    /// Camera subpath vertex limit (pinhole included).
    pub fn max_camera_vertices(&self) -> usize {
        (self.max_depth as usize).saturating_add(1)
    }

    /// Light subpath vertex limit (emitter point included).
    pub fn max_light_vertices(&self) -> usize {
        self.max_depth as usize
    }

    /// All techniques of one sample through `raster`, in the documented
    /// order of streams: camera subpath, light subpath, connections. Each
    /// nonzero technique is passed to `emit` (finite or not: the caller
    /// counts and drops non-finite ones). Used by [`Integrator::sample`] and
    /// by PSSMLT over BDPT.
    pub fn sample_all(
        &self,
        scene: &Scene,
        raster: Vec2,
        source: &mut dyn RandomSource,
        buffers: &mut SubpathBuffers,
        mut emit: impl FnMut(&Connection),
    ) {
        self.sample_all_in(scene, &SceneBsdfs, raster, source, buffers, |c| {
            if let Some(c) = &c[0] {
                emit(c);
            }
        });
    }

    /// [`Bdpt::sample_all`] under every level of `bsdfs` at once
    /// ([`connect_in`]): subpaths traced once, each technique passed to
    /// `emit` as one entry per level (skipped when no level carries light).
    pub fn sample_all_in<B: ConnectionBsdfs>(
        &self,
        scene: &Scene,
        bsdfs: &B,
        raster: Vec2,
        source: &mut dyn RandomSource,
        buffers: &mut SubpathBuffers,
        mut emit: impl FnMut(&[Option<Connection>]),
    ) {
        let mut out = [None; MAX_CONNECTION_LEVELS];
        let out = &mut out[..bsdfs.levels()];
        let rr = Some(self.rr_depth);
        source.set_stream(Stream::Camera);
        let nc = generate_camera_subpath(
            scene,
            raster,
            source,
            self.max_camera_vertices(),
            rr,
            &mut buffers.camera,
        );
        source.set_stream(Stream::Light);
        let nl = generate_light_subpath(
            scene,
            source,
            self.max_light_vertices(),
            rr,
            &mut buffers.light,
        );
        source.set_stream(Stream::Connection);
        let max_depth = self.max_depth as usize;
        for t in 1..=nc {
            for s in 0..=nl {
                if (s == 1 && t == 1) || s + t < 2 || s + t - 1 > max_depth {
                    continue;
                }
                connect_in(
                    scene,
                    bsdfs,
                    &buffers.camera,
                    &buffers.light,
                    s,
                    t,
                    source,
                    self.heuristic,
                    out,
                );
                if out.iter().any(Option::is_some) {
                    emit(out);
                }
            }
        }
    }
}

thread_local! {
    /// Per-thread subpath storage for [`Integrator::sample`].
    static BUFFERS: RefCell<SubpathBuffers> = RefCell::new(SubpathBuffers::default());
}

impl Integrator for Bdpt {
    fn name(&self) -> &'static str {
        "bdpt"
    }

    fn domain(&self) -> SampleDomain {
        SampleDomain::PixelsWithSplats
    }

    fn sample(
        &self,
        scene: &Scene,
        pixel: Option<(u32, u32)>,
        source: &mut dyn RandomSource,
        film: &mut dyn FilmSink,
        stats: &mut SampleStats,
    ) {
        let Some((px, py)) = pixel else {
            return;
        };
        source.set_stream(Stream::Camera);
        let u = source.next_2d();
        let raster = Vec2::new(px as f32 + u.0, py as f32 + u.1);
        let mut l = Rgb::BLACK;
        BUFFERS.with_borrow_mut(|buffers| {
            self.sample_all(scene, raster, source, buffers, |c| {
                if !c.l.is_finite() {
                    stats.nonfinite += 1;
                } else if c.splat {
                    film.splat(c.raster, c.l);
                } else {
                    l += c.l;
                }
            });
        });
        // Every camera sample counts towards the pixel's filter weight, black or not.
        film.add_sample(raster, l);
    }
}

crate::settings! {
    /// Bidirectional path tracer settings, as the registry fills them.
    pub struct BdptSettings {
        /// MIS heuristic over the techniques: power (β = 2) or balance.
        pub heuristic: MisHeuristic = MisHeuristic::Power;
        flatten {
            /// Path depth.
            pub depth: DepthParams = DepthParams::default();
        }
    }
}

impl BdptSettings {
    /// The per-sample integrator these settings describe.
    pub fn integrator(&self) -> Bdpt {
        Bdpt {
            max_depth: self.depth.limit(),
            rr_depth: self.depth.rr_depth,
            heuristic: self.heuristic,
        }
    }
}

impl IntegratorSettings for BdptSettings {
    const NAME: &'static str = "bdpt";
    const DESCRIPTION: &'static str = "Bidirectional path tracing: every technique of one camera and one light subpath, MIS-weighted.";

    fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError> {
        Ok(crate::render::run_per_pixel(
            scene,
            &self.integrator(),
            run,
            stop,
            observer,
        ))
    }
}
