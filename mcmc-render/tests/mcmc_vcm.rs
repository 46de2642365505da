//! MCMC over VCM's light subpaths (`mcmc-vcm`) against `vcm`, its targets,
//! and its determinism.
//!
//! # Agreement tolerances
//!
//! As in `vcm.rs` and `agree_mlt.rs`: each estimator runs as `K` = 24
//! independent replicates (fixed seeds); the standard error of an image
//! mean is sd(replicate means)/√K (Student's t, 23 degrees of freedom), `σ`
//! that of the difference of the two means. A channel passes when the
//! difference lies within 4σ (false-alarm rate ≈ 5e-4 per channel) and
//! within 1%, and the budget must make 5σ < 1%; the control (the same
//! estimates ×1.01) must fail.
//!
//! # Scene
//!
//! The repo's Cornell box at 64×64 (16 iterations; 48 for `mcmc-vcm`), `max_depth` 5, camera
//! tilted so that the emitter is out of view (`common::repo_scene_tilted`),
//! both integrators with a fixed radius 0.1 (α = 1, the thesis's setting;
//! merging carries about 3% of the energy).
//!
//! Why a fixed radius: the running normalisation of Eq. 6.4 averages
//! `b_c` over the whole render, but with radius reduction the targets
//! change from iteration to iteration (η = π r² N moves energy between the
//! path-tracing and the light-subpath techniques, so `b_con` drifts), and
//! the render-wide mean then biases every iteration: measured +0.6% to +1%
//! at α = 0.75 (ignored test `running_normalisation_needs_a_fixed_radius`),
//! while `normalisation = iteration` agrees there. `validate` refuses
//! `normalisation = render` with α < 1.

mod common;

use common::{MeanAgreement, image_mean, mean_se, mean_se1, repo_scene_path, repo_scene_tilted};
use mcmc_core::chain::Chain;
use mcmc_core::rng::{ChainRng, child_rng, stream_rng, uniform};
use mcmc_core::sample::Sample;
use mcmc_core::space::TorusPoint;
use mcmc_render::color::Rgb;
use mcmc_render::integrators::mcmc_vcm::{
    CameraPass, ChainKind, ConEstimate, Iteration, LightChains, LightContribution, LightTarget,
    McmcVcmSettings, NormalisationScope, Restart, RestartPool, light_contribution,
};
use mcmc_render::integrators::vcm::{VcmMode, VcmSettings};
use mcmc_render::integrators::{Rendered, RunSettings, registry};
use mcmc_render::observer::NoObserver;
use mcmc_render::pss::PssSource;
use mcmc_render::scene::Scene;
use std::collections::HashMap;
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

const RES: u32 = 64;
const DEPTH: u32 = 5;
const REPS: u64 = 24;
const ITERATIONS: u32 = 16;
/// Iterations of the `mcmc-vcm` replicates: its image mean is about twice
/// as noisy per iteration as `vcm`'s (correlated light subpaths), so it
/// runs three times as long for 5σ < 1%.
const MCMC_ITERATIONS: u32 = 48;

fn cornell() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-box.xml", RES, DEPTH))
}

/// The 16×16 Cornell box (256 camera subpaths per iteration).
fn cornell_16() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-box.xml", 16, DEPTH))
}

/// VCM settings with the scene's depth, radius 0.1 and α = 1 (a fixed
/// radius, as the thesis runs).
fn vcm_settings(scene: &Scene) -> VcmSettings {
    let mut s = VcmSettings {
        mode: VcmMode::Vcm,
        radius: Some(0.1),
        alpha: 1.0,
        ..VcmSettings::default()
    };
    s.depth.max_depth = i64::from(scene.integrator.max_depth);
    s.depth.rr_depth = scene.integrator.rr_depth;
    s
}

/// `mcmc-vcm` with `vcm_settings`, `chains`, 1024 restart candidates
/// (four per light subpath of an iteration at 16×16) and 4 chain pairs.
fn settings(scene: &Scene, chains: LightChains) -> McmcVcmSettings {
    McmcVcmSettings {
        light_chains: chains,
        candidates: 1024,
        units: 4,
        vcm: vcm_settings(scene),
        ..McmcVcmSettings::default()
    }
}

/// One run of `iterations` iterations.
fn run(scene: &Scene, s: &McmcVcmSettings, iterations: u32, seed: u64) -> Rendered {
    let run = RunSettings {
        spp: Some(iterations),
        seed,
        ..RunSettings::default()
    };
    let out = s
        .integrator(scene)
        .render(scene, &run, &AtomicBool::new(false), &NoObserver);
    assert_eq!(out.statistics["iterations"], u64::from(iterations));
    assert_eq!(out.statistics["nonfinite_samples"], 0);
    out
}

/// Image means of `REPS` runs of `iterations`.
fn reps(scene: &Scene, s: &McmcVcmSettings, iterations: u32, seed0: u64) -> Vec<[f64; 3]> {
    (0..REPS)
        .map(|k| {
            let out = run(scene, s, iterations, seed0 + k);
            if k == 0 {
                eprintln!("{}", serde_json::Value::Object(out.statistics.clone()));
            }
            image_mean(&out.image)
        })
        .collect()
}

/// `vcm` replicates of `scene` (`iterations` each).
fn vcm_reps(scene: &Scene, iterations: u32, seed0: u64) -> Vec<[f64; 3]> {
    let s = vcm_settings(scene);
    (0..REPS)
        .map(|k| {
            let run = RunSettings {
                spp: Some(iterations),
                seed: seed0 + k,
                ..RunSettings::default()
            };
            let out = s
                .integrator(scene)
                .render(scene, &run, &AtomicBool::new(false), &NoObserver);
            image_mean(&out.image)
        })
        .collect()
}

fn cornell_vcm() -> &'static [[f64; 3]] {
    static R: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    R.get_or_init(|| vcm_reps(cornell(), ITERATIONS, 100))
}

fn cornell_mcmc_vcm() -> &'static [[f64; 3]] {
    static R: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    R.get_or_init(|| {
        reps(
            cornell(),
            &settings(cornell(), LightChains::Both),
            MCMC_ITERATIONS,
            200,
        )
    })
}

/// Asserts agreement within 4σ and 1%, with 5σ < 1%.
fn check(what: &str, reference: &[[f64; 3]], test: &[[f64; 3]]) {
    let a = MeanAgreement::new(reference, test);
    eprintln!("{what}: rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "{what} disagrees with vcm: {a:?}"
    );
    assert!(
        a.resolves(5.0, 0.01),
        "{what}: noise too large for 1%: {a:?}"
    );
}

/// The control of an agreement: `test`'s estimates biased by +1% must
/// fail the same 4σ-and-1% check against `reference`.
fn assert_one_percent_bias_detected(reference: &[[f64; 3]], test: &[[f64; 3]]) {
    let biased: Vec<[f64; 3]> = test.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let a = MeanAgreement::new(reference, &biased);
    assert!(
        !a.failures(4.0, 0.01).is_empty(),
        "1% bias not detected: {a:?}"
    );
}

/// `mcmc-vcm` (both chains, replica exchange) agrees with `vcm`.
#[test]
fn mcmc_vcm_agrees_with_vcm_on_the_cornell_box() {
    check("mcmc-vcm", cornell_vcm(), cornell_mcmc_vcm());
}

/// The control: the same estimates biased by +1% must fail.
#[test]
fn a_one_percent_bias_is_detected() {
    assert_one_percent_bias_detected(cornell_vcm(), cornell_mcmc_vcm());
}

/// `light_subpaths` sets an iteration's chain steps (and exchange
/// attempts) over all pairs: `light_subpaths × pixels`, rounded — 256
/// with the default and 640 with 2.5 on 16×16 — and a value outside
/// (0, 1024] is one line of error, not a run. With independent light
/// subpaths the MIS scale is `vcm`'s `k = L/N`.
#[test]
fn light_subpaths_set_the_chain_steps_of_an_iteration() {
    let scene = cornell_16();
    for (light_subpaths, per_iteration) in [(1.0, 256), (2.5, 640)] {
        let mut s = settings(scene, LightChains::Both);
        s.vcm.light_subpaths = light_subpaths;
        let out = run(scene, &s, 2, 11);
        let steps = |c: &str| out.statistics["chains"][c]["steps"].as_u64().expect(c);
        assert_eq!(
            steps("contribution") + steps("visibility"),
            2 * per_iteration
        );
        assert_eq!(out.statistics["exchange_attempts"], 2 * per_iteration);
        // Independent light subpaths are `vcm`'s estimator, MIS scale
        // k = L/N included (it was 1 whatever L until session 28).
        let mut s = settings(scene, LightChains::Independent);
        s.vcm.light_subpaths = light_subpaths;
        let out = run(scene, &s, 2, 11);
        assert_eq!(
            out.statistics["light_density_scale"],
            per_iteration as f64 / 256.0
        );
    }
    for bad in ["0", "-1", "nan", "inf", "1025"] {
        let set = [("light_subpaths".to_string(), bad.to_string())];
        let e = registry::configure(None, Some("mcmc-vcm"), &set).err();
        assert!(e.is_some_and(|e| !e.contains('\n')), "light_subpaths={bad}");
    }
}

/// `light_subpaths = 2` (twice the chain steps per iteration; the
/// estimator's denominators `n_c` and the MIS scale `k` count them) agrees
/// with `vcm` as the default does: 24 replicates of 24 iterations, the
/// light subpaths of the default's 48 (so the same 5σ < 1% budget, as
/// measured for the default), within 4σ and 1%; control: the same
/// estimates ×1.01 must fail. Ignored (about the default agreement's
/// cost): `cargo test --profile test -p mcmc-render --test mcmc_vcm --
/// --ignored more_light_subpaths`.
#[test]
#[ignore]
fn more_light_subpaths_per_iteration_agree_with_vcm() {
    assert_light_subpaths_agree_with_vcm(2.0, MCMC_ITERATIONS / 2, 400);
}

/// `light_subpaths = 4` (the setting that gains 1.5–2.1× at equal time on
/// the interior lit through a window, and loses 1.55–1.83× on the plain
/// Cornell box: docs/vcm.md, Sessions 25 and 30) agrees with `vcm`: 24
/// replicates of 16 iterations, 64 light subpaths per pixel against the
/// default test's 48 (session 25's command-line run of 72 replicates of 12
/// iterations read σ 0.11% per channel, so 24 of 16 give about 0.17%: 5σ
/// < 1%), within 4σ and 1%; control: the same estimates ×1.01 must fail.
/// Session 30: −0.19%, −0.21%, −0.31% (σ 0.15%, 0.15%, 0.18%), 35 s of
/// CPU with `vcm`'s replicates, which the default agreement test shares.
#[test]
fn four_light_subpaths_per_iteration_agree_with_vcm() {
    assert_light_subpaths_agree_with_vcm(4.0, 16, 600);
}

/// `mcmc-vcm` (both chains) with `light_subpaths` per pixel, `REPS`
/// replicates of `iterations` from seed `seed0`, agrees with `vcm` (4σ and
/// 1%, 5σ < 1%), and the same estimates ×1.01 are rejected.
fn assert_light_subpaths_agree_with_vcm(light_subpaths: f64, iterations: u32, seed0: u64) {
    let mut s = settings(cornell(), LightChains::Both);
    s.vcm.light_subpaths = light_subpaths;
    let out = reps(cornell(), &s, iterations, seed0);
    let what = format!("mcmc-vcm light_subpaths={light_subpaths}");
    check(&what, cornell_vcm(), &out);
    assert_one_percent_bias_detected(cornell_vcm(), &out);
}

/// The light-subpath contribution `C^Ω` pinned: `N` independent light
/// subpaths per iteration, each adding its `C^Ω` once (no chains), give
/// `vcm`'s image — so `E[C^Ω]` summed over `N` subpaths is `vcm`'s
/// light-side contribution (the path-tracing side is `vcm`'s own code).
#[test]
fn independent_light_subpaths_reproduce_vcm() {
    let out = reps(
        cornell(),
        &settings(cornell(), LightChains::Independent),
        ITERATIONS,
        300,
    );
    check("mcmc-vcm light_chains=independent", cornell_vcm(), &out);
}

/// `b_con` from the visibility chain (`b_vis · E_vis[lum C^Ω]`) and from
/// the independent light subpaths (Eq. 6.4) estimate the same constant:
/// one 16×16 run of 256 iterations reports both with their standard
/// errors (iteration batches, 255 dof); their difference must lie within
/// 4σ of the combined error `σ = √(se_d² + se_v²)`, and the budget must
/// resolve 5%: 5σ < 5% of `b_con`. Control: the visibility estimate ×1.05
/// must fail (a 5% bias, which 5σ < 5% makes detectable). Budget: 64
/// iterations gave σ = 1.7% of `b_con` (5σ = 8.3%, session 14), so 256
/// give 0.8% (5σ = 4.0%); under 1 s.
#[test]
fn the_visibility_chain_estimates_b_con() {
    let scene = cornell_16();
    let mut s = settings(scene, LightChains::Both);
    s.con_estimate = ConEstimate::Combined;
    let out = run(scene, &s, 256, 700);
    let stat = |k: &str| out.statistics[k].as_f64().expect(k);
    let (d, se_d) = (stat("b_con_direct"), stat("b_con_direct_standard_error"));
    let (v, se_v) = (
        stat("b_con_visibility"),
        stat("b_con_visibility_standard_error"),
    );
    let sigma = se_d.hypot(se_v);
    eprintln!("b_con direct {d} ± {se_d}, visibility {v} ± {se_v}");
    assert!(
        5.0 * sigma < 0.05 * d,
        "noise too large: σ {sigma}, b_con {d}"
    );
    assert!(
        (v - d).abs() < 4.0 * sigma,
        "visibility {v} vs direct {d}, σ {sigma}"
    );
    assert!((1.05 * v - d).abs() > 4.0 * sigma, "5% bias not detected");
    // The combined estimate lies between the two, closer to the one of
    // smaller error.
    let c = stat("b_con");
    assert!(c >= d.min(v) && c <= d.max(v));
    assert_eq!((c - d).abs() < (c - v).abs(), se_d < se_v);
}

/// Per iteration `i` of [`transfer_estimates`]: `b_con(k)` by Eq. 6.4
/// (`direct`), `b_con(1)` (`unscaled`), and the camera pass's transfer
/// per camera sample `Δ`.
struct TransferEstimates {
    direct: Vec<f64>,
    unscaled: Vec<f64>,
    transfer: Vec<f64>,
}

/// Iterations and light subpaths per iteration of [`transfer_estimates`].
const TRANSFER_ITERATIONS: u64 = 64;
const TRANSFER_SUBPATHS: usize = 1024;

/// The two estimates of `b_con(k)` behind `con_estimate = direct` and
/// `transfer` on the 16×16 Cornell box in `mode = bpt` (no merging, so
/// the identity checked below is exact) with the light-subpath densities
/// scaled by `k = 4`: `TRANSFER_ITERATIONS` independent camera passes,
/// each with `TRANSFER_SUBPATHS` independent light subpaths evaluated
/// with `k`'s and with `k = 1`'s weights (the same subpaths, the camera
/// subpaths taken in turn).
fn transfer_estimates() -> TransferEstimates {
    let scene = cornell_16();
    let mut s = settings(scene, LightChains::Both);
    s.vcm.mode = VcmMode::Bpt;
    s.con_estimate = ConEstimate::Transfer;
    let integrator = s.integrator(scene);
    let (k, radius) = (4.0, 0.1);
    let mut pass = CameraPass::default();
    let mut c = LightContribution::default();
    let mut out = TransferEstimates {
        direct: Vec::new(),
        unscaled: Vec::new(),
        transfer: Vec::new(),
    };
    for i in 0..TRANSFER_ITERATIONS {
        integrator.camera_pass(scene, radius, k, 31, i, &mut pass);
        let n = pass.cameras.len();
        let scaled = Iteration::new(&integrator.vcm, &pass.cameras, radius, k);
        let unscaled = Iteration::new(&integrator.vcm, &pass.cameras, radius, 1.0);
        let mut rng = stream_rng(32, i);
        let (mut direct, mut one) = (0.0, 0.0);
        for j in 0..TRANSFER_SUBPATHS {
            let point = TorusPoint::fresh(child_rng(&mut rng));
            light_contribution(
                scene,
                &scaled,
                &mut PssSource::new(&point, 1),
                j % n,
                &mut c,
            );
            assert!(c.finite);
            direct += c.luminance;
            light_contribution(
                scene,
                &unscaled,
                &mut PssSource::new(&point, 1),
                j % n,
                &mut c,
            );
            one += c.luminance;
        }
        out.direct.push(direct / TRANSFER_SUBPATHS as f64);
        out.unscaled.push(one / TRANSFER_SUBPATHS as f64);
        out.transfer.push(pass.transfer / n as f64);
    }
    out
}

/// `con_estimate = transfer` rests on `b_con(k) = b_con(1) + Δ`: the MIS
/// weights sum to one over all techniques for any scale `k` of the
/// light-subpath densities, so the energy the light subpaths gain is
/// what path tracing loses (module docs of `mcmc_vcm`). Per iteration `i`
/// (independent camera passes and light subpaths) `x_i = direct_i −
/// (unscaled_i + Δ_i)` has mean 0; over the 64 iterations its mean must
/// lie within 4σ, σ = sd(x)/√64 (Student's t, 63 dof: P(|t| > 4) ≈ 2e-4),
/// and the budget must resolve 10% of the transfer (5σ < 0.1 mean Δ; a
/// first run with 24 × 2048 subpaths gave σ = 1.8% of Δ, so 64 × 1024
/// give about 1.4%, 5σ ≈ 7%; 0.6 s there). Control: `Δ` scaled by 1.1
/// (a 10% error in the camera side) must fail. Measured with `k = 4` on
/// this box, `transfer`'s per-iteration variance was 1.2× `direct`'s
/// (24 iterations): where light subpaths reach the camera easily the
/// camera side's noise is not smaller; on an interior lit through a
/// window it is (docs/vcm.md, session 16).
#[test]
fn the_camera_transfer_is_the_light_side_shift() {
    let e = transfer_estimates();
    let x = |scale: f64| -> Vec<f64> {
        (0..e.direct.len())
            .map(|i| e.direct[i] - e.unscaled[i] - scale * e.transfer[i])
            .collect()
    };
    let (delta, _) = mean_se1(&e.transfer);
    let (m, se) = mean_se1(&x(1.0));
    let (direct, _) = mean_se1(&e.direct);
    eprintln!("b_con(k) {direct}, transfer {delta}, direct − (unscaled + transfer) {m} ± {se}");
    assert!(delta > 0.1 * direct, "k moves little energy: {delta}");
    assert!(5.0 * se < 0.1 * delta, "noise too large: σ {se}, Δ {delta}");
    assert!(m.abs() < 4.0 * se, "{m} ± {se}");
    let (mb, seb) = mean_se1(&x(1.1));
    assert!(
        mb.abs() > 4.0 * seb,
        "a 10% error in Δ not detected: {mb} ± {seb}"
    );
}

/// `mcmc-vcm` with `con_estimate = direct`, `visibility` and `combined`
/// agrees with `vcm` (same replicates and tolerances as the default
/// estimator's (`transfer`) test;
/// control: the `combined` estimates ×1.01 must fail). About 5 minutes:
/// `cargo test -p mcmc-render --test mcmc_vcm -- --ignored con_estimates`.
#[test]
#[ignore]
fn con_estimates_agree_with_vcm_on_the_cornell_box() {
    let mut s = settings(cornell(), LightChains::Both);
    s.con_estimate = ConEstimate::Direct;
    check(
        "con_estimate=direct",
        cornell_vcm(),
        &reps(cornell(), &s, MCMC_ITERATIONS, 1000),
    );
    s.con_estimate = ConEstimate::Visibility;
    check(
        "con_estimate=visibility",
        cornell_vcm(),
        &reps(cornell(), &s, MCMC_ITERATIONS, 800),
    );
    s.con_estimate = ConEstimate::Combined;
    let combined = reps(cornell(), &s, MCMC_ITERATIONS, 900);
    check("con_estimate=combined", cornell_vcm(), &combined);
    assert_one_percent_bias_detected(cornell_vcm(), &combined);
}

/// The running normalisation with radius reduction (module docs),
/// measured: at 16×16, 128 iterations, α = 0.75 for both integrators,
/// `normalisation = render` lies more than 4σ above `vcm` while
/// `normalisation = iteration` agrees. About 2 minutes:
/// `cargo test -p mcmc-render --test mcmc_vcm -- --ignored`.
#[test]
#[ignore]
fn running_normalisation_needs_a_fixed_radius() {
    let scene = cornell_16();
    let mut s = settings(scene, LightChains::Both);
    s.con_estimate = ConEstimate::Direct;
    s.vcm.alpha = 0.75;
    let reference: Vec<[f64; 3]> = (0..REPS)
        .map(|k| {
            let run = RunSettings {
                spp: Some(128),
                seed: 400 + k,
                ..RunSettings::default()
            };
            let out =
                s.vcm
                    .integrator(scene)
                    .render(scene, &run, &AtomicBool::new(false), &NoObserver);
            image_mean(&out.image)
        })
        .collect();
    let render = MeanAgreement::new(&reference, &reps(scene, &s, 128, 500));
    eprintln!("render: rel {:?} {render:?}", render.rel());
    assert!(!render.failures(4.0, 0.01).is_empty());
    s.normalisation = NormalisationScope::Iteration;
    check(
        "normalisation=iteration at 16×16",
        &reference,
        &reps(scene, &s, 128, 600),
    );
}

/// Mean and standard error of the mean of `n` values from their sum and
/// sum of squares.
fn mean_se_of_sums(sum: f64, squares: f64, n: f64) -> (f64, f64) {
    let mean = sum / n;
    (mean, ((squares / n - mean * mean) / (n - 1.0)).sqrt())
}

/// The restart pool's picks against values worked by hand: luminances
/// 0, 2, 0, 1, 3 have cumulative sums 0, 2, 2, 3, 6 (mean 1.2) and
/// visible candidates 1, 3, 4.
#[test]
fn the_restart_pool_picks_as_worked_by_hand() {
    let mut pool = RestartPool::default();
    pool.rebuild([0.0, 2.0, 0.0, 1.0, 3.0].into_iter());
    assert!((pool.weight() - 1.2).abs() < 1e-12);
    // ∝ lum: u · 6 = 0.6, 2.4, 5.4 fall in the sums of candidates 1, 3, 4.
    assert_eq!([0.1, 0.4, 0.9].map(|u| pool.contribution(u)), [1, 3, 4]);
    // Uniform among the visible: thirds.
    assert_eq!(
        [0.0, 0.5, 0.99].map(|u| pool.visibility(u, None)),
        [Some(1), Some(3), Some(4)]
    );
    // Among the visible other than 3 (halves), and other than 1.
    assert_eq!(
        [0.0, 0.6].map(|u| pool.visibility(u, Some(3))),
        [Some(1), Some(4)]
    );
    assert_eq!(pool.visibility(0.0, Some(1)), Some(3));
    pool.rebuild([0.0, 5.0].into_iter());
    assert_eq!(pool.visibility(0.5, Some(1)), None);
    assert_eq!(pool.visibility(0.5, None), Some(1));
}

/// `restart = weighted` is importance resampling's proper weighting
/// (module docs of `mcmc_vcm`, "Restarts"), checked on synthetic pools
/// through the integrator's own `RestartPool`: `M` = 8 candidates, each
/// visible with probability 1/4, a visible one of luminance 100 with
/// probability 1/10 and 1 otherwise (a heavy tail, as the scaled MIS
/// gives on the interior). Exact values: `b_con = E[lum] = 0.25 · 10.9 =
/// 2.725`; the contribution target's share of bright states `10/10.9`,
/// the visibility target's `1/10`. With `W` the pool's mean luminance,
/// `x` the contribution chain's pick and `y` the visibility chain's
/// (another visible candidate, or a fresh visible draw when there is
/// none), `E[W 1(x bright)] = b_con · 10/10.9`, `E[W 1(y bright)] =
/// b_con / 10` and `E[W 1(x bright) 1(y bright)] = b_con · 10/10.9 / 10`
/// (the two starts independent under the weighting). Tolerance: 4σ, σ the
/// standard error of the mean over 500 000 pools (normal: the sums are
/// bounded, the count huge); 5σ must lie under 10% of each value.
/// Controls, which must fail at 4σ: the thesis's rule unweighted (the
/// contribution chain's pick alone: its share of bright states is about
/// 0.20 instead of 0.92), and the visibility chain's pick among all the
/// visible candidates, the contribution chain's included (weighted: about
/// 1.27 instead of 0.27, the two starts coinciding). A NumPy model of the
/// same rules (session 18, before this test could be built; 0.4–1.5
/// million pools per seed, five seeds) gave those values, and the weighted
/// means within 1.9σ of the exact ones.
#[test]
fn weighted_restarts_are_properly_weighted() {
    const M: usize = 8;
    const POOLS: usize = 500_000;
    const VISIBLE: f64 = 0.25;
    const BRIGHT: f64 = 0.1;
    const HIGH: f64 = 100.0;
    let b_con = VISIBLE * ((1.0 - BRIGHT) + BRIGHT * HIGH);
    let bright_con = BRIGHT * HIGH / ((1.0 - BRIGHT) + BRIGHT * HIGH);
    let draw = |rng: &mut ChainRng| {
        if uniform(rng) >= VISIBLE {
            0.0
        } else if uniform(rng) < BRIGHT {
            HIGH
        } else {
            1.0
        }
    };
    let mut rng = stream_rng(1800, 0);
    let mut pool = RestartPool::default();
    let mut lum = [0.0; M];
    // Σ and Σ² of W·1(x bright), W·1(y bright), W·1(x, y bright),
    // W·1(y_old bright); and of 1(x bright) over pools with a visible
    // candidate (the unweighted control).
    let (mut sums, mut squares) = ([0.0f64; 4], [0.0f64; 4]);
    let (mut x_bright, mut with_visible) = (0.0f64, 0.0f64);
    for _ in 0..POOLS {
        for l in &mut lum {
            *l = draw(&mut rng);
        }
        pool.rebuild(lum.iter().copied());
        let w = pool.weight();
        let (u_con, u_vis) = (uniform(&mut rng), uniform(&mut rng));
        if w == 0.0 {
            // Weight 0: the pool adds nothing (and has no restart).
            continue;
        }
        let x = pool.contribution(u_con);
        let y = match pool.visibility(u_vis, Some(x)) {
            Some(j) => lum[j],
            None => loop {
                let l = draw(&mut rng);
                if l > 0.0 {
                    break l;
                }
            },
        };
        let y_old = lum[pool.visibility(u_vis, None).expect("x is visible")];
        let bright = |l: f64| f64::from(u8::from(l == HIGH));
        let values = [
            w * bright(lum[x]),
            w * bright(y),
            w * bright(lum[x]) * bright(y),
            w * bright(y_old),
        ];
        for ((sum, square), v) in sums.iter_mut().zip(&mut squares).zip(values) {
            *sum += v;
            *square += v * v;
        }
        x_bright += bright(lum[x]);
        with_visible += 1.0;
    }
    let n = POOLS as f64;
    let expected = [
        b_con * bright_con,
        b_con * BRIGHT,
        b_con * bright_con * BRIGHT,
    ];
    let names = ["W·x bright", "W·y bright", "W·x, y bright"];
    for (((name, exact), sum), square) in names.iter().zip(expected).zip(sums).zip(squares) {
        let (m, se) = mean_se_of_sums(sum, square, n);
        eprintln!("{name}: {m} ± {se}, exact {exact}");
        assert!(5.0 * se < 0.1 * exact, "{name}: σ {se}");
        assert!(
            (m - exact).abs() < 4.0 * se,
            "{name}: {m} ± {se} against {exact}"
        );
    }
    // Controls.
    let (m, se) = mean_se_of_sums(sums[3], squares[3], n);
    eprintln!("control, W·y bright with y among all visible: {m} ± {se}");
    assert!((m - expected[1]).abs() > 4.0 * se);
    let (m, se) = mean_se_of_sums(x_bright, x_bright, with_visible);
    eprintln!("control, unweighted x bright: {m} ± {se}, target {bright_con}");
    assert!((m - bright_con).abs() > 4.0 * se);
}

/// The interior of session 17's restart-bias study at 64×48 (image
/// means do not depend on the resolution), radius 0.01 m fixed.
fn interior() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let defines = HashMap::from([
            ("width".to_string(), "64".to_string()),
            ("height".to_string(), "48".to_string()),
        ]);
        Scene::load(&repo_scene_path("interior-window.xml"), &defines).expect("interior loads")
    })
}

/// Iterations per replicate of the interior restart test.
const INTERIOR_ITERATIONS: u32 = 96;

/// Restarts from 1000 candidates on the interior (issue 16, sessions 17–18;
/// about 4 visible candidates per pool, where the thesis's rule read G
/// −10% at 48 iterations): `restart = weighted` agrees with `vcm` at the
/// same radius, and the thesis's rule (`resampled`) on the same seeds
/// must fail. 24 replicates of 96 iterations each (`mcmc-vcm`'s image mean
/// spread ~10% per run at 48 iterations there, `vcm`'s ~5%): σ of the
/// difference ≈ 1.6% (Student's t, 23 dof); pass within 4σ, and 4σ must
/// lie under 10% of the mean (the old rule's bias, so the control can
/// fail). About 2 minutes of CPU:
/// `cargo test -p mcmc-render --test mcmc_vcm -- --ignored weighted_restarts_remove --nocapture`.
#[test]
#[ignore]
fn weighted_restarts_remove_the_restart_bias_on_the_interior() {
    let scene = interior();
    let mut v = vcm_settings(scene);
    v.radius = Some(0.01);
    let reference: Vec<[f64; 3]> = (0..REPS)
        .map(|k| {
            let run = RunSettings {
                spp: Some(INTERIOR_ITERATIONS),
                seed: 1300 + k,
                ..RunSettings::default()
            };
            let out = v
                .integrator(scene)
                .render(scene, &run, &AtomicBool::new(false), &NoObserver);
            image_mean(&out.image)
        })
        .collect();
    let mcmc = |restart| McmcVcmSettings {
        candidates: 1000,
        restart,
        vcm: v.clone(),
        ..McmcVcmSettings::default()
    };
    let weighted = reps(scene, &mcmc(Restart::Weighted), INTERIOR_ITERATIONS, 1400);
    let resampled = reps(scene, &mcmc(Restart::Resampled), INTERIOR_ITERATIONS, 1400);
    let a = MeanAgreement::new(&reference, &weighted);
    let control = MeanAgreement::new(&reference, &resampled);
    let paired: Vec<[f64; 3]> = resampled
        .iter()
        .zip(&weighted)
        .map(|(r, w)| [0, 1, 2].map(|c| r[c] - w[c]))
        .collect();
    eprintln!(
        "weighted: rel {:?}\n  {a:?}\nresampled: rel {:?}\n  {control:?}\nresampled − weighted, paired: {:?}",
        a.rel(),
        control.rel(),
        mean_se(&paired)
    );
    assert!(a.resolves(4.0, 0.1), "noise too large: {a:?}");
    assert!(a.failures(4.0, 1.0).is_empty(), "weighted: {a:?}");
    assert!(
        !control.failures(4.0, 1.0).is_empty(),
        "the resampled restarts' bias not detected: {control:?}"
    );
}

/// The targets (Eqs. 6.2, 6.3) on random light subpaths of one
/// iteration: the visibility target is exactly 0 or −∞ in log (1 or 0),
/// the contribution target `ln lum C^Ω`; and a contribution chain run by
/// `mcmc-core`'s Metropolis–Hastings never accepts (nor holds) a state of
/// zero contribution, while such proposals do occur (so the check is not
/// vacuous).
#[test]
fn targets_are_exact_and_the_contribution_chain_never_accepts_black() {
    let scene = cornell_16();
    let integrator = settings(scene, LightChains::Both).integrator(scene);
    let mut pass = CameraPass::default();
    integrator.camera_pass(scene, 0.1, 1.0, 7, 0, &mut pass);
    let it = Iteration::new(&integrator.vcm, &pass.cameras, 0.1, 1.0);
    let n = pass.cameras.len();
    let mut rng = stream_rng(11, 0);
    let (mut black, mut visible) = (0, 0);
    let mut c = LightContribution::default();
    let mut start = None;
    for i in 0..4000 {
        let point = TorusPoint::fresh(child_rng(&mut rng));
        let camera = i % n;
        light_contribution(scene, &it, &mut PssSource::new(&point, 1), camera, &mut c);
        let vis = LightTarget {
            scene,
            it: &it,
            camera,
            kind: ChainKind::Visibility,
        };
        let con = LightTarget {
            scene,
            it: &it,
            camera,
            kind: ChainKind::Contribution,
        };
        let (lv, lc) = (
            mcmc_core::target::Target::evaluate(&vis, &point),
            mcmc_core::target::Target::evaluate(&con, &point),
        );
        assert!(c.finite);
        if c.luminance > 0.0 {
            visible += 1;
            assert_eq!(lv.log_density, 0.0);
            assert_eq!(lc.log_density, c.luminance.ln());
            start.get_or_insert((point, camera));
        } else {
            black += 1;
            assert_eq!(lv.log_density, f64::NEG_INFINITY);
            assert_eq!(lc.log_density, f64::NEG_INFINITY);
        }
    }
    assert!(
        visible > 100 && black > 100,
        "visible {visible}, black {black}"
    );
    let (point, camera) = start.unwrap();
    let first = LightTarget {
        scene,
        it: &it,
        camera,
        kind: ChainKind::Contribution,
    };
    let sample = Sample::evaluate(&first, point);
    let mut chain =
        Chain::from_sample(sample, integrator.algorithm(true), stream_rng(12, 0)).unwrap();
    let (mut zero_proposals, mut accepted) = (0, 0);
    for i in 0..4000 {
        let target = LightTarget {
            scene,
            it: &it,
            camera: (i * 7) % n,
            kind: ChainKind::Contribution,
        };
        chain.step_with(&target, |t| {
            assert!(
                t.current.payload.luminance > 0.0,
                "the chain holds a black state"
            );
            if let Some(y) = t.proposal
                && y.payload.luminance <= 0.0
            {
                zero_proposals += 1;
                assert_eq!(t.alpha, 0.0);
                assert!(!t.accepted, "a black proposal was accepted");
            }
            accepted += t.accepted as u32;
        });
        assert!(chain.current().payload.luminance > 0.0);
    }
    assert!(
        zero_proposals > 100,
        "only {zero_proposals} black proposals"
    );
    assert!(accepted > 100, "only {accepted} acceptances");
}

/// One seed gives the same bits on 1 and 2 threads.
#[test]
fn images_do_not_depend_on_the_thread_count() {
    let scene = cornell_16();
    let s = settings(scene, LightChains::Both);
    let render = |threads: usize| -> Vec<Rgb> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| run(scene, &s, 3, 9).image)
    };
    let (a, b) = (render(1), render(2));
    assert!(a.iter().any(|p| p.r > 0.0));
    for (i, (p, q)) in a.iter().zip(&b).enumerate() {
        assert_eq!(
            (p.r.to_bits(), p.g.to_bits(), p.b.to_bits()),
            (q.r.to_bits(), q.g.to_bits(), q.b.to_bits()),
            "pixel {i}"
        );
    }
}
