//! `mept` (path-space MLT with the manifold perturbation) agrees with path
//! tracing to 1% of the image mean per channel on the repo's tilted
//! Cornell box; its images are bit-identical for any thread count; the
//! registered name is `mlt` with `manifold_perturbation` = 1.
//!
//! # Tolerances
//!
//! As `tests/path_space_mlt.rs` (same scene, same PT reference, same
//! check): `K` replicates with distinct fixed seeds, each with its own
//! bootstrap and chains; `σ` is the standard error of the difference of
//! the means (K ≥ 30 on both sides, so normal quantiles apply); a channel
//! passes within 4σ and 1%, and the budget must give 5σ < 1%
//! (`MeanAgreement::resolves`). The control scales the replicates by 1.01
//! and must fail. The glossy/glass box (Dirac chains through the glass
//! sphere, where the walk and the generalised geometry term matter) is an
//! ignored test of minutes.

mod common;

use common::{MeanAgreement, image_mean, mc_reps, pt_of, repo_scene, repo_scene_tilted};
use mcmc_core::runner::with_threads;
use mcmc_render::integrators::RunSettings;
use mcmc_render::integrators::mept::Mept;
use mcmc_render::integrators::registry;
use mcmc_render::markov::{ChainFamily, ChainSettings, Normalization, StartupCut};
use mcmc_render::observer::NoObserver;
use mcmc_render::path_space::{PathFamily, PathMutations};
use mcmc_render::scene::Scene;
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

const RES: u32 = 16;
const DEPTH: u32 = 5;

fn cornell() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| repo_scene_tilted("cornell-box.xml", RES, DEPTH))
}

/// PT replicates: 48 × 256 spp (as `path_space_mlt.rs`).
fn pt_reference() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| mc_reps(cornell(), &pt_of(cornell()), 256, 48, 1000))
}

/// The `mept` mixture: the bidirectional mutation and the manifold
/// perturbation, weight 1 each, and the independent proposal at 0.3
/// (what `mept`'s defaults select).
fn mept_mutations() -> PathMutations {
    Mept::default().mlt.mutations()
}

/// Image means of `k` runs of the `mept` chains (running normalisation)
/// with `mept`'s start-up: `draws` BDPT draws (`bdpt_startup`).
fn mept_reps(
    scene: &Scene,
    draws: usize,
    chains: usize,
    mpp: u64,
    k: u64,
    seed0: u64,
) -> Vec<[f64; 3]> {
    let max = scene.integrator.max_depth;
    let family = PathFamily::new(scene, (max != u32::MAX).then_some(max as usize))
        .with_bdpt_startup(draws as u64);
    assert!(family.has_bdpt_startup());
    let stop = AtomicBool::new(false);
    (0..k)
        .map(|s| {
            let settings = ChainSettings {
                mutation: mept_mutations(),
                // The search replaces the bootstrap (as `mept` runs it).
                bootstrap: 1,
                chains,
                mutations_per_pixel: Some(mpp),
                seed: seed0 + s,
                normalization: Normalization::Running,
                ..ChainSettings::default()
            };
            let r = mcmc_render::markov::run(scene, &family, &settings, &stop, &NoObserver)
                .expect("mept runs");
            assert_eq!(r.chain_stats.invalid_density, 0, "NaN/inf paths");
            image_mean(&r.image())
        })
        .collect()
}

/// 64 replicates of 40 000 BDPT start-up draws (`mept`'s start-up; up to
/// session 10, 300 000 ordinary candidates), 512 chains, 1024 mutations
/// per pixel (the `mlt` test's budget).
fn mept_replicates() -> &'static [[f64; 3]] {
    static MEPT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    MEPT.get_or_init(|| mept_reps(cornell(), 40_000, 512, 1024, 64, 21_000))
}

#[test]
fn mept_is_mlt_with_the_manifold_perturbation_on() {
    let m = mept_mutations();
    assert_eq!(m.manifold_perturbation, 1.0);
    assert_eq!(m.independent, 0.3);
    assert_eq!(m.lens_perturbation, 0.0);
    // `mlt`'s caustic and multi-chain perturbations (on since session 20)
    // stay off in `mept`, whose measured mixture is without them.
    assert_eq!(m.caustic_perturbation, 0.0);
    assert_eq!(m.multi_chain_perturbation, 0.0);
    assert_eq!(Mept::default().mlt.chain.bootstrap, 200_000);
    assert!(Mept::default().mlt.bdpt_startup);
    // The draws' b alone (session 12): the running estimate merges the
    // heavy-tailed independent proposals.
    assert_eq!(
        Mept::default().mlt.chain.normalization,
        Normalization::Bootstrap
    );
    assert!(!mcmc_render::integrators::mlt::Mlt::default().bdpt_startup);
    // Perturbation sizes: both ends or neither, 0 < min < max.
    let sized = registry::configure(
        None,
        Some("mept"),
        &[
            ("lens_perturbation_min".into(), "0.5".into()),
            ("lens_perturbation_max".into(), "8".into()),
        ],
    )
    .expect("sizes accepted");
    assert_eq!(sized.settings_json()["lens_perturbation_max"], 8.0);
    let mut mlt = mcmc_render::integrators::mlt::Mlt {
        caustic_perturbation_min: 0.2,
        caustic_perturbation_max: 4.0,
        ..Default::default()
    };
    let sizes = mlt.mutations().sizes;
    assert_eq!(sizes.caustic.map(|k| (k.r1, k.r2)), Some((0.2, 4.0)));
    assert_eq!(sizes.lens, None);
    mlt.caustic_perturbation_max = -1.0;
    assert!(
        mlt.sizes().is_err(),
        "one end of a size pair alone is refused"
    );
    for bad in [("0", "4"), ("4", "2"), ("1", "inf")] {
        assert!(
            registry::configure(
                None,
                Some("mept"),
                &[
                    ("multi_chain_perturbation_min".into(), bad.0.into()),
                    ("multi_chain_perturbation_max".into(), bad.1.into()),
                ],
            )
            .is_err(),
            "{bad:?} accepted"
        );
    }
    assert_eq!(
        PathMutations {
            manifold_perturbation: 0.0,
            independent: 0.0,
            lens_perturbation: 1.0,
            caustic_perturbation: 1.0,
            multi_chain_perturbation: 1.0,
            ..m
        },
        mcmc_render::integrators::mlt::Mlt::default().mutations()
    );
    let integ = registry::configure(None, Some("mept"), &[("max_depth".into(), "4".into())])
        .expect("mept is registered");
    assert_eq!(integ.name(), "mept");
    let json = integ.settings_json();
    assert_eq!(json["manifold_perturbation"], 1.0);
    assert_eq!(json["independent_mutation"], 0.3);
    assert!(
        registry::configure(
            None,
            Some("mept"),
            &[("manifold_perturbation".into(), "-1".into())]
        )
        .is_err()
    );
}

#[test]
fn mept_agrees_with_pt_on_the_cornell_box() {
    let a = MeanAgreement::new(pt_reference(), mept_replicates());
    eprintln!("mept: rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "mept disagrees with PT: {a:?}"
    );
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
}

#[test]
fn a_one_percent_bias_is_rejected() {
    let biased: Vec<[f64; 3]> = mept_replicates()
        .iter()
        .map(|m| m.map(|v| v * 1.01))
        .collect();
    let a = MeanAgreement::new(pt_reference(), &biased);
    eprintln!("mept x1.01: rel {:?}\n  {a:?}", a.rel());
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
    assert!(!a.failures(4.0, 0.01).is_empty(), "a 1% bias passed: {a:?}");
}

#[test]
fn mept_images_are_bit_identical_across_thread_counts() {
    // With `unconnectable_chains` too, on caustic-sds (the glossy-glass
    // box has no unconnectable path through a non-Dirac vertex within
    // DEPTH): a second member, and its search continued as the chains run.
    for chains_of_their_own in ["false", "true"] {
        let scene = match chains_of_their_own {
            "true" => repo_scene("caustic-sds.xml", RES),
            _ => repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH),
        };
        let bits = |threads: usize, seed: u64| -> Vec<u32> {
            let integ = registry::configure(
                None,
                Some("mept"),
                &[
                    // caustic-sds's unconnectable paths are ≈ 1 in 15 000
                    // BDPT draws (13 in 200 000 at 128×96).
                    (
                        "bootstrap".into(),
                        match chains_of_their_own {
                            "true" => "100000",
                            _ => "2000",
                        }
                        .into(),
                    ),
                    ("chains".into(), "64".into()),
                    ("mutations_per_pixel".into(), "8".into()),
                    ("unconnectable_chains".into(), chains_of_their_own.into()),
                    // Bounded, as the BDPT draws and member 1 need.
                    (
                        "max_depth".into(),
                        match chains_of_their_own {
                            "true" => "8",
                            _ => "-1",
                        }
                        .into(),
                    ),
                ],
            )
            .expect("mept");
            let run = RunSettings {
                seed,
                ..RunSettings::default()
            };
            let out = with_threads(threads, || {
                integ.render(&scene, &run, &AtomicBool::new(false), &NoObserver)
            })
            .expect("mept runs");
            assert!(image_mean(&out.image)[1] > 0.0, "black image");
            let stats = serde_json::to_string(&out.statistics).unwrap();
            assert!(stats.contains("manifold perturbation"), "{stats}");
            let families = out
                .statistics
                .get("families")
                .and_then(|f| f.as_array())
                .map_or(1, Vec::len);
            let searched = out
                .statistics
                .get("searches")
                .and_then(|s| s[1]["run_draws"].as_u64());
            match chains_of_their_own {
                "true" => assert!(families == 2 && searched > Some(0), "{stats}"),
                _ => assert!(families == 1, "{stats}"),
            }
            out.image
                .iter()
                .flat_map(|p| [p.r.to_bits(), p.g.to_bits(), p.b.to_bits()])
                .collect()
        };
        let one = bits(1, 42);
        assert!(
            one == bits(2, 42),
            "1 vs 2 threads differ ({chains_of_their_own})"
        );
        assert!(one != bits(2, 43), "seed ignored");
    }
}

/// Image means of the PT replicates and of the tested integrator's.
type Replicates = (Vec<[f64; 3]>, Vec<[f64; 3]>);

/// The tilted glossy-glass box (gold glossy, glass sphere: caustics and
/// paths seen through the sphere, where the manifold walk and the
/// generalised geometry term enter the ratio) with its PT replicates and
/// `mept`'s, shared by the agreement test and its control below.
///
/// Sizing (session 19). Run once (2026-11-25, 260 s on the loaded
/// machine) with 128 PT replicates at 256 spp and 96 `mept` replicates of
/// the budget below: rel −0.16%, −0.18%, −0.16% (R/G/B), σ of the
/// difference 0.23%, 0.24%, 0.35%, so 5σ = 1.75% on blue. PT's blue
/// spreads 2.25% per replicate of 256 spp (`path_space_mlt.rs`,
/// `glossy_glass`), an SE of 0.20% at 128 replicates, which leaves
/// √(0.35² − 0.20²) = 0.29% to `mept` (2.8% per replicate). Replicates
/// scale as σ²: PT at 128 × 2048 spp gives 0.07%, and `mept` needs
/// √(0.18² − 0.07²) = 0.166% for a total σ of 0.18% (5σ = 0.9%, a 10%
/// margin for the noise of σ's estimate): 96 × (0.29 / 0.166)² ≈ 290
/// replicates, 288 here. Caveat: that run started from 300 000 ordinary
/// candidates; since 2026-11-26 `mept` starts from 40 000 BDPT draws (the
/// budget below, the Cornell test's, kept so that the per-replicate
/// start-up is `mept`'s own), with which the Cornell test needed 64
/// replicates where 48 had sufficed, so blue's σ here may be up to 15%
/// larger than this sizing assumes.
fn glossy_glass() -> &'static Replicates {
    static REPS: OnceLock<Replicates> = OnceLock::new();
    REPS.get_or_init(|| {
        let scene = repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH);
        let pt = mc_reps(&scene, &pt_of(&scene), 2048, 128, 1000);
        let mept = mept_reps(&scene, 40_000, 512, 1024, 288, 23_000);
        (pt, mept)
    })
}

/// `unconnectable_chains` splits the target: every path the whole target
/// weighs is weighed by exactly one of the two members, with the same
/// `ln I`, and member 1's are the unconnectable paths through a non-Dirac
/// vertex. Exact (no tolerance), over caustic-sds's start-up candidates
/// and camera-walk candidates (member 1's independent proposal), which
/// must include such paths (else the check is empty).
#[test]
fn unconnectable_chains_split_the_target() {
    use mcmc_core::target::Target;
    let scene = repo_scene("caustic-sds.xml", RES);
    let whole = PathFamily::new(&scene, Some(8));
    let split = PathFamily::new(&scene, Some(8)).with_unconnectable_chains(1.0);
    assert_eq!((whole.members(), split.members()), (1, 2));
    let mut rng = mcmc_core::rng::stream_rng(7, 0);
    let (mut lit, mut through_non_dirac) = (0, 0);
    for i in 0..200_000 {
        let path = if i % 2 == 0 {
            whole.draw_candidate(&mut rng)
        } else {
            whole.draw_camera_candidate(&mut rng)
        };
        let all = whole.target(0).evaluate(&path).log_density;
        let parts = [0, 1].map(|m| split.target(m).evaluate(&path).log_density);
        if all == f64::NEG_INFINITY {
            assert_eq!(parts, [f64::NEG_INFINITY; 2]);
            continue;
        }
        lit += 1;
        let member = usize::from(parts[0] == f64::NEG_INFINITY);
        assert_eq!(
            parts[member], all,
            "member {member} weighs the path differently"
        );
        assert_eq!(
            parts[1 - member],
            f64::NEG_INFINITY,
            "both members weigh a path"
        );
        let expected = path.is_unconnectable() && !path.is_specular_chain();
        assert_eq!(member == 1, expected);
        through_non_dirac += usize::from(expected);
    }
    assert!(
        through_non_dirac > 0 && lit > 1000,
        "{through_non_dirac} of {lit}"
    );
}

/// `mept` agrees with PT on the glossy-glass box to 1% (4σ and 1%, and
/// 5σ < 1%; sizing at `glossy_glass`). Ignored for its run time
/// (`cargo test -p mcmc-render --profile test --test path_space_mept --
/// --ignored on_the_glossy_glass_box --nocapture` runs it with its
/// control). Passed once (session 19, 2026-11-27, 2 cores, load 1.7 → 7.6
/// from other builds): rel −0.17%, −0.24%, −0.16% (R/G/B), σ of the
/// difference 0.13%, 0.13%, 0.15% (PT 0.05/0.05/0.07%, `mept`
/// 0.12/0.12/0.14%: blue spreads 2.3% per replicate, less than the 2.8%
/// assumed), so 5σ = 0.77% on blue; the ×1.01 control fails on every
/// channel (5.4–6.4σ). Both tests together: 462 s wall, 306 s CPU
/// (`/usr/bin/time -v`). The means sit 1.0–1.8σ low on every channel, as
/// on 2026-11-25 (−0.16%, −0.18%, −0.16%, with the ordinary start-up and
/// the first 96 of these seeds): not significant, but a bias of ≈ −0.2%
/// is not excluded.
#[test]
#[ignore]
fn mept_agrees_with_pt_on_the_glossy_glass_box() {
    let (pt, mept) = glossy_glass();
    common::assert_agrees_to_one_percent("mept glossy-glass", pt, mept);
}

/// The control of the glossy-glass agreement: the same `mept` replicates
/// scaled by 1.01 must fail it. Ignored with the replicates it scales.
#[test]
#[ignore]
fn a_one_percent_bias_is_rejected_on_the_glossy_glass_box() {
    let (pt, mept) = glossy_glass();
    common::assert_one_percent_bias_is_rejected("mept glossy-glass", pt, mept);
}

/// `mept`'s start-up (`bdpt_startup`, `path_space::bdpt_startup`): the
/// mean of the draws' totals estimates the same `b` as the ordinary
/// bootstrap, and each weighted state, regenerated from its index, is
/// the path whose weight was recorded, with `w = I / Σ_s p_s`.
///
/// Tolerance: both estimates are means of iid terms (the search's draws,
/// the bootstrap's candidates; 60 000 and 1 000 000 of them, far above 30,
/// so the normal quantile applies), each with its sample standard error;
/// the difference must be within 4σ of the combined error, and 4σ must
/// resolve 3% of `b`. Control: the search's states weighted without MIS
/// (`I / p_s` of the split that drew them, every technique counted
/// fully), which overcounts the paths several techniques reach and must
/// be rejected.
#[test]
fn the_bdpt_startup_estimates_the_bootstraps_b() {
    use mcmc_render::markov::ChainFamily;
    use mcmc_render::path_space::bdpt_startup::SEARCH_INDEX;
    let scene = cornell();
    let max = scene.integrator.max_depth as usize;
    let draws = 60_000u64;
    let family = PathFamily::new(scene, Some(max)).with_bdpt_startup(draws);
    assert!(family.has_bdpt_startup());
    let search = family.search(0, 5, &StartupCut::NEVER).expect("a search");
    assert!(search.replaces_bootstrap);
    assert_eq!(search.draws, draws);
    // The search's b: mean and standard error over all draws (zeros too).
    let mean_se = |totals: &[f64]| {
        let n = draws as f64;
        let m = totals.iter().sum::<f64>() / n;
        let ss =
            totals.iter().map(|t| (t - m).powi(2)).sum::<f64>() + (n - totals.len() as f64) * m * m;
        (m, (ss / (n - 1.0) / n).sqrt())
    };
    let totals: Vec<f64> = search.per_draw.iter().map(|lw| lw.exp()).collect();
    let (b_search, se_search) = mean_se(&totals);
    let (boot, _) =
        mcmc_render::markov::bootstrap(&PathFamily::new(scene, Some(max)), 1_000_000, 6)
            .expect("bootstrap");
    let (b_boot, se_boot) = (boot.b(), boot.standard_error());
    let sigma = (se_search.powi(2) + se_boot.powi(2)).sqrt();
    eprintln!("b: search {b_search:.5} ± {se_search:.5}, bootstrap {b_boot:.5} ± {se_boot:.5}");
    assert!(4.0 * sigma < 0.03 * b_boot, "σ {sigma} does not resolve 3%");
    assert!(
        (b_search - b_boot).abs() < 4.0 * sigma,
        "search b {b_search} vs bootstrap {b_boot} (σ {sigma})"
    );
    // Every weighted state, regenerated, carries its recorded weight; and
    // the control's per-draw totals without MIS.
    let mut no_mis = vec![0.0; draws as usize];
    for &(index, log_w) in &search.weighted {
        let x = family.candidate(5, index);
        let k = x.segments();
        let ways: Vec<f64> = (0..=k).map(|s| x.log_regrowth_density(0, k, s)).collect();
        let expected = x.log_density() - mcmc_core::math::log_sum_exp(&ways);
        assert!(
            (expected - log_w).abs() <= 1e-9 * log_w.abs().max(1.0),
            "state {index:#x}: weight {log_w}, regenerated {expected}"
        );
        let i = index - SEARCH_INDEX;
        let s = ((i >> 6) & 63) as usize;
        no_mis[(i >> 12) as usize] += (x.log_density() - ways[s]).exp();
    }
    let (b_wrong, se_wrong) = mean_se(&no_mis);
    let sigma_wrong = (se_wrong.powi(2) + se_boot.powi(2)).sqrt();
    eprintln!("control without MIS: {b_wrong:.5} ± {se_wrong:.5}");
    assert!(
        (b_wrong - b_boot).abs() > 4.0 * sigma_wrong,
        "the control without MIS weights passed"
    );
}

/// With a time budget the specular-chain pass runs for
/// `specular_time_share` of it (so its noise falls with the budget, as
/// the chains' does), never below `specular_samples`; without one, or
/// with a share of 0, it stays at `specular_samples` (session 12: at a
/// fixed 16 spp the pass was all of `mept`'s flat RMSE on caustic-sds).
/// The pass is not reported as interrupted by its own deadline.
#[test]
fn the_specular_pass_takes_its_share_of_a_time_budget() {
    let scene = repo_scene_tilted("cornell-glossy-glass.xml", RES, DEPTH);
    let pass_spp = |share: &str, budget: Option<f64>| -> u64 {
        let integ = registry::configure(
            None,
            Some("mept"),
            &[
                ("bootstrap".into(), "2000".into()),
                ("chains".into(), "64".into()),
                ("mutations_per_pixel".into(), "8".into()),
                ("specular_time_share".into(), share.into()),
            ],
        )
        .expect("mept");
        let run = RunSettings {
            seed: 7,
            time_budget: budget.map(std::time::Duration::from_secs_f64),
            ..RunSettings::default()
        };
        let out = integ
            .render(&scene, &run, &AtomicBool::new(false), &NoObserver)
            .expect("mept runs");
        // The chains may run out of the budget on a loaded machine; the
        // pass's own deadline is not a stop.
        let pass = &out.statistics["specular_pass"];
        assert_eq!(
            pass["interrupted"], false,
            "the pass's deadline counted as a stop"
        );
        pass["samples_per_pixel"]
            .as_u64()
            .expect("specular_pass statistics")
    };
    // 0.3 of 1 s on a 16×16 image: thousands of samples per pixel.
    let timed = pass_spp("0.3", Some(1.0));
    assert!(timed > 16, "the pass kept 16 spp in its 0.3 s: {timed}");
    assert_eq!(pass_spp("0.3", None), 16, "no budget: specular_samples");
    assert_eq!(pass_spp("0", Some(1.0)), 16, "share 0: specular_samples");
    assert!(
        registry::configure(
            None,
            Some("mept"),
            &[("specular_time_share".into(), "1".into())]
        )
        .is_err(),
        "a share of 1 leaves the chains no time"
    );
}

/// Replicate image means of member 1 of `unconnectable_chains` (the paths
/// `L S+ (D S+)* E`) on caustic-sds at `RES`, and of path tracing's
/// estimate of the same class: per seed, the specular-chain pass through
/// diffuse vertices minus the plain pass on the same random numbers (the
/// two count a specular chain identically, so the paired difference is
/// the class alone). Sizes from `UNCONNECTABLE_REPS` (`k_pt,spp,k,chains,mpp`).
fn unconnectable_class() -> Replicates {
    use mcmc_render::path_space::specular_pass::SpecularChains;
    let sizes: Vec<u64> = std::env::var("UNCONNECTABLE_REPS")
        .unwrap_or_else(|_| "128,32768,512,128,1024".into())
        .split(',')
        .map(|v| v.parse().expect("UNCONNECTABLE_REPS: five integers"))
        .collect();
    let [k_pt, spp, k, chains, mpp] = sizes[..] else {
        panic!("UNCONNECTABLE_REPS: five integers")
    };
    let scene = repo_scene("caustic-sds.xml", RES);
    let pass = |through_diffuse| SpecularChains {
        min_depth: 1,
        max_depth: 8,
        through_diffuse,
    };
    let pt: Vec<[f64; 3]> = (0..k_pt)
        .map(|s| {
            let [a, b] = [true, false].map(|d| {
                image_mean(&common::render_image(
                    &scene,
                    &pass(d),
                    spp as u32,
                    5000 + s,
                ))
            });
            [0, 1, 2].map(|c| a[c] - b[c])
        })
        .collect();
    let family = PathFamily::new(&scene, Some(8))
        .with_bdpt_startup(200_000)
        .with_unconnectable_chains(1.0);
    assert_eq!(family.members(), 2);
    let stop = AtomicBool::new(false);
    let chains_member_1: Vec<[f64; 3]> = (0..k)
        .map(|s| {
            let settings = ChainSettings {
                mutation: mept_mutations(),
                bootstrap: 1,
                chains: chains as usize,
                mutations_per_pixel: Some(mpp),
                seed: 9000 + s,
                normalization: Normalization::Bootstrap,
                ..ChainSettings::default()
            };
            let r = mcmc_render::markov::run(&scene, &family, &settings, &stop, &NoObserver)
                .expect("mept runs");
            image_mean(&r.families[1].image())
        })
        .collect();
    (pt, chains_member_1)
}

/// `unconnectable_chains`' member 1 agrees with path tracing on its class
/// (see [`unconnectable_class`]), within 4σ and 10%, with 5σ < 10%; the
/// ×1.10 control must fail. 10%, not 1%: the class is ≈ 8% of caustic-sds's
/// image and heavy-tailed for both estimates. Sizing (session 35): 64 PT
/// replicates of 16 384 spp against 96 of 128 chains × 1024 mutations per
/// pixel gave rel −1.5% (every channel) with σ 4.2% of the class mean;
/// 128 × 32 768 spp against 384 replicates −1.0%, σ 2.08% (5σ = 10.4%:
/// the chains' spread is 38% per replicate); 512 replicates (the default)
/// −1.43%, σ 1.82% (5σ = 9.1%), the ×1.10 control 4.26σ out (2989 s at
/// nice 19 beside CI). Those runs' assertions still read 5% by mistake,
/// so they failed; the figures were checked against the 10% rule by hand.
/// Ignored for its run time (`cargo test --release -p mcmc-render --test
/// path_space_mept -- --ignored unconnectable_chains_agree --nocapture`).
#[test]
#[ignore]
fn unconnectable_chains_agree_with_path_tracing_on_their_class() {
    let (pt, chains) = unconnectable_class();
    let a = MeanAgreement::new(&pt, &chains);
    eprintln!(
        "class mean PT {:?}, chains {:?}, rel {:?}, σ {:?}, standard errors {:?}",
        a.reference,
        a.test,
        a.rel(),
        a.sigma,
        a.se
    );
    assert!(a.resolves(5.0, 0.10), "5σ ≥ 10%: {a:?}");
    assert!(a.failures(4.0, 0.10).is_empty(), "{a:?}");
    let biased: Vec<[f64; 3]> = chains.iter().map(|m| m.map(|v| v * 1.10)).collect();
    let control = MeanAgreement::new(&pt, &biased);
    assert!(
        !control.failures(4.0, 0.10).is_empty(),
        "×1.10 passed: {control:?}"
    );
}

/// A stop during the start-up of the two-member family (Ctrl-C before the
/// chains move) writes both members' start-up estimates: each search's
/// image splats, scaled to the first search's draws (a cut may leave them
/// with different counts), so the image's mean luminance is `b̂₀ + b̂₁`
/// (box filter) to float rounding. Control: member 0's `b̂` alone, which
/// the image must exceed by member 1's share (≈ 8% of it on caustic-sds).
#[test]
fn a_stopped_start_up_with_unconnectable_chains_films_both_members() {
    let scene = repo_scene("caustic-sds.xml", RES);
    let family = PathFamily::new(&scene, Some(8))
        .with_bdpt_startup(1_000_000)
        .with_unconnectable_chains(1.0);
    let settings = ChainSettings {
        mutation: mept_mutations(),
        bootstrap: 1,
        chains: 64,
        mutations_per_pixel: Some(8),
        seed: 5,
        normalization: Normalization::Bootstrap,
        ..ChainSettings::default()
    };
    let stop = AtomicBool::new(true);
    let r = mcmc_render::markov::run(&scene, &family, &settings, &stop, &NoObserver)
        .expect("a stopped start-up still gives an image");
    assert_eq!(r.mutations, 0);
    let image = r.startup_image.as_ref().expect("the start-up's image");
    let mean = image.iter().map(|p| f64::from(p.luminance())).sum::<f64>() / image.len() as f64;
    let b: Vec<f64> = r.families.iter().map(|f| f.bootstrap_b.0).collect();
    let draws: Vec<u64> = r.searches.iter().flatten().map(|s| s.draws).collect();
    eprintln!("mean {mean}, b̂ {b:?}, draws {draws:?}");
    assert!(draws.iter().all(|&d| d < 1_000_000), "not cut: {draws:?}");
    assert!(b[1] > 0.0, "member 1 found no light: {b:?}");
    assert!(
        (mean - (b[0] + b[1])).abs() <= 1e-5 * mean,
        "{mean} vs {b:?}"
    );
    assert!(
        mean - b[0] > 0.02 * mean,
        "member 1 left out: {mean} vs {b:?}"
    );
}
