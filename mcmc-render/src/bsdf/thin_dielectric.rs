//! Thin dielectric sheet (Mitsuba 3 `thindielectric`): two parallel smooth
//! interfaces so close that light leaves the sheet undeflected.
//!
//! With r = F(|cos θ_o|) the reflectance of one interface, the light that
//! is reflected at the first interface or crosses it (t = 1 − r), bounces an
//! odd number of times inside and crosses back sums to
//! R = r + t² r Σₖ r^{2k} = r + t² r/(1 − r²) = 2r/(1 + r);
//! the rest, T = 1 − R, leaves on the far side along
//! −`wo` (η = 1 across the sheet, so no radiance scaling and the same BSDF
//! in both transport modes). Both lobes are Dirac deltas, chosen with
//! probabilities R and T; the sample weights are the colour scales.

use super::fresnel::fresnel_dielectric;
use super::{BsdfSample, TransportMode};
use crate::color::Rgb;
use glam::Vec3;

/// A thin dielectric sheet.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThinDielectric {
    /// η_inside / η_outside of the sheet's material.
    pub eta: f32,
    /// Scale on reflection.
    pub specular_reflectance: Rgb,
    /// Scale on transmission.
    pub specular_transmittance: Rgb,
}

impl ThinDielectric {
    /// Total reflectance R = 2r/(1 + r) of the sheet for incidence `wo`
    /// (either side).
    pub fn reflectance(&self, wo: Vec3) -> f32 {
        let r = fresnel_dielectric(wo.z.abs(), self.eta).r;
        2.0 * r / (1.0 + r)
    }

    /// Reflection when `u_lobe < R` (mirror about the normal, same side),
    /// else straight through (−`wo`).
    pub fn sample(&self, wo: Vec3, u_lobe: f32, _mode: TransportMode) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let r = self.reflectance(wo);
        let (wi, weight, pdf) = if u_lobe < r {
            (Vec3::new(-wo.x, -wo.y, wo.z), self.specular_reflectance, r)
        } else {
            (-wo, self.specular_transmittance, 1.0 - r)
        };
        (pdf > 0.0).then_some(BsdfSample {
            wi,
            weight,
            pdf,
            is_delta: true,
            eta: 1.0,
        })
    }
}
