//! The path state: a light path `x_0 … x_k` (emitter to camera) with its
//! measurement contribution `f(x)`, the scalar target `I(x) = lum f(x)`,
//! the raster position it lands on, and per vertex the area densities with
//! which a light walk and a camera walk would produce it.
//!
//! # Measure and contribution
//!
//! Paths live in Veach's path space: the product of the area measures at
//! the vertices, with two conventions the rest of the renderer uses too
//! (pbrt-v4's, BDPT's [`Vertex`] densities):
//!
//! - the **camera vertex** `x_k` (the pinhole, or a point on the thin lens)
//!   is measured with the lens's *probability* measure (density 1 for any
//!   sampler, a Dirac point for the pinhole), and the camera's importance is
//!   the density of the raster position being uniform over the image, so
//!   that `f(x)` splatted at the path's raster position, times the number of
//!   pixels, is the image (as PSSMLT's splats are);
//! - an **emitter at infinity** (environment, `constant`, directional
//!   light) makes `x_0` a [`VertexKind::Infinite`] vertex, a direction
//!   `ω = x_0.wo` (from the scene towards the emitter) measured in **solid
//!   angle** (pbrt-v4's and Mitsuba 0.6's convention; a directional light's
//!   one direction with the counting measure, as a point light's position).
//!   The edge `x_0 x_1` then has no area factor (`G` is 1: the solid angle
//!   at `x_0` is the measure itself, and the cosine at `x_1` is its
//!   scattering term's), `L_e` is the environment's radiance along `ω` (a
//!   directional light's irradiance), and every density of `x_0` is per
//!   unit solid angle: `pdf_fwd(x_0)` = selection × the environment's
//!   direction density (selection alone for a directional light),
//!   `pdf_rev(x_0)` = the camera walk's solid-angle density at `x_1` (or
//!   the camera's). A light walk from `x_0` starts on the disk of radius
//!   `R` perpendicular to `ω` ([`crate::light::Lights::infinite_origin`]),
//!   so `pdf_fwd(x_1) = |ng_1·ω| / (πR²)`, an area density, and a ratio of
//!   two paths' densities is formed vertex by vertex in the same measure
//!   (solid angle at `x_0`, area elsewhere). Only `x_0` may be at
//!   infinity; a path with a vertex at infinity elsewhere carries nothing;
//! - at a vertex that scatters through a **Dirac lobe** (mirror, smooth
//!   dielectric, smooth plastic's coating; [`Vertex::delta`]) `f` and the
//!   densities hold the *coefficients* of the Dirac distribution: the lobe's
//!   value `c = weight · P` from [`crate::bsdf::Bsdf::sample`] and its
//!   selection probability `P`, which cancel in every ratio a mutation forms.
//!
//! With `w` unit directions, `ng`/`ns` geometric/shading normals, and the
//! radiance-mode BSDF `f_s(→camera, →light)`:
//!
//! ```text
//! f(x) = L_e(x_0→x_1) · Π_{i<k} |ng_i·w_{i,i+1}| / d²_{i,i+1}           (no cosine at a point light; 1 after x_0 at infinity)
//!      · Π_{0<i<k} f_s(x_i) |ns_i·w_{i→i−1}|                             (c_rad at Dirac vertices)
//!      · W(x_k→x_{k−1})                                                 (the camera's solid-angle density)
//! ```
//!
//! which is the path tracer's estimate times its density: `f / p_{0,k+1}`
//! is exactly PT's throughput, and for every bidirectional split `f / p_s`
//! is BDPT's unweighted contribution. Visibility is *not* evaluated by
//! [`Path::evaluate`]: a path is built from traced walks (visible by
//! construction) and at most one connection, which its builder tests with
//! [`Path::edge_visible`].
//!
//! # Densities
//!
//! [`Path::vertices`] are BDPT's [`Vertex`] values, light to camera, with
//! these meanings (written by [`Path::evaluate`]):
//!
//! - `pdf_fwd` of `x_i`: area density with which a **light walk** produces
//!   `x_i` (from `x_{i−1}`, having arrived from `x_{i−2}`); `x_0`: the
//!   emitter point's density (selection × area); `x_k`: 0 (light walks never
//!   hit the camera, as in BDPT);
//! - `pdf_rev` of `x_i`: area density with which a **camera walk** produces
//!   `x_i` (from `x_{i+1}`, having arrived from `x_{i+2}`); `x_k`: 1 (the
//!   lens convention above); `x_0`: the density of the camera walk hitting
//!   the emitter (0 for point lights);
//! - `delta`: `x_i` scatters through a Dirac lobe;
//! - `wo`: unit direction from `x_i` towards `x_{i+1}` (zero at `x_k`);
//! - `beta` and `raster` are not used by path states (white, zero).
//!
//! At a Dirac vertex a camera walk's density is the lobe probability; a
//! light walk's is the lobe probability times `lum(c_rad |ng·w_c| /
//! |ng·w_l|) / lum(c_imp · shading correction)`, the change of variables
//! between the importance-mode and radiance-mode Dirac distributions
//! (it is 1 for mirrors and corrects refraction's η²), so that `f / p` is
//! BDPT's light-walk throughput there too.
//!
//! A regrowth of vertices `first..=last` with `s` of them from the light
//! side has density [`Path::log_regrowth_density`]: the product of those
//! vertices' `pdf_fwd` (light part) and `pdf_rev` (camera part), zero when
//! the connection between the parts touches a Dirac vertex or a delta
//! emitter. The bidirectional mutation's `T(x→y)` and the start-up's
//! reference density are sums of these.

use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::geometry::Ray;
use crate::integrators::path_vertex::{Vertex, VertexKind, shading_correction};
use crate::light::Light;
use crate::pss::{PathSample, Splat};
use crate::scene::Scene;
use glam::{Vec2, Vec3};
use mcmc_core::target::{Evaluation, Target};

/// Words per vertex of [`Path::to_words`].
pub const VERTEX_WORDS: usize = 14;

/// A light path `x_0` (on an emitter) … `x_k` (the camera) in a scene,
/// with its contribution and the densities mutations need (see the module
/// docs).
///
/// The path holds its scene: `mcmc-core` kernels see only states, and a
/// mutation traces rays in the scene of the path it mutates.
#[derive(Clone)]
pub struct Path<'s> {
    /// The scene the path lies in.
    pub scene: &'s Scene,
    /// The vertices, light to camera: `x_0` has kind [`VertexKind::Light`]
    /// (or [`VertexKind::Infinite`] on an emitter at infinity), `x_k` kind
    /// [`VertexKind::Camera`], the others
    /// [`VertexKind::Surface`]. Field meanings as in the module docs.
    pub vertices: Vec<Vertex>,
    /// `f(x)`, RGB (zero when the path carries nothing or is malformed).
    pub contribution: Rgb,
    /// Raster position where the camera sees `x_{k−1}` (zero when outside).
    pub raster: Vec2,
}

impl std::fmt::Debug for Path<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Path")
            .field("vertices", &self.vertices)
            .field("contribution", &self.contribution)
            .field("raster", &self.raster)
            .finish_non_exhaustive()
    }
}

impl<'s> Path<'s> {
    /// An empty path in `scene` (zero contribution).
    pub fn new(scene: &'s Scene) -> Self {
        Path {
            scene,
            vertices: Vec::new(),
            contribution: Rgb::BLACK,
            raster: Vec2::ZERO,
        }
    }

    /// Builds and evaluates the path `light` followed by `camera` reversed:
    /// `light` is a light subpath (emitter first) and `camera` a camera
    /// subpath (camera first), as BDPT's walks write them; either may be
    /// empty as long as the path starts on an emitter and ends at the
    /// camera. The vertex on an emitter that starts the path becomes a
    /// [`VertexKind::Light`] vertex. Visibility of the joining edge is not
    /// tested (see [`Path::edge_visible`]).
    pub fn from_subpaths(scene: &'s Scene, light: &[Vertex], camera: &[Vertex]) -> Self {
        let mut path = Path::new(scene);
        path.assign_subpaths(light, camera);
        path
    }

    /// [`Path::from_subpaths`] into an existing path, reusing its storage.
    pub fn assign_subpaths(&mut self, light: &[Vertex], camera: &[Vertex]) {
        self.vertices.clear();
        self.vertices.extend_from_slice(light);
        self.vertices.extend(camera.iter().rev().copied());
        self.normalize_ends();
        self.evaluate();
    }

    /// Gives the end vertices their path-state kinds: an emitter point hit
    /// by a camera walk becomes the path's light vertex.
    pub fn normalize_ends(&mut self) {
        let scene = self.scene;
        if let Some(first) = self.vertices.first_mut()
            && first.kind == VertexKind::Surface
            && first.is_light()
        {
            *first = Vertex::light(scene, first.light, first.sp, Rgb::WHITE, 0.0);
        }
    }

    /// Appends the path's exact encoding to `out`, for checkpoints of its
    /// chain ([`crate::markov::checkpoint`]): the vertex count, then per
    /// vertex [`VERTEX_WORDS`] words holding every field bit for bit (24
    /// `f32` two to a word, the shape and primitive, the emitter, the kind
    /// and `delta`), then `f(x)` and the raster position.
    ///
    /// Why every field and not fewer: a path-space state is the outcome
    /// of its chain's whole history (unlike a primary-sample point, it is
    /// not a function of a few stored random numbers), and its derived
    /// fields (densities, directions, `f`) are read by the next mutation;
    /// storing them makes the decoded state the saved one by construction,
    /// and [`Path::from_words`] checks them against a re-evaluation.
    pub fn to_words(&self, out: &mut Vec<u64>) {
        let pair = |a: f32, b: f32| u64::from(a.to_bits()) | u64::from(b.to_bits()) << 32;
        out.push(self.vertices.len() as u64);
        for v in &self.vertices {
            let sp = &v.sp;
            let floats = [
                sp.p.x, sp.p.y, sp.p.z, sp.p_err.x, sp.p_err.y, sp.p_err.z, sp.ng.x, sp.ng.y,
                sp.ng.z, sp.ns.x, sp.ns.y, sp.ns.z, sp.uv.x, sp.uv.y, v.wo.x, v.wo.y, v.wo.z,
                v.beta.r, v.beta.g, v.beta.b, v.pdf_fwd, v.pdf_rev, v.raster.x, v.raster.y,
            ];
            out.extend(floats.chunks_exact(2).map(|c| pair(c[0], c[1])));
            let kind = match v.kind {
                VertexKind::Camera => 0,
                VertexKind::Light => 1,
                VertexKind::Surface => 2,
                VertexKind::Infinite => 3,
            };
            out.push(u64::from(sp.shape) | u64::from(sp.prim) << 32);
            out.push(u64::from(v.light) | (kind | u64::from(v.delta) << 8) << 32);
        }
        let c = self.contribution;
        out.extend([
            pair(c.r, c.g),
            pair(c.b, self.raster.x),
            u64::from(self.raster.y.to_bits()),
        ]);
    }

    /// The path [`Path::to_words`] wrote at the front of `input` (advanced
    /// past it), in `scene`; `None` when the words are not a path of
    /// `scene` that its own evaluation reproduces: at least two vertices,
    /// an emitter first and the camera last, kinds, emitters and shapes
    /// that exist (a surface vertex on a shape, an emitter vertex on an
    /// emitter), finite positions, normals, UVs and directions at
    /// infinity, and every derived field (densities, directions, `f`,
    /// raster position) equal, bit for bit, to what [`Path::evaluate`]
    /// gives — a forged or foreign state is refused before a mutation
    /// reads it.
    pub fn from_words(scene: &'s Scene, input: &mut &[u64]) -> Option<Path<'s>> {
        let (&n, rest) = input.split_first()?;
        let n = usize::try_from(n).ok()?;
        let len = n.checked_mul(VERTEX_WORDS)?.checked_add(3)?;
        if n < 2 || rest.len() < len {
            return None;
        }
        let (words, rest) = rest.split_at(len);
        let lo = |w: u64| f32::from_bits(w as u32);
        let hi = |w: u64| f32::from_bits((w >> 32) as u32);
        let mut vertices = Vec::with_capacity(n);
        for (i, w) in words.chunks_exact(VERTEX_WORDS).enumerate() {
            let f: Vec<f32> = w[..12].iter().flat_map(|&x| [lo(x), hi(x)]).collect();
            let v3 = |i: usize| Vec3::new(f[i], f[i + 1], f[i + 2]);
            let (shape, prim) = (w[12] as u32, (w[12] >> 32) as u32);
            let (light, flags) = (w[13] as u32, w[13] >> 32);
            let kind = match (flags & 0xff, i) {
                (1, 0) => VertexKind::Light,
                (3, 0) => VertexKind::Infinite,
                (0, _) if i + 1 == n => VertexKind::Camera,
                (2, _) if i > 0 && i + 1 < n => VertexKind::Surface,
                _ => return None,
            };
            let delta = match flags >> 8 {
                0 => false,
                1 => true,
                _ => return None,
            };
            let shape_ok = (shape as usize) < scene.shapes.len()
                || (shape == u32::MAX && kind != VertexKind::Surface);
            let light_ok = (light as usize) < scene.lights.lights.len()
                || (light == crate::integrators::path_vertex::NO_LIGHT
                    && !matches!(kind, VertexKind::Light | VertexKind::Infinite));
            // Positions, normals, UVs and `ω` at infinity are not derived
            // (the evaluation checks the rest): a genuine state's are finite.
            if !(shape_ok && light_ok && f[..17].iter().all(|x| x.is_finite())) {
                return None;
            }
            vertices.push(Vertex {
                kind,
                sp: crate::geometry::SurfacePoint {
                    p: v3(0),
                    p_err: v3(3),
                    ng: v3(6),
                    ns: v3(9),
                    uv: Vec2::new(f[12], f[13]),
                    shape,
                    prim,
                },
                wo: v3(14),
                beta: Rgb::new(f[17], f[18], f[19]),
                pdf_fwd: f[20],
                pdf_rev: f[21],
                delta,
                light,
                raster: Vec2::new(f[22], f[23]),
            });
        }
        let tail = &words[n * VERTEX_WORDS..];
        let path = Path {
            scene,
            vertices,
            contribution: Rgb::new(lo(tail[0]), hi(tail[0]), lo(tail[1])),
            raster: Vec2::new(hi(tail[1]), lo(tail[2])),
        };
        // Every derived field as the evaluation gives it (which is how
        // every state a chain holds was made).
        let mut again = path.clone();
        again.evaluate();
        let mut check = Vec::with_capacity(words.len() + 1);
        again.to_words(&mut check);
        if check[1..] != *words {
            return None;
        }
        *input = rest;
        Some(path)
    }

    /// Number of vertices `k + 1`.
    pub fn len(&self) -> usize {
        self.vertices.len()
    }

    /// True for a path without vertices.
    pub fn is_empty(&self) -> bool {
        self.vertices.is_empty()
    }

    /// Number of segments `k` (the depth, as `max_depth` counts it).
    pub fn segments(&self) -> usize {
        self.vertices.len().saturating_sub(1)
    }

    /// The scalar target `I(x) = lum f(x)`, as the splat's luminance.
    pub fn luminance(&self) -> f64 {
        self.contribution.luminance() as f64
    }

    /// `ln I(x)`: `−∞` for a path that carries nothing, NaN for a NaN or
    /// infinite contribution (which `mcmc-core` rejects and counts).
    pub fn log_density(&self) -> f64 {
        let i = self.luminance();
        if !self.contribution.is_finite() || !i.is_finite() {
            f64::NAN
        } else if i > 0.0 {
            i.ln()
        } else {
            f64::NEG_INFINITY
        }
    }

    /// True for a path `L S* E`: at least one segment, and every vertex
    /// between the emitter point and the camera scatters through a Dirac
    /// lobe (an emitter seen directly or through mirrors and glass). No
    /// bidirectional move can keep a vertex of such a path.
    pub fn is_specular_chain(&self) -> bool {
        let k = self.segments();
        k >= 1 && self.vertices[1..k].iter().all(|v| v.delta)
    }

    /// True for a path that no technique but the camera walk that hits
    /// the emitter can draw: no edge joins two vertices that do not
    /// scatter through a Dirac lobe (the emitter point and the camera count
    /// as such vertices), so no connection can make it. These are the
    /// specular chains ([`Path::is_specular_chain`], the emitter seen
    /// directly included) and the paths `L S+ (D S+)* E`, seen and lit
    /// only through mirrors and glass.
    pub fn is_unconnectable(&self) -> bool {
        let k = self.segments();
        let dirac = |i: usize| i > 0 && i < k && self.vertices[i].delta;
        self.is_specular_chain() || (k >= 2 && (0..k).all(|i| dirac(i) || dirac(i + 1)))
    }

    /// The payload the Markov-chain driver films: one splat of `f(x)` at
    /// the raster position, depth `k`.
    pub fn sample(&self) -> PathSample {
        PathSample {
            splats: vec![Splat {
                p: self.raster,
                l: self.contribution,
                class: 0,
            }],
            depth: self.segments() as u32,
        }
    }

    /// True when the segment `x_i x_{i+1}` is unoccluded (the camera's clip
    /// range is part of [`Path::evaluate`], which zeroes `f` outside it).
    pub fn edge_visible(&self, i: usize) -> bool {
        let scene = self.scene;
        let (a, b) = (&self.vertices[i], &self.vertices[i + 1]);
        if a.kind == VertexKind::Infinite {
            // `b` must see the emitter: nothing along `ω` (as a light
            // sample at infinity is tested, `Scene::light_visible`).
            let ray = if b.on_surface() {
                b.sp.spawn_ray(a.wo)
            } else {
                Ray::new(b.p(), a.wo)
            };
            return !scene.geometry.occluded(&ray);
        }
        if b.kind == VertexKind::Camera {
            return scene
                .geometry
                .segment_clear(a.sp.spawn_origin(b.p()), b.p());
        }
        scene.geometry.visible(&a.sp, &b.sp)
    }

    /// True when every segment is unoccluded (tests and start-up checks;
    /// mutations test only the edges they create).
    pub fn all_visible(&self) -> bool {
        (0..self.segments()).all(|i| self.edge_visible(i))
    }

    /// True when vertex `i` can end a deterministic connection: the camera,
    /// an emitter point, an emitter at infinity as `x_0` (the connection
    /// is then the direction `ω` itself), or a surface vertex that does not
    /// scatter through a Dirac lobe and whose BSDF has a non-Dirac part.
    /// (A camera walk never ends on a delta emitter: its `pdf_rev` is 0.)
    pub fn connectible(&self, i: usize) -> bool {
        let scene = self.scene;
        let v = &self.vertices[i];
        match v.kind {
            VertexKind::Camera => true,
            VertexKind::Light => true,
            VertexKind::Surface => !v.delta && !scene.bsdf_at(&v.sp).is_delta(),
            VertexKind::Infinite => i == 0,
        }
    }

    /// `ln` of the area density with which a bidirectional regrowth
    /// produces vertices `first..=last` (all others held fixed), `s` of
    /// them by a light walk (from `x_{first−1}`, or from the emitters when
    /// `first = 0`) and the rest by a camera walk (from `x_{last+1}`, or
    /// from the camera when `last = k`), joined by a connection. `−∞` when
    /// that split cannot produce the path: the connection touches a Dirac
    /// vertex, the light walk would have to hit the camera, or the camera
    /// walk a delta emitter.
    pub fn log_regrowth_density(&self, first: usize, last: usize, s: usize) -> f64 {
        let k = self.segments();
        if last > k || first > last + 1 || s > last + 1 - first {
            return f64::NEG_INFINITY;
        }
        let join = first + s; // first camera-walk vertex
        if join > k {
            // The light walk would produce the camera vertex.
            return f64::NEG_INFINITY;
        }
        if join > 0 && !(self.connectible(join - 1) && self.connectible(join)) {
            return f64::NEG_INFINITY;
        }
        let mut log_p = 0.0f64;
        for (i, v) in self.vertices.iter().enumerate().take(last + 1).skip(first) {
            let p = if i < join { v.pdf_fwd } else { v.pdf_rev };
            if !(p > 0.0) {
                return f64::NEG_INFINITY;
            }
            log_p += (p as f64).ln();
        }
        log_p
    }

    /// Recomputes the contribution, the raster position and every vertex's
    /// densities, directions and Dirac coefficients from the vertex
    /// positions, kinds, emitters and `delta` flags. Visibility is not
    /// tested. A malformed path (fewer than two vertices, wrong end kinds,
    /// a vertex at infinity other than `x_0`) gets a zero contribution.
    pub fn evaluate(&mut self) {
        let scene = self.scene;
        self.contribution = Rgb::BLACK;
        self.raster = Vec2::ZERO;
        let n = self.vertices.len();
        if n < 2 {
            return;
        }
        let k = n - 1;
        let vs = &mut self.vertices;
        for i in 0..n {
            vs[i].beta = Rgb::WHITE;
            vs[i].raster = Vec2::ZERO;
            // A vertex at infinity keeps its direction `ω` in `wo`.
            vs[i].wo = if vs[i].kind == VertexKind::Infinite {
                vs[i].wo
            } else if i < k {
                vs[i].direction_to(&vs[i + 1]).unwrap_or(Vec3::ZERO)
            } else {
                Vec3::ZERO
            };
        }
        for i in 0..n {
            let fwd = match i {
                0 => vs[0].pdf_light_origin(scene),
                _ if i == k => 0.0,
                1 => walk_density(scene, &vs[0], None, &vs[1], TransportMode::Importance),
                _ => walk_density(
                    scene,
                    &vs[i - 1],
                    Some(&vs[i - 2]),
                    &vs[i],
                    TransportMode::Importance,
                ),
            };
            let rev = if i == k {
                1.0
            } else if i == 0 && vs[0].is_delta_light(scene) {
                0.0
            } else if i + 1 == k {
                walk_density(scene, &vs[k], None, &vs[i], TransportMode::Radiance)
            } else {
                walk_density(
                    scene,
                    &vs[i + 1],
                    Some(&vs[i + 2]),
                    &vs[i],
                    TransportMode::Radiance,
                )
            };
            vs[i].pdf_fwd = fwd;
            vs[i].pdf_rev = rev;
        }
        if !matches!(vs[0].kind, VertexKind::Light | VertexKind::Infinite)
            || vs[k].kind != VertexKind::Camera
            || vs[1..].iter().any(|v| v.kind == VertexKind::Infinite)
        {
            return;
        }
        let Some(raster_dir) = vs[k].direction_to(&vs[k - 1]) else {
            return;
        };
        let raster = if vs[k - 1].kind == VertexKind::Infinite {
            // The environment seen directly: no clip distance applies (a
            // camera ray that escapes sees it, as path tracing's does).
            scene
                .camera
                .raster_of_ray(vs[k].p(), raster_dir)
                .map(|r| r.0)
        } else {
            scene
                .camera
                .connect(vs[k].p(), vs[k - 1].p())
                .map(|cs| cs.raster)
        };
        let Some(raster) = raster else {
            return;
        };
        let camera = scene.camera.pdf_we(vs[k].p(), raster_dir).1 as f64;
        let le = emitted(scene, &vs[0], &vs[1]);
        let mut f = [
            le.r as f64 * camera,
            le.g as f64 * camera,
            le.b as f64 * camera,
        ];
        let mut scale = 1.0f64;
        for i in 0..k {
            scale *= edge_factor(&vs[i], &vs[i + 1]);
        }
        for i in 1..k {
            let c = scattering(scene, &vs[i - 1], &vs[i], &vs[i + 1]);
            f[0] *= c.r as f64;
            f[1] *= c.g as f64;
            f[2] *= c.b as f64;
        }
        self.contribution = Rgb::new(
            (f[0] * scale) as f32,
            (f[1] * scale) as f32,
            (f[2] * scale) as f32,
        );
        self.raster = raster;
    }
}

/// `|ng_a · w| / d²` for the segment `a b` (no cosine at a vertex off any
/// surface): the area-measure factor of `f` on that edge, the cosine taken
/// at the light-side end (the camera-side end's is in its scattering term).
/// 1 from a vertex at infinity, which is measured in solid angle.
fn edge_factor(a: &Vertex, b: &Vertex) -> f64 {
    if a.kind == VertexKind::Infinite {
        return 1.0;
    }
    let d = b.p() - a.p();
    let d2 = d.length_squared() as f64;
    if !(d2 > 0.0) {
        return 0.0;
    }
    let cos = if a.on_surface() {
        (a.sp.ng.dot(d).abs() as f64) / d2.sqrt()
    } else {
        1.0
    };
    cos / d2
}

/// Radiance (area lights, environments), intensity (point lights) or
/// irradiance (directional lights) the path's emitter vertex `x0` sends
/// towards `x1`.
pub fn emitted(scene: &Scene, x0: &Vertex, x1: &Vertex) -> Rgb {
    if !x0.is_light() {
        return Rgb::BLACK;
    }
    if x0.kind == VertexKind::Infinite {
        return match &scene.lights.lights[x0.light as usize] {
            Light::Environment(env) => env.eval(x0.wo),
            Light::Directional { irradiance, .. } => *irradiance,
            Light::Area { .. } | Light::Point { .. } => Rgb::BLACK,
        };
    }
    let Some(w) = x0.direction_to(x1) else {
        return Rgb::BLACK;
    };
    match &scene.lights.lights[x0.light as usize] {
        Light::Area { .. } => scene.lights.area_radiance(x0.light, &x0.sp, w),
        Light::Point {
            intensity, spot, ..
        } => *intensity * spot.map_or(1.0, |s| s.falloff(w)),
        // Emitters at infinity are `Infinite` vertices (handled above).
        Light::Directional { .. } | Light::Environment(_) => Rgb::BLACK,
    }
}

/// The Dirac lobe of `v`'s BSDF that scatters world direction `wo` into
/// `wi`: its selection probability `P` and value coefficient `c = weight ·
/// P` in `mode`, or `None` when no Dirac lobe of the BSDF maps `wo` to `wi`
/// (to within 1e-4 in cosine).
pub fn dirac_lobe(
    scene: &Scene,
    v: &Vertex,
    wo: Vec3,
    wi: Vec3,
    mode: TransportMode,
) -> Option<(f32, Rgb)> {
    let frame = scene.shading_frame(&v.sp);
    let bsdf = scene.bsdf_at(&v.sp);
    let (lo, li) = (frame.to_local(wo), frame.to_local(wi));
    // In the walk's own mode: a normal or bump map's importance sampler
    // picks between two frames, which the radiance-mode inverse misses.
    let inverse = bsdf.invert_in(lo, li, 0.5, mode)?;
    let u_lobe = 0.5 * (inverse.u_lobe.0 + inverse.u_lobe.1);
    let bs = bsdf.sample(lo, u_lobe, (0.5, 0.5), mode)?;
    if !bs.is_delta || !(bs.pdf > 0.0) || bs.wi.dot(li) < 1.0 - 1e-4 {
        return None;
    }
    Some((bs.pdf, bs.weight * bs.pdf))
}

/// The scattering factor of `f` at surface vertex `v` between its
/// light-side neighbour `light` and camera-side neighbour `camera`:
/// `f_s(→camera, →light) |ns·w_light|` in radiance mode, or the Dirac
/// coefficient when `v.delta`.
pub fn scattering(scene: &Scene, light: &Vertex, v: &Vertex, camera: &Vertex) -> Rgb {
    if v.kind != VertexKind::Surface {
        return Rgb::BLACK;
    }
    let (Some(wc), Some(wl)) = (v.direction_to(camera), v.direction_to(light)) else {
        return Rgb::BLACK;
    };
    if v.delta {
        return dirac_lobe(scene, v, wc, wl, TransportMode::Radiance).map_or(Rgb::BLACK, |l| l.1);
    }
    let frame = scene.shading_frame(&v.sp);
    scene.bsdf_at(&v.sp).eval(
        frame.to_local(wc),
        frame.to_local(wl),
        TransportMode::Radiance,
    ) * v.sp.ns.dot(wl).abs()
}

/// Area density at `next` when a walk standing at `from` (having arrived
/// from `behind`; `None` at an emitter point or the camera) samples it:
/// `mode` is the walk's transport mode (importance for light walks). At a
/// Dirac vertex, the coefficient convention of the module docs.
pub fn walk_density(
    scene: &Scene,
    from: &Vertex,
    behind: Option<&Vertex>,
    next: &Vertex,
    mode: TransportMode,
) -> f32 {
    if from.kind != VertexKind::Surface || !from.delta {
        return from.pdf(scene, behind, next, mode);
    }
    let (Some(behind), Some(wn)) = (behind, from.direction_to(next)) else {
        return 0.0;
    };
    let Some(wb) = from.direction_to(behind) else {
        return 0.0;
    };
    let Some((p, c)) = dirac_lobe(scene, from, wb, wn, mode) else {
        return 0.0;
    };
    let p = match mode {
        TransportMode::Radiance => p,
        TransportMode::Importance => {
            // Light walk: wb points to the light side, wn to the camera side.
            let Some((_, c_rad)) = dirac_lobe(scene, from, wn, wb, TransportMode::Radiance) else {
                return 0.0;
            };
            let (ng, ns) = (from.sp.ng, from.sp.ns);
            let rad = c_rad.luminance() * ng.dot(wn).abs() / ng.dot(wb).abs();
            let imp = c.luminance() * shading_correction(wb, wn, ng, ns);
            if !(imp > 0.0) || !rad.is_finite() {
                return 0.0;
            }
            p * rad / imp
        }
    };
    from.convert_density(p, next)
}

/// The path-space target `ln π(x) = ln I(x)`: it reads the contribution the
/// path carries (mutations evaluate proposals when they build them), so an
/// evaluation costs no rays. Its payload is [`Path::sample`].
#[derive(Clone, Copy, Debug, Default)]
pub struct PathTarget {
    /// Leave out the specular chains ([`Path::is_specular_chain`]:
    /// `I = 0` there), which `mlt`'s specular-chain pass path traces
    /// instead ([`super::specular_pass`]).
    pub without_specular_chains: bool,
    /// Leave out every unconnectable path ([`Path::is_unconnectable`], a
    /// superset of the specular chains), which the specular-chain pass
    /// then traces through diffuse vertices too.
    pub without_unconnectable: bool,
    /// Leave out the unconnectable paths through a non-Dirac vertex
    /// (`L S+ (D S+)* E`: [`Path::is_unconnectable`] but not
    /// [`Path::is_specular_chain`]), which `mlt`'s unconnectable chains
    /// sample instead.
    pub without_unconnectable_through_non_dirac: bool,
    /// Keep only the unconnectable paths through a non-Dirac vertex: the
    /// target of `mlt`'s unconnectable chains.
    pub only_unconnectable: bool,
}

impl PathTarget {
    /// `ln I(x)` as [`Path::log_density`], `−∞` on a left-out path.
    pub fn log_density(&self, path: &Path<'_>) -> f64 {
        let through_non_dirac = || path.is_unconnectable() && !path.is_specular_chain();
        if (self.without_specular_chains && path.is_specular_chain())
            || (self.without_unconnectable && path.is_unconnectable())
            || (self.without_unconnectable_through_non_dirac && through_non_dirac())
            || (self.only_unconnectable && !through_non_dirac())
        {
            f64::NEG_INFINITY
        } else {
            path.log_density()
        }
    }
}

impl Target<Path<'_>> for PathTarget {
    type Payload = PathSample;

    fn evaluate(&self, state: &Path<'_>) -> Evaluation<PathSample> {
        Evaluation::new(self.log_density(state), state.sample())
    }
}
