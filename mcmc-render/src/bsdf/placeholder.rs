//! Temporary Lambertian-only BSDF so the renderer works before the real
//! BSDF set lands. The lead deletes this file at merge; the method set
//! matches the real `Bsdf` exactly.

use super::{BsdfDesc, BsdfSample, TransportMode};
use crate::color::Rgb;
use glam::Vec3;
use std::f32::consts::{FRAC_1_PI, PI};

/// Runtime BSDF (placeholder: Lambertian only).
#[derive(Clone, Debug)]
pub enum Bsdf {
    /// Lambertian reflector with the given albedo (one-sided, like Mitsuba's `diffuse`).
    Diffuse(Rgb),
    /// `twosided` Lambertian: mirrored onto the back side.
    TwoSidedDiffuse(Rgb),
}

#[allow(clippy::only_used_in_recursion)] // `mode` mirrors the real BSDF interface
impl Bsdf {
    /// A Lambertian BSDF.
    pub fn diffuse(reflectance: Rgb) -> Self {
        Bsdf::Diffuse(reflectance)
    }

    /// Builds the runtime BSDF from a parsed description (placeholder: `Diffuse` only).
    pub fn from_desc(desc: &BsdfDesc) -> Result<Bsdf, String> {
        match desc {
            BsdfDesc::Diffuse { reflectance } => Ok(Bsdf::diffuse(*reflectance)),
            BsdfDesc::TwoSided { inner } => match **inner {
                BsdfDesc::Diffuse { reflectance } => Ok(Bsdf::TwoSidedDiffuse(reflectance)),
                _ => Err("placeholder: twosided supports diffuse only".into()),
            },
            other => Err(format!("BSDF {other:?} is not implemented yet")),
        }
    }

    /// `f(wo, wi)` without the cosine factor.
    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        match self {
            Bsdf::TwoSidedDiffuse(r) => {
                let (wo, wi) = flip_pair(wo, wi);
                Bsdf::Diffuse(*r).eval(wo, wi, mode)
            }
            Bsdf::Diffuse(r) => {
                if wo.z <= 0.0 || wi.z <= 0.0 {
                    Rgb::BLACK
                } else {
                    *r * FRAC_1_PI
                }
            }
        }
    }

    /// Cosine-weighted hemisphere sampling.
    pub fn sample(
        &self,
        wo: Vec3,
        _u_lobe: f32,
        u: (f32, f32),
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        match self {
            Bsdf::TwoSidedDiffuse(r) => {
                let flip = wo.z < 0.0;
                let wo = if flip { -wo } else { wo };
                let mut s = Bsdf::Diffuse(*r).sample(wo, _u_lobe, u, mode)?;
                if flip {
                    s.wi = -s.wi;
                }
                Some(s)
            }
            Bsdf::Diffuse(r) => {
                if wo.z <= 0.0 {
                    return None;
                }
                let rad = u.0.sqrt();
                let phi = 2.0 * PI * u.1;
                let z = (1.0 - u.0).max(0.0).sqrt();
                let wi = Vec3::new(rad * phi.cos(), rad * phi.sin(), z);
                let pdf = z * FRAC_1_PI;
                if pdf <= 0.0 {
                    return None;
                }
                Some(BsdfSample {
                    wi,
                    weight: *r,
                    pdf,
                    is_delta: false,
                    eta: 1.0,
                })
            }
        }
    }

    /// Solid-angle density of sampling `wi` given `wo`.
    pub fn pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        match self {
            Bsdf::TwoSidedDiffuse(r) => {
                let (wo, wi) = flip_pair(wo, wi);
                Bsdf::Diffuse(*r).pdf(wo, wi, mode)
            }
            Bsdf::Diffuse(_) => {
                if wo.z <= 0.0 || wi.z <= 0.0 {
                    0.0
                } else {
                    wi.z * FRAC_1_PI
                }
            }
        }
    }

    /// True when every lobe is a Dirac delta.
    pub fn is_delta(&self) -> bool {
        false
    }

    /// True when at least one lobe is a Dirac delta.
    pub fn has_delta_lobe(&self) -> bool {
        false
    }
}

/// Mirrors a direction pair onto the upper hemisphere of `wo`.
fn flip_pair(wo: Vec3, wi: Vec3) -> (Vec3, Vec3) {
    if wo.z < 0.0 { (-wo, -wi) } else { (wo, wi) }
}
