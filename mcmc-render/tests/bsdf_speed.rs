//! Throughput of `sample` and `eval_pdf` per model (a measurement, not a
//! check): `cargo test --release -p mcmc-render --test bsdf_speed -- --ignored --nocapture`.

mod bsdf_common;

use bsdf_common::*;
use mcmc_render::bsdf::{Bsdf, BsdfDesc, MicrofacetKind, TransportMode};
use mcmc_render::color::Rgb;
use mcmc_render::sampling::RandomSource;
use std::hint::black_box;
use std::time::Instant;

#[test]
#[ignore = "measurement; run explicitly"]
fn bsdf_throughput() {
    let models: Vec<(&str, Bsdf)> = vec![
        ("diffuse", Bsdf::diffuse(Rgb::splat(0.5))),
        (
            "conductor (gold)",
            build(&BsdfDesc::Conductor {
                eta: GOLD_ETA,
                k: GOLD_K,
                specular_reflectance: Rgb::WHITE,
            }),
        ),
        (
            "dielectric",
            build(&BsdfDesc::Dielectric {
                int_ior: 1.5,
                ext_ior: 1.0,
                specular_reflectance: Rgb::WHITE,
                specular_transmittance: Rgb::WHITE,
            }),
        ),
        (
            "roughconductor beckmann 0.2",
            build(&rough_conductor(MicrofacetKind::Beckmann, (0.2, 0.2))),
        ),
        (
            "roughconductor ggx 0.2",
            build(&rough_conductor(MicrofacetKind::Ggx, (0.2, 0.2))),
        ),
        (
            "roughdielectric beckmann 0.2",
            build(&rough_dielectric(MicrofacetKind::Beckmann, (0.2, 0.2), 1.5)),
        ),
        (
            "roughdielectric ggx 0.2",
            build(&rough_dielectric(MicrofacetKind::Ggx, (0.2, 0.2), 1.5)),
        ),
    ];
    const N: usize = 2_000_000;
    let mut r = rng(7);
    // Inputs are precomputed so the loops time the BSDF alone.
    let inputs: Vec<_> = (0..4096)
        .map(|_| {
            let wo = sph(
                (0.2 + 0.8 * r.next_1d()).acos(),
                std::f32::consts::TAU * r.next_1d(),
            );
            let wi = sph(3.1 * r.next_1d(), std::f32::consts::TAU * r.next_1d());
            (r.next_1d(), r.next_2d(), wo, wi)
        })
        .collect();
    for (name, b) in &models {
        let t = Instant::now();
        let mut acc = 0.0f32;
        for i in 0..N {
            let (ul, u, wo, _) = inputs[i & 4095];
            if let Some(s) = b.sample(black_box(wo), ul, u, TransportMode::Radiance) {
                acc += s.weight.r;
            }
        }
        let ns_sample = t.elapsed().as_secs_f64() * 1e9 / N as f64;
        let t = Instant::now();
        for i in 0..N {
            let (_, _, wo, wi) = inputs[i & 4095];
            let (f, p) = b.eval_pdf(black_box(wo), black_box(wi), TransportMode::Radiance);
            acc += f.r + p;
        }
        let ns_eval = t.elapsed().as_secs_f64() * 1e9 / N as f64;
        println!("{name:32} sample {ns_sample:6.1} ns   eval_pdf {ns_eval:6.1} ns   ({acc:.1})");
    }
}
