//! RELT (Kitaoka et al. 2009): the path-class partition, the MIS weights
//! over replicas, the replica drop rule, statistics and thread-count
//! determinism. Agreement with path tracing is `agree_mlt.rs`.

mod common;

use common::{MeanAgreement, image_mean, mc_reps, pt_of, repo_scene, repo_scene_tilted};
use mcmc_core::rng::stream_rng;
use mcmc_core::runner::with_threads;
use mcmc_core::space::TorusPoint;
use mcmc_core::target::Target;
use mcmc_render::color::Rgb;
use mcmc_render::integrators::bdpt::{Bdpt, MisHeuristic};
use mcmc_render::integrators::registry::IntegratorSettings;
use mcmc_render::integrators::relt::{Relt, ReltExchange, ReltFamily, ReltMisClasses};
use mcmc_render::integrators::{Rendered, RunSettings};
use mcmc_render::markov::{ChainFamily, StartupCut};
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
    /// With `mis_classes=per_class` a replica whose target lacks a class
    /// films none of it (`L1`: the uniform replica alone, or with the full
    /// one under `full_l1`), and the weights still sum to 1 over the rest.
    #[test]
    fn mis_weights_sum_to_one(
        v in prop::array::uniform6(0.0f64..10.0),
        b_hat in prop::array::uniform4(1e-3f64..10.0),
        beta in 1.0f64..3.0,
        luminance in any::<bool>(),
        uniform_share in 0.01f64..=1.0,
        per_class in any::<bool>(),
        full_l1 in any::<bool>(),
    ) {
        let scene = repo_scene("cornell-box.xml", 4);
        let settings = Relt {
            mis_power: beta,
            uniform_share,
            target: if luminance { ClassScalar::Luminance } else { ClassScalar::XyzSum },
            mis_classes: if per_class { ReltMisClasses::PerClass } else { ReltMisClasses::All },
            full_l1,
            ..Relt::default()
        };
        let family = family(&scene, &settings);
        let replicas = settings.replicas();
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
            if per_class {
                // Only the replicas whose target holds the class film it
                // (the uniform replica's, `None`, holds every class).
                for (k, r) in replicas.iter().enumerate() {
                    let holds = r.weights.is_none_or(|d| d[c] > 0.0);
                    prop_assert!(holds || factors[k][c] == 0.0, "{} films class {c}", r.name);
                }
            }
        }
        // L1: the uniform replica alone, or with the full one under
        // full_l1 (whose weight is then > 0 wherever q_full > 0).
        if per_class {
            prop_assert_eq!(factors[2][1], 0.0);
            if !full_l1 {
                prop_assert_eq!(factors[1][1], 0.0);
            } else if q[1] > 0.0 {
                prop_assert!(factors[1][1] > 0.0);
            }
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
    // A small search: still run (and so covered by the thread-count tests),
    // and continued during the run (one draw per mutation).
    s.l0_search = 20_000;
    s.l0_search_rate = 1.0;
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
    // The search continued during the run (l0_search_rate 1 here):
    // 16 tasks of one replica set each, 256 mutations per task in one
    // round, units (strides) of 20 000 / 10 000 = 2 draws, so every task
    // owes ⌊1 · 256 / 2⌋ = 128 units: 4096 draws; equal for every thread
    // count, as the specific replica's b_4 they go into.
    assert_eq!(one.statistics["searches"][3]["run_draws"], 4096);
    assert_eq!(one.statistics["searches"], two.statistics["searches"]);
    assert_eq!(one.statistics["searches"], three.statistics["searches"]);
    assert_eq!(one.statistics["families"], three.statistics["families"]);
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
fn the_continued_search_pools_its_draws_into_b4_and_rescales_only_the_specific_replica() {
    // 64 chains / 4 replicas = 16 replica sets in 16 tasks; 48 mutations
    // per pixel on 16×16 = 12 288 mutations, 768 per task in 3 rounds of
    // 64 sweeps (256 mutations). At 0.3 draws per mutation in units
    // (strides) of 20 000 / 10 000 = 2 draws, a task owes ⌊0.3·256/2⌋ =
    // 38, ⌊76.8⌋ = 76 and ⌊115.2⌋ = 115 units after its rounds: 230
    // draws, 3680 over the 16 tasks.
    let scene = repo_scene_tilted("cornell-glossy-glass.xml", 16, 5);
    let settings = |rate: f64| {
        let mut s = small_settings();
        s.chain.mutations_per_pixel = Some(48);
        s.l0_search_rate = rate;
        s
    };
    let off = small(&scene, 5, settings(0.0));
    let on = small(&scene, 5, settings(0.3));
    assert_eq!(on.statistics["searches"][3]["run_draws"], 3680);
    assert_eq!(off.statistics["searches"][3]["run_draws"], 0);
    // The continued draws enter the specific replica's running b_4 only
    // (not the MIS weights' b̂, nor any chain): the other layers are the
    // same bits, the specific one is scaled by the ratio of the b_4's.
    let layer_bits = |r: &Rendered, k: usize| -> Vec<u32> {
        r.layers[k]
            .1
            .iter()
            .flat_map(|p| [p.r.to_bits(), p.g.to_bits(), p.b.to_bits()])
            .collect()
    };
    for k in 0..3 {
        assert!(layer_bits(&on, k) == layer_bits(&off, k), "layer {k}");
    }
    let b4 = |r: &Rendered| r.statistics["families"][3]["b_running"].as_f64().unwrap();
    let ratio = b4(&on) / b4(&off);
    assert!(ratio != 1.0);
    let mut lit = 0;
    for (a, b) in on.layers[3].1.iter().zip(&off.layers[3].1) {
        for (x, y) in [(a.r, b.r), (a.g, b.g), (a.b, b.b)] {
            let expected = f64::from(y) * ratio;
            assert!((f64::from(x) - expected).abs() <= 1e-6 * expected.abs());
            lit += usize::from(y > 0.0);
        }
    }
    assert!(lit > 0, "the specific replica filmed nothing");
    // b_4 merged over the rounds is the pooled mean of all its draws: the
    // run without the continued search pools the 4000 bootstrap draws,
    // the 20 000 start-up search draws and the uniform replica's 3072
    // draws (one per sweep); the continued draws, recomputed here by hand
    // (task t's unit u starts at first_index + (16u + t)·2), add their
    // weights and their count.
    let uniform_draws = on.statistics["families"][0]["mutations"].as_u64().unwrap();
    assert_eq!(uniform_draws, 3072);
    let n_off = (4000 + 20_000 + uniform_draws) as f64;
    let n_on = n_off + 3680.0;
    let s = settings(0.3);
    let bdpt = Bdpt {
        max_depth: s.depth.limit(),
        rr_depth: s.depth.rr_depth,
        heuristic: MisHeuristic::Power,
    };
    let fam = ReltFamily::new(&scene, bdpt, &s.replicas(), &s);
    let plan = fam
        .continued_search(3)
        .expect("the specific replica searches on");
    assert_eq!(plan.unit, 2);
    let mut sum = 0.0;
    for t in 0..16 {
        for u in 0..115 {
            let first = plan.first_index + (u * 16 + t) * plan.unit;
            sum += fam
                .search_unit(3, 5, first)
                .iter()
                .map(|lw| lw.exp())
                .sum::<f64>();
        }
    }
    let pooled = (n_off * b4(&off) + sum) / n_on;
    eprintln!(
        "b_4: {} without, {} with, pooled by hand {pooled}",
        b4(&off),
        b4(&on)
    );
    assert!(
        (b4(&on) - pooled).abs() <= 1e-9 * pooled,
        "b_4 is not the pooled mean"
    );
    // No other replica searches.
    assert!((0..3).all(|m| fam.continued_search(m).is_none()));
}

#[test]
fn filmed_rescales_only_the_full_and_indirect_replicas_of_the_same_chains() {
    // relt's default `filmed` against `running`, same seed: the same
    // chains and draws, so the uniform and specific layers are the same
    // bits and the full and indirect ones differ by their scales' ratio,
    // `b_filmed / filmed_share` over `b_running` (docs/relt.md, session 24).
    let scene = repo_scene_tilted("cornell-glossy-glass.xml", 16, 5);
    let filmed = small(&scene, 5, small_settings());
    assert_eq!(
        Relt::default().chain.normalization,
        mcmc_render::markov::Normalization::Filmed
    );
    let mut settings = small_settings();
    settings.chain.normalization = mcmc_render::markov::Normalization::Running;
    let running = small(&scene, 5, settings);
    let layer = |r: &Rendered, k: usize| -> Vec<f32> {
        r.layers[k].1.iter().flat_map(|p| [p.r, p.g, p.b]).collect()
    };
    for k in [0, 3] {
        let same = layer(&filmed, k)
            .iter()
            .map(|x| x.to_bits())
            .eq(layer(&running, k).iter().map(|x| x.to_bits()));
        assert!(same, "layer {k}");
    }
    for k in [1, 2] {
        let f = &filmed.statistics["families"][k];
        let get = |name: &str| f[name].as_f64().unwrap_or(f64::NAN);
        let (b, share, scale) = (get("b_filmed"), get("filmed_share"), get("scale"));
        assert!(share > 0.0 && share <= 1.0, "replica {k}: share {share}");
        assert!((scale - b / share).abs() <= 1e-12 * scale, "replica {k}");
        let ratio = scale / get("b_running");
        assert!(ratio != 1.0, "replica {k}: the scales are equal");
        let mut lit = 0;
        for (x, y) in layer(&filmed, k).iter().zip(layer(&running, k)) {
            let expected = f64::from(y) * ratio;
            assert!(
                (f64::from(*x) - expected).abs() <= 1e-6 * expected.abs(),
                "replica {k}"
            );
            lit += usize::from(y > 0.0);
        }
        assert!(lit > 0, "replica {k} filmed nothing");
    }
    // The uniform and specific replicas film all of their targets.
    for k in [0, 3] {
        assert!(filmed.statistics["families"][k].get("b_filmed").is_none());
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

/// A RELT run stopped before its chains move writes its start-up
/// candidates' image: each candidate's splats weighted per path class by
/// the replicas' MIS factors `Σ_k g_{k,c} q_k` (the specific replica's
/// `1/q_4` on `L0`, the power heuristic over the others elsewhere: 1 on
/// every class; `markov/startup.rs`). On the tilted Cornell box (depth 5),
/// 200 runs stopped at once, each drawing one round of 4096 candidates,
/// against PT (48 × 256 spp) within 4σ and 1% with 5σ < 1% (Student's t
/// with 199 degrees of freedom); the same replicates × 1.01 must fail.
/// Measured: −0.10%, +0.00%, −0.04% (σ 0.15%, 0.16%, 0.18%).
#[test]
fn a_run_stopped_in_its_start_up_writes_the_candidates_image() {
    let scene = repo_scene_tilted("cornell-box.xml", 16, 5);
    let stop = AtomicBool::new(true);
    let mut settings = small_settings();
    settings.chain.bootstrap = 4096;
    // Without the L0 search, and a small annealing population: neither
    // makes the start-up image, and they took most of the test's time.
    (settings.l0_search, settings.l0_search_rate) = (0, 0.0);
    settings.annealing_particles = 1000;
    let reps: Vec<[f64; 3]> = (0..200)
        .map(|i| {
            let run = RunSettings {
                seed: 31_000 + i,
                ..RunSettings::default()
            };
            let r = settings
                .render(&scene, &run, &stop, &NoObserver)
                .expect("relt runs");
            assert!(r.interrupted && r.statistics["image_from_start_up"] == true);
            image_mean(&r.image)
        })
        .collect();
    let pt = mc_reps(&scene, &pt_of(&scene), 256, 48, 1000);
    let a = MeanAgreement::new(&pt, &reps);
    eprintln!("relt start-up image: rel {:?}\n  {a:?}", a.rel());
    assert!(a.failures(4.0, 0.01).is_empty(), "disagrees with PT: {a:?}");
    assert!(a.resolves(5.0, 0.01), "noise too large: {a:?}");
    let biased: Vec<[f64; 3]> = reps.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let b = MeanAgreement::new(&pt, &biased);
    assert!(!b.failures(4.0, 0.01).is_empty(), "a 1% bias passed: {b:?}");
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
    // And so does `filmed` (relt's default), which reads the filmed part
    // off the same payload: pssmlt refuses both with one line.
    use mcmc_render::markov::Normalization;
    let scene = repo_scene("cornell-box.xml", 8);
    for (normalization, name) in [
        (Normalization::Ratios, "normalization=ratios"),
        (Normalization::Filmed, "normalization=filmed"),
    ] {
        let mut settings = mcmc_render::integrators::pssmlt::Pssmlt::default();
        settings.chain.normalization = normalization;
        settings.chain.bootstrap = 100;
        settings.chain.chains = 4;
        settings.chain.mutations_per_pixel = Some(1);
        let stop = AtomicBool::new(false);
        let e = match settings.render(&scene, &RunSettings::default(), &stop, &NoObserver) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("pssmlt ran with {name}"),
        };
        assert!(e.contains(name) && !e.contains('\n'), "{e}");
    }
}

#[test]
fn the_l0_screen_misses_no_l0_path() {
    // The specific replica's search traces in full only the draws whose
    // camera subpath alone reaches an emitter after a Dirac delta, and
    // gives the others L0 = 0: that is exact only if no sample with
    // L0 > 0 fails the screen.
    for (name, samples) in [
        ("cornell-glossy-glass.xml", 6000),
        ("caustic-sds.xml", 3000),
    ] {
        let scene = repo_scene(name, 16);
        let sampler = ClassifiedBdpt(bdpt_of(&scene));
        let (mut l0, mut screened) = (0, 0);
        for i in 0..samples {
            let v = class_values(&trace(&scene, &sampler, i), ClassScalar::XyzSum);
            let point = TorusPoint::fresh(stream_rng(11, i));
            let pass = sampler.may_carry_specular_implicit(&scene, &point);
            screened += usize::from(pass);
            if v[PathClass::SpecularImplicit as usize] > 0.0 {
                l0 += 1;
                assert!(pass, "{name}: sample {i} carries L0 but fails the screen");
            }
        }
        eprintln!("{name}: {l0} samples with L0, {screened} pass the screen of {samples}");
        if name == "cornell-glossy-glass.xml" {
            assert!(l0 > 0, "{name}: no L0 sample to check the screen on");
        }
    }
}

/// Mean and standard error of `n` values whose non-zero ones are `w`.
fn mean_se(w: impl Iterator<Item = f64>, n: u64) -> (f64, f64) {
    let (s, s2) = w.fold((0.0, 0.0), |(s, s2), x| (s + x, s2 + x * x));
    let n = n as f64;
    let mean = s / n;
    (mean, ((s2 / n - mean * mean) / (n - 1.0)).sqrt())
}

#[test]
fn the_l0_search_estimates_b4_without_bias() {
    // The search's mean weight over its draws against the plain mean of
    // q_4 over independent full traces, on the glossy-glass box (L0 is
    // common there) with δ = 1 so that the L5 part, which the search
    // estimates from a subsample of 1 in 10 draws, is large. Both are
    // means of many independent draws (10^5 and 2·10^4), so their
    // difference is normal to a good approximation: pass within 4σ
    // (false alarm 6e-5). Control: the subsample without its factor 10
    // (L5 undercounted) must fall outside 4σ.
    let scene = repo_scene("cornell-glossy-glass.xml", 16);
    let settings = Relt {
        delta: 1.0,
        l0_search: 100_000,
        l0_search_rate: 1.0,
        ..Relt::default()
    };
    let fam = family(&scene, &settings);
    let specific = 3;
    let search = fam
        .search(specific, 5, &StartupCut::NEVER)
        .expect("the specific replica searches");
    assert_eq!(search.draws, 100_000);
    let stride = 10.0;
    let sampler = ClassifiedBdpt(bdpt_of(&scene));
    let subsampled: Vec<bool> = search
        .weighted
        .iter()
        .map(|&(i, _)| !sampler.may_carry_specular_implicit(&scene, &fam.candidate(5, i)))
        .collect();
    let found = search.weighted.iter().map(|w| w.1.exp());
    let (b_search, se_search) = mean_se(found.clone(), search.draws);
    let plain_n = 20_000;
    let plain = (0..plain_n).map(|i| {
        fam.target(specific)
            .evaluate(&fam.candidate(5, i))
            .log_density
            .exp()
    });
    let (b_plain, se_plain) = mean_se(plain, plain_n);
    let sigma = se_search.hypot(se_plain);
    eprintln!("b_4: search {b_search:.5} ± {se_search:.5}, plain {b_plain:.5} ± {se_plain:.5}");
    assert!(subsampled.iter().any(|&s| s) && subsampled.iter().any(|&s| !s));
    assert!((b_search - b_plain).abs() < 4.0 * sigma, "search disagrees");
    let control = found
        .zip(&subsampled)
        .map(|(w, &s)| if s { w / stride } else { w });
    let (b_control, _) = mean_se(control, search.draws);
    eprintln!("control (subsample unscaled): {b_control:.5}");
    assert!((b_control - b_plain).abs() > 4.0 * sigma, "control passed");
    // The search continued during the run: 5000 units (strides of 10
    // draws) of its own candidates. The units' weight sums are
    // independent, each an unbiased estimate of 10·b_4, so b_4 is their
    // mean over 10 with the standard error of that mean; against the
    // plain mean within 4σ.
    let plan = fam
        .continued_search(specific)
        .expect("the search continues");
    assert_eq!(plan.unit, 10);
    // Control: each unit's representative (its first draw, when it fails
    // the screen) without its factor 10 must fall outside 4σ.
    let (units, controls): (Vec<f64>, Vec<f64>) = (0..5000u64)
        .map(|u| {
            let first = plan.first_index + u * plan.unit;
            let w = fam.search_unit(specific, 5, first);
            let sum = w.iter().map(|lw| lw.exp()).sum::<f64>();
            let x = fam.candidate(5, first);
            let control = if sampler.may_carry_specular_implicit(&scene, &x) {
                sum
            } else {
                let q = fam.target(specific).evaluate(&x).log_density.exp().max(0.0);
                sum - q * (stride - 1.0)
            };
            (sum / stride, control / stride)
        })
        .unzip();
    let (b_run, se_run) = mean_se(units.into_iter(), 5000);
    let sigma = se_run.hypot(se_plain);
    eprintln!("b_4: continued search {b_run:.5} ± {se_run:.5}");
    assert!(
        (b_run - b_plain).abs() < 4.0 * sigma,
        "continued search disagrees"
    );
    let (b_control, _) = mean_se(controls.into_iter(), 5000);
    eprintln!("control (representatives unscaled): {b_control:.5}");
    assert!((b_control - b_plain).abs() > 4.0 * sigma, "control passed");
}

#[test]
fn the_l0_search_starts_the_specific_replica_on_l0_paths() {
    // The glass cube of docs/relt.md: its L0 paths (the yellow cube seen
    // and lit through the glass, caustics seen through it) are rare, and
    // the bootstrap and annealing start-up found none. The search finds
    // some, and the specific replica's starts are resampled from its
    // weights: the number of starts on an L0 path is Binomial(n, share),
    // share = the L0 draws' part of the total weight; checked within 4
    // binomial standard deviations (plus one for the discreteness of
    // systematic resampling).
    let scene = repo_scene("relt-glass-cube.xml", 16);
    let settings = Relt {
        l0_search: 100_000,
        ..Relt::default()
    };
    let fam = family(&scene, &settings);
    let specific = 3;
    let search = fam
        .search(specific, 7, &StartupCut::NEVER)
        .expect("the specific replica searches");
    let l0_of = |x: &TorusPoint| {
        let e = fam.target(specific).evaluate(x);
        class_values(&e.payload.splats, ClassScalar::XyzSum)[PathClass::SpecularImplicit as usize]
    };
    let (mut l0_draws, mut l0_weight, mut total) = (0, 0.0, 0.0);
    for &(i, lw) in &search.weighted {
        total += lw.exp();
        if l0_of(&fam.candidate(7, i)) > 0.0 {
            l0_draws += 1;
            l0_weight += lw.exp();
        }
    }
    let share = l0_weight / total;
    let n = 64;
    let starts = search
        .starts(&fam, n, 7, specific)
        .expect("resampling")
        .expect("weighted draws");
    let on_l0 = starts.iter().filter(|x| l0_of(x) > 0.0).count();
    eprintln!(
        "{l0_draws} L0 draws of {} weighted, L0 share {share:.3}, starts on L0 {on_l0}/{n}",
        search.weighted.len()
    );
    assert!(l0_draws > 0, "the search found no L0 path");
    let expected = n as f64 * share;
    let sd = (n as f64 * share * (1.0 - share)).sqrt();
    assert!(on_l0 > 0, "no start on an L0 path");
    assert!(
        (on_l0 as f64 - expected).abs() <= 4.0 * sd + 1.0,
        "{on_l0} starts on L0, expected {expected:.1} ± {sd:.1}"
    );
}

/// The Cornell box at `res`×`res` and `max_depth` seen from below its
/// light (camera at y = 0.5 looking straight up, 0.49 below it): the
/// frame (half-width 0.49 · tan 19.65° = 0.18) lies inside the 0.46 ×
/// 0.38 emitter, so every pixel is one where the light is seen directly,
/// the pixels that `mis_classes=per_class` leaves to the uniform replica
/// (docs/relt.md, "1479 ± 43").
fn under_the_light(res: u32, max_depth: u32) -> Scene {
    let text = common::repo_scene_tilted_text("cornell-box.xml", res, max_depth);
    let from = r#"origin="0, 0, 3.9" target="0, -1.1, 0" up="0, 1, 0""#;
    let to = r#"origin="0, 0.5, 0.01" target="0, 0.99, 0.01" up="0, 0, 1""#;
    let out = text.replace(from, to);
    assert_ne!(out, text, "camera not found");
    common::load_str(&out)
}

/// `mis_classes=per_class` (and, as a check of the test, `all`): on real
/// BDPT samples of the box, drawn uniformly in primary sample space, the
/// MIS weights `w_k = factor_k · q_k` of every class sum to 1 over the
/// replicas (1e-12) for random `b̂ > 0`, shares and β, also on the paths
/// where some replica's density is 0 (such a replica's chain never sits
/// there, and it contributes `factor · 0`); under `per_class` a replica
/// whose target lacks the class has factor 0 whatever its density (it
/// films none of the class), so `L1` is the uniform replica's alone
/// without `full_l1`, with weight 1. The uniform replica's `q = 1` is in
/// every class's sum, so no sum is empty or short.
#[test]
fn per_class_weights_sum_to_one_on_real_paths_of_the_box() {
    let mut rng = stream_rng(77, 0);
    let mut u = move || mcmc_core::rng::uniform(&mut rng);
    for (scene, name) in [
        (repo_scene("cornell-box.xml", 16), "front"),
        (under_the_light(8, 5), "under the light"),
    ] {
        let (mut l1_paths, mut l1_zero_q) = (0, 0);
        for case in 0..4 {
            let settings = Relt {
                mis_classes: if case < 3 {
                    ReltMisClasses::PerClass
                } else {
                    ReltMisClasses::All
                },
                full_l1: case == 1,
                specific_replica: case != 2,
                mis_power: if case == 0 { 1.0 } else { 1.0 + 2.0 * u() },
                uniform_share: if case == 0 { 1.0 } else { 0.05 + 0.95 * u() },
                ..Relt::default()
            };
            let family = family(&scene, &settings);
            let replicas = settings.replicas();
            let m = replicas.len();
            let specific = replicas.iter().position(|r| r.name == "specific");
            for i in 0..1500 {
                let b_hat: Vec<f64> = (0..m).map(|_| 1e-3 + 10.0 * u()).collect();
                let x = TorusPoint::fresh(stream_rng(78, i));
                let e = family.target(0).evaluate(&x);
                let v = class_values(&e.payload.splats, settings.target);
                if v.iter().any(|l| l.is_nan()) {
                    continue;
                }
                let q: Vec<f64> = (0..m)
                    .map(|k| family.member_log_density(k, &e.payload).unwrap().exp())
                    .collect();
                let factors: Vec<[f64; PATH_CLASSES]> = (0..m)
                    .map(|k| family.class_weights(k, &e.payload, &b_hat).unwrap())
                    .collect();
                if v[1] > 0.0 {
                    l1_paths += 1;
                    l1_zero_q += usize::from(q.contains(&0.0));
                }
                for c in 0..PATH_CLASSES {
                    // A replica never sits where its q is 0: its weight
                    // there is 0 (its factor may be 1/0 for L0).
                    let total: f64 = factors
                        .iter()
                        .zip(&q)
                        .map(|(f, &q)| if q > 0.0 { f[c] * q } else { 0.0 })
                        .sum();
                    // L0 with the specific replica is its alone: weight 1
                    // where L0 > 0 (q_4 ≥ L0), nothing to weigh elsewhere.
                    if c == 0 && specific.is_some() && v[0] == 0.0 {
                        assert!(total == 0.0 || (total - 1.0).abs() < 1e-12);
                        continue;
                    }
                    assert!(
                        (total - 1.0).abs() < 1e-12,
                        "{name}, case {case}, path {i}, class {c}: Σw = {total}, q = {q:?}"
                    );
                    for (k, r) in replicas.iter().enumerate() {
                        let films = factors[k][c] != 0.0;
                        if Some(k) == specific {
                            assert!(!films || c == 0, "the specific replica films class {c}");
                        } else if settings.mis_classes == ReltMisClasses::PerClass {
                            let holds = r.weights.is_none_or(|d| d[c] > 0.0);
                            assert!(holds || !films, "{} films class {c}", r.name);
                        }
                    }
                }
                if settings.mis_classes == ReltMisClasses::PerClass && !settings.full_l1 {
                    let w = factors[0][1] * q[0];
                    assert!(
                        (w - 1.0).abs() < 1e-12,
                        "L1: the uniform replica's alone, w = {w}"
                    );
                }
            }
        }
        eprintln!("{name}: {l1_paths} paths with L1, {l1_zero_q} of them with some q_k = 0");
        assert!(l1_paths > 0, "{name}: no L1 path drawn");
        assert!(l1_zero_q > 0, "{name}: no L1 path where a replica's q is 0");
    }
}

/// Interior-pixel means (2 pixels, the Gaussian filter's radius, from
/// every edge) of `k` RELT runs under the light: `mis_classes=per_class`,
/// no specific replica (the box has no `L0`), 48 chains (16 sets of
/// three) of `mpp` mutations per pixel, seeds `seed0 ..`.
fn per_class_under_the_light(scene: &Scene, mpp: u64, k: u64, seed0: u64) -> Vec<[f64; 3]> {
    let settings = Relt {
        mis_classes: ReltMisClasses::PerClass,
        specific_replica: false,
        annealing_particles: 1000,
        l0_search: 0,
        ..Relt::default()
    };
    let family = family(scene, &settings);
    let stop = AtomicBool::new(false);
    let mask = interior(scene);
    (0..k)
        .map(|s| {
            let chain = mcmc_render::markov::ChainSettings::<()> {
                bootstrap: 10_000,
                chains: 48,
                mutations_per_pixel: Some(mpp),
                seed: seed0 + s,
                normalization: mcmc_render::markov::Normalization::Running,
                ..Default::default()
            };
            let r = mcmc_render::markov::run(scene, &family, &chain, &stop, &NoObserver)
                .expect("relt runs");
            assert_eq!(r.chain_stats.invalid_density, 0, "NaN/inf paths");
            common::masked_mean(&r.image(), Some(&mask))
        })
        .collect()
}

/// The pixels at least 2 from every edge.
fn interior(scene: &Scene) -> Vec<bool> {
    let (w, h) = (scene.film.width, scene.film.height);
    (0..w * h)
        .map(|i| (2..w - 2).contains(&(i % w)) && (2..h - 2).contains(&(i / w)))
        .collect()
}

/// `mis_classes=per_class` agrees with BDPT where the light is seen
/// directly (every pixel, `under_the_light`), per channel.
///
/// Tolerance: `K` replicates of each (distinct fixed seeds; a RELT
/// replicate has its own bootstrap, annealing and chains), SE of a mean
/// = sd(replicate means)/√K, σ of the difference = √(SE_relt² +
/// SE_bdpt²). Pass within 4σ: with K = 12 each the difference over σ
/// is Student's t with ≥ 11 dof (Welch), P(|T| > 4) ≈ 2e-3 per
/// channel. The budget must make 5σ < 1% (asserted), so the control,
/// the RELT replicates ×1.01, lies ≥ 5σ out and must fail; session 14's
/// suspected excess (+9%, docs/relt.md) would lie ≥ 45σ out.
///
/// Ignored: at this budget (measured, session 15, load ~16) RELT's SE
/// is 0.30% per channel, so the 1% resolution check fails (+0.42%,
/// 1.4σ: agreement; a +9% excess would be 30σ out); it needs ~3× the
/// mutations, over the 3 s limit. Run with `cargo test -p mcmc-render
/// --test relt -- --ignored per_class_agrees`.
#[test]
#[ignore]
fn per_class_agrees_with_bdpt_where_the_light_is_seen_directly() {
    const K: u64 = 12;
    let scene = under_the_light(10, 3);
    let mask = interior(&scene);
    let bdpt: Vec<[f64; 3]> = (0..K)
        .map(|s| {
            let img = common::render_image(&scene, &bdpt_of(&scene), 64, 500 + s);
            common::masked_mean(&img, Some(&mask))
        })
        .collect();
    let relt = per_class_under_the_light(&scene, 256, K, 600);
    let a = common::MeanAgreement::new(&bdpt, &relt);
    eprintln!("per_class under the light: rel {:?}\n  {a:?}", a.rel());
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "per_class disagrees with BDPT on the light: {a:?}"
    );
    // The control: a 1% bias must be rejected.
    let biased: Vec<[f64; 3]> = relt.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let control = common::MeanAgreement::new(&bdpt, &biased);
    assert!(
        !control.failures(4.0, 0.01).is_empty(),
        "a 1% bias passed: {control:?}"
    );
}
