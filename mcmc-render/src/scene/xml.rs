//! Mitsuba 3 XML: reads a scene file into a tree of plugins and typed
//! parameters, resolving `<default>`, `$name` substitution and `<include>`.
//! A file whose root `version` is below 2.0.0 is upgraded as it is read
//! ([`super::upgrade`]).
//! Every element and attribute this module does not know is refused with
//! its file and line; what a plugin does with its parameters is decided by
//! [`super::loader`].

use super::SceneError;
use super::upgrade;
use crate::color::Rgb;
use glam::{Mat4, Vec3, Vec4};
use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A position in a scene file, for error messages.
#[derive(Clone, Debug)]
pub struct Loc {
    /// The file.
    pub file: Arc<PathBuf>,
    /// One-based line number.
    pub line: u32,
}

impl fmt::Display for Loc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.file.display(), self.line)
    }
}

/// A typed parameter value.
#[derive(Clone, Debug)]
pub enum Value {
    /// `<float>`.
    Float(f32),
    /// `<integer>`.
    Integer(i64),
    /// `<boolean>`.
    Boolean(bool),
    /// `<string>`.
    String(String),
    /// `<rgb>`.
    Rgb(Rgb),
    /// `<point>`.
    Point(Vec3),
    /// `<vector>`.
    Vector(Vec3),
    /// `<transform>`: the composed matrix.
    Transform(Mat4),
}

impl Value {
    /// The XML tag of this kind of value.
    pub fn tag(&self) -> &'static str {
        match self {
            Value::Float(_) => "float",
            Value::Integer(_) => "integer",
            Value::Boolean(_) => "boolean",
            Value::String(_) => "string",
            Value::Rgb(_) => "rgb",
            Value::Point(_) => "point",
            Value::Vector(_) => "vector",
            Value::Transform(_) => "transform",
        }
    }
}

/// A named parameter of a plugin.
#[derive(Clone, Debug)]
pub struct Param {
    /// The `name` attribute.
    pub name: String,
    /// The parsed value.
    pub value: Value,
    /// The `value` attribute as written (defaults substituted), for
    /// consumers that parse it at their own precision (integrator
    /// parameters take `<float>` as `f64`; [`Value::Float`] is `f32`).
    pub text: Option<String>,
    /// Where it was written.
    pub loc: Loc,
}

/// A plugin element (`<shape type="…">`, `<bsdf …>`, …).
#[derive(Clone, Debug)]
pub struct Plugin {
    /// Element name (`shape`, `bsdf`, `emitter`, …).
    pub tag: String,
    /// The `type` attribute.
    pub kind: String,
    /// The `id` attribute, if any.
    pub id: Option<String>,
    /// The `name` attribute, if any.
    pub name: Option<String>,
    /// Where it was written.
    pub loc: Loc,
    /// Typed parameters, in file order.
    pub params: Vec<Param>,
    /// Nested plugins and references, in file order.
    pub children: Vec<Child>,
}

/// A nested element of a plugin.
#[derive(Clone, Debug)]
pub enum Child {
    /// An inline plugin.
    Plugin(Plugin),
    /// `<ref id="…"/>`, optionally with `name="…"` (the parameter it
    /// sets, e.g. a scene-level texture as `reflectance`).
    Ref {
        /// The referenced id.
        id: String,
        /// The `name` attribute (upgraded like a parameter name), if any.
        name: Option<String>,
        /// Where it was written.
        loc: Loc,
    },
}

/// Element names that open a nested plugin.
const PLUGIN_TAGS: &[&str] = &[
    "shape",
    "bsdf",
    "emitter",
    "sensor",
    "film",
    "sampler",
    "rfilter",
    "integrator",
    "texture",
];

/// Maximum `<include>` nesting (guards against include cycles).
const MAX_INCLUDE_DEPTH: usize = 16;

/// Maximum `<include>`d files in all (an include graph that fans out would
/// otherwise be followed exponentially often).
const MAX_INCLUDES: usize = 1000;

/// Maximum nesting of plugin elements (real scenes nest three or four;
/// the walk is recursive, so an unbounded depth would overflow the stack).
const MAX_NESTING: usize = 32;

struct Parser {
    defaults: HashMap<String, String>,
    overrides: HashMap<String, String>,
    /// Files included so far.
    includes: usize,
    /// The file being read is a Mitsuba 0.x file, upgraded as it is read.
    legacy: bool,
}

/// Parses a scene file. `overrides` are `$name` values that win over the
/// file's `<default>` elements (Mitsuba's `-D name=value`).
pub fn parse_file(
    path: &Path,
    overrides: &HashMap<String, String>,
) -> Result<Vec<Child>, SceneError> {
    let mut parser = Parser {
        defaults: HashMap::new(),
        overrides: overrides.clone(),
        includes: 0,
        legacy: false,
    };
    let mut out = Vec::new();
    parser.parse_scene_file(path, 0, &mut out)?;
    Ok(out)
}

/// Parses a scene given as a string (the embedded default scene); `base`
/// names it in messages and anchors relative paths.
pub fn parse_str(text: &str, base: &Path) -> Result<Vec<Child>, SceneError> {
    let mut parser = Parser {
        defaults: HashMap::new(),
        overrides: HashMap::new(),
        includes: 0,
        legacy: false,
    };
    let mut out = Vec::new();
    parser.parse_scene_text(text, base, 0, &mut out)?;
    Ok(out)
}

fn err(loc: &Loc, msg: impl Into<String>) -> SceneError {
    SceneError::At {
        location: loc.to_string(),
        message: msg.into(),
    }
}

impl Parser {
    fn parse_scene_file(
        &mut self,
        path: &Path,
        depth: usize,
        out: &mut Vec<Child>,
    ) -> Result<(), SceneError> {
        crate::resources::regular_file(path).map_err(SceneError::Invalid)?;
        let text = std::fs::read_to_string(path).map_err(|e| SceneError::Io {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        self.parse_scene_text(&text, path, depth, out)
    }

    fn parse_scene_text(
        &mut self,
        text: &str,
        path: &Path,
        depth: usize,
        out: &mut Vec<Child>,
    ) -> Result<(), SceneError> {
        let file = Arc::new(path.to_path_buf());
        let doc = roxmltree::Document::parse(text).map_err(|e| SceneError::At {
            location: format!("{}:{}", path.display(), e.pos().row),
            message: format!("malformed XML: {e}"),
        })?;
        let root = doc.root_element();
        let loc = loc_of(&doc, root, &file);
        if root.tag_name().name() != "scene" {
            return Err(err(
                &loc,
                format!(
                    "the root element must be <scene>, found <{}>",
                    root.tag_name().name()
                ),
            ));
        }
        check_attrs(root, &["version"], &loc)?;
        // Each file is upgraded by its own version (an included file too).
        let outer = self.legacy;
        self.legacy = match root.attribute("version") {
            Some(v) => upgrade::is_legacy(v).map_err(|e| err(&loc, e))?,
            None => false,
        };
        self.scene_children(&doc, root, path, depth, out)?;
        self.legacy = outer;
        Ok(())
    }

    fn scene_children(
        &mut self,
        doc: &roxmltree::Document,
        root: roxmltree::Node,
        path: &Path,
        depth: usize,
        out: &mut Vec<Child>,
    ) -> Result<(), SceneError> {
        let file = Arc::new(path.to_path_buf());
        for node in root.children().filter(|n| n.is_element()) {
            let loc = loc_of(doc, node, &file);
            match node.tag_name().name() {
                "default" => {
                    check_attrs(node, &["name", "value"], &loc)?;
                    let name = req_attr(node, "name", &loc)?.to_string();
                    let value = req_attr(node, "value", &loc)?.to_string();
                    self.defaults.entry(name).or_insert(value);
                }
                "include" => {
                    check_attrs(node, &["filename"], &loc)?;
                    let name = self.attr(node, "filename", &loc)?;
                    if depth + 1 > MAX_INCLUDE_DEPTH {
                        return Err(err(&loc, "<include> nested too deeply (cycle?)"));
                    }
                    self.includes += 1;
                    if self.includes > MAX_INCLUDES {
                        return Err(err(
                            &loc,
                            format!(
                                "more than {MAX_INCLUDES} <include>d files in all (an include graph that fans out?)"
                            ),
                        ));
                    }
                    let target = path.parent().unwrap_or_else(|| Path::new(".")).join(name);
                    self.parse_scene_file(&target, depth + 1, out)?;
                }
                "ref" => {
                    return Err(err(&loc, "<ref> is only allowed inside a plugin"));
                }
                tag if PLUGIN_TAGS.contains(&tag) => {
                    out.push(Child::Plugin(self.plugin(doc, node, &file, 1)?));
                }
                other => {
                    return Err(err(
                        &loc,
                        format!("unsupported element <{other}> in <scene>"),
                    ));
                }
            }
        }
        Ok(())
    }

    /// An attribute value after `$name` substitution.
    fn attr(&self, node: roxmltree::Node, name: &str, loc: &Loc) -> Result<String, SceneError> {
        let raw = req_attr(node, name, loc)?;
        self.substitute(raw, loc)
    }

    fn opt_attr(
        &self,
        node: roxmltree::Node,
        name: &str,
        loc: &Loc,
    ) -> Result<Option<String>, SceneError> {
        node.attribute(name)
            .map(|raw| self.substitute(raw, loc))
            .transpose()
    }

    fn substitute(&self, raw: &str, loc: &Loc) -> Result<String, SceneError> {
        if !raw.contains('$') {
            return Ok(raw.to_string());
        }
        let mut out = String::with_capacity(raw.len());
        let mut rest = raw;
        while let Some(pos) = rest.find('$') {
            out.push_str(&rest[..pos]);
            let after = &rest[pos + 1..];
            let len = after
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(after.len());
            let name = &after[..len];
            if name.is_empty() {
                return Err(err(loc, format!("stray '$' in attribute value \"{raw}\"")));
            }
            let value = self
                .overrides
                .get(name)
                .or_else(|| self.defaults.get(name))
                .ok_or_else(|| {
                    err(
                        loc,
                        format!("${name} is not defined (no <default name=\"{name}\">)"),
                    )
                })?;
            out.push_str(value);
            rest = &after[len..];
        }
        out.push_str(rest);
        Ok(out)
    }

    /// Plugin element `node`, at `nesting` levels below `<scene>`.
    fn plugin(
        &self,
        doc: &roxmltree::Document,
        node: roxmltree::Node,
        file: &Arc<PathBuf>,
        nesting: usize,
    ) -> Result<Plugin, SceneError> {
        let loc = loc_of(doc, node, file);
        if nesting > MAX_NESTING {
            return Err(err(
                &loc,
                format!("plugins nested more than {MAX_NESTING} deep"),
            ));
        }
        let tag = node.tag_name().name().to_string();
        check_attrs(node, &["type", "id", "name"], &loc)?;
        let kind = self.attr(node, "type", &loc)?;
        let mut plugin = Plugin {
            tag,
            kind,
            id: self.opt_attr(node, "id", &loc)?,
            name: self
                .opt_attr(node, "name", &loc)?
                .map(|n| self.upgrade_name(&n)),
            loc,
            params: Vec::new(),
            children: Vec::new(),
        };
        for child in node.children().filter(|n| n.is_element()) {
            let loc = loc_of(doc, child, file);
            let ctag = child.tag_name().name();
            match ctag {
                "ref" => {
                    check_attrs(child, &["id", "name"], &loc)?;
                    let name = self
                        .opt_attr(child, "name", &loc)?
                        .map(|n| self.param_name(&plugin, &n));
                    plugin.children.push(Child::Ref {
                        id: self.attr(child, "id", &loc)?,
                        name,
                        loc,
                    });
                }
                t if PLUGIN_TAGS.contains(&t) => {
                    let mut nested = self.plugin(doc, child, file, nesting + 1)?;
                    // A nested plugin's name is a parameter name too.
                    nested.name = nested.name.map(|n| self.param_name(&plugin, &n));
                    plugin.children.push(Child::Plugin(nested));
                }
                "float" | "integer" | "boolean" | "string" | "rgb" | "point" | "vector"
                | "transform" | "spectrum" => self.param(&mut plugin, child, ctag, loc)?,
                // Mitsuba 0.6's gamma-encoded colour.
                "srgb" if self.legacy => self.param(&mut plugin, child, ctag, loc)?,
                other => {
                    return Err(err(
                        &loc,
                        format!(
                            "unsupported element <{other}> in <{} type=\"{}\">",
                            plugin.tag, plugin.kind
                        ),
                    ));
                }
            }
        }
        if self.legacy {
            self.upgrade_uv_params(&mut plugin)?;
        }
        Ok(plugin)
    }

    /// Parameter element `node` (tag `tag`) of `plugin`.
    fn param(
        &self,
        plugin: &mut Plugin,
        node: roxmltree::Node,
        tag: &str,
        loc: Loc,
    ) -> Result<(), SceneError> {
        let name = self.param_name(plugin, &self.attr(node, "name", &loc)?);
        if plugin.params.iter().any(|p| p.name == name) {
            return Err(err(&loc, format!("parameter '{name}' given twice")));
        }
        let value = self.value(node, tag, &loc)?;
        let text = self
            .attr(node, "value", &loc)
            .ok()
            .map(|t| t.trim().to_string());
        plugin.params.push(Param {
            name,
            value,
            text,
            loc,
        });
        Ok(())
    }

    /// A `name` attribute as Mitsuba 3 reads it (snake_case in a 0.x file).
    fn upgrade_name(&self, name: &str) -> String {
        if self.legacy {
            upgrade::snake_case(name)
        } else {
            name.to_string()
        }
    }

    /// A parameter's name as Mitsuba 3 reads it: in a 0.x file snake_case,
    /// and a `diffuse` BSDF's `diffuse_reflectance` is its `reflectance`.
    fn param_name(&self, plugin: &Plugin, name: &str) -> String {
        let name = self.upgrade_name(name);
        if self.legacy
            && plugin.tag == "bsdf"
            && plugin.kind == "diffuse"
            && name == "diffuse_reflectance"
        {
            "reflectance".into()
        } else {
            name
        }
    }

    /// Mitsuba 0.x `uoffset`, `voffset`, `uscale`, `vscale` floats become
    /// one `to_uv` transform, written where the first of them was.
    fn upgrade_uv_params(&self, plugin: &mut Plugin) -> Result<(), SceneError> {
        let Some(first) = plugin
            .params
            .iter()
            .position(|p| upgrade::UV_PARAMS.contains(&p.name.as_str()))
        else {
            return Ok(());
        };
        let loc = plugin.params[first].loc.clone();
        if plugin.params.iter().any(|p| p.name == "to_uv") {
            return Err(err(
                &loc,
                "uoffset/voffset/uscale/vscale given together with to_uv",
            ));
        }
        let (mut offset, mut scale) = ([0.0; 2], [1.0; 2]);
        let mut kept = Vec::with_capacity(plugin.params.len());
        for p in plugin.params.drain(..) {
            let slot = match p.name.as_str() {
                "uoffset" => &mut offset[0],
                "voffset" => &mut offset[1],
                "uscale" => &mut scale[0],
                "vscale" => &mut scale[1],
                _ => {
                    kept.push(p);
                    continue;
                }
            };
            *slot = match p.value {
                Value::Float(v) => v,
                _ => return Err(err(&p.loc, format!("'{}' must be a <float>", p.name))),
            };
        }
        kept.insert(
            first,
            Param {
                name: "to_uv".into(),
                value: Value::Transform(upgrade::to_uv(offset, scale)),
                text: None,
                loc,
            },
        );
        plugin.params = kept;
        Ok(())
    }

    fn value(&self, node: roxmltree::Node, tag: &str, loc: &Loc) -> Result<Value, SceneError> {
        if tag != "transform" {
            check_leaf(node, loc)?;
        }
        match tag {
            "float" => {
                check_attrs(node, &["name", "value"], loc)?;
                Ok(Value::Float(parse_f32(
                    &self.attr(node, "value", loc)?,
                    loc,
                )?))
            }
            "integer" => {
                check_attrs(node, &["name", "value"], loc)?;
                let s = self.attr(node, "value", loc)?;
                let v = s
                    .trim()
                    .parse::<i64>()
                    .map_err(|_| err(loc, format!("'{s}' is not an integer")))?;
                Ok(Value::Integer(v))
            }
            "boolean" => {
                check_attrs(node, &["name", "value"], loc)?;
                let s = self.attr(node, "value", loc)?;
                match s.trim() {
                    "true" => Ok(Value::Boolean(true)),
                    "false" => Ok(Value::Boolean(false)),
                    _ => Err(err(loc, format!("'{s}' is not a boolean (true|false)"))),
                }
            }
            "string" => {
                check_attrs(node, &["name", "value"], loc)?;
                Ok(Value::String(self.attr(node, "value", loc)?))
            }
            "srgb" => {
                check_attrs(node, &["name", "value"], loc)?;
                let text = self.attr(node, "value", loc)?;
                Ok(Value::Rgb(upgrade::srgb(&text).map_err(|e| err(loc, e))?))
            }
            "spectrum" => {
                check_attrs(node, &["name", "value"], loc)?;
                let text = self.attr(node, "value", loc)?;
                Ok(Value::Rgb(
                    upgrade::spectrum(&text, self.legacy).map_err(|e| err(loc, e))?,
                ))
            }
            "rgb" => {
                check_attrs(node, &["name", "value"], loc)?;
                let v = parse_list(&self.attr(node, "value", loc)?, loc)?;
                match v.as_slice() {
                    [x] => Ok(Value::Rgb(Rgb::splat(*x))),
                    [r, g, b] => Ok(Value::Rgb(Rgb::new(*r, *g, *b))),
                    _ => Err(err(loc, "<rgb> needs one or three numbers")),
                }
            }
            "point" | "vector" => {
                check_attrs(node, &["name", "value", "x", "y", "z"], loc)?;
                let v = self.xyz(node, loc, 0.0)?;
                Ok(if tag == "point" {
                    Value::Point(v)
                } else {
                    Value::Vector(v)
                })
            }
            "transform" => {
                check_attrs(node, &["name"], loc)?;
                let mut m = Mat4::IDENTITY;
                for op in node.children().filter(|n| n.is_element()) {
                    let oloc = Loc {
                        file: loc.file.clone(),
                        line: line_of(op),
                    };
                    // Each operation is applied after the ones before it.
                    m = self.transform_op(op, &oloc)? * m;
                }
                Ok(Value::Transform(m))
            }
            _ => unreachable!("value() called with a checked tag"),
        }
    }

    /// Reads `x`/`y`/`z` attributes or a `value` list (one number broadcasts).
    fn xyz(&self, node: roxmltree::Node, loc: &Loc, default: f32) -> Result<Vec3, SceneError> {
        if let Some(v) = self.opt_attr(node, "value", loc)? {
            let v = parse_list(&v, loc)?;
            return match v.as_slice() {
                [x] => Ok(Vec3::splat(*x)),
                [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
                _ => Err(err(loc, "expected one or three numbers")),
            };
        }
        let mut out = Vec3::splat(default);
        for (i, a) in ["x", "y", "z"].iter().enumerate() {
            if let Some(s) = self.opt_attr(node, a, loc)? {
                out[i] = parse_f32(&s, loc)?;
            }
        }
        Ok(out)
    }

    fn vec_attr(&self, node: roxmltree::Node, name: &str, loc: &Loc) -> Result<Vec3, SceneError> {
        let v = parse_list(&self.attr(node, name, loc)?, loc)?;
        match v.as_slice() {
            [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
            _ => Err(err(loc, format!("'{name}' needs three numbers"))),
        }
    }

    fn transform_op(&self, op: roxmltree::Node, loc: &Loc) -> Result<Mat4, SceneError> {
        check_leaf(op, loc)?;
        let tag = match op.tag_name().name() {
            "lookAt" if self.legacy => "lookat",
            t => t,
        };
        match tag {
            "translate" => {
                check_attrs(op, &["x", "y", "z", "value"], loc)?;
                Ok(Mat4::from_translation(self.xyz(op, loc, 0.0)?))
            }
            "scale" => {
                check_attrs(op, &["x", "y", "z", "value"], loc)?;
                Ok(Mat4::from_scale(self.xyz(op, loc, 1.0)?))
            }
            "rotate" => {
                check_attrs(op, &["x", "y", "z", "value", "angle"], loc)?;
                let axis = self.xyz(op, loc, 0.0)?;
                let angle = parse_f32(&self.attr(op, "angle", loc)?, loc)?;
                if axis.length_squared() == 0.0 || !axis.is_finite() {
                    return Err(err(loc, "<rotate> needs a non-zero axis"));
                }
                Ok(Mat4::from_axis_angle(axis.normalize(), angle.to_radians()))
            }
            "matrix" => {
                check_attrs(op, &["value"], loc)?;
                let v = parse_list(&self.attr(op, "value", loc)?, loc)?;
                match v.len() {
                    16 => Ok(Mat4::from_cols(
                        Vec4::new(v[0], v[4], v[8], v[12]),
                        Vec4::new(v[1], v[5], v[9], v[13]),
                        Vec4::new(v[2], v[6], v[10], v[14]),
                        Vec4::new(v[3], v[7], v[11], v[15]),
                    )),
                    9 => Ok(Mat4::from_cols(
                        Vec4::new(v[0], v[3], v[6], 0.0),
                        Vec4::new(v[1], v[4], v[7], 0.0),
                        Vec4::new(v[2], v[5], v[8], 0.0),
                        Vec4::W,
                    )),
                    _ => Err(err(loc, "<matrix> needs 16 (or 9) numbers, row-major")),
                }
            }
            "lookat" => {
                check_attrs(op, &["origin", "target", "up"], loc)?;
                let origin = self.vec_attr(op, "origin", loc)?;
                let target = self.vec_attr(op, "target", loc)?;
                let up = if op.attribute("up").is_some() {
                    self.vec_attr(op, "up", loc)?
                } else {
                    Vec3::Y
                };
                look_at(origin, target, up).ok_or_else(|| {
                    err(
                        loc,
                        "<lookat> is degenerate (origin equals target, or up is parallel to the view)",
                    )
                })
            }
            other => Err(err(
                loc,
                format!("unsupported element <{other}> in <transform>"),
            )),
        }
    }
}

/// Mitsuba's look-at frame: columns (left, up, forward, origin), so the
/// camera looks down its local +z with +y up.
pub fn look_at(origin: Vec3, target: Vec3, up: Vec3) -> Option<Mat4> {
    let dir = (target - origin).try_normalize()?;
    let left = up.normalize_or_zero().cross(dir).try_normalize()?;
    let new_up = dir.cross(left);
    Some(Mat4::from_cols(
        left.extend(0.0),
        new_up.extend(0.0),
        dir.extend(0.0),
        origin.extend(1.0),
    ))
}

fn line_of(node: roxmltree::Node) -> u32 {
    node.document().text_pos_at(node.range().start).row
}

fn loc_of(_doc: &roxmltree::Document, node: roxmltree::Node, file: &Arc<PathBuf>) -> Loc {
    Loc {
        file: file.clone(),
        line: line_of(node),
    }
}

fn req_attr<'a>(
    node: roxmltree::Node<'a, '_>,
    name: &str,
    loc: &Loc,
) -> Result<&'a str, SceneError> {
    node.attribute(name).ok_or_else(|| {
        err(
            loc,
            format!(
                "<{}> is missing the '{name}' attribute",
                node.tag_name().name()
            ),
        )
    })
}

/// Refuses children (elements or text) inside an element that takes none
/// — parameter tags and transform operations — instead of ignoring them.
fn check_leaf(node: roxmltree::Node, loc: &Loc) -> Result<(), SceneError> {
    let tag = node.tag_name().name();
    for child in node.children() {
        if child.is_element() {
            return Err(err(
                &Loc {
                    file: loc.file.clone(),
                    line: line_of(child),
                },
                format!(
                    "unexpected <{}> inside <{tag}> (it takes no child elements)",
                    child.tag_name().name()
                ),
            ));
        }
        if child.is_text() && child.text().is_some_and(|t| !t.trim().is_empty()) {
            return Err(err(
                loc,
                format!("unexpected text inside <{tag}> (values go in attributes)"),
            ));
        }
    }
    Ok(())
}

fn check_attrs(node: roxmltree::Node, allowed: &[&str], loc: &Loc) -> Result<(), SceneError> {
    for a in node.attributes() {
        if !allowed.contains(&a.name()) {
            return Err(err(
                loc,
                format!(
                    "unsupported attribute '{}' on <{}>",
                    a.name(),
                    node.tag_name().name()
                ),
            ));
        }
    }
    Ok(())
}

fn parse_f32(s: &str, loc: &Loc) -> Result<f32, SceneError> {
    let v = s
        .trim()
        .parse::<f32>()
        .map_err(|_| err(loc, format!("'{s}' is not a number")))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(err(loc, format!("'{s}' is not a finite number")))
    }
}

/// Numbers separated by commas and/or whitespace.
fn parse_list(s: &str, loc: &Loc) -> Result<Vec<f32>, SceneError> {
    s.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|t| !t.is_empty())
        .map(|t| parse_f32(t, loc))
        .collect()
}
