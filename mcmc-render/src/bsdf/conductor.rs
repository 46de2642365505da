//! Smooth and rough conductors (Mitsuba 3 `conductor`, `roughconductor`).

use super::fresnel::{ConductorFresnel, reflect};
use super::microfacet::Microfacet;
use super::{BsdfSample, TransportMode, reflection_sample};
use crate::color::Rgb;
use glam::Vec3;

/// A smooth conductor: a single Dirac reflection lobe weighted by the full
/// complex Fresnel term (the perfect mirror when `eta = 0, k = 1`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SmoothConductor {
    /// Complex index of refraction.
    pub fresnel: ConductorFresnel,
    /// Scale on the Fresnel reflectance.
    pub specular_reflectance: Rgb,
}

impl SmoothConductor {
    /// Mirror reflection about the normal; `None` from below the surface or
    /// when nothing is reflected.
    pub fn sample(&self, wo: Vec3, _mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let weight = self.specular_reflectance * self.fresnel.eval(wo.z);
        (!weight.is_black()).then_some(BsdfSample {
            wi: Vec3::new(-wo.x, -wo.y, wo.z),
            weight,
            pdf: 1.0,
            is_delta: true,
            eta: 1.0,
        })
    }
}

/// A rough conductor: Cook–Torrance microfacet reflection,
/// f = F(wo·h) D(h) G(wo, wi, h) / (4 cos θ_o cos θ_i), sampled through
/// visible normals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoughConductor {
    /// Microfacet distribution.
    pub distribution: Microfacet,
    /// Complex index of refraction.
    pub fresnel: ConductorFresnel,
    /// Scale on the Fresnel reflectance.
    pub specular_reflectance: Rgb,
}

impl RoughConductor {
    /// f(wo, wi) without the cosine; zero unless both directions are above.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        self.eval_pdf(wo, wi).0
    }

    /// Density of `wi`: visible-normal density times the reflection Jacobian
    /// 1/(4 wo·h).
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.eval_pdf(wo, wi).1
    }

    /// `eval` and `pdf` together, sharing the half vector, D and G1.
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return (Rgb::BLACK, 0.0);
        }
        let h = (wo + wi).normalize_or_zero();
        let woh = wo.dot(h);
        let d = self.distribution.d(h);
        if d == 0.0 || woh <= 0.0 {
            return (Rgb::BLACK, 0.0);
        }
        // Mitsuba's G1 in the value, the exact one in the density (see the
        // `microfacet` module documentation).
        let (g1o, g1o_exact) = self.distribution.g1_both(wo, h);
        let g1i = self.distribution.g1(wi, h);
        let f = self.fresnel.eval(woh);
        let value = self.specular_reflectance * f * (d * g1o * g1i / (4.0 * wo.z * wi.z));
        // Visible-normal density G1(wo) (wo·h) D / cos θ_o, times 1/(4 wo·h).
        let pdf = g1o_exact * d / (4.0 * wo.z);
        if pdf.is_finite() && value.is_finite() {
            (value, pdf)
        } else {
            (Rgb::BLACK, 0.0)
        }
    }

    /// Samples a visible normal and reflects `wo` about it. The weight is
    /// F · G1(wi) (D and G1(wo) cancel against the pdf; for Beckmann times
    /// G1_fit(wo)/G1_exact(wo), see [`Microfacet::g1`]); weight and pdf are
    /// evaluated from the final (wo, wi) pair so they match `eval`/`pdf`.
    pub fn sample(&self, wo: Vec3, u: (f32, f32), _mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let m = self.distribution.sample_visible(wo, u);
        let wi = reflect(wo, m).normalize_or_zero();
        reflection_sample(wi, self.eval_pdf(wo, wi))
    }
}
