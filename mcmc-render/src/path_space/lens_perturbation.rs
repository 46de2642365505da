//! Veach's lens perturbation (Veach 1997 §11.4.3; Mitsuba 0.6's
//! `LensPerturbation`): move the path's raster position a little, re-trace
//! the camera's specular chain, reconnect to the kept light side.
//!
//! # Pattern
//!
//! Paths whose camera end reads `(L|D) D S* E` (light to camera): with `j`
//! the camera-most vertex `x_j` (`j < k`) that does not scatter through a
//! Dirac lobe, every `x_{j+1} … x_{k−1}` scatters through one, `x_j` is a
//! surface vertex and both `x_{j−1}` and `x_j` can end a connection
//! ([`Path::connectible`]; `x_{j−1}` may be an emitter at infinity, then
//! the reconnection is the kept direction `ω`). Other paths get a failed
//! proposal ([`Invalid::Pattern`]).
//!
//! # The move
//!
//! 1. An offset `Δ` on the film: `|Δ| = r₂ · exp(−ln(r₂/r₁) · u₁)`,
//!    `φ = 2π u₂` (Mitsuba's exponential kernel), density
//!    `p_Δ(Δ) = 1 / (2π |Δ|² ln(r₂/r₁))` on `r₁ ≤ |Δ| ≤ r₂`.
//! 2. The camera ray through `x.raster + Δ` from the same lens point (off
//!    the image: [`Invalid::OffImage`]), and a camera walk of `k − j`
//!    vertices `y_{k−1} … y_j` that samples each BSDF as the camera walk
//!    does. The proposal must keep the pattern: `y_{k−1} … y_{j+1}` scatter
//!    through Dirac lobes (any of them: a dielectric may switch between
//!    reflection and refraction), `y_j` does not
//!    ([`Invalid::PatternChanged`]).
//! 3. `y_j` is connected to the kept `x_{j−1}` (visibility tested).
//!
//! # Transition density
//!
//! The walk is the camera walk of the path state's densities with the
//! uniform raster density `1/A` (`A` = pixels) replaced by `p_Δ`:
//!
//! ```text
//! T(x→y) = p_Δ(y.raster − x.raster) · A · Π_{i=j}^{k−1} pdf_rev(y_i)
//! ```
//!
//! (`pdf_rev` in the path state's Dirac-coefficient convention, so the
//! lobe choices are included). `p_Δ` depends on `|Δ|` alone and the
//! reverse move draws the same `j`, so
//! `ln T(y→x) − ln T(x→y) = Σ_{i=j}^{k−1} ln pdf_rev(x_i) − ln pdf_rev(y_i)`:
//! the change of the re-traced part's path densities, as in Veach and
//! Mitsuba.
//!
//! # Parameters
//!
//! `r₁` = 0.1 pixels and `r₂ = √(0.05 · A / π)` pixels (the offset covers
//! 5% of the image): Mitsuba 0.6's `minJump` and `coveredArea`, the sizes
//! Veach recommends.

use super::retrace::{
    RetraceFailure, component_names, finish_proposal, log_density_product, trace_dirac_chain,
};
use super::state::Path;
use crate::bsdf::TransportMode;
use crate::geometry::Ray;
use crate::integrators::path_vertex::{Vertex, VertexKind};
use crate::pss::PathSample;
use crate::scene::Scene;
use glam::Vec2;
use mcmc_core::kernel::{Kernel, Proposal};
use mcmc_core::rng::{ChainRng, uniform};
use mcmc_core::sample::Sample;
use std::f64::consts::PI;

/// Why a lens perturbation could not be made (its component offset after
/// the mutation's own component 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Invalid {
    /// The path's camera end is not `(L|D) D S* E`.
    Pattern = 1,
    /// The perturbed raster position is off the image.
    OffImage = 2,
    /// The re-traced walk escaped or was absorbed.
    WalkEnded = 3,
    /// The re-traced walk changed the pattern (a non-Dirac lobe inside the
    /// chain, or a Dirac-only surface where the chain should end).
    PatternChanged = 4,
    /// The reconnection to the light side is occluded.
    Occluded = 5,
    /// The proposal carries nothing (zero BSDF, clipped).
    ZeroContribution = 6,
    /// A re-traced vertex's density evaluated to zero (rounding).
    ZeroDensity = 7,
}

impl Invalid {
    /// Every reason, in component order.
    pub const ALL: [Invalid; 7] = [
        Invalid::Pattern,
        Invalid::OffImage,
        Invalid::WalkEnded,
        Invalid::PatternChanged,
        Invalid::Occluded,
        Invalid::ZeroContribution,
        Invalid::ZeroDensity,
    ];

    /// The reason's name in the statistics.
    pub fn name(self) -> &'static str {
        match self {
            Invalid::Pattern => "pattern mismatch",
            Invalid::OffImage => "off the image",
            Invalid::WalkEnded => "walk ended",
            Invalid::PatternChanged => "pattern changed",
            Invalid::Occluded => "occluded",
            Invalid::ZeroContribution => "zero contribution",
            Invalid::ZeroDensity => "zero proposal density",
        }
    }
}

/// The exponential film-offset kernel of the perturbations: `|Δ|` between
/// `r1` and `r2` pixels with density `∝ 1/|Δ|²` in the plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OffsetKernel {
    /// Smallest offset (pixels).
    pub r1: f64,
    /// Largest offset (pixels).
    pub r2: f64,
}

impl OffsetKernel {
    /// Mitsuba 0.6's sizes for a film of `pixels` pixels: `r₁` = 0.1,
    /// `r₂ = √(0.05 · pixels / π)` (Veach's recommendation).
    pub fn mitsuba(pixels: f64) -> Self {
        OffsetKernel {
            r1: 0.1,
            r2: (0.05 * pixels / PI).sqrt(),
        }
    }

    /// The offset of two uniform numbers.
    pub fn sample(&self, u1: f64, u2: f64) -> Vec2 {
        let r = self.r2 * (-(self.r2 / self.r1).ln() * u1).exp();
        let phi = 2.0 * PI * u2;
        Vec2::new((r * phi.cos()) as f32, (r * phi.sin()) as f32)
    }

    /// `ln p_Δ` of an offset of length `r` (`−∞` outside `[r1, r2]`).
    pub fn log_density(&self, r: f64) -> f64 {
        if !(r >= self.r1 && r <= self.r2) {
            return f64::NEG_INFINITY;
        }
        -(2.0 * PI * r * r * (self.r2 / self.r1).ln()).ln()
    }
}

/// The index `j` of the vertex where the lens perturbation's re-traced
/// chain ends (see the module docs), `None` when `x` does not match
/// `(L|D) D S* E`.
pub fn lens_chain(x: &Path) -> Option<usize> {
    let k = x.segments();
    if x.len() < 3 {
        return None;
    }
    let mut j = k - 1;
    while j >= 1 && x.vertices[j].delta {
        j -= 1;
    }
    let ok = j >= 1
        && x.vertices[j].kind == VertexKind::Surface
        && x.connectible(j)
        && x.connectible(j - 1);
    ok.then_some(j)
}

/// Veach's lens perturbation as an `mcmc-core` kernel over [`Path`]s:
/// component 0 is the mutation, components 1–7 its failed proposals by
/// [`Invalid`] reason.
#[derive(Clone, Debug)]
pub struct LensPerturbation {
    /// The offset kernel; `None`: Mitsuba's sizes for the path's film.
    pub offsets: Option<OffsetKernel>,
    /// The statistics' name of component 0.
    pub name: String,
    walk: Vec<Vertex>,
}

impl Default for LensPerturbation {
    fn default() -> Self {
        LensPerturbation::new(None)
    }
}

impl LensPerturbation {
    /// The perturbation with offset kernel `offsets` (`None`: Mitsuba's).
    pub fn new(offsets: Option<OffsetKernel>) -> Self {
        LensPerturbation {
            offsets,
            name: "lens perturbation".into(),
            walk: Vec::new(),
        }
    }

    /// The offset kernel used on `scene`'s film.
    pub fn offsets(&self, scene: &Scene) -> OffsetKernel {
        self.offsets
            .unwrap_or_else(|| OffsetKernel::mitsuba(film_pixels(scene)))
    }

    /// `ln T(x→y)` (module docs), `−∞` when the move cannot produce `y`
    /// from `x`. The vertices before `j` and the camera vertex are assumed
    /// shared (as every proposal has them).
    pub fn log_transition_density(&self, x: &Path, y: &Path) -> f64 {
        let Some(j) = lens_chain(x) else {
            return f64::NEG_INFINITY;
        };
        if y.len() != x.len() || lens_chain(y) != Some(j) || y.contribution.is_black() {
            return f64::NEG_INFINITY;
        }
        let scene = x.scene;
        let offset = (y.raster - x.raster).length() as f64;
        let log_p = self.offsets(scene).log_density(offset);
        log_p + film_pixels(scene).ln() + log_chain_density(y, j)
    }

    /// Draws a proposal into `y`; returns `j`, or why it failed.
    fn mutate<'s>(
        &mut self,
        x: &Path<'s>,
        y: &mut Path<'s>,
        rng: &mut ChainRng,
    ) -> Result<usize, Invalid> {
        let j = lens_chain(x).ok_or(Invalid::Pattern)?;
        let offset = self.offsets(x.scene).sample(uniform(rng), uniform(rng));
        self.retrace(x, y, j, x.raster + offset, rng)?;
        Ok(j)
    }

    /// Re-traces `x`'s camera chain `y_{k−1} … y_j` through `raster` (a
    /// camera walk from `x`'s lens point) and reconnects it to the kept
    /// `x_{j−1}` into `y` (the move's steps 2 and 3; the lens subpath
    /// mutation draws `raster` uniformly instead).
    pub(crate) fn retrace<'s>(
        &mut self,
        x: &Path<'s>,
        y: &mut Path<'s>,
        j: usize,
        raster: glam::Vec2,
        rng: &mut ChainRng,
    ) -> Result<(), Invalid> {
        let scene = x.scene;
        let k = x.segments();
        if !on_image(scene, raster) {
            return Err(Invalid::OffImage);
        }
        let cam = &x.vertices[k];
        let ray = camera_ray(x, raster).ok_or(Invalid::Pattern)?;
        let count = k - j;
        // walk[i] = y_{k−i}: the chain y_{k−1} … y_{j+1} must stay Dirac.
        trace_dirac_chain(
            scene,
            cam,
            ray,
            TransportMode::Radiance,
            count,
            &mut self.walk,
            rng,
        )?;
        let vs = &mut y.vertices;
        vs.clear();
        vs.extend_from_slice(&x.vertices[..j]);
        vs.extend(self.walk[1..].iter().rev());
        vs.push(*cam);
        finish_proposal::<Invalid>(y, |y| lens_chain(y) == Some(j), |_| Ok(()), j - 1)
    }
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

/// True when `raster` lies on `scene`'s image.
pub fn on_image(scene: &Scene, raster: Vec2) -> bool {
    let (w, h) = (scene.film.width as f32, scene.film.height as f32);
    raster.x >= 0.0 && raster.x < w && raster.y >= 0.0 && raster.y < h
}

/// The camera ray through `raster` from the lens point of `x`'s camera
/// vertex (`None` when that point is not on the lens).
pub fn camera_ray(x: &Path, raster: Vec2) -> Option<Ray> {
    let k = x.segments();
    let cam = &x.vertices[k];
    let camera = &x.scene.camera;
    if camera.has_lens() {
        // Same lens point: the numbers that make it.
        let dir = cam.direction_to(&x.vertices[k - 1])?;
        let (_, u_lens) = camera.invert(cam.p(), dir)?;
        Some(camera.generate_ray_lens(raster, u_lens))
    } else {
        Some(camera.generate_ray(raster))
    }
}

/// Pixels of `scene`'s image (the uniform raster density is its inverse).
pub fn film_pixels(scene: &Scene) -> f64 {
    scene.film.width as f64 * scene.film.height as f64
}

/// `Σ_{i=j}^{k−1} ln pdf_rev(y_i)`: the camera walk's density of the
/// re-traced vertices (`−∞` when one is zero).
pub fn log_chain_density(y: &Path, j: usize) -> f64 {
    log_density_product(y.vertices[j..y.segments()].iter().map(|v| v.pdf_rev))
}

impl<'s> Kernel<Path<'s>, PathSample> for LensPerturbation {
    fn propose(
        &mut self,
        current: &Sample<Path<'s>, PathSample>,
        proposal: &mut Sample<Path<'s>, PathSample>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let x = &current.state;
        let y = &mut proposal.state;
        let j = match self.mutate(x, y, rng) {
            Ok(j) => j,
            Err(reason) => return Proposal::failed(reason as usize),
        };
        let forward = log_chain_density(y, j);
        let backward = log_chain_density(x, j);
        if !(forward > f64::NEG_INFINITY) {
            return Proposal::failed(Invalid::ZeroDensity as usize);
        }
        Proposal::with_ratio(backward - forward, 0)
    }

    fn component_names(&self) -> Vec<String> {
        component_names(&self.name, Invalid::ALL.iter().map(|r| r.name()))
    }
}
