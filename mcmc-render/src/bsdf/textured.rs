//! Textured BSDF parameters: which colour parameters of a BSDF come from
//! a texture, and the BSDF at a surface point ([`BsdfAt`]).
//!
//! The scene keeps every BSDF as built from its file ([`Bsdf`], the
//! textured parameters holding the texture's mean) and, beside it, its
//! [`BsdfTextures`]. At a hit, [`BsdfTextures::apply`] copies the BSDF
//! (a small `Copy` value) and writes the texture values at the point's UV
//! into it: no allocation, and untextured BSDFs are lent as they are.

use super::perturb::Perturbed;
use super::wrapped::Wrap;
use super::{Bsdf, BsdfSample, OneSided, TransportMode};
use crate::color::Rgb;
use crate::texture::Texture;
use glam::{Vec2, Vec3};

/// A colour parameter of a BSDF that may be textured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TexturedParam {
    /// `reflectance` of `diffuse` (also inside `twosided`).
    Reflectance,
    /// `specular_reflectance` of `conductor`, `roughconductor`,
    /// `dielectric`, `roughdielectric` (and the conductors in `twosided`).
    SpecularReflectance,
    /// `specular_transmittance` of `dielectric` and `roughdielectric`.
    SpecularTransmittance,
    /// `diffuse_reflectance` of `plastic` and `roughplastic` (also inside
    /// `twosided`). Their lobe-selection weight stays the one computed from
    /// the texture's mean, as Mitsuba 3 computes it.
    DiffuseReflectance,
}

impl TexturedParam {
    /// Its name in a Mitsuba scene file.
    pub fn name(self) -> &'static str {
        match self {
            TexturedParam::Reflectance => "reflectance",
            TexturedParam::SpecularReflectance => "specular_reflectance",
            TexturedParam::SpecularTransmittance => "specular_transmittance",
            TexturedParam::DiffuseReflectance => "diffuse_reflectance",
        }
    }

    /// The field of `bsdf` this parameter sets, if the model has it.
    fn field(self, bsdf: &mut Bsdf) -> Option<&mut Rgb> {
        use TexturedParam::*;
        Some(match (self, bsdf) {
            (Reflectance, Bsdf::Diffuse(b) | Bsdf::TwoSided(OneSided::Diffuse(b))) => {
                &mut b.reflectance
            }
            (SpecularReflectance, Bsdf::Conductor(b) | Bsdf::TwoSided(OneSided::Conductor(b))) => {
                &mut b.specular_reflectance
            }
            (
                SpecularReflectance,
                Bsdf::RoughConductor(b) | Bsdf::TwoSided(OneSided::RoughConductor(b)),
            ) => &mut b.specular_reflectance,
            (SpecularReflectance, Bsdf::Dielectric(b)) => &mut b.specular_reflectance,
            (SpecularReflectance, Bsdf::RoughDielectric(b)) => &mut b.specular_reflectance,
            (SpecularTransmittance, Bsdf::Dielectric(b)) => &mut b.specular_transmittance,
            (SpecularTransmittance, Bsdf::RoughDielectric(b)) => &mut b.specular_transmittance,
            (DiffuseReflectance, Bsdf::Plastic(b) | Bsdf::TwoSided(OneSided::Plastic(b))) => {
                b.diffuse_reflectance_mut()
            }
            (
                DiffuseReflectance,
                Bsdf::RoughPlastic(b) | Bsdf::TwoSided(OneSided::RoughPlastic(b)),
            ) => b.diffuse_reflectance_mut(),
            _ => return None,
        })
    }
}

/// The textured parameters of one BSDF (empty for most).
#[derive(Clone, Debug, Default)]
pub struct BsdfTextures(pub Vec<(TexturedParam, Texture)>);

impl BsdfTextures {
    /// True when no parameter is textured.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// Checks that `bsdf` has every textured parameter (one line naming
    /// the first it lacks).
    pub fn check(&self, bsdf: &Bsdf) -> Result<(), String> {
        let mut b = *bsdf;
        for (param, _) in &self.0 {
            if param.field(&mut b).is_none() {
                return Err(format!(
                    "a texture for '{}' does not apply to this BSDF",
                    param.name()
                ));
            }
        }
        Ok(())
    }

    /// `bsdf` with its textured parameters set to the textures' values at `uv`.
    #[inline]
    pub fn apply(&self, bsdf: &Bsdf, uv: Vec2) -> Bsdf {
        let mut b = *bsdf;
        for (param, texture) in &self.0 {
            if let Some(field) = param.field(&mut b) {
                *field = texture.eval(uv);
            }
        }
        b
    }
}

/// The BSDF at a surface point, as every integrator sees it: the scene's
/// model lent when untextured, a copy textured at the point's UV, or
/// either under `normalmap`, `bumpmap` or `mask` with what they make of
/// the point ([`Wrap`]: the perturbed frame, the opacity). Its `eval`, `eval_pdf`, `sample` and `pdf` take
/// directions in the point's shading frame (`Frame::from_normal(sp.ns)`),
/// as [`Bsdf`]'s do.
#[derive(Clone, Copy, Debug)]
pub enum BsdfAt<'a> {
    /// The scene's BSDF, unchanged.
    Shared(&'a Bsdf),
    /// A copy with the texture values at the point.
    Textured(Bsdf),
    /// A (possibly textured) copy under wrappers.
    Wrapped(Bsdf, Wrap),
}

impl BsdfAt<'_> {
    /// The (textured) model, without the perturbation.
    #[inline(always)]
    pub fn model(&self) -> &Bsdf {
        match self {
            BsdfAt::Shared(b) => b,
            BsdfAt::Textured(b) | BsdfAt::Wrapped(b, _) => b,
        }
    }

    /// The perturbed frame, under `normalmap` or `bumpmap`.
    pub fn perturbed(&self) -> Option<&Perturbed> {
        match self {
            BsdfAt::Wrapped(_, w) => w.perturbed.as_ref(),
            _ => None,
        }
    }

    /// [`Bsdf::eval`] at the point.
    #[inline(always)]
    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        match self {
            BsdfAt::Shared(b) => b.eval(wo, wi, mode),
            BsdfAt::Textured(b) => b.eval(wo, wi, mode),
            BsdfAt::Wrapped(b, w) => w.eval_pdf(b, wo, wi, mode).0,
        }
    }

    /// [`Bsdf::eval_pdf`] at the point.
    #[inline(always)]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Rgb, f32) {
        match self {
            BsdfAt::Shared(b) => b.eval_pdf(wo, wi, mode),
            BsdfAt::Textured(b) => b.eval_pdf(wo, wi, mode),
            BsdfAt::Wrapped(b, w) => w.eval_pdf(b, wo, wi, mode),
        }
    }

    /// [`Bsdf::sample`] at the point.
    #[inline(always)]
    pub fn sample(
        &self,
        wo: Vec3,
        u_lobe: f32,
        u: (f32, f32),
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        match self {
            BsdfAt::Shared(b) => b.sample(wo, u_lobe, u, mode),
            BsdfAt::Textured(b) => b.sample(wo, u_lobe, u, mode),
            BsdfAt::Wrapped(b, w) => w.sample(b, wo, u_lobe, u, mode),
        }
    }

    /// [`Bsdf::pdf`] at the point.
    #[inline(always)]
    pub fn pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        match self {
            BsdfAt::Shared(b) => b.pdf(wo, wi, mode),
            BsdfAt::Textured(b) => b.pdf(wo, wi, mode),
            BsdfAt::Wrapped(b, w) => w.eval_pdf(b, wo, wi, mode).1,
        }
    }

    /// True when every lobe is a Dirac delta ([`Bsdf::is_delta`]; a
    /// perturbation tilts lobes but keeps them Dirac or not; a fully
    /// transparent masked point has only the null lobe).
    #[inline(always)]
    pub fn is_delta(&self) -> bool {
        match self {
            BsdfAt::Wrapped(b, w) => w.is_delta(b),
            _ => self.model().is_delta(),
        }
    }

    /// [`Bsdf::invert`] at the point: the numbers that make
    /// [`BsdfAt::sample`] return `wi`. Not implemented under wrappers
    /// (`normalmap`, `bumpmap`, `mask`): `None` there, which
    /// inverse-sampling callers treat as "no such sample".
    pub fn invert(
        &self,
        wo: Vec3,
        wi: Vec3,
        u_choice: f32,
    ) -> Option<crate::bsdf::invert::SampleInverse> {
        match self {
            BsdfAt::Shared(b) => b.invert(wo, wi, u_choice),
            BsdfAt::Textured(b) => b.invert(wo, wi, u_choice),
            BsdfAt::Wrapped(..) => None,
        }
    }

    /// True when a lobe is a Dirac delta ([`Bsdf::has_delta_lobe`], and
    /// the null lobe of a masked point that is not fully opaque).
    pub fn has_delta_lobe(&self) -> bool {
        match self {
            BsdfAt::Wrapped(b, w) => w.has_delta_lobe(b),
            _ => self.model().has_delta_lobe(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::BsdfDesc;
    use crate::texture::Checkerboard;
    use glam::Affine2;

    fn board() -> Texture {
        Texture::Checkerboard(Box::new(Checkerboard {
            color0: Texture::Constant(Rgb::new(0.9, 0.1, 0.1)),
            color1: Texture::Constant(Rgb::new(0.1, 0.1, 0.9)),
            to_uv: Affine2::IDENTITY,
        }))
    }

    /// A textured two-sided diffuse BSDF evaluates to the texture's value
    /// at the UV, from both sides, and leaves the template untouched.
    #[test]
    fn textured_two_sided_diffuse() {
        let desc = BsdfDesc::TwoSided {
            inner: Box::new(BsdfDesc::Diffuse {
                reflectance: Rgb::splat(0.5),
            }),
        };
        let template = Bsdf::from_desc(&desc).unwrap();
        let t = BsdfTextures(vec![(TexturedParam::Reflectance, board())]);
        t.check(&template).unwrap();
        let up = glam::Vec3::new(0.0, 0.6, 0.8);
        let down = glam::Vec3::new(0.0, 0.6, -0.8);
        let mode = crate::bsdf::TransportMode::Radiance;
        for (uv, want) in [
            (Vec2::new(0.25, 0.25), Rgb::new(0.9, 0.1, 0.1)),
            (Vec2::new(0.75, 0.25), Rgb::new(0.1, 0.1, 0.9)),
        ] {
            let b = t.apply(&template, uv);
            let f = want * std::f32::consts::FRAC_1_PI;
            assert_eq!(b.eval(up, up, mode), f);
            assert_eq!(b.eval(down, down, mode), f);
        }
        assert_eq!(template, Bsdf::from_desc(&desc).unwrap());
    }

    /// A texture bound to a parameter the model lacks is refused.
    #[test]
    fn mismatched_parameter_is_refused() {
        let diffuse = Bsdf::diffuse(Rgb::splat(0.5));
        let t = BsdfTextures(vec![(TexturedParam::SpecularTransmittance, board())]);
        assert!(t.check(&diffuse).is_err());
    }
}
