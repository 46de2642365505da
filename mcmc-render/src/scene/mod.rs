//! Scenes: loading the Mitsuba 3 XML subset ([`xml`], [`loader`], [`mesh`],
//! [`serialized`])
//! into a [`SceneDesc`], and building the runtime [`Scene`] (BVH, BSDFs,
//! lights, camera) from it.

pub mod loader;
pub mod mesh;
pub mod named;
mod obj_indices;
pub mod serialized;
pub mod upgrade;
pub mod xml;

use crate::bsdf::textured::{BsdfAt, BsdfTextures};
use crate::bsdf::wrapped::{Wrap, Wrappers};
use crate::bsdf::{Bsdf, BsdfDesc};
use crate::camera::Camera;
use crate::color::Rgb;
use crate::frame::Frame;
use crate::geometry::{GeoShape, Geometry, Hit, MeshData, Ray, Surface, SurfacePoint};
use crate::light::{DirectSample, Lights};
use glam::{Mat3, Mat4, Vec3};
use std::collections::HashMap;
use std::path::Path;

/// Why a scene could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// A problem at a known place in a scene file.
    #[error("{location}: {message}")]
    At {
        /// `file:line`.
        location: String,
        /// What is wrong.
        message: String,
    },
    /// A file could not be read.
    #[error("cannot read {path}: {message}")]
    Io {
        /// The file.
        path: String,
        /// The system's reason.
        message: String,
    },
    /// A problem with the scene as a whole.
    #[error("{0}")]
    Invalid(String),
}

/// Which image axis `fov` spans (Mitsuba's `fov_axis`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FovAxis {
    /// Horizontal (default).
    X,
    /// Vertical.
    Y,
    /// Diagonal.
    Diagonal,
    /// The smaller of the two image dimensions.
    Smaller,
    /// The larger of the two image dimensions.
    Larger,
}

/// The perspective sensor's parameters.
#[derive(Clone, Debug)]
pub struct CameraDesc {
    /// Camera to world (looks down local +z, +y up).
    pub to_world: Mat4,
    /// Field of view in degrees.
    pub fov_deg: f32,
    /// Axis the field of view spans.
    pub fov_axis: FovAxis,
    /// Near clipping distance.
    pub near_clip: f32,
    /// Far clipping distance.
    pub far_clip: f32,
    /// Lens radius (`thinlens`'s `aperture_radius`; 0 for `perspective`).
    pub aperture_radius: f32,
    /// Distance of the plane in focus (`thinlens`; Mitsuba's default: `far_clip`).
    pub focus_distance: f32,
}

impl Default for CameraDesc {
    fn default() -> Self {
        CameraDesc {
            to_world: Mat4::IDENTITY,
            fov_deg: 39.597_755,
            fov_axis: FovAxis::X,
            near_clip: 0.01,
            far_clip: 10000.0,
            aperture_radius: 0.0,
            focus_distance: 10000.0,
        }
    }
}

/// Reconstruction filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FilterKind {
    /// Box of radius 0.5 pixel.
    Box,
    /// Windowed Gaussian cut at 4 standard deviations (Mitsuba's default, stddev 0.5).
    Gaussian {
        /// Standard deviation in pixels.
        stddev: f32,
    },
    /// Mitsuba's `tent`: `max(0, 1 − |x|/radius)` per axis.
    Tent {
        /// Radius in pixels (Mitsuba's default 1).
        radius: f32,
    },
}

/// The film's parameters.
#[derive(Clone, Debug)]
pub struct FilmDesc {
    /// Width of the image (the crop window) in pixels.
    pub width: u32,
    /// Height of the image (the crop window) in pixels.
    pub height: u32,
    /// Width of the full film (what the field of view spans).
    pub full_width: u32,
    /// Height of the full film.
    pub full_height: u32,
    /// Offset of the crop window in the full film, in pixels.
    pub crop_offset: (u32, u32),
    /// Reconstruction filter.
    pub filter: FilterKind,
}

impl Default for FilmDesc {
    fn default() -> Self {
        FilmDesc {
            width: 768,
            height: 576,
            full_width: 768,
            full_height: 576,
            crop_offset: (0, 0),
            filter: FilterKind::Gaussian { stddev: 0.5 },
        }
    }
}

/// Path-integrator settings in Mitsuba's semantics.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IntegratorDesc {
    /// Longest path in segments (`u32::MAX` = unbounded; 1 = emitters
    /// seen directly; 2 = direct lighting).
    pub max_depth: u32,
    /// Depth from which Russian roulette applies.
    pub rr_depth: u32,
}

impl Default for IntegratorDesc {
    fn default() -> Self {
        IntegratorDesc {
            max_depth: u32::MAX,
            rr_depth: 5,
        }
    }
}

/// The scene file's `<integrator>` element as written: the registry
/// ([`crate::integrators::registry`]) turns it into settings.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct IntegratorElement {
    /// The `type` attribute (a registered name or alias).
    pub kind: String,
    /// Parameters in file order, as text.
    pub params: Vec<(String, String)>,
    /// Where it was written (`file:line`).
    pub loc: String,
}

/// A point light.
#[derive(Clone, Debug)]
pub struct PointLightDesc {
    /// World position.
    pub position: Vec3,
    /// Radiant intensity (W/sr per channel; on the axis for a spot light).
    pub intensity: Rgb,
    /// The `spot` profile, for a spot light.
    pub spot: Option<crate::light::SpotProfile>,
}

/// An emitter at infinity, as a scene file describes it.
#[derive(Clone, Debug)]
pub enum InfiniteLightDesc {
    /// `directional`: parallel light.
    Directional {
        /// Unit world direction the light travels in.
        direction: Vec3,
        /// Irradiance on a surface facing the light.
        irradiance: Rgb,
    },
    /// `envmap` or `constant`.
    Environment(Box<crate::environment::Environment>),
}

/// The geometry of a shape in world space.
#[derive(Clone, Debug)]
pub enum ShapeGeometry {
    /// Triangle mesh (obj, ply, rectangle, cube).
    Mesh(mesh::TriMesh),
    /// Analytic sphere.
    Sphere {
        /// Centre.
        center: Vec3,
        /// Radius.
        radius: f32,
        /// Object-to-world rotation (for the UV mapping).
        frame: Mat3,
    },
    /// Unit disk in z = 0 mapped by `to_world`.
    Disk {
        /// Object to world.
        to_world: Mat4,
    },
}

/// A shape with its material and optional area emission.
#[derive(Clone, Debug)]
pub struct ShapeDesc {
    /// Mitsuba plugin name (`obj`, `sphere`, …).
    pub kind: String,
    /// World-space geometry.
    pub geometry: ShapeGeometry,
    /// Index into [`SceneDesc::bsdfs`].
    pub bsdf: usize,
    /// Area-emitter radiance, if the shape emits.
    pub emission: Option<Rgb>,
    /// Mitsuba's `flip_normals`.
    pub flip_normals: bool,
    /// `file:line` of the shape element.
    pub location: String,
}

/// Everything a scene file describes, with Mitsuba's defaults filled in.
#[derive(Clone, Debug, Default)]
pub struct SceneDesc {
    /// Shapes.
    pub shapes: Vec<ShapeDesc>,
    /// BSDFs (shapes refer to them by index); a textured parameter holds
    /// its texture's mean.
    pub bsdfs: Vec<BsdfDesc>,
    /// The textured parameters of each BSDF, indexed like `bsdfs`.
    pub bsdf_textures: Vec<BsdfTextures>,
    /// The `normalmap`, `bumpmap` and `mask` around each BSDF, indexed
    /// like `bsdfs`.
    pub bsdf_wrappers: Vec<Wrappers>,
    /// Point lights.
    pub point_lights: Vec<PointLightDesc>,
    /// Emitters at infinity (at most one environment).
    pub infinite_lights: Vec<InfiniteLightDesc>,
    /// Camera.
    pub camera: CameraDesc,
    /// Film.
    pub film: FilmDesc,
    /// Integrator settings.
    pub integrator: IntegratorDesc,
    /// The `<integrator>` element, if the file has one.
    pub integrator_element: Option<IntegratorElement>,
    /// Samples per pixel (`independent` sampler's `sample_count`, default 4).
    pub sample_count: u32,
}

/// Per-shape runtime data.
#[derive(Clone, Debug)]
pub struct ShapeInfo {
    /// Index into [`Scene::bsdfs`].
    pub bsdf: u32,
    /// Index into the lights, when the shape emits.
    pub light: Option<u32>,
    /// Plugin name, for `info`.
    pub kind: String,
}

/// A scene ready to render.
pub struct Scene {
    /// Geometry and BVH.
    pub geometry: Geometry,
    /// Per-shape data, indexed like [`Geometry::shapes`].
    pub shapes: Vec<ShapeInfo>,
    /// Runtime BSDFs (textured parameters hold the texture's mean; shading
    /// uses [`Scene::bsdf_at`]).
    pub bsdfs: Vec<Bsdf>,
    /// The textured parameters of each BSDF, indexed like `bsdfs`; empty
    /// when no BSDF of the scene is textured.
    textures: Vec<BsdfTextures>,
    /// The `normalmap`, `bumpmap` and `mask` around each BSDF, indexed
    /// like `bsdfs`; empty when the scene has none.
    wrappers: Vec<Wrappers>,
    /// True when some BSDF is a `mask`.
    has_masks: bool,
    /// Per BSDF (indexed like `bsdfs`; empty when none is anisotropic):
    /// true when its shading frame must follow ∂p/∂u, as Mitsuba 3's does,
    /// because its roughness is (or may be, textured) anisotropic.
    tangent_framed: Vec<bool>,
    /// Parsed BSDFs, for reporting.
    pub bsdf_descs: Vec<BsdfDesc>,
    /// Emitters and the light-selection distribution.
    pub lights: Lights,
    /// The camera.
    pub camera: Camera,
    /// Film settings.
    pub film: FilmDesc,
    /// The path depth settings of the file's `<integrator>` element.
    pub integrator: IntegratorDesc,
    /// The `<integrator>` element, if the file has one.
    pub integrator_element: Option<IntegratorElement>,
    /// Samples per pixel the file asks for.
    pub sample_count: u32,
    /// Zero-area triangles dropped while loading.
    pub dropped_degenerate: usize,
}

/// A surface hit with everything shading needs.
#[derive(Clone, Copy, Debug)]
pub struct Interaction {
    /// The point and its normals.
    pub sp: SurfacePoint,
    /// Distance from the ray origin.
    pub t: f32,
}

impl Scene {
    /// Loads a scene file. `defines` override `<default>` values.
    pub fn load(path: &Path, defines: &HashMap<String, String>) -> Result<Scene, SceneError> {
        let tree = xml::parse_file(path, defines)?;
        let base = path.parent().unwrap_or_else(|| Path::new("."));
        let desc = loader::Loader::new(base).load(&tree, &path.display().to_string())?;
        Scene::build(desc)
    }

    /// Loads a scene from XML text; relative mesh paths resolve against `base_dir`.
    pub fn load_str(text: &str, name: &Path, base_dir: &Path) -> Result<Scene, SceneError> {
        let tree = xml::parse_str(text, name)?;
        let desc = loader::Loader::new(base_dir).load(&tree, &name.display().to_string())?;
        Scene::build(desc)
    }

    /// Builds the runtime scene (BSDFs, BVH, lights, camera).
    pub fn build(desc: SceneDesc) -> Result<Scene, SceneError> {
        let mut bsdfs = Vec::with_capacity(desc.bsdfs.len());
        for (i, d) in desc.bsdfs.iter().enumerate() {
            let b = Bsdf::from_desc(d).map_err(SceneError::Invalid)?;
            if let Some(t) = desc.bsdf_textures.get(i) {
                t.check(&b).map_err(SceneError::Invalid)?;
            }
            bsdfs.push(b);
        }
        let tangent_framed: Vec<bool> = bsdfs
            .iter()
            .enumerate()
            .map(|(i, b)| {
                b.is_anisotropic()
                    || desc
                        .bsdf_textures
                        .get(i)
                        .is_some_and(BsdfTextures::may_be_anisotropic)
            })
            .collect();
        let tangent_framed = if tangent_framed.contains(&true) {
            tangent_framed
        } else {
            Vec::new()
        };
        let textures = if desc.bsdf_textures.iter().all(BsdfTextures::is_empty) {
            Vec::new()
        } else {
            desc.bsdf_textures
        };
        let wrappers = if desc.bsdf_wrappers.iter().all(Wrappers::is_empty) {
            Vec::new()
        } else {
            desc.bsdf_wrappers
        };
        let no_geometry = desc.shapes.is_empty()
            && desc.point_lights.is_empty()
            && desc.infinite_lights.is_empty();
        let mut geo_shapes = Vec::with_capacity(desc.shapes.len());
        let mut shapes = Vec::with_capacity(desc.shapes.len());
        let mut emitters = Vec::new();
        let mut dropped = 0;
        // Meshes are moved, not copied: a million-triangle mesh is large.
        for (i, s) in desc.shapes.into_iter().enumerate() {
            let surface = match s.geometry {
                ShapeGeometry::Mesh(m) => {
                    dropped += m.dropped_degenerate;
                    Surface::Mesh(MeshData {
                        positions: m.positions,
                        normals: m.normals,
                        uvs: m.uvs,
                        indices: m.indices,
                    })
                }
                ShapeGeometry::Sphere {
                    center,
                    radius,
                    frame,
                } => Surface::Sphere {
                    center,
                    radius,
                    frame,
                },
                ShapeGeometry::Disk { to_world } => {
                    let normal = (Mat3::from_mat4(to_world).inverse().transpose() * Vec3::Z)
                        .try_normalize()
                        .ok_or_else(|| {
                            SceneError::Invalid(format!(
                                "{}: degenerate disk transform",
                                s.location
                            ))
                        })?;
                    Surface::Disk {
                        to_world,
                        to_local: to_world.inverse(),
                        normal,
                    }
                }
            };
            let light = s.emission.map(|radiance| {
                emitters.push((i as u32, radiance));
                (emitters.len() - 1) as u32
            });
            geo_shapes.push(GeoShape {
                surface,
                flip_normals: s.flip_normals,
            });
            shapes.push(ShapeInfo {
                bsdf: s.bsdf as u32,
                light,
                kind: s.kind,
            });
        }
        if no_geometry {
            return Err(SceneError::Invalid(
                "the scene has no shapes and no lights".into(),
            ));
        }
        let geometry = Geometry::build(geo_shapes);
        let lights = Lights::new(
            &geometry,
            &emitters,
            &desc.point_lights,
            &desc.infinite_lights,
        );
        let camera = Camera::new(&desc.camera, &desc.film).map_err(SceneError::Invalid)?;
        Ok(Scene {
            geometry,
            shapes,
            bsdfs,
            textures,
            has_masks: wrappers.iter().any(|w| w.opacity.is_some()),
            tangent_framed,
            wrappers,
            bsdf_descs: desc.bsdfs,
            lights,
            camera,
            film: desc.film,
            integrator: desc.integrator,
            integrator_element: desc.integrator_element,
            sample_count: desc.sample_count.max(1),
            dropped_degenerate: dropped,
        })
    }

    /// Closest surface hit along `ray`.
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray) -> Option<Interaction> {
        let hit: Hit = self.geometry.intersect(ray)?;
        Some(Interaction {
            sp: self.geometry.surface_point(ray, &hit),
            t: hit.t,
        })
    }

    /// The shading frame at a surface point, in which every integrator
    /// evaluates, samples and inverts [`Scene::bsdf_at`]: +z the shading
    /// normal. Isotropic BSDFs do not depend on the tangent, so they get
    /// the cheap [`Frame::from_normal`]; anisotropic ones get Mitsuba 3's
    /// frame, whose tangent is ∂p/∂u ([`Frame::from_normal_and_tangent`]),
    /// so `alpha_u` lies along the texture's u axis as in Mitsuba.
    #[inline(always)]
    pub fn shading_frame(&self, sp: &SurfacePoint) -> Frame {
        // Scenes without anisotropic BSDFs (most) skip the shape lookup.
        if !self.tangent_framed.is_empty()
            && self.tangent_framed[self.shapes[sp.shape as usize].bsdf as usize]
        {
            self.tangent_frame(sp)
        } else {
            Frame::from_normal(sp.ns)
        }
    }

    /// Mitsuba 3's shading frame at `sp` (kept out of the hot path).
    #[inline(never)]
    fn tangent_frame(&self, sp: &SurfacePoint) -> Frame {
        Frame::from_normal_and_tangent(sp.ns, self.geometry.tangents(sp).0)
    }

    /// The BSDF at a surface point, with its textured parameters (if any)
    /// evaluated at the point's UV and, under `normalmap` or `bumpmap`,
    /// the perturbed frame at the point (relative to the shading frame
    /// [`Scene::shading_frame`] the integrators use).
    #[inline(always)]
    pub fn bsdf_at(&self, sp: &SurfacePoint) -> BsdfAt<'_> {
        self.bsdf_at_in(&self.bsdfs, sp)
    }

    /// True when some surface can scatter through a Dirac lobe: a smooth
    /// conductor or dielectric, a smooth `plastic`'s coating, or a `mask`'s
    /// pass-through. Without one, every path of two or more segments has an
    /// edge between two non-Dirac vertices, so a connection can make it.
    pub fn has_dirac_lobes(&self) -> bool {
        self.has_masks || self.bsdfs.iter().any(Bsdf::has_delta_lobe)
    }

    /// The index into [`Scene::bsdfs`] of the BSDF at a surface point.
    #[inline(always)]
    pub fn bsdf_index(&self, sp: &SurfacePoint) -> usize {
        self.shapes[sp.shape as usize].bsdf as usize
    }

    /// [`Scene::bsdf_at`] with `bsdfs` (indexed like [`Scene::bsdfs`],
    /// e.g. roughened copies of them) in place of the scene's BSDFs; the
    /// textures and wrappers are the scene's.
    #[inline(always)]
    pub fn bsdf_at_in<'a>(&self, bsdfs: &'a [Bsdf], sp: &SurfacePoint) -> BsdfAt<'a> {
        let i = self.bsdf_index(sp);
        let bsdf = &bsdfs[i];
        let model = match self.textures.get(i) {
            Some(t) if !t.is_empty() => t.apply(bsdf, sp.uv),
            _ => match self.wrappers.get(i) {
                Some(w) if !w.is_empty() => return BsdfAt::Wrapped(*bsdf, self.wrap(w, sp)),
                _ => return BsdfAt::Shared(bsdf),
            },
        };
        match self.wrappers.get(i) {
            Some(w) if !w.is_empty() => BsdfAt::Wrapped(model, self.wrap(w, sp)),
            _ => BsdfAt::Textured(model),
        }
    }

    /// What the wrappers `w` make of `sp` (kept out of the hot path).
    #[inline(never)]
    fn wrap(&self, w: &Wrappers, sp: &SurfacePoint) -> Wrap {
        let perturbed = w.perturbation.as_ref().map(|p| {
            let n = p.normal(sp.ns, sp.ng, sp.uv, self.geometry.tangents(sp));
            p.at(&self.shading_frame(sp), n)
        });
        let opacity = w
            .opacity
            .as_ref()
            .map_or(1.0, |t| t.eval_1(sp.uv).clamp(0.0, 1.0));
        Wrap { perturbed, opacity }
    }

    /// The segment from `from` towards `to` (a point, or with `to = None`
    /// the ray along the unit `d` to infinity) as light tracing connects
    /// a vertex to the camera: `None` when a surface blocks it, else the
    /// product of `1 − opacity` over the `mask` surfaces it crosses and
    /// their count. Each crossing is the null lobe of a path vertex that
    /// pure light tracing cannot sample (the camera is a point), so
    /// connecting through it with this weight is that path's estimate;
    /// it adds the crossings to the path's depth. (BDPT and path tracing
    /// sample those vertices and keep masks opaque to shadow rays, as
    /// Mitsuba 3 does.)
    pub fn camera_connection(&self, from: Vec3, to: Option<Vec3>, d: Vec3) -> Option<(f32, u32)> {
        let segment = |o: Vec3| -> Option<Ray> {
            match to {
                None => Some(Ray::new(o, d)),
                Some(t) => {
                    let delta = t - o;
                    let dist = delta.length();
                    if !(dist > 0.0) || !dist.is_finite() {
                        return None;
                    }
                    let mut r = Ray::new(o, delta / dist);
                    r.tmax = dist * (1.0 - 1e-4);
                    Some(r)
                }
            }
        };
        let Some(mut ray) = segment(from) else {
            return (to == Some(from)).then_some((1.0, 0));
        };
        if !self.has_masks {
            return (!self.geometry.occluded(&ray)).then_some((1.0, 0));
        }
        let (mut t, mut crossings) = (1.0f32, 0u32);
        while let Some(its) = self.intersect(&ray) {
            let i = self.shapes[its.sp.shape as usize].bsdf as usize;
            let opacity = self.wrappers.get(i).and_then(|w| w.opacity.as_ref())?;
            t *= 1.0 - opacity.eval_1(its.sp.uv).clamp(0.0, 1.0);
            crossings += 1;
            if !(t > 0.0) {
                return None;
            }
            ray = segment(its.sp.spawn_ray(ray.d).o)?;
        }
        Some((t, crossings))
    }

    /// True when nothing blocks the light sample `ds` from `sp` (for an
    /// emitter at infinity: when the ray towards it leaves the scene).
    #[inline(always)]
    pub fn light_visible(&self, sp: &SurfacePoint, ds: &DirectSample) -> bool {
        if ds.at_infinity {
            !self.geometry.occluded(&sp.spawn_ray(ds.wi))
        } else {
            self.geometry.visible(sp, &ds.p)
        }
    }

    /// Radiance emitted from a surface point towards `w` (unit, pointing away).
    pub fn emitted(&self, sp: &SurfacePoint, w: Vec3) -> Rgb {
        match self.shapes[sp.shape as usize].light {
            Some(l) => self.lights.area_radiance(l, sp, w),
            None => Rgb::BLACK,
        }
    }
}
