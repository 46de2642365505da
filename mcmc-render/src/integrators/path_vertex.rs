//! Path vertices for bidirectional methods: what a subpath stores at each
//! vertex, and the area-measure densities that MIS needs (Veach 1997 §10,
//! pbrt-v4 `Vertex`).
//!
//! Densities are always **per unit area at the vertex they produce**
//! (solid-angle densities times `|cos θ| / d²` at the receiving vertex), so
//! that the densities of different techniques for one path can be compared.
//! A vertex stores `pdf_fwd` (the density with which its own subpath
//! produced it) and `pdf_rev` (the density with which the *other* direction
//! would produce it, filled in by the walk from the next vertex, and
//! overridden at the connection).

use crate::bsdf::TransportMode;
use crate::bsdf::textured::BsdfAt;
use crate::color::Rgb;
use crate::geometry::SurfacePoint;
use crate::light::Light;
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// Where the BSDFs at the vertices of a connection come from: the scene's
/// own ([`SceneBsdfs`]), or one of several roughened copies of them (the
/// levels of a tempered ladder, `crate::tempered`). A connection and its
/// MIS weight are evaluated per level with the subpaths traced once.
pub trait ConnectionBsdfs: Sync {
    /// Number of levels.
    fn levels(&self) -> usize;
    /// The BSDF of level `level` at `sp`.
    fn bsdf_at<'a>(&'a self, scene: &'a Scene, level: usize, sp: &SurfacePoint) -> BsdfAt<'a>;
    /// True when every level's BSDF at `sp` is level 0's (e.g. a diffuse
    /// surface, which tempering leaves alone): a connection through such
    /// vertices has the same value and MIS weight at every level, so it
    /// is evaluated once.
    fn same_at_every_level(&self, scene: &Scene, sp: &SurfacePoint) -> bool;
}

/// The scene's own BSDFs: one level.
#[derive(Clone, Copy, Debug, Default)]
pub struct SceneBsdfs;

impl ConnectionBsdfs for SceneBsdfs {
    #[inline(always)]
    fn levels(&self) -> usize {
        1
    }
    #[inline(always)]
    fn bsdf_at<'a>(&'a self, scene: &'a Scene, _level: usize, sp: &SurfacePoint) -> BsdfAt<'a> {
        scene.bsdf_at(sp)
    }
    #[inline(always)]
    fn same_at_every_level(&self, _scene: &Scene, _sp: &SurfacePoint) -> bool {
        true
    }
}

/// Marks "no emitter" in [`Vertex::light`].
pub const NO_LIGHT: u32 = u32::MAX;

/// What a vertex is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VertexKind {
    /// The pinhole (first vertex of a camera subpath).
    Camera,
    /// A point on an emitter where a light subpath starts.
    Light,
    /// A scattering point on a surface (possibly on an emitter).
    Surface,
    /// An emitter at infinity: the end of a camera subpath that escaped
    /// the scene into the environment, or the origin of a light subpath
    /// from a directional light or an environment. Its `wo` is the unit
    /// direction from the scene towards the emitter; it has no position
    /// (densities towards it are solid-angle densities, densities from it
    /// are the origin disk's `1/(πR²)` times the cosine at the receiver).
    Infinite,
}

/// One vertex of a camera or light subpath.
#[derive(Clone, Copy, Debug)]
pub struct Vertex {
    /// What the vertex is.
    pub kind: VertexKind,
    /// Position and normals. Point lights and the pinhole have zero normals
    /// (they are not on a surface: no cosine at them).
    pub sp: SurfacePoint,
    /// Unit world direction towards the previous vertex of its own subpath
    /// (surface vertices); for [`VertexKind::Infinite`], the direction from
    /// the scene towards the emitter.
    pub wo: Vec3,
    /// Subpath throughput up to and including this vertex's arrival
    /// (pbrt's β): for camera subpaths the importance-weighted estimate of
    /// the subpath, for light subpaths the emitted power carried.
    pub beta: Rgb,
    /// Area density of this vertex under its own subpath's sampling.
    pub pdf_fwd: f32,
    /// Area density of this vertex under the opposite subpath's sampling.
    pub pdf_rev: f32,
    /// True when the BSDF sampled at this vertex was a Dirac delta.
    pub delta: bool,
    /// Emitter index when the vertex lies on an emitter, else [`NO_LIGHT`].
    pub light: u32,
    /// Raster position (camera vertices only).
    pub raster: Vec2,
}

/// `|wo·ns| |wi·ng| / (|wo·ng| |wi·ns|)`: the factor that makes importance
/// transport with shading normals adjoint to radiance transport (Veach 1997 §5.3).
pub fn shading_correction(wo: Vec3, wi: Vec3, ng: Vec3, ns: Vec3) -> f32 {
    let num = wo.dot(ns).abs() * wi.dot(ng).abs();
    let den = wo.dot(ng).abs() * wi.dot(ns).abs();
    if den > 0.0 { num / den } else { 0.0 }
}

impl Vertex {
    /// A placeholder vertex (for pre-sized buffers).
    pub const EMPTY: Vertex = Vertex {
        kind: VertexKind::Camera,
        sp: SurfacePoint {
            p: Vec3::ZERO,
            p_err: Vec3::ZERO,
            ng: Vec3::ZERO,
            ns: Vec3::ZERO,
            uv: Vec2::ZERO,
            shape: u32::MAX,
            prim: crate::geometry::NO_PRIM,
        },
        wo: Vec3::ZERO,
        beta: Rgb::BLACK,
        pdf_fwd: 0.0,
        pdf_rev: 0.0,
        delta: false,
        light: NO_LIGHT,
        raster: Vec2::ZERO,
    };

    /// The pinhole at `origin`, for a ray through `raster`, with throughput `beta`.
    pub fn camera(origin: Vec3, raster: Vec2, beta: Rgb) -> Vertex {
        let mut v = Vertex::EMPTY;
        v.kind = VertexKind::Camera;
        v.sp.p = origin;
        v.raster = raster;
        v.beta = beta;
        v.pdf_fwd = 1.0;
        v
    }

    /// A light-subpath origin on emitter `light`. Point lights get zero normals.
    pub fn light(scene: &Scene, light: u32, sp: SurfacePoint, beta: Rgb, pdf_fwd: f32) -> Vertex {
        let mut v = Vertex::EMPTY;
        v.kind = VertexKind::Light;
        v.sp = sp;
        if matches!(scene.lights.lights[light as usize], Light::Point { .. }) {
            v.sp.ng = Vec3::ZERO;
            v.sp.ns = Vec3::ZERO;
        }
        v.light = light;
        v.beta = beta;
        v.pdf_fwd = pdf_fwd;
        v
    }

    /// A vertex on emitter `light` at infinity, in unit direction `w` from
    /// the scene, with throughput `beta` and density `pdf_fwd`.
    pub fn infinite(light: u32, w: Vec3, beta: Rgb, pdf_fwd: f32) -> Vertex {
        let mut v = Vertex::EMPTY;
        v.kind = VertexKind::Infinite;
        v.wo = w;
        v.light = light;
        v.beta = beta;
        v.pdf_fwd = pdf_fwd;
        v
    }

    /// Unit direction from this vertex towards `next` (`None` when they coincide).
    #[inline]
    pub fn direction_to(&self, next: &Vertex) -> Option<Vec3> {
        if next.kind == VertexKind::Infinite {
            Some(next.wo)
        } else if self.kind == VertexKind::Infinite {
            Some(-self.wo)
        } else {
            let d = next.p() - self.p();
            let len2 = d.length_squared();
            (len2 > 0.0).then(|| d / len2.sqrt())
        }
    }

    /// A surface vertex reached from direction `wo` (world, pointing back).
    pub fn surface(scene: &Scene, sp: SurfacePoint, wo: Vec3, beta: Rgb) -> Vertex {
        let mut v = Vertex::EMPTY;
        v.kind = VertexKind::Surface;
        v.sp = sp;
        v.wo = wo;
        v.beta = beta;
        v.light = scene.shapes[sp.shape as usize].light.unwrap_or(NO_LIGHT);
        v
    }

    /// Position.
    #[inline]
    pub fn p(&self) -> Vec3 {
        self.sp.p
    }

    /// True when the vertex lies on a surface (densities get a cosine there).
    #[inline]
    pub fn on_surface(&self) -> bool {
        self.sp.ng != Vec3::ZERO
    }

    /// True when a deterministic connection to this vertex can carry light:
    /// endpoints always, surfaces unless their BSDF is purely specular.
    pub fn is_connectible(&self, scene: &Scene) -> bool {
        self.is_connectible_in(scene, &SceneBsdfs, 0)
    }

    /// [`Vertex::is_connectible`] with the BSDF of `level` of `bsdfs`.
    #[inline(always)]
    pub fn is_connectible_in<B: ConnectionBsdfs>(
        &self,
        scene: &Scene,
        bsdfs: &B,
        level: usize,
    ) -> bool {
        match self.kind {
            VertexKind::Camera | VertexKind::Light | VertexKind::Infinite => true,
            VertexKind::Surface => !bsdfs.bsdf_at(scene, level, &self.sp).is_delta(),
        }
    }

    /// True when every level of `bsdfs` gives this vertex the same
    /// scattering (endpoints always; surfaces whose BSDF no level changes):
    /// its values and densities in a connection are then level 0's.
    #[inline(always)]
    pub fn is_same_at_every_level<B: ConnectionBsdfs>(&self, scene: &Scene, bsdfs: &B) -> bool {
        self.kind != VertexKind::Surface || bsdfs.same_at_every_level(scene, &self.sp)
    }

    /// True when the vertex lies on an emitter.
    #[inline]
    pub fn is_light(&self) -> bool {
        self.light != NO_LIGHT
    }

    /// True for an emitter origin that is a Dirac delta in position or
    /// direction (point and directional lights): no path can hit it.
    pub fn is_delta_light(&self, scene: &Scene) -> bool {
        matches!(self.kind, VertexKind::Light | VertexKind::Infinite)
            && scene.lights.lights[self.light as usize].is_delta()
    }

    /// BSDF value (no cosine) for scattering from `wo` towards `next`, with
    /// the adjoint shading-normal correction for importance transport.
    /// Zero for non-surface vertices.
    pub fn f(&self, scene: &Scene, next: &Vertex, mode: TransportMode) -> Rgb {
        self.f_in(scene, &SceneBsdfs, 0, next, mode)
    }

    /// [`Vertex::f`] with the BSDF of `level` of `bsdfs`.
    #[inline(always)]
    pub fn f_in<B: ConnectionBsdfs>(
        &self,
        scene: &Scene,
        bsdfs: &B,
        level: usize,
        next: &Vertex,
        mode: TransportMode,
    ) -> Rgb {
        if self.kind != VertexKind::Surface {
            return Rgb::BLACK;
        }
        let Some(wi) = self.direction_to(next) else {
            return Rgb::BLACK;
        };
        let frame = scene.shading_frame(&self.sp);
        let f = bsdfs.bsdf_at(scene, level, &self.sp).eval(
            frame.to_local(self.wo),
            frame.to_local(wi),
            mode,
        );
        match mode {
            TransportMode::Radiance => f,
            TransportMode::Importance => {
                f * shading_correction(self.wo, wi, self.sp.ng, self.sp.ns)
            }
        }
    }

    /// Converts a solid-angle density at this vertex into an area density
    /// at `next`. Towards a vertex at infinity the solid-angle density is
    /// kept; from one, `pdf` is the origin disk's area density and only the
    /// cosine at `next` applies.
    pub fn convert_density(&self, pdf: f32, next: &Vertex) -> f32 {
        if next.kind == VertexKind::Infinite {
            return pdf;
        }
        if self.kind == VertexKind::Infinite {
            return if next.on_surface() {
                pdf * next.sp.ng.dot(self.wo).abs()
            } else {
                pdf
            };
        }
        let w = next.p() - self.p();
        let d2 = w.length_squared();
        if !(d2 > 0.0) {
            return 0.0;
        }
        let inv = 1.0 / d2;
        let mut pdf = pdf * inv;
        if next.on_surface() {
            pdf *= next.sp.ng.dot(w * inv.sqrt()).abs();
        }
        pdf
    }

    /// Area density at `next` of sampling it from this vertex, having
    /// arrived from `prev` (unused for endpoints), by a walk in `mode`.
    pub fn pdf(
        &self,
        scene: &Scene,
        prev: Option<&Vertex>,
        next: &Vertex,
        mode: TransportMode,
    ) -> f32 {
        self.pdf_in(scene, &SceneBsdfs, 0, prev, next, mode)
    }

    /// [`Vertex::pdf`] with the BSDF of `level` of `bsdfs`.
    #[inline(always)]
    pub fn pdf_in<B: ConnectionBsdfs>(
        &self,
        scene: &Scene,
        bsdfs: &B,
        level: usize,
        prev: Option<&Vertex>,
        next: &Vertex,
        mode: TransportMode,
    ) -> f32 {
        if matches!(self.kind, VertexKind::Light | VertexKind::Infinite) {
            return self.pdf_light(scene, next);
        }
        let Some(wn) = self.direction_to(next) else {
            return 0.0;
        };
        let pdf = match self.kind {
            VertexKind::Camera => scene.camera.pdf_we(self.p(), wn).1,
            _ => {
                let Some(wp) = prev.and_then(|prev| self.direction_to(prev)) else {
                    return 0.0;
                };
                let frame = scene.shading_frame(&self.sp);
                bsdfs.bsdf_at(scene, level, &self.sp).pdf(
                    frame.to_local(wp),
                    frame.to_local(wn),
                    mode,
                )
            }
        };
        self.convert_density(pdf, next)
    }

    /// Area density at `next` of the emitted direction when a light subpath
    /// starts at this vertex (which must lie on an emitter).
    pub fn pdf_light(&self, scene: &Scene, next: &Vertex) -> f32 {
        if !self.is_light() {
            return 0.0;
        }
        if self.kind == VertexKind::Infinite {
            return self.convert_density(scene.lights.infinite_disk_pdf(), next);
        }
        let d = next.p() - self.p();
        let d2 = d.length_squared();
        if !(d2 > 0.0) {
            return 0.0;
        }
        let w = d / d2.sqrt();
        let pdf_dir = match &scene.lights.lights[self.light as usize] {
            Light::Point { spot: None, .. } => 0.25 * FRAC_1_PI,
            Light::Point { spot: Some(s), .. } => s.pdf(w),
            Light::Area { .. } => {
                let c = self.sp.ns.dot(w);
                if c > 0.0 { c * FRAC_1_PI } else { 0.0 }
            }
            // Emitters at infinity are `Infinite` vertices (handled above).
            Light::Directional { .. } | Light::Environment(_) => 0.0,
        };
        let mut pdf = pdf_dir / d2;
        if next.on_surface() {
            pdf *= next.sp.ng.dot(w).abs();
        }
        pdf
    }

    /// Area density of choosing this emitter point as a light-subpath origin
    /// (selection probability times position density). For an emitter at
    /// infinity, the density of its direction (pbrt's convention): solid
    /// angle for an environment, 1 for a directional light (a delta).
    pub fn pdf_light_origin(&self, scene: &Scene) -> f32 {
        if !self.is_light() {
            return 0.0;
        }
        let pmf = scene.lights.pmf(self.light);
        match &scene.lights.lights[self.light as usize] {
            Light::Point { .. } | Light::Directional { .. } => pmf,
            Light::Environment(env) => pmf * env.pdf(self.wo),
            Light::Area { area, .. } => {
                if *area > 0.0 {
                    pmf / area
                } else {
                    0.0
                }
            }
        }
    }

    /// Radiance this (emitter) vertex sends towards `to`.
    pub fn le(&self, scene: &Scene, to: &Vertex) -> Rgb {
        if !self.is_light() {
            return Rgb::BLACK;
        }
        match self.kind {
            VertexKind::Surface => {
                let w = (to.p() - self.p()).normalize_or_zero();
                scene.lights.area_radiance(self.light, &self.sp, w)
            }
            VertexKind::Infinite => scene.lights.environment_radiance(self.wo),
            VertexKind::Camera | VertexKind::Light => Rgb::BLACK,
        }
    }
}
