//! The BSDF wrappers that act per point: `normalmap`/`bumpmap`
//! ([`Perturbation`]) and `mask` (an opacity cut-out), as the scene keeps
//! them beside a BSDF ([`Wrappers`]) and as they apply at one point
//! ([`Wrap`]).
//!
//! `mask` follows Mitsuba 3 (`src/bsdfs/mask.cpp`, 3.9): with opacity `α`
//! (a texture's value, its luminance for a colour one, clamped to [0, 1];
//! default 0.5) the BSDF is `α·f_nested` plus a forward Dirac delta of
//! weight `1 − α` (the "null" lobe: the path continues straight through,
//! `wi = −wo`). Sampling picks the null lobe with probability `1 − α`
//! (weight 1) and the nested BSDF otherwise (its weight, its density
//! times `α`). A null interaction is a path vertex like any other: it
//! counts towards `max_depth`, as Mitsuba 3's `path` counts it
//! (`depth += 1` at every valid interaction), and shadow rays are blocked
//! by a masked surface whatever its opacity, as Mitsuba 3's `ray_test`
//! blocks them: the light through a cut-out arrives through the null lobe.

use super::invert::SampleInverse;
use super::perturb::{Perturbation, Perturbed};
use super::{Bsdf, BsdfSample, TransportMode};
use crate::color::Rgb;
use crate::texture::Texture;
use glam::Vec3;

/// The wrappers around one BSDF of a scene (both empty for most).
#[derive(Clone, Debug, Default)]
pub struct Wrappers {
    /// `normalmap` or `bumpmap` around the BSDF.
    pub perturbation: Option<Perturbation>,
    /// `mask`'s opacity, around everything else.
    pub opacity: Option<Texture>,
}

impl Wrappers {
    /// True when the BSDF is not wrapped.
    pub fn is_empty(&self) -> bool {
        self.perturbation.is_none() && self.opacity.is_none()
    }
}

/// The wrappers at one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wrap {
    /// The perturbed frame, under `normalmap` or `bumpmap`.
    pub perturbed: Option<Perturbed>,
    /// `mask`'s opacity at the point (1 without a mask).
    pub opacity: f32,
}

impl Wrap {
    /// The nested BSDF (perturbed or not): `(eval, pdf)`.
    #[inline]
    fn inner_eval_pdf(&self, b: &Bsdf, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Rgb, f32) {
        match &self.perturbed {
            Some(p) => p.eval_pdf(b, wo, wi, mode),
            None => b.eval_pdf(wo, wi, mode),
        }
    }

    /// `(eval, pdf)` of the wrapped BSDF `b` (the null lobe is a delta:
    /// neither includes it).
    #[inline(never)]
    pub fn eval_pdf(&self, b: &Bsdf, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Rgb, f32) {
        let (f, pdf) = self.inner_eval_pdf(b, wo, wi, mode);
        (f * self.opacity, pdf * self.opacity)
    }

    /// Samples the wrapped BSDF `b`: the null lobe when `u_lobe ≥ α`, else
    /// the nested BSDF with `u_lobe / α`.
    #[inline(never)]
    pub fn sample(
        &self,
        b: &Bsdf,
        wo: Vec3,
        u_lobe: f32,
        u: (f32, f32),
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let a = self.opacity;
        if !(u_lobe < a) {
            return Some(BsdfSample {
                wi: -wo,
                weight: Rgb::WHITE,
                pdf: 1.0 - a,
                is_delta: true,
                eta: 1.0,
            });
        }
        let u_lobe = (u_lobe / a).min(1.0 - f32::EPSILON / 2.0);
        let mut s = match &self.perturbed {
            Some(p) => p.sample(b, wo, u_lobe, u, mode),
            None => b.sample(wo, u_lobe, u, mode),
        }?;
        s.pdf *= a;
        Some(s)
    }

    /// The numbers with which [`Wrap::sample`] returns `wi` from `wo` in
    /// `mode` (see [`Bsdf::invert`]), or `None` when it cannot. The null
    /// lobe is taken when `wi` is `−wo` to within 1e-5 (the nested BSDF
    /// reaches that direction with probability zero unless it is a delta
    /// transmission at normal incidence): its interval `[α, 1)` of `u_lobe`
    /// is many-to-one, and a caller draws the fresh uniform in it, as for
    /// the dielectric's lobe choice. Otherwise the nested inverse (through
    /// the perturbation, in the frame the sampler draws from), its
    /// `u_lobe` interval scaled by `α`.
    pub fn invert(
        &self,
        b: &Bsdf,
        wo: Vec3,
        wi: Vec3,
        u_choice: f32,
        mode: TransportMode,
    ) -> Option<SampleInverse> {
        let a = self.opacity;
        if (wi + wo).length_squared() < 1e-10 {
            return (a < 1.0).then_some(SampleInverse {
                u_lobe: (a.max(0.0), 1.0),
                u: (0.5, 0.5),
                u_used: false,
            });
        }
        if !(a > 0.0) {
            return None;
        }
        let mut inv = match &self.perturbed {
            Some(p) => p.invert(b, wo, wi, u_choice, mode),
            None => b.invert(wo, wi, u_choice),
        }?;
        inv.u_lobe = (a * inv.u_lobe.0, a * inv.u_lobe.1);
        (inv.u_lobe.1 > inv.u_lobe.0).then_some(inv)
    }

    /// True when every lobe is a Dirac delta: a fully transparent point,
    /// or a delta model.
    #[inline]
    pub fn is_delta(&self, b: &Bsdf) -> bool {
        self.opacity <= 0.0 || b.is_delta()
    }

    /// True when a lobe is a Dirac delta (the null lobe of a point that is
    /// not fully opaque included).
    pub fn has_delta_lobe(&self, b: &Bsdf) -> bool {
        self.opacity < 1.0 || b.has_delta_lobe()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Half-transparent diffuse: eval and pdf are α times the nested
    /// ones; sampling picks the null lobe with probability 1 − α (weight
    /// 1, straight through) and the nested one otherwise (its weight, its
    /// density times α), and the mean weight over u is α·albedo + (1 − α).
    #[test]
    fn mask_mixes_the_nested_bsdf_with_a_null_lobe() {
        let b = Bsdf::diffuse(Rgb::splat(0.6));
        let w = Wrap {
            perturbed: None,
            opacity: 0.25,
        };
        let (wo, wi) = (
            Vec3::new(0.0, 0.6, 0.8),
            Vec3::new(0.36, 0.0, 0.8).normalize(),
        );
        let mode = TransportMode::Radiance;
        let (f, pdf) = w.eval_pdf(&b, wo, wi, mode);
        let (g, q) = b.eval_pdf(wo, wi, mode);
        assert_eq!(f, g * 0.25);
        assert_eq!(pdf, q * 0.25);
        let null = w.sample(&b, wo, 0.25, (0.3, 0.3), mode).unwrap();
        assert!(null.is_delta && null.wi == -wo && null.weight == Rgb::WHITE);
        assert_eq!(null.pdf, 0.75);
        let s = w.sample(&b, wo, 0.1, (0.3, 0.7), mode).unwrap();
        assert!(!s.is_delta);
        let (f, pdf) = w.eval_pdf(&b, wo, s.wi, mode);
        assert!((s.pdf - pdf).abs() < 1e-6);
        assert!(((f * (s.wi.z / pdf)).g - s.weight.g).abs() < 1e-5);
        let n = 1000;
        let mean: f32 = (0..n)
            .map(|i| {
                let u = (i as f32 + 0.5) / n as f32;
                w.sample(&b, wo, u, (u, 1.0 - u), mode)
                    .map_or(0.0, |s| s.weight.g)
            })
            .sum::<f32>()
            / n as f32;
        assert!((mean - (0.25 * 0.6 + 0.75)).abs() < 1e-4, "{mean}");
        assert!(!w.is_delta(&b) && w.has_delta_lobe(&b));
        let clear = Wrap {
            perturbed: None,
            opacity: 0.0,
        };
        assert!(clear.is_delta(&b));
    }
}
