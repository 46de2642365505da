//! Turns the plugin tree of [`super::xml`] into a [`SceneDesc`], applying
//! Mitsuba 3's defaults and refusing every plugin or parameter outside the
//! supported subset (with its file and line).

use super::mesh;
use super::named;
use super::xml::{Child, Loc, Param, Plugin, Value};
use super::{
    CameraDesc, FilmDesc, FilterKind, FovAxis, IntegratorDesc, IntegratorElement, PointLightDesc,
    SceneDesc, SceneError, ShapeDesc, ShapeGeometry,
};
use crate::bsdf::{BsdfDesc, MicrofacetKind};
use crate::color::Rgb;
use glam::{Mat4, Vec3};
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
        match self.get(name) {
            None => Ok(default),
            Some(p) => match &p.value {
                Value::Integer(v) => Ok(*v),
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
    fn opt_rgb(&mut self, name: &str) -> Result<Option<Rgb>, SceneError> {
        match self.get(name) {
            None => Ok(None),
            Some(p) => match &p.value {
                Value::Rgb(v) => Ok(Some(*v)),
                Value::Float(v) => Ok(Some(Rgb::splat(*v))),
                Value::Integer(v) => Ok(Some(Rgb::splat(*v as f32))),
                _ => Err(self.type_err(p, "an <rgb> or a <float>")),
            },
        }
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

/// Loads everything the parsed tree describes.
pub struct Loader {
    /// Directory that relative mesh paths are resolved against.
    base_dir: PathBuf,
    desc: SceneDesc,
    named_bsdfs: HashMap<String, usize>,
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
                    self.named_bsdfs.insert(id.clone(), index);
                }
                Ok(())
            }
            "emitter" => {
                if p.kind != "point" {
                    return Err(err(
                        &p.loc,
                        format!(
                            "unsupported emitter \"{}\" at scene level (supported: point; area emitters go inside a <shape>)",
                            p.kind
                        ),
                    ));
                }
                self.point_light(p)
            }
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

    fn push_bsdf(&mut self, desc: BsdfDesc) -> usize {
        self.desc.bsdfs.push(desc);
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
        if p.kind != "perspective" {
            return Err(err(
                &p.loc,
                format!("unsupported sensor \"{}\" (supported: perspective)", p.kind),
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
                    if spp <= 0 {
                        return Err(err(&c.loc, "sample_count must be positive"));
                    }
                    self.desc.sample_count = spp.min(u32::MAX as i64) as u32;
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
                (tag, kind) => {
                    return Err(err(
                        &c.loc,
                        format!(
                            "unsupported <{tag} type=\"{kind}\"> (supported rfilter: box, gaussian)"
                        ),
                    ));
                }
            }
        }
        self.desc.film = FilmDesc {
            width: width as u32,
            height: height as u32,
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
        });
        Ok(())
    }

    fn bsdf(&mut self, p: &Plugin) -> Result<BsdfDesc, SceneError> {
        let mut props = Props::new(p);
        let desc = match p.kind.as_str() {
            "diffuse" => BsdfDesc::Diffuse {
                reflectance: props.rgb("reflectance", Rgb::splat(0.5))?,
            },
            "conductor" | "roughconductor" => {
                let (eta, k) = conductor_ior(&mut props)?;
                let specular_reflectance = props.rgb("specular_reflectance", Rgb::WHITE)?;
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
                    let (distribution, alpha_u, alpha_v) = microfacet(&mut props, &p.loc)?;
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
                let specular_reflectance = props.rgb("specular_reflectance", Rgb::WHITE)?;
                let specular_transmittance = props.rgb("specular_transmittance", Rgb::WHITE)?;
                if p.kind == "dielectric" {
                    BsdfDesc::Dielectric {
                        int_ior,
                        ext_ior,
                        specular_reflectance,
                        specular_transmittance,
                    }
                } else {
                    let (distribution, alpha_u, alpha_v) = microfacet(&mut props, &p.loc)?;
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
                let diffuse_reflectance = props.rgb("diffuse_reflectance", Rgb::splat(0.5))?;
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
                        microfacet_params(&mut props, &p.loc)?;
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
                        Child::Ref { id, loc } => self.bsdf_by_id(id, loc)?,
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
                let inner = inner.ok_or_else(|| err(&p.loc, "twosided needs a nested <bsdf>"))?;
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
                return Ok(BsdfDesc::TwoSided {
                    inner: Box::new(inner),
                });
            }
            other => {
                return Err(err(
                    &p.loc,
                    format!(
                        "unsupported bsdf \"{other}\" (supported: diffuse, conductor, roughconductor, dielectric, roughdielectric, thindielectric, plastic, roughplastic, twosided)"
                    ),
                ));
            }
        };
        no_children(p)?;
        props.finish()?;
        Ok(desc)
    }

    fn bsdf_by_id(&self, id: &str, loc: &Loc) -> Result<BsdfDesc, SceneError> {
        let index = self.named_bsdfs.get(id).ok_or_else(|| {
            err(
                loc,
                format!("no <bsdf id=\"{id}\"> defined before this reference"),
            )
        })?;
        Ok(self.desc.bsdfs[*index].clone())
    }

    fn shape(&mut self, p: &Plugin) -> Result<(), SceneError> {
        let mut props = Props::new(p);
        let to_world = props.transform("to_world")?;
        let flip_normals = props.boolean("flip_normals", false)?;
        let geometry = match p.kind.as_str() {
            "obj" | "ply" => {
                let (filename, loc) = props.opt_string("filename")?.ok_or_else(|| {
                    err(
                        &p.loc,
                        format!("<shape type=\"{}\"> needs a 'filename'", p.kind),
                    )
                })?;
                let face_normals = props.boolean("face_normals", false)?;
                let path = self.base_dir.join(&filename);
                let mesh = if p.kind == "obj" {
                    mesh::load_obj(&path)
                } else {
                    mesh::load_ply(&path)
                }
                .map_err(|e| err(&loc, format!("cannot load mesh \"{filename}\": {e}")))?;
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
                ShapeGeometry::Sphere {
                    center: to_world.transform_point3(center),
                    radius: radius * sx,
                }
            }
            other => {
                return Err(err(
                    &p.loc,
                    format!(
                        "unsupported shape \"{other}\" (supported: obj, ply, rectangle, cube, sphere, disk)"
                    ),
                ));
            }
        };
        props.finish()?;
        let mut bsdf = None;
        let mut emission = None;
        for child in &p.children {
            match child {
                Child::Ref { id, loc } => {
                    if bsdf.is_some() {
                        return Err(err(loc, "a shape takes one BSDF"));
                    }
                    bsdf = Some(*self.named_bsdfs.get(id).ok_or_else(|| {
                        err(
                            loc,
                            format!("no <bsdf id=\"{id}\"> defined before this reference"),
                        )
                    })?);
                }
                Child::Plugin(c) if c.tag == "bsdf" => {
                    if bsdf.is_some() {
                        return Err(err(&c.loc, "a shape takes one BSDF"));
                    }
                    let d = self.bsdf(c)?;
                    let index = self.push_bsdf(d);
                    if let Some(id) = &c.id {
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
            None => self.push_bsdf(BsdfDesc::Diffuse {
                reflectance: Rgb::splat(0.5),
            }),
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

/// `distribution`, `alpha` / `alpha_u` / `alpha_v` and `sample_visible`.
/// `distribution`, roughness and `sample_visible` of a microfacet model
/// whose sampling is visible-normal only (refuses `sample_visible=false`).
fn microfacet(props: &mut Props, loc: &Loc) -> Result<(MicrofacetKind, f32, f32), SceneError> {
    let (distribution, alpha_u, alpha_v, sample_visible) = microfacet_params(props, loc)?;
    if !sample_visible {
        return Err(err(
            loc,
            "sample_visible=false is not supported (visible-normal sampling only)",
        ));
    }
    Ok((distribution, alpha_u, alpha_v))
}

/// `distribution` (beckmann), `alpha` (0.1) or `alpha_u`+`alpha_v`, and
/// `sample_visible` (true), as Mitsuba 3's microfacet distributions read them.
fn microfacet_params(
    props: &mut Props,
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
    let alpha = props.opt_float("alpha")?;
    let au = props.opt_float("alpha_u")?;
    let av = props.opt_float("alpha_v")?;
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
    if !(alpha_u > 0.0 && alpha_v > 0.0) {
        return Err(err(loc, "alpha must be positive"));
    }
    let sample_visible = props.boolean("sample_visible", true)?;
    Ok((distribution, alpha_u, alpha_v, sample_visible))
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
