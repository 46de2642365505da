//! Smooth and rough dielectric interfaces (Mitsuba 3 `dielectric`,
//! `roughdielectric`).
//!
//! `eta` is η_inside/η_outside; "inside" is the side opposite the normal.
//! Refraction is non-symmetric (Veach 1997, §5.2): with η_o the index on the
//! side of `wo` and η_i on the side of `wi`, the radiance-mode BSDF carries a
//! factor (η_o/η_i)² that the importance-mode BSDF does not, so that
//! f_Radiance(wo, wi) = (η_o/η_i)² f_Importance(wo, wi) and
//! f_Importance(wo, wi) = f_Radiance(wi, wo).

use super::fresnel::{fresnel_dielectric, reflect, refract};
use super::microfacet::Microfacet;
use super::{BsdfSample, TransportMode};
use crate::color::Rgb;
use glam::Vec3;

/// A smooth dielectric: two Dirac lobes (reflection, refraction), chosen with
/// probability equal to the Fresnel reflectance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SmoothDielectric {
    /// η_inside / η_outside.
    pub eta: f32,
    /// Scale on reflection.
    pub specular_reflectance: Rgb,
    /// Scale on transmission.
    pub specular_transmittance: Rgb,
}

impl SmoothDielectric {
    /// Chooses reflection when `u_lobe < F`, else refraction. The weight is the
    /// colour scale (the Fresnel factor cancels against the lobe probability),
    /// times (η_o/η_i)² = `eta_ti²` on refraction in radiance mode.
    pub fn sample(&self, wo: Vec3, u_lobe: f32, mode: TransportMode) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let fr = fresnel_dielectric(wo.z, self.eta);
        if u_lobe < fr.r {
            Some(BsdfSample {
                wi: Vec3::new(-wo.x, -wo.y, wo.z),
                weight: self.specular_reflectance,
                pdf: fr.r,
                is_delta: true,
                eta: 1.0,
            })
        } else {
            let wi = Vec3::new(-fr.eta_ti * wo.x, -fr.eta_ti * wo.y, fr.cos_t);
            let scale = match mode {
                TransportMode::Radiance => fr.eta_ti * fr.eta_ti,
                TransportMode::Importance => 1.0,
            };
            Some(BsdfSample {
                wi,
                weight: self.specular_transmittance * scale,
                pdf: 1.0 - fr.r,
                is_delta: true,
                eta: fr.eta_it,
            })
        }
    }
}

/// A rough dielectric interface (Walter et al. 2007) with visible-normal
/// sampling and the separable Smith term.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoughDielectric {
    /// Microfacet distribution.
    pub distribution: Microfacet,
    /// η_inside / η_outside.
    pub eta: f32,
    /// Scale on reflection.
    pub specular_reflectance: Rgb,
    /// Scale on transmission.
    pub specular_transmittance: Rgb,
}

/// The microfacet normal connecting `wo` and `wi`, oriented up, with the
/// quantities every query needs; `None` for degenerate or back-facing
/// configurations.
struct HalfVector {
    h: Vec3,
    reflect: bool,
    /// η on the `wi` side over η on the `wo` side (1 for reflection).
    eta_path: f32,
    wo_h: f32,
    wi_h: f32,
}

impl RoughDielectric {
    fn half_vector(&self, wo: Vec3, wi: Vec3) -> Option<HalfVector> {
        let (co, ci) = (wo.z, wi.z);
        if co == 0.0 || ci == 0.0 {
            return None;
        }
        let reflect = co * ci > 0.0;
        let eta_path = if reflect {
            1.0
        } else if co > 0.0 {
            self.eta
        } else {
            1.0 / self.eta
        };
        // Generalised half vector: ∝ η_o·wo + η_i·wi (Walter et al. eq. 16).
        let h = (wo + wi * eta_path).normalize_or_zero();
        if h.z == 0.0 {
            return None;
        }
        let h = if h.z < 0.0 { -h } else { h };
        let (wo_h, wi_h) = (wo.dot(h), wi.dot(h));
        // Each direction must see the front of the microfacet from its own side.
        if wo_h * co <= 0.0 || wi_h * ci <= 0.0 {
            return None;
        }
        Some(HalfVector {
            h,
            reflect,
            eta_path,
            wo_h,
            wi_h,
        })
    }

    /// f(wo, wi) without the cosine, in the given transport mode.
    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        self.eval_pdf(wo, wi, mode).0
    }

    /// Density of `wi` (mode-independent): visible-normal density from the
    /// side of `wo`, times the lobe probability (F or 1 − F), times the
    /// half-vector Jacobian.
    pub fn pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        self.eval_pdf(wo, wi, mode).1
    }

    /// `eval` and `pdf` together, sharing the half vector, D, G1 and F.
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Rgb, f32) {
        let Some(hv) = self.half_vector(wo, wi) else {
            return (Rgb::BLACK, 0.0);
        };
        let d = self.distribution.d(hv.h);
        if d == 0.0 {
            return (Rgb::BLACK, 0.0);
        }
        // g1 repeats half_vector's orientation test; it passes here.
        // Mitsuba's G1 in the value, the exact one in the visible-normal
        // density (see the `microfacet` module documentation).
        let (g1o, g1o_exact) = self.distribution.g1_both(wo, hv.h);
        let g1i = self.distribution.g1(wi, hv.h);
        // Fresnel is symmetric across a refraction pair, but evaluated from
        // the denser side it loses all precision near the critical angle
        // (cos²θ_t cancels). For transmission, evaluate it from the outside,
        // where it is well-conditioned; this also keeps f(wo, wi) and
        // f(wi, wo) consistent.
        let cos_fresnel = if hv.reflect || wo.z > 0.0 {
            hv.wo_h
        } else {
            hv.wi_h
        };
        let f = fresnel_dielectric(cos_fresnel, self.eta).r;
        let (co, ci) = (wo.z.abs(), wi.z.abs());
        // Visible-normal density from the side of wo: G1(wo) |wo·h| D / |cos θ_o|.
        let pdf_m = g1o_exact * hv.wo_h.abs() * d / co;
        let (value, pdf) = if hv.reflect {
            let v = self.specular_reflectance * (f * d * g1o * g1i / (4.0 * co * ci));
            (v, pdf_m * f / (4.0 * hv.wi_h.abs()))
        } else {
            let denom = hv.wo_h + hv.eta_path * hv.wi_h;
            let eta2 = hv.eta_path * hv.eta_path;
            // Walter et al. eq. 21 in importance form:
            // η² |wo·h||wi·h| (1−F) D G / (|cos θ_o cos θ_i| (wo·h + η wi·h)²);
            // radiance mode drops the η² (the 1/η² solid-angle compression).
            let mode_eta2 = match mode {
                TransportMode::Radiance => 1.0,
                TransportMode::Importance => eta2,
            };
            let jac = eta2 * hv.wi_h.abs() / (denom * denom);
            let v = mode_eta2 * (1.0 - f) * d * g1o * g1i * (hv.wo_h * hv.wi_h).abs()
                / (co * ci * denom * denom);
            (self.specular_transmittance * v, pdf_m * (1.0 - f) * jac)
        };
        if pdf.is_finite() && value.is_finite() {
            (value, pdf)
        } else {
            (Rgb::BLACK, 0.0)
        }
    }

    /// Samples a visible normal from the side of `wo` (consuming `u`), then
    /// reflects with probability F (decided by `u_lobe`) or refracts.
    /// The weight is G1(wi, m) times the colour scale, times (η_o/η_i)² on
    /// refraction in radiance mode; it and the pdf are evaluated from the final
    /// (wo, wi) pair so that they equal `eval`/`pdf` exactly (near the critical
    /// angle, f32 rounding would otherwise make them differ by percents).
    pub fn sample(
        &self,
        wo: Vec3,
        u_lobe: f32,
        u: (f32, f32),
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let wo_up = if wo.z < 0.0 { -wo } else { wo };
        let m = self.distribution.sample_visible(wo_up, u);
        let fr = fresnel_dielectric(wo.dot(m), self.eta);
        let (wi, eta) = if u_lobe < fr.r {
            let wi = reflect(wo, m);
            if wi.z * wo.z <= 0.0 {
                return None;
            }
            (wi, 1.0)
        } else {
            let wi = refract(wo, m, fr.cos_t, fr.eta_ti).normalize_or_zero();
            if wi.z * wo.z >= 0.0 {
                return None;
            }
            (wi, fr.eta_it)
        };
        let (f, pdf) = self.eval_pdf(wo, wi, mode);
        if pdf.is_nan() || pdf <= 0.0 {
            return None;
        }
        let weight = f * (wi.z.abs() / pdf);
        weight.is_finite().then_some(BsdfSample {
            wi,
            weight,
            pdf,
            is_delta: false,
            eta,
        })
    }
}
