//! The runtime BSDF: a closed enum over every supported model, built from a
//! parsed [`BsdfDesc`].

use super::conductor::{RoughConductor, SmoothConductor};
use super::dielectric::{RoughDielectric, SmoothDielectric};
use super::diffuse::Diffuse;
use super::fresnel::ConductorFresnel;
use super::microfacet::Microfacet;
use super::plastic::SmoothPlastic;
use super::rough_plastic::RoughPlastic;
use super::thin_dielectric::ThinDielectric;
use super::{BsdfDesc, BsdfSample, TransportMode};
use crate::color::Rgb;
use glam::Vec3;

/// A surface scattering model in the local shading frame (z = normal).
///
/// See the module documentation of [`crate::bsdf`] for the direction and
/// weight conventions. Every method is allocation-free and returns finite
/// values (zero / `None` for degenerate configurations). A plain value
/// (`Copy`, nothing boxed), so that a textured BSDF can be made per hit
/// point on the stack (`bsdf::textured`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bsdf {
    /// One-sided Lambertian reflection.
    Diffuse(Diffuse),
    /// Smooth conductor or perfect mirror (Dirac reflection).
    Conductor(SmoothConductor),
    /// Microfacet conductor.
    RoughConductor(RoughConductor),
    /// Smooth dielectric (Dirac reflection and refraction).
    Dielectric(SmoothDielectric),
    /// Microfacet dielectric.
    RoughDielectric(RoughDielectric),
    /// Smooth plastic: Dirac coating reflection over a diffuse base.
    Plastic(SmoothPlastic),
    /// Rough plastic: glossy coating reflection over a diffuse base (its
    /// transmittance table shared, by reference).
    RoughPlastic(RoughPlastic),
    /// Thin dielectric sheet (Dirac reflection and straight transmission).
    ThinDielectric(ThinDielectric),
    /// A reflective BSDF applied on both sides: queries from below the surface
    /// are mirrored to the upper hemisphere (z of both directions negated).
    TwoSided(OneSided),
}

/// The models `twosided` can wrap: those without transmission (Mitsuba 3
/// refuses the others too), held inline rather than boxed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OneSided {
    /// Lambertian reflection.
    Diffuse(Diffuse),
    /// Smooth conductor or perfect mirror.
    Conductor(SmoothConductor),
    /// Microfacet conductor.
    RoughConductor(RoughConductor),
    /// Smooth plastic.
    Plastic(SmoothPlastic),
    /// Rough plastic.
    RoughPlastic(RoughPlastic),
}

impl OneSided {
    /// The wrapped model as a (one-sided) [`Bsdf`].
    #[inline]
    pub fn bsdf(&self) -> Bsdf {
        match *self {
            OneSided::Diffuse(b) => Bsdf::Diffuse(b),
            OneSided::Conductor(b) => Bsdf::Conductor(b),
            OneSided::RoughConductor(b) => Bsdf::RoughConductor(b),
            OneSided::Plastic(b) => Bsdf::Plastic(b),
            OneSided::RoughPlastic(b) => Bsdf::RoughPlastic(b),
        }
    }

    /// A one-sided model as `twosided` holds it; `None` for the models
    /// with transmission and for `twosided` itself.
    pub fn from_bsdf(b: Bsdf) -> Option<OneSided> {
        match b {
            Bsdf::Diffuse(b) => Some(OneSided::Diffuse(b)),
            Bsdf::Conductor(b) => Some(OneSided::Conductor(b)),
            Bsdf::RoughConductor(b) => Some(OneSided::RoughConductor(b)),
            Bsdf::Plastic(b) => Some(OneSided::Plastic(b)),
            Bsdf::RoughPlastic(b) => Some(OneSided::RoughPlastic(b)),
            Bsdf::Dielectric(_)
            | Bsdf::RoughDielectric(_)
            | Bsdf::ThinDielectric(_)
            | Bsdf::TwoSided(_) => None,
        }
    }
}

/// Checks that a colour parameter is finite.
fn finite_rgb(name: &str, c: Rgb) -> Result<Rgb, String> {
    if c.is_finite() {
        Ok(c)
    } else {
        Err(format!("BSDF parameter `{name}` must be finite, got {c:?}"))
    }
}

/// Checks a roughness: finite and non-negative (tiny values are clamped later).
fn roughness(name: &str, a: f32) -> Result<f32, String> {
    if a.is_finite() && a >= 0.0 {
        Ok(a)
    } else {
        Err(format!(
            "BSDF parameter `{name}` must be a finite, non-negative roughness, got {a}"
        ))
    }
}

/// Relative index int_ior/ext_ior, both required positive and finite.
fn relative_ior(int_ior: f32, ext_ior: f32) -> Result<f32, String> {
    if !(int_ior.is_finite() && ext_ior.is_finite() && int_ior > 0.0 && ext_ior > 0.0) {
        return Err(format!(
            "the interior and exterior indices of refraction must be positive and finite, got int_ior={int_ior}, ext_ior={ext_ior}"
        ));
    }
    Ok(int_ior / ext_ior)
}

/// Relative index of a plastic coating: as [`relative_ior`], and not 1
/// (an index-matched coating has no Fresnel reflection to build on; Mitsuba
/// 3 refuses it for `roughplastic`, and its `plastic` would divide by zero
/// in the diffuse Fresnel fit's use).
fn plastic_ior(int_ior: f32, ext_ior: f32) -> Result<f32, String> {
    let eta = relative_ior(int_ior, ext_ior)?;
    if eta == 1.0 {
        return Err(format!(
            "a plastic coating needs int_ior != ext_ior, got {int_ior} for both"
        ));
    }
    Ok(eta)
}

/// Checks a diffuse albedo: finite, each channel in [0, 1] (the
/// internal-scattering sum R/(1 − R·F_dr) diverges for larger R).
fn reflectance(name: &str, c: Rgb) -> Result<Rgb, String> {
    let c = finite_rgb(name, c)?;
    if c.to_array().iter().all(|v| (0.0..=1.0).contains(v)) {
        Ok(c)
    } else {
        Err(format!(
            "BSDF parameter `{name}` must lie in [0, 1] per channel, got {c:?}"
        ))
    }
}

impl Bsdf {
    /// Builds the runtime BSDF for a scene description. Errors (one line,
    /// naming the parameter) for non-finite or out-of-range parameters and for
    /// a transmissive BSDF nested in `twosided` (which Mitsuba 3 refuses too).
    /// An index-matched `roughdielectric` (int_ior == ext_ior) becomes the
    /// smooth `dielectric`, which it equals exactly.
    pub fn from_desc(desc: &BsdfDesc) -> Result<Bsdf, String> {
        Ok(match desc {
            BsdfDesc::Diffuse { reflectance } => Bsdf::Diffuse(Diffuse {
                reflectance: finite_rgb("reflectance", *reflectance)?,
            }),
            BsdfDesc::PerfectMirror => Bsdf::Conductor(SmoothConductor {
                fresnel: ConductorFresnel::mirror(),
                specular_reflectance: Rgb::WHITE,
            }),
            BsdfDesc::Conductor {
                eta,
                k,
                specular_reflectance,
            } => Bsdf::Conductor(SmoothConductor {
                fresnel: ConductorFresnel::new(finite_rgb("eta", *eta)?, finite_rgb("k", *k)?),
                specular_reflectance: finite_rgb("specular_reflectance", *specular_reflectance)?,
            }),
            BsdfDesc::RoughConductor {
                distribution,
                alpha_u,
                alpha_v,
                eta,
                k,
                specular_reflectance,
            } => Bsdf::RoughConductor(RoughConductor {
                distribution: Microfacet::new(
                    *distribution,
                    roughness("alpha_u", *alpha_u)?,
                    roughness("alpha_v", *alpha_v)?,
                ),
                fresnel: ConductorFresnel::new(finite_rgb("eta", *eta)?, finite_rgb("k", *k)?),
                specular_reflectance: finite_rgb("specular_reflectance", *specular_reflectance)?,
            }),
            BsdfDesc::Dielectric {
                int_ior,
                ext_ior,
                specular_reflectance,
                specular_transmittance,
            } => Bsdf::Dielectric(SmoothDielectric {
                eta: relative_ior(*int_ior, *ext_ior)?,
                specular_reflectance: finite_rgb("specular_reflectance", *specular_reflectance)?,
                specular_transmittance: finite_rgb(
                    "specular_transmittance",
                    *specular_transmittance,
                )?,
            }),
            BsdfDesc::RoughDielectric {
                distribution,
                alpha_u,
                alpha_v,
                int_ior,
                ext_ior,
                specular_reflectance,
                specular_transmittance,
            } => {
                let eta = relative_ior(*int_ior, *ext_ior)?;
                let specular_reflectance =
                    finite_rgb("specular_reflectance", *specular_reflectance)?;
                let specular_transmittance =
                    finite_rgb("specular_transmittance", *specular_transmittance)?;
                let distribution = Microfacet::new(
                    *distribution,
                    roughness("alpha_u", *alpha_u)?,
                    roughness("alpha_v", *alpha_v)?,
                );
                if eta == 1.0 {
                    // Index-matched: no microfacet reflects (F = 0) and every
                    // microfacet refracts straight through, so the interface is
                    // exactly the smooth one. Mitsuba 3 instead returns an
                    // infinite pdf with weight G1 here; the delta form is exact.
                    Bsdf::Dielectric(SmoothDielectric {
                        eta,
                        specular_reflectance,
                        specular_transmittance,
                    })
                } else {
                    Bsdf::RoughDielectric(RoughDielectric {
                        distribution,
                        eta,
                        specular_reflectance,
                        specular_transmittance,
                    })
                }
            }
            BsdfDesc::Plastic {
                diffuse_reflectance,
                specular_reflectance,
                int_ior,
                ext_ior,
                nonlinear,
            } => {
                let eta = plastic_ior(*int_ior, *ext_ior)?;
                let diffuse = reflectance("diffuse_reflectance", *diffuse_reflectance)?;
                let specular = finite_rgb("specular_reflectance", *specular_reflectance)?;
                Bsdf::Plastic(SmoothPlastic::new(eta, diffuse, specular, *nonlinear))
            }
            BsdfDesc::RoughPlastic {
                distribution,
                alpha,
                sample_visible,
                diffuse_reflectance,
                specular_reflectance,
                int_ior,
                ext_ior,
                nonlinear,
            } => {
                let eta = plastic_ior(*int_ior, *ext_ior)?;
                let diffuse = reflectance("diffuse_reflectance", *diffuse_reflectance)?;
                let specular = finite_rgb("specular_reflectance", *specular_reflectance)?;
                Bsdf::RoughPlastic(RoughPlastic::new(
                    *distribution,
                    roughness("alpha", *alpha)?,
                    *sample_visible,
                    eta,
                    diffuse,
                    specular,
                    *nonlinear,
                ))
            }
            BsdfDesc::ThinDielectric {
                int_ior,
                ext_ior,
                specular_reflectance,
                specular_transmittance,
            } => Bsdf::ThinDielectric(ThinDielectric {
                eta: relative_ior(*int_ior, *ext_ior)?,
                specular_reflectance: finite_rgb("specular_reflectance", *specular_reflectance)?,
                specular_transmittance: finite_rgb(
                    "specular_transmittance",
                    *specular_transmittance,
                )?,
            }),
            BsdfDesc::TwoSided { inner } => match Bsdf::from_desc(inner)? {
                // Two-sided twice is two-sided once.
                b @ Bsdf::TwoSided(_) => b,
                b => Bsdf::TwoSided(OneSided::from_bsdf(b).ok_or_else(|| {
                    "`twosided` can only wrap BSDFs without transmission (not dielectric/roughdielectric/thindielectric)"
                        .to_string()
                })?),
            },
        })
    }

    /// A Lambertian BSDF with the given albedo.
    pub fn diffuse(reflectance: Rgb) -> Bsdf {
        Bsdf::Diffuse(Diffuse { reflectance })
    }

    /// f(wo, wi) without the cosine factor; zero for delta lobes.
    pub fn eval(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        match self {
            Bsdf::Diffuse(b) => b.eval(wo, wi),
            Bsdf::Conductor(_) | Bsdf::Dielectric(_) | Bsdf::ThinDielectric(_) => Rgb::BLACK,
            Bsdf::RoughConductor(b) => b.eval(wo, wi),
            Bsdf::RoughDielectric(b) => b.eval(wo, wi, mode),
            Bsdf::Plastic(b) => b.eval(wo, wi),
            Bsdf::RoughPlastic(b) => b.eval(wo, wi),
            Bsdf::TwoSided(inner) => {
                let (wo, wi) = to_front(wo, wi);
                inner.bsdf().eval(wo, wi, mode)
            }
        }
    }

    /// `(eval(wo, wi, mode), pdf(wo, wi, mode))` in one call, sharing the
    /// work (half vector, D, G1, Fresnel) — what MIS needs at every vertex.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Rgb, f32) {
        match self {
            Bsdf::TwoSided(inner) => {
                let (wo, wi) = to_front(wo, wi);
                inner.bsdf().eval_pdf_one_sided(wo, wi, mode)
            }
            b => b.eval_pdf_one_sided(wo, wi, mode),
        }
    }

    /// [`Bsdf::eval_pdf`] of a model that is not [`Bsdf::TwoSided`]. Kept
    /// apart (not recursive) so that it and its callers can be inlined.
    #[inline]
    fn eval_pdf_one_sided(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Rgb, f32) {
        match self {
            Bsdf::Diffuse(b) => (b.eval(wo, wi), b.pdf(wo, wi)),
            Bsdf::Conductor(_) | Bsdf::Dielectric(_) | Bsdf::ThinDielectric(_) => (Rgb::BLACK, 0.0),
            Bsdf::RoughConductor(b) => b.eval_pdf(wo, wi),
            Bsdf::RoughDielectric(b) => b.eval_pdf(wo, wi, mode),
            Bsdf::Plastic(b) => b.eval_pdf(wo, wi),
            Bsdf::RoughPlastic(b) => b.eval_pdf(wo, wi),
            // Never called on it (`eval_pdf` unwraps it).
            Bsdf::TwoSided(_) => (Rgb::BLACK, 0.0),
        }
    }

    /// Importance-samples `wi` given `wo`. `u_lobe` chooses between lobes
    /// (dielectrics: reflection when `u_lobe` < Fresnel reflectance); `u`
    /// chooses the direction within the lobe (`u.0` first). Models with a
    /// single lobe ignore `u_lobe`; delta models ignore `u`. Returns `None`
    /// when no direction carries energy (e.g. `wo` below a one-sided surface).
    #[inline]
    pub fn sample(
        &self,
        wo: Vec3,
        u_lobe: f32,
        u: (f32, f32),
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        // Diffuse, one- or two-sided (most surfaces of most scenes), inline
        // in the caller's loop; the other models out of line, so that their
        // code does not crowd the loop.
        match self {
            Bsdf::Diffuse(b) => b.sample(wo, u, mode),
            Bsdf::TwoSided(OneSided::Diffuse(b)) => {
                two_sided_sample(wo, |wo| b.sample(wo, u, mode))
            }
            _ => self.sample_general(wo, u_lobe, u, mode),
        }
    }

    /// [`Bsdf::sample`] for every model (the slow path of its dispatch).
    #[inline(never)]
    fn sample_general(
        &self,
        wo: Vec3,
        u_lobe: f32,
        u: (f32, f32),
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        match self {
            Bsdf::TwoSided(inner) => {
                two_sided_sample(wo, |wo| inner.bsdf().sample_one_sided(wo, u_lobe, u, mode))
            }
            b => b.sample_one_sided(wo, u_lobe, u, mode),
        }
    }

    /// [`Bsdf::sample`] of a model that is not [`Bsdf::TwoSided`] (not
    /// recursive, so the path tracer's loop can inline it).
    #[inline]
    fn sample_one_sided(
        &self,
        wo: Vec3,
        u_lobe: f32,
        u: (f32, f32),
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        match self {
            Bsdf::Diffuse(b) => b.sample(wo, u, mode),
            Bsdf::Conductor(b) => b.sample(wo, mode),
            Bsdf::RoughConductor(b) => b.sample(wo, u, mode),
            Bsdf::Dielectric(b) => b.sample(wo, u_lobe, mode),
            Bsdf::RoughDielectric(b) => b.sample(wo, u_lobe, u, mode),
            Bsdf::Plastic(b) => b.sample(wo, u_lobe, u, mode),
            Bsdf::RoughPlastic(b) => b.sample(wo, u_lobe, u, mode),
            Bsdf::ThinDielectric(b) => b.sample(wo, u_lobe, mode),
            // Never called on it (`sample_general` unwraps it).
            Bsdf::TwoSided(_) => None,
        }
    }

    /// Solid-angle density with which [`Bsdf::sample`] produces `wi` from
    /// `wo` (zero for delta lobes). The reverse density a bidirectional
    /// method needs is `pdf(wi, wo, mode.flip())`.
    pub fn pdf(&self, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        match self {
            Bsdf::Diffuse(b) => b.pdf(wo, wi),
            Bsdf::Conductor(_) | Bsdf::Dielectric(_) | Bsdf::ThinDielectric(_) => 0.0,
            Bsdf::RoughConductor(b) => b.pdf(wo, wi),
            Bsdf::RoughDielectric(b) => b.pdf(wo, wi, mode),
            Bsdf::Plastic(b) => b.pdf(wo, wi),
            Bsdf::RoughPlastic(b) => b.pdf(wo, wi),
            Bsdf::TwoSided(inner) => {
                let (wo, wi) = to_front(wo, wi);
                inner.bsdf().pdf(wo, wi, mode)
            }
        }
    }

    /// True when every lobe is a Dirac delta (smooth conductor, mirror,
    /// smooth and thin dielectric): `eval` and `pdf` are then identically
    /// zero and only `sample` transports light.
    #[inline]
    pub fn is_delta(&self) -> bool {
        match self {
            Bsdf::Conductor(_) | Bsdf::Dielectric(_) | Bsdf::ThinDielectric(_) => true,
            Bsdf::Diffuse(_)
            | Bsdf::RoughConductor(_)
            | Bsdf::RoughDielectric(_)
            | Bsdf::Plastic(_)
            | Bsdf::RoughPlastic(_) => false,
            Bsdf::TwoSided(inner) => inner.bsdf().is_delta(),
        }
    }

    /// True when the roughness differs along the two tangents
    /// (`alpha_u ≠ alpha_v`): only then does the BSDF depend on which way
    /// the shading frame's tangent points (see [`crate::scene::Scene::shading_frame`]).
    pub fn is_anisotropic(&self) -> bool {
        let m = match self {
            Bsdf::RoughConductor(b) | Bsdf::TwoSided(OneSided::RoughConductor(b)) => {
                &b.distribution
            }
            Bsdf::RoughDielectric(b) => &b.distribution,
            Bsdf::RoughPlastic(b) | Bsdf::TwoSided(OneSided::RoughPlastic(b)) => b.distribution(),
            _ => return false,
        };
        let (au, av) = m.alpha();
        au != av
    }

    /// True when at least one lobe is a Dirac delta: the delta models, and
    /// the smooth `plastic`, whose coating reflection is a Dirac lobe over a
    /// diffuse one (its samples say per sample with `is_delta`).
    pub fn has_delta_lobe(&self) -> bool {
        match self {
            Bsdf::Plastic(_) => true,
            Bsdf::TwoSided(inner) => inner.bsdf().has_delta_lobe(),
            b => b.is_delta(),
        }
    }
}

/// Samples a one-sided model with `wo` mirrored to the front (z negated
/// when below), mirroring the sampled direction back.
#[inline]
fn two_sided_sample(
    wo: Vec3,
    one_sided: impl FnOnce(Vec3) -> Option<BsdfSample>,
) -> Option<BsdfSample> {
    let flip = wo.z < 0.0;
    let wo = if flip {
        Vec3::new(wo.x, wo.y, -wo.z)
    } else {
        wo
    };
    let mut s = one_sided(wo)?;
    if flip {
        s.wi.z = -s.wi.z;
    }
    Some(s)
}

/// Mitsuba 3's two-sided mapping: when `wo` is below the surface, negate the
/// z of both directions so the one-sided model sees `wo` from the front.
#[inline]
fn to_front(wo: Vec3, wi: Vec3) -> (Vec3, Vec3) {
    if wo.z < 0.0 {
        (Vec3::new(wo.x, wo.y, -wo.z), Vec3::new(wi.x, wi.y, -wi.z))
    } else {
        (wo, wi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bsdf_is_shareable_across_threads() {
        fn assert_traits<T: Clone + Send + Sync + std::fmt::Debug + 'static>() {}
        assert_traits::<Bsdf>();
        // Small enough to store per shape and to copy per hit for textured
        // materials (`bsdf::textured`): 72 bytes since the rough plastic,
        // whose cached constants (distribution, two colours, coating
        // reflectance, sampling weight, table reference) fill 64 bytes and
        // leave no niche for the enum tags.
        assert!(
            std::mem::size_of::<Bsdf>() <= 72,
            "{}",
            std::mem::size_of::<Bsdf>()
        );
    }
}
