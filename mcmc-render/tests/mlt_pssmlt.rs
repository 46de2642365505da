//! PSSMLT on `mcmc-core`: unbiased start-up, extreme primary samples,
//! black scenes, thread-count determinism (also of replica sets under the
//! driver's exchange path) and Kelemen's MIS variant. Agreement with path
//! tracing on the repo's Cornell variants is `agree_mlt.rs`.

mod common;

use mcmc_core::rng::stream_rng;
use mcmc_core::runner::with_threads;
use mcmc_core::space::TorusPoint;
use mcmc_render::color::Rgb;
use mcmc_render::integrators::pssmlt::{bootstrap, render_pssmlt};
use mcmc_render::integrators::pt::PathTracer;
use mcmc_render::markov::{MltError, MltResult};
use mcmc_render::observer::NoObserver;
use mcmc_render::pss::PssmltSettings;
use mcmc_render::pss::{Mutation, PssSource, PssTarget, SmallStepKind};
use mcmc_render::sampling::{IndependentSource, RandomSource};
use mcmc_render::scene::Scene;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::collections::HashMap;
use std::path::Path;
use std::sync::atomic::AtomicBool;

fn cornell(res: u32, look_y: f32, max_depth: u32) -> Scene {
    let mut defines = HashMap::new();
    defines.insert("res".to_string(), res.to_string());
    defines.insert("look_y".to_string(), look_y.to_string());
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/scenes/cornell-box.xml");
    let mut s = Scene::load(&path, &defines).expect("cornell box loads");
    s.integrator.max_depth = max_depth;
    s
}

fn pt_of(scene: &Scene) -> PathTracer {
    PathTracer {
        max_depth: scene.integrator.max_depth,
        rr_depth: scene.integrator.rr_depth,
    }
}

fn image_mean(img: &[Rgb]) -> [f64; 3] {
    let mut m = [0.0f64; 3];
    for p in img {
        m[0] += p.r as f64;
        m[1] += p.g as f64;
        m[2] += p.b as f64;
    }
    m.map(|v| v / img.len() as f64)
}

/// Mean and standard error of the mean of `k` replicate vectors.
fn mean_se(reps: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let k = reps.len() as f64;
    let mut mean = [0.0; 3];
    let mut se = [0.0; 3];
    for c in 0..3 {
        let m = reps.iter().map(|v| v[c]).sum::<f64>() / k;
        let var = reps.iter().map(|v| (v[c] - m).powi(2)).sum::<f64>() / (k - 1.0);
        mean[c] = m;
        se[c] = (var / k).sqrt();
    }
    (mean, se)
}

fn pssmlt(scene: &Scene, settings: &PssmltSettings) -> MltResult {
    let stop = AtomicBool::new(false);
    render_pssmlt(scene, pt_of(scene), settings, &stop, &NoObserver).expect("pssmlt runs")
}

fn small_settings(seed: u64) -> PssmltSettings {
    PssmltSettings {
        bootstrap: 20_000,
        chains: 64,
        mutations_per_pixel: Some(64),
        seed,
        ..PssmltSettings::default()
    }
}

/// `I(u)` by plain Monte Carlo with an independent generator, without
/// `TorusPoint`, `PssSource` or `Bootstrap`: camera sample uniform on the
/// image, then the path tracer.
fn independent_mean_luminance(scene: &Scene, n: usize, seed: u64) -> (f64, f64) {
    let pt = pt_of(scene);
    let mut src = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(seed));
    let (w, h) = (scene.film.width as f32, scene.film.height as f32);
    let (mut s, mut s2) = (0.0f64, 0.0f64);
    for _ in 0..n {
        let (ux, uy) = src.next_2d();
        let ray = scene.camera.generate_ray(glam::Vec2::new(ux * w, uy * h));
        let v = pt.li(scene, ray, &mut src).luminance() as f64;
        s += v;
        s2 += v * v;
    }
    let m = s / n as f64;
    (m, ((s2 / n as f64 - m * m) / n as f64).sqrt())
}

#[test]
fn bootstrap_b_star_is_unbiased() {
    // Emitter out of view: the weights I(u) are then light-tailed enough
    // for the normal approximation behind the 4σ bound.
    let scene = cornell(8, -1.1, 4);
    let target = PssTarget {
        scene: &scene,
        sampler: pt_of(&scene),
    };
    // 200 bootstraps of 500 candidates: their mean is an estimate of b from
    // 1e5 paths, with standard error = sd(b*)/sqrt(200) measured over seeds.
    let reps: Vec<f64> = (0..200)
        .map(|s| {
            bootstrap(&target, 500, 10_000 + s)
                .expect("bootstrap")
                .0
                .b()
        })
        .collect();
    let k = reps.len() as f64;
    let mb = reps.iter().sum::<f64>() / k;
    let se_b = (reps.iter().map(|v| (v - mb).powi(2)).sum::<f64>() / (k - 1.0) / k).sqrt();
    let (mi, se_i) = independent_mean_luminance(&scene, 200_000, 3);
    eprintln!("mean b* {mb} ± {se_b}, independent {mi} ± {se_i}");
    // Independent estimates: 4σ of the difference.
    let sigma = (se_b * se_b + se_i * se_i).sqrt();
    assert!(
        (mb - mi).abs() < 4.0 * sigma,
        "b* {mb} ± {se_b} vs {mi} ± {se_i}"
    );
    // The standard error the bootstrap reports matches the spread over seeds
    // (within 25%: the sd of 200 replicates has ~5% relative error, the
    // per-bootstrap SE of 500 heavy-tailed weights more).
    let sd_reps = se_b * k.sqrt();
    let reported = bootstrap(&target, 500, 99)
        .expect("bootstrap")
        .0
        .standard_error();
    assert!(
        (reported / sd_reps - 1.0).abs() < 0.5,
        "reported SE {reported} vs sd over seeds {sd_reps}"
    );
}

#[test]
fn extreme_primary_samples_give_finite_results() {
    let scene = cornell(8, 0.0, 5);
    let target = PssTarget {
        scene: &scene,
        sampler: pt_of(&scene),
    };
    for v in [0.0, 1.0 - f64::EPSILON / 2.0, 1.0 - 1e-9, 0.5] {
        let p = TorusPoint::from_values(&vec![v; 64], stream_rng(1, 0));
        let mut src = PssSource::new(&p, 1);
        for _ in 0..64 {
            let u = src.next_1d();
            assert!((0.0..1.0).contains(&u), "coordinate {v} read as {u}");
        }
        let e = target.trace(&p);
        assert!(!e.log_density.is_nan(), "coordinate {v}: NaN log density");
        assert!(e.payload.splats.iter().all(|s| s.l.is_finite()));
        let (w, h) = (scene.film.width as f32, scene.film.height as f32);
        for s in &e.payload.splats {
            assert!(s.p.x >= 0.0 && s.p.x < w && s.p.y >= 0.0 && s.p.y < h);
        }
    }
}

#[test]
fn a_black_scene_is_a_clear_error() {
    let mut defines = HashMap::new();
    defines.insert("res".to_string(), "8".to_string());
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/scenes/cornell-box.xml");
    let text = std::fs::read_to_string(&path).unwrap();
    let black = text.replace("18.387, 13.9873, 6.75357", "0, 0, 0");
    let scene = Scene::load_str(&black, Path::new("black.xml"), Path::new(".")).unwrap();
    let stop = AtomicBool::new(false);
    let r = render_pssmlt(
        &scene,
        pt_of(&scene),
        &small_settings(1),
        &stop,
        &NoObserver,
    );
    match r {
        Err(e @ MltError::BlackScene { .. }) => {
            let msg = e.to_string();
            assert!(msg.contains("black"), "{msg}");
        }
        Err(e) => panic!("wrong error: {e}"),
        Ok(_) => panic!("a black scene rendered without error"),
    }
}

#[test]
fn images_are_bit_identical_across_thread_counts() {
    let scene = cornell(16, 0.0, 5);
    for small in [
        SmallStepKind::Kelemen {
            s1: 1.0 / 1024.0,
            s2: 1.0 / 64.0,
        },
        SmallStepKind::Gaussian { sigma: 0.01 },
        SmallStepKind::Adaptive,
    ] {
        let mut st = small_settings(42);
        st.bootstrap = 2000;
        st.mutations_per_pixel = Some(8);
        st.mutation = Mutation {
            small,
            large_step_probability: 0.3,
        };
        let bits = |threads: usize, seed: u64| -> Vec<u32> {
            let mut st = st.clone();
            st.seed = seed;
            let r = with_threads(threads, || pssmlt(&scene, &st));
            r.image()
                .iter()
                .flat_map(|p| [p.r.to_bits(), p.g.to_bits(), p.b.to_bits()])
                .collect()
        };
        let one = bits(1, 42);
        assert!(one == bits(2, 42), "{small:?}: 1 vs 2 threads differ");
        assert!(one == bits(5, 42), "{small:?}: 1 vs 5 threads differ");
        assert!(one != bits(2, 43), "{small:?}: seed ignored");
    }
}

#[test]
fn replica_sets_are_bit_identical_across_thread_counts() {
    // The driver's exchange path: 12 sets of three powered levels with
    // even–odd swaps, spread over 5 tasks.
    let scene = cornell(16, 0.0, 5);
    let family = common::tempered::TemperedPss::new(&scene, pt_of(&scene), &[1.0, 0.6, 0.3]);
    let run = |threads: usize, seed: u64| {
        let mut st = small_settings(seed);
        st.bootstrap = 2000;
        st.chains = 36;
        st.tasks = 5;
        st.mutations_per_pixel = Some(12);
        let stop = AtomicBool::new(false);
        let r = with_threads(threads, || {
            mcmc_render::markov::run(&scene, &family, &st, &stop, &NoObserver).expect("runs")
        });
        let bits: Vec<u32> = r
            .image()
            .iter()
            .flat_map(|p| [p.r.to_bits(), p.g.to_bits(), p.b.to_bits()])
            .collect();
        (bits, r.exchange.expect("exchange counts"))
    };
    let (one, exchange) = run(1, 42);
    assert!(
        exchange.pairs.iter().any(|p| p.accepted > 0),
        "no swap accepted: {exchange:?}"
    );
    assert!(one.iter().any(|&b| b != 0), "black image");
    assert!(
        run(2, 42) == (one.clone(), exchange.clone()),
        "1 vs 2 threads differ"
    );
    assert!(
        run(3, 42) == (one.clone(), exchange),
        "1 vs 3 threads differ"
    );
    assert!(run(2, 43).0 != one, "seed ignored");
}

#[test]
fn kelemen_mis_and_plain_estimators_agree() {
    // Kelemen's MIS weights change the variance, not the expectation: the
    // image means of both estimators over seeds agree within 4σ.
    let scene = cornell(8, -1.1, 4);
    let run = |mis: bool, s: u64| {
        let mut st = small_settings(900 + s);
        st.mis_large_steps = mis;
        image_mean(&pssmlt(&scene, &st).image())
    };
    let plain: Vec<[f64; 3]> = (0..6).map(|s| run(false, s)).collect();
    let mis: Vec<[f64; 3]> = (0..6).map(|s| run(true, s)).collect();
    let (ma, sa) = mean_se(&plain);
    let (mb, sb) = mean_se(&mis);
    eprintln!("plain {ma:?} ± {sa:?}\nmis {mb:?} ± {sb:?}");
    for c in 0..3 {
        let sigma = (sa[c] * sa[c] + sb[c] * sb[c]).sqrt();
        assert!((ma[c] - mb[c]).abs() < 4.0 * sigma, "channel {c}");
    }
}
