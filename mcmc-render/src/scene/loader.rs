//! Turns the plugin tree of [`super::xml`] into a [`SceneDesc`], applying
//! Mitsuba 3's defaults and refusing every plugin or parameter outside the
//! supported subset (with its file and line).

use super::mesh;
use super::named;
use super::serialized;
use super::xml::{Child, Loc, Param, Plugin, Value};
use super::{
    CameraDesc, FilmDesc, FilterKind, FovAxis, InfiniteLightDesc, IntegratorDesc,
    IntegratorElement, PointLightDesc, SceneDesc, SceneError, ShapeDesc, ShapeGeometry,
};
use crate::bsdf::microfacet::MIN_ALPHA;
use crate::bsdf::perturb::{PerturbKind, Perturbation};
use crate::bsdf::textured::{BsdfTextures, TexturedParam};
use crate::bsdf::wrapped::Wrappers;
use crate::bsdf::{BsdfDesc, MicrofacetKind};
use crate::color::Rgb;
use crate::environment::{EnvRadiance, Environment, LatLong};
use crate::light::SpotProfile;
use crate::texture::{self, Bitmap, Checkerboard, FilterType, Texture, WrapMode};
use glam::{Mat3, Mat4, Vec3};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

fn err(loc: &Loc, msg: impl Into<String>) -> SceneError {
    SceneError::At {
        location: loc.to_string(),
        message: msg.into(),
    }
}

/// Typed access to a plugin's parameters; every parameter must be read
/// once, and [`Props::finish`] refuses the ones nobody asked for.
struct Props<'a> {
    plugin: &'a Plugin,
    used: Vec<bool>,
}

impl<'a> Props<'a> {
    fn new(plugin: &'a Plugin) -> Self {
        Props {
            plugin,
            used: vec![false; plugin.params.len()],
        }
    }

    fn what(&self) -> String {
        format!("<{} type=\"{}\">", self.plugin.tag, self.plugin.kind)
    }

    fn get(&mut self, name: &str) -> Option<&'a Param> {
        let i = self.plugin.params.iter().position(|p| p.name == name)?;
        self.used[i] = true;
        Some(&self.plugin.params[i])
    }

    fn type_err(&self, p: &Param, want: &str) -> SceneError {
        err(
            &p.loc,
            format!(
                "parameter '{}' of {} must be {want}, found <{}>",
                p.name,
                self.what(),
                p.value.tag()
            ),
        )
    }

    fn float(&mut self, name: &str, default: f32) -> Result<f32, SceneError> {
        Ok(self.opt_float(name)?.unwrap_or(default))
    }

    fn opt_float(&mut self, name: &str) -> Result<Option<f32>, SceneError> {
        match self.get(name) {
            None => Ok(None),
            Some(p) => match &p.value {
                Value::Float(v) => Ok(Some(*v)),
                Value::Integer(v) => Ok(Some(*v as f32)),
                _ => Err(self.type_err(p, "a <float>")),
            },
        }
    }

    fn int(&mut self, name: &str, default: i64) -> Result<i64, SceneError> {
        Ok(self.opt_int(name)?.unwrap_or(default))
    }

    fn opt_int(&mut self, name: &str) -> Result<Option<i64>, SceneError> {
        match self.get(name) {
            None => Ok(None),
            Some(p) => match &p.value {
                Value::Integer(v) => Ok(Some(*v)),
                _ => Err(self.type_err(p, "an <integer>")),
            },
        }
    }

    fn boolean(&mut self, name: &str, default: bool) -> Result<bool, SceneError> {
        match self.get(name) {
            None => Ok(default),
            Some(p) => match &p.value {
                Value::Boolean(v) => Ok(*v),
                _ => Err(self.type_err(p, "a <boolean>")),
            },
        }
    }

    fn opt_string(&mut self, name: &str) -> Result<Option<(String, Loc)>, SceneError> {
        match self.get(name) {
            None => Ok(None),
            Some(p) => match &p.value {
                Value::String(v) => Ok(Some((v.clone(), p.loc.clone()))),
                _ => Err(self.type_err(p, "a <string>")),
            },
        }
    }

    /// An `<rgb>` or a `<float>` (broadcast to grey), as Mitsuba allows.
    /// Every colour the loader reads is a physical quantity (a
    /// reflectance, transmittance, radiance or a conductor's η and k), so
    /// a negative or non-finite one is refused here, at its line.
    fn opt_rgb(&mut self, name: &str) -> Result<Option<Rgb>, SceneError> {
        let Some(p) = self.get(name) else {
            return Ok(None);
        };
        let v = match &p.value {
            Value::Rgb(v) => *v,
            Value::Float(v) => Rgb::splat(*v),
            Value::Integer(v) => Rgb::splat(*v as f32),
            _ => return Err(self.type_err(p, "an <rgb> or a <float>")),
        };
        if !v.to_array().iter().all(|c| c.is_finite() && *c >= 0.0) {
            return Err(err(
                &p.loc,
                format!(
                    "'{name}' must be finite and non-negative, got {:?}",
                    v.to_array()
                ),
            ));
        }
        Ok(Some(v))
    }

    fn rgb(&mut self, name: &str, default: Rgb) -> Result<Rgb, SceneError> {
        Ok(self.opt_rgb(name)?.unwrap_or(default))
    }

    fn point(&mut self, name: &str, default: Vec3) -> Result<Vec3, SceneError> {
        match self.get(name) {
            None => Ok(default),
            Some(p) => match &p.value {
                Value::Point(v) | Value::Vector(v) => Ok(*v),
                _ => Err(self.type_err(p, "a <point>")),
            },
        }
    }

    fn transform(&mut self, name: &str) -> Result<Mat4, SceneError> {
        match self.get(name) {
            None => Ok(Mat4::IDENTITY),
            Some(p) => match &p.value {
                Value::Transform(m) => {
                    if m.is_finite() && m.determinant() != 0.0 {
                        Ok(*m)
                    } else {
                        Err(err(&p.loc, "the transform is singular or not finite"))
                    }
                }
                _ => Err(self.type_err(p, "a <transform>")),
            },
        }
    }

    /// An index of refraction given as a number or a Mitsuba material name.
    fn ior(&mut self, name: &str, default: f32) -> Result<f32, SceneError> {
        match self.get(name) {
            None => Ok(default),
            Some(p) => match &p.value {
                Value::Float(v) => Ok(*v),
                Value::Integer(v) => Ok(*v as f32),
                Value::String(s) => named::ior(s).ok_or_else(|| {
                    err(&p.loc, format!("unknown index-of-refraction name \"{s}\""))
                }),
                _ => Err(self.type_err(p, "a <float> or a <string>")),
            },
        }
    }

    fn finish(self) -> Result<(), SceneError> {
        for (p, used) in self.plugin.params.iter().zip(&self.used) {
            if !used {
                return Err(err(
                    &p.loc,
                    format!("unsupported parameter '{}' of {}", p.name, self.what()),
                ));
            }
        }
        Ok(())
    }
}

/// A BSDF as the loader reads it: the model, its textured parameters and
/// the `normalmap`, `bumpmap` or `mask` around it.
type LoadedBsdf = (BsdfDesc, BsdfTextures, Wrappers);

/// Loads everything the parsed tree describes.
pub struct Loader {
    /// Directory that relative mesh paths are resolved against.
    base_dir: PathBuf,
    desc: SceneDesc,
    named_bsdfs: HashMap<String, usize>,
    /// Scene-level `<texture id=…>`s, for `<ref id=… name=…>`.
    named_textures: HashMap<String, Texture>,
    /// Where each `id` was declared (Mitsuba refuses a duplicate).
    ids: HashMap<String, Loc>,
    saw_sensor: bool,
    saw_integrator: bool,
}

impl Loader {
    /// A loader resolving relative file names against `base_dir`.
    pub fn new(base_dir: &Path) -> Self {
        Loader {
            base_dir: base_dir.to_path_buf(),
            desc: SceneDesc {
                sample_count: 4,
                ..SceneDesc::default()
            },
            named_bsdfs: HashMap::new(),
            named_textures: HashMap::new(),
            ids: HashMap::new(),
            saw_sensor: false,
            saw_integrator: false,
        }
    }

    /// Processes the top-level children of `<scene>` and returns the description.
    pub fn load(mut self, children: &[Child], file_loc: &str) -> Result<SceneDesc, SceneError> {
        for child in children {
            match child {
                Child::Ref { loc, .. } => return Err(err(loc, "<ref> outside a plugin")),
                Child::Plugin(p) => self.top_level(p)?,
            }
        }
        if !self.saw_sensor {
            return Err(SceneError::Invalid(format!(
                "{file_loc}: the scene has no <sensor type=\"perspective\">"
            )));
        }
        Ok(self.desc)
    }

    fn top_level(&mut self, p: &Plugin) -> Result<(), SceneError> {
        match p.tag.as_str() {
            "shape" => self.shape(p),
            "bsdf" => {
                let desc = self.bsdf(p)?;
                let index = self.push_bsdf(desc);
                if let Some(id) = &p.id {
                    self.declare(id, &p.loc)?;
                    self.named_bsdfs.insert(id.clone(), index);
                }
                Ok(())
            }
            "texture" => {
                let id = p.id.as_ref().ok_or_else(|| {
                    err(
                        &p.loc,
                        "a scene-level <texture> needs an 'id' (to be referenced with <ref id=\"…\" name=\"…\"/>)",
                    )
                })?;
                let texture = self.texture(p)?;
                self.declare(id, &p.loc)?;
                self.named_textures.insert(id.clone(), texture);
                Ok(())
            }
            "emitter" => match p.kind.as_str() {
                "point" => self.point_light(p),
                "spot" => self.spot_light(p),
                "directional" => self.directional_light(p),
                "envmap" | "constant" => self.environment(p),
                other => Err(err(
                    &p.loc,
                    format!(
                        "unsupported emitter \"{other}\" at scene level (supported: point, spot, directional, envmap, constant; area emitters go inside a <shape>)"
                    ),
                )),
            },
            "sensor" => {
                if self.saw_sensor {
                    return Err(err(&p.loc, "only one <sensor> is supported"));
                }
                self.saw_sensor = true;
                self.sensor(p)
            }
            "integrator" => {
                if self.saw_integrator {
                    return Err(err(&p.loc, "only one <integrator> is supported"));
                }
                self.saw_integrator = true;
                self.integrator(p)
            }
            other => Err(err(
                &p.loc,
                format!("<{other}> is not allowed at scene level"),
            )),
        }
    }

    /// Records that `id` is declared at `loc`; a second declaration of
    /// the same id is refused, as Mitsuba 3 refuses it.
    fn declare(&mut self, id: &str, loc: &Loc) -> Result<(), SceneError> {
        if let Some(first) = self.ids.get(id) {
            return Err(err(
                loc,
                format!("duplicate id \"{id}\" (first declared at {first})"),
            ));
        }
        self.ids.insert(id.to_string(), loc.clone());
        Ok(())
    }

    fn push_bsdf(&mut self, (desc, textures, wrappers): LoadedBsdf) -> usize {
        self.desc.bsdfs.push(desc);
        self.desc.bsdf_textures.push(textures);
        self.desc.bsdf_wrappers.push(wrappers);
        self.desc.bsdfs.len() - 1
    }

    /// Keeps the `<integrator>` element for the registry, which checks it
    /// here (an unknown type or parameter, or a bad value, fails the load
    /// at its line), and reads the path depth settings every integrator
    /// shares.
    fn integrator(&mut self, p: &Plugin) -> Result<(), SceneError> {
        no_children(p)?;
        let mut params = Vec::with_capacity(p.params.len());
        for param in &p.params {
            let text = match &param.value {
                // At full precision: integrator parameters are `f64`.
                Value::Float(v) => param.text.clone().unwrap_or_else(|| v.to_string()),
                Value::Integer(v) => v.to_string(),
                Value::Boolean(v) => v.to_string(),
                Value::String(v) => v.clone(),
                other => {
                    return Err(err(
                        &param.loc,
                        format!(
                            "integrator parameter '{}' is a <{}>; integrators take <integer>, <float>, <boolean> or <string>",
                            param.name,
                            other.tag()
                        ),
                    ));
                }
            };
            params.push((param.name.clone(), text));
        }
        let element = IntegratorElement {
            kind: p.kind.clone(),
            params,
            loc: p.loc.to_string(),
        };
        let configured =
            crate::integrators::registry::from_element(&element).map_err(|e| err(&p.loc, e))?;
        let depth = |name: &str| {
            configured
                .params()
                .into_iter()
                .find(|d| d.name == name)
                .and_then(|d| d.value.as_i64())
        };
        let defaults = IntegratorDesc::default();
        self.desc.integrator = IntegratorDesc {
            max_depth: depth("max_depth").map_or(defaults.max_depth, crate::settings::depth_limit),
            rr_depth: depth("rr_depth")
                .and_then(|v| u32::try_from(v).ok())
                .unwrap_or(defaults.rr_depth),
        };
        self.desc.integrator_element = Some(element);
        Ok(())
    }

    fn sensor(&mut self, p: &Plugin) -> Result<(), SceneError> {
        if p.kind != "perspective" && p.kind != "thinlens" {
            return Err(err(
                &p.loc,
                format!(
                    "unsupported sensor \"{}\" (supported: perspective, thinlens)",
                    p.kind
                ),
            ));
        }
        let mut props = Props::new(p);
        let fov = props.float("fov", 39.597_755)?;
        let fov_axis = match props.opt_string("fov_axis")? {
            None => FovAxis::X,
            Some((s, loc)) => match s.as_str() {
                "x" => FovAxis::X,
                "y" => FovAxis::Y,
                "diagonal" => FovAxis::Diagonal,
                "smaller" => FovAxis::Smaller,
                "larger" => FovAxis::Larger,
                _ => return Err(err(&loc, format!("unknown fov_axis \"{s}\""))),
            },
        };
        let near_clip = props.float("near_clip", 0.01)?;
        let far_clip = props.float("far_clip", 10000.0)?;
        let to_world = props.transform("to_world")?;
        let (aperture_radius, focus_distance) = if p.kind == "thinlens" {
            // Mitsuba 3 requires the aperture and focuses at far_clip by default.
            let a = props.opt_float("aperture_radius")?.ok_or_else(|| {
                err(
                    &p.loc,
                    "<sensor type=\"thinlens\"> needs an 'aperture_radius'",
                )
            })?;
            let f = props.float("focus_distance", far_clip)?;
            if !(a.is_finite() && a > 0.0) {
                return Err(err(
                    &p.loc,
                    format!("aperture_radius must be positive and finite, got {a}"),
                ));
            }
            if !(f.is_finite() && f > 0.0) {
                return Err(err(
                    &p.loc,
                    format!("focus_distance must be positive and finite, got {f}"),
                ));
            }
            (a, f)
        } else {
            (0.0, far_clip)
        };
        props.finish()?;
        if !(fov > 0.0 && fov < 180.0) {
            return Err(err(
                &p.loc,
                format!("fov must be in (0, 180) degrees, got {fov}"),
            ));
        }
        if !(near_clip > 0.0 && far_clip > near_clip) {
            return Err(err(&p.loc, "need 0 < near_clip < far_clip"));
        }
        self.desc.camera = CameraDesc {
            to_world,
            fov_deg: fov,
            fov_axis,
            near_clip,
            far_clip,
            aperture_radius,
            focus_distance,
        };
        for child in &p.children {
            let c = match child {
                Child::Plugin(c) => c,
                Child::Ref { loc, .. } => {
                    return Err(err(loc, "<ref> is not supported in <sensor>"));
                }
            };
            match (c.tag.as_str(), c.kind.as_str()) {
                ("film", "hdrfilm") => self.film(c)?,
                ("sampler", "independent") => {
                    no_children(c)?;
                    let mut props = Props::new(c);
                    let spp = props.int("sample_count", 4)?;
                    props.finish()?;
                    // Refused, not clamped: a count beyond u32 is a typo.
                    self.desc.sample_count =
                        u32::try_from(spp).ok().filter(|&n| n > 0).ok_or_else(|| {
                            err(
                                &c.loc,
                                format!("sample_count must be between 1 and 4294967295, got {spp}"),
                            )
                        })?;
                }
                (tag, kind) => {
                    return Err(err(
                        &c.loc,
                        format!(
                            "unsupported <{tag} type=\"{kind}\"> in <sensor> (supported: hdrfilm, independent)"
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    fn film(&mut self, p: &Plugin) -> Result<(), SceneError> {
        let mut props = Props::new(p);
        let width = props.int("width", 768)?;
        let height = props.int("height", 576)?;
        let crop_x = props.int("crop_offset_x", 0)?;
        let crop_y = props.int("crop_offset_y", 0)?;
        let crop_w = props.opt_int("crop_width")?;
        let crop_h = props.opt_int("crop_height")?;
        if props.boolean("sample_border", false)? {
            return Err(err(&p.loc, "sample_border=true is not supported"));
        }
        // These only choose the output container and channel layout, which
        // this renderer fixes (linear float RGB EXR); accept Mitsuba's
        // values that match it and refuse the rest.
        for (name, allowed) in [
            ("file_format", &["openexr", "exr"][..]),
            ("pixel_format", &["rgb", "rgba"][..]),
            ("component_format", &["float32"][..]),
        ] {
            if let Some((s, loc)) = props.opt_string(name)?
                && !allowed.contains(&s.as_str())
            {
                return Err(err(
                    &loc,
                    format!(
                        "unsupported {name} \"{s}\" (supported: {})",
                        allowed.join(", ")
                    ),
                ));
            }
        }
        props.finish()?;
        if width <= 0 || height <= 0 || width > 1 << 16 || height > 1 << 16 {
            return Err(err(
                &p.loc,
                format!(
                    "film resolution must be positive (and at most 65536), got {width}x{height}"
                ),
            ));
        }
        let mut filter = FilterKind::Gaussian { stddev: 0.5 };
        for child in &p.children {
            let c = match child {
                Child::Plugin(c) => c,
                Child::Ref { loc, .. } => return Err(err(loc, "<ref> is not supported in <film>")),
            };
            no_children(c)?;
            match (c.tag.as_str(), c.kind.as_str()) {
                ("rfilter", "box") => {
                    Props::new(c).finish()?;
                    filter = FilterKind::Box;
                }
                ("rfilter", "gaussian") => {
                    let mut props = Props::new(c);
                    let stddev = props.float("stddev", 0.5)?;
                    props.finish()?;
                    // The film keeps filter footprints at most 16 pixels wide.
                    if !(stddev > 0.0 && stddev <= 1.875) {
                        return Err(err(&c.loc, "stddev must be in (0, 1.875] pixels"));
                    }
                    filter = FilterKind::Gaussian { stddev };
                }
                ("rfilter", "tent") => {
                    let mut props = Props::new(c);
                    let radius = props.float("radius", 1.0)?;
                    props.finish()?;
                    // The film keeps filter footprints at most 16 pixels wide.
                    if !(radius > 0.0 && radius <= 7.5) {
                        return Err(err(&c.loc, "radius must be in (0, 7.5] pixels"));
                    }
                    filter = FilterKind::Tent { radius };
                }
                (tag, kind) => {
                    return Err(err(
                        &c.loc,
                        format!(
                            "unsupported <{tag} type=\"{kind}\"> (supported rfilter: box, gaussian, tent)"
                        ),
                    ));
                }
            }
        }
        let crop_w = crop_w.unwrap_or(width.saturating_sub(crop_x));
        let crop_h = crop_h.unwrap_or(height.saturating_sub(crop_y));
        if crop_x < 0
            || crop_y < 0
            || crop_w <= 0
            || crop_h <= 0
            || crop_x.saturating_add(crop_w) > width
            || crop_y.saturating_add(crop_h) > height
        {
            return Err(err(
                &p.loc,
                format!(
                    "the crop window {crop_w}x{crop_h} at ({crop_x}, {crop_y}) must lie within the {width}x{height} film"
                ),
            ));
        }
        self.desc.film = FilmDesc {
            width: crop_w as u32,
            height: crop_h as u32,
            full_width: width as u32,
            full_height: height as u32,
            crop_offset: (crop_x as u32, crop_y as u32),
            filter,
        };
        Ok(())
    }

    fn point_light(&mut self, p: &Plugin) -> Result<(), SceneError> {
        no_children(p)?;
        let mut props = Props::new(p);
        let intensity = props.rgb("intensity", Rgb::WHITE)?;
        let position = props.point("position", Vec3::ZERO)?;
        let to_world = props.transform("to_world")?;
        props.finish()?;
        self.desc.point_lights.push(PointLightDesc {
            position: to_world.transform_point3(position),
            intensity,
            spot: None,
        });
        Ok(())
    }

    /// Mitsuba 3's `spot`: `intensity` (1) on the axis, the local +z of
    /// `to_world`; `cutoff_angle` (20°), `beam_width` (¾ of the cutoff).
    fn spot_light(&mut self, p: &Plugin) -> Result<(), SceneError> {
        no_children(p)?;
        let mut props = Props::new(p);
        let intensity = props.rgb("intensity", Rgb::WHITE)?;
        let cutoff = props.float("cutoff_angle", 20.0)?;
        let beam = props.float("beam_width", cutoff * 0.75)?;
        let to_world = props.transform("to_world")?;
        props.finish()?;
        if !(intensity.is_finite() && intensity.min_channel() >= 0.0) {
            return Err(err(
                &p.loc,
                format!("'intensity' must be finite and non-negative, got {intensity:?}"),
            ));
        }
        let spot = SpotProfile::new(Mat3::from_mat4(to_world), cutoff, beam)
            .map_err(|e| err(&p.loc, e))?;
        self.desc.point_lights.push(PointLightDesc {
            position: to_world.transform_point3(Vec3::ZERO),
            intensity,
            spot: Some(spot),
        });
        Ok(())
    }

    /// Mitsuba 3's `directional`: `irradiance` (1) travelling along
    /// `direction`, or along the local +z of `to_world` (not both).
    fn directional_light(&mut self, p: &Plugin) -> Result<(), SceneError> {
        no_children(p)?;
        let mut props = Props::new(p);
        let irradiance = props.rgb("irradiance", Rgb::WHITE)?;
        let has_direction = p.params.iter().any(|q| q.name == "direction");
        let has_to_world = p.params.iter().any(|q| q.name == "to_world");
        if has_direction && has_to_world {
            return Err(err(
                &p.loc,
                "a directional emitter takes 'direction' or 'to_world', not both",
            ));
        }
        let direction = props.point("direction", Vec3::Z)?;
        let to_world = props.transform("to_world")?;
        props.finish()?;
        let direction = to_world
            .transform_vector3(direction)
            .try_normalize()
            .ok_or_else(|| err(&p.loc, "the directional emitter's direction is zero"))?;
        if !(irradiance.is_finite() && irradiance.min_channel() >= 0.0) {
            return Err(err(
                &p.loc,
                format!("'irradiance' must be finite and non-negative, got {irradiance:?}"),
            ));
        }
        self.desc
            .infinite_lights
            .push(InfiniteLightDesc::Directional {
                direction,
                irradiance,
            });
        Ok(())
    }

    /// Mitsuba 3's `envmap` (`filename` of a lat-long image, `scale` 1,
    /// `to_world`) and `constant` (`radiance` 1). One per scene.
    fn environment(&mut self, p: &Plugin) -> Result<(), SceneError> {
        no_children(p)?;
        if self
            .desc
            .infinite_lights
            .iter()
            .any(|l| matches!(l, InfiniteLightDesc::Environment(_)))
        {
            return Err(err(
                &p.loc,
                "only one environment emitter (envmap or constant) is allowed per scene",
            ));
        }
        let mut props = Props::new(p);
        let radiance = if p.kind == "constant" {
            let l = props.rgb("radiance", Rgb::WHITE)?;
            if !(l.is_finite() && l.min_channel() >= 0.0) {
                return Err(err(
                    &p.loc,
                    format!("'radiance' must be finite and non-negative, got {l:?}"),
                ));
            }
            EnvRadiance::Constant(l)
        } else {
            let (filename, loc) = props
                .opt_string("filename")?
                .ok_or_else(|| err(&p.loc, "<emitter type=\"envmap\"> needs a 'filename'"))?;
            let scale = props.float("scale", 1.0)?;
            if !(scale.is_finite() && scale >= 0.0) {
                return Err(err(
                    &p.loc,
                    format!("'scale' must be finite and non-negative, got {scale}"),
                ));
            }
            let path = self.base_dir.join(&filename);
            // Any format the bitmap texture reads; 8-bit images are
            // sRGB-decoded, as Mitsuba's envmap does.
            let (w, h, texels) = texture::read_linear(&path, false).map_err(|e| {
                err(
                    &loc,
                    format!("cannot load environment map \"{filename}\": {e}"),
                )
            })?;
            let texels = texels.into_iter().map(|t| t * scale).collect();
            let map = LatLong::new(w as usize, h as usize, texels)
                .map_err(|e| err(&loc, format!("environment map \"{filename}\": {e}")))?;
            EnvRadiance::Map(Box::new(map))
        };
        let to_world = props.transform("to_world")?;
        props.finish()?;
        let env =
            Environment::new(radiance, Mat3::from_mat4(to_world)).map_err(|e| err(&p.loc, e))?;
        self.desc
            .infinite_lights
            .push(InfiniteLightDesc::Environment(Box::new(env)));
        Ok(())
    }

    /// A BSDF and its textured parameters (their constants in the
    /// description are the textures' means).
    fn bsdf(&mut self, p: &Plugin) -> Result<LoadedBsdf, SceneError> {
        let mut props = Props::new(p);
        let mut tex = TextureChildren::new(p);
        let mut textures = BsdfTextures::default();
        let mut color = |loader: &mut Self,
                         props: &mut Props,
                         param: TexturedParam,
                         default: Rgb|
         -> Result<Rgb, SceneError> {
            loader.color_param(props, &mut tex, param, default, &mut textures)
        };
        use TexturedParam::*;
        let desc = match p.kind.as_str() {
            "diffuse" => BsdfDesc::Diffuse {
                reflectance: color(self, &mut props, Reflectance, Rgb::splat(0.5))?,
            },
            "conductor" | "roughconductor" => {
                let (eta, k) = conductor_ior(&mut props)?;
                let specular_reflectance =
                    color(self, &mut props, SpecularReflectance, Rgb::WHITE)?;
                if p.kind == "conductor" {
                    if eta == Rgb::splat(0.0)
                        && k == Rgb::WHITE
                        && specular_reflectance == Rgb::WHITE
                    {
                        BsdfDesc::PerfectMirror
                    } else {
                        BsdfDesc::Conductor {
                            eta,
                            k,
                            specular_reflectance,
                        }
                    }
                } else {
                    let (distribution, alpha_u, alpha_v) =
                        self.microfacet(&mut props, &mut tex, &mut textures, &p.loc)?;
                    BsdfDesc::RoughConductor {
                        distribution,
                        alpha_u,
                        alpha_v,
                        eta,
                        k,
                        specular_reflectance,
                    }
                }
            }
            "dielectric" | "roughdielectric" => {
                let int_ior = props.ior("int_ior", 1.5046)?;
                let ext_ior = props.ior("ext_ior", 1.000_277)?;
                if !(int_ior > 0.0 && ext_ior > 0.0) || int_ior == ext_ior {
                    return Err(err(
                        &p.loc,
                        "int_ior and ext_ior must be positive and differ",
                    ));
                }
                let specular_reflectance =
                    color(self, &mut props, SpecularReflectance, Rgb::WHITE)?;
                let specular_transmittance =
                    color(self, &mut props, SpecularTransmittance, Rgb::WHITE)?;
                if p.kind == "dielectric" {
                    BsdfDesc::Dielectric {
                        int_ior,
                        ext_ior,
                        specular_reflectance,
                        specular_transmittance,
                    }
                } else {
                    let (distribution, alpha_u, alpha_v) =
                        self.microfacet(&mut props, &mut tex, &mut textures, &p.loc)?;
                    BsdfDesc::RoughDielectric {
                        distribution,
                        alpha_u,
                        alpha_v,
                        int_ior,
                        ext_ior,
                        specular_reflectance,
                        specular_transmittance,
                    }
                }
            }
            "plastic" | "roughplastic" => {
                let int_ior = props.ior("int_ior", 1.49)?;
                let ext_ior = props.ior("ext_ior", 1.000_277)?;
                if !(int_ior > 0.0 && ext_ior > 0.0) || int_ior == ext_ior {
                    return Err(err(
                        &p.loc,
                        "int_ior and ext_ior must be positive and differ",
                    ));
                }
                // A texture's mean must lie in [0, 1] (its texels are not checked).
                let diffuse_reflectance =
                    color(self, &mut props, DiffuseReflectance, Rgb::splat(0.5))?;
                if !diffuse_reflectance
                    .to_array()
                    .iter()
                    .all(|c| (0.0..=1.0).contains(c))
                {
                    return Err(err(&p.loc, "diffuse_reflectance must lie in [0, 1]"));
                }
                let specular_reflectance = props.rgb("specular_reflectance", Rgb::WHITE)?;
                let nonlinear = props.boolean("nonlinear", false)?;
                if p.kind == "plastic" {
                    BsdfDesc::Plastic {
                        diffuse_reflectance,
                        specular_reflectance,
                        int_ior,
                        ext_ior,
                        nonlinear,
                    }
                } else {
                    let (distribution, alpha_u, alpha_v, sample_visible) =
                        self.roughness(&mut props, &mut tex, None, &p.loc)?;
                    if alpha_u != alpha_v {
                        return Err(err(
                            &p.loc,
                            "roughplastic does not support anisotropic roughness (as Mitsuba 3)",
                        ));
                    }
                    BsdfDesc::RoughPlastic {
                        distribution,
                        alpha: alpha_u,
                        sample_visible,
                        diffuse_reflectance,
                        specular_reflectance,
                        int_ior,
                        ext_ior,
                        nonlinear,
                    }
                }
            }
            "thindielectric" => {
                let int_ior = props.ior("int_ior", 1.5046)?;
                let ext_ior = props.ior("ext_ior", 1.000_277)?;
                if !(int_ior > 0.0 && ext_ior > 0.0) {
                    return Err(err(&p.loc, "int_ior and ext_ior must be positive"));
                }
                BsdfDesc::ThinDielectric {
                    int_ior,
                    ext_ior,
                    specular_reflectance: props.rgb("specular_reflectance", Rgb::WHITE)?,
                    specular_transmittance: props.rgb("specular_transmittance", Rgb::WHITE)?,
                }
            }
            "twosided" => {
                let mut inner = None;
                for child in &p.children {
                    let d = match child {
                        Child::Plugin(c) if c.tag == "bsdf" => self.bsdf(c)?,
                        Child::Ref { id, loc, .. } => self.bsdf_by_id(id, loc)?,
                        Child::Plugin(c) => {
                            return Err(err(
                                &c.loc,
                                format!("<{}> is not allowed in twosided", c.tag),
                            ));
                        }
                    };
                    if inner.is_some() {
                        return Err(err(
                            &p.loc,
                            "twosided with two different BSDFs is not supported (give exactly one)",
                        ));
                    }
                    inner = Some(d);
                }
                let (inner, inner_textures, wrappers) =
                    inner.ok_or_else(|| err(&p.loc, "twosided needs a nested <bsdf>"))?;
                if !wrappers.is_empty() {
                    return Err(err(
                        &p.loc,
                        "twosided cannot wrap normalmap, bumpmap or mask (put the twosided inside them)",
                    ));
                }
                if matches!(inner, BsdfDesc::TwoSided { .. }) {
                    return Err(err(&p.loc, "twosided cannot wrap another twosided"));
                }
                if matches!(
                    inner,
                    BsdfDesc::Dielectric { .. }
                        | BsdfDesc::RoughDielectric { .. }
                        | BsdfDesc::ThinDielectric { .. }
                ) {
                    return Err(err(
                        &p.loc,
                        "twosided can only wrap BSDFs without transmission (as Mitsuba 3)",
                    ));
                }
                props.finish()?;
                return Ok((
                    BsdfDesc::TwoSided {
                        inner: Box::new(inner),
                    },
                    inner_textures,
                    Wrappers::default(),
                ));
            }
            "normalmap" | "bumpmap" => return self.perturbed_bsdf(p),
            "mask" => return self.mask(p),
            other => {
                return Err(err(
                    &p.loc,
                    format!(
                        "unsupported bsdf \"{other}\" (supported: diffuse, conductor, roughconductor, dielectric, roughdielectric, thindielectric, plastic, roughplastic, twosided, normalmap, bumpmap, mask)"
                    ),
                ));
            }
        };
        tex.finish()?;
        props.finish()?;
        Ok((desc, textures, Wrappers::default()))
    }

    /// `mask`: one nested `<bsdf>` or `<ref>` (which may be a `normalmap`
    /// or `bumpmap`) and `opacity` (0.5), a number or a `<texture
    /// name="opacity">`, as Mitsuba 3 reads it.
    fn mask(&mut self, p: &Plugin) -> Result<LoadedBsdf, SceneError> {
        let mut props = Props::new(p);
        let mut tex = TextureChildren::new(p);
        let opacity = match tex.take("opacity") {
            Some(child) => {
                if props.opt_rgb("opacity")?.is_some() {
                    return Err(err(child.loc(), "'opacity' is given twice"));
                }
                self.texture_of(child)?
            }
            None => Texture::Constant(props.rgb("opacity", Rgb::splat(0.5))?),
        };
        let mut inner = None;
        for child in &p.children {
            let d = match child {
                Child::Plugin(c) if c.tag == "bsdf" => self.bsdf(c)?,
                Child::Ref { name, .. } if name.as_deref() == Some("opacity") => continue,
                Child::Ref { id, loc, .. } => self.bsdf_by_id(id, loc)?,
                Child::Plugin(c) if c.tag == "texture" && c.name.as_deref() == Some("opacity") => {
                    continue;
                }
                Child::Plugin(c) => {
                    return Err(err(
                        &c.loc,
                        if c.tag == "texture" {
                            "mask takes one <texture name=\"opacity\">".to_string()
                        } else {
                            format!("<{}> is not allowed in mask", c.tag)
                        },
                    ));
                }
            };
            if inner.is_some() {
                return Err(err(&p.loc, "mask takes exactly one nested <bsdf> or <ref>"));
            }
            inner = Some(d);
        }
        let (desc, textures, mut wrappers) = inner.ok_or_else(|| {
            err(
                &p.loc,
                "mask needs a nested <bsdf> (the BSDF of the opaque part)",
            )
        })?;
        if wrappers.opacity.is_some() {
            return Err(err(&p.loc, "mask cannot wrap another mask"));
        }
        wrappers.opacity = Some(opacity);
        props.finish()?;
        Ok((desc, textures, wrappers))
    }

    /// `normalmap` (texture `normalmap`) or `bumpmap` (one texture, any
    /// name, a bitmap) around exactly one nested BSDF or `<ref>`, with
    /// `flip_invalid_normals`, `use_shadowing_function` and (bumpmap)
    /// `scale`, as Mitsuba 3.9 reads them.
    fn perturbed_bsdf(&mut self, p: &Plugin) -> Result<LoadedBsdf, SceneError> {
        let mut props = Props::new(p);
        let what = &p.kind;
        let mut inner = None;
        let mut map = None;
        for child in &p.children {
            // The map: a <texture> or a <ref> to a scene-level texture.
            let map_src = match child {
                Child::Plugin(c) if c.tag == "texture" => {
                    Some((TexSource::Inline(c), c.name.as_deref(), &c.loc))
                }
                Child::Ref { id, name, loc } if self.named_textures.contains_key(id) => {
                    Some((TexSource::Ref { id, loc }, name.as_deref(), loc))
                }
                _ => None,
            };
            if let Some((src, name, loc)) = map_src {
                let named = name == Some("normalmap");
                if map.is_some() || (what == "normalmap" && !named) {
                    return Err(err(
                        loc,
                        if what == "normalmap" {
                            "normalmap takes one <texture name=\"normalmap\">".to_string()
                        } else {
                            "bumpmap takes one <texture>".to_string()
                        },
                    ));
                }
                map = Some((self.texture_of(src)?, loc.clone()));
                continue;
            }
            let d = match child {
                Child::Plugin(c) if c.tag == "bsdf" => self.bsdf(c)?,
                Child::Ref { id, loc, .. } => self.bsdf_by_id(id, loc)?,
                Child::Plugin(c) => {
                    return Err(err(&c.loc, format!("<{}> is not allowed in {what}", c.tag)));
                }
            };
            if inner.is_some() {
                return Err(err(
                    &p.loc,
                    format!("{what} takes exactly one nested <bsdf> or <ref>"),
                ));
            }
            inner = Some(d);
        }
        let (desc, textures, nested) = inner.ok_or_else(|| {
            err(
                &p.loc,
                format!("{what} needs a nested <bsdf> (the BSDF whose frame it perturbs)"),
            )
        })?;
        if nested.perturbation.is_some() {
            return Err(err(
                &p.loc,
                format!("{what} cannot wrap another normalmap or bumpmap"),
            ));
        }
        if nested.opacity.is_some() {
            return Err(err(
                &p.loc,
                format!("{what} cannot wrap a mask (put the mask outside)"),
            ));
        }
        let (texture, texture_loc) = map.ok_or_else(|| {
            err(
                &p.loc,
                if what == "normalmap" {
                    "normalmap needs a <texture name=\"normalmap\">".to_string()
                } else {
                    "bumpmap needs a height <texture>".to_string()
                },
            )
        })?;
        let kind = if what == "normalmap" {
            PerturbKind::Normal(texture)
        } else {
            let scale = props.float("scale", 1.0)?;
            if !scale.is_finite() {
                return Err(err(&p.loc, "bumpmap scale must be finite"));
            }
            match texture {
                Texture::Bitmap(height) => PerturbKind::Bump { height, scale },
                _ => {
                    return Err(err(
                        &texture_loc,
                        "bumpmap needs a bitmap texture (Mitsuba 3 computes height gradients only for bitmaps)",
                    ));
                }
            }
        };
        let perturbation = Perturbation {
            kind,
            flip_invalid_normals: props.boolean("flip_invalid_normals", true)?,
            use_shadowing_function: props.boolean("use_shadowing_function", true)?,
        };
        props.finish()?;
        let wrappers = Wrappers {
            perturbation: Some(perturbation),
            opacity: None,
        };
        Ok((desc, textures, wrappers))
    }

    /// The index of the BSDF a `<ref id=…>` names (one line when the id
    /// is unknown or names a texture).
    fn bsdf_index(&self, id: &str, loc: &Loc) -> Result<usize, SceneError> {
        match self.named_bsdfs.get(id) {
            Some(index) => Ok(*index),
            None if self.named_textures.contains_key(id) => Err(err(
                loc,
                format!("\"{id}\" is a <texture>, but a <bsdf> is expected here"),
            )),
            None => Err(err(
                loc,
                format!("no <bsdf id=\"{id}\"> defined before this reference"),
            )),
        }
    }

    fn bsdf_by_id(&self, id: &str, loc: &Loc) -> Result<LoadedBsdf, SceneError> {
        let index = self.bsdf_index(id, loc)?;
        Ok((
            self.desc.bsdfs[index].clone(),
            self.desc.bsdf_textures[index].clone(),
            self.desc.bsdf_wrappers[index].clone(),
        ))
    }

    /// The texture a `<texture>` child or a `<ref id=… name=…>` gives
    /// (one line when the id is unknown or names a BSDF).
    fn texture_of(&mut self, src: TexSource) -> Result<Texture, SceneError> {
        match src {
            TexSource::Inline(p) => self.texture(p),
            TexSource::Ref { id, loc } => match self.named_textures.get(id) {
                Some(t) => Ok(t.clone()),
                None if self.named_bsdfs.contains_key(id) => Err(err(
                    loc,
                    format!("\"{id}\" is a <bsdf>, but a <texture> is expected here"),
                )),
                None => Err(err(
                    loc,
                    format!("no <texture id=\"{id}\"> defined before this reference"),
                )),
            },
        }
    }

    /// A colour parameter that may be a texture: the constant (`<rgb>`,
    /// `<float>`) or a nested `<texture name=…>`, whose mean it returns
    /// after recording the texture in `textures`.
    fn color_param(
        &mut self,
        props: &mut Props,
        tex: &mut TextureChildren,
        param: TexturedParam,
        default: Rgb,
        textures: &mut BsdfTextures,
    ) -> Result<Rgb, SceneError> {
        let name = param.name();
        let constant = props.opt_rgb(name)?;
        let Some(child) = tex.take(name) else {
            return Ok(constant.unwrap_or(default));
        };
        if constant.is_some() {
            return Err(err(child.loc(), format!("'{name}' is given twice")));
        }
        let t = self.texture_of(child)?;
        let mean = t.mean();
        if !matches!(t, Texture::Constant(_)) {
            textures.0.push((param, t));
        }
        Ok(mean)
    }

    /// `distribution`, roughness and `sample_visible` of a microfacet
    /// model whose sampling is visible-normal only (refuses
    /// `sample_visible=false`) and whose roughness may be textured
    /// (`roughconductor`, `roughdielectric`; see [`Loader::roughness`]).
    fn microfacet(
        &mut self,
        props: &mut Props,
        tex: &mut TextureChildren,
        textures: &mut BsdfTextures,
        loc: &Loc,
    ) -> Result<(MicrofacetKind, f32, f32), SceneError> {
        let (distribution, alpha_u, alpha_v, sample_visible) =
            self.roughness(props, tex, Some(textures), loc)?;
        if !sample_visible {
            return Err(err(
                loc,
                "sample_visible=false is not supported (visible-normal sampling only)",
            ));
        }
        Ok((distribution, alpha_u, alpha_v))
    }

    /// `distribution` (beckmann), `alpha` (0.1) or `alpha_u`+`alpha_v`,
    /// and `sample_visible` (true), as Mitsuba 3's microfacet models read
    /// them. With `textures` (the models where Mitsuba 3 takes a texture
    /// for the roughness) each roughness may be a `<texture>` or a `<ref
    /// name=…>`, recorded there and read per hit with `Texture::eval_1`
    /// (the description holds its mean); without (`roughplastic`) a
    /// texture is refused, as Mitsuba 3 refuses it.
    fn roughness(
        &mut self,
        props: &mut Props,
        tex: &mut TextureChildren,
        mut textures: Option<&mut BsdfTextures>,
        loc: &Loc,
    ) -> Result<(MicrofacetKind, f32, f32, bool), SceneError> {
        let distribution = match props.opt_string("distribution")? {
            None => MicrofacetKind::Beckmann,
            Some((s, l)) => match s.as_str() {
                "beckmann" => MicrofacetKind::Beckmann,
                "ggx" => MicrofacetKind::Ggx,
                _ => {
                    return Err(err(
                        &l,
                        format!("unknown distribution \"{s}\" (beckmann|ggx)"),
                    ));
                }
            },
        };
        let mut alpha_param = |loader: &mut Self, param: TexturedParam| {
            let name = param.name();
            let constant = props.opt_float(name)?;
            let Some(src) = tex.take(name) else {
                if constant.is_some_and(|a| !(a > 0.0)) {
                    return Err(err(loc, "alpha must be positive"));
                }
                return Ok(constant);
            };
            let Some(textures) = textures.as_deref_mut() else {
                return Err(err(
                    src.loc(),
                    format!(
                        "'{name}' must be a number here, not a texture (as in Mitsuba 3: roughplastic's coating tables depend on it)"
                    ),
                ));
            };
            if constant.is_some() {
                return Err(err(src.loc(), format!("'{name}' is given twice")));
            }
            let t = loader.texture_of(src)?;
            // The description's placeholder; per hit the texture's value
            // is used (clamped below at MIN_ALPHA, as Mitsuba does).
            let mean = t.mean_1().max(MIN_ALPHA);
            if !matches!(t, Texture::Constant(_)) {
                textures.0.push((param, t));
            }
            Ok(Some(mean))
        };
        let alpha = alpha_param(self, TexturedParam::Alpha)?;
        let au = alpha_param(self, TexturedParam::AlphaU)?;
        let av = alpha_param(self, TexturedParam::AlphaV)?;
        let (alpha_u, alpha_v) = match (alpha, au, av) {
            (Some(a), None, None) => (a, a),
            (None, Some(u), Some(v)) => (u, v),
            (None, None, None) => (0.1, 0.1),
            _ => {
                return Err(err(
                    loc,
                    "give either 'alpha' or both 'alpha_u' and 'alpha_v'",
                ));
            }
        };
        let sample_visible = props.boolean("sample_visible", true)?;
        Ok((distribution, alpha_u, alpha_v, sample_visible))
    }

    /// A colour that may be a texture inside a texture (`checkerboard`'s
    /// colours).
    fn texture_or_color(
        &mut self,
        props: &mut Props,
        tex: &mut TextureChildren,
        name: &str,
        default: f32,
    ) -> Result<Texture, SceneError> {
        let constant = props.opt_rgb(name)?;
        match tex.take(name) {
            None => Ok(Texture::Constant(constant.unwrap_or(Rgb::splat(default)))),
            Some(child) if constant.is_none() => self.texture_of(child),
            Some(child) => Err(err(child.loc(), format!("'{name}' is given twice"))),
        }
    }

    /// A `<texture>` element: `bitmap` or `checkerboard`.
    fn texture(&mut self, p: &Plugin) -> Result<Texture, SceneError> {
        let mut props = Props::new(p);
        let to_uv = props.transform("to_uv")?;
        let to_uv = texture::uv_transform(&to_uv).map_err(|e| err(&p.loc, e))?;
        let t = match p.kind.as_str() {
            "bitmap" => {
                let (filename, loc) = props
                    .opt_string("filename")?
                    .ok_or_else(|| err(&p.loc, "<texture type=\"bitmap\"> needs a 'filename'"))?;
                let filter = match props.opt_string("filter_type")? {
                    None => FilterType::Bilinear,
                    Some((s, l)) => match s.as_str() {
                        "bilinear" => FilterType::Bilinear,
                        "nearest" => FilterType::Nearest,
                        _ => {
                            return Err(err(
                                &l,
                                format!("unknown filter_type \"{s}\" (bilinear|nearest)"),
                            ));
                        }
                    },
                };
                let wrap = match props.opt_string("wrap_mode")? {
                    None => WrapMode::Repeat,
                    Some((s, l)) => match s.as_str() {
                        "repeat" => WrapMode::Repeat,
                        "mirror" => WrapMode::Mirror,
                        "clamp" => WrapMode::Clamp,
                        _ => {
                            return Err(err(
                                &l,
                                format!("unknown wrap_mode \"{s}\" (repeat|mirror|clamp)"),
                            ));
                        }
                    },
                };
                let raw = props.boolean("raw", false)?;
                // Storage and GPU options of Mitsuba that change no value
                // here (texels are stored in single precision).
                props.boolean("accel", true)?;
                if let Some((s, l)) = props.opt_string("format")?
                    && !["auto", "variant", "fp16"].contains(&s.as_str())
                {
                    return Err(err(
                        &l,
                        format!("unknown format \"{s}\" (auto|variant|fp16)"),
                    ));
                }
                no_children(p)?;
                let path = self.base_dir.join(&filename);
                let bitmap = Bitmap::load(&path, raw, filter, wrap, to_uv).map_err(|e| {
                    err(
                        &loc,
                        format!("cannot load texture \"{}\": {e}", path.display()),
                    )
                })?;
                Texture::Bitmap(std::sync::Arc::new(bitmap))
            }
            "checkerboard" => {
                let mut tex = TextureChildren::new(p);
                let color0 = self.texture_or_color(&mut props, &mut tex, "color0", 0.4)?;
                let color1 = self.texture_or_color(&mut props, &mut tex, "color1", 0.2)?;
                tex.finish()?;
                Texture::Checkerboard(Box::new(Checkerboard {
                    color0,
                    color1,
                    to_uv,
                }))
            }
            other => {
                return Err(err(
                    &p.loc,
                    format!("unsupported texture \"{other}\" (supported: bitmap, checkerboard)"),
                ));
            }
        };
        props.finish()?;
        Ok(t)
    }

    fn shape(&mut self, p: &Plugin) -> Result<(), SceneError> {
        let mut props = Props::new(p);
        let to_world = props.transform("to_world")?;
        let flip_normals = props.boolean("flip_normals", false)?;
        let geometry = match p.kind.as_str() {
            "obj" | "ply" | "serialized" => {
                let (filename, loc) = props.opt_string("filename")?.ok_or_else(|| {
                    err(
                        &p.loc,
                        format!("<shape type=\"{}\"> needs a 'filename'", p.kind),
                    )
                })?;
                let mut face_normals = props.boolean("face_normals", false)?;
                // Mitsuba flips v by default for OBJ files only; its
                // `serialized` plugin has no such flag.
                let flip_uv = if p.kind == "serialized" {
                    false
                } else {
                    props.boolean("flip_tex_coords", p.kind == "obj")?
                };
                let path = self.base_dir.join(&filename);
                crate::resources::regular_file(&path)
                    .map_err(|e| err(&loc, format!("cannot load mesh \"{filename}\": {e}")))?;
                let mut mesh = match p.kind.as_str() {
                    "obj" => mesh::load_obj(&path),
                    "ply" => mesh::load_ply(&path),
                    _ => {
                        let index = props.int("shape_index", 0)?;
                        let index = u32::try_from(index).map_err(|_| {
                            err(
                                &p.loc,
                                format!(
                                    "cannot load mesh \"{filename}\": shape_index must be in 0..2^32, got {index}"
                                ),
                            )
                        })?;
                        serialized::load_serialized(&path, index).map(|s| {
                            face_normals |= s.face_normals;
                            s.mesh
                        })
                    }
                }
                .map_err(|e| err(&loc, format!("cannot load mesh \"{filename}\": {e}")))?;
                if flip_uv {
                    mesh.flip_tex_coords();
                }
                let mesh = mesh
                    .finish(&to_world, face_normals)
                    .map_err(|e| err(&loc, format!("mesh \"{filename}\": {e}")))?;
                ShapeGeometry::Mesh(mesh)
            }
            "rectangle" => ShapeGeometry::Mesh(
                mesh::rectangle()
                    .finish(&to_world, true)
                    .map_err(|e| err(&p.loc, e))?,
            ),
            "cube" => ShapeGeometry::Mesh(
                mesh::cube()
                    .finish(&to_world, true)
                    .map_err(|e| err(&p.loc, e))?,
            ),
            "disk" => ShapeGeometry::Disk { to_world },
            "sphere" => {
                let center = props.point("center", Vec3::ZERO)?;
                let radius = props.float("radius", 1.0)?;
                if !(radius > 0.0) {
                    return Err(err(&p.loc, "sphere radius must be positive"));
                }
                // Mitsuba composes to_world with the center/radius; only
                // similarity transforms keep a sphere a sphere.
                let sx = to_world.x_axis.truncate().length();
                let sy = to_world.y_axis.truncate().length();
                let sz = to_world.z_axis.truncate().length();
                let tol = 1e-4 * sx.max(sy).max(sz);
                if (sx - sy).abs() > tol || (sx - sz).abs() > tol {
                    return Err(err(&p.loc, "sphere to_world must not scale non-uniformly"));
                }
                // The rotation left once the uniform scale is divided out.
                let frame = glam::Mat3::from_mat4(to_world) * (1.0 / sx);
                ShapeGeometry::Sphere {
                    center: to_world.transform_point3(center),
                    radius: radius * sx,
                    frame,
                }
            }
            other => {
                return Err(err(
                    &p.loc,
                    format!(
                        "unsupported shape \"{other}\" (supported: obj, ply, serialized, rectangle, cube, sphere, disk)"
                    ),
                ));
            }
        };
        props.finish()?;
        let mut bsdf = None;
        let mut emission = None;
        for child in &p.children {
            match child {
                Child::Ref { id, loc, .. } => {
                    if bsdf.is_some() {
                        return Err(err(loc, "a shape takes one BSDF"));
                    }
                    bsdf = Some(self.bsdf_index(id, loc)?);
                }
                Child::Plugin(c) if c.tag == "bsdf" => {
                    if bsdf.is_some() {
                        return Err(err(&c.loc, "a shape takes one BSDF"));
                    }
                    let d = self.bsdf(c)?;
                    let index = self.push_bsdf(d);
                    if let Some(id) = &c.id {
                        self.declare(id, &c.loc)?;
                        self.named_bsdfs.insert(id.clone(), index);
                    }
                    bsdf = Some(index);
                }
                Child::Plugin(c) if c.tag == "emitter" => {
                    if c.kind != "area" {
                        return Err(err(
                            &c.loc,
                            format!(
                                "unsupported emitter \"{}\" on a shape (supported: area)",
                                c.kind
                            ),
                        ));
                    }
                    if emission.is_some() {
                        return Err(err(&c.loc, "a shape takes one emitter"));
                    }
                    no_children(c)?;
                    let mut props = Props::new(c);
                    let radiance = props.rgb("radiance", Rgb::WHITE)?;
                    props.finish()?;
                    if !radiance.is_finite()
                        || radiance.r < 0.0
                        || radiance.g < 0.0
                        || radiance.b < 0.0
                    {
                        return Err(err(&c.loc, "radiance must be finite and non-negative"));
                    }
                    emission = Some(radiance);
                }
                Child::Plugin(c) => {
                    return Err(err(
                        &c.loc,
                        format!(
                            "<{} type=\"{}\"> is not supported inside a <shape>",
                            c.tag, c.kind
                        ),
                    ));
                }
            }
        }
        let bsdf = match bsdf {
            Some(b) => b,
            // Mitsuba gives a shape without a BSDF a diffuse one of albedo 0.5.
            None => self.push_bsdf((
                BsdfDesc::Diffuse {
                    reflectance: Rgb::splat(0.5),
                },
                BsdfTextures::default(),
                Wrappers::default(),
            )),
        };
        self.desc.shapes.push(ShapeDesc {
            kind: p.kind.clone(),
            geometry,
            bsdf,
            emission,
            flip_normals,
            location: p.loc.to_string(),
        });
        Ok(())
    }
}

/// Mitsuba's conductor IOR: either `material` (default "none": eta 0, k 1,
/// a perfect mirror) or explicit `eta`/`k`, never both.
fn conductor_ior(props: &mut Props) -> Result<(Rgb, Rgb), SceneError> {
    let material = props.opt_string("material")?;
    let eta = props.opt_rgb("eta")?;
    let k = props.opt_rgb("k")?;
    match material {
        Some((name, loc)) if name != "none" => {
            if eta.is_some() || k.is_some() {
                return Err(err(&loc, "give either 'material' or 'eta'/'k', not both"));
            }
            let (eta, k) = named::conductor(&name)
                .ok_or_else(|| err(&loc, format!("unknown conductor material \"{name}\"")))?;
            Ok((Rgb::new(eta[0], eta[1], eta[2]), Rgb::new(k[0], k[1], k[2])))
        }
        _ => Ok((eta.unwrap_or(Rgb::splat(0.0)), k.unwrap_or(Rgb::WHITE))),
    }
}

/// Where a textured parameter's texture comes from: a nested
/// `<texture name=…>` or a `<ref id=… name=…>` to a scene-level one.
#[derive(Clone, Copy)]
enum TexSource<'a> {
    Inline(&'a Plugin),
    Ref { id: &'a str, loc: &'a Loc },
}

impl TexSource<'_> {
    fn loc(&self) -> &Loc {
        match self {
            TexSource::Inline(p) => &p.loc,
            TexSource::Ref { loc, .. } => loc,
        }
    }
}

/// The nested `<texture name=…>` and `<ref id=… name=…>` elements of a
/// plugin, each to be taken once by the parameter it names;
/// [`TextureChildren::finish`] refuses any other child and any texture
/// nobody took.
struct TextureChildren<'a> {
    plugin: &'a Plugin,
    taken: Vec<bool>,
}

impl<'a> TextureChildren<'a> {
    fn new(plugin: &'a Plugin) -> Self {
        TextureChildren {
            plugin,
            taken: vec![false; plugin.children.len()],
        }
    }

    /// The texture child or reference named `name`, if any.
    fn take(&mut self, name: &str) -> Option<TexSource<'a>> {
        let plugin = self.plugin;
        plugin
            .children
            .iter()
            .enumerate()
            .find_map(|(i, c)| match c {
                Child::Plugin(t) if t.tag == "texture" && t.name.as_deref() == Some(name) => {
                    self.taken[i] = true;
                    Some(TexSource::Inline(t))
                }
                Child::Ref {
                    id,
                    name: Some(n),
                    loc,
                } if n == name => {
                    self.taken[i] = true;
                    Some(TexSource::Ref { id, loc })
                }
                _ => None,
            })
    }

    fn finish(self) -> Result<(), SceneError> {
        let what = format!("<{} type=\"{}\">", self.plugin.tag, self.plugin.kind);
        for (c, taken) in self.plugin.children.iter().zip(self.taken) {
            match c {
                _ if taken => {}
                Child::Plugin(t) if t.tag == "texture" => {
                    return Err(err(
                        &t.loc,
                        match &t.name {
                            Some(n) => format!("parameter '{n}' of {what} cannot be a texture"),
                            None => format!("a <texture> in {what} needs a 'name'"),
                        },
                    ));
                }
                Child::Plugin(t) => {
                    return Err(err(
                        &t.loc,
                        format!("<{}> is not allowed inside {what}", t.tag),
                    ));
                }
                Child::Ref {
                    name: Some(n), loc, ..
                } => {
                    return Err(err(
                        loc,
                        format!("parameter '{n}' of {what} cannot be a texture"),
                    ));
                }
                Child::Ref { loc, .. } => {
                    return Err(err(
                        loc,
                        format!(
                            "a <ref> inside {what} needs a 'name' (the parameter it sets, e.g. name=\"reflectance\")"
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

fn no_children(p: &Plugin) -> Result<(), SceneError> {
    match p.children.first() {
        None => Ok(()),
        Some(Child::Plugin(c)) => Err(err(
            &c.loc,
            format!(
                "<{}> is not allowed inside <{} type=\"{}\">",
                c.tag, p.tag, p.kind
            ),
        )),
        Some(Child::Ref { loc, .. }) => Err(err(
            loc,
            format!(
                "<ref> is not allowed inside <{} type=\"{}\">",
                p.tag, p.kind
            ),
        )),
    }
}
