//! The manifold perturbation (Jakob & Marschner 2012 §5; Mitsuba 0.6's
//! `ManifoldPerturbation`, switched on by `mlt`'s and `erpt`'s
//! `manifoldPerturbation`) as an `mcmc-core` kernel on [`Path`]s: perturb
//! the direction at a non-specular vertex `x_a`, trace it through the
//! specular vertices to the next non-specular vertex `x_b'`, and walk the
//! specular chain between `x_b` and the following non-specular vertex
//! `x_c` onto the specular manifold so that it ends at `x_b'`
//! ([`crate::manifold::perturbation::propose`], with the reverse-walk
//! check). `docs/manifold.md` has the geometry, `docs/path-space.md` the
//! mutation.
//!
//! # Pattern
//!
//! Any path with at least three non-specular vertices (the emitter vertex,
//! the camera, and surface vertices that did not scatter through a Dirac
//! lobe): `L [DS]* D [DS]* E` in Mitsuba's words. Specular means Dirac
//! ([`crate::integrators::path_vertex::Vertex::delta`]); glossy vertices
//! are non-specular here (Mitsuba 0.6 may treat a rough vertex as specular
//! on its offset manifold at random; not done, see `docs/path-space.md`).
//! A specular vertex the manifold cannot describe (transmission through a
//! `thindielectric`, a normal- or bump-mapped or masked BSDF, a vertex
//! without a tangent frame) makes the proposal invalid
//! ([`Invalid::Unsupported`], counted), and so does a move whose chain
//! reaches an emitter at infinity (`x_0` as `a` or `c`: the manifold
//! describes points, not directions). Such moves keep `x_0`, so the
//! refusal holds from `x` and from every proposal alike.
//!
//! # Selection
//!
//! With `N` the indices of the non-specular vertices (light to camera), a
//! move is a triple `(a, b, c)` of consecutive entries of `N`, in either
//! order (towards the camera or towards the light): `2(|N| − 2)` triples,
//! drawn uniformly. Proposals keep every vertex's kind and Dirac flag, so
//! `N` and the selection probability are the same from `y` and cancel.
//!
//! # The direction kernel at `x_a`
//!
//! - `x_a` the camera: the raster position moves by Veach's exponential
//!   offset ([`OffsetKernel::mitsuba`], as the lens perturbation), the new
//!   camera ray leaves the same lens point. Solid-angle density
//!   `p(ω') = p_Δ(|Δ|) · A · W(ω')`, `A` the pixels, `W` the camera's
//!   solid-angle density of a uniform raster position.
//! - otherwise: a von Mises–Fisher lobe around the current direction `ω`
//!   whose peak density is `λ² · max(1/4π, p_s(ω))` (Mitsuba's rule,
//!   `λ` = `probFactor` = 50), `p_s(ω)` the solid-angle density with which
//!   `x_a`'s BSDF (from its other neighbour) or emitter samples `ω`:
//!   concentration `κ = 2π λ² max(1/4π, p_s(ω))`. `κ` depends on `ω`, so
//!   the reverse density uses `κ(ω')`.
//!
//! # Densities and the ratio
//!
//! On the manifold of paths with a fixed pattern, the natural measure is
//! the product of the areas at the non-specular vertices; only `x_b`
//! moves, and its density per unit area is (Jakob & Marschner)
//!
//! ```text
//! T(x→y) = p(ω'|ω) · G(x_a ↔ x_b') / |cos θ_a|
//! ```
//!
//! with `G` the generalised geometry term through the specular chain
//! `x_a … x_b'` ([`proposal_density`]); the walk is deterministic given
//! `x_b'` (and reversible, checked) and adds nothing.
//!
//! The path state's contribution `f` is measured differently: the area at
//! *every* vertex with the Dirac coefficients of its specular vertices
//! (`path_space::state`). On a chain `x_p … x_q` (light side `p`, camera
//! side `q`, specular between) the two differ by the Radon–Nikodym factor
//!
//! ```text
//! J = Π_{i=p}^{q−1} |cos θ_i| / d²_{i,i+1}   /   (G(x_q ↔ x_p) / |cos θ_q|)
//! ```
//!
//! (geometric cosines, 1 off surfaces; `G(x_q ↔ x_p)` anchored at the
//! camera side, where the Dirac coefficients of radiance transport are
//! defined): the state's product of segment factors is the solid angle at
//! `x_q` per area of `x_p` taken segment by segment, the manifold's is the
//! same through the chain. `J = 1` for a chain without specular vertices.
//! The core's acceptance multiplies `f(y)/f(x)` by the kernel's ratio, so
//! the kernel returns
//!
//! ```text
//! ln T(y→x) − ln T(x→y) + ln J(x) − ln J(y)
//! ```
//!
//! over the two chains `x_a … x_b` and `x_b … x_c` (the others are
//! unchanged): the ratio of the proposal densities in the state's measure.

use super::lens_perturbation::{OffsetKernel, film_pixels};
use super::retrace::component_names;
use super::state::Path;
use crate::bsdf::TransportMode;
use crate::integrators::path_vertex::{Vertex, VertexKind};
use crate::light::Light;
use crate::manifold::constraint::{generalized_geometry, offset_frame};
use crate::manifold::perturbation::{proposal_density, propose};
use crate::manifold::walk::{WalkConfig, WalkFailure};
use crate::manifold::{ManifoldVertex, Role, Specular};
use crate::pss::PathSample;
use glam::{DVec3, Vec2};
use mcmc_core::kernel::{Kernel, Proposal};
use mcmc_core::rng::{ChainRng, uniform};
use mcmc_core::sample::Sample;
use std::f64::consts::PI;

/// Mitsuba 0.6's `probFactor` (`lambda`): the direction kernel's peak is
/// this squared times the sampling density of the current direction.
pub const PROB_FACTOR: f64 = 50.0;

/// Why a manifold perturbation could not be made (its component, after
/// the mutation's own component 0). Walk failures take components
/// `WALK_FAILURES ..`, one per [`WalkFailure`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Invalid {
    /// Fewer than three non-specular vertices.
    Pattern = 1,
    /// A vertex the manifold cannot describe (wrapped BSDF, undeflected
    /// transmission, no tangent frame).
    Unsupported = 2,
    /// The perturbed raster position is off the image.
    OffImage = 3,
    /// The new connection next to `x_b` is occluded.
    Occluded = 4,
    /// The proposal carries nothing (zero BSDF, clipped, a Dirac lobe no
    /// longer matched).
    ZeroContribution = 5,
    /// A density or Jacobian was zero or singular.
    ZeroDensity = 6,
}

/// Component of the first walk failure reason ([`WalkFailure::ALL`]
/// order).
pub const WALK_FAILURES: usize = 7;

impl Invalid {
    /// Every reason, in component order.
    pub const ALL: [Invalid; 6] = [
        Invalid::Pattern,
        Invalid::Unsupported,
        Invalid::OffImage,
        Invalid::Occluded,
        Invalid::ZeroContribution,
        Invalid::ZeroDensity,
    ];

    /// The reason's name in the statistics.
    pub fn name(self) -> &'static str {
        match self {
            Invalid::Pattern => "pattern mismatch",
            Invalid::Unsupported => "unsupported vertex",
            Invalid::OffImage => "off the image",
            Invalid::Occluded => "occluded",
            Invalid::ZeroContribution => "zero contribution",
            Invalid::ZeroDensity => "zero proposal density",
        }
    }
}

/// A failed proposal: one of [`Invalid`] or a walk failure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Failure {
    /// Not a walk failure.
    Invalid(Invalid),
    /// The trace or the walk failed.
    Walk(WalkFailure),
}

impl Failure {
    /// The kernel component that counts it.
    pub fn component(self) -> usize {
        match self {
            Failure::Invalid(r) => r as usize,
            Failure::Walk(w) => {
                WALK_FAILURES + WalkFailure::ALL.iter().position(|f| *f == w).unwrap_or(0)
            }
        }
    }
}

impl From<Invalid> for Failure {
    fn from(r: Invalid) -> Self {
        Failure::Invalid(r)
    }
}

impl From<WalkFailure> for Failure {
    fn from(w: WalkFailure) -> Self {
        Failure::Walk(w)
    }
}

/// One move: the perturbed vertex `x_a`, the moved vertex `x_b` and the
/// fixed end `x_c` of the walked chain, path indices (`a < b < c` towards
/// the camera, `a > b > c` towards the light).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Selection {
    /// Where the direction is perturbed.
    pub a: usize,
    /// The non-specular vertex that moves.
    pub b: usize,
    /// The anchor of the walked chain.
    pub c: usize,
}

impl Selection {
    /// Path indices from `a` to `c` in move order.
    fn indices(&self) -> Vec<usize> {
        if self.a < self.c {
            (self.a..=self.c).collect()
        } else {
            (self.c..=self.a).rev().collect()
        }
    }

    /// Position of `b` in [`Selection::indices`].
    fn b_offset(&self) -> usize {
        self.a.abs_diff(self.b)
    }
}

/// Every move the perturbation can make on `x` (see the module docs);
/// empty when the pattern does not match.
pub fn selections(x: &Path) -> Vec<Selection> {
    let n: Vec<usize> = (0..x.len()).filter(|&i| !x.vertices[i].delta).collect();
    let mut out = Vec::new();
    for w in n.windows(3) {
        out.push(Selection {
            a: w[0],
            b: w[1],
            c: w[2],
        });
        out.push(Selection {
            a: w[2],
            b: w[1],
            c: w[0],
        });
    }
    out
}

/// The manifold descriptors of `x`'s vertices `sel.a … sel.c`, in move
/// order.
fn descriptors(x: &Path, sel: Selection) -> Result<Vec<ManifoldVertex>, Invalid> {
    sel.indices()
        .into_iter()
        .map(|i| {
            let v = &x.vertices[i];
            // The other neighbour says whether a dielectric refracted.
            let other = if i > 0 {
                x.vertices[i - 1].p()
            } else {
                x.vertices[1].p()
            };
            ManifoldVertex::from_path_vertex(x.scene, v, None, other).ok_or(Invalid::Unsupported)
        })
        .collect()
}

/// `ln J` of a chain given in path order (light side first), see the
/// module docs; `None` when its generalised geometry term is singular.
fn log_chain_jacobian(chain: &[ManifoldVertex]) -> Option<f64> {
    if chain.len() == 2 {
        return Some(0.0);
    }
    let cos = |v: &ManifoldVertex, w: DVec3| {
        if v.on_surface() {
            v.geo.ng.dot(w).abs()
        } else {
            1.0
        }
    };
    let mut log_state = 0.0;
    for s in chain.windows(2) {
        let d = s[1].p() - s[0].p();
        let d2 = d.length_squared();
        log_state += (cos(&s[0], d / d2.sqrt()) / d2).ln();
    }
    let reversed: Vec<ManifoldVertex> = chain.iter().rev().copied().collect();
    let g = if chain[0].on_surface() {
        generalized_geometry(&reversed)?
    } else {
        // A point light has no area to end a chain on: take the term
        // anchored at it and reverse it by étendue (η² dA dσ⊥ is
        // conserved), G(q → p) = G(p → q) (η_p/η_q)².
        let ratio = end_ior(chain) / end_ior(&reversed);
        generalized_geometry(chain)? * ratio * ratio
    };
    let q = &reversed[0];
    let cos_q = cos(q, (reversed[1].p() - q.p()).normalize());
    let log_j = log_state - (g / cos_q).ln();
    log_j.is_finite().then_some(log_j)
}

/// Index of refraction of the medium around a chain's first vertex, from
/// the specular vertex next to it (1 outside a refracting surface, and
/// next to a mirror).
fn end_ior(chain: &[ManifoldVertex]) -> f64 {
    match chain[1].role {
        Role::Specular(Specular::Refract { eta })
            if (chain[0].p() - chain[1].p()).dot(chain[1].geo.ns) < 0.0 =>
        {
            eta
        }
        _ => 1.0,
    }
}

/// `ln J` of the two chains `a … b` and `b … c` of a move-ordered chain.
fn log_jacobian(chain: &[ManifoldVertex], b: usize, towards_camera: bool) -> Option<f64> {
    let path_order = |part: &[ManifoldVertex]| -> Vec<ManifoldVertex> {
        if towards_camera {
            part.to_vec()
        } else {
            part.iter().rev().copied().collect()
        }
    };
    Some(
        log_chain_jacobian(&path_order(&chain[..=b]))?
            + log_chain_jacobian(&path_order(&chain[b..]))?,
    )
}

/// `ln` of the von Mises–Fisher density on the sphere with concentration
/// `kappa` at a direction whose cosine to the mean is `cos`.
pub fn log_vmf(kappa: f64, cos: f64) -> f64 {
    kappa.ln() - (2.0 * PI).ln() - (-(-2.0 * kappa).exp_m1()).ln() + kappa * (cos - 1.0)
}

/// A direction from the von Mises–Fisher lobe around the unit `mu`.
pub fn sample_vmf(mu: DVec3, kappa: f64, u1: f64, u2: f64) -> DVec3 {
    // Inverse of the cosine's CDF, stable for large κ.
    let w = (1.0 + (u1 + (1.0 - u1) * (-2.0 * kappa).exp()).ln() / kappa).clamp(-1.0, 1.0);
    let s = (1.0 - w * w).max(0.0).sqrt();
    let phi = 2.0 * PI * u2;
    let (t1, t2) = offset_frame(mu);
    (mu * w + (t1 * phi.cos() + t2 * phi.sin()) * s).normalize()
}

/// The manifold perturbation: component 0 is the mutation, components
/// 1–6 its failures by [`Invalid`] reason, then one per [`WalkFailure`].
#[derive(Clone, Debug)]
pub struct ManifoldPerturbation {
    /// The film-offset kernel when `x_a` is the camera; `None`: Mitsuba's
    /// sizes for the path's film.
    pub offsets: Option<OffsetKernel>,
    /// `λ` of the direction kernel ([`PROB_FACTOR`]).
    pub prob_factor: f64,
    /// The walk's tolerances.
    pub walk: WalkConfig,
    /// The statistics' name of component 0.
    pub name: String,
}

impl Default for ManifoldPerturbation {
    fn default() -> Self {
        ManifoldPerturbation {
            offsets: None,
            prob_factor: PROB_FACTOR,
            walk: WalkConfig::default(),
            name: "manifold perturbation".into(),
        }
    }
}

impl ManifoldPerturbation {
    fn offsets(&self, x: &Path) -> OffsetKernel {
        self.offsets
            .unwrap_or_else(|| OffsetKernel::mitsuba(film_pixels(x.scene)))
    }

    /// `κ` of the direction kernel at `x_a` (not the camera) around the
    /// direction `w` towards the chain, `other` the vertex on `x_a`'s other
    /// side (`None` at the path's ends).
    fn concentration(&self, x: &Path, a: usize, other: Option<usize>, w: DVec3) -> f64 {
        let v = &x.vertices[a];
        let w32 = w.as_vec3();
        let p = match v.kind {
            VertexKind::Light => match &x.scene.lights.lights[v.light as usize] {
                Light::Area { .. } => (v.sp.ns.dot(w32).max(0.0) as f64) / PI,
                Light::Point { spot: Some(s), .. } => s.pdf(w32) as f64,
                _ => 0.25 / PI,
            },
            VertexKind::Surface => match other.and_then(|o| v.direction_to(&x.vertices[o])) {
                Some(wo) => {
                    let frame = x.scene.shading_frame(&v.sp);
                    x.scene.bsdf_at(&v.sp).pdf(
                        frame.to_local(wo),
                        frame.to_local(w32),
                        TransportMode::Radiance,
                    ) as f64
                }
                None => 0.0,
            },
            _ => 0.0,
        };
        let peak = if p.is_finite() {
            p.max(0.25 / PI)
        } else {
            0.25 / PI
        };
        2.0 * PI * self.prob_factor * self.prob_factor * peak
    }

    /// The vertex on `x_a`'s other side from the chain.
    fn other_side(x: &Path, sel: Selection) -> Option<usize> {
        if sel.a < sel.c {
            sel.a.checked_sub(1)
        } else {
            (sel.a + 1 < x.len()).then_some(sel.a + 1)
        }
    }

    /// `ln p(ω_to|ω_from)` of the direction kernel at `x_a` of the move
    /// `sel`, for paths `from` and `to` that share `x_a` and its other
    /// neighbour (the part that cancels when `x_a` is the camera, `p_Δ`,
    /// is left out: it depends on `|Δ|` alone).
    fn log_direction_density(&self, from: &Path, to: &Path, sel: Selection) -> f64 {
        let next = if sel.a < sel.c { sel.a + 1 } else { sel.a - 1 };
        let dir = |p: &Path| {
            (p.vertices[next].p().as_dvec3() - p.vertices[sel.a].p().as_dvec3()).normalize()
        };
        let (w_from, w_to) = (dir(from), dir(to));
        if from.vertices[sel.a].kind == VertexKind::Camera {
            let scene = to.scene;
            let we = scene
                .camera
                .pdf_we(to.vertices[sel.a].p(), w_to.as_vec3())
                .1 as f64;
            return film_pixels(scene).ln() + we.ln();
        }
        let kappa = self.concentration(from, sel.a, Self::other_side(from, sel), w_from);
        log_vmf(kappa, w_from.dot(w_to).min(1.0))
    }

    /// `ln T(x→y)` of the move `sel` (module docs) in the manifold's
    /// measure: the density per unit area of `y`'s `x_b` (up to `p_Δ` when
    /// `x_a` is the camera), `−∞` when `y` is not on the move's path.
    /// What the density test histograms.
    pub fn log_proposal_density(&self, x: &Path, y: &Path, sel: Selection) -> f64 {
        let Ok(chain) = descriptors(y, sel) else {
            return f64::NEG_INFINITY;
        };
        let log_dir = self.log_direction_density(x, y, sel);
        match proposal_density(&chain[..=sel.b_offset()], 1.0) {
            Some(d) if d > 0.0 && log_dir.is_finite() => log_dir + d.ln(),
            _ => f64::NEG_INFINITY,
        }
    }

    /// `ln T(y→x) − ln T(x→y)` in the path state's measure (module docs),
    /// from the two paths; `None` when a density or Jacobian is singular.
    pub fn log_ratio(&self, x: &Path, y: &Path, sel: Selection) -> Option<f64> {
        let (cx, cy) = (descriptors(x, sel).ok()?, descriptors(y, sel).ok()?);
        self.log_ratio_of(x, y, sel, &cx, &cy)
    }

    fn log_ratio_of(
        &self,
        x: &Path,
        y: &Path,
        sel: Selection,
        cx: &[ManifoldVertex],
        cy: &[ManifoldVertex],
    ) -> Option<f64> {
        let b = sel.b_offset();
        let towards_camera = sel.a < sel.c;
        let density = |p: &Path, q: &Path, chain: &[ManifoldVertex]| {
            let d = proposal_density(&chain[..=b], 1.0)?;
            let log = self.log_direction_density(p, q, sel) + d.ln();
            log.is_finite().then_some(log)
        };
        let forward = density(x, y, cy)?;
        let backward = density(y, x, cx)?;
        let jx = log_jacobian(cx, b, towards_camera)?;
        let jy = log_jacobian(cy, b, towards_camera)?;
        let r = backward - forward + jx - jy;
        r.is_finite().then_some(r)
    }

    /// Makes the move `sel` from `x` into `y` and returns its
    /// `ln T(y→x) − ln T(x→y)`.
    pub fn perturb<'s>(
        &self,
        x: &Path<'s>,
        y: &mut Path<'s>,
        sel: Selection,
        rng: &mut ChainRng,
    ) -> Result<f64, Failure> {
        let scene = x.scene;
        let cx = descriptors(x, sel)?;
        let b = sel.b_offset();
        let a = &x.vertices[sel.a];
        let dir = if a.kind == VertexKind::Camera {
            let offset = self.offsets(x).sample(uniform(rng), uniform(rng));
            let raster = x.raster + offset;
            let (w, h) = (scene.film.width as f32, scene.film.height as f32);
            if !(raster.x >= 0.0 && raster.x < w && raster.y >= 0.0 && raster.y < h) {
                return Err(Invalid::OffImage.into());
            }
            camera_direction(x, raster).ok_or(Invalid::OffImage)?
        } else {
            let w = (cx[1].p() - cx[0].p()).normalize();
            let kappa = self.concentration(x, sel.a, Self::other_side(x, sel), w);
            sample_vmf(w, kappa, uniform(rng), uniform(rng))
        };
        // The chain x_a … x_b is traced again in the new direction, the
        // chain x_c … x_b walked to the new x_b (reverse check included).
        let moved = propose(scene, &cx, b, dir, 1.0, &self.walk)?;
        let vs = &mut y.vertices;
        vs.clear();
        vs.extend_from_slice(&x.vertices);
        for (r, i) in sel.indices().into_iter().enumerate() {
            if r > 0 && r + 1 < moved.path.len() {
                vs[i].sp = moved.path[r].sp;
            }
        }
        y.normalize_ends();
        y.evaluate();
        // Traced segments are visible by construction; the one joining the
        // walked chain (or x_c) to x_b' is tested.
        let joint = if sel.a < sel.c { sel.b } else { sel.b - 1 };
        if !y.edge_visible(joint) {
            return Err(Invalid::Occluded.into());
        }
        if y.contribution.is_black() {
            return Err(Invalid::ZeroContribution.into());
        }
        self.log_ratio_of(x, y, sel, &cx, &moved.path)
            .ok_or(Invalid::ZeroDensity.into())
    }
}

/// The unit direction of the camera ray through `raster` from `x`'s lens
/// point (the pinhole, or the same point on a thin lens).
fn camera_direction(x: &Path, raster: Vec2) -> Option<DVec3> {
    let camera = &x.scene.camera;
    let k = x.segments();
    let ray = if camera.has_lens() {
        let cam: &Vertex = &x.vertices[k];
        let to = cam.direction_to(&x.vertices[k - 1])?;
        let (_, u_lens) = camera.invert(cam.p(), to)?;
        camera.generate_ray_lens(raster, u_lens)
    } else {
        camera.generate_ray(raster)
    };
    Some(ray.d.as_dvec3().normalize())
}

impl<'s> Kernel<Path<'s>, PathSample> for ManifoldPerturbation {
    fn propose(
        &mut self,
        current: &Sample<Path<'s>, PathSample>,
        proposal: &mut Sample<Path<'s>, PathSample>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let x = &current.state;
        let moves = selections(x);
        if moves.is_empty() {
            return Proposal::failed(Invalid::Pattern as usize);
        }
        let pick = ((uniform(rng) * moves.len() as f64) as usize).min(moves.len() - 1);
        match self.perturb(x, &mut proposal.state, moves[pick], rng) {
            Ok(ratio) => Proposal::with_ratio(ratio, 0),
            Err(f) => Proposal::failed(f.component()),
        }
    }

    fn component_names(&self) -> Vec<String> {
        let walk = WalkFailure::ALL
            .iter()
            .map(|w| format!("walk {}", w.name()));
        component_names(
            &self.name,
            Invalid::ALL
                .iter()
                .map(|r| r.name().to_string())
                .chain(walk),
        )
    }
}
