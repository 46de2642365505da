//! Scattering functions (BSDFs) in a local shading frame whose +z axis is
//! the shading normal.
//!
//! Conventions (shared by every BSDF and every integrator):
//! - `wo` and `wi` are unit vectors pointing *away* from the surface, in the
//!   local frame. `wo` is the direction the path arrived from (towards the
//!   camera for camera paths), `wi` the sampled direction.
//! - [`Bsdf::eval`] returns `f(wo, wi)` **without** the cosine factor.
//! - [`BsdfSample::weight`] is `f · |cos θ_i| / pdf` (the throughput factor).
//! - Delta lobes (smooth conductor, smooth and thin dielectric, the coating
//!   of `plastic`) return `is_delta` samples; `eval` and `pdf` leave them
//!   out (zero for purely delta models; the diffuse lobe alone for `plastic`).
//! - The reverse pdf bidirectional methods need is `pdf(wi, wo, mode.flip())`.
//!
//! Models ([`Bsdf`], built from a scene's [`BsdfDesc`] by [`Bsdf::from_desc`]),
//! all with Mitsuba 3 semantics:
//! - `diffuse`: one-sided Lambertian ([`diffuse`]);
//! - `conductor`: smooth, exact complex Fresnel per channel; `material="none"`
//!   is the perfect mirror ([`conductor`]);
//! - `roughconductor`: Beckmann or GGX, anisotropic, separable Smith G,
//!   visible-normal sampling ([`conductor`], [`microfacet`]);
//! - `dielectric`: smooth, reflection chosen with probability F, (η_o/η_i)²
//!   radiance scaling on refraction in radiance mode ([`dielectric`]);
//! - `roughdielectric`: Walter et al. 2007 with visible-normal sampling and
//!   the same mode-dependent factor ([`dielectric`]);
//! - `plastic`: Dirac coating reflection (Fresnel) over a diffuse base, with
//!   the internal-scattering term and Mitsuba's lobe-selection weight
//!   ([`plastic`]);
//! - `roughplastic`: Beckmann or GGX (isotropic) coating over a diffuse base,
//!   with the coating's transmittance tables computed here ([`rough_plastic`]);
//! - `thindielectric`: a thin sheet, Dirac reflection with the internal
//!   multiple-reflection sum 2r/(1 + r) and undeflected transmission
//!   ([`thin_dielectric`]);
//! - `twosided`: wraps a reflective model, mirroring queries from below.
//!
//! Beckmann shadowing: `eval` uses Mitsuba's rational fit of Smith's G1, so
//! it equals Mitsuba's value; `pdf` is the exact density of the visible
//! normals that `sample` draws (normalised only with the exact G1), not
//! Mitsuba's `pdf`, which carries the fit and so is off the true density by
//! G1_fit(wo)/G1_exact(wo) (< 0.35 %). Sample weights are `eval · cos / pdf`,
//! so every estimator converges to the integral of Mitsuba's `eval`
//! (details in [`microfacet`]).
//!
//! Where this differs from Mitsuba 3, on purpose:
//! - an index-matched `roughdielectric` is built as the smooth `dielectric`
//!   (which it equals; Mitsuba returns an infinite pdf there).
//!
//! Beyond eval/sample/pdf: [`Bsdf::eval_pdf`] (both at once, for MIS),
//! [`Bsdf::invert`] (the random numbers that sample a given direction, for
//! fused state spaces) and [`Bsdf::regularized`] (roughened copies, for
//! path-space regularization and roughness tempering).
//!
//! Random numbers: [`Bsdf::sample`] takes `u_lobe` and `u = (u.0, u.1)` for
//! every model (models ignore what they do not need). Integrators should draw
//! all three at every bounce, `u_lobe` first, so that each bounce consumes a
//! fixed number of primary-sample dimensions (what PSSMLT/MMLT need).

pub mod conductor;
pub mod desc;
pub mod dielectric;
pub mod diffuse;
pub mod fresnel;
pub mod invert;
pub mod microfacet;
pub mod model;
pub mod perturb;
pub mod plastic;
pub mod regularize;
pub mod rough_plastic;
pub mod special;
pub mod textured;
pub mod thin_dielectric;
pub mod wrapped;
pub use desc::{BsdfDesc, MicrofacetKind};
pub use model::{Bsdf, OneSided};

use crate::color::Rgb;
use glam::Vec3;

/// Whether the path carries radiance (traced from the camera) or importance
/// (traced from a light). Non-symmetric scattering (refraction) differs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TransportMode {
    /// Camera paths: radiance flows opposite to the tracing direction.
    Radiance,
    /// Light paths: importance flows opposite to the tracing direction.
    Importance,
}

impl TransportMode {
    /// The other mode.
    pub fn flip(self) -> Self {
        match self {
            TransportMode::Radiance => TransportMode::Importance,
            TransportMode::Importance => TransportMode::Radiance,
        }
    }
}

/// The result of importance sampling a BSDF.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// Sampled direction, local frame, unit length.
    pub wi: Vec3,
    /// `f · |cos θ_i| / pdf`.
    pub weight: Rgb,
    /// Solid-angle density of `wi` (for delta lobes: the discrete lobe probability).
    pub pdf: f32,
    /// True when the sampled lobe is a Dirac delta.
    pub is_delta: bool,
    /// Relative index of refraction along the sampled direction (1 for reflection).
    pub eta: f32,
}

/// The sample of a non-delta reflection lobe at `wi` (upper hemisphere),
/// given `(f, pdf) = eval_pdf(wo, wi)`: weight `f · cos θ_i / pdf`; `None`
/// below the surface, for a zero or NaN density or a non-finite weight.
#[inline]
pub(crate) fn reflection_sample(wi: Vec3, (f, pdf): (Rgb, f32)) -> Option<BsdfSample> {
    if wi.z <= 0.0 || !(pdf > 0.0) {
        return None;
    }
    let weight = f * (wi.z / pdf);
    weight.is_finite().then_some(BsdfSample {
        wi,
        weight,
        pdf,
        is_delta: false,
        eta: 1.0,
    })
}

/// Cosine of the angle to the local normal.
pub fn cos_theta(w: Vec3) -> f32 {
    w.z
}

/// True when both directions are on the same side of the surface.
pub fn same_hemisphere(a: Vec3, b: Vec3) -> bool {
    a.z * b.z > 0.0
}
