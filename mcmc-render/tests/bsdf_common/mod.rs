//! Shared fixtures for the BSDF test suites: the set of configurations every
//! check runs over, direction helpers and a seeded random source.

#![allow(dead_code)]

use glam::Vec3;
use mcmc_render::bsdf::{Bsdf, BsdfDesc, MicrofacetKind};
use mcmc_render::color::Rgb;
use mcmc_render::sampling::{IndependentSource, RandomSource};
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// A seeded uniform source.
pub fn rng(seed: u64) -> IndependentSource<Xoshiro256PlusPlus> {
    IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(seed))
}

/// Draws `(u_lobe, u)` in the order the renderer uses.
pub fn draw(r: &mut impl RandomSource) -> (f32, (f32, f32)) {
    let u_lobe = r.next_1d();
    let u = r.next_2d();
    (u_lobe, u)
}

/// Unit direction from spherical angles (θ from +z, φ from +x).
pub fn sph(theta: f32, phi: f32) -> Vec3 {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    Vec3::new(st * cp, st * sp, ct)
}

/// Gold-like conductor constants (linear sRGB), as in common material tables.
pub const GOLD_ETA: Rgb = Rgb::new(0.143, 0.374, 1.442);
/// Imaginary part paired with [`GOLD_ETA`].
pub const GOLD_K: Rgb = Rgb::new(3.983, 2.385, 1.603);

/// Roughness pairs exercised everywhere: smooth-ish, rough, anisotropic.
pub const ALPHAS: [(f32, f32); 3] = [(0.05, 0.05), (0.5, 0.5), (0.05, 0.4)];

/// Both microfacet distributions.
pub const KINDS: [MicrofacetKind; 2] = [MicrofacetKind::Beckmann, MicrofacetKind::Ggx];

/// A rough conductor description.
pub fn rough_conductor(kind: MicrofacetKind, (au, av): (f32, f32)) -> BsdfDesc {
    BsdfDesc::RoughConductor {
        distribution: kind,
        alpha_u: au,
        alpha_v: av,
        eta: GOLD_ETA,
        k: GOLD_K,
        specular_reflectance: Rgb::WHITE,
    }
}

/// A rough dielectric description (glass, η = 1.5).
pub fn rough_dielectric(kind: MicrofacetKind, (au, av): (f32, f32), eta: f32) -> BsdfDesc {
    BsdfDesc::RoughDielectric {
        distribution: kind,
        alpha_u: au,
        alpha_v: av,
        int_ior: eta,
        ext_ior: 1.0,
        specular_reflectance: Rgb::WHITE,
        specular_transmittance: Rgb::WHITE,
    }
}

/// Builds a BSDF that the tests expect to be valid.
pub fn build(desc: &BsdfDesc) -> Bsdf {
    Bsdf::from_desc(desc).unwrap_or_else(|e| panic!("{desc:?}: {e}"))
}

/// Relative difference with an absolute floor.
pub fn rel_diff(a: f32, b: f32, floor: f32) -> f32 {
    (a - b).abs() / a.abs().max(b.abs()).max(floor)
}
