//! Emitters at infinity (an environment map and a directional light) in
//! every integrator: LT, BDPT, PSSMLT (over PT and over BDPT) and MMLT
//! agree with path tracing to 1% of the image mean, per channel, on
//! `scenes/envmap-spheres.xml` at 16×16 and `max_depth` 5; so do LT, BDPT
//! and MMLT on the spot light of `scenes/spot-floor.xml`, and LT, BDPT,
//! PSSMLT and MMLT through the thin lens, crop window and tent filter of
//! `scenes/dof-spheres.xml` (a 16×16 window of a 32×24 frame); and LT,
//! BDPT, PSSMLT and MMLT on `scenes/env-textured-plastic.xml` (a textured
//! floor and sphere, a rough-plastic mesh with interpolated normals, an
//! environment map), issue 12's combined check, where `guided`, `relt`,
//! `tempered-pssmlt`, `mcmc-vcm` and (with merging, radius reduced)
//! `vcm` and `mcmc-vcm` agree too (`mlt`, `mept`, `erpt` and `fused`
//! handle emitters at infinity since session 19: `path_space_mlt.rs`,
//! under a sky; `fused.rs`, its inverses' round trips). (Agreement with
//! Mitsuba 3: `mitsuba_scenes.rs`; BDPT's MIS weights with an environment
//! are checked exactly in `bdpt_mis.rs`.)
//!
//! The environment is seen directly above the horizon, so the test covers
//! each estimator's way of reaching it: PT's escaped rays (MIS against
//! light sampling), LT's splat of the environment seen by the pinhole,
//! BDPT's technique (0, t) ending at infinity and light subpaths that start
//! on the scene's bounding disk, and MMLT's depth 1 on the environment.
//!
//! Tolerances as in `agree_mlt.rs`: `K` replicates with distinct fixed
//! seeds, the standard error of each mean is sd(replicate means)/√K, a
//! channel passes when the difference to PT is within 4σ and 1%, and the
//! budgets make 5σ < 1% (σ the SE of the difference, asserted), so a 1%
//! discrepancy fails with probability ≈ 0.84. The control shows that a
//! 1% bias is rejected.

mod common;

use common::{Budget, MeanAgreement, Mlt, bdpt_of, lt_of, mc_reps, mlt_reps, pt_of};
use mcmc_render::integrators::Integrator;
use mcmc_render::scene::Scene;
use std::collections::HashMap;
use std::sync::OnceLock;

/// A repo scene at 16×16, `max_depth` 5.
fn load(file: &str) -> Scene {
    let defines: HashMap<String, String> = [("width", "16"), ("height", "16"), ("max_depth", "5")]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    Scene::load(&common::repo_scene_path(file), &defines).expect("scene loads")
}

/// The environment scene.
fn scene() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let scene = load("envmap-spheres.xml");
        assert!(scene.lights.environment().is_some());
        scene
    })
}

/// The spot-light scene.
fn spot_scene() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| load("spot-floor.xml"))
}

/// [`mc_reps`] on the environment scene.
fn env_reps(integ: &dyn Integrator, spp: u32, k: u64, seed0: u64) -> Vec<[f64; 3]> {
    mc_reps(scene(), integ, spp, k, seed0)
}

/// PT replicates shared by the tests.
fn pt_reference() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| env_reps(&pt_of(scene()), 256, 32, 100))
}

/// [`mlt_reps`] with this file's budget: 20 000 bootstrap candidates,
/// 256 chains, `mpp` mutations per pixel.
fn mlt_reps_of(scene: &Scene, kind: Mlt, mpp: u64, k: u64, seed0: u64) -> Vec<[f64; 3]> {
    let budget = Budget {
        bootstrap: 20_000,
        chains: 256,
        mpp,
    };
    mlt_reps(scene, kind, budget, k, seed0)
}

/// [`mlt_reps_of`] on the environment scene.
fn env_mlt_reps(kind: Mlt, mpp: u64, k: u64, seed0: u64) -> Vec<[f64; 3]> {
    mlt_reps_of(scene(), kind, mpp, k, seed0)
}

/// Asserts agreement with the environment scene's PT within 4σ and 1%,
/// with 5σ < 1%.
fn check(what: &str, test: &[[f64; 3]]) -> MeanAgreement {
    check_against(what, pt_reference(), test)
}

/// Asserts agreement of `test` with `pt` within 4σ and 1%, with 5σ < 1%.
fn check_against(what: &str, pt: &[[f64; 3]], test: &[[f64; 3]]) -> MeanAgreement {
    let a = MeanAgreement::new(pt, test);
    eprintln!("{what}: rel {:?}\n  {a:?}", a.rel());
    assert!(
        a.resolves(5.0, 0.01),
        "{what}: noise too large for 1%: {a:?}"
    );
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "{what} disagrees with PT: {a:?}"
    );
    a
}

#[test]
fn lt_agrees_with_pt_under_an_environment() {
    // Per-replicate spread ~1.7% at 128 light paths per pixel (the
    // environment seen directly is the noisiest part); 32 × 1024 for SE < 0.2%.
    check("lt", &env_reps(&lt_of(scene()), 1024, 32, 200));
}

#[test]
fn bdpt_agrees_with_pt_under_an_environment() {
    check("bdpt", &env_reps(&bdpt_of(scene()), 64, 24, 300));
}

#[test]
fn pssmlt_agrees_with_pt_under_an_environment() {
    check("pssmlt-pt", &env_mlt_reps(Mlt::PssmltPt, 512, 16, 400));
    check("pssmlt-bdpt", &env_mlt_reps(Mlt::PssmltBdpt, 256, 16, 500));
}

/// MMLT replicates, shared by its test and the control.
fn mmlt_reps() -> &'static [[f64; 3]] {
    static MMLT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    MMLT.get_or_init(|| env_mlt_reps(Mlt::Mmlt, 1024, 16, 600))
}

#[test]
fn mmlt_agrees_with_pt_under_an_environment() {
    check("mmlt", mmlt_reps());
}

#[test]
fn a_one_percent_bias_is_rejected() {
    let biased: Vec<[f64; 3]> = mmlt_reps().iter().map(|m| m.map(|v| v * 1.01)).collect();
    let a = MeanAgreement::new(pt_reference(), &biased);
    eprintln!("mmlt x1.01: rel {:?}\n  {a:?}", a.rel());
    assert!(a.resolves(5.0, 0.01), "noise too large for 1%: {a:?}");
    assert!(
        !a.failures(4.0, 0.01).is_empty(),
        "a 1% bias passed the check: {a:?}"
    );
}

#[test]
fn lt_bdpt_and_mmlt_agree_with_pt_under_a_spot_light() {
    let scene = spot_scene();
    let pt = mc_reps(scene, &pt_of(scene), 256, 24, 700);
    check_against("spot lt", &pt, &mc_reps(scene, &lt_of(scene), 256, 24, 800));
    check_against(
        "spot bdpt",
        &pt,
        &mc_reps(scene, &bdpt_of(scene), 128, 24, 900),
    );
    // MMLT's per-replicate spread is ~0.9% per channel here: 32 replicates.
    check_against(
        "spot mmlt",
        &pt,
        &mlt_reps_of(scene, Mlt::Mmlt, 1024, 32, 1000),
    );
}

/// `dof-spheres.xml` as a 16×16 window of a 32×24 frame, `max_depth` 5.
fn lens_scene() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let defines: HashMap<String, String> = [
            ("width", "32"),
            ("height", "24"),
            ("crop_x", "9"),
            ("crop_y", "4"),
            ("crop_width", "16"),
            ("crop_height", "16"),
            ("max_depth", "5"),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
        let scene = Scene::load(&common::repo_scene_path("dof-spheres.xml"), &defines)
            .expect("scene loads");
        assert!(scene.camera.has_lens());
        assert_eq!(scene.camera.resolution(), (16, 16));
        scene
    })
}

/// PT replicates of the lens scene.
fn lens_pt() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| {
        let scene = lens_scene();
        mc_reps(scene, &pt_of(scene), 256, 24, 1100)
    })
}

#[test]
fn lt_bdpt_and_pssmlt_agree_with_pt_through_a_thin_lens() {
    let scene = lens_scene();
    let pt = lens_pt();
    check_against(
        "lens lt",
        pt,
        // Two thirds of LT's paths land outside the window, and the sky
        // seen through the lens is heavy-tailed: ~2% spread per replicate
        // at 4096 light paths per pixel; 64 replicates.
        &mc_reps(scene, &lt_of(scene), 4096, 64, 1200),
    );
    check_against(
        "lens bdpt",
        pt,
        &mc_reps(scene, &bdpt_of(scene), 64, 24, 1300),
    );
    check_against(
        "lens pssmlt-bdpt",
        pt,
        &mlt_reps_of(scene, Mlt::PssmltBdpt, 256, 24, 1400),
    );
}

/// MMLT through the lens: 48 runs (its spread is ~1.3% per replicate at
/// 1024 mutations per pixel); about a minute of 2 cores, so ignored by
/// default: `cargo test -p mcmc-render --test agree_features -- --ignored`.
#[test]
#[ignore]
fn mmlt_agrees_with_pt_through_a_thin_lens() {
    let scene = lens_scene();
    check_against(
        "lens mmlt",
        lens_pt(),
        &mlt_reps_of(scene, Mlt::Mmlt, 1024, 48, 1500),
    );
}

/// `env-textured-plastic.xml` at 16×16 (the combined scene).
fn combined_scene() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| load("env-textured-plastic.xml"))
}

/// PT replicates on the combined scene, shared by its tests.
fn combined_pt() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| mc_reps(combined_scene(), &pt_of(combined_scene()), 256, 24, 1600))
}

#[test]
fn every_integrator_agrees_with_pt_on_a_textured_plastic_scene_under_an_environment() {
    let scene = combined_scene();
    assert!(scene.lights.environment().is_some());
    let pt = combined_pt();
    check_against(
        "combined lt",
        pt,
        &mc_reps(scene, &lt_of(scene), 1024, 32, 1700),
    );
    check_against(
        "combined bdpt",
        pt,
        &mc_reps(scene, &bdpt_of(scene), 64, 24, 1800),
    );
    check_against(
        "combined pssmlt-bdpt",
        pt,
        &mlt_reps_of(scene, Mlt::PssmltBdpt, 256, 24, 1900),
    );
    check_against(
        "combined mmlt",
        pt,
        &mlt_reps_of(scene, Mlt::Mmlt, 1024, 32, 2000),
    );
}

/// `normalmap-bumpmap.xml`: a bump-mapped floor and sphere and a
/// normal-mapped mesh with interpolated normals, under the sky map. The
/// perturbed frames' light-side clip, terminator term and flips (whose
/// importance-mode sampling mixes the two frames) are what LT, BDPT's
/// light subpaths and the Metropolis integrators see differently from PT.
fn perturbed_scene() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| load("normalmap-bumpmap.xml"))
}

/// PT replicates on [`perturbed_scene`].
fn perturbed_pt() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| {
        let scene = perturbed_scene();
        mc_reps(scene, &pt_of(scene), 256, 24, 2100)
    })
}

#[test]
fn lt_and_bdpt_agree_with_pt_under_normal_and_bump_maps() {
    let scene = perturbed_scene();
    check_against(
        "perturbed lt",
        perturbed_pt(),
        &mc_reps(scene, &lt_of(scene), 1024, 32, 2200),
    );
    check_against(
        "perturbed bdpt",
        perturbed_pt(),
        &mc_reps(scene, &bdpt_of(scene), 64, 24, 2300),
    );
}

#[test]
fn pssmlt_and_mmlt_agree_with_pt_under_normal_and_bump_maps() {
    let scene = perturbed_scene();
    check_against(
        "perturbed pssmlt-bdpt",
        perturbed_pt(),
        &mlt_reps_of(scene, Mlt::PssmltBdpt, 256, 24, 2400),
    );
    check_against(
        "perturbed mmlt",
        perturbed_pt(),
        &mlt_reps_of(scene, Mlt::Mmlt, 1024, 32, 2500),
    );
}

/// `mask-leaves.xml` without its sun (`-D sun=0`): alpha cut-outs under
/// the sky. (A delta light seen through a cut-out reaches LT and BDPT but,
/// as in Mitsuba 3's `path`, never PT: masks block shadow rays and BSDF
/// sampling cannot hit a delta light.) LT connects to the camera through
/// masks with their transmittance (the null vertices it cannot sample);
/// PT and BDPT sample the null lobe.
fn mask_scene() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        let defines: HashMap<String, String> = [
            ("width", "16"),
            ("height", "16"),
            ("max_depth", "5"),
            ("sun", "0"),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
        Scene::load(&common::repo_scene_path("mask-leaves.xml"), &defines).expect("scene loads")
    })
}

/// PT replicates on [`mask_scene`].
fn mask_pt() -> &'static [[f64; 3]] {
    static PT: OnceLock<Vec<[f64; 3]>> = OnceLock::new();
    PT.get_or_init(|| {
        let scene = mask_scene();
        mc_reps(scene, &pt_of(scene), 1024, 24, 2600)
    })
}

#[test]
fn lt_and_bdpt_agree_with_pt_through_alpha_cut_outs() {
    let scene = mask_scene();
    check_against(
        "mask lt",
        mask_pt(),
        &mc_reps(scene, &lt_of(scene), 4096, 32, 2700),
    );
    check_against(
        "mask bdpt",
        mask_pt(),
        &mc_reps(scene, &bdpt_of(scene), 256, 24, 2800),
    );
}

#[test]
#[ignore]
fn pssmlt_agrees_with_pt_through_alpha_cut_outs() {
    let scene = mask_scene();
    check_against(
        "mask pssmlt-bdpt",
        mask_pt(),
        &mlt_reps_of(scene, Mlt::PssmltBdpt, 1024, 24, 2900),
    );
}

#[test]
#[ignore]
fn mmlt_agrees_with_pt_through_alpha_cut_outs() {
    // 32 replicates of 4096 mutations per pixel resolved only ~1.4% at
    // 5σ (per-replicate spread ~1.5%): 48 of 16384.
    let scene = mask_scene();
    check_against(
        "mask mmlt",
        mask_pt(),
        &mlt_reps_of(scene, Mlt::Mmlt, 16384, 48, 3000),
    );
}

/// The registered integrators the test above does not cover, on the same
/// scene, run as the command line runs them (`registry::configure` with
/// the scene's `<integrator>` element, whose `max_depth` carries over):
/// `guided` (path guiding over PT) agrees with PT as above. (`vcm` is
/// checked against BDPT on this scene in `vcm.rs` and against PT below;
/// `relt`,
/// `tempered-pssmlt` and `mcmc-vcm` in the next test; `mlt`, `mept`,
/// `erpt` and `fused` under a sky in `path_space_mlt.rs`.)
#[test]
fn guided_agrees_on_the_textured_plastic_scene() {
    use mcmc_render::integrators::registry;
    use mcmc_render::integrators::{Rendered, RunSettings};
    use mcmc_render::observer::NoObserver;
    use std::sync::atomic::AtomicBool;
    let scene = combined_scene();
    let render = |name: &str, spp: u32, seed: u64| -> Result<Rendered, String> {
        let integ = registry::configure(scene.integrator_element.as_ref(), Some(name), &[])?;
        let run = RunSettings {
            spp: Some(spp),
            seed,
            ..RunSettings::default()
        };
        integ
            .render(scene, &run, &AtomicBool::new(false), &NoObserver)
            .map_err(|e| e.to_string())
    };
    // 24 replicates of 256 spp gave σ = 0.20% of the red mean (5σ =
    // 1.0003%, just over the resolution bound), and 32 of 256 no less (the
    // guided replicates' spread is heavy-tailed at 256 spp while the guide
    // learns); 24 of 1024 spp: measured σ 0.09% / 0.08% / 0.06% of the
    // means, rel −0.16% / −0.11% / −0.07% (5 s).
    let guided: Vec<[f64; 3]> = (0..24)
        .map(|k| {
            let r = render("guided", 1024, 2100 + k).expect("guided renders");
            assert_eq!(r.statistics["nonfinite_samples"], 0);
            common::image_mean(&r.image)
        })
        .collect();
    check_against("combined guided", combined_pt(), &guided);
}

/// One run of a registered integrator on `scene` as the command line runs
/// it (`registry::configure` with the scene's `<integrator>` element, whose
/// `max_depth` carries over, and `--set` assignments), `spp` the run's
/// sample count (mutations per pixel come from `sets` for chain families).
fn render_registered(
    scene: &Scene,
    name: &str,
    sets: &[(&str, &str)],
    spp: Option<u32>,
    seed: u64,
) -> Result<mcmc_render::integrators::Rendered, String> {
    use mcmc_render::integrators::{RunSettings, registry};
    use mcmc_render::observer::NoObserver;
    use std::sync::atomic::AtomicBool;
    let sets: Vec<(String, String)> = sets
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    let integ = registry::configure(scene.integrator_element.as_ref(), Some(name), &sets)?;
    let run = RunSettings {
        spp,
        seed,
        ..RunSettings::default()
    };
    integ
        .render(scene, &run, &AtomicBool::new(false), &NoObserver)
        .map_err(|e| e.to_string())
}

/// Image means of `k` registry runs (seeds `seed0..seed0 + k`).
fn registered_reps(
    name: &str,
    sets: &[(&str, &str)],
    spp: Option<u32>,
    k: u64,
    seed0: u64,
) -> Vec<[f64; 3]> {
    (0..k)
        .map(|i| {
            let r = render_registered(combined_scene(), name, sets, spp, seed0 + i)
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            common::image_mean(&r.image)
        })
        .collect()
}

/// The integrators registered since issue 12's list (pt, lt, bdpt,
/// pssmlt, mmlt) and not covered above, on the combined scene:
/// `relt` (replica exchange over BDPT's path classes),
/// `tempered-pssmlt` (tempered replicas over BDPT) and `mcmc-vcm` (MCMC
/// over VCM's light subpaths) handle the environment and agree with PT
/// as above (each asserted to resolve 1% at 5σ; the control: RELT's
/// replicates scaled by 1.01 are rejected). (`fused`, `mlt`, `mept` and
/// `erpt` handle emitters at infinity since session 19: `fused.rs`,
/// `path_space_mlt.rs`.) (`mcmc-vcm` runs in its `bpt`
/// mode, without merging: its merges have a fixed radius, whose bias
/// `vcm.rs` bounds against BDPT but which is no part of this check.)
#[test]
fn relt_tempered_and_mcmc_vcm_agree() {
    let pt = combined_pt();
    let chain = [
        ("bootstrap", "10000"),
        ("chains", "256"),
        ("normalization", "running"),
    ];
    let relt: Vec<[f64; 3]> = registered_reps(
        "relt",
        // l0_search: the size this check was calibrated with (the default
        // became 4 000 000 in session 12).
        &[
            chain[0],
            chain[1],
            ("mutations_per_pixel", "384"),
            ("l0_search", "1000000"),
        ],
        None,
        RELT_REPS.0,
        RELT_REPS.1,
    );
    check_against("combined relt", pt, &relt);
    let biased: Vec<[f64; 3]> = relt.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let a = MeanAgreement::new(pt, &biased);
    eprintln!("relt x1.01: rel {:?}\n  {a:?}", a.rel());
    assert!(
        !a.failures(4.0, 0.01).is_empty(),
        "a 1% bias passed the check: {a:?}"
    );
    check_against(
        "combined tempered-pssmlt",
        pt,
        &registered_reps(
            "tempered-pssmlt",
            &[
                chain[0],
                chain[1],
                chain[2],
                ("levels", "2"),
                ("t_max", "4"),
                ("mutations_per_pixel", "256"),
            ],
            None,
            TEMPERED_REPS.0,
            TEMPERED_REPS.1,
        ),
    );
    check_against(
        "combined mcmc-vcm",
        pt,
        &registered_reps(
            "mcmc-vcm",
            &[("mode", "bpt"), ("candidates", "1024"), ("units", "4")],
            Some(MCMC_VCM_ITERATIONS),
            MCMC_VCM_REPS.0,
            MCMC_VCM_REPS.1,
        ),
    );
}

/// The integrators registered after the test above (issue 12's "any that
/// land meanwhile"): `tempered-mmlt` (tempered replicas per MMLT depth),
/// `mcmc-pg` (PSSMLT over the guided tracer, pre-trained tree) and
/// `smcmc` (stratified MCMC, random replay) handle the environment map and
/// agree with PT on the combined scene. Tolerance and the 5σ < 1%
/// resolution as in `check_against`; the control (a 1% bias rejected) is
/// the RELT one above, on the same PT replicates and machinery.
#[test]
fn tempered_mmlt_mcmc_pg_and_smcmc_agree_on_the_combined_scene() {
    let pt = combined_pt();
    let chain = [("bootstrap", "10000"), ("chains", "256")];
    check_against(
        "combined tempered-mmlt",
        pt,
        &registered_reps(
            "tempered-mmlt",
            &[
                chain[0],
                chain[1],
                ("levels", "2"),
                ("t_max", "4"),
                ("mutations_per_pixel", "512"),
            ],
            None,
            2 * LATER_REPS,
            3400,
        ),
    );
    check_against(
        "combined mcmc-pg",
        pt,
        &registered_reps(
            "mcmc-pg",
            &[
                chain[0],
                chain[1],
                ("nee", "true"),
                ("mutations_per_pixel", "256"),
            ],
            None,
            LATER_REPS,
            3500,
        ),
    );
    check_against(
        "combined smcmc",
        pt,
        &registered_reps(
            "smcmc",
            &[("mutations_per_pixel", "256")],
            None,
            LATER_REPS,
            3600,
        ),
    );
}

/// Replicates of each integrator in the test above (tempered-mmlt: twice
/// as many at half the mutations, because its per-run noise, the start-up
/// and normalisation, did not shrink from 512 to 1024 mutations per pixel:
/// at 16 × 512 5σ reached 1.0%). Measured at load average ~10 (26 Nov):
/// tempered-mmlt −0.14%, +0.07%, +0.10%; mcmc-pg −0.06%, +0.06%, +0.25%;
/// smcmc +0.11%, +0.09%, +0.05%; 35 s of CPU for the three.
const LATER_REPS: u64 = 16;

/// Replicates and first seed of each integrator in the test above. The
/// budgets: at 16 × 1024 mutations per pixel (RELT, tempered PSSMLT) and
/// 16 × 64 iterations (mcmc-vcm) the measured standard errors of the
/// means were 0.09–0.11%, 0.04–0.06% and 0.04–0.06% (PT's 0.03–0.04%),
/// so a quarter of the work (a third for RELT) keeps σ of the difference
/// below ~0.16%, i.e. 5σ < 1% (asserted by `check_against`); 16
/// replicates each, as in the rest of this file. Measured at these
/// budgets (σ of the difference): RELT −0.19%, −0.22%, −0.12% (0.12–0.14%;
/// its ×1.01 control reads +0.78% to +0.88%, 5.9–6.3σ, rejected), tempered
/// PSSMLT −0.17%, −0.14%, −0.13% (0.10–0.12%), mcmc-vcm +0.33%, +0.30%,
/// +0.14% (0.15–0.19%; +0.12%, +0.11%, +0.03% at 64 iterations).
/// mcmc-vcm's 16 × 16 iterations left 5σ at 0.95% (blue) with
/// `con_estimate = direct`; with `transfer` (the default since session 16)
/// the same seeds gave 1.02% and failed the resolution check, and 24
/// replicates still 1.03% (red). Over 24 other seeds the two estimators'
/// image means spread alike (sd 1.10% and 1.12% in red per replicate,
/// docs/vcm.md session 16), so 5σ < 1% in red needs ~30 replicates at 16
/// iterations: the budget was at the edge for both. Now 24 × 32
/// iterations: measured 5σ 0.69%, 0.62%, 0.51% (CLI runs of these seeds,
/// session 16); about 13 s of CPU more than 16 × 16.
/// RELT: 24 replicates since session 24. Under `normalization=filmed`
/// (relt's default since then) the 16 replicates calibrated under
/// `running` gave 5σ = 1.04% in blue (relative σ 0.207%, agreement +0.18%,
/// +0.17%, +0.26%): `filmed`'s scale uses the run's uniform draws only, not
/// the 10 000-candidate bootstrap pool, so short runs spread a little more.
/// 24 replicates bring 5σ to about 1.04%·√(16/24) ≈ 0.85%; measured with
/// them: +0.11%, +0.06%, +0.18% against PT, the ×1.01 control rejected.
const RELT_REPS: (u64, u64) = (24, 3100);
const TEMPERED_REPS: (u64, u64) = (16, 3200);
const MCMC_VCM_REPS: (u64, u64) = (24, 3300);
/// `mcmc-vcm` iterations per replicate (one light subpath per pixel each).
const MCMC_VCM_ITERATIONS: u32 = 32;

/// Image means and merge shares (`energy_shares.merge` of the sidecar) of
/// `k` registry runs on the combined scene.
fn registered_reps_with_merge_share(
    name: &str,
    sets: &[(&str, &str)],
    spp: u32,
    k: u64,
    seed0: u64,
) -> (Vec<[f64; 3]>, f64) {
    let mut merge = 0.0;
    let means = (0..k)
        .map(|i| {
            let r = render_registered(combined_scene(), name, sets, Some(spp), seed0 + i)
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(r.statistics["nonfinite_samples"], 0, "{name}");
            merge += r.statistics["energy_shares"]["merge"]
                .as_f64()
                .expect("merge share");
            common::image_mean(&r.image)
        })
        .collect();
    (means, merge / k as f64)
}

/// Issue 12's last detours closed: `vcm` and `mcmc-vcm`, **with merging**,
/// against PT directly on the combined scene (until now `vcm` was checked
/// against BDPT only, and `mcmc-vcm` with merging against `vcm` only).
///
/// Merging with a fixed radius is biased (photon mapping's blur and corner
/// bias), so both run with SmallVCM's radius reduction, α = 0.75: the
/// radius starts at 15% of the scene's radius (at 5%, as in `vcm.rs`,
/// merging carried 0.6% of the energy here; SmallVCM's 0.3% nothing at
/// 16×16) and shrinks as `i^{(α−1)/2}` (to 0.55× after 128 iterations), so
/// the bias vanishes as the iterations grow; what is left after this budget
/// is below the test's resolution (measured: see the constants below).
/// `mcmc-vcm` with reduction needs `normalisation = iteration` (its
/// render-wide normalisation needs a fixed radius, docs/vcm.md). Each run
/// must give merging a real share of the energy (asserted > 1%), or the
/// check would not test it.
///
/// Tolerance (as the rest of this file): `K` replicates with fixed seeds
/// per estimator; the standard error of each mean is sd(replicate
/// means)/√K and σ that of the difference, √(se_pt² + se_test²). A channel
/// passes when |difference| < 4σ (Student's t with K − 1 = 23 degrees of
/// freedom per mean: two-sided false-alarm rate below 1e-3 per channel) and < 1% of PT's mean; `check_against` also asserts 5σ < 1%,
/// so a 1% discrepancy lies ≥ 5σ out and fails with probability ≈ 0.84.
/// Control: `vcm`'s replicates scaled by 1.01 must fail.
#[test]
fn vcm_with_merging_agrees_with_pt_on_the_textured_plastic_scene() {
    let pt = combined_pt();
    let reduce = MERGE_RADIUS_RULE;
    let (vcm, vcm_merge) = registered_reps_with_merge_share(
        "vcm",
        &reduce,
        VCM_PT.iterations,
        VCM_PT.reps,
        VCM_PT.seed0,
    );
    eprintln!("vcm merge share {vcm_merge}");
    assert!(vcm_merge > 0.01, "vcm merges too little: {vcm_merge}");
    check_against("combined vcm (merging, alpha 0.75)", pt, &vcm);
    let biased: Vec<[f64; 3]> = vcm.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let a = MeanAgreement::new(pt, &biased);
    eprintln!("vcm x1.01: rel {:?}\n  {a:?}", a.rel());
    assert!(
        !a.failures(4.0, 0.01).is_empty(),
        "a 1% bias passed the check: {a:?}"
    );
}

/// `mcmc-vcm` with merging against PT, as the test above (same radius
/// rule and tolerance; the control there applies to this check too).
#[test]
fn mcmc_vcm_with_merging_agrees_with_pt_on_the_textured_plastic_scene() {
    let pt = combined_pt();
    let reduce = MERGE_RADIUS_RULE;
    let (mcmc, mcmc_merge) = registered_reps_with_merge_share(
        "mcmc-vcm",
        &[
            reduce[0],
            reduce[1],
            ("normalisation", "iteration"),
            ("candidates", "1024"),
            ("units", "4"),
        ],
        MCMC_VCM_PT.iterations,
        MCMC_VCM_PT.reps,
        MCMC_VCM_PT.seed0,
    );
    eprintln!("mcmc-vcm merge share {mcmc_merge}");
    assert!(
        mcmc_merge > 0.01,
        "mcmc-vcm merges too little: {mcmc_merge}"
    );
    check_against("combined mcmc-vcm (merging, alpha 0.75)", pt, &mcmc);
}

/// Budget of one estimator in the test above: iterations per replicate,
/// replicates, first seed.
struct RepBudget {
    iterations: u32,
    reps: u64,
    seed0: u64,
}

/// `vcm`: 24 × 128 iterations (as `vcm.rs`). Measured: merging 17% of the
/// energy; +0.11%, +0.08%, +0.20% against PT (σ of the difference 0.11%,
/// 0.09%, 0.06%); the ×1.01 control reads +1.11% to +1.20% (≥ 10σ), rejected.
const VCM_PT: RepBudget = RepBudget {
    iterations: 128,
    reps: 24,
    seed0: 3400,
};
/// `mcmc-vcm`: 24 × 128 iterations (16 × 32 left σ at 0.33–0.43%, 5σ > 1%).
/// Measured: merging 32%; +0.40%, +0.36%, +0.49% (σ 0.10%, 0.11%, 0.14%;
/// `con_estimate = direct`: +0.32%, +0.29%, +0.44%): within 4σ and 1%, but
/// 3.2–3.9σ high. Session 17 (docs/vcm.md) resolved the excess as the merge
/// kernel's bias, which `vcm` shares: over other seeds at this radius rule
/// `vcm` reads +0.30%, +0.21%, +0.31% and `mcmc-vcm` +0.32%, +0.22%, +0.35%
/// against PT (σ ≈ 0.06%), both grow with a fixed radius and vanish
/// without merging. The bias is about 2.5σ of this test's resolution, so
/// these fixed seeds sit near its bound. Both tests together: 17 s of CPU.
const MCMC_VCM_PT: RepBudget = RepBudget {
    iterations: 128,
    reps: 24,
    seed0: 3500,
};
/// The merge radius of both tests above: 15% of the scene's radius at the
/// first iteration, reduced with α = 0.75.
const MERGE_RADIUS_RULE: [(&str, &str); 2] = [("radius_factor", "0.15"), ("alpha", "0.75")];
