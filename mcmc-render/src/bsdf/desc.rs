//! Parsed BSDF descriptions: what a scene file asks for, with Mitsuba 3's
//! defaults already filled in. The scene loader produces these; the BSDF
//! module turns them into runtime [`super::Bsdf`] values.

use crate::color::Rgb;

/// Microfacet normal distribution.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MicrofacetKind {
    /// Beckmann distribution.
    Beckmann,
    /// GGX / Trowbridge–Reitz distribution.
    Ggx,
}

/// A BSDF as described by a scene file (Mitsuba 3 plugin semantics).
#[derive(Clone, Debug, PartialEq)]
pub enum BsdfDesc {
    /// Lambertian reflector (`diffuse`).
    Diffuse {
        /// Albedo (Mitsuba default 0.5).
        reflectance: Rgb,
    },
    /// Smooth conductor with complex index of refraction (`conductor`).
    Conductor {
        /// Real part of the IOR, per channel.
        eta: Rgb,
        /// Imaginary part (absorption), per channel.
        k: Rgb,
        /// Scale on the Fresnel reflectance (default 1).
        specular_reflectance: Rgb,
    },
    /// Rough conductor (`roughconductor`).
    RoughConductor {
        /// Normal distribution.
        distribution: MicrofacetKind,
        /// Roughness along the tangent.
        alpha_u: f32,
        /// Roughness along the bitangent.
        alpha_v: f32,
        /// Real part of the IOR.
        eta: Rgb,
        /// Imaginary part of the IOR.
        k: Rgb,
        /// Scale on the Fresnel reflectance.
        specular_reflectance: Rgb,
    },
    /// Smooth dielectric interface (`dielectric`).
    Dielectric {
        /// Interior index of refraction (Mitsuba default: bk7, 1.5046).
        int_ior: f32,
        /// Exterior index of refraction (Mitsuba default: air, 1.000277).
        ext_ior: f32,
        /// Scale on reflection.
        specular_reflectance: Rgb,
        /// Scale on transmission.
        specular_transmittance: Rgb,
    },
    /// Rough dielectric interface (`roughdielectric`).
    RoughDielectric {
        /// Normal distribution.
        distribution: MicrofacetKind,
        /// Roughness along the tangent.
        alpha_u: f32,
        /// Roughness along the bitangent.
        alpha_v: f32,
        /// Interior index of refraction.
        int_ior: f32,
        /// Exterior index of refraction.
        ext_ior: f32,
        /// Scale on reflection.
        specular_reflectance: Rgb,
        /// Scale on transmission.
        specular_transmittance: Rgb,
    },
    /// Smooth plastic (`plastic`): diffuse base under a smooth coating.
    Plastic {
        /// Albedo of the base (Mitsuba default 0.5).
        diffuse_reflectance: Rgb,
        /// Scale on the specular reflection (default 1).
        specular_reflectance: Rgb,
        /// Interior index of refraction (default: polypropylene, 1.49).
        int_ior: f32,
        /// Exterior index of refraction (default: air, 1.000277).
        ext_ior: f32,
        /// Colour shift from internal scattering (default false).
        nonlinear: bool,
    },
    /// Rough plastic (`roughplastic`): diffuse base under a rough coating.
    RoughPlastic {
        /// Normal distribution (default Beckmann).
        distribution: MicrofacetKind,
        /// Roughness (isotropic; default 0.1).
        alpha: f32,
        /// Visible-normal sampling (default true); else D(m) cos θ_m sampling.
        sample_visible: bool,
        /// Albedo of the base (default 0.5).
        diffuse_reflectance: Rgb,
        /// Scale on the specular reflection (default 1).
        specular_reflectance: Rgb,
        /// Interior index of refraction (default: polypropylene, 1.49).
        int_ior: f32,
        /// Exterior index of refraction (default: air, 1.000277).
        ext_ior: f32,
        /// Colour shift from internal scattering (default false).
        nonlinear: bool,
    },
    /// Thin dielectric sheet (`thindielectric`).
    ThinDielectric {
        /// Interior index of refraction (default: bk7, 1.5046).
        int_ior: f32,
        /// Exterior index of refraction (default: air, 1.000277).
        ext_ior: f32,
        /// Scale on reflection.
        specular_reflectance: Rgb,
        /// Scale on transmission.
        specular_transmittance: Rgb,
    },
    /// `twosided` wrapper: the same BSDF on both sides of the surface.
    TwoSided {
        /// The wrapped BSDF.
        inner: Box<BsdfDesc>,
    },
    /// `conductor` with `material="none"`: a perfect mirror (Mitsuba's default conductor).
    PerfectMirror,
}
