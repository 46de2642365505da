//! Tempered replica exchange PSSMLT (`tempered-pssmlt`, spec seed000 ch. 5):
//! the per-level densities of one shared evaluation, its one-level
//! identity with PSSMLT over BDPT, the Eq. 5.13 weights, thread-count
//! determinism and agreement with PT on the tilted Cornell box (with a
//! control that must fail).
//!
//! # Tolerances of the agreement test
//!
//! As in `agree_mlt.rs`: `K` independent replicates per estimator, the
//! standard error of a mean is sd/√K, a channel passes when the difference
//! to PT is within 4σ (σ the standard error of the difference; Student's t
//! with K − 1 ≥ 11 degrees of freedom puts 4σ at a two-sided false-alarm
//! rate below 3e-3 per channel) and within 1%, and the budget is such that
//! 5σ < 1%, so a 1% bias fails the 4σ check with probability ≈ 0.84.

mod common;

use common::{
    MeanAgreement, bdpt_of, image_mean, load_str, mc_reps, pt_of, registry_image_bits as render,
    repo_scene_path, repo_scene_tilted,
};
use mcmc_core::rng::stream_rng;
use mcmc_core::runner::with_threads;
use mcmc_core::space::TorusPoint;
use mcmc_render::color::Rgb;
use mcmc_render::integrators::registry;
use mcmc_render::integrators::tempered_pssmlt::{TemperedExchange, TemperedFamily, TemperedPssmlt};
use mcmc_render::integrators::{Rendered, RunSettings};
use mcmc_render::markov::{self, Normalization};
use mcmc_render::observer::NoObserver;
use mcmc_render::pss::{PssTarget, PssmltSettings};
use mcmc_render::scene::Scene;
use mcmc_render::staged::stage_seed;
use mcmc_render::tempered::{
    Regularization, RegularizationSchedule, SPECULAR_STAND_IN, ScheduleKind, TemperedBdpt,
    TemperedBsdfs, chain_mis_weights, level_density, temperatures,
};
use proptest::prelude::*;
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

const RES: u32 = 16;
const DEPTH: u32 = 5;

fn glossy() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH))
}

fn cornell() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-box.xml", RES, DEPTH))
}

/// The plastic box (smooth plastic sphere and box), tilted like the others
/// (`repo_scene_tilted` expects a 256-pixel default; this scene's is 64).
fn plastic() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let text = std::fs::read_to_string(repo_scene_path("cornell-plastic.xml"))
            .expect("scene file")
            .replace(r#"target="0, 0, 0""#, r#"target="0, -1.1, 0""#)
            .replace(
                r#""width" value="64""#,
                &format!(r#""width" value="{RES}""#),
            )
            .replace(
                r#""height" value="64""#,
                &format!(r#""height" value="{RES}""#),
            )
            .replace(
                r#""max_depth" value="8""#,
                &format!(r#""max_depth" value="{DEPTH}""#),
            );
        let scene = load_str(&text);
        assert_eq!((scene.film.width, scene.integrator.max_depth), (RES, DEPTH));
        scene
    })
}

fn sampler(scene: &Scene, temps: &[f64], floor: f64) -> TemperedBdpt {
    sampler_with(scene, temps, floor, SPECULAR_STAND_IN)
}

/// [`sampler`] with smooth BSDFs standing in as roughness `stand_in` at `T > 1`.
fn sampler_with(scene: &Scene, temps: &[f64], floor: f64, stand_in: f64) -> TemperedBdpt {
    TemperedBdpt {
        bdpt: bdpt_of(scene),
        bsdfs: TemperedBsdfs::with_stand_in(scene, temps, floor, stand_in),
    }
}

/// Random primary-sample states with fixed seeds.
fn states(n: usize, seed: u64) -> Vec<TorusPoint> {
    (0..n)
        .map(|i| TorusPoint::fresh(stream_rng(seed, i as u64)))
        .collect()
}

#[test]
fn level_densities_equal_a_fresh_evaluation_at_that_level() {
    // The glossy-glass box (glass sphere, gold glossy, diffuse walls),
    // regularised and not: every level's density from the shared
    // evaluation against a one-level ladder at that temperature alone.
    let scene = glossy();
    let temps = temperatures(8, 2500.0);
    let mut compared = [0usize; 8];
    for floor in [0.0, 4e-3] {
        let all = sampler(scene, &temps, floor);
        let target = PssTarget {
            scene,
            sampler: all.clone(),
        };
        let fresh: Vec<PssTarget<TemperedBdpt>> = temps
            .iter()
            .map(|&t| PssTarget {
                scene,
                sampler: sampler(scene, &[t], floor),
            })
            .collect();
        for x in states(3000, 11) {
            let e = target.trace(&x);
            for (k, f) in fresh.iter().enumerate() {
                let shared = level_density(&e.payload, k).expect("level record");
                let alone = f.trace(&x);
                let want = alone.payload.luminance();
                assert!(
                    (shared - want).abs() <= 1e-12 * want.abs(),
                    "level {k}: shared {shared} vs fresh {want}"
                );
                if want > 0.0 {
                    compared[k] += 1;
                }
            }
            // Level 0's splats are the image's, exactly the fresh ones.
            let level0 = fresh[0].trace(&x).payload.splats;
            let image: Vec<_> = e.payload.splats.iter().filter(|s| s.class == 0).collect();
            assert_eq!(image.len(), level0.len());
            for (a, b) in image.iter().zip(&level0) {
                assert_eq!(**a, *b);
            }
        }
    }
    // Enough contributing states at every level for the check to bite.
    assert!(compared.iter().all(|&c| c > 500), "{compared:?}");
}

#[test]
fn hot_levels_differ_from_the_cold_one_where_glossy_or_glass_connects() {
    // The control of the test above: the levels are not copies of level 0.
    let scene = glossy();
    let target = PssTarget {
        scene,
        sampler: sampler(scene, &temperatures(8, 2500.0), 0.0),
    };
    let differing = states(2000, 99)
        .iter()
        .filter(|x| {
            let e = target.trace(x);
            let p0 = level_density(&e.payload, 0).unwrap();
            let p7 = level_density(&e.payload, 7).unwrap();
            (p0 - p7).abs() > 1e-6 * p0.max(p7)
        })
        .count();
    assert!(differing > 50, "only {differing} states differ");
}

#[test]
fn one_level_without_regularisation_is_bdpt() {
    // The tempered sampler with one level T = 1 emits BDPT's splats, bit
    // for bit, and no level record.
    let scene = glossy();
    let tempered = PssTarget {
        scene,
        sampler: sampler(scene, &[1.0], 0.0),
    };
    let plain = PssTarget {
        scene,
        sampler: bdpt_of(scene),
    };
    for x in states(3000, 5) {
        let a = tempered.trace(&x);
        let b = plain.trace(&x);
        assert_eq!(a.payload, b.payload);
        assert_eq!(a.log_density.to_bits(), b.log_density.to_bits());
    }
}

const SMALL: [(&str, &str); 4] = [
    ("bootstrap", "2000"),
    ("chains", "64"),
    ("mutations_per_pixel", "16"),
    ("max_depth", "5"),
];

#[test]
fn one_level_image_is_pssmlt_over_bdpt_bit_for_bit() {
    let scene = glossy();
    let mut tempered = SMALL.to_vec();
    tempered.push(("levels", "1"));
    let mut pssmlt = SMALL.to_vec();
    pssmlt.push(("base", "bdpt"));
    let a = render("tempered-pssmlt", &tempered, scene, 3);
    assert_eq!(a, render("pssmlt", &pssmlt, scene, 3));
    // Control: another seed gives another image.
    assert_ne!(a, render("pssmlt", &pssmlt, scene, 4));
}

#[test]
fn images_are_bit_identical_for_one_and_two_threads() {
    let scene = glossy();
    let mut sets = SMALL.to_vec();
    sets.push(("levels", "4"));
    let one = with_threads(1, || render("tempered-pssmlt", &sets, scene, 9));
    let two = with_threads(2, || render("tempered-pssmlt", &sets, scene, 9));
    assert!(one == two, "1 vs 2 threads differ");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, rng_seed: proptest::test_runner::RngSeed::Fixed(15), ..ProptestConfig::default() })]
    /// Eq. 5.13: the chain weights of any state sum to 1 over the levels
    /// (when some level has density).
    #[test]
    fn chain_weights_sum_to_one(
        pi in prop::collection::vec(prop_oneof![Just(0.0), 1e-30f64..1e30], 1..16),
        b in prop::collection::vec(1e-6f64..1e6, 16),
    ) {
        let b = &b[..pi.len()];
        let w = chain_mis_weights(&pi, b);
        if pi.iter().any(|&p| p > 0.0) {
            let sum: f64 = w.iter().sum();
            prop_assert!((sum - 1.0).abs() < 1e-12, "{sum}");
            prop_assert!(w.iter().all(|&x| (0.0..=1.0 + 1e-15).contains(&x)));
        } else {
            prop_assert!(w.iter().all(|&x| x == 0.0));
        }
    }
}

#[test]
fn the_regularisation_schedules_are_selectable() {
    let mut t = TemperedPssmlt::default();
    assert_eq!(t.ladder.schedule().floor(10), 0.0);
    t.ladder.regularization = ScheduleKind::Power;
    t.ladder.gamma = 0.5;
    t.ladder.rho0 = 0.01;
    assert!((t.ladder.schedule().floor(3) - 0.005).abs() < 1e-15);
    let r = Regularization {
        kind: ScheduleKind::Geometric,
        rho0: 0.01,
        gamma: 0.5,
    };
    assert!((r.floor(3) - 0.00125).abs() < 1e-15);
}

/// A registry render of `name` with `sets` on `scene`.
fn render_full(name: &str, sets: &[(&str, &str)], scene: &Scene, seed: u64) -> Rendered {
    let sets: Vec<(String, String)> = sets
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    let integrator = registry::configure(None, Some(name), &sets).expect("configures");
    let run = RunSettings {
        seed,
        ..Default::default()
    };
    integrator
        .render(scene, &run, &AtomicBool::new(false), &NoObserver)
        .expect("renders")
}

/// Staged regularisation (`regularization_stages`, `mcmc_render::staged`):
/// a two-stage run is exactly the sample-weighted mean of two one-stage
/// runs, the first at the floor of sample index 0 with a third of the
/// budget, the second at the floor of the samples per pixel before it
/// (`regularization_n`), with two thirds and the second stage's seed. The
/// statistics show the floors falling as ρ₀ (n+1)^(−γ). Controls: the
/// second stage at the first stage's floor, or combined with equal
/// weights, is another image.
#[test]
fn staged_regularisation_is_the_weighted_mean_of_its_stages() {
    let scene = glossy();
    let mut base = SMALL.to_vec();
    base.retain(|(k, _)| *k != "mutations_per_pixel");
    base.extend([
        ("levels", "4"),
        ("regularization", "power"),
        ("rho0", "0.05"),
        ("gamma", "0.5"),
    ]);
    let with = |extra: &[(&'static str, &'static str)]| {
        let mut s = base.clone();
        s.extend_from_slice(extra);
        s
    };
    let staged = render_full(
        "tempered-pssmlt",
        &with(&[
            ("regularization_stages", "2"),
            ("mutations_per_pixel", "15"),
        ]),
        scene,
        3,
    );
    // Stage budgets 15·1/3 = 5 and 15·2/3 = 10 per pixel.
    let first = render_full(
        "tempered-pssmlt",
        &with(&[("mutations_per_pixel", "5")]),
        scene,
        3,
    );
    let second_seed = stage_seed(3, 1);
    let second = render_full(
        "tempered-pssmlt",
        &with(&[("mutations_per_pixel", "10"), ("regularization_n", "5")]),
        scene,
        second_seed,
    );
    let (a, b) = (first.samples as f32, second.samples as f32);
    assert_eq!(staged.samples, first.samples + second.samples);
    let mean_of = |x: &Rendered, y: &Rendered, wx: f32, wy: f32| -> Vec<Rgb> {
        x.image
            .iter()
            .zip(&y.image)
            .map(|(p, q)| (*p * wx + *q * wy) * (1.0 / (wx + wy)))
            .collect()
    };
    let max_rel = |u: &[Rgb], v: &[Rgb]| -> f64 {
        u.iter()
            .zip(v)
            .flat_map(|(p, q)| [(p.r, q.r), (p.g, q.g), (p.b, q.b)])
            .map(|(x, y)| f64::from((x - y).abs()) / f64::from(x.abs().max(y.abs()).max(1e-6)))
            .fold(0.0, f64::max)
    };
    // f32 sums of two weighted terms: a few ulps.
    let expected = mean_of(&first, &second, a, b);
    assert!(max_rel(&staged.image, &expected) < 1e-5);
    let floors: Vec<f64> = staged.statistics["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["floor"].as_f64().unwrap())
        .collect();
    assert_eq!(floors, [0.05, 0.05 / 6f64.sqrt()]);
    // Controls.
    assert!(max_rel(&staged.image, &mean_of(&first, &second, 1.0, 1.0)) > 1e-3);
    let held = render_full(
        "tempered-pssmlt",
        &with(&[("mutations_per_pixel", "10")]),
        scene,
        second_seed,
    );
    assert!(max_rel(&staged.image, &mean_of(&first, &held, a, b)) > 1e-3);
}

#[test]
fn stages_need_a_decaying_schedule() {
    for schedule in ["off", "constant"] {
        let sets = vec![
            ("max_depth".to_string(), "5".to_string()),
            ("regularization".to_string(), schedule.to_string()),
            ("regularization_stages".to_string(), "3".to_string()),
        ];
        let e = registry::configure(None, Some("tempered-mmlt"), &sets)
            .err()
            .expect("refused");
        assert!(
            e.contains("needs a decaying schedule") && !e.contains('\n'),
            "{e}"
        );
    }
}

/// Image means of `k` tempered runs on the tilted box (4 levels, T up to
/// 2500, IS permutations), `control`: with [`UnnormalisedMis`].
fn tempered_reps(scene: &Scene, control: bool, k: u64, seed0: u64) -> Vec<[f64; 3]> {
    tempered_reps_with(scene, control, (10_000, 1024), k, seed0, SPECULAR_STAND_IN)
}

/// [`tempered_reps`] with `(bootstrap candidates, mutations per pixel)`
/// and the stand-in roughness of smooth BSDFs at `T > 1`.
fn tempered_reps_with(
    scene: &Scene,
    control: bool,
    (bootstrap, mpp): (usize, u64),
    k: u64,
    seed0: u64,
    stand_in: f64,
) -> Vec<[f64; 3]> {
    let stop = AtomicBool::new(false);
    let s = sampler_with(scene, &temperatures(4, 2500.0), 0.0, stand_in);
    (0..k)
        .map(|i| {
            let settings = PssmltSettings {
                bootstrap,
                chains: 512,
                mutations_per_pixel: Some(mpp),
                seed: seed0 + i,
                normalization: Normalization::Running,
                ..PssmltSettings::default()
            };
            let family = TemperedFamily::new(scene, &s, TemperedExchange::IsPermutation);
            let r = if control {
                markov::run(
                    scene,
                    &common::tempered::UnnormalisedMis(family),
                    &settings,
                    &stop,
                    &NoObserver,
                )
            } else {
                markov::run(scene, &family, &settings, &stop, &NoObserver)
            }
            .expect("tempered run");
            image_mean(&r.image())
        })
        .collect()
}

fn pt_reference() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| mc_reps(cornell(), &pt_of(cornell()), 256, 48, 1000))
}

#[test]
fn tempered_pssmlt_agrees_with_pt_on_the_cornell_box() {
    // 12 replicates of 1024 mutations per pixel (256 per level). Measured:
    // −0.19%, +0.06%, +0.04% with σ 0.15%, 0.17%, 0.20% (5σ < 1% on
    // every channel; the control reads +25%).
    let a = MeanAgreement::new(pt_reference(), &tempered_reps(cornell(), false, 12, 15_000));
    eprintln!("tempered-pssmlt: rel {:?}\n  {a:?}", a.rel());
    assert!(a.failures(4.0, 0.01).is_empty(), "disagrees with PT: {a:?}");
    assert!(a.resolves(5.0, 0.01), "noise too large: {a:?}");
}

/// A run stopped before its chains move writes its start-up candidates'
/// image (`MltResult::startup_image`): for a ladder whose levels share one
/// evaluation, each candidate's splats weighted by the levels' class
/// factors `Σ_d g_{d,c} q_d` (1 on the image class, 0 on the level
/// records; `markov/startup.rs`). Stopped at once, each run draws one
/// round of 4096 candidates; 200 replicates against PT with the tolerance
/// of the module's comment. Measured: −0.04%, −0.05%, +0.02% (σ 0.15%,
/// 0.15%, 0.17%; 3 s). The control, the same replicates × 1.01, must
/// fail.
#[test]
fn a_run_stopped_in_its_start_up_writes_the_candidates_image() {
    let scene = cornell();
    let stop = AtomicBool::new(true);
    let s = sampler(scene, &temperatures(4, 2500.0), 0.0);
    let reps: Vec<[f64; 3]> = (0..200)
        .map(|i| {
            let settings = PssmltSettings {
                bootstrap: 4096,
                chains: 64,
                mutations_per_pixel: Some(64),
                seed: 21_000 + i,
                ..PssmltSettings::default()
            };
            let family = TemperedFamily::new(scene, &s, TemperedExchange::IsPermutation);
            let r = markov::run(scene, &family, &settings, &stop, &NoObserver).expect("runs");
            assert!(r.mutations == 0 && r.startup_image.is_some() && r.interrupted);
            image_mean(&r.image())
        })
        .collect();
    let a = MeanAgreement::new(pt_reference(), &reps);
    eprintln!("tempered-pssmlt start-up image: rel {:?}\n  {a:?}", a.rel());
    assert!(a.failures(4.0, 0.01).is_empty(), "disagrees with PT: {a:?}");
    assert!(a.resolves(5.0, 0.01), "noise too large: {a:?}");
    let biased: Vec<[f64; 3]> = reps.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let b = MeanAgreement::new(pt_reference(), &biased);
    assert!(!b.failures(4.0, 0.01).is_empty(), "a 1% bias passed: {b:?}");
}

#[test]
fn eq_5_13_without_the_normalisations_is_rejected() {
    let a = MeanAgreement::new(pt_reference(), &tempered_reps(cornell(), true, 12, 15_000));
    eprintln!("unnormalised MIS: rel {:?}\n  {a:?}", a.rel());
    assert!(
        !a.failures(4.0, 0.01).is_empty(),
        "the control passed: {a:?}"
    );
}

/// Issue 15's agreement where the levels really differ: the tilted
/// glossy-glass box (glass sphere, glossy gold, diffuse walls; depth 5),
/// 4 levels up to T = 2500 combined by Eq. 5.13 (32 replicates of 100k
/// bootstrap candidates and 4096 mutations per pixel), against PT (64 ×
/// 2048 spp). Tolerance as `MeanAgreement`: within 4σ and 1%, and 5σ < 1%
/// asserted; the control, the same replicates × 1.01, must fail.
/// Measured with PT at 64 × 1024 spp: −0.18%, −0.20%, −0.30% (σ 0.15%,
/// 0.16%, 0.21%; 1.2–1.5σ), but 5σ was 1.03% in blue, where PT's own SE
/// (0.15%) dominated: hence PT's 2048 spp. With it: −0.12%, −0.12%,
/// −0.19% (σ 0.13%, 0.14%, 0.18%; passed, 915 s at load average 8).
#[test]
#[ignore = "minutes: tempered PSSMLT to 1% on the glossy-glass box"]
fn tempered_pssmlt_agrees_with_pt_on_the_glossy_glass_box() {
    let scene = glossy();
    let pt = mc_reps(scene, &pt_of(scene), 2048, 64, 1000);
    let reps = tempered_reps_with(scene, false, (100_000, 4096), 32, 16_000, SPECULAR_STAND_IN);
    let a = MeanAgreement::new(&pt, &reps);
    eprintln!("tempered-pssmlt glossy: rel {:?}\n  {a:?}", a.rel());
    assert!(a.failures(4.0, 0.01).is_empty(), "disagrees with PT: {a:?}");
    assert!(a.resolves(5.0, 0.01), "noise too large: {a:?}");
    let biased: Vec<[f64; 3]> = reps.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let b = MeanAgreement::new(&pt, &biased);
    assert!(!b.failures(4.0, 0.01).is_empty(), "a 1% bias passed: {b:?}");
}

/// Stand-in roughness of the smooth plastic coat at `T > 1` in the test
/// below: `√T · 0.01` reaches 0.5 at the hottest of 4 levels (T = 2500).
const WIDE_STAND_IN: f64 = 0.01;

#[test]
fn a_wide_stand_in_makes_the_hot_levels_differ_on_the_plastic_box() {
    // What makes the agreement test below bite: with the wide stand-in the
    // smooth plastic coat is a rough lobe at every hot level, so the hot
    // densities differ from the cold one on many states (and with the
    // thesis's 10⁻⁴ far fewer states are affected).
    let scene = plastic();
    let count = |stand_in: f64| {
        let target = PssTarget {
            scene,
            sampler: sampler_with(scene, &temperatures(4, 2500.0), 0.0, stand_in),
        };
        states(1000, 98)
            .iter()
            .filter(|x| {
                let e = target.trace(x);
                let p0 = level_density(&e.payload, 0).unwrap();
                let p3 = level_density(&e.payload, 3).unwrap();
                (p0 - p3).abs() > 0.05 * p0.max(p3)
            })
            .count()
    };
    let (wide, thesis) = (count(WIDE_STAND_IN), count(SPECULAR_STAND_IN));
    eprintln!("states differing by > 5%: wide {wide}, thesis {thesis} of 1000");
    assert!(
        wide > 100 && wide > 2 * thesis,
        "wide {wide}, thesis {thesis}"
    );
}

/// The stand-in roughness of smooth BSDFs (`specular_roughness`) changes
/// only the levels with `T > 1`; Eq. 5.13 films level 0's contribution
/// with weights that sum to 1 over the levels, so the image must stay
/// PT's. The tilted plastic box (smooth plastic sphere and box, depth 5),
/// 4 levels up to T = 2500 with the wide stand-in (hot coats up to
/// roughness 0.5), 24 replicates of 1024 mutations per pixel, against PT
/// (48 × 1024 spp). Tolerance as the Cornell box's (header; Student's t
/// with 23 degrees of freedom): within 4σ and 1%, 5σ < 1% asserted; the
/// control, the same replicates × 1.01, must fail. With 12 replicates and
/// PT at 256 spp it agreed (+0.05%, +0.33%, +0.41%) but blue's 5σ was
/// 1.34% (σ 0.27%, the dim blue channel): hence the budget, which puts it
/// out of the default suite (≈ 5 min at load 10; ≈ 290 s for half of it).
#[test]
#[ignore = "minutes: tempered PSSMLT with a wide stand-in to 1% on the plastic box"]
fn a_wide_stand_in_keeps_the_image_unbiased_on_the_plastic_box() {
    let scene = plastic();
    let pt = mc_reps(scene, &pt_of(scene), 1024, 48, 1000);
    let reps = tempered_reps_with(scene, false, (10_000, 1024), 24, 17_000, WIDE_STAND_IN);
    let a = MeanAgreement::new(&pt, &reps);
    eprintln!(
        "tempered-pssmlt plastic, wide stand-in: rel {:?}\n  {a:?}",
        a.rel()
    );
    assert!(a.failures(4.0, 0.01).is_empty(), "disagrees with PT: {a:?}");
    assert!(a.resolves(5.0, 0.01), "noise too large: {a:?}");
    let biased: Vec<[f64; 3]> = reps.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let b = MeanAgreement::new(&pt, &biased);
    assert!(!b.failures(4.0, 0.01).is_empty(), "a 1% bias passed: {b:?}");
}
