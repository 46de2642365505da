//! BDPT, PSSMLT and MMLT agree with path tracing on the repo's Cornell
//! variants to 1% of the image mean, per channel.
//!
//! # Tolerances
//!
//! Every estimator is run as `K` independent replicates (distinct fixed
//! seeds; for PSSMLT and MMLT each replicate has its own bootstrap and
//! chains). The standard error of a mean is sd(replicate means)/√K, so it
//! includes everything that varies between seeds: for (PS/M)MLT the image
//! luminance is essentially `b` (bootstrap plus large steps, the running
//! normalisation), while the split between channels depends on where the
//! chains went. With `σ` the standard error of the difference to PT, a
//! channel passes when the difference is within 4σ (false-alarm rate
//! ~1e-4 per channel for the t distributions with ≥ 11 degrees of freedom
//! used here) and within 1%, and the budgets are chosen so that 5σ < 1%
//! (SE ≤ 0.2%): a 1% discrepancy then lies 5σ out and fails the 4σ check
//! with probability ≈ 0.84, a 1.5% one with probability > 0.999. The
//! control test checks that an estimate biased by 1% is rejected.
//!
//! # Scenes
//!
//! `scenes/cornell-box.xml` and `scenes/cornell-glossy-glass.xml` at 16×16,
//! `max_depth` 5 (the MMLT default), with the camera tilted down so that
//! the emitter is out of view (`common::repo_scene_tilted_text`): seen
//! directly, its pixels dominate the variance of the image mean for every
//! estimator and of `b` for MLT (measured: ~10× the variance), and
//! resolving 1% with them in view would cost minutes per estimator. The
//! emitter seen directly is a one-segment path (PT's first hit, BDPT's
//! technique (0, 2), MMLT's depth 1), covered by the PT/LT tests on the
//! untilted scenes (`agree_pt_lt.rs`).
//!
//! The default tests use the diffuse box (about 100 s of one core). The
//! glossy-glass variant is noisier for every estimator (caustic, glossy
//! gold): BDPT and PSSMLT over BDPT are checked to 1% there, and MMLT,
//! whose `b` and blue channel spread 2.5–3.6% between seeds, to 3% only,
//! in two ignored tests that take 6.5 minutes of one core together
//! (`cargo test -p mcmc-render --test agree_mlt -- --ignored`).

mod common;

use common::{
    Budget, MeanAgreement, Mlt, bdpt_of, image_mean, mc_reps, mlt_reps, pt_of, repo_scene_tilted,
};
use mcmc_core::replica::{ExchangeContext, ExchangeMove, Schedule};
use mcmc_render::fused_space::{Conversion, FusedFamily, FusedMutation};
use mcmc_render::integrators::relt::{
    MakeExchange, Relt, ReltExchange, ReltFamily, ReltMisClasses,
};
use mcmc_render::markov::{ChainSettings, Normalization};
use mcmc_render::observer::NoObserver;
use mcmc_render::pss::PssmltSettings;
use mcmc_render::scene::Scene;
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

const RES: u32 = 16;
const DEPTH: u32 = 5;

/// Asserts agreement within 4σ and 1%, with 5σ < 1%.
fn check(what: &str, pt: &[[f64; 3]], test: &[[f64; 3]]) {
    check_to(what, pt, test, 0.01);
}

/// Asserts agreement within 4σ and `bound` (relative), with 5σ < `bound`.
fn check_to(what: &str, pt: &[[f64; 3]], test: &[[f64; 3]], bound: f64) {
    let a = MeanAgreement::new(pt, test);
    eprintln!("{what}: rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.failures(4.0, bound).is_empty(),
        "{what} disagrees with PT: {a:?}"
    );
    assert!(
        a.resolves(5.0, bound),
        "{what}: noise too large for {bound}: {a:?}"
    );
}

/// The tilted box.
fn cornell() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-box.xml", RES, DEPTH))
}

/// PT replicates of the tilted box, shared by the tests: 48 × 256 spp
/// (measured per-replicate spread 0.7% per channel, so SE ≈ 0.1%).
fn pt_reference() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| mc_reps(cornell(), &pt_of(cornell()), 256, 48, 1000))
}

/// MMLT replicates, shared by the agreement test and the control: 32 runs
/// of 5000 bootstrap candidates per depth (the running normalisation adds
/// ~3e5 large steps), 1024 chains of ~1000 mutations. Measured
/// per-replicate spread 0.5–1.0% per channel (blue the largest).
fn mmlt_reps() -> &'static [[f64; 3]] {
    static MMLT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    let budget = Budget {
        bootstrap: 5000,
        chains: 1024,
        mpp: 4096,
    };
    MMLT.get_or_init(|| mlt_reps(cornell(), Mlt::Mmlt, budget, 32, 4000))
}

#[test]
fn bdpt_agrees_with_pt_on_the_cornell_box() {
    // Per-replicate spread 0.65% at 128 spp; 24 replicates.
    let bdpt = mc_reps(cornell(), &bdpt_of(cornell()), 128, 24, 2000);
    check("bdpt", pt_reference(), &bdpt);
}

#[test]
fn pssmlt_agrees_with_pt_on_the_cornell_box() {
    // Over PT; per-replicate spread 0.4–0.8% (blue the largest) at ~2.6e5
    // mutations; 24 replicates.
    let budget = Budget {
        bootstrap: 50_000,
        chains: 512,
        mpp: 1024,
    };
    let pss = mlt_reps(cornell(), Mlt::PssmltPt, budget, 24, 3000);
    check("pssmlt-pt", pt_reference(), &pss);
}

#[test]
fn pssmlt_over_bdpt_agrees_with_pt_on_the_cornell_box() {
    // All techniques of one BDPT sample per state; per-replicate spread
    // 0.4–0.8% at ~2.6e5 mutations; 16 replicates.
    let budget = Budget {
        bootstrap: 50_000,
        chains: 512,
        mpp: 1024,
    };
    let pss = mlt_reps(cornell(), Mlt::PssmltBdpt, budget, 16, 6000);
    check("pssmlt-bdpt", pt_reference(), &pss);
}

#[test]
fn mmlt_agrees_with_pt_on_the_cornell_box() {
    check("mmlt", pt_reference(), mmlt_reps());
}

#[test]
fn a_one_percent_bias_is_rejected() {
    // The same check on a deliberately biased estimator: the MMLT
    // replicates (the noisiest estimator above) scaled by 1.01 must fail
    // against PT.
    let biased: Vec<[f64; 3]> = mmlt_reps().iter().map(|m| m.map(|v| v * 1.01)).collect();
    let a = MeanAgreement::new(pt_reference(), &biased);
    eprintln!("mmlt x1.01: rel {:?}\n  {a:?}", a.rel());
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
    assert!(
        !a.failures(4.0, 0.01).is_empty(),
        "a 1% bias passed the check: {a:?}"
    );
}

/// Image means of `k` runs of PSSMLT over PT on a two-level power ladder
/// (`I`, `I^0.5`) with even–odd swaps, through the driver's exchange path
/// (`blind`: swaps without their acceptance test, the control).
fn tempered_reps(blind: bool, k: u64, seed0: u64) -> Vec<[f64; 3]> {
    let scene = cornell();
    let mut family = common::tempered::TemperedPss::new(scene, pt_of(scene), &[1.0, 0.5]);
    family.blind = blind;
    let stop = AtomicBool::new(false);
    (0..k)
        .map(|s| {
            // 256 sets; 1024 mutations per pixel per level, as PSSMLT's
            // test above.
            let settings = PssmltSettings {
                bootstrap: 50_000,
                chains: 512,
                mutations_per_pixel: Some(2048),
                seed: seed0 + s,
                normalization: Normalization::Running,
                ..PssmltSettings::default()
            };
            let r = mcmc_render::markov::run(scene, &family, &settings, &stop, &NoObserver)
                .expect("tempered run");
            assert_eq!(r.chain_stats.invalid_density, 0, "NaN/inf paths");
            image_mean(&r.image())
        })
        .collect()
}

#[test]
fn tempered_pssmlt_with_swaps_agrees_with_pt_on_the_cornell_box() {
    // Level 0's chains are PSSMLT's, with states swapped in from the
    // flatter level; 16 replicates.
    check("tempered", pt_reference(), &tempered_reps(false, 16, 7000));
}

#[test]
fn swaps_without_their_acceptance_test_are_rejected() {
    // The control of the test above: level 0 then samples a mixture of
    // `I` and `I^0.5`, so the expected-value weights `1/I` no longer
    // undo its density and the channels' split is off.
    // Measured with the agreement test's 16 replicates: +2.8%, −1.2%,
    // −5.3%. With 4 replicates σ doubles to ≈ 0.4% (the agreement test's
    // budget makes 5σ < 1% at 16), so blue's −5.3% is still ~13σ and 5×
    // the 1% bound.
    let blind = tempered_reps(true, 4, 7000);
    let a = MeanAgreement::new(pt_reference(), &blind);
    eprintln!("blind swaps: rel {:?}\n  {a:?}", a.rel());
    assert!(
        !a.failures(4.0, 0.01).is_empty(),
        "blind swaps passed the check: {a:?}"
    );
}

/// Image means of `k` RELT runs on the tilted box with `mpp` mutations
/// per pixel, with the exchange move `make` (`None`: the default
/// neighbour swaps).
fn relt_reps(make: Option<MakeExchange>, mpp: u64, k: u64, seed0: u64) -> Vec<[f64; 3]> {
    // The diffuse box has no L0 path: a short search (its δ·L5 subsample
    // still starts the specific replica and joins its b_4).
    let settings = Relt {
        l0_search: 50_000,
        ..Relt::default()
    };
    relt_reps_on(cornell(), settings, make, mpp, k, seed0)
}

/// Image means of `k` RELT runs on `scene` with `mpp` mutations per pixel
/// (all four replicas).
fn relt_reps_on(
    scene: &Scene,
    mut settings: Relt,
    make: Option<MakeExchange>,
    mpp: u64,
    k: u64,
    seed0: u64,
) -> Vec<[f64; 3]> {
    let stop = AtomicBool::new(false);
    settings.depth.max_depth = i64::from(DEPTH);
    let bdpt = bdpt_of(scene);
    let family = ReltFamily::new(scene, bdpt, &settings.replicas(), &settings);
    let family = match make {
        Some(make) => family.with_exchange(make),
        None => family,
    };
    (0..k)
        .map(|s| {
            // 128 replica sets of four.
            let chain = ChainSettings::<()> {
                bootstrap: 50_000,
                chains: 512,
                mutations_per_pixel: Some(mpp),
                seed: seed0 + s,
                normalization: Normalization::Running,
                ..ChainSettings::default()
            };
            let r = mcmc_render::markov::run(scene, &family, &chain, &stop, &NoObserver)
                .expect("relt runs");
            assert_eq!(r.chain_stats.invalid_density, 0, "NaN/inf paths");
            image_mean(&r.image())
        })
        .collect()
}

#[test]
fn relt_agrees_with_pt_on_the_cornell_box() {
    // 512 mutations per pixel per replica. Measured per-replicate spread
    // ≈ 0.4% per channel; 12 replicates.
    check("relt", pt_reference(), &relt_reps(None, 2048, 12, 8000));
}

/// Ignored for its budget (about 70 s of the default suite's 15 minutes):
/// the two settings' mechanisms are checked exactly in mcmc-core (the
/// random-neighbour move in the transition-matrix tests, the sweep shares
/// by the resting-level exact test); run with
/// `cargo test -p mcmc-render --test agree_mlt -- --ignored relt_with_a_resting`.
#[test]
#[ignore]
fn relt_with_a_resting_uniform_replica_and_one_swap_per_sweep_agrees_with_pt() {
    // The non-default allocation and exchange: the uniform replica draws
    // in a quarter of the sweeps (its film over its own draws, the MIS
    // with the shares as sample counts) and one random neighbour pair is
    // tried per sweep (the paper's Algorithm 1). Same budget as the
    // default's test above. Measured per-replicate spread: 0.69% in blue
    // (12 replicates; green 0.56%, red 0.45%), PT's standard error 0.075%:
    // 5σ < 1% needs 0.69²/K + 0.075² ≤ 0.2², i.e. K ≥ 14; K = 20 gives
    // σ ≈ 0.17% (MeanAgreement checks 5σ < 1% from the replicates).
    let settings = Relt {
        uniform_share: 0.25,
        exchange: ReltExchange::RandomNeighbour,
        l0_search: 50_000,
        ..Relt::default()
    };
    let reps = relt_reps_on(cornell(), settings, None, 2048, 20, 8100);
    check(
        "relt uniform_share=0.25, random_neighbour",
        pt_reference(),
        &reps,
    );
    // Control: the same replicates biased by 1% must fail the check.
    let biased: Vec<[f64; 3]> = reps.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let a = MeanAgreement::new(pt_reference(), &biased);
    eprintln!("relt resting x1.01: rel {:?}\n  {a:?}", a.rel());
    assert!(!a.failures(4.0, 0.01).is_empty(), "a 1% bias passed: {a:?}");
}

/// Ignored for its budget (twice the default test's 12 × 2048 mutations
/// per pixel, about 80 s of one core); run with
/// `cargo test -p mcmc-render --test agree_mlt -- --ignored relt_with_per_class`.
#[test]
#[ignore]
fn relt_with_per_class_mis_agrees_with_pt() {
    // `mis_classes=per_class`: each class's MIS weights run over the
    // replicas whose target holds it, so L1 (the eye path hitting the
    // light without a specular bounce; here after diffuse bounces, the
    // emitter being out of view) comes from the uniform replica alone,
    // L2 from uniform and full; then with `full_l1` (L1 also in the full
    // replica's target, and so in its weights). Same budget and seeds'
    // spacing as the default's test above (per-replicate spread ≈ 0.4%,
    // 12 replicates: σ ≈ 0.15% with PT's 0.1%, so 5σ < 1%; check_to
    // asserts that from the replicates).
    for full_l1 in [false, true] {
        let settings = Relt {
            mis_classes: ReltMisClasses::PerClass,
            full_l1,
            l0_search: 50_000,
            ..Relt::default()
        };
        let reps = relt_reps_on(cornell(), settings, None, 2048, 12, 8200);
        let what = format!("relt per_class, full_l1={full_l1}");
        check(&what, pt_reference(), &reps);
        // Control: the same replicates biased by 1% must fail the check.
        let biased: Vec<[f64; 3]> = reps.iter().map(|m| m.map(|v| v * 1.01)).collect();
        let a = MeanAgreement::new(pt_reference(), &biased);
        eprintln!("{what} x1.01: rel {:?}\n  {a:?}", a.rel());
        assert!(!a.failures(4.0, 0.01).is_empty(), "a 1% bias passed: {a:?}");
    }
}

/// Neighbour swaps accepted by `min(1, π_{i−1}(x_i)/π_{i−1}(x_{i−1}))`:
/// the swap's ratio without the reverse term `π_i(x_{i−1})/π_i(x_i)`.
struct ForwardOnlySwap;

impl<S, P: Clone> ExchangeMove<S, P> for ForwardOnlySwap {
    fn name(&self) -> String {
        "forward-only".into()
    }
    fn schedule(&self) -> Schedule {
        Schedule::AfterAllMutations
    }
    fn exchange(&mut self, _level: Option<usize>, cx: &mut ExchangeContext<'_, S, P>) {
        for i in (1..cx.levels()).rev() {
            let log_r = cx.log_density(i - 1, i) - cx.log_density(i - 1, i - 1);
            if log_r >= 0.0 || mcmc_core::rng::uniform(cx.rng()).ln() < log_r {
                cx.swap(i - 1, i);
            }
        }
    }
}

#[test]
fn relt_with_swaps_missing_their_reverse_term_is_rejected() {
    // The control of the test above. Its defect is gross (measured with
    // the full budget of 12 × 2048 mutations per pixel: −49%, −50%, −56%),
    // so a quarter of the replicates at a quarter of the budget suffices:
    // with the 0.4% per-replicate spread of 2048 mutations per pixel
    // doubled at 512, σ = 0.8%/√3 ≈ 0.5%, and −49% is ~100σ (and 49× the
    // 1% bound), so the check rejects it on any seed.
    let biased = relt_reps(Some(|_| Box::new(ForwardOnlySwap)), 512, 3, 8000);
    let a = MeanAgreement::new(pt_reference(), &biased);
    eprintln!("relt forward-only swaps: rel {:?}\n  {a:?}", a.rel());
    assert!(
        !a.failures(4.0, 0.01).is_empty(),
        "swaps without their reverse term passed: {a:?}"
    );
}

/// The tilted glossy-glass box and its PT replicates: 64 × 1024 spp
/// (per-replicate spread 1.5% at 256 spp, so SE ≈ 0.1%).
fn glossy() -> (Scene, Vec<[f64; 3]>) {
    let scene = repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH);
    let pt = mc_reps(&scene, &pt_of(&scene), 1024, 64, 1000);
    (scene, pt)
}

#[test]
#[ignore = "minutes: BDPT and PSSMLT to 1% on the glossy-glass box"]
fn bdpt_and_pssmlt_agree_with_pt_on_the_glossy_glass_box() {
    // Measured: BDPT +0.06%, PSSMLT over BDPT
    // +0.2% per channel, SE of the difference 0.13–0.19%.
    let (scene, pt) = glossy();
    check(
        "bdpt",
        &pt,
        &mc_reps(&scene, &bdpt_of(&scene), 512, 64, 2000),
    );
    let pss = Budget {
        bootstrap: 100_000,
        chains: 1024,
        mpp: 1024,
    };
    check(
        "pssmlt-bdpt",
        &pt,
        &mlt_reps(&scene, Mlt::PssmltBdpt, pss, 24, 3000),
    );
}

#[test]
#[ignore = "minutes: RELT to 1% on the glossy-glass box"]
fn relt_agrees_with_pt_on_the_glossy_glass_box() {
    // With the default start-up, the specific replica's chains start
    // from the l0_search's L0 paths (the glass sphere's) and its b_4
    // includes the search's draws.
    relt_agrees_on_the_glossy_glass_box("relt", Relt::default());
}

#[test]
#[ignore = "minutes: RELT with the search continued to 1% on the glossy-glass box"]
fn relt_with_the_search_continued_agrees_with_pt_on_the_glossy_glass_box() {
    // The search goes on while the chains run (one draw per mutation)
    // and its draws join the specific replica's b_4, which scales the
    // glass sphere's L0 light.
    let settings = Relt {
        l0_search_rate: 1.0,
        ..Relt::default()
    };
    relt_agrees_on_the_glossy_glass_box("relt l0_search_rate=1", settings);
}

/// RELT with `settings` against PT on the glossy-glass box, with a ×1.01
/// control that must fail.
fn relt_agrees_on_the_glossy_glass_box(name: &str, settings: Relt) {
    // 48 replicates of 16384 mutations per pixel (4096 per replica). At
    // 24 × 8192 the means agreed (+0.33%, +0.41%, +0.09%) but σ was
    // 0.24–0.28%, too large to resolve 1% at 5σ.
    let (scene, pt) = glossy();
    let reps = relt_reps_on(&scene, settings, None, 16_384, 48, 9000);
    check(name, &pt, &reps);
    // Control: the same replicates biased by 1% must fail the check.
    let biased: Vec<[f64; 3]> = reps.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let a = MeanAgreement::new(&pt, &biased);
    eprintln!("{name} glossy x1.01: rel {:?}\n  {a:?}", a.rel());
    assert!(!a.failures(4.0, 0.01).is_empty(), "a 1% bias passed: {a:?}");
}

#[test]
#[ignore = "minutes: MMLT to 1% on the glossy-glass box (resolves 1.5% at 5σ)"]
fn mmlt_agrees_with_pt_on_the_glossy_glass_box() {
    // 3 × 48 replicates of 2e4 bootstrap candidates per depth, 1024 chains,
    // 16384 mutations per pixel. The blue channel's per-replicate spread
    // is heavy-tailed (rarely found glass paths): the first block of 48
    // alone measured −1.05% ± 0.34% (3.1σ), the next two −0.47% ± 0.39%
    // and −0.18% ± 0.46%. Pooled over the 144 replicates: +0.30%, −0.04%,
    // −0.57% with SE of the difference 0.16%, 0.16%, 0.25%. So the
    // means must agree within 1% and 4σ, and the noise must be small
    // enough that a 1.5% bias lies 5σ out (measured 5σ: 0.80%, 0.80%,
    // 1.23%; a 1% bias is 4σ out on blue). ~12 min of one core.
    let (scene, pt) = glossy();
    let mmlt = Budget {
        bootstrap: 20_000,
        chains: 1024,
        mpp: 16_384,
    };
    let reps: Vec<[f64; 3]> = [4000, 5000, 6000]
        .into_iter()
        .flat_map(|seed0| mlt_reps(&scene, Mlt::Mmlt, mmlt, 48, seed0))
        .collect();
    let a = MeanAgreement::new(&pt, &reps);
    eprintln!("mmlt: rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "mmlt disagrees with PT: {a:?}"
    );
    assert!(a.resolves(5.0, 0.015), "mmlt: noise too large: {a:?}");
}

/// Image means of `k` runs of `fused` (MMLT's depths with path-space
/// moves half of the time) on `scene`, converting by `conversion`.
fn fused_reps(
    scene: &Scene,
    (budget, conversion): (Budget, Conversion),
    k: u64,
    seed0: u64,
) -> Vec<[f64; 3]> {
    let stop = AtomicBool::new(false);
    (0..k)
        .map(|s| {
            let family = FusedFamily::new(scene, common::mmlt_depths(scene));
            let settings = ChainSettings {
                mutation: FusedMutation {
                    conversion,
                    ..FusedMutation::default()
                },
                bootstrap: budget.bootstrap,
                chains: budget.chains,
                mutations_per_pixel: Some(budget.mpp),
                seed: seed0 + s,
                normalization: Normalization::Running,
                ..ChainSettings::default()
            };
            let r = mcmc_render::markov::run(scene, &family, &settings, &stop, &NoObserver)
                .expect("fused runs");
            assert_eq!(r.chain_stats.invalid_density, 0, "fused: NaN/inf paths");
            image_mean(&r.image())
        })
        .collect()
}

#[test]
#[ignore = "minutes: fused to 1% on the Cornell box (measured: passes)"]
fn fused_agrees_with_pt_on_the_cornell_box() {
    // MMLT's budget (per-replicate spread 0.5–1.0% per channel). Measured
    // (2026-11-25, load average 15–20 on 2 cores, 900 s with the PT
    // reference): −0.07%, −0.19%, −0.10% per channel, SE of the
    // difference 0.18%, 0.15%, 0.16% (−0.4σ, −1.2σ, −0.6σ; 5σ < 1%).
    let budget = Budget {
        bootstrap: 5000,
        chains: 1024,
        mpp: 4096,
    };
    check(
        "fused",
        pt_reference(),
        &fused_reps(cornell(), (budget, Conversion::Eager), 32, 7000),
    );
}

#[test]
#[ignore = "minutes: fused with lazy conversion to 1% on the Cornell box"]
fn fused_with_lazy_conversion_agrees_with_pt_on_the_cornell_box() {
    // The test above with conversion=lazy (docs/fused.md, Session 22).
    let budget = Budget {
        bootstrap: 5000,
        chains: 1024,
        mpp: 4096,
    };
    check(
        "fused (lazy)",
        pt_reference(),
        &fused_reps(cornell(), (budget, Conversion::Lazy), 32, 7000),
    );
}

#[test]
#[ignore = "minutes: fused to 1% on the glossy-glass box"]
fn fused_agrees_with_pt_on_the_glossy_glass_box() {
    // MMLT's budget on this scene (see mmlt_agrees_with_pt_on_the_glossy_glass_box).
    let (scene, pt) = glossy();
    let budget = Budget {
        bootstrap: 20_000,
        chains: 1024,
        mpp: 16_384,
    };
    let reps = fused_reps(&scene, (budget, Conversion::Eager), 48, 8000);
    let a = MeanAgreement::new(&pt, &reps);
    eprintln!("fused: rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "fused disagrees with PT: {a:?}"
    );
    assert!(a.resolves(5.0, 0.015), "fused: noise too large: {a:?}");
}
