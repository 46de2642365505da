//! relMSE against a long reference falls as expected with the budget, for
//! every integrator: PT, LT, BDPT, PSSMLT (over PT), MMLT, RELT, path-space
//! MLT and MCMC over VCM (`mcmc-vcm`, 16×16 by default, against `vcm` at
//! the same fixed radius: see `mcmc_vcm_rate`), on the repo's
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
use mcmc_render::integrators::mcmc_vcm::McmcVcmSettings;
use mcmc_render::integrators::mept::Mept;
use mcmc_render::integrators::mlt::Mlt;
use mcmc_render::integrators::mmlt::render_family;
use mcmc_render::integrators::pssmlt::render_pssmlt;
use mcmc_render::integrators::registry::IntegratorSettings;
use mcmc_render::integrators::relt::Relt;
use mcmc_render::integrators::vcm::VcmSettings;
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

impl Reference {
    /// The reference of `scene` from two independent luminance images.
    fn from_halves(scene: Scene, halves: &[Vec<f64>; 2]) -> Self {
        let mean = pixel_mean(halves);
        let weights = rel_weights(&mean);
        let share = rel_mse_weighted(&halves[0], &halves[1], &weights, None) / 4.0;
        Reference {
            scene,
            mean,
            weights,
            share,
        }
    }
}

fn reference() -> &'static Reference {
    static REF: OnceLock<Reference> = OnceLock::new();
    REF.get_or_init(|| {
        let scene = repo_scene_tilted("cornell-box.xml", 32, 5);
        let halves = [90_001, 90_002]
            .map(|seed| luminance(&render_image(&scene, &pt_of(&scene), 1024, seed)));
        Reference::from_halves(scene, &halves)
    })
}

/// `K` replicates' luminance images at `budget` (1 or 4), seeds from
/// `seed0`.
fn replicates(render: &impl Fn(u64, u64) -> Vec<Rgb>, budget: u64, seed0: u64) -> Vec<Vec<f64>> {
    (0..K)
        .map(|s| luminance(&render(budget, seed0 + s)))
        .collect()
}

/// The ratio of relMSE at budgets `N` and `4N` against a reference, with
/// its standard error and the Student-t factor (see the module comment).
struct Rate {
    e1: f64,
    s1: f64,
    e4: f64,
    s4: f64,
    share: f64,
    ratio: f64,
    se: f64,
    t: f64,
}

impl Rate {
    /// The rate of the replicates `at_n`, `at_4n` (luminance images), each
    /// scaled by `scale` (1 for the test itself; a control scales them).
    fn new(r: &Reference, at_n: &[Vec<f64>], at_4n: &[Vec<f64>], scale: f64) -> Self {
        let rel = |images: &[Vec<f64>]| -> Vec<f64> {
            images
                .iter()
                .map(|img| {
                    let scaled: Vec<f64> = img.iter().map(|v| v * scale).collect();
                    rel_mse_weighted(&scaled, &r.mean, &r.weights, None)
                })
                .collect()
        };
        let (e1, s1) = mean_se1(&rel(at_n));
        let (e4, s4) = mean_se1(&rel(at_4n));
        let (d1, d4) = (e1 - r.share, e4 - r.share);
        let ratio = d1 / d4;
        let se = ratio * ((s1 / d1).powi(2) + (s4 / d4).powi(2)).sqrt();
        let t = StudentsT::new(0.0, 1.0, (K - 1) as f64)
            .expect("t distribution")
            .inverse_cdf(1.0 - 0.5e-3);
        Rate {
            e1,
            s1,
            e4,
            s4,
            share: r.share,
            ratio,
            se,
            t,
        }
    }

    /// The ratio is consistent with 4 (a `1/N` rate).
    fn is_one_over_n(&self) -> bool {
        (self.ratio - 4.0).abs() < self.t * self.se
    }

    /// The test could tell `1/N` from `1/√N`.
    fn resolves(&self) -> bool {
        self.t * self.se < 2.0
    }

    fn report(&self, what: &str) {
        eprintln!(
            "{what}: relMSE {:.3e} ± {:.1e} at N, {:.3e} ± {:.1e} at 4N, \
             reference share {:.1e}; ratio {:.2} ± {:.2} (t = {:.2})",
            self.e1, self.s1, self.e4, self.s4, self.share, self.ratio, self.se, self.t
        );
    }

    /// Asserts the `1/N` rate, resolved.
    fn check(&self, what: &str) {
        self.report(what);
        assert!(
            self.is_one_over_n(),
            "{what}: relMSE ratio {} ± {}, expected 4",
            self.ratio,
            self.se
        );
        assert!(
            self.resolves(),
            "{what}: ratio too noisy ({}) to tell 1/N from 1/√N",
            self.se
        );
    }
}

/// Checks the ratio of relMSE at budgets `N` and `4N` against `r` (see the
/// module comment); `render(budget, seed)` renders one replicate with
/// `budget` = 1 or 4. Returns the replicates' luminance images at `N` and
/// `4N`, for controls.
fn check_rate_against(
    r: &Reference,
    what: &str,
    render: impl Fn(u64, u64) -> Vec<Rgb>,
) -> [Vec<Vec<f64>>; 2] {
    let at_n = replicates(&render, 1, 100);
    let at_4n = replicates(&render, 4, 200);
    Rate::new(r, &at_n, &at_4n, 1.0).check(what);
    [at_n, at_4n]
}

/// [`check_rate_against`] the PT reference of the tilted Cornell box.
fn check_rate(what: &str, render: impl Fn(u64, u64) -> Vec<Rgb>) {
    check_rate_against(reference(), what, render);
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

/// The factor of `mcmc-vcm`'s control: its replicates scaled by it must
/// fail the rate test. A scale `s` adds the fixed bias
/// `(s − 1)² mean_p w_p R_p²` to the relMSE at both budgets, so the ratio
/// falls towards 1 once that bias is comparable to the variance at `4N`.
/// Measured (session 15, 16×16): relMSE 4.07e-3 ± 1.6e-4 at N, 1.05e-3 ±
/// 3.0e-5 at 4N, ratio 3.95 ± 0.19 (t = 4.07, passes); scaled by 1.1,
/// 6.78e-3 and 2.79e-3, ratio 2.44 ± 0.12 (fails by 13 standard errors).
/// The bias of 10% is thus 1.7e-3 (mean_p w_p R_p² ≈ 0.17: most pixels of
/// the tilted box lie near the weights' floor 0.1); a 1% scale would add
/// 1.7e-5, 1.6% of the relMSE at 4N, which this budget cannot resolve
/// (it would need about 100× the work), so the control is a 10% bias.
/// 3.9 s of CPU on 2 threads (6.1 s wall at load 14).
const MCMC_VCM_CONTROL_SCALE: f64 = 1.1;

/// `mcmc-vcm` (both chains, replica exchange, running normalisation) on
/// the tilted Cornell box at `res`², `iterations` iterations at `N`:
/// relMSE against `vcm` at the same fixed radius (0.1, α = 1, the
/// thesis's setting and `mcmc-vcm`'s default) in two halves of
/// `reference_iterations` each. With a fixed radius both converge to the
/// same radius-biased image (`mcmc_vcm.rs`'s agreement test), so the
/// reference is of the estimator's own limit and the merges' bias does not
/// flatten the rate. The chains restart each iteration by importance
/// resampling, so iterations are near-independent and 4× the iterations
/// should give ¼ of the variance; the running normalisation's error falls
/// as 1/iterations too (its squared relative error is inversely
/// proportional to the candidates drawn so far). 1024 restart candidates
/// and 4 chain pairs, as `mcmc_vcm.rs`'s tests.
fn mcmc_vcm_rate(res: u32, iterations: u32, reference_iterations: u32) {
    let scene = repo_scene_tilted("cornell-box.xml", res, 5);
    let mut vcm = VcmSettings {
        radius: Some(0.1),
        alpha: 1.0,
        ..VcmSettings::default()
    };
    vcm.depth.max_depth = i64::from(scene.integrator.max_depth);
    vcm.depth.rr_depth = scene.integrator.rr_depth;
    let run = |spp: u32, seed: u64| RunSettings {
        spp: Some(spp),
        seed,
        ..RunSettings::default()
    };
    let stop = AtomicBool::new(false);
    let halves = [90_003, 90_004].map(|seed| {
        let out = vcm.integrator(&scene).render(
            &scene,
            &run(reference_iterations, seed),
            &stop,
            &NoObserver,
        );
        luminance(&out.image)
    });
    let r = Reference::from_halves(scene, &halves);
    let mcmc = McmcVcmSettings {
        candidates: 1024,
        units: 4,
        vcm,
        ..McmcVcmSettings::default()
    };
    let [at_n, at_4n] = check_rate_against(&r, "mcmc-vcm", |budget, seed| {
        let n = iterations * budget as u32;
        let out = mcmc
            .integrator(&r.scene)
            .render(&r.scene, &run(n, seed), &stop, &NoObserver);
        assert_eq!(out.statistics["iterations"], u64::from(n));
        assert_eq!(out.statistics["nonfinite_samples"], 0);
        out.image
    });
    let control = Rate::new(&r, &at_n, &at_4n, MCMC_VCM_CONTROL_SCALE);
    control.report("mcmc-vcm scaled (control)");
    assert!(
        !control.is_one_over_n(),
        "control: a {MCMC_VCM_CONTROL_SCALE}× image passed the 1/N rate"
    );
}

/// `mcmc-vcm` at 16×16, 8 iterations at `N` (32 at `4N`), reference 2 ×
/// 512 `vcm` iterations; the control must fail.
#[test]
fn mcmc_vcm_relmse_falls_as_one_over_n() {
    mcmc_vcm_rate(16, 8, 512);
}

/// The same at 32×32 (the other tests' size), 16 iterations at `N`,
/// reference 2 × 1024 iterations. Ignored (the default suite's time is
/// spent); `cargo test -p mcmc-render --test agree_convergence --
/// --ignored mcmc_vcm_relmse_at_32 --nocapture`.
#[test]
#[ignore]
fn mcmc_vcm_relmse_at_32_falls_as_one_over_n() {
    mcmc_vcm_rate(32, 16, 1024);
}
