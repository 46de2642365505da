//! Veach's caustic perturbation (Veach 1997 §11.4.3; Mitsuba 0.6's
//! `CausticPerturbation`): turn the direction leaving the light-side end
//! of the path's last specular chain a little, re-trace the chain to the
//! vertex the camera sees, reconnect that vertex to the camera.
//!
//! # Pattern
//!
//! Paths whose camera end reads `(L|D) S* D E` (light to camera): `x_{k−1}`
//! (the vertex the camera sees) is a surface vertex that can end a
//! connection ([`Path::connectible`]); with `l` the camera-most vertex
//! before it that can end a connection (an emitter point or a non-Dirac
//! surface vertex), every `x_{l+1} … x_{k−2}` scatters through a Dirac
//! lobe. `l = k − 2` (no chain: `(L|D) D E`) is allowed, as in Mitsuba.
//! `x_l` may not be an emitter at infinity (`x_0` of an environment or a
//! directional light: its walks leave a disk along a fixed direction, so
//! there is no direction at a point to turn); the move keeps `x_0`, so the
//! test gives the same answer from `x` and from every proposal. Other
//! paths get a failed proposal ([`Invalid::Pattern`]).
//!
//! # The move
//!
//! 1. An angle `θ` and an azimuth `φ` about the direction `w` from `x_l`
//!    to `x_{l+1}` ([`spawn_direction`]):
//!    `θ = θ₂ exp(−ln(θ₂/θ₁) u₁)`, `φ = 2π u₂`, density in solid angle
//!    `p_ω(θ) = 1 / (2π sin θ · θ · ln(θ₂/θ₁))` on `θ₁ ≤ θ ≤ θ₂`
//!    ([`AngleKernel`]). Angles `θ ≥ π` (possible when `θ₂` is large)
//!    fail ([`Invalid::AngleRange`]): the map `θ → ω` is one-to-one below
//!    `π` only.
//! 2. From the kept `x_l` along the new direction, a light walk (importance
//!    transport) of `k − 1 − l` vertices `y_{l+1} … y_{k−1}` that samples
//!    each BSDF as light walks do; the proposal must keep the pattern
//!    (`y_{l+1} … y_{k−2}` Dirac, any lobe; `y_{k−1}` not;
//!    [`Invalid::PatternChanged`]).
//! 3. `y_{k−1}` is connected to the kept camera vertex (same lens point;
//!    off the image: [`Invalid::OffImage`]; visibility tested).
//!
//! # Transition density
//!
//! The walk is the light walk of the path state's densities with the BSDF
//! (or emission) sampling at `x_l` replaced by `p_ω`:
//!
//! ```text
//! T(x→y) = p_ω^x(θ) · |cos θ_{y_{l+1}}| / |y_{l+1} − x_l|² · Π_{i=l+2}^{k−1} pdf_fwd(y_i)
//! ```
//!
//! (`pdf_fwd` in the path state's Dirac-coefficient convention, lobe
//! choices included). `θ` is the angle between the two paths' directions
//! at `x_l`, the same both ways; the sizes `θ₁, θ₂` depend on the path the
//! move starts from (below), but their ratio does not, so `p_ω^x(θ) =
//! p_ω^y(θ)` wherever both are non-zero, and the reverse move is possible
//! only when `θ` also lies in `y`'s range (otherwise the proposal fails,
//! [`Invalid::NoReverse`]).
//!
//! # Parameters
//!
//! Mitsuba 0.6's sizes: the film offsets of the lens perturbation (`r₁` =
//! 0.1 px, `r₂ = √(0.05 A / π)` px; [`OffsetKernel::mitsuba`]) turned into
//! angles seen from the camera (`radPerPixel`, the smaller field of view
//! over its pixels; [`crate::camera::Camera::radians_per_pixel`]) and
//! scaled by Veach's heuristic `|x_k − x_{k−1}| / Σ_{i=l}^{k−2} |x_{i+1} −
//! x_i|` (camera segment over the chain's length), so that the vertex the
//! camera sees moves by about as many pixels as the lens perturbation
//! moves it.

use super::lens_perturbation::{OffsetKernel, film_pixels};
use super::retrace::{
    RetraceFailure, component_names, finish_proposal, log_density_product, trace_dirac_chain,
};
use super::state::Path;
use crate::bsdf::TransportMode;
use crate::frame::Frame;
use crate::geometry::Ray;
use crate::integrators::path_vertex::{Vertex, VertexKind};
use crate::pss::PathSample;
use glam::{DVec3, Vec3};
use mcmc_core::kernel::{Kernel, Proposal};
use mcmc_core::rng::{ChainRng, uniform};
use mcmc_core::sample::Sample;
use std::f64::consts::PI;

/// Why a caustic perturbation could not be made (its component offset
/// after the mutation's own component 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Invalid {
    /// The path's camera end is not `(L|D) S* D E`.
    Pattern = 1,
    /// The sampled angle is `π` or more.
    AngleRange = 2,
    /// The re-traced walk escaped or was absorbed.
    WalkEnded = 3,
    /// The re-traced walk changed the pattern.
    PatternChanged = 4,
    /// The camera does not see the new end vertex on its image.
    OffImage = 5,
    /// The connection to the camera is occluded.
    Occluded = 6,
    /// The proposal carries nothing (zero BSDF, clipped).
    ZeroContribution = 7,
    /// A re-traced vertex's density evaluated to zero (rounding).
    ZeroDensity = 8,
    /// The angle lies outside the reverse move's range (`T(y→x) = 0`).
    NoReverse = 9,
}

impl Invalid {
    /// Every reason, in component order.
    pub const ALL: [Invalid; 9] = [
        Invalid::Pattern,
        Invalid::AngleRange,
        Invalid::WalkEnded,
        Invalid::PatternChanged,
        Invalid::OffImage,
        Invalid::Occluded,
        Invalid::ZeroContribution,
        Invalid::ZeroDensity,
        Invalid::NoReverse,
    ];

    /// The reason's name in the statistics.
    pub fn name(self) -> &'static str {
        match self {
            Invalid::Pattern => "pattern mismatch",
            Invalid::AngleRange => "angle of pi or more",
            Invalid::WalkEnded => "walk ended",
            Invalid::PatternChanged => "pattern changed",
            Invalid::OffImage => "off the image",
            Invalid::Occluded => "occluded",
            Invalid::ZeroContribution => "zero contribution",
            Invalid::ZeroDensity => "zero proposal density",
            Invalid::NoReverse => "no reverse move",
        }
    }
}

/// The exponential angle kernel of the perturbations: a direction at angle
/// `θ ∈ [θ₁, θ₂]` from a given one, `θ` with density `∝ 1/θ`, the azimuth
/// uniform.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AngleKernel {
    /// Smallest angle (radians).
    pub theta1: f64,
    /// Largest angle (radians).
    pub theta2: f64,
}

impl AngleKernel {
    /// `(θ, φ)` of two uniform numbers.
    pub fn sample(&self, u1: f64, u2: f64) -> (f64, f64) {
        let theta = self.theta2 * (-(self.theta2 / self.theta1).ln() * u1).exp();
        (theta, 2.0 * PI * u2)
    }

    /// The unit direction at `(θ, φ)` from unit `axis`.
    pub fn direction(axis: Vec3, theta: f64, phi: f64) -> Vec3 {
        let (s, c) = theta.sin_cos();
        let local = Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, c as f32);
        Frame::from_normal(axis).to_world(local).normalize()
    }

    /// `ln p_ω` in solid angle at angle `θ` (`−∞` outside `[θ₁, θ₂]` or at
    /// `π` and beyond).
    pub fn log_density(&self, theta: f64) -> f64 {
        if !(theta >= self.theta1 && theta <= self.theta2 && theta < PI) {
            return f64::NEG_INFINITY;
        }
        -(2.0 * PI * theta.sin() * theta * (self.theta2 / self.theta1).ln()).ln()
    }
}

/// The unit direction of the ray a walk at `from` spawns to reach `to`:
/// from the offset origin of [`crate::geometry::SurfacePoint::spawn_origin`]
/// (the vertex itself off surfaces). The perturbations measure their
/// angles between these directions, so that the angle of a move is the
/// same both ways even at angles near the offset's size.
pub fn spawn_direction(from: &Vertex, to: &Vertex) -> Option<DVec3> {
    let origin = if from.on_surface() {
        from.sp.spawn_origin(to.p())
    } else {
        from.p()
    };
    let d = to.p().as_dvec3() - origin.as_dvec3();
    let len = d.length();
    (len > 0.0).then(|| d / len)
}

/// The angle between two directions, accurate for small angles.
pub fn angle_between(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b))
}

/// The index `l` of the vertex whose outgoing direction the caustic
/// perturbation turns (see the module docs), `None` when `x` does not
/// match `(L|D) S* D E`.
pub fn caustic_chain(x: &Path) -> Option<usize> {
    if x.len() < 3 {
        return None;
    }
    let k = x.segments();
    let seen = &x.vertices[k - 1];
    if seen.kind != VertexKind::Surface || !x.connectible(k - 1) {
        return None;
    }
    let mut l = k - 2;
    while !x.connectible(l) {
        if !x.vertices[l].delta || l == 0 {
            return None;
        }
        l -= 1;
    }
    // An emitter at infinity has no point to turn a direction about (its
    // light walks leave a disk along the fixed `−ω`): not this pattern.
    (x.vertices[l].kind != VertexKind::Infinite).then_some(l)
}

/// Veach's caustic perturbation as an `mcmc-core` kernel over [`Path`]s:
/// component 0 is the mutation, components 1–9 its failed proposals by
/// [`Invalid`] reason.
#[derive(Clone, Debug)]
pub struct CausticPerturbation {
    /// The film offsets the angle sizes come from; `None`: Mitsuba's
    /// sizes for the path's film.
    pub offsets: Option<OffsetKernel>,
    /// The statistics' name of component 0.
    pub name: String,
    walk: Vec<Vertex>,
}

impl Default for CausticPerturbation {
    fn default() -> Self {
        CausticPerturbation::new(None)
    }
}

impl CausticPerturbation {
    /// The perturbation with film offsets `offsets` (`None`: Mitsuba's).
    pub fn new(offsets: Option<OffsetKernel>) -> Self {
        CausticPerturbation {
            offsets,
            name: "caustic perturbation".into(),
            walk: Vec::new(),
        }
    }

    /// The angle kernel for moves from `x` whose chain starts at `x_l`:
    /// the film offsets as angles, times Veach's length ratio (module
    /// docs). `None` for a degenerate path (zero lengths).
    pub fn angles(&self, x: &Path, l: usize) -> Option<AngleKernel> {
        let scene = x.scene;
        let k = x.segments();
        let offsets = self
            .offsets
            .unwrap_or_else(|| OffsetKernel::mitsuba(film_pixels(scene)));
        let per_pixel = scene.camera.radians_per_pixel() as f64;
        let p = |i: usize| x.vertices[i].p().as_dvec3();
        let length_e = (p(k) - p(k - 1)).length();
        let length_l: f64 = (l..k - 1).map(|i| (p(i + 1) - p(i)).length()).sum();
        let factor = length_e / length_l;
        let kernel = AngleKernel {
            theta1: per_pixel * offsets.r1 * factor,
            theta2: per_pixel * offsets.r2 * factor,
        };
        (kernel.theta1 > 0.0 && kernel.theta2.is_finite()).then_some(kernel)
    }

    /// `ln T(x→y)` (module docs), `−∞` when the move cannot produce `y`
    /// from `x`. The vertices up to `l` and the camera vertex are assumed
    /// shared (as every proposal has them).
    pub fn log_transition_density(&self, x: &Path, y: &Path) -> f64 {
        let Some(l) = caustic_chain(x) else {
            return f64::NEG_INFINITY;
        };
        if y.len() != x.len() || caustic_chain(y) != Some(l) || y.contribution.is_black() {
            return f64::NEG_INFINITY;
        }
        let Some(angles) = self.angles(x, l) else {
            return f64::NEG_INFINITY;
        };
        let from = &x.vertices[l];
        let (Some(old), Some(new)) = (
            spawn_direction(from, &x.vertices[l + 1]),
            spawn_direction(from, &y.vertices[l + 1]),
        ) else {
            return f64::NEG_INFINITY;
        };
        let theta = angle_between(old, new);
        angles.log_density(theta) + log_chain_density(y, l)
    }

    /// Draws a proposal into `y`; returns `l`, or why it failed.
    fn mutate<'s>(
        &mut self,
        x: &Path<'s>,
        y: &mut Path<'s>,
        rng: &mut ChainRng,
    ) -> Result<usize, Invalid> {
        let l = caustic_chain(x).ok_or(Invalid::Pattern)?;
        let angles = self.angles(x, l).ok_or(Invalid::Pattern)?;
        let scene = x.scene;
        let k = x.segments();
        let (theta, phi) = angles.sample(uniform(rng), uniform(rng));
        if theta >= PI {
            return Err(Invalid::AngleRange);
        }
        let start = &x.vertices[l];
        let axis = spawn_direction(start, &x.vertices[l + 1]).ok_or(Invalid::Pattern)?;
        let dir = AngleKernel::direction(axis.as_vec3(), theta, phi);
        let ray = if start.on_surface() {
            start.sp.spawn_ray(dir)
        } else {
            Ray::new(start.p(), dir)
        };
        let count = k - 1 - l;
        // walk[i] = y_{l+i}: the chain y_{l+1} … y_{k−2} must stay Dirac.
        trace_dirac_chain(
            scene,
            start,
            ray,
            TransportMode::Importance,
            count,
            &mut self.walk,
            rng,
        )?;
        let cam = x.vertices[k];
        let vs = &mut y.vertices;
        vs.clear();
        vs.extend_from_slice(&x.vertices[..=l]);
        vs.extend_from_slice(&self.walk[1..]);
        vs.push(cam);
        let on_image = |y: &Path| match scene.camera.connect(cam.p(), y.vertices[k - 1].p()) {
            Some(_) => Ok(()),
            None => Err(Invalid::OffImage),
        };
        finish_proposal(y, |y| caustic_chain(y) == Some(l), on_image, k - 1)?;
        Ok(l)
    }
}

/// `ln` of the re-traced vertices' density without the angle kernel:
/// the solid angle at `y_l` to area at `y_{l+1}`, then the light walk's
/// `Σ_{i=l+2}^{k−1} ln pdf_fwd(y_i)` (`−∞` when one is zero).
fn log_chain_density(y: &Path, l: usize) -> f64 {
    let vs = &y.vertices;
    let solid_angle_to_area = vs[l].convert_density(1.0, &vs[l + 1]);
    log_density_product(
        std::iter::once(solid_angle_to_area)
            .chain(vs[l + 2..y.segments()].iter().map(|v| v.pdf_fwd)),
    )
}

impl From<RetraceFailure> for Invalid {
    fn from(f: RetraceFailure) -> Self {
        match f {
            RetraceFailure::WalkEnded => Invalid::WalkEnded,
            RetraceFailure::PatternChanged => Invalid::PatternChanged,
            RetraceFailure::Occluded => Invalid::Occluded,
            RetraceFailure::ZeroContribution => Invalid::ZeroContribution,
        }
    }
}

impl<'s> Kernel<Path<'s>, PathSample> for CausticPerturbation {
    fn propose(
        &mut self,
        current: &Sample<Path<'s>, PathSample>,
        proposal: &mut Sample<Path<'s>, PathSample>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let x = &current.state;
        let y = &mut proposal.state;
        if let Err(reason) = self.mutate(x, y, rng) {
            return Proposal::failed(reason as usize);
        }
        let forward = self.log_transition_density(x, y);
        if !(forward > f64::NEG_INFINITY) {
            return Proposal::failed(Invalid::ZeroDensity as usize);
        }
        let backward = self.log_transition_density(y, x);
        if !(backward > f64::NEG_INFINITY) {
            return Proposal::failed(Invalid::NoReverse as usize);
        }
        Proposal::with_ratio(backward - forward, 0)
    }

    fn component_names(&self) -> Vec<String> {
        component_names(&self.name, Invalid::ALL.iter().map(|r| r.name()))
    }
}
