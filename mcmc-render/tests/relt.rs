//! RELT (Kitaoka et al. 2009): the path-class partition, the MIS weights
//! over replicas, the replica drop rule, statistics and thread-count
//! determinism. Agreement with path tracing is `agree_mlt.rs`.

mod common;

use common::{repo_scene, repo_scene_tilted};
use mcmc_core::rng::stream_rng;
use mcmc_core::runner::with_threads;
use mcmc_core::space::TorusPoint;
use mcmc_render::color::Rgb;
use mcmc_render::integrators::bdpt::{Bdpt, MisHeuristic};
use mcmc_render::integrators::registry::IntegratorSettings;
use mcmc_render::integrators::relt::{Relt, ReltExchange, ReltFamily};
use mcmc_render::integrators::{Rendered, RunSettings};
use mcmc_render::markov::ChainFamily;
use mcmc_render::observer::NoObserver;
use mcmc_render::path_classes::{ClassScalar, ClassifiedBdpt, PathClass, class_values};
use mcmc_render::pss::{PATH_CLASSES, PathSample, PssPathSampler, PssSource, Splat};
use mcmc_render::scene::Scene;
use proptest::prelude::*;
use std::sync::atomic::AtomicBool;

fn bdpt_of(scene: &Scene) -> Bdpt {
    Bdpt {
        max_depth: scene.integrator.max_depth,
        rr_depth: scene.integrator.rr_depth,
        heuristic: MisHeuristic::Power,
    }
}

/// The splats of `sampler` at primary-sample point `i` of a fixed stream.
fn trace(scene: &Scene, sampler: &impl PssPathSampler, i: u64) -> Vec<Splat> {
    let point = TorusPoint::fresh(stream_rng(11, i));
    let mut source = PssSource::new(&point, sampler.streams());
    let mut out = Vec::new();
    sampler.trace(scene, &mut source, &mut out);
    out
}

#[test]
fn the_classes_partition_every_bdpt_sample() {
    // Same numbers, same techniques: the classified sampler's splats are
    // BDPT's, bit for bit, each with exactly one class; so the classes
    // sum back to BDPT's contribution.
    for name in [
        "cornell-box.xml",
        "cornell-glossy-glass.xml",
        "caustic-sds.xml",
    ] {
        let scene = repo_scene(name, 16);
        let bdpt = bdpt_of(&scene);
        let mut per_class = [0usize; PATH_CLASSES];
        for i in 0..3000 {
            let plain = trace(&scene, &bdpt, i);
            let classified = trace(&scene, &ClassifiedBdpt(bdpt), i);
            assert_eq!(plain.len(), classified.len(), "{name}: sample {i}");
            for (a, b) in plain.iter().zip(&classified) {
                assert_eq!((a.p, a.l), (b.p, b.l), "{name}: sample {i}");
                assert!(usize::from(b.class) < PATH_CLASSES);
                per_class[usize::from(b.class)] += 1;
            }
        }
        eprintln!("{name}: splats per class {per_class:?}");
        // A pinhole camera is never hit: no L3.
        assert_eq!(per_class[PathClass::ImplicitCaustic as usize], 0, "{name}");
        for c in [
            PathClass::Implicit,
            PathClass::Explicit,
            PathClass::ExplicitCaustic,
            PathClass::Indirect,
        ] {
            assert!(per_class[c as usize] > 0, "{name}: no {c:?} splat");
        }
        // Specular implicit paths need a mirror or glass; on the glass box
        // (a large light) 3000 samples find some (7 measured), on the SDS
        // scene (a small lamp) they are the rare paths RELT is for.
        let specular = per_class[PathClass::SpecularImplicit as usize];
        match name {
            "cornell-box.xml" => assert_eq!(specular, 0, "{name}: L0 without a specular surface"),
            "cornell-glossy-glass.xml" => assert!(specular > 0, "{name}: no L0 behind the glass"),
            _ => {}
        }
    }
}

#[test]
fn the_partition_rule_follows_the_techniques() {
    assert_eq!(PathClass::of(0, 2, false), PathClass::Implicit);
    assert_eq!(PathClass::of(0, 5, true), PathClass::SpecularImplicit);
    assert_eq!(PathClass::of(1, 2, true), PathClass::Explicit);
    assert_eq!(PathClass::of(3, 1, false), PathClass::ExplicitCaustic);
    assert_eq!(PathClass::of(2, 0, false), PathClass::ImplicitCaustic);
    assert_eq!(PathClass::of(2, 2, true), PathClass::Indirect);
}

fn family<'a>(scene: &'a Scene, settings: &Relt) -> ReltFamily<'a> {
    ReltFamily::new(scene, bdpt_of(scene), &settings.replicas(), settings)
}

/// A payload with class values `v` (one splat per class, grey).
fn payload(v: &[f64; PATH_CLASSES]) -> PathSample {
    let splats = v
        .iter()
        .enumerate()
        .map(|(c, &x)| Splat {
            p: glam::Vec2::ZERO,
            l: Rgb::splat(x as f32),
            class: c as u8,
        })
        .collect();
    PathSample { splats, depth: 0 }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Eq. 23's weights `w_k = b̂_k · factor_k · q_k / b̂_k` (the factor
    /// times `q_k`, since the driver scales by `b_k`) sum to 1 over the
    /// replicas that film a class, for any `b̂ > 0` and `β ≥ 1`; `L0` is
    /// filmed by the specific replica alone, with weight 1. A uniform
    /// replica drawing in a share of the sweeps only changes how the
    /// weight is split (each film is over its own draws): the sum stays 1.
    #[test]
    fn mis_weights_sum_to_one(
        v in prop::array::uniform6(0.0f64..10.0),
        b_hat in prop::array::uniform4(1e-3f64..10.0),
        beta in 1.0f64..3.0,
        luminance in any::<bool>(),
        uniform_share in 0.01f64..=1.0,
    ) {
        let scene = repo_scene("cornell-box.xml", 4);
        let settings = Relt {
            mis_power: beta,
            uniform_share,
            target: if luminance { ClassScalar::Luminance } else { ClassScalar::XyzSum },
            ..Relt::default()
        };
        let family = family(&scene, &settings);
        let x = payload(&v);
        let values = class_values(&x.splats, settings.target);
        prop_assume!(values[1..].iter().any(|&l| l > 0.0));
        let q: Vec<f64> = (0..4)
            .map(|k| family.member_log_density(k, &x).unwrap().exp())
            .collect();
        let factors: Vec<[f64; PATH_CLASSES]> = (0..4)
            .map(|k| family.class_weights(k, &x, &b_hat).unwrap())
            .collect();
        for (c, &specific) in factors[3].iter().enumerate().skip(1) {
            let total: f64 = factors.iter().zip(&q).map(|(f, q)| f[c] * q).sum();
            prop_assert!((total - 1.0).abs() < 1e-12, "class {c}: Σw = {total}");
            prop_assert_eq!(specific, 0.0);
        }
        if values[0] > 0.0 {
            prop_assert!((factors[3][0] * q[3] - 1.0).abs() < 1e-12);
            prop_assert!((0..3).all(|k| factors[k][0] == 0.0));
        }
    }
}

/// A small RELT run on the 16×16 box.
fn small(scene: &Scene, seed: u64, settings: Relt) -> Rendered {
    let stop = AtomicBool::new(false);
    let run = RunSettings {
        seed,
        ..RunSettings::default()
    };
    settings
        .render(scene, &run, &stop, &NoObserver)
        .expect("relt runs")
}

fn small_settings() -> Relt {
    let mut s = Relt::default();
    s.chain.bootstrap = 4000;
    s.chain.chains = 64;
    s.chain.mutations_per_pixel = Some(16);
    s.depth.max_depth = 5;
    s
}

fn bits(r: &Rendered) -> Vec<u32> {
    r.image
        .iter()
        .flat_map(|p| [p.r.to_bits(), p.g.to_bits(), p.b.to_bits()])
        .collect()
}

#[test]
fn a_resting_uniform_replica_with_one_swap_per_sweep_is_bit_identical_across_thread_counts() {
    // uniform_share = 1/4: the uniform replica draws in every fourth sweep
    // of each set, exactly (⌊(i+1)/4⌋ > ⌊i/4⌋); one random pair per sweep.
    let scene = repo_scene_tilted("cornell-glossy-glass.xml", 16, 5);
    let settings = || Relt {
        uniform_share: 0.25,
        exchange: ReltExchange::RandomNeighbour,
        ..small_settings()
    };
    let one = with_threads(1, || small(&scene, 5, settings()));
    let two = with_threads(2, || small(&scene, 5, settings()));
    let three = with_threads(3, || small(&scene, 5, settings()));
    assert!(bits(&one) == bits(&two), "1 vs 2 threads differ");
    assert!(bits(&one) == bits(&three), "1 vs 3 threads differ");
    assert_eq!(one.statistics["exchange"], two.statistics["exchange"]);
    let m: Vec<u64> = one.statistics["families"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["mutations"].as_u64().unwrap())
        .collect();
    // 16 × 16 pixels × 16 mutations per pixel = 4096 mutations over
    // 1 + 1 + 1 + 1/4 per sweep: ⌈4096/3.25⌉ = 1261 sweeps, shared out
    // over 16 sets (64 chains / 4) as 13 sets of 79 and 3 of 78. The
    // uniform replica draws in sweeps 3, 7, 11, …: ⌊79/4⌋ = ⌊78/4⌋ = 19
    // per set.
    assert_eq!(m, vec![16 * 19, 1261, 1261, 1261]);
    // One pair tried per sweep, every pair tried, and exchanges happen.
    let ex = &one.statistics["exchange"];
    let pairs = ex["pairs"].as_array().unwrap();
    let attempts: u64 = pairs.iter().map(|p| p["attempted"].as_u64().unwrap()).sum();
    assert_eq!(attempts, 1261, "{ex}");
    assert!(
        pairs.iter().all(|p| p["accepted"].as_u64().unwrap() > 0),
        "{ex}"
    );
}

#[test]
fn relt_is_bit_identical_across_thread_counts() {
    let scene = repo_scene_tilted("cornell-glossy-glass.xml", 16, 5);
    let one = with_threads(1, || small(&scene, 5, small_settings()));
    let two = with_threads(2, || small(&scene, 5, small_settings()));
    let three = with_threads(3, || small(&scene, 5, small_settings()));
    assert!(bits(&one) == bits(&two), "1 vs 2 threads differ");
    assert!(bits(&one) == bits(&three), "1 vs 3 threads differ");
    assert_eq!(one.statistics["exchange"], two.statistics["exchange"]);
    let other = with_threads(2, || small(&scene, 6, small_settings()));
    assert!(bits(&one) != bits(&other), "seed ignored");
    // Every neighbour pair exchanged, and the layers sum to the image.
    let pairs = one.statistics["exchange"]["pairs"].as_array().unwrap();
    assert_eq!(pairs.len(), 3, "{pairs:?}");
    assert!(pairs.iter().all(|p| p["accepted"].as_u64().unwrap() > 0));
    assert_eq!(one.layers.len(), 4);
    for (i, c) in one.image.iter().enumerate() {
        let sum: f32 = one
            .layers
            .iter()
            .map(|(_, l)| l[i].r + l[i].g + l[i].b)
            .sum();
        let total = c.r + c.g + c.b;
        assert!(
            (sum - total).abs() <= 1e-5 * total.abs().max(1e-6),
            "pixel {i}"
        );
    }
}

#[test]
fn a_replica_the_bootstrap_never_reached_is_dropped() {
    // Direct light only (max_depth 2): no L5 and, without speculars, no
    // L0, so the specific replica's b̂ is 0.
    let scene = repo_scene("cornell-box.xml", 16);
    let mut settings = small_settings();
    settings.depth.max_depth = 2;
    let r = small(&scene, 1, settings);
    assert_eq!(
        r.statistics["dropped_replicas"],
        serde_json::json!(["specific"])
    );
    assert_eq!(
        r.statistics["replicas"],
        serde_json::json!(["uniform", "full", "indirect"])
    );
    assert!(r.image.iter().any(|c| c.luminance() > 0.0));
}

#[test]
fn kelemen_mis_is_refused() {
    let mut settings = Relt::default();
    settings.chain.kelemen_mis = true;
    let e = settings.validate().unwrap_err();
    assert!(e.contains("kelemen_mis"), "{e}");
}

#[test]
fn the_ratio_chain_agrees_with_the_running_normalisation() {
    // On the diffuse box, where the uniform draws estimate every b_k
    // well: b_k by the chain of ratios (Eq. 10, errors from the spread
    // between tasks) and by the running estimate agree within 4σ.
    let scene = repo_scene_tilted("cornell-box.xml", 16, 5);
    let mut settings = small_settings();
    settings.chain.normalization = mcmc_render::markov::Normalization::Ratios;
    settings.chain.mutations_per_pixel = Some(256);
    let r = small(&scene, 3, settings);
    let families = r.statistics["families"].as_array().unwrap();
    for (k, f) in families.iter().enumerate().skip(1) {
        let ratio_b = f["scale"].as_f64().unwrap();
        let running = f["b_running"].as_f64().unwrap();
        let se_running = f["b_running_standard_error"].as_f64().unwrap();
        let se_ratio = f["scale_standard_error"].as_f64().unwrap();
        let sigma = se_running.hypot(se_ratio);
        eprintln!(
            "replica {k}: ratios {ratio_b:.5} ± {se_ratio:.5}, running {running:.5} ± {se_running:.5}"
        );
        assert!(sigma > 0.0 && sigma.is_finite(), "replica {k}: σ = {sigma}");
        assert!((ratio_b - running).abs() < 4.0 * sigma, "replica {k}");
    }
}

#[test]
fn ratios_need_members_that_share_an_evaluation() {
    let scene = repo_scene("cornell-box.xml", 8);
    let mut settings = mcmc_render::integrators::pssmlt::Pssmlt::default();
    settings.chain.normalization = mcmc_render::markov::Normalization::Ratios;
    settings.chain.bootstrap = 100;
    settings.chain.chains = 4;
    settings.chain.mutations_per_pixel = Some(1);
    let stop = AtomicBool::new(false);
    let e = match settings.render(&scene, &RunSettings::default(), &stop, &NoObserver) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("pssmlt ran with normalization=ratios"),
    };
    assert!(e.contains("normalization=ratios"), "{e}");
}
