//! Smooth plastic (Mitsuba 3 `plastic`): a diffuse base under a smooth
//! dielectric coating.
//!
//! Two lobes. A Dirac reflection off the coating, weighted by the Fresnel
//! reflectance F(cos θ_o) and `specular_reflectance`. And a diffuse lobe:
//! light refracts in (1 − F(cos θ_o)), scatters off the Lambertian base,
//! bounces between base and coating any number of times, and refracts out
//! (1 − F(cos θ_i)); summing the internal bounces in closed form gives
//!
//!   f_d = R / (1 − F_dr) · (1 − F(cos θ_o)) (1 − F(cos θ_i)) / (η² π),
//!
//! with F_dr the diffuse Fresnel reflectance of the coating seen from inside
//! ([`fresnel_diffuse_reflectance`] of 1/η), R the `diffuse_reflectance`, and
//! with `nonlinear` the denominator 1 − R·F_dr (the colour shift real
//! coatings show; Mitsuba's default keeps the linear form so textures keep
//! their colours). f_d is symmetric in its directions, so the adjoint
//! (importance) BSDF is the same.
//!
//! Sampling, as Mitsuba: the specular lobe is chosen with probability
//! F·w / (F·w + (1 − F)(1 − w)), F = F(cos θ_o), w = s / (d + s) with s and d
//! the channel means of the specular and diffuse reflectances; the diffuse
//! lobe is cosine-sampled. `pdf` is the diffuse lobe's density times its
//! selection probability (the Dirac lobe has none).

use super::diffuse::square_to_cosine_hemisphere;
use super::fresnel::{fresnel_dielectric, fresnel_diffuse_reflectance};
use super::{BsdfSample, TransportMode, reflection_sample};
use crate::color::Rgb;
use glam::Vec3;
use std::f32::consts::FRAC_1_PI;

/// Smooth plastic with Mitsuba 3's parameters; build with [`SmoothPlastic::new`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SmoothPlastic {
    /// η_inside / η_outside of the coating.
    eta: f32,
    /// Diffuse albedo of the base.
    diffuse_reflectance: Rgb,
    /// Scale on the specular reflection.
    specular_reflectance: Rgb,
    /// Mitsuba's `nonlinear`: internal scattering shifts colours.
    nonlinear: bool,
    /// Diffuse Fresnel reflectance of the coating from inside.
    fdr_int: f32,
    /// Weight w of the specular lobe in the lobe choice.
    specular_sampling_weight: f32,
}

/// Mean of the three channels (Mitsuba's `mean()` of an RGB value).
pub(crate) fn channel_mean(c: Rgb) -> f32 {
    (c.r + c.g + c.b) / 3.0
}

impl SmoothPlastic {
    /// The diffuse base's albedo, for textures to set per hit (the lobe
    /// weight keeps the value computed at construction).
    pub(crate) fn diffuse_reflectance_mut(&mut self) -> &mut Rgb {
        &mut self.diffuse_reflectance
    }

    /// A plastic with relative index `eta` (int/ext, positive and not 1),
    /// base albedo `diffuse_reflectance` and specular scale `specular_reflectance`.
    pub fn new(
        eta: f32,
        diffuse_reflectance: Rgb,
        specular_reflectance: Rgb,
        nonlinear: bool,
    ) -> Self {
        let (d, s) = (
            channel_mean(diffuse_reflectance),
            channel_mean(specular_reflectance),
        );
        SmoothPlastic {
            eta,
            diffuse_reflectance,
            specular_reflectance,
            nonlinear,
            fdr_int: fresnel_diffuse_reflectance(1.0 / eta),
            // An all-black material (d = s = 0) would give 0/0.
            specular_sampling_weight: if d + s > 0.0 { s / (d + s) } else { 0.5 },
        }
    }

    /// η_inside / η_outside.
    pub fn eta(&self) -> f32 {
        self.eta
    }

    /// The base albedo.
    pub fn diffuse_reflectance(&self) -> Rgb {
        self.diffuse_reflectance
    }

    /// The specular scale.
    pub fn specular_reflectance(&self) -> Rgb {
        self.specular_reflectance
    }

    /// Mitsuba's `nonlinear` flag.
    pub fn nonlinear(&self) -> bool {
        self.nonlinear
    }

    /// Albedo of the base after the internal bounces, divided by η²π: the
    /// direction-independent factor of the diffuse lobe.
    fn diffuse_scale(&self) -> Rgb {
        let r = self.diffuse_reflectance;
        let denom = if self.nonlinear {
            Rgb::WHITE - r * self.fdr_int
        } else {
            Rgb::splat(1.0 - self.fdr_int)
        };
        Rgb::new(r.r / denom.r, r.g / denom.g, r.b / denom.b) * (FRAC_1_PI / (self.eta * self.eta))
    }

    /// Probability of choosing the specular lobe, given F(cos θ_o).
    pub fn specular_probability(&self, f_o: f32) -> f32 {
        let ps = f_o * self.specular_sampling_weight;
        let pd = (1.0 - f_o) * (1.0 - self.specular_sampling_weight);
        if ps + pd > 0.0 { ps / (ps + pd) } else { 0.0 }
    }

    /// Fresnel reflectance of the coating for a direction above it.
    pub fn fresnel(&self, cos: f32) -> f32 {
        fresnel_dielectric(cos, self.eta).r
    }

    /// `(f, pdf)` of the diffuse lobe; zero unless both directions are above.
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return (Rgb::BLACK, 0.0);
        }
        let (f_o, f_i) = (self.fresnel(wo.z), self.fresnel(wi.z));
        let value = self.diffuse_scale() * ((1.0 - f_o) * (1.0 - f_i));
        let pdf = (1.0 - self.specular_probability(f_o)) * wi.z * FRAC_1_PI;
        (value, pdf)
    }

    /// f(wo, wi) of the diffuse lobe (the Dirac lobe has no value).
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        self.eval_pdf(wo, wi).0
    }

    /// Density of `wi` under the diffuse lobe times its selection probability.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.eval_pdf(wo, wi).1
    }

    /// Chooses the specular lobe when `u_lobe` is below its probability
    /// (mirror direction, weight F·specular/probability, `is_delta`), else
    /// cosine-samples the diffuse lobe with `u`.
    pub fn sample(
        &self,
        wo: Vec3,
        u_lobe: f32,
        u: (f32, f32),
        _mode: TransportMode,
    ) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let f_o = self.fresnel(wo.z);
        let p_spec = self.specular_probability(f_o);
        if u_lobe < p_spec {
            let weight = self.specular_reflectance * (f_o / p_spec);
            return weight.is_finite().then_some(BsdfSample {
                wi: Vec3::new(-wo.x, -wo.y, wo.z),
                weight,
                pdf: p_spec,
                is_delta: true,
                eta: 1.0,
            });
        }
        let wi = square_to_cosine_hemisphere(u);
        reflection_sample(wi, self.eval_pdf(wo, wi))
    }
}
