//! Textured BSDF parameters: which colour parameters of a BSDF come from
//! a texture, and the BSDF at a surface point ([`BsdfAt`]).
//!
//! The scene keeps every BSDF as built from its file ([`Bsdf`], the
//! textured parameters holding the texture's mean) and, beside it, its
//! [`BsdfTextures`]. At a hit, [`BsdfTextures::apply`] copies the BSDF
//! (a small `Copy` value) and writes the texture values at the point's UV
//! into it: no allocation, and untextured BSDFs are lent as they are.

use super::microfacet::Microfacet;
use super::perturb::Perturbed;
use super::wrapped::Wrap;
use super::{Bsdf, BsdfSample, OneSided, TransportMode};
use crate::color::Rgb;
use crate::texture::Texture;
use glam::{Vec2, Vec3};

/// A parameter of a BSDF that may be textured: a colour, or a microfacet
/// roughness (a scalar, read with [`Texture::eval_1`] as Mitsuba 3 reads a
/// float texture).
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
    /// Isotropic roughness `alpha` of `roughconductor` (also inside
    /// `twosided`) and `roughdielectric`: Mitsuba 3 takes a texture there
    /// (not for `roughplastic`, whose coating tables depend on it).
    Alpha,
    /// `alpha_u` (roughness along the tangent) of the same models.
    AlphaU,
    /// `alpha_v` (roughness along the bitangent) of the same models.
    AlphaV,
}

impl TexturedParam {
    /// Its name in a Mitsuba scene file.
    pub fn name(self) -> &'static str {
        match self {
            TexturedParam::Reflectance => "reflectance",
            TexturedParam::SpecularReflectance => "specular_reflectance",
            TexturedParam::SpecularTransmittance => "specular_transmittance",
            TexturedParam::DiffuseReflectance => "diffuse_reflectance",
            TexturedParam::Alpha => "alpha",
            TexturedParam::AlphaU => "alpha_u",
            TexturedParam::AlphaV => "alpha_v",
        }
    }

    /// Writes the value of `texture` at `uv` into `bsdf`; false when the
    /// model has no such parameter. A roughness goes through
    /// [`Microfacet::new`], which clamps it below at `MIN_ALPHA` as
    /// Mitsuba 3's distribution does.
    #[inline]
    fn set(self, bsdf: &mut Bsdf, texture: &Texture, uv: Vec2) -> bool {
        use TexturedParam::*;
        match self {
            Alpha | AlphaU | AlphaV => {
                let Some(m) = Self::microfacet(bsdf) else {
                    return false;
                };
                let a = texture.eval_1(uv);
                let (au, av) = m.alpha();
                let (au, av) = match self {
                    Alpha => (a, a),
                    AlphaU => (a, av),
                    _ => (au, a),
                };
                *m = Microfacet::new(m.kind(), au, av);
                true
            }
            _ => match self.field(bsdf) {
                Some(field) => {
                    *field = texture.eval(uv);
                    true
                }
                None => false,
            },
        }
    }

    /// The distribution of the models whose roughness may be textured.
    fn microfacet(bsdf: &mut Bsdf) -> Option<&mut Microfacet> {
        match bsdf {
            Bsdf::RoughConductor(b) | Bsdf::TwoSided(OneSided::RoughConductor(b)) => {
                Some(&mut b.distribution)
            }
            Bsdf::RoughDielectric(b) => Some(&mut b.distribution),
            _ => None,
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

    /// True when `alpha_u` or `alpha_v` is textured: the roughness may
    /// then differ along the two tangents somewhere on the surface.
    pub fn may_be_anisotropic(&self) -> bool {
        self.0
            .iter()
            .any(|(param, _)| matches!(param, TexturedParam::AlphaU | TexturedParam::AlphaV))
    }

    /// Checks that `bsdf` has every textured parameter (one line naming
    /// the first it lacks).
    pub fn check(&self, bsdf: &Bsdf) -> Result<(), String> {
        let mut b = *bsdf;
        for (param, texture) in &self.0 {
            if !param.set(&mut b, texture, Vec2::ZERO) {
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
            param.set(&mut b, texture, uv);
        }
        b
    }
}

/// The BSDF at a surface point, as every integrator sees it: the scene's
/// model lent when untextured, a copy textured at the point's UV, or
/// either under `normalmap`, `bumpmap` or `mask` with what they make of
/// the point ([`Wrap`]: the perturbed frame, the opacity). Its `eval`, `eval_pdf`, `sample` and `pdf` take
/// directions in the point's shading frame ([`crate::scene::Scene::shading_frame`]),
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

    /// [`BsdfAt::invert_in`] in radiance mode. The numbers are the same
    /// in both modes except under `normalmap`/`bumpmap`, whose importance
    /// sampler chooses between two frames: callers inverting light
    /// subpaths use [`BsdfAt::invert_in`].
    pub fn invert(
        &self,
        wo: Vec3,
        wi: Vec3,
        u_choice: f32,
    ) -> Option<crate::bsdf::invert::SampleInverse> {
        self.invert_in(wo, wi, u_choice, TransportMode::Radiance)
    }

    /// [`Bsdf::invert`] at the point: the numbers that make
    /// [`BsdfAt::sample`] in `mode` return `wi`, under `normalmap`,
    /// `bumpmap` and `mask` too ([`Wrap::invert`]: the mask's null lobe
    /// is the interval `[α, 1)` of `u_lobe`, the nested lobes are scaled
    /// into `[0, α)`, and a perturbed frame is inverted in the frame the
    /// sampler draws from).
    pub fn invert_in(
        &self,
        wo: Vec3,
        wi: Vec3,
        u_choice: f32,
        mode: TransportMode,
    ) -> Option<crate::bsdf::invert::SampleInverse> {
        match self {
            BsdfAt::Shared(b) => b.invert(wo, wi, u_choice),
            BsdfAt::Textured(b) => b.invert(wo, wi, u_choice),
            BsdfAt::Wrapped(b, w) => w.invert(b, wo, wi, u_choice, mode),
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

    /// A roughness texture writes its scalar value at the UV into the
    /// copy's distribution, which then equals the model built with that
    /// constant roughness (so eval, sample, pdf, invert and the adjoint
    /// all see it); `regularized` raises the textured value, not the
    /// template's; `roughplastic` and diffuse have no textured roughness.
    #[test]
    fn textured_roughness() {
        use crate::bsdf::MicrofacetKind;
        let desc = |a: f32| BsdfDesc::RoughDielectric {
            distribution: MicrofacetKind::Ggx,
            alpha_u: a,
            alpha_v: 0.3,
            int_ior: 1.5,
            ext_ior: 1.0,
            specular_reflectance: Rgb::WHITE,
            specular_transmittance: Rgb::WHITE,
        };
        let template = Bsdf::from_desc(&desc(0.2)).unwrap();
        let t = BsdfTextures(vec![(TexturedParam::AlphaU, board())]);
        t.check(&template).unwrap();
        // board(): color0 (0.9, 0.1, 0.1), color1 (0.1, 0.1, 0.9); the
        // scalar lookup is the other colour's channel mean (Mitsuba 3.9.1).
        for (uv, a) in [
            (Vec2::new(0.25, 0.25), (0.1f32 + 0.1 + 0.9) / 3.0),
            (Vec2::new(0.75, 0.25), (0.9f32 + 0.1 + 0.1) / 3.0),
        ] {
            let b = t.apply(&template, uv);
            assert_eq!(b, Bsdf::from_desc(&desc(a)).unwrap());
            match b.regularized(0.5) {
                Bsdf::RoughDielectric(d) => assert_eq!(d.distribution.alpha(), (0.5, 0.5)),
                other => panic!("{other:?}"),
            }
            match b.regularized(0.35) {
                Bsdf::RoughDielectric(d) => assert_eq!(d.distribution.alpha(), (a.max(0.35), 0.35)),
                other => panic!("{other:?}"),
            }
        }
        let plastic = Bsdf::from_desc(&BsdfDesc::RoughPlastic {
            distribution: MicrofacetKind::Beckmann,
            alpha: 0.1,
            sample_visible: true,
            diffuse_reflectance: Rgb::splat(0.5),
            specular_reflectance: Rgb::WHITE,
            int_ior: 1.49,
            ext_ior: 1.0,
            nonlinear: false,
        })
        .unwrap();
        let alpha = BsdfTextures(vec![(TexturedParam::Alpha, board())]);
        assert!(alpha.check(&plastic).is_err());
        assert!(alpha.check(&Bsdf::diffuse(Rgb::splat(0.5))).is_err());
    }
}
