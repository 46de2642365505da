//! relMSE against a long reference falls as expected with the budget, for
//! every integrator: PT, LT, BDPT, PSSMLT (over PT), MMLT, RELT and path-space
//! MLT, on the repo's
//! Cornell box (32×32, `max_depth` 5, camera tilted down as in
//! `agree_mlt.rs`).
//!
//! # What is expected
//!
//! For an unbiased estimator `X_N` with a budget of `N` samples (or
//! mutations, with the bootstrap scaled alongside), and a reference `R`
//! independent of it, with fixed per-pixel weights `w` (the relMSE of
//! `mcmc-render compare` with the reference's luminance in the weights):
//!
//!   `E[relMSE(X_N, R)] = mean_p w_p (Var X_N,p + Var R_p)`.
//!
//! Independent-sample estimators have `Var X_N = v/N`, so after
//! subtracting the reference's share the ratio between budgets `N` and
//! `4N` is 4. For the Markov-chain estimators (fixed number of chains,
//! each 4× longer; stationary starts from the bootstrap, so no start-up
//! bias) the asymptotic variance is `τ v/N` too; a ratio near 2 would mean
//! a `1/√N` rate, below 4 a not-yet-asymptotic or biased estimator.
//!
//! The reference is PT at 2048 spp in two independent halves `R1, R2`;
//! `E[relMSE(R1, R2)] = 4 mean_p w_p Var R_p`, which gives the share to
//! subtract (≈ 1% of the smallest relMSE here).
//!
//! # Tolerance
//!
//! `K` replicates at each budget give the means `ē_N, ē_4N` and their
//! standard errors (spread over replicates). The ratio
//! `ρ = (ē_N − v̂_R)/(ē_4N − v̂_R)` has, by the delta method for
//! independent numerator and denominator, relative standard error
//! `√((se_N/d_N)² + (se_4N/d_4N)²)`. A test passes when `|ρ − 4| < t se_ρ`,
//! with `t` the Student-t quantile for a two-sided false-alarm rate of 1e-3
//! on `K − 1` degrees of freedom, and it must be able to reject the `1/√N`
//! rate: `t se_ρ < 2`.
//!
//! `K = 16`: the relMSE of one replicate is a skewed quantity (measured
//! spread between replicates 15–20% for PT at 16×16), and with 8
//! replicates its standard error was underestimated badly enough to put
//! PT's ratio 7 "standard errors" from 4 (2.95 ± 0.15), while 32
//! replicates at 4, 16 and 64 spp gave relMSE × spp = 3.04e-2, 3.12e-2,
//! 2.96e-2 (± 4%). 32×32 pixels halve the spread of 16×16.
//!
//! The Markov chains are long enough to be near the asymptote (≥ 512
//! mutations per chain at `N`): with chains as short as their
//! autocorrelation time the variance of a chain's mean is below `τ v/n`,
//! and the ratio falls short of 4 (measured: MMLT with 256 mutations per
//! chain gave 3.0 ± 0.3).

mod common;

use common::{
    bdpt_of, lt_of, luminance, mean_se1, mmlt_depths, pixel_mean, pt_of, rel_mse_weighted,
    rel_weights, render_image, repo_scene_tilted,
};
use mcmc_render::color::Rgb;
use mcmc_render::integrators::erpt::Erpt;
use mcmc_render::integrators::mept::Mept;
use mcmc_render::integrators::mlt::Mlt;
use mcmc_render::integrators::mmlt::render_family;
use mcmc_render::integrators::pssmlt::render_pssmlt;
use mcmc_render::integrators::registry::IntegratorSettings;
use mcmc_render::integrators::relt::Relt;
use mcmc_render::integrators::{Integrator, RunSettings};
use mcmc_render::markov::Normalization;
use mcmc_render::observer::NoObserver;
use mcmc_render::pss::PssmltSettings;
use mcmc_render::scene::Scene;
use statrs::distribution::{ContinuousCDF, StudentsT};
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

const K: u64 = 16;

/// The scene and the reference (luminance of the two halves, weights, and
/// the reference's relMSE share `v̂_R`).
struct Reference {
    scene: Scene,
    mean: Vec<f64>,
    weights: Vec<f64>,
    share: f64,
}

fn reference() -> &'static Reference {
    static REF: OnceLock<Reference> = OnceLock::new();
    REF.get_or_init(|| {
        let scene = repo_scene_tilted("cornell-box.xml", 32, 5);
        let halves: Vec<Vec<f64>> = [90_001, 90_002]
            .iter()
            .map(|&seed| luminance(&render_image(&scene, &pt_of(&scene), 1024, seed)))
            .collect();
        let mean = pixel_mean(&halves);
        let weights = rel_weights(&mean);
        let share = rel_mse_weighted(&halves[0], &halves[1], &weights, None) / 4.0;
        Reference {
            scene,
            mean,
            weights,
            share,
        }
    })
}

/// Checks the ratio of relMSE at budgets `N` and `4N` (see the module
/// comment); `render(budget, seed)` renders one replicate with `budget`
/// = 1 or 4.
fn check_rate(what: &str, render: impl Fn(u64, u64) -> Vec<Rgb>) {
    let r = reference();
    let rel = |budget: u64, seed0: u64| -> Vec<f64> {
        (0..K)
            .map(|s| {
                let img = luminance(&render(budget, seed0 + s));
                rel_mse_weighted(&img, &r.mean, &r.weights, None)
            })
            .collect()
    };
    let (e1, s1) = mean_se1(&rel(1, 100));
    let (e4, s4) = mean_se1(&rel(4, 200));
    let (d1, d4) = (e1 - r.share, e4 - r.share);
    let ratio = d1 / d4;
    let se = ratio * ((s1 / d1).powi(2) + (s4 / d4).powi(2)).sqrt();
    let t = StudentsT::new(0.0, 1.0, (K - 1) as f64)
        .expect("t distribution")
        .inverse_cdf(1.0 - 0.5e-3);
    eprintln!(
        "{what}: relMSE {e1:.3e} ± {s1:.1e} at N, {e4:.3e} ± {s4:.1e} at 4N, \
         reference share {:.1e}; ratio {ratio:.2} ± {se:.2}",
        r.share
    );
    assert!(
        (ratio - 4.0).abs() < t * se,
        "{what}: relMSE ratio {ratio} ± {se}, expected 4"
    );
    assert!(
        t * se < 2.0,
        "{what}: ratio too noisy ({se}) to tell 1/N from 1/√N"
    );
}

fn mc(integ: &dyn Integrator, spp: u32) -> impl Fn(u64, u64) -> Vec<Rgb> + '_ {
    move |budget, seed| render_image(&reference().scene, integ, spp * budget as u32, seed)
}

#[test]
fn pt_relmse_falls_as_one_over_n() {
    let pt = pt_of(&reference().scene);
    check_rate("pt", mc(&pt, 4));
}

#[test]
fn lt_relmse_falls_as_one_over_n() {
    let lt = lt_of(&reference().scene);
    check_rate("lt", mc(&lt, 4));
}

#[test]
fn bdpt_relmse_falls_as_one_over_n() {
    let bdpt = bdpt_of(&reference().scene);
    check_rate("bdpt", mc(&bdpt, 2));
}

/// PSSMLT/MMLT with the bootstrap and the mutations scaled by `budget`,
/// 32 chains (each 4× longer at 4N).
fn mlt_settings(budget: u64, seed: u64, bootstrap: usize, mpp: u64) -> PssmltSettings {
    PssmltSettings {
        bootstrap: bootstrap * budget as usize,
        chains: 32,
        mutations_per_pixel: Some(mpp * budget),
        seed,
        normalization: Normalization::Running,
        ..PssmltSettings::default()
    }
}

#[test]
fn pssmlt_relmse_falls_as_one_over_n() {
    let scene = &reference().scene;
    let stop = AtomicBool::new(false);
    check_rate("pssmlt-pt", |budget, seed| {
        let st = mlt_settings(budget, seed, 2000, 16);
        render_pssmlt(scene, pt_of(scene), &st, &stop, &NoObserver)
            .expect("pssmlt runs")
            .image()
    });
}

#[test]
fn mmlt_relmse_falls_as_one_over_n() {
    let scene = &reference().scene;
    let stop = AtomicBool::new(false);
    check_rate("mmlt", |budget, seed| {
        let st = mlt_settings(budget, seed, 1000, 32);
        render_family(scene, mmlt_depths(scene), &st, &stop, &NoObserver)
            .expect("mmlt runs")
            .image()
    });
}

#[test]
fn mlt_relmse_falls_as_one_over_n() {
    // Path-space MLT (bidirectional mutation): 32 chains, 32 mutations per
    // pixel and 2000 bootstrap candidates at N, both scaled alongside.
    let scene = &reference().scene;
    let stop = AtomicBool::new(false);
    check_rate("mlt", |budget, seed| {
        let mut mlt = Mlt::default();
        mlt.depth.max_depth = 5;
        mlt.chain.bootstrap = 2000 * budget as usize;
        mlt.chain.chains = 32;
        mlt.chain.mutations_per_pixel = Some(32 * budget);
        let run = RunSettings {
            seed,
            ..RunSettings::default()
        };
        mlt.render(scene, &run, &stop, &NoObserver)
            .expect("mlt runs")
            .image
    });
}

#[test]
fn relt_relmse_falls_as_one_over_n() {
    // 8 replica sets of four (32 chains), 16 mutations per pixel per
    // replica at N, the bootstrap scaled alongside.
    let scene = &reference().scene;
    let stop = AtomicBool::new(false);
    check_rate("relt", |budget, seed| {
        let mut relt = Relt::default();
        relt.depth.max_depth = 5;
        relt.chain.bootstrap = 2000 * budget as usize;
        // The Cornell box has no specular vertex, so no draw passes the
        // search's camera-subpath screen and `b_4` rests on the 10 000
        // draws traced in full (`SEARCH_FULL_DRAWS`) whatever the search
        // size: 100 000 gives an estimate of the same variance as the
        // 1 000 000 this test was calibrated with (the default is
        // 4 000 000) for 38% less work (session 14: 4.7 s against 7.6 s
        // of user time per N/4N pair).
        relt.l0_search = 100_000;
        relt.chain.chains = 32;
        relt.chain.mutations_per_pixel = Some(64 * budget);
        let run = RunSettings {
            seed,
            ..RunSettings::default()
        };
        relt.render(scene, &run, &stop, &NoObserver)
            .expect("relt runs")
            .image
    });
}

/// `mept` (`mlt` with the manifold perturbation, the independent proposal
/// and the BDPT start-up, its registry defaults) as `mlt`'s test above:
/// 32 chains, 32 mutations per pixel and 2000 start-up draws at N, both
/// scaled alongside (and the specular-chain pass's spp). Ignored (session 13: the default suite's time is
/// spent); `cargo test -p mcmc-render --test agree_convergence --
/// --ignored mept_ --nocapture`. Measured once (session 13, 116 s with
/// `erpt`'s at load ≈ 18): relMSE 2.241e-2 ± 8.7e-4 at N, 5.599e-3 ±
/// 1.9e-4 at 4N, ratio 4.01 ± 0.21 (passed).
#[test]
#[ignore]
fn mept_relmse_falls_as_one_over_n() {
    let scene = &reference().scene;
    let stop = AtomicBool::new(false);
    check_rate("mept", |budget, seed| {
        let mut mept = Mept::default();
        mept.mlt.depth.max_depth = 5;
        mept.mlt.chain.bootstrap = 2000 * budget as usize;
        mept.mlt.chain.chains = 32;
        mept.mlt.chain.mutations_per_pixel = Some(32 * budget);
        // The specular-chain pass (the emitter seen directly) is scaled
        // too, or its fixed variance would flatten the rate.
        mept.mlt.specular_samples = 16 * budget as i64;
        let run = RunSettings {
            seed,
            ..RunSettings::default()
        };
        mept.render(scene, &run, &stop, &NoObserver)
            .expect("mept runs")
            .image
    });
}

/// `erpt` at Mitsuba's defaults: 2 passes (camera samples per pixel) at N,
/// 8 at 4N; the passes are independent, so the rate is exactly 1/N if
/// each pass is unbiased. Ignored like `mept`'s; measured once (session
/// 13): relMSE 2.248e-3 ± 1.0e-4 at N, 5.969e-4 ± 1.9e-5 at 4N, ratio
/// 3.83 ± 0.21 (passed).
#[test]
#[ignore]
fn erpt_relmse_falls_as_one_over_n() {
    let scene = &reference().scene;
    let stop = AtomicBool::new(false);
    check_rate("erpt", |budget, seed| {
        let mut erpt = Erpt::default();
        erpt.depth.max_depth = 5;
        erpt.luminance_samples = 4000;
        let run = RunSettings {
            spp: Some(2 * budget as u32),
            seed,
            ..RunSettings::default()
        };
        erpt.render(scene, &run, &stop, &NoObserver)
            .expect("erpt runs")
            .image
    });
}
