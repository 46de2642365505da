//! Round trips through `Bsdf::invert`: sampling with the recovered numbers
//! reproduces the sampled direction, and the recovered numbers are the ones
//! that were used.

mod bsdf_common;

use bsdf_common::*;
use glam::Vec3;
use mcmc_render::bsdf::perturb::{PerturbKind, Perturbation};
use mcmc_render::bsdf::textured::BsdfAt;
use mcmc_render::bsdf::wrapped::Wrap;
use mcmc_render::bsdf::{Bsdf, BsdfDesc, MicrofacetKind, TransportMode};
use mcmc_render::color::Rgb;
use mcmc_render::frame::Frame;
use mcmc_render::sampling::RandomSource;
use mcmc_render::texture::Texture;

fn models() -> Vec<(String, Bsdf)> {
    let mut v: Vec<(String, Bsdf)> = vec![
        ("diffuse".into(), Bsdf::diffuse(Rgb::splat(0.5))),
        (
            "gold".into(),
            build(&BsdfDesc::Conductor {
                eta: GOLD_ETA,
                k: GOLD_K,
                specular_reflectance: Rgb::WHITE,
            }),
        ),
        (
            "glass".into(),
            build(&BsdfDesc::Dielectric {
                int_ior: 1.5,
                ext_ior: 1.0,
                specular_reflectance: Rgb::WHITE,
                specular_transmittance: Rgb::WHITE,
            }),
        ),
        (
            "twosided diffuse".into(),
            build(&BsdfDesc::TwoSided {
                inner: Box::new(BsdfDesc::Diffuse {
                    reflectance: Rgb::splat(0.5),
                }),
            }),
        ),
    ];
    v.push((
        "plastic".into(),
        build(&BsdfDesc::Plastic {
            diffuse_reflectance: Rgb::splat(0.5),
            specular_reflectance: Rgb::WHITE,
            int_ior: 1.49,
            ext_ior: 1.0,
            nonlinear: false,
        }),
    ));
    v.push((
        "thindielectric".into(),
        build(&BsdfDesc::ThinDielectric {
            int_ior: 1.5,
            ext_ior: 1.0,
            specular_reflectance: Rgb::WHITE,
            specular_transmittance: Rgb::WHITE,
        }),
    ));
    for kind in KINDS {
        for (alpha, sample_visible) in [(0.05f32, true), (0.5, true), (0.3, false)] {
            v.push((
                format!("roughplastic {kind:?} {alpha} visible={sample_visible}"),
                build(&BsdfDesc::RoughPlastic {
                    distribution: kind,
                    alpha,
                    sample_visible,
                    diffuse_reflectance: Rgb::splat(0.5),
                    specular_reflectance: Rgb::WHITE,
                    int_ior: 1.49,
                    ext_ior: 1.0,
                    nonlinear: false,
                }),
            ));
        }
    }
    for kind in KINDS {
        for alpha in ALPHAS.into_iter().chain([(1.0, 1.0)]) {
            v.push((
                format!("roughconductor {kind:?} {alpha:?}"),
                build(&rough_conductor(kind, alpha)),
            ));
            v.push((
                format!("roughdielectric {kind:?} {alpha:?}"),
                build(&rough_dielectric(kind, alpha, 1.5)),
            ));
        }
    }
    v.extend(textured_roughness_models());
    v
}

#[test]
fn sampling_the_inverse_reproduces_the_direction() {
    let mut r = rng(77);
    let mut r_choice = rng(78);
    let mode = TransportMode::Radiance;
    for (name, b) in models() {
        let mut angle_errs = Vec::new();
        let mut u_errs = Vec::new();
        let mut other_lobe = 0usize;
        // Measure preservation of the stochastic inverse: the lobe it picks
        // must be distributed like the lobe sampling drew.
        let (mut glossy_drawn, mut glossy_inverted, mut bernoulli_var) = (0u32, 0u32, 0f64);
        for i in 0..20_000 {
            // Outgoing directions over the whole sphere (both sides for dielectrics).
            let (a, c) = r.next_2d();
            let mut wo = sph(
                (0.02 + 0.96 * a) * std::f32::consts::FRAC_PI_2,
                std::f32::consts::TAU * c,
            );
            if i % 2 == 1
                && matches!(
                    b,
                    Bsdf::Dielectric(_)
                        | Bsdf::RoughDielectric(_)
                        | Bsdf::ThinDielectric(_)
                        | Bsdf::TwoSided(_)
                )
            {
                wo.z = -wo.z;
            }
            let (ul, u) = draw(&mut r);
            let Some(s) = b.sample(wo, ul, u, mode) else {
                continue;
            };
            // Rough plastic's inverse picks one of its two lobes at random.
            // (From its own stream, so the other models' samples stay as they were.)
            let u_choice = r_choice.next_1d();
            let inv = b.invert(wo, s.wi, u_choice).unwrap_or_else(|| {
                panic!(
                    "{name}: no inverse for a sampled direction wo={wo:?} wi={:?}",
                    s.wi
                )
            });
            let (lo, hi) = inv.u_lobe;
            // The lobe probability is recomputed from the half vector of (wo, wi),
            // which rounds slightly differently from the sampled normal.
            let mut same_lobe = ul >= lo - 1e-4 && ul < hi + 1e-4;
            if let Bsdf::RoughPlastic(_) = b {
                // Its lobe probability depends on wo alone, so it is exact:
                // no slack (with it, a draw just below the split would count
                // as the other lobe's and compare the wrong numbers).
                same_lobe = ul >= lo && ul < hi;
                // The glossy lobe is [0, p), the diffuse one [p, 1).
                let p = if lo == 0.0 { hi } else { lo };
                glossy_drawn += u32::from(ul < p);
                glossy_inverted += u32::from(lo == 0.0);
                bernoulli_var += (p * (1.0 - p)) as f64;
                // Both lobes reach every direction: the inverse may pick the
                // other one (then only the direction must come back).
                other_lobe += usize::from(!same_lobe);
                if !same_lobe {
                    let again = b
                        .sample(wo, 0.5 * (lo + hi), inv.u, mode)
                        .expect("resample");
                    angle_errs.push((again.wi - s.wi).length());
                    continue;
                }
            }
            assert!(same_lobe, "{name}: u_lobe {ul} outside [{lo}, {hi})");
            let ul2 = ul.clamp(lo, hi - 1e-7);
            let again = b
                .sample(wo, ul2, if inv.u_used { inv.u } else { u }, mode)
                .expect("resample");
            angle_errs.push((again.wi - s.wi).length());
            if inv.u_used {
                let d0 = (inv.u.0 - u.0).abs();
                let d0 = d0.min(1.0 - d0); // u.0 is an angle for GGX: compare on the circle
                u_errs.push(d0.max((inv.u.1 - u.1).abs()));
            }
        }
        angle_errs.sort_by(f32::total_cmp);
        // The direction must come back: sampling maps u to wi with f32
        // rounding amplified at most by the map's stretch (~1/α ≈ 20 for
        // α = 0.05), so 1e-4 is ~100× the observed worst case yet far below
        // any lobe width.
        assert!(
            angle_errs.last().is_none_or(|&e| e < 1e-4),
            "{name}: |Δwi| {:?}",
            angle_errs.last()
        );
        // Recovering u from wi amplifies wi's rounding (~6e-8) by the inverse
        // Jacobian, ~1/α² ≈ 400 at α = 0.05, hence 1e-4 for nearly all samples.
        // Where wi hardly depends on u (the azimuth u.0 near the pole of
        // GGX's cap, far tails) u is ill-conditioned but also irrelevant, so
        // the bound is on the 99.9th percentile, with 1e-3 on the worst case.
        let p999 = u_errs
            .get((u_errs.len().max(1) - 1) * 999 / 1000)
            .copied()
            .unwrap_or(0.0);
        assert!(p999 < 1e-4, "{name}: u error p99.9 {p999}");
        assert!(
            u_errs.last().is_none_or(|&e| e < 1e-3),
            "{name}: u error {:?}",
            u_errs.last()
        );
        assert!(
            angle_errs.len() > 10_000,
            "{name}: only {} samples",
            angle_errs.len()
        );
        if let Bsdf::RoughPlastic(_) = b {
            // Where the lobes overlap the choice must go both ways sometimes.
            assert!(other_lobe > 0, "{name}: the inverse never switched lobes");
            // Both counts have mean Σ p_spec(wo); each has variance at most
            // Σ p(1 − p) (the inverse's choice given wi is Bernoulli too), so
            // their difference is within 5 SE of zero (false alarm < 1e-6).
            // Control: u_choice^0.8 instead of u_choice (a biased choice)
            // fails this by 11 SE at Beckmann α = 0.5.
            let d = glossy_drawn as f64 - glossy_inverted as f64;
            let se = (2.0 * bernoulli_var).sqrt();
            assert!(
                d.abs() < 5.0 * se,
                "{name}: glossy lobe drawn {glossy_drawn}, chosen by the inverse {glossy_inverted} (SE {se:.1})"
            );
        }
        u_errs.sort_by(f32::total_cmp);
        let q = |v: &Vec<f32>, p: f64| {
            if v.is_empty() {
                0.0
            } else {
                v[((v.len() - 1) as f64 * p) as usize]
            }
        };
        eprintln!(
            "{name:40} n={} |Δwi| p50 {:.1e} p99.9 {:.1e} max {:.1e} | u p50 {:.1e} p99.9 {:.1e} max {:.1e}",
            angle_errs.len(),
            q(&angle_errs, 0.5),
            q(&angle_errs, 0.999),
            q(&angle_errs, 1.0),
            q(&u_errs, 0.5),
            q(&u_errs, 0.999),
            q(&u_errs, 1.0)
        );
    }
}

/// The wrappers of a `BsdfAt::Wrapped` as `Scene::bsdf_at` builds them:
/// a tilted normal (with and without `flip_invalid_normals`), the untilted
/// one (whose mirror image is itself), a mask, and a mask around a tilted
/// normal. Returns (name, wrap, opacity, whether importance sampling
/// splits between two frames).
fn wraps() -> Vec<(&'static str, Wrap, f32, bool)> {
    let frame = Frame::from_normal(Vec3::Z);
    let perturbed = |n: Vec3, flip: bool| {
        Perturbation {
            kind: PerturbKind::Normal(Texture::Constant(Rgb::splat(0.5))),
            flip_invalid_normals: flip,
            use_shadowing_function: true,
        }
        .at(&frame, n.normalize())
    };
    let tilted = Vec3::new(0.5, -0.3, 0.8);
    vec![
        (
            "normal map",
            Wrap {
                perturbed: Some(perturbed(tilted, true)),
                opacity: 1.0,
            },
            1.0,
            true,
        ),
        (
            "normal map, no flips",
            Wrap {
                perturbed: Some(perturbed(tilted, false)),
                opacity: 1.0,
            },
            1.0,
            false,
        ),
        (
            "untilted normal map",
            Wrap {
                perturbed: Some(perturbed(Vec3::Z, true)),
                opacity: 1.0,
            },
            1.0,
            false,
        ),
        (
            "mask 0.4",
            Wrap {
                perturbed: None,
                opacity: 0.4,
            },
            0.4,
            false,
        ),
        (
            "mask 0.6 over a normal map",
            Wrap {
                perturbed: Some(perturbed(tilted, true)),
                opacity: 0.6,
            },
            0.6,
            true,
        ),
    ]
}

/// Round trips through `BsdfAt::invert_in` under `normalmap`/`bumpmap`
/// (a perturbed frame) and `mask`, in both transport modes, for nested
/// models of every kind (smooth, rough, delta, two-lobed with a stochastic
/// inverse):
/// - sampling the recovered numbers gives the direction back, and the
///   recovered lobe interval holds the `u_lobe` that was drawn (the frame
///   and the null lobe are functions of the directions);
/// - for Dirac samples (the null lobe, delta nested lobes) the interval's
///   length is the probability with which `sample` picks that lobe (its
///   reported `pdf`), so drawing the fresh `u_lobe` uniformly in it is
///   measure-preserving;
/// - for the rough plastic, whose inverse picks its lobe at random, the
///   lobe the inverse chooses is distributed as the lobe sampling drew
///   (the Bernoulli check above, in the nested model's numbers).
#[test]
fn sampling_the_inverse_reproduces_the_direction_under_wrappers() {
    let nested: Vec<(&str, Bsdf)> = vec![
        ("diffuse", Bsdf::diffuse(Rgb::splat(0.5))),
        (
            "glass",
            build(&BsdfDesc::Dielectric {
                int_ior: 1.5,
                ext_ior: 1.0,
                specular_reflectance: Rgb::WHITE,
                specular_transmittance: Rgb::WHITE,
            }),
        ),
        (
            "plastic",
            build(&BsdfDesc::Plastic {
                diffuse_reflectance: Rgb::splat(0.5),
                specular_reflectance: Rgb::WHITE,
                int_ior: 1.49,
                ext_ior: 1.0,
                nonlinear: false,
            }),
        ),
        (
            "roughplastic",
            build(&BsdfDesc::RoughPlastic {
                distribution: MicrofacetKind::Ggx,
                alpha: 0.5,
                sample_visible: true,
                diffuse_reflectance: Rgb::splat(0.5),
                specular_reflectance: Rgb::WHITE,
                int_ior: 1.49,
                ext_ior: 1.0,
                nonlinear: false,
            }),
        ),
        (
            "roughconductor",
            build(&rough_conductor(MicrofacetKind::Ggx, (0.2, 0.2))),
        ),
        (
            "roughdielectric",
            build(&rough_dielectric(MicrofacetKind::Beckmann, (0.3, 0.3), 1.5)),
        ),
    ];
    let mut r = rng(91);
    let mut r_choice = rng(92);
    for (wname, wrap, opacity, splits) in wraps() {
        for (bname, model) in &nested {
            for mode in [TransportMode::Radiance, TransportMode::Importance] {
                let name = format!("{wname} / {bname} / {mode:?}");
                let b = BsdfAt::Wrapped(*model, wrap);
                let (mut n, mut nulls, mut worst) = (0usize, 0usize, 0f32);
                let (mut glossy_drawn, mut glossy_inverted, mut var) = (0u32, 0u32, 0f64);
                for i in 0..4000 {
                    let (a, c) = r.next_2d();
                    let mut wo = sph(
                        (0.02 + 0.96 * a) * std::f32::consts::FRAC_PI_2,
                        std::f32::consts::TAU * c,
                    );
                    if i % 4 == 3 {
                        wo.z = -wo.z;
                    }
                    let (ul, u) = draw(&mut r);
                    let Some(s) = b.sample(wo, ul, u, mode) else {
                        continue;
                    };
                    let inv = b
                        .invert_in(wo, s.wi, r_choice.next_1d(), mode)
                        .unwrap_or_else(|| {
                            panic!("{name}: no inverse for wo={wo:?} wi={:?}", s.wi)
                        });
                    let (lo, hi) = inv.u_lobe;
                    n += 1;
                    nulls += usize::from(s.wi == -wo && ul >= opacity);
                    if s.is_delta {
                        assert!(
                            ((hi - lo) - s.pdf).abs() < 1e-5,
                            "{name}: lobe interval [{lo}, {hi}) for a lobe of probability {}",
                            s.pdf
                        );
                    }
                    let u_again = if inv.u_used { inv.u } else { u };
                    if *bname == "roughplastic" && ul < opacity {
                        // The nested numbers: undo the mask's scale and the
                        // frame choice's half.
                        let scale = opacity
                            * if splits && mode == TransportMode::Importance {
                                0.5
                            } else {
                                1.0
                            };
                        let base = if lo >= scale { scale } else { 0.0 };
                        let (nlo, nhi) = ((lo - base) / scale, (hi - base) / scale);
                        let p = if nlo < 1e-6 { nhi } else { nlo };
                        glossy_drawn += u32::from((ul - base) / scale < p);
                        glossy_inverted += u32::from(nlo < 1e-6);
                        var += f64::from(p * (1.0 - p));
                        if !(ul >= lo && ul < hi) {
                            // The inverse chose the other lobe.
                            let again = b
                                .sample(wo, 0.5 * (lo + hi), u_again, mode)
                                .expect("resample");
                            worst = worst.max((again.wi - s.wi).length());
                            continue;
                        }
                    }
                    assert!(
                        ul >= lo - 1e-4 && ul < hi + 1e-4,
                        "{name}: u_lobe {ul} outside [{lo}, {hi}) for wo={wo:?} wi={:?}",
                        s.wi
                    );
                    let again = b
                        .sample(wo, ul.clamp(lo, hi - 1e-7), u_again, mode)
                        .unwrap_or_else(|| panic!("{name}: no resample"));
                    worst = worst.max((again.wi - s.wi).length());
                }
                // As above: f32 rounding amplified by the sampling map's stretch.
                assert!(worst < 1e-4, "{name}: |Δwi| {worst}");
                assert!(n > 1000, "{name}: only {n} samples");
                if opacity < 1.0 {
                    assert!(nulls > 0, "{name}: no null-lobe sample");
                }
                if *bname == "roughplastic" {
                    // As above: 5 SE of the difference of two Bernoulli sums.
                    let d = f64::from(glossy_drawn) - f64::from(glossy_inverted);
                    let se = (2.0 * var).sqrt();
                    assert!(
                        d.abs() < 5.0 * se,
                        "{name}: glossy drawn {glossy_drawn}, inverted {glossy_inverted} (SE {se:.1})"
                    );
                }
                eprintln!("{name:60} n={n} nulls={nulls} max |Δwi| {worst:.1e}");
            }
        }
    }
}
