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

/// The BSDFs a surface with roughness textures has at two UVs, as
/// `Scene::bsdf_at` makes them (`BsdfTextures::apply`): a Beckmann rough
/// gold with `alpha` from a checkerboard (0.05 / 0.5), a GGX rough glass
/// with `alpha_u` and `alpha_v` from two boards (anisotropic: 0.05 / 0.4
/// and 0.3 / 0.1), and the glass board inside `twosided` on a conductor.
/// Each is checked to carry the texture's value (Mitsuba 3.9.1's scalar
/// checkerboard lookup: `color1` where the colour lookup gives `color0`),
/// so the suites that run over these exercise the textured path.
pub fn textured_roughness_models() -> Vec<(String, Bsdf)> {
    use glam::{Affine2, Vec2};
    use mcmc_render::bsdf::OneSided;
    use mcmc_render::bsdf::textured::{BsdfTextures, TexturedParam};
    use mcmc_render::texture::{Checkerboard, Texture};
    let board = |a: f32, b: f32| {
        Texture::Checkerboard(Box::new(Checkerboard {
            color0: Texture::Constant(Rgb::splat(a)),
            color1: Texture::Constant(Rgb::splat(b)),
            to_uv: Affine2::IDENTITY,
        }))
    };
    let iso = BsdfTextures(vec![(TexturedParam::Alpha, board(0.05, 0.5))]);
    let aniso = BsdfTextures(vec![
        (TexturedParam::AlphaU, board(0.05, 0.4)),
        (TexturedParam::AlphaV, board(0.3, 0.1)),
    ]);
    let gold = build(&rough_conductor(MicrofacetKind::Beckmann, (0.2, 0.2)));
    let glass = build(&rough_dielectric(MicrofacetKind::Ggx, (0.2, 0.2), 1.5));
    let two = build(&BsdfDesc::TwoSided {
        inner: Box::new(rough_conductor(MicrofacetKind::Ggx, (0.2, 0.2))),
    });
    let mut v = Vec::new();
    // uv (0.25, 0.25): the colour lookup is color0, the scalar one color1.
    for (uv, iso_alpha, aniso_alpha) in [
        (Vec2::new(0.25, 0.25), (0.5, 0.5), (0.4, 0.1)),
        (Vec2::new(0.75, 0.25), (0.05, 0.05), (0.05, 0.3)),
    ] {
        for (name, template, textures, want) in [
            ("roughconductor", gold, &iso, iso_alpha),
            ("roughdielectric", glass, &aniso, aniso_alpha),
            ("twosided roughconductor", two, &aniso, aniso_alpha),
        ] {
            textures.check(&template).expect("applies");
            let b = textures.apply(&template, uv);
            let alpha = match b {
                Bsdf::RoughConductor(c) | Bsdf::TwoSided(OneSided::RoughConductor(c)) => {
                    c.distribution.alpha()
                }
                Bsdf::RoughDielectric(d) => d.distribution.alpha(),
                other => panic!("{other:?}"),
            };
            assert_eq!(alpha, want, "{name} at {uv}");
            v.push((format!("textured-α {name} at uv {uv} (α {alpha:?})"), b));
        }
    }
    v
}
