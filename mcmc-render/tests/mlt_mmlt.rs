//! PSSMLT over BDPT and multiplexed MLT: agreement with path tracing and
//! thread-count determinism.

use mcmc_core::runner::with_threads;
use mcmc_render::color::Rgb;
use mcmc_render::integrators::bdpt::{Bdpt, MisHeuristic};
use mcmc_render::integrators::pssmlt::{
    MltResult, NoMltObserver, Normalization, PssmltSettings, render_family, render_pssmlt,
};
use mcmc_render::integrators::pt::PathTracer;
use mcmc_render::pss::MmltDepth;
use mcmc_render::render::{NoObserver, RenderSettings, render};
use mcmc_render::scene::Scene;
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

fn bdpt_of(scene: &Scene) -> Bdpt {
    Bdpt {
        max_depth: scene.integrator.max_depth,
        rr_depth: scene.integrator.rr_depth,
        heuristic: MisHeuristic::Power,
    }
}

fn depths(scene: &Scene) -> Vec<MmltDepth> {
    (1..=scene.integrator.max_depth as usize)
        .map(|depth| MmltDepth {
            bdpt: bdpt_of(scene),
            depth,
        })
        .collect()
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

fn pt_reps(scene: &Scene, k: u64) -> Vec<[f64; 3]> {
    let pt = PathTracer {
        max_depth: scene.integrator.max_depth,
        rr_depth: scene.integrator.rr_depth,
    };
    (0..k)
        .map(|s| {
            let settings = RenderSettings {
                spp: Some(256),
                time_budget: None,
                seed: 500 + s,
            };
            let stop = AtomicBool::new(false);
            image_mean(&render(scene, &pt, &settings, &stop, &NoObserver).image())
        })
        .collect()
}

fn settings(seed: u64) -> PssmltSettings {
    PssmltSettings {
        bootstrap: 100_000,
        chains: 256,
        mutations_per_pixel: Some(1024),
        seed,
        normalization: Normalization::Running,
        ..PssmltSettings::default()
    }
}

/// PT and a Metropolis estimator agree on every channel mean: within 4σ of
/// the difference (σ from the spread over seeds, both sides independent)
/// and within 1%, with 4σ below `resolution` (relative) so that the test
/// can tell a bias of that size.
fn check_agreement(what: &str, pt: &[[f64; 3]], mlt: &[[f64; 3]], resolution: f64) {
    let (mp, sp) = mean_se(pt);
    let (mm, sm) = mean_se(mlt);
    eprintln!("pt {mp:?} ± {sp:?}\n{what} {mm:?} ± {sm:?}");
    for c in 0..3 {
        let sigma = (sp[c] * sp[c] + sm[c] * sm[c]).sqrt();
        assert!(
            (mm[c] - mp[c]).abs() < 4.0 * sigma,
            "{what} channel {c}: pt {} ± {}, {} ± {}",
            mp[c],
            sp[c],
            mm[c],
            sm[c]
        );
        let rel = (mm[c] - mp[c]) / mp[c];
        assert!(
            rel.abs() < 0.01,
            "{what} channel {c}: relative difference {rel}"
        );
        assert!(
            4.0 * sigma < resolution * mp[c],
            "{what} channel {c}: noise too large to resolve {resolution}"
        );
    }
}

fn run(r: Result<MltResult, mcmc_render::integrators::pssmlt::MltError>) -> [f64; 3] {
    let r = r.expect("mlt runs");
    assert_eq!(r.chain_stats.invalid_density, 0);
    image_mean(&r.image())
}

#[test]
fn pssmlt_over_bdpt_and_pt_agree_on_the_cornell_box() {
    let scene = cornell(16, -1.1, 5);
    let k = 12;
    let stop = AtomicBool::new(false);
    let mlt: Vec<[f64; 3]> = (0..k)
        .map(|s| {
            run(render_pssmlt(
                &scene,
                bdpt_of(&scene),
                &settings(700 + s),
                &stop,
                &NoMltObserver,
            ))
        })
        .collect();
    check_agreement("pssmlt-bdpt", &pt_reps(&scene, k), &mlt, 0.01);
}

#[test]
fn mmlt_and_pt_agree_on_the_cornell_box() {
    let scene = cornell(16, -1.1, 5);
    let k = 12;
    let stop = AtomicBool::new(false);
    let mlt: Vec<[f64; 3]> = (0..k)
        .map(|s| {
            run(render_family(
                &scene,
                depths(&scene),
                &settings(800 + s),
                &stop,
                &NoMltObserver,
            ))
        })
        .collect();
    // MMLT's image mean is noisier at this budget (chains split over five
    // depths): with per-depth normalisation, measured 4σ of the difference
    // ≈ 1.3% (red), 0.9% (green), 1.3% (blue) of the mean over 12 seeds
    // (it was 1.6–2.1% when one film was scaled by b = Σ b_d and chains
    // were drawn at random), so this fast test resolves 1.5%, not 1%; the
    // means themselves agree to 0.05–0.2% (and the 1% check still holds).
    check_agreement("mmlt", &pt_reps(&scene, k), &mlt, 0.015);
}

#[test]
fn mmlt_is_bit_identical_across_thread_counts() {
    let scene = cornell(16, 0.0, 4);
    let bits = |threads: usize, seed: u64| -> Vec<u32> {
        let mut st = settings(seed);
        st.bootstrap = 2000;
        st.chains = 64;
        st.mutations_per_pixel = Some(8);
        let stop = AtomicBool::new(false);
        let r = with_threads(threads, || {
            render_family(&scene, depths(&scene), &st, &stop, &NoMltObserver)
        })
        .expect("mmlt runs");
        r.image()
            .iter()
            .flat_map(|p| [p.r.to_bits(), p.g.to_bits(), p.b.to_bits()])
            .collect()
    };
    let one = bits(1, 42);
    assert!(one == bits(2, 42), "1 vs 2 threads differ");
    assert!(one == bits(5, 42), "1 vs 5 threads differ");
    assert!(one != bits(2, 43), "seed ignored");
}

#[test]
fn mmlt_with_kelemen_mis_per_depth_agrees_with_plain_mmlt() {
    // Kelemen's MIS weights, applied per depth with that depth's b_d, change
    // the variance, not the expectation: the image means of both estimators
    // over seeds agree within 4σ (σ from the spread over seeds).
    let scene = cornell(8, -1.1, 4);
    let stop = AtomicBool::new(false);
    let run_with = |mis: bool, s: u64| {
        // Different seeds for the two estimators keep them independent,
        // as the σ of the difference assumes.
        let mut st = settings(950 + s + if mis { 100 } else { 0 });
        st.bootstrap = 20_000;
        st.chains = 64;
        st.mutations_per_pixel = Some(512);
        st.normalization = Normalization::Bootstrap;
        st.mis_large_steps = mis;
        run(render_family(
            &scene,
            depths(&scene),
            &st,
            &stop,
            &NoMltObserver,
        ))
    };
    let plain: Vec<[f64; 3]> = (0..6).map(|s| run_with(false, s)).collect();
    let mis: Vec<[f64; 3]> = (0..6).map(|s| run_with(true, s)).collect();
    let (ma, sa) = mean_se(&plain);
    let (mb, sb) = mean_se(&mis);
    eprintln!("plain {ma:?} ± {sa:?}\nmis {mb:?} ± {sb:?}");
    for c in 0..3 {
        let sigma = (sa[c] * sa[c] + sb[c] * sb[c]).sqrt();
        assert!((ma[c] - mb[c]).abs() < 4.0 * sigma, "channel {c}");
    }
}
