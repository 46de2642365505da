//! Tempered replica exchange MMLT (`tempered-mmlt`, spec seed000 ch. 5,
//! "8 levels per path length"): the per-level densities of one shared
//! evaluation of a depth's technique, its one-level identity with MMLT,
//! thread-count determinism, replica groups confined to one depth, and
//! agreement with PT on the tilted Cornell box (with a control that must
//! fail).
//!
//! # Tolerances of the agreement test
//!
//! As in `tempered_pssmlt.rs`: `K = 12` independent replicates, the
//! standard error of a mean is sd/√K, a channel passes when the
//! difference to PT is within 4σ (σ the standard error of the difference;
//! Student's t with 11 degrees of freedom puts 4σ at a two-sided
//! false-alarm rate below 3e-3 per channel) and within 1%, and the budget
//! is such that 5σ < 1%.

mod common;

use common::{
    MeanAgreement, image_mean, mc_reps, pt_of, registry_image_bits as render, repo_scene_tilted,
};
use mcmc_core::rng::stream_rng;
use mcmc_core::runner::with_threads;
use mcmc_core::space::TorusPoint;
use mcmc_render::integrators::registry;
use mcmc_render::integrators::tempered_mmlt::{TemperedMmlt, TemperedMmltFamily};
use mcmc_render::integrators::tempered_pssmlt::TemperedLadder;
use mcmc_render::markov::{self, ChainFamily, Normalization};
use mcmc_render::observer::NoObserver;
use mcmc_render::pss::{PssTarget, PssmltSettings};
use mcmc_render::scene::Scene;
use mcmc_render::tempered::{TemperedBsdfs, TemperedMmltDepth, level_density, temperatures};
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

/// Tempered-MMLT settings with `levels` levels and depth 5.
fn settings(levels: usize) -> TemperedMmlt {
    let mut t = TemperedMmlt::default();
    t.ladder.levels = levels;
    t.depth.max_depth = i64::from(DEPTH);
    t
}

fn states(n: usize, seed: u64) -> Vec<TorusPoint> {
    (0..n)
        .map(|i| TorusPoint::fresh(stream_rng(seed, i as u64)))
        .collect()
}

#[test]
fn level_densities_equal_a_fresh_evaluation_of_the_same_depth() {
    // The glossy-glass box, regularised and not: every level's density
    // from the shared evaluation of depth d's technique against a
    // one-level ladder at that temperature alone; level 0's splat is
    // MMLT's own.
    let scene = glossy();
    let temps = temperatures(8, 2500.0);
    let mut compared = [0usize; 8];
    for floor in [0.0, 4e-3] {
        for depth in settings(1).samplers(scene) {
            let all = TemperedMmltDepth {
                depth: depth.depth,
                bsdfs: TemperedBsdfs::new(scene, &temps, floor),
            };
            let shared = PssTarget {
                scene,
                sampler: all,
            };
            let fresh: Vec<_> = temps
                .iter()
                .map(|&t| PssTarget {
                    scene,
                    sampler: TemperedMmltDepth {
                        depth: depth.depth,
                        bsdfs: TemperedBsdfs::new(scene, &[t], floor),
                    },
                })
                .collect();
            let plain = PssTarget {
                scene,
                sampler: depth.depth,
            };
            for x in states(600, 11 + depth.depth.depth as u64) {
                let e = shared.trace(&x);
                for (k, f) in fresh.iter().enumerate() {
                    let got = level_density(&e.payload, k).expect("level record");
                    let want = f.trace(&x).payload.luminance();
                    assert!(
                        (got - want).abs() <= 1e-12 * want.abs(),
                        "depth {} level {k}: shared {got} vs fresh {want}",
                        depth.depth.depth
                    );
                    if want > 0.0 {
                        compared[k] += 1;
                    }
                }
                if floor == 0.0 {
                    let image: Vec<_> = e.payload.splats.iter().filter(|s| s.class == 0).collect();
                    let mmlt = plain.trace(&x).payload.splats;
                    assert_eq!(image.len(), mmlt.len());
                    for (a, b) in image.iter().zip(&mmlt) {
                        assert_eq!(**a, *b);
                    }
                }
            }
        }
    }
    assert!(compared.iter().all(|&c| c > 300), "{compared:?}");
}

#[test]
fn hot_levels_differ_from_the_cold_one() {
    // The control of the test above: the levels are not copies of level 0.
    let scene = glossy();
    let differing: usize = settings(8)
        .samplers(scene)
        .into_iter()
        .map(|s| {
            let target = PssTarget { scene, sampler: s };
            states(2000, 99)
                .iter()
                .filter(|x| {
                    let e = target.trace(x);
                    let p0 = level_density(&e.payload, 0).unwrap();
                    let p7 = level_density(&e.payload, 7).unwrap();
                    (p0 - p7).abs() > 1e-6 * p0.max(p7)
                })
                .count()
        })
        .sum();
    assert!(differing > 50, "only {differing} states differ");
}

const SMALL: [(&str, &str); 4] = [
    ("bootstrap", "2000"),
    ("chains", "64"),
    ("mutations_per_pixel", "16"),
    ("max_depth", "5"),
];

#[test]
fn one_level_image_is_mmlt_bit_for_bit() {
    let scene = glossy();
    let mut tempered = SMALL.to_vec();
    tempered.push(("levels", "1"));
    let mut mmlt = SMALL.to_vec();
    mmlt.push(("small_step", "kelemen"));
    let a = render("tempered-mmlt", &tempered, scene, 3);
    assert_eq!(a, render("mmlt", &mmlt, scene, 3));
    // Control: another seed gives another image.
    assert_ne!(a, render("mmlt", &mmlt, scene, 4));
}

#[test]
fn images_are_bit_identical_for_one_and_two_threads() {
    let scene = glossy();
    let mut sets = SMALL.to_vec();
    sets.push(("levels", "4"));
    let one = with_threads(1, || render("tempered-mmlt", &sets, scene, 9));
    let two = with_threads(2, || render("tempered-mmlt", &sets, scene, 9));
    assert!(one == two, "1 vs 2 threads differ");
}

#[test]
fn replica_groups_are_the_levels_of_one_depth() {
    let scene = cornell();
    let t = settings(3);
    let samplers = t.samplers(scene);
    let family = TemperedMmltFamily::new(scene, &samplers, &t.ladder);
    assert_eq!(family.members(), 3 * DEPTH as usize);
    let groups = family.replica_groups();
    assert_eq!(groups, vec![0..3, 3..6, 6..9, 9..12, 12..15]);
    // Every exchange stays in a group: the per-member statistics of a
    // run show one set count per depth, and each depth's three levels
    // made the same number of mutations.
    let run = PssmltSettings {
        bootstrap: 4000,
        chains: 30,
        mutations_per_pixel: Some(8),
        seed: 1,
        ..PssmltSettings::default()
    };
    let r = markov::run(scene, &family, &run, &AtomicBool::new(false), &NoObserver)
        .expect("tempered mmlt run");
    let ex = r.exchange.as_ref().expect("exchange statistics");
    assert!(
        ex.pairs.iter().all(|p| p.j < 3),
        "pair outside a 3-level set: {ex:?}"
    );
    for g in &groups {
        let m: Vec<u64> = g.clone().map(|k| r.families[k].mutations).collect();
        assert!(
            m.iter().all(|&x| x == m[0]),
            "levels of one depth differ: {m:?}"
        );
    }
}

/// Image means of `k` tempered-MMLT runs on the tilted box (4 levels, T up
/// to 2500, IS permutations), `control`: with the unnormalised MIS.
fn tempered_reps(
    scene: &Scene,
    control: bool,
    k: u64,
    mutations_per_pixel: u64,
    seed0: u64,
) -> Vec<[f64; 3]> {
    let stop = AtomicBool::new(false);
    let t = settings(4);
    let ladder: TemperedLadder = t.ladder.clone();
    let samplers = t.samplers(scene);
    (0..k)
        .map(|i| {
            let run = PssmltSettings {
                bootstrap: 10_000,
                chains: 512,
                mutations_per_pixel: Some(mutations_per_pixel),
                seed: seed0 + i,
                normalization: Normalization::Running,
                ..PssmltSettings::default()
            };
            let family = TemperedMmltFamily::new(scene, &samplers, &ladder);
            let r = if control {
                markov::run(
                    scene,
                    &common::tempered::UnnormalisedMis(family),
                    &run,
                    &stop,
                    &NoObserver,
                )
            } else {
                markov::run(scene, &family, &run, &stop, &NoObserver)
            }
            .expect("tempered mmlt run");
            image_mean(&r.image())
        })
        .collect()
}

fn pt_reference() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| mc_reps(cornell(), &pt_of(cornell()), 256, 48, 1000))
}

#[test]
fn tempered_mmlt_agrees_with_pt_on_the_cornell_box() {
    // 12 replicates of 4096 mutations per pixel (1024 per level, spread
    // over the 5 depths). At 1024 per pixel σ was 0.27–0.36% (5σ > 1%):
    // rel −0.33%, −0.16%, −0.38%.
    let a = MeanAgreement::new(
        pt_reference(),
        &tempered_reps(cornell(), false, 12, 4096, 25_000),
    );
    eprintln!("tempered-mmlt: rel {:?}\n  {a:?}", a.rel());
    assert!(a.failures(4.0, 0.01).is_empty(), "disagrees with PT: {a:?}");
    assert!(a.resolves(5.0, 0.01), "noise too large: {a:?}");
}

#[test]
fn eq_5_13_without_the_normalisations_is_rejected() {
    // The unnormalised MIS is biased by tens of percent: the smaller
    // budget suffices for it to fail.
    let a = MeanAgreement::new(
        pt_reference(),
        &tempered_reps(cornell(), true, 12, 1024, 25_000),
    );
    eprintln!("unnormalised MIS: rel {:?}\n  {a:?}", a.rel());
    assert!(
        !a.failures(4.0, 0.01).is_empty(),
        "the control passed: {a:?}"
    );
}

#[test]
fn the_depth_limit_is_required() {
    let mut t = TemperedMmlt::default();
    t.depth.max_depth = -1;
    let err = registry::IntegratorSettings::validate(&t).unwrap_err();
    assert!(err.contains("max_depth"), "{err}");
}
