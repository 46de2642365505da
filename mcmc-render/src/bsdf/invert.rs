//! Inversion of BSDF sampling: the random numbers with which
//! [`Bsdf::sample`] produces a given direction. Fused state spaces and
//! technique-changing MCMC moves map paths back to primary samples with it.

use super::Bsdf;
use super::diffuse::cosine_hemisphere_to_square;
use super::fresnel::fresnel_dielectric;
use glam::Vec3;

/// Random numbers that make [`Bsdf::sample`] return a given `wi`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleInverse {
    /// Interval `[lo, hi)` of `u_lobe` values that select the lobe of `wi`.
    /// Its length is the lobe's selection probability; a caller that needs a
    /// single value (e.g. to refill a primary-sample vector) should draw it
    /// uniformly in the interval, which keeps the map measure-preserving.
    pub u_lobe: (f32, f32),
    /// The direction numbers `(u.0, u.1)`; meaningful only when `u_used`.
    pub u: (f32, f32),
    /// False for delta models, which ignore `u` (a caller draws it freely).
    pub u_used: bool,
}

impl Bsdf {
    /// The numbers `(u_lobe, u)` with which `sample(wo, u_lobe, u, mode)`
    /// (in either mode: directions do not depend on it)
    /// returns `wi`, or `None` when `sample` cannot produce `wi` from `wo`.
    ///
    /// `u_choice` (uniform in [0, 1)) is used only where the sampling map is
    /// many-to-one: `roughplastic`, whose glossy and diffuse lobes both reach
    /// every `wi`, picks the lobe with probability proportional to its share
    /// of `pdf(wo, wi)`, which keeps the inverse measure-preserving.
    ///
    /// For delta models `wi` is trusted to be the reflected or refracted
    /// direction (its hemisphere picks the lobe). Smooth `plastic` takes `wi`
    /// for its Dirac lobe when it is the mirror direction of `wo` to within
    /// 1e-5 (a diffuse sample lands there with probability ~1e-10).
    /// Exact up to f32 rounding:
    /// sampling the returned numbers gives `wi` back to roughly 1e-5 rad in
    /// well-conditioned regions (less precisely in the far tails of very
    /// peaked lobes, where the sampling map compresses a wide range of `u`).
    pub fn invert(&self, wo: Vec3, wi: Vec3, u_choice: f32) -> Option<SampleInverse> {
        const ANY: (f32, f32) = (0.0, 1.0);
        match self {
            Bsdf::Diffuse(_) => {
                if wo.z <= 0.0 || wi.z <= 0.0 {
                    return None;
                }
                Some(SampleInverse {
                    u_lobe: ANY,
                    u: cosine_hemisphere_to_square(wi),
                    u_used: true,
                })
            }
            Bsdf::Conductor(c) => {
                if wo.z <= 0.0
                    || wi.z <= 0.0
                    || (c.specular_reflectance * c.fresnel.eval(wo.z)).is_black()
                {
                    return None;
                }
                Some(SampleInverse {
                    u_lobe: ANY,
                    u: (0.5, 0.5),
                    u_used: false,
                })
            }
            Bsdf::RoughConductor(c) => {
                if wo.z <= 0.0 || wi.z <= 0.0 {
                    return None;
                }
                let m = (wo + wi).normalize_or_zero();
                let u = c.distribution.invert_visible(wo, m)?;
                Some(SampleInverse {
                    u_lobe: ANY,
                    u,
                    u_used: true,
                })
            }
            Bsdf::Dielectric(d) => {
                if wo.z == 0.0 || wi.z == 0.0 {
                    return None;
                }
                let r = fresnel_dielectric(wo.z, d.eta).r;
                let u_lobe = if wo.z * wi.z > 0.0 {
                    (0.0, r)
                } else {
                    (r, 1.0)
                };
                (u_lobe.1 > u_lobe.0).then_some(SampleInverse {
                    u_lobe,
                    u: (0.5, 0.5),
                    u_used: false,
                })
            }
            Bsdf::RoughDielectric(d) => {
                if wo.z == 0.0 || wi.z == 0.0 {
                    return None;
                }
                let reflect = wo.z * wi.z > 0.0;
                let eta_path = if reflect {
                    1.0
                } else if wo.z > 0.0 {
                    d.eta
                } else {
                    1.0 / d.eta
                };
                let h = (wo + wi * eta_path).normalize_or_zero();
                let m = if h.z < 0.0 { -h } else { h };
                let wo_up = if wo.z < 0.0 { -wo } else { wo };
                let u = d.distribution.invert_visible(wo_up, m)?;
                // `sample` chooses the lobe with F evaluated at wo·m.
                let r = fresnel_dielectric(wo.dot(m), d.eta).r;
                let u_lobe = if reflect { (0.0, r) } else { (r, 1.0) };
                (u_lobe.1 > u_lobe.0).then_some(SampleInverse {
                    u_lobe,
                    u,
                    u_used: true,
                })
            }
            Bsdf::TwoSided(inner) => {
                let flip = wo.z < 0.0;
                let (wo, wi) = if flip {
                    (Vec3::new(wo.x, wo.y, -wo.z), Vec3::new(wi.x, wi.y, -wi.z))
                } else {
                    (wo, wi)
                };
                inner.bsdf().invert(wo, wi, u_choice)
            }
            Bsdf::Plastic(p) => {
                if wo.z <= 0.0 || wi.z <= 0.0 {
                    return None;
                }
                let p_spec = p.specular_probability(p.fresnel(wo.z));
                let mirror = Vec3::new(-wo.x, -wo.y, wo.z);
                if (wi - mirror).length_squared() < 1e-10 {
                    (p_spec > 0.0).then_some(SampleInverse {
                        u_lobe: (0.0, p_spec),
                        u: (0.5, 0.5),
                        u_used: false,
                    })
                } else {
                    (p_spec < 1.0).then_some(SampleInverse {
                        u_lobe: (p_spec, 1.0),
                        u: cosine_hemisphere_to_square(wi),
                        u_used: true,
                    })
                }
            }
            Bsdf::RoughPlastic(p) => {
                let (u_lobe, u) = p.invert(wo, wi, u_choice)?;
                (u_lobe.1 > u_lobe.0).then_some(SampleInverse {
                    u_lobe,
                    u,
                    u_used: true,
                })
            }
            Bsdf::ThinDielectric(d) => {
                if wo.z == 0.0 || wi.z == 0.0 {
                    return None;
                }
                let r = d.reflectance(wo);
                let u_lobe = if wo.z * wi.z > 0.0 {
                    (0.0, r)
                } else {
                    (r, 1.0)
                };
                (u_lobe.1 > u_lobe.0).then_some(SampleInverse {
                    u_lobe,
                    u: (0.5, 0.5),
                    u_used: false,
                })
            }
        }
    }
}
