//! The two maps between multiplexed primary sample space and path space
//! for one MMLT depth: [`trace`] (`P_t^{-1}`, the ordinary MMLT sampler,
//! keeping the path it built) and [`invert`] (`P_t`, the inverse path
//! sampler of spec seed001 §2.3, vertex by vertex with the routines of
//! [`crate::inverse`]), and the round trip of §5.1 ([`round_trip`]).
//!
//! # Layout of the numbers (MMLT's, [`crate::pss::MmltDepth`])
//!
//! Three interleaved streams, number `i` of stream `k` at coordinate
//! `3i + k`. For technique `(s, t)` of a path `x_0 … x_k` (`k = s + t − 1`;
//! light subpath `x_0 … x_{s−1}`, camera subpath `x_k … x_s`):
//!
//! | stream | numbers | inverse |
//! |---|---|---|
//! | connection 0 | technique bin `⌊u·n⌋` | uniform in the bin |
//! | camera 0–1 | raster position (`t ≥ 2`) | raster of the first camera ray |
//! | camera 2–3 | lens point (thin lens, `t ≥ 2`) | [`crate::camera::Camera::invert`] |
//! | camera, 4 per surface vertex `x_{k−j}`, `1 ≤ j ≤ t − 2` | lobe, direction, roulette | `BsdfAt::invert_in` (importance mode on the light side): lobe uniform in its interval, direction numbers (fresh for Dirac lobes); roulette fresh (off) |
//! | light 0 | emitter choice (`s ≥ 2`) | uniform in the emitter's interval |
//! | light 1–2 | position (`s ≥ 2`) | area inverse (fresh for point lights); at infinity the disk point below `x_1` ([`crate::light::Lights::infinite_origin_to_square`]) |
//! | light 3–4 | direction (`s ≥ 2`) | cosine / sphere / spot inverse; at infinity the environment's ([`crate::inverse::infinite_direction_to_square`]; fresh for a directional light) |
//! | light, 4 per surface vertex `x_j`, `1 ≤ j ≤ s − 2` | lobe, direction, roulette | as on the camera side |
//! | connection 1–3 | next-event emitter and point (`s = 1`) | as light 0–2, from `x_1`; at infinity the environment's direction (fresh for a directional light) |
//! | connection 1–2 | lens point (`t = 1`, thin lens) | camera inverse |
//!
//! A camera walk that escapes to the environment (`s = 0`, `x_0` at
//! infinity) needs nothing more: its last direction is the scattering at
//! `x_1` towards `ω`, inverted as any other. Every other coordinate is a
//! fresh uniform (the camera stream when
//! `t = 1`, the light stream when `s ≤ 1`, and the unread tail), which is
//! the reversible-jump fill of spec seed001 §4.

use crate::bsdf::TransportMode;
use crate::fused_space::FusedState;
use crate::integrators::bdpt::SubpathBuffers;
use crate::integrators::path_vertex::{Vertex, VertexKind};
use crate::inverse::{
    area_point_to_square, direct_point_to_square, emission_direction_to_square, in_interval,
    infinite_direction_to_square, light_selection, raster_to_square,
};
use crate::light::Light;
use crate::path_space::Path;
use crate::pss::{MmltDepth, PathSample, PssSource};
use crate::sampling::Stream;
use crate::scene::Scene;
use glam::Vec3;
use mcmc_core::rng::{ChainRng, child_rng, uniform};
use mcmc_core::space::TorusPoint;
use std::cell::RefCell;

/// Why a path has no multiplexed primary sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InverseFailure {
    /// The path's length or technique does not belong to this depth.
    Technique,
    /// The sampled direction is not one the BSDF along the path samples
    /// (`BsdfAt::invert_in` returns `None`).
    Bsdf,
    /// The emitter's choice, point or direction cannot be inverted (a
    /// sphere light's cone sampling for `s = 1`, a point off the emitter,
    /// an environment direction of zero density, `x_1` off the disk of an
    /// emitter at infinity).
    Emitter,
    /// The camera ray misses the image.
    Camera,
}

thread_local! {
    /// Subpath storage for [`trace`].
    static BUFFERS: RefCell<SubpathBuffers> = RefCell::new(SubpathBuffers::default());
}

/// `P_t^{-1}`: traces `state.point` with MMLT's sampler of `depth`, and
/// caches in `state` the path it builds (light to camera, the connection's
/// sampled endpoint included; its vertices only, not evaluated: call
/// [`Path::evaluate`] for its densities and contribution), its technique
/// and MMLT's splat and
/// `ln π = ln lum(n · w · C)`. A sample that carries nothing leaves an empty
/// path and `ln π = −∞`; a NaN or infinite one `ln π = NaN`.
pub fn trace<'s>(scene: &'s Scene, depth: &MmltDepth, state: &mut FusedState<'s>) {
    let mut source = PssSource::new(&state.point, Stream::COUNT);
    state.depth = Some(depth.depth);
    state.point_stale = false;
    state.technique = None;
    state.path.vertices.clear();
    state.path.contribution = crate::color::Rgb::BLACK;
    state.sample.splats.clear();
    state.sample.depth = depth.depth as u32;
    state.log_density = f64::NEG_INFINITY;
    let traced = BUFFERS.with_borrow_mut(|b| {
        let (c, splat) = depth.sample_technique(scene, &mut source, b)?;
        let (s, t) = (c.s, c.t);
        // The connection's sampled endpoint replaces the one-vertex
        // subpath's vertex; the vertices go straight into the path's
        // storage (no per-trace allocation).
        let first_light = if s == 1 { Some(c.sampled?) } else { None };
        let last_camera = if t == 1 { Some(c.sampled?) } else { None };
        let path = &mut state.path;
        path.vertices.extend_from_slice(&b.light[..s]);
        if let Some(v) = first_light {
            path.vertices[0] = v;
        }
        path.vertices.extend(b.camera[..t].iter().rev().copied());
        if let Some(v) = last_camera {
            *path.vertices.last_mut().expect("t = 1 vertex") = v;
        }
        // Only the vertices: a path-space move evaluates the path it
        // starts from ([`Path::evaluate`]); primary-sample moves and
        // round trips need only MMLT's splat.
        path.normalize_ends();
        Some((s, t, splat))
    });
    let Some((s, t, splat)) = traced else {
        return;
    };
    state.technique = Some((s, t));
    state.log_density = log_luminance(splat.l);
    state.sample.splats.push(splat);
}

/// MMLT's `ln π` of a splat: `ln lum(l)`, `−∞` for nothing, NaN for a
/// NaN or infinite one.
pub(crate) fn log_luminance(l: crate::color::Rgb) -> f64 {
    let i = f64::from(l.luminance());
    if !l.is_finite() || !i.is_finite() {
        f64::NAN
    } else if i > 0.0 {
        i.ln()
    } else {
        f64::NEG_INFINITY
    }
}

/// One stream's numbers while inverting: `None` is a fresh uniform.
#[derive(Default)]
struct Numbers {
    streams: [Vec<Option<f64>>; Stream::COUNT],
    /// The interleaved coordinates being assembled (kept for its allocation).
    values: Vec<f64>,
}

thread_local! {
    /// The inverse's scratch numbers (an inversion per accepted path-space
    /// move allocated them anew each time).
    static NUMBERS: RefCell<Numbers> = RefCell::new(Numbers::default());
}

impl Numbers {
    fn clear(&mut self) {
        for v in &mut self.streams {
            v.clear();
        }
    }

    fn set(&mut self, stream: Stream, i: usize, u: f32) {
        let v = &mut self.streams[stream.index()];
        if v.len() <= i {
            v.resize(i + 1, None);
        }
        v[i] = Some(f64::from(u));
    }

    fn set2(&mut self, stream: Stream, i: usize, u: (f32, f32)) {
        self.set(stream, i, u.0);
        self.set(stream, i + 1, u.1);
    }

    /// Writes the interleaved coordinates into `point`, fresh uniforms in
    /// the gaps; later coordinates are uniform on first read.
    fn write_point(&mut self, rng: &mut ChainRng, point: &mut TorusPoint) {
        let m = Stream::COUNT;
        let len = self.streams.iter().map(Vec::len).max().unwrap_or(0);
        self.values.clear();
        for i in 0..len {
            for k in 0..m {
                self.values.push(match self.streams[k].get(i) {
                    Some(Some(u)) => *u,
                    _ => uniform(rng),
                });
            }
        }
        point.set_values(&self.values, child_rng(rng));
    }
}

/// Unit direction from `a` to `b`.
fn dir(a: &Vertex, b: &Vertex) -> Option<Vec3> {
    a.direction_to(b)
}

/// The scattering numbers at surface vertex `v` that send a walk arriving
/// from `from` on to `to`: (lobe, direction) written at number `base` of
/// `stream`.
fn invert_scattering(
    scene: &Scene,
    v: &Vertex,
    from: &Vertex,
    to: &Vertex,
    (stream, base): (Stream, usize),
    numbers: &mut Numbers,
    rng: &mut ChainRng,
) -> Result<(), InverseFailure> {
    let (Some(wo), Some(wi)) = (dir(v, from), dir(v, to)) else {
        return Err(InverseFailure::Bsdf);
    };
    let frame = scene.shading_frame(&v.sp);
    // Light subpaths scatter in importance mode (normal and bump maps
    // sample them differently).
    let mode = match stream {
        Stream::Light => TransportMode::Importance,
        _ => TransportMode::Radiance,
    };
    let inv = scene
        .bsdf_at(&v.sp)
        .invert_in(
            frame.to_local(wo),
            frame.to_local(wi),
            uniform(rng) as f32,
            mode,
        )
        .ok_or(InverseFailure::Bsdf)?;
    if inv.u_lobe != (0.0, 1.0) {
        let u =
            in_interval(inv.u_lobe.0, inv.u_lobe.1, uniform(rng)).ok_or(InverseFailure::Bsdf)?;
        numbers.set(stream, base, u);
    }
    if inv.u_used {
        numbers.set2(stream, base + 1, inv.u);
    }
    Ok(())
}

/// `P_t`: writes into `point` the multiplexed primary sample of `path`
/// under technique `s` (light vertices) of `depth`, with fresh uniforms
/// from `rng` where the sampler's map is many-to-one or ignores its
/// numbers. The technique is not changed (spec seed001 §2.1). On failure
/// `point` is left as it was.
pub fn invert(
    scene: &Scene,
    depth: &MmltDepth,
    path: &Path<'_>,
    s: usize,
    rng: &mut ChainRng,
    point: &mut TorusPoint,
) -> Result<(), InverseFailure> {
    NUMBERS.with_borrow_mut(|numbers| {
        numbers.clear();
        invert_numbers(scene, depth, path, s, rng, numbers)?;
        numbers.write_point(rng, point);
        Ok(())
    })
}

/// The numbers of [`invert`], stream by stream.
fn invert_numbers(
    scene: &Scene,
    depth: &MmltDepth,
    path: &Path<'_>,
    s: usize,
    rng: &mut ChainRng,
    numbers: &mut Numbers,
) -> Result<(), InverseFailure> {
    let vs = &path.vertices;
    let k = path.segments();
    if vs.len() < 2 || k != depth.depth || s > k {
        return Err(InverseFailure::Technique);
    }
    let t = k + 1 - s;
    let n = depth.technique_count();
    let bin = depth
        .technique_iter()
        .position(|st| st == (s, t))
        .ok_or(InverseFailure::Technique)?;
    let u_bin = in_interval(
        bin as f32 / n as f32,
        (bin + 1) as f32 / n as f32,
        uniform(rng),
    )
    .filter(|u| ((u * n as f32) as usize).min(n - 1) == bin)
    .ok_or(InverseFailure::Technique)?;
    numbers.set(Stream::Connection, 0, u_bin);
    let camera = &scene.camera;
    let lens = usize::from(camera.has_lens()) * 2;

    // Camera side: x_k (lens), then x_{k−1} … x_s.
    let xk = &vs[k];
    let first = dir(xk, &vs[k - 1]).ok_or(InverseFailure::Camera)?;
    let (raster, u_lens) = camera.invert(xk.p(), first).ok_or(InverseFailure::Camera)?;
    if t >= 2 {
        numbers.set2(Stream::Camera, 0, raster_to_square(scene, raster));
        if lens > 0 {
            numbers.set2(Stream::Camera, 2, u_lens);
        }
        for j in 1..t.saturating_sub(1) {
            let v = k - j;
            let base = 2 + lens + 4 * (j - 1);
            invert_scattering(
                scene,
                &vs[v],
                &vs[v + 1],
                &vs[v - 1],
                (Stream::Camera, base),
                numbers,
                rng,
            )?;
        }
    } else if lens > 0 {
        numbers.set2(Stream::Connection, 1, u_lens);
    }

    // Light side: x_0 … x_{s−1}.
    if s >= 1 {
        let x0 = &vs[0];
        let light = x0.light;
        if !x0.is_light() || scene.lights.lights.get(light as usize).is_none() {
            return Err(InverseFailure::Technique);
        }
        // x_0 on an emitter at infinity holds only its direction ω = wo.
        let at_infinity = x0.kind == VertexKind::Infinite;
        let u_sel =
            light_selection(&scene.lights, light, uniform(rng)).ok_or(InverseFailure::Emitter)?;
        if s == 1 {
            numbers.set(Stream::Connection, 1, u_sel);
            let u = if at_infinity {
                infinite_direction_to_square(scene, light, x0.wo)
            } else {
                direct_point_to_square(scene, light, vs[1].p(), &x0.sp)
            };
            match u {
                Some(Some(u)) => numbers.set2(Stream::Connection, 2, u),
                Some(None) => {}
                None => return Err(InverseFailure::Emitter),
            }
        } else {
            numbers.set(Stream::Light, 0, u_sel);
            if at_infinity {
                // The walk enters along −ω from the point of the disk whose
                // ray passes through x_1; the direction is ω's (none for a
                // directional light).
                let u = scene
                    .lights
                    .infinite_origin_to_square(-x0.wo, vs[1].p())
                    .ok_or(InverseFailure::Emitter)?;
                numbers.set2(Stream::Light, 1, u);
                if let Some(u) = infinite_direction_to_square(scene, light, x0.wo)
                    .ok_or(InverseFailure::Emitter)?
                {
                    numbers.set2(Stream::Light, 3, u);
                }
            } else {
                if matches!(scene.lights.lights[light as usize], Light::Area { .. }) {
                    let u = area_point_to_square(scene, light, &x0.sp)
                        .ok_or(InverseFailure::Emitter)?;
                    numbers.set2(Stream::Light, 1, u);
                }
                let d = dir(x0, &vs[1]).ok_or(InverseFailure::Emitter)?;
                let u = emission_direction_to_square(scene, light, &x0.sp, d)
                    .ok_or(InverseFailure::Emitter)?;
                numbers.set2(Stream::Light, 3, u);
            }
            for j in 1..s - 1 {
                invert_scattering(
                    scene,
                    &vs[j],
                    &vs[j - 1],
                    &vs[j + 1],
                    (Stream::Light, 5 + 4 * (j - 1)),
                    numbers,
                    rng,
                )?;
            }
        }
    }
    Ok(())
}

/// Why a round trip failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RoundTripFailure {
    /// No inverse ([`invert`]).
    Inverse(InverseFailure),
    /// Re-tracing the numbers gave another technique or a zero (or NaN)
    /// contribution (spec seed001 §5.1, §6).
    Retrace,
}

/// The round trip of spec seed001 §5.1: inverts `path` under technique
/// `s`, re-traces the numbers into `out` (whose scene and buffers are
/// reused) and checks that the same technique produced a non-zero, finite
/// contribution.
pub fn round_trip<'s>(
    scene: &'s Scene,
    depth: &MmltDepth,
    path: &Path<'_>,
    s: usize,
    rng: &mut ChainRng,
    out: &mut FusedState<'s>,
) -> Result<(), RoundTripFailure> {
    invert(scene, depth, path, s, rng, &mut out.point).map_err(RoundTripFailure::Inverse)?;
    trace(scene, depth, out);
    let t = depth.depth + 1 - s;
    if out.technique != Some((s, t)) || !out.log_density.is_finite() {
        return Err(RoundTripFailure::Retrace);
    }
    Ok(())
}

/// An empty payload of depth `depth` (for states not traced yet).
pub(crate) fn empty_sample(depth: usize) -> PathSample {
    PathSample {
        splats: Vec::new(),
        depth: depth as u32,
    }
}
