//! Emitters: one-sided area lights on any shape, point lights, and
//! emitters at infinity (an environment — `envmap` or `constant` — and
//! `directional` lights), chosen in proportion to their power.
//!
//! Emitters at infinity start light paths on a disk of the scene's
//! bounding-sphere radius `R` facing the sampled direction, at distance `R`
//! from the centre (pbrt's method): the disk's area density `1/(πR²)` is
//! the position density, and the geometry term to the first hit has no
//! `1/d²`. A scene holds at most one environment (as in Mitsuba 3).
//!
//! Area lights are sampled uniformly by area (per-triangle area CDF for
//! meshes); densities are converted to solid angle at the receiving point.
//! Sphere lights seen from outside are sampled uniformly in the cone they
//! subtend (pbrt-v4's method) for next-event estimation; light-path
//! origins are always sampled by area.

use crate::color::Rgb;
use crate::environment::Environment;
use crate::frame::Frame;
use crate::geometry::{FlatTriangle, Geometry, Surface, SurfacePoint, triangle_area};
use crate::scene::{InfiniteLightDesc, PointLightDesc};
use crate::warp;
use glam::{Mat3, Vec2, Vec3};
use std::f32::consts::PI;

/// One emitter.
#[derive(Clone, Debug)]
pub enum Light {
    /// Constant radiance leaving the normal side of a shape.
    Area {
        /// Shape index.
        shape: u32,
        /// Emitted radiance.
        radiance: Rgb,
        /// Shape area.
        area: f32,
        /// Normalised cumulative triangle areas (meshes only).
        tri_cdf: Vec<f32>,
        /// The mesh's triangles, cached for sampling (empty unless the shape
        /// is a mesh without vertex normals).
        flat_tris: Vec<FlatTriangle>,
        /// Centre and radius when the shape is a sphere (cone sampling).
        sphere: Option<(Vec3, f32)>,
    },
    /// Point light: isotropic, or a spot light when `spot` is set.
    Point {
        /// Position.
        position: Vec3,
        /// Radiant intensity (on the axis, for a spot light).
        intensity: Rgb,
        /// Mitsuba's `spot` profile, if the light is a spot light.
        spot: Option<SpotProfile>,
    },
    /// Parallel light (a Dirac delta in direction), never hit by rays.
    Directional {
        /// Unit direction the light travels in.
        direction: Vec3,
        /// Irradiance on a surface facing it.
        irradiance: Rgb,
    },
    /// Radiance from every direction at infinity (`envmap`, `constant`).
    Environment(Box<Environment>),
}

/// Mitsuba 3's `spot` emission profile: full intensity within `beam_width`
/// of the axis (the local +z of `to_world`), falling off linearly in the
/// angle to zero at `cutoff_angle` (measured against Mitsuba 3). Light
/// paths leave it uniformly in the cone of the cutoff angle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpotProfile {
    /// World to light frame (a rotation).
    to_local: Mat3,
    /// Light frame to world.
    to_world: Mat3,
    cos_cutoff: f32,
    cos_beam: f32,
    /// Cutoff angle in radians.
    cutoff: f32,
    /// `1 / (cutoff − beam_width)` in radians.
    inv_transition: f32,
}

impl SpotProfile {
    /// The profile for angles in degrees and a light-to-world rotation.
    /// Errors for angles outside (0°, 90°], a beam wider than the cutoff,
    /// or a `to_world` with scale or shear.
    pub fn new(to_world: Mat3, cutoff_deg: f32, beam_deg: f32) -> Result<SpotProfile, String> {
        if !(cutoff_deg > 0.0 && cutoff_deg <= 90.0) {
            return Err(format!(
                "'cutoff_angle' must be in (0, 90] degrees, got {cutoff_deg}"
            ));
        }
        if !(beam_deg > 0.0 && beam_deg <= cutoff_deg) {
            return Err(format!(
                "'beam_width' must be in (0, cutoff_angle = {cutoff_deg}] degrees, got {beam_deg}"
            ));
        }
        if !crate::frame::is_rotation(to_world) {
            return Err(
                "a spot emitter's to_world must be a rotation and translation (no scale or shear)"
                    .into(),
            );
        }
        let (cutoff, beam) = (cutoff_deg.to_radians(), beam_deg.to_radians());
        Ok(SpotProfile {
            to_local: to_world.transpose(),
            to_world,
            cos_cutoff: cutoff.cos(),
            cos_beam: beam.cos(),
            cutoff,
            inv_transition: if cutoff > beam {
                1.0 / (cutoff - beam)
            } else {
                0.0
            },
        })
    }

    /// Fraction of the on-axis intensity sent along the unit world direction `w`.
    pub fn falloff(&self, w: Vec3) -> f32 {
        let cos = (self.to_local * w).z;
        if !(cos > self.cos_cutoff) {
            0.0
        } else if cos >= self.cos_beam {
            1.0
        } else {
            ((self.cutoff - cos.clamp(-1.0, 1.0).acos()) * self.inv_transition).clamp(0.0, 1.0)
        }
    }

    /// Solid angle of the cutoff cone.
    fn cone_solid_angle(&self) -> f32 {
        2.0 * PI * (1.0 - self.cos_cutoff)
    }

    /// A direction uniform in the cutoff cone, with its solid-angle density.
    pub fn sample(&self, u: (f32, f32)) -> (Vec3, f32) {
        let cos = 1.0 - u.0 * (1.0 - self.cos_cutoff);
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let (sp, cp) = (2.0 * PI * u.1).sin_cos();
        let w = self.to_world * Vec3::new(sin * cp, sin * sp, cos);
        (w.normalize(), 1.0 / self.cone_solid_angle())
    }

    /// The numbers with which [`SpotProfile::sample`] returns the unit
    /// world direction `w` (the inverse sampler of `crate::inverse`), or
    /// `None` outside the cone.
    pub fn invert(&self, w: Vec3) -> Option<(f32, f32)> {
        let l = (self.to_local * w).as_dvec3();
        let width = 1.0 - f64::from(self.cos_cutoff);
        // The cone's rim (u₀ → 1) can come back a rounding error outside.
        if !(l.z > f64::from(self.cos_cutoff) - 1e-6) || !(width > 0.0) {
            return None;
        }
        let u0 = ((1.0 - l.z) / width).clamp(0.0, 1.0);
        Some((
            crate::sampling::to_unit_f32(u0),
            crate::inverse::angle_to_unit(l.y.atan2(l.x)),
        ))
    }

    /// Density of [`SpotProfile::sample`] at the unit world direction `w`.
    pub fn pdf(&self, w: Vec3) -> f32 {
        if (self.to_local * w).z > self.cos_cutoff {
            1.0 / self.cone_solid_angle()
        } else {
            0.0
        }
    }
}

impl Light {
    /// True for emitters that are Dirac deltas in position or direction
    /// (point and directional lights): no ray can hit them.
    pub fn is_delta(&self) -> bool {
        matches!(self, Light::Point { .. } | Light::Directional { .. })
    }
}

/// A light sample seen from a receiving point (next-event estimation).
#[derive(Clone, Copy, Debug)]
pub struct DirectSample {
    /// The light point (for point lights: its position, zero error, normal towards the receiver).
    pub p: SurfacePoint,
    /// Unit direction from the receiver towards the light.
    pub wi: Vec3,
    /// Distance to the light point.
    pub dist: f32,
    /// Incident radiance (for point lights `I / d²`).
    pub le: Rgb,
    /// Solid-angle density at the receiver, including the selection
    /// probability (for point lights: the selection probability alone).
    pub pdf: f32,
    /// True for point and directional lights.
    pub is_delta: bool,
    /// True for emitters at infinity: `p` is then a point beyond the
    /// scene's bounding sphere along `wi`, `dist` is infinite, and
    /// visibility is a ray that must escape the scene.
    pub at_infinity: bool,
}

/// A light-path origin for light tracing.
#[derive(Clone, Copy, Debug)]
pub struct EmissionSample {
    /// The starting point.
    pub p: SurfacePoint,
    /// Unit direction of the first segment.
    pub dir: Vec3,
    /// `Le · cos / (p_select · p_area · p_dir)`, the initial throughput.
    pub weight: Rgb,
    /// Radiance along `dir` (area lights) or intensity (point lights),
    /// before division by the densities.
    pub le: Rgb,
    /// True for point lights (their origin is a delta position).
    pub is_delta: bool,
    /// Density of the origin: selection probability times area density
    /// (for point lights: the selection probability; for emitters at
    /// infinity: the selection probability over the disk's area `πR²`).
    pub pdf_pos: f32,
    /// Density of `dir`: solid angle for area and point lights and for
    /// environments, 1 for directional lights (a delta).
    pub pdf_dir: f32,
    /// True for emitters at infinity: `p` lies on the disk outside the
    /// scene, not on a surface (`ng`, `ns` are `dir`).
    pub at_infinity: bool,
}

/// The cone a sphere subtends from an outside point.
#[derive(Clone, Copy, Debug)]
struct SphereCone {
    /// Unit direction from the point to the centre.
    axis: Vec3,
    sin2_max: f32,
    one_minus_cos: f32,
    /// Uniform solid-angle density over the cone.
    pdf: f32,
}

/// All emitters and their selection distribution.
#[derive(Clone, Debug, Default)]
pub struct Lights {
    /// The emitters.
    pub lights: Vec<Light>,
    pmf: Vec<f32>,
    cdf: Vec<f32>,
    /// Index of the environment emitter, if any.
    environment: Option<u32>,
    /// Centre and radius of the scene's bounding sphere (emitters at infinity).
    scene_center: Vec3,
    scene_radius: f32,
}

/// Bounding sphere of every shape (centre, radius), at least radius 1e-3.
fn bounding_sphere(geometry: &Geometry) -> (Vec3, f32) {
    let Some((lo, hi)) = geometry.bounds() else {
        return (Vec3::ZERO, 1.0);
    };
    let center = (lo + hi) * 0.5;
    // A little margin, so that disk origins lie strictly outside every shape.
    let radius = ((hi - lo).length() * 0.5 * 1.01).max(1e-3);
    (center, radius)
}

/// A triangle of a mesh emitter picked by area with `u.0` (reused, rescaled
/// to the triangle's share of the CDF) and a uniform point on it with
/// (`u.0`, `u.1`): the triangle's index and the point's barycentrics.
#[inline(always)]
fn pick_triangle(tri_cdf: &[f32], u: (f32, f32)) -> (usize, (f32, f32, f32)) {
    let i = tri_cdf
        .partition_point(|&c| c <= u.0)
        .min(tri_cdf.len() - 1);
    let lo = if i == 0 { 0.0 } else { tri_cdf[i - 1] };
    let width = tri_cdf[i] - lo;
    let u0 = if width > 0.0 {
        ((u.0 - lo) / width).clamp(0.0, crate::sampling::ONE_MINUS_EPSILON)
    } else {
        0.5
    };
    (i, warp::uniform_triangle((u0, u.1)))
}

/// The direct-light sample of area-light point `lp` (area density
/// `pdf_area`, light chosen with probability `pmf`) seen from `p`: `None`
/// from behind the light or for a degenerate density.
#[inline(always)]
fn area_direct(
    lp: SurfacePoint,
    pdf_area: f32,
    pmf: f32,
    radiance: Rgb,
    p: Vec3,
) -> Option<DirectSample> {
    let delta = lp.p - p;
    let dist2 = delta.length_squared();
    if !(dist2 > 0.0) {
        return None;
    }
    let dist = dist2.sqrt();
    let wi = delta / dist;
    let cos_l = lp.ns.dot(-wi);
    if cos_l <= 0.0 {
        return None;
    }
    let pdf = pmf * pdf_area * dist2 / cos_l;
    if !(pdf > 0.0 && pdf.is_finite()) {
        return None;
    }
    Some(DirectSample {
        p: lp,
        wi,
        dist,
        le: radiance,
        pdf,
        is_delta: false,
        at_infinity: false,
    })
}

impl Lights {
    /// Builds emitters from `(shape, radiance)` pairs, point lights and
    /// emitters at infinity (at most one environment: the caller checks).
    pub fn new(
        geometry: &Geometry,
        area: &[(u32, Rgb)],
        points: &[PointLightDesc],
        infinite: &[InfiniteLightDesc],
    ) -> Lights {
        let mut lights = Vec::new();
        for &(shape, radiance) in area {
            let surface = &geometry.shapes[shape as usize].surface;
            let tri_cdf = match surface {
                Surface::Mesh(m) => {
                    let mut acc = 0.0f64;
                    let mut cdf: Vec<f32> = m
                        .indices
                        .iter()
                        .map(|t| {
                            acc += triangle_area(m, t) as f64;
                            acc as f32
                        })
                        .collect();
                    let total = acc as f32;
                    cdf.iter_mut().for_each(|c| *c /= total);
                    if let Some(last) = cdf.last_mut() {
                        *last = 1.0;
                    }
                    cdf
                }
                _ => Vec::new(),
            };
            let sphere = match surface {
                Surface::Sphere { center, radius, .. } => Some((*center, *radius)),
                _ => None,
            };
            let flat_tris = (0..tri_cdf.len() as u32)
                .map(|t| geometry.flat_triangle(shape, t))
                .collect::<Option<Vec<_>>>()
                .unwrap_or_default();
            lights.push(Light::Area {
                shape,
                radiance,
                area: surface.area(),
                tri_cdf,
                flat_tris,
                sphere,
            });
        }
        for p in points {
            lights.push(Light::Point {
                position: p.position,
                intensity: p.intensity,
                spot: p.spot,
            });
        }
        let mut environment = None;
        for l in infinite {
            match l {
                InfiniteLightDesc::Directional {
                    direction,
                    irradiance,
                } => lights.push(Light::Directional {
                    direction: *direction,
                    irradiance: *irradiance,
                }),
                InfiniteLightDesc::Environment(env) => {
                    environment = Some(lights.len() as u32);
                    lights.push(Light::Environment(env.clone()));
                }
            }
        }
        let (scene_center, scene_radius) = bounding_sphere(geometry);
        let disk_area = f64::from(PI * scene_radius * scene_radius);
        let power: Vec<f64> = lights
            .iter()
            .map(|l| match l {
                Light::Area { radiance, area, .. } => {
                    (PI * area * radiance.luminance()).max(0.0) as f64
                }
                Light::Point {
                    intensity, spot, ..
                } => {
                    let solid_angle = spot.map_or(4.0 * PI, |s| s.cone_solid_angle());
                    (solid_angle * intensity.luminance()).max(0.0) as f64
                }
                Light::Directional { irradiance, .. } => {
                    disk_area * f64::from(irradiance.luminance().max(0.0))
                }
                Light::Environment(env) => disk_area * env.radiant_integral().max(0.0),
            })
            .collect();
        let total: f64 = power.iter().sum();
        let pmf: Vec<f32> = if total > 0.0 && total.is_finite() {
            power.iter().map(|p| (p / total) as f32).collect()
        } else {
            vec![1.0 / lights.len().max(1) as f32; lights.len()]
        };
        let mut acc = 0.0f32;
        let mut cdf: Vec<f32> = pmf
            .iter()
            .map(|p| {
                acc += p;
                acc
            })
            .collect();
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        Lights {
            lights,
            pmf,
            cdf,
            environment,
            scene_center,
            scene_radius,
        }
    }

    /// Index of the environment emitter (`envmap` or `constant`), if any.
    #[inline]
    pub fn environment(&self) -> Option<u32> {
        self.environment
    }

    /// Radiance arriving from the environment along the unit direction `d`
    /// (pointing away from the scene); black without an environment.
    #[inline]
    pub fn environment_radiance(&self, d: Vec3) -> Rgb {
        match self.environment.map(|i| &self.lights[i as usize]) {
            Some(Light::Environment(env)) => env.eval(d),
            _ => Rgb::BLACK,
        }
    }

    /// Solid-angle density with which [`Lights::sample_direct`] picks the
    /// environment along `d` (selection probability included).
    pub fn pdf_environment(&self, d: Vec3) -> f32 {
        match self.environment {
            Some(i) => match &self.lights[i as usize] {
                Light::Environment(env) => self.pmf[i as usize] * env.pdf(d),
                _ => 0.0,
            },
            None => 0.0,
        }
    }

    /// Radius of the scene's bounding sphere (1% margin included): the
    /// disk of emitters at infinity, and the scale of `vcm`'s automatic
    /// merge radius.
    pub fn scene_radius(&self) -> f32 {
        self.scene_radius
    }

    /// Density of a light-path origin on the disk of an emitter at
    /// infinity (per unit area, selection excluded): `1/(πR²)`.
    pub fn infinite_disk_pdf(&self) -> f32 {
        1.0 / (PI * self.scene_radius * self.scene_radius)
    }

    /// The origin of a light path entering the scene along unit `dir` from
    /// an emitter at infinity: the point of `u_pos` on the disk of radius
    /// `R` perpendicular to `dir`, `R` before the scene's centre (uniform,
    /// density [`Lights::infinite_disk_pdf`]). Light walks and the
    /// path-space walks that continue from a kept vertex at infinity share it.
    pub fn infinite_origin(&self, dir: Vec3, u_pos: (f32, f32)) -> Vec3 {
        let frame = Frame::from_normal(dir);
        let d = warp::concentric_disk(u_pos) * self.scene_radius;
        self.scene_center - dir * self.scene_radius + frame.s * d.x + frame.t * d.y
    }

    /// Inverse of [`Lights::infinite_origin`]: the numbers `u_pos` whose
    /// origin's ray along unit `dir` passes through `p` (the orthogonal
    /// projection of `p` onto the disk, in the same frame), or `None` when
    /// that projection lies outside the disk (beyond `f32` rounding).
    pub fn infinite_origin_to_square(&self, dir: Vec3, p: Vec3) -> Option<(f32, f32)> {
        let frame = Frame::from_normal(dir);
        let q = (p - self.scene_center).as_dvec3() / f64::from(self.scene_radius);
        let d = glam::DVec2::new(q.dot(frame.s.as_dvec3()), q.dot(frame.t.as_dvec3()));
        let r2 = d.length_squared();
        if !(r2 <= 1.0 + 1e-5) {
            return None;
        }
        let d = if r2 > 1.0 { d / r2.sqrt() } else { d };
        Some(crate::inverse::disk_to_square(d.as_vec2()))
    }

    /// A point beyond the scene's bounding sphere along `d` from `p`
    /// (stands in for a point of an emitter at infinity).
    fn far_point(&self, p: Vec3, d: Vec3) -> SurfacePoint {
        let reach = (p - self.scene_center).length() + 2.0 * self.scene_radius;
        SurfacePoint {
            p: p + d * reach,
            p_err: Vec3::ZERO,
            ng: -d,
            ns: -d,
            uv: Vec2::ZERO,
            shape: u32::MAX,
            prim: crate::geometry::NO_PRIM,
        }
    }

    /// True when an emitter lies at infinity (`envmap`, `constant`,
    /// `directional`).
    pub fn has_emitter_at_infinity(&self) -> bool {
        self.lights
            .iter()
            .any(|l| matches!(l, Light::Directional { .. } | Light::Environment(_)))
    }

    /// True when the scene has no emitter.
    pub fn is_empty(&self) -> bool {
        self.lights.is_empty()
    }

    /// Probability of selecting light `i`.
    pub fn pmf(&self, i: u32) -> f32 {
        self.pmf[i as usize]
    }

    /// Picks a light with probability ∝ power; returns (index, pmf, `u` remapped to [0,1)).
    pub fn select(&self, u: f32) -> Option<(u32, f32)> {
        if self.lights.is_empty() {
            return None;
        }
        let i = self
            .cdf
            .partition_point(|&c| c <= u)
            .min(self.lights.len() - 1);
        let p = self.pmf[i];
        (p > 0.0).then_some((i as u32, p))
    }

    /// The interval `[lo, hi)` of selection numbers `u` for which
    /// [`Lights::select`] picks light `i` (empty for a light of zero
    /// power).
    pub fn selection_interval(&self, i: u32) -> (f32, f32) {
        let i = i as usize;
        let lo = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        (lo, self.cdf[i])
    }

    /// Uniform point on an area light; returns it with its area density.
    fn sample_area_point(
        &self,
        geometry: &Geometry,
        light: &Light,
        u: (f32, f32),
    ) -> Option<(SurfacePoint, f32)> {
        let Light::Area {
            shape,
            area,
            tri_cdf,
            flat_tris,
            ..
        } = light
        else {
            return None;
        };
        // Only meshes have a triangle CDF: they skip the shape look-up.
        let sp = if !tri_cdf.is_empty() {
            let (i, (b0, b1, b2)) = pick_triangle(tri_cdf, u);
            match flat_tris.get(i) {
                Some(t) => t.point(b0, b1, b2),
                None => geometry.triangle_point(*shape, i as u32, b0, b1, b2),
            }
        } else {
            match &geometry.shapes[*shape as usize].surface {
                Surface::Sphere { center, radius, .. } => {
                    geometry.sphere_point(*shape, *center + warp::uniform_sphere(u) * *radius)
                }
                Surface::Disk { .. } => {
                    let d: Vec2 = warp::concentric_disk(u);
                    geometry.disk_point(*shape, d.x, d.y)
                }
                // A mesh always has a triangle CDF (an empty mesh is no emitter).
                Surface::Mesh(_) => return None,
            }
        };
        Some((sp, 1.0 / area))
    }

    /// Next-event estimation: a light point seen from `p`, with numbers
    /// consumed as `u_sel` (light choice) then `u` (position).
    #[inline(always)]
    pub fn sample_direct(
        &self,
        geometry: &Geometry,
        p: Vec3,
        u_sel: f32,
        u: (f32, f32),
    ) -> Option<DirectSample> {
        let (i, pmf) = self.select(u_sel)?;
        let light = &self.lights[i as usize];
        // Fast path for the common emitter, a mesh without vertex normals:
        // no shape look-up, the triangle's data cached.
        if let Light::Area {
            radiance,
            area,
            tri_cdf,
            flat_tris,
            ..
        } = light
            && !flat_tris.is_empty()
        {
            let (t, (b0, b1, b2)) = pick_triangle(tri_cdf, u);
            let lp = flat_tris[t].point(b0, b1, b2);
            return area_direct(lp, 1.0 / area, pmf, *radiance, p);
        }
        self.sample_direct_other(geometry, light, pmf, p, u)
    }

    /// [`Lights::sample_direct`] for all but flat mesh emitters.
    #[inline(never)]
    fn sample_direct_other(
        &self,
        geometry: &Geometry,
        light: &Light,
        pmf: f32,
        p: Vec3,
        u: (f32, f32),
    ) -> Option<DirectSample> {
        match light {
            Light::Point {
                position,
                intensity,
                spot,
            } => {
                let delta = *position - p;
                let dist2 = delta.length_squared();
                if !(dist2 > 0.0) {
                    return None;
                }
                let dist = dist2.sqrt();
                let wi = delta / dist;
                let falloff = spot.map_or(1.0, |s| s.falloff(-wi));
                Some(DirectSample {
                    p: SurfacePoint {
                        p: *position,
                        p_err: Vec3::ZERO,
                        ng: -wi,
                        ns: -wi,
                        uv: Vec2::ZERO,
                        shape: u32::MAX,
                        prim: crate::geometry::NO_PRIM,
                    },
                    wi,
                    dist,
                    le: *intensity * (falloff / dist2),
                    pdf: pmf,
                    is_delta: true,
                    at_infinity: false,
                })
            }
            Light::Directional {
                direction,
                irradiance,
            } => {
                let wi = -*direction;
                Some(DirectSample {
                    p: self.far_point(p, wi),
                    wi,
                    dist: f32::INFINITY,
                    le: *irradiance,
                    pdf: pmf,
                    is_delta: true,
                    at_infinity: true,
                })
            }
            Light::Environment(env) => {
                let (wi, le, pdf) = env.sample(u)?;
                Some(DirectSample {
                    p: self.far_point(p, wi),
                    wi,
                    dist: f32::INFINITY,
                    le,
                    pdf: pmf * pdf,
                    is_delta: false,
                    at_infinity: true,
                })
            }
            Light::Area {
                radiance,
                shape,
                sphere,
                ..
            } => {
                if let Some((center, radius)) = sphere
                    && let Some(ds) = self.sample_sphere_cone(
                        geometry, *shape, *center, *radius, *radiance, pmf, p, u,
                    )
                {
                    return ds;
                }
                let (lp, pdf_area) = self.sample_area_point(geometry, light, u)?;
                area_direct(lp, pdf_area, pmf, *radiance, p)
            }
        }
    }

    /// Solid-angle density with which [`Lights::sample_direct`] from `p`
    /// produces the point `lp` of area light `i` (0 for the back side).
    pub fn pdf_direct(&self, i: u32, p: Vec3, lp: &SurfacePoint) -> f32 {
        let Light::Area { area, .. } = &self.lights[i as usize] else {
            return 0.0;
        };
        if let Light::Area {
            sphere: Some((center, radius)),
            ..
        } = &self.lights[i as usize]
            && let Some(cone) = Lights::sphere_cone_of(*center, *radius, p)
        {
            return self.pmf[i as usize] * cone.pdf;
        }
        let delta = lp.p - p;
        let dist2 = delta.length_squared();
        let cos_l = lp.ns.dot(-delta) / dist2.sqrt();
        if cos_l <= 0.0 || !(dist2 > 0.0) {
            return 0.0;
        }
        self.pmf[i as usize] * dist2 / (cos_l * area)
    }

    /// The cone of directions a sphere light subtends from `p`, when `p`
    /// is clearly outside it (inside, sampling falls back to area).
    fn sphere_cone_of(center: Vec3, radius: f32, p: Vec3) -> Option<SphereCone> {
        let to_c = (center.as_dvec3() - p.as_dvec3()).as_vec3();
        let dc2 = to_c.length_squared();
        let r2 = radius * radius;
        if !(dc2 > r2 * 1.0001) {
            return None;
        }
        let sin2_max = r2 / dc2;
        // 1 − cos θmax loses precision for tiny cones; use its series.
        let one_minus_cos = if sin2_max < 1e-3 {
            sin2_max / 2.0 + sin2_max * sin2_max / 8.0
        } else {
            1.0 - (1.0 - sin2_max).max(0.0).sqrt()
        };
        let pdf = 1.0 / (2.0 * PI * one_minus_cos);
        (pdf.is_finite() && pdf > 0.0).then_some(SphereCone {
            axis: to_c / dc2.sqrt(),
            sin2_max,
            one_minus_cos,
            pdf,
        })
    }

    /// Inverse of the cone sampling of [`Lights::sample_direct`] towards a
    /// sphere light (centre, radius) from `p` (spec seed001 §2.3): the
    /// numbers `u` that sample the sphere's point `lp`. `None` when `p` is
    /// not clearly outside the sphere (next-event estimation samples by
    /// area there); `Some(None)` when `lp` is not on the cap the cone
    /// sampling reaches (the side facing `p`). The forward map is one to
    /// one on that cap: `u₀` from the angle to the cone's axis (uniform in
    /// `cos θ`, or in `sin² θ` for tiny cones, as the forward branches), `u₁`
    /// from the azimuth of the point's normal in the forward's frame.
    pub fn sphere_cone_to_square(
        center: Vec3,
        radius: f32,
        p: Vec3,
        lp: Vec3,
    ) -> Option<Option<(f32, f32)>> {
        let cone = Lights::sphere_cone_of(center, radius, p)?;
        let d = (lp.as_dvec3() - p.as_dvec3()).normalize_or_zero();
        let axis = cone.axis.as_dvec3();
        let n = (lp - center) / radius;
        // The far side is never sampled (and faces away from `p`).
        if !(n.as_dvec3().dot(-d) > 0.0) {
            return Some(None);
        }
        let cos_t = d.dot(axis);
        // sin² θ from the cross product keeps its digits for small angles.
        let sin2 = d.cross(axis).length_squared();
        let (sin2_max, one_minus_cos) = (f64::from(cone.sin2_max), f64::from(cone.one_minus_cos));
        let u0 = if cone.sin2_max < 1e-3 {
            sin2 / sin2_max
        } else {
            // 1 − cos θ = sin² θ / (1 + cos θ), without cancellation.
            sin2 / ((1.0 + cos_t) * one_minus_cos)
        };
        // The silhouette (u₀ → 1) comes back a rounding error beyond it.
        if !(cos_t > 0.0 && u0 <= 1.0 + 1e-4) {
            return Some(None);
        }
        let local = Frame::from_normal(-cone.axis).to_local(n);
        let u1 = crate::inverse::angle_to_unit(f64::from(local.y).atan2(f64::from(local.x)));
        Some(Some((crate::sampling::to_unit_f32(u0.clamp(0.0, 1.0)), u1)))
    }

    /// Next-event estimation towards a sphere light by uniform sampling of
    /// the cone it subtends (pbrt-v4's method): `None` when `p` is inside
    /// (the caller then samples by area). The inner `Option` is the sample.
    #[allow(clippy::too_many_arguments)]
    fn sample_sphere_cone(
        &self,
        geometry: &Geometry,
        shape: u32,
        center: Vec3,
        radius: f32,
        radiance: Rgb,
        pmf: f32,
        p: Vec3,
        u: (f32, f32),
    ) -> Option<Option<DirectSample>> {
        let cone = Lights::sphere_cone_of(center, radius, p)?;
        // Uniform in cos θ over [cos θmax, 1].
        let (sin2, cos_t) = if cone.sin2_max < 1e-3 {
            let s2 = cone.sin2_max * u.0;
            (s2, (1.0 - s2).max(0.0).sqrt())
        } else {
            let c = 1.0 - u.0 * cone.one_minus_cos;
            (1.0 - c * c, c)
        };
        // Angle at the centre between −axis and the sampled surface point.
        let sin_max = cone.sin2_max.sqrt();
        let cos_alpha = sin2 / sin_max + cos_t * (1.0 - sin2 / cone.sin2_max).max(0.0).sqrt();
        let sin_alpha = (1.0 - cos_alpha * cos_alpha).max(0.0).sqrt();
        let phi = 2.0 * PI * u.1;
        let frame = Frame::from_normal(-cone.axis);
        let n = frame.to_world(Vec3::new(
            sin_alpha * phi.cos(),
            sin_alpha * phi.sin(),
            cos_alpha,
        ));
        let lp = geometry.sphere_point(shape, center + n * radius);
        let delta = lp.p - p;
        let dist = delta.length();
        if !(dist > 0.0) {
            return Some(None);
        }
        let wi = delta / dist;
        if lp.ns.dot(-wi) <= 0.0 {
            return Some(None);
        }
        Some(Some(DirectSample {
            p: lp,
            wi,
            dist,
            le: radiance,
            pdf: pmf * cone.pdf,
            is_delta: false,
            at_infinity: false,
        }))
    }

    /// Radiance of area light `i` leaving `sp` towards unit `w`.
    pub fn area_radiance(&self, i: u32, sp: &SurfacePoint, w: Vec3) -> Rgb {
        match &self.lights[i as usize] {
            Light::Area { radiance, .. } if sp.ns.dot(w) > 0.0 => *radiance,
            _ => Rgb::BLACK,
        }
    }

    /// Starts a light path: numbers consumed as `u_sel`, `u_pos`, `u_dir`.
    pub fn sample_emission(
        &self,
        geometry: &Geometry,
        u_sel: f32,
        u_pos: (f32, f32),
        u_dir: (f32, f32),
    ) -> Option<EmissionSample> {
        let (i, pmf) = self.select(u_sel)?;
        let light = &self.lights[i as usize];
        match light {
            Light::Point {
                position,
                intensity,
                spot,
            } => {
                let (dir, pdf_dir) = match spot {
                    Some(s) => s.sample(u_dir),
                    None => (warp::uniform_sphere(u_dir), 1.0 / (4.0 * PI)),
                };
                let le = *intensity * spot.map_or(1.0, |s| s.falloff(dir));
                Some(EmissionSample {
                    p: SurfacePoint {
                        p: *position,
                        p_err: Vec3::ZERO,
                        ng: dir,
                        ns: dir,
                        uv: Vec2::ZERO,
                        shape: u32::MAX,
                        prim: crate::geometry::NO_PRIM,
                    },
                    dir,
                    weight: le / (pmf * pdf_dir),
                    le,
                    is_delta: true,
                    pdf_pos: pmf,
                    pdf_dir,
                    at_infinity: false,
                })
            }
            Light::Directional {
                direction,
                irradiance,
            } => self.emission_at_infinity(*direction, *irradiance, pmf, 1.0, u_pos),
            Light::Environment(env) => {
                let (w, le, pdf) = env.sample(u_dir)?;
                self.emission_at_infinity(-w, le, pmf, pdf, u_pos)
            }
            Light::Area { radiance, area, .. } => {
                let (lp, _) = self.sample_area_point(geometry, light, u_pos)?;
                let local = warp::cosine_hemisphere(u_dir);
                if local.z <= 0.0 {
                    return None;
                }
                let dir = Frame::from_normal(lp.ns).to_world(local);
                // Le·cos / (pmf · (1/A) · cos/π) = Le·π·A / pmf.
                Some(EmissionSample {
                    p: lp,
                    dir,
                    weight: *radiance * (PI * area / pmf),
                    le: *radiance,
                    is_delta: false,
                    pdf_pos: pmf / area,
                    pdf_dir: local.z * std::f32::consts::FRAC_1_PI,
                    at_infinity: false,
                })
            }
        }
    }

    /// A light path entering the scene along `dir` from an emitter at
    /// infinity (radiance or irradiance `le`, direction density `pdf_dir`):
    /// its origin is uniform on the disk of radius `R` perpendicular to
    /// `dir`, `R` before the scene's centre.
    fn emission_at_infinity(
        &self,
        dir: Vec3,
        le: Rgb,
        pmf: f32,
        pdf_dir: f32,
        u_pos: (f32, f32),
    ) -> Option<EmissionSample> {
        let p = self.infinite_origin(dir, u_pos);
        let pdf_pos = pmf * self.infinite_disk_pdf();
        if !(pdf_pos > 0.0 && pdf_dir > 0.0) {
            return None;
        }
        Some(EmissionSample {
            p: SurfacePoint {
                p,
                p_err: Vec3::ZERO,
                ng: dir,
                ns: dir,
                uv: Vec2::ZERO,
                shape: u32::MAX,
                prim: crate::geometry::NO_PRIM,
            },
            dir,
            weight: le / (pdf_pos * pdf_dir),
            le,
            is_delta: false,
            pdf_pos,
            pdf_dir,
            at_infinity: true,
        })
    }
}
