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
use crate::color::Rgb;
use crate::frame::Frame;
use crate::geometry::SurfacePoint;
use crate::light::Light;
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

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
    /// (surface vertices only).
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
        match self.kind {
            VertexKind::Camera | VertexKind::Light => true,
            VertexKind::Surface => !scene.bsdf_at(&self.sp).is_delta(),
        }
    }

    /// True when the vertex lies on an emitter.
    #[inline]
    pub fn is_light(&self) -> bool {
        self.light != NO_LIGHT
    }

    /// True for a point light (a Dirac delta in position).
    pub fn is_delta_light(&self, scene: &Scene) -> bool {
        self.kind == VertexKind::Light
            && matches!(
                scene.lights.lights[self.light as usize],
                Light::Point { .. }
            )
    }

    /// BSDF value (no cosine) for scattering from `wo` towards `next`, with
    /// the adjoint shading-normal correction for importance transport.
    /// Zero for non-surface vertices.
    pub fn f(&self, scene: &Scene, next: Vec3, mode: TransportMode) -> Rgb {
        if self.kind != VertexKind::Surface {
            return Rgb::BLACK;
        }
        let d = next - self.p();
        let len2 = d.length_squared();
        if !(len2 > 0.0) {
            return Rgb::BLACK;
        }
        let wi = d / len2.sqrt();
        let frame = Frame::from_normal(self.sp.ns);
        let f = scene
            .bsdf_at(&self.sp)
            .eval(frame.to_local(self.wo), frame.to_local(wi), mode);
        match mode {
            TransportMode::Radiance => f,
            TransportMode::Importance => {
                f * shading_correction(self.wo, wi, self.sp.ng, self.sp.ns)
            }
        }
    }

    /// Converts a solid-angle density at this vertex into an area density at `next`.
    pub fn convert_density(&self, pdf: f32, next: &Vertex) -> f32 {
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
        if self.kind == VertexKind::Light {
            return self.pdf_light(scene, next);
        }
        let d = next.p() - self.p();
        let len2 = d.length_squared();
        if !(len2 > 0.0) {
            return 0.0;
        }
        let wn = d / len2.sqrt();
        let pdf = match self.kind {
            VertexKind::Camera => scene.camera.pdf_we(wn).1,
            _ => {
                let Some(prev) = prev else {
                    return 0.0;
                };
                let wp = (prev.p() - self.p()).normalize_or_zero();
                if wp == Vec3::ZERO {
                    return 0.0;
                }
                let frame = Frame::from_normal(self.sp.ns);
                scene
                    .bsdf_at(&self.sp)
                    .pdf(frame.to_local(wp), frame.to_local(wn), mode)
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
        let d = next.p() - self.p();
        let d2 = d.length_squared();
        if !(d2 > 0.0) {
            return 0.0;
        }
        let w = d / d2.sqrt();
        let pdf_dir = match &scene.lights.lights[self.light as usize] {
            Light::Point { .. } => 0.25 * FRAC_1_PI,
            Light::Area { .. } => {
                let c = self.sp.ns.dot(w);
                if c > 0.0 { c * FRAC_1_PI } else { 0.0 }
            }
        };
        let mut pdf = pdf_dir / d2;
        if next.on_surface() {
            pdf *= next.sp.ng.dot(w).abs();
        }
        pdf
    }

    /// Area density of choosing this emitter point as a light-subpath origin
    /// (selection probability times position density).
    pub fn pdf_light_origin(&self, scene: &Scene) -> f32 {
        if !self.is_light() {
            return 0.0;
        }
        let pmf = scene.lights.pmf(self.light);
        match &scene.lights.lights[self.light as usize] {
            Light::Point { .. } => pmf,
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
        if !self.is_light() || self.kind != VertexKind::Surface {
            return Rgb::BLACK;
        }
        let w = (to.p() - self.p()).normalize_or_zero();
        scene.lights.area_radiance(self.light, &self.sp, w)
    }
}

/// Density of the emitted direction for an emission sample (cosine
/// hemisphere for area lights, uniform sphere for point lights).
pub(crate) fn emission_pdf_dir(is_point: bool, ns: Vec3, dir: Vec3) -> f32 {
    if is_point {
        1.0 / (4.0 * PI)
    } else {
        ns.dot(dir).max(0.0) * FRAC_1_PI
    }
}
