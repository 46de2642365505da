//! The single-technique entry point that multiplexed MLT uses: choosing one
//! technique `(s, t)` of a path depth uniformly, generating subpaths of
//! exactly those lengths (no Russian roulette) and scaling the connection by
//! the number of techniques must estimate the same image mean as all
//! techniques of that depth from [`Bdpt::sample_all`] (Hachisuka et al.
//! 2014, eq. for the multiplexed estimator).
//!
//! Each estimator is an average of N independent per-sample values (the
//! image-mean contribution of one sample: camera samples and splats both
//! count `l / (pixels · N)`), so its standard error is sd/√N; the two must
//! agree within 4 combined standard errors, and that bound must be below 3%
//! of the mean so the test can see a wrong scale such as a missing factor
//! `n_strategies`.

use glam::Vec2;
use mcmc_render::integrators::bdpt::{
    Bdpt, MisHeuristic, SubpathBuffers, connect, generate_camera_subpath, generate_light_subpath,
};
use mcmc_render::sampling::{IndependentSource, RandomSource, Stream};
use mcmc_render::scene::Scene;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::path::Path;

fn scene() -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box.xml");
    let text = std::fs::read_to_string(path)
        .expect("scene file")
        .replace(
            r#"<default name="width" value="256"/>"#,
            r#"<default name="width" value="32"/>"#,
        )
        .replace(
            r#"<default name="height" value="256"/>"#,
            r#"<default name="height" value="32"/>"#,
        );
    Scene::load_str(&text, Path::new("cornell.xml"), Path::new(".")).expect("scene loads")
}

/// Mean and standard error of `n` draws of `f`.
fn mean_se(n: usize, mut f: impl FnMut() -> f64) -> (f64, f64) {
    let (mut s, mut s2) = (0.0, 0.0);
    for _ in 0..n {
        let x = f();
        s += x;
        s2 += x * x;
    }
    let m = s / n as f64;
    let var = (s2 / n as f64 - m * m) * n as f64 / (n - 1) as f64;
    (m, (var / n as f64).sqrt())
}

#[test]
fn one_technique_per_sample_matches_all_techniques_per_depth() {
    let scene = scene();
    let (w, h) = (32.0f32, 32.0f32);
    let bdpt = Bdpt {
        max_depth: 8,
        rr_depth: 5,
        heuristic: MisHeuristic::Power,
    };
    let n = 300_000;
    // Path lengths in vertices s + t = k, i.e. k − 1 segments.
    for k in [3usize, 4, 5] {
        let mut src = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(k as u64));
        let mut bufs = SubpathBuffers::default();
        let (all, se_all) = mean_se(n, || {
            let u = src.next_2d();
            let raster = Vec2::new(u.0 * w, u.1 * h);
            let mut sum = 0.0f64;
            bdpt.sample_all(&scene, raster, &mut src, &mut bufs, |c| {
                if c.s + c.t == k {
                    sum += c.l.g as f64;
                }
            });
            sum
        });
        let mut src = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(100 + k as u64));
        let (one, se_one) = mean_se(n, || {
            src.set_stream(Stream::Camera);
            let n_strategies = k;
            let s = ((src.next_1d() * n_strategies as f32) as usize).min(n_strategies - 1);
            let t = k - s;
            if s == 1 && t == 1 {
                return 0.0;
            }
            let u = src.next_2d();
            let raster = Vec2::new(u.0 * w, u.1 * h);
            if generate_camera_subpath(&scene, raster, &mut src, t, None, &mut bufs.camera) != t {
                return 0.0;
            }
            src.set_stream(Stream::Light);
            if generate_light_subpath(&scene, &mut src, s, None, &mut bufs.light) != s {
                return 0.0;
            }
            src.set_stream(Stream::Connection);
            connect(
                &scene,
                &bufs.camera,
                &bufs.light,
                s,
                t,
                &mut src,
                bdpt.heuristic,
            )
            .map_or(0.0, |c| c.l.g as f64 * n_strategies as f64)
        });
        eprintln!("k {k}: all {all} ± {se_all}, one technique {one} ± {se_one}");
        let sigma = (se_all * se_all + se_one * se_one).sqrt();
        assert!(
            (all - one).abs() < 4.0 * sigma,
            "k {k}: {all} vs {one} (σ {sigma})"
        );
        assert!(
            4.0 * sigma < 0.03 * all,
            "k {k}: noise too large (σ {sigma})"
        );
    }
}
