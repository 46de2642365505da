//! Our path tracer against the committed Mitsuba 3 references of the
//! feature scenes in `scenes/` (`scenes/reference/NAME.json`, made by
//! `scenes/tools/mitsuba_reference.py`: per-channel image means over 8
//! Mitsuba seeds with their standard error), so CI needs no Python.
//!
//! Tolerance: our mean comes from `K` = 16 replicates with distinct fixed
//! seeds (SE = sd/√K); σ = √(SE_ours² + SE_mitsuba²). A channel passes
//! when it is within 4σ (two-sided false-alarm rate ≈ 1e-3 for Student's t
//! with 15 degrees of freedom) and within 1%, and 5σ < 1% is asserted, so
//! a 1% discrepancy would be rejected with probability ≈ 0.84. The control
//! scales our replicates by 1.01 and must fail.

mod common;

use common::{MeanAgreement, image_mean, mean_se, pt_of, render_image};
use mcmc_render::scene::Scene;
use std::collections::HashMap;

/// Mitsuba's per-channel mean and standard error for a reference.
fn mitsuba_reference(name: &str) -> ([f64; 3], [f64; 3]) {
    let path = common::repo_scene_path("reference").join(format!("{name}.json"));
    let text = std::fs::read_to_string(&path).expect("reference JSON");
    let json: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
    let triple = |key: &str| -> [f64; 3] {
        let v = json[key].as_array().expect("array");
        [0, 1, 2].map(|c| v[c].as_f64().expect("number"))
    };
    (triple("mean"), triple("se"))
}

/// Our PT image means over 16 seeds at the reference's default settings.
fn ours(name: &str, spp: u32) -> Vec<[f64; 3]> {
    ours_with(name, spp, &HashMap::new())
}

/// [`ours`] with `<default>` values overridden by `defines`.
fn ours_with(name: &str, spp: u32, defines: &HashMap<String, String>) -> Vec<[f64; 3]> {
    let scene = Scene::load(&common::repo_scene_path(&format!("{name}.xml")), defines)
        .expect("scene loads");
    let pt = pt_of(&scene);
    (0..16)
        .map(|s| image_mean(&render_image(&scene, &pt, spp, 50 + s)))
        .collect()
}

/// The agreement of our replicates `reps` with Mitsuba's mean.
fn against_mitsuba(name: &str, reps: &[[f64; 3]]) -> MeanAgreement {
    let (reference, se_ref) = mitsuba_reference(name);
    let (test, se_test) = mean_se(reps);
    MeanAgreement {
        reference,
        test,
        se: (se_ref, se_test),
        sigma: [0, 1, 2].map(|c| se_ref[c].hypot(se_test[c])),
    }
}

/// Checks scene `name` at `spp` per replicate, and that the same
/// replicates scaled by 1.01 are rejected (the control).
fn check_scene(name: &str, spp: u32) {
    let reps = ours(name, spp);
    let a = against_mitsuba(name, &reps);
    eprintln!("{name}: rel {:?}\n  {a:?}", a.rel());
    assert!(a.resolves(5.0, 0.01), "{name}: noise too large: {a:?}");
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "{name} differs from Mitsuba: {a:?}"
    );
    let biased: Vec<[f64; 3]> = reps.iter().map(|m| m.map(|v| v * 1.01)).collect();
    let b = against_mitsuba(name, &biased);
    assert!(
        !b.failures(4.0, 0.01).is_empty(),
        "{name}: a 1% bias passed: {b:?}"
    );
}

#[test]
fn environment_and_directional_light_match_mitsuba() {
    check_scene("envmap-spheres", 32);
}

#[test]
fn spot_light_matches_mitsuba() {
    check_scene("spot-floor", 32);
}

#[test]
fn thin_lens_crop_window_and_tent_filter_match_mitsuba() {
    check_scene("dof-spheres", 16);
}

#[test]
fn textured_normal_interpolated_plastic_under_an_environment_matches_mitsuba() {
    check_scene("env-textured-plastic", 16);
}

#[test]
fn normal_and_bump_maps_match_mitsuba() {
    check_scene("normalmap-bumpmap", 16);
    // Control: the floor without its bumps (scale 0) reads ~+2.5% and
    // must be rejected.
    let flat = [("floor_bump".to_string(), "0".to_string())].into();
    let a = against_mitsuba(
        "normalmap-bumpmap",
        &ours_with("normalmap-bumpmap", 16, &flat),
    );
    eprintln!("flat floor: rel {:?}", a.rel());
    assert!(
        !a.failures(4.0, 0.01).is_empty(),
        "a flat floor passed: {a:?}"
    );
}

#[test]
fn alpha_cut_outs_match_mitsuba() {
    check_scene("mask-leaves", 16);
    // Control: another opacity image (the grey height field of the bump
    // test) must be rejected.
    let other = [("leaf_mask".to_string(), "textures/bumps.png".to_string())].into();
    let a = against_mitsuba("mask-leaves", &ours_with("mask-leaves", 16, &other));
    eprintln!("other mask: rel {:?}", a.rel());
    assert!(
        !a.failures(4.0, 0.01).is_empty(),
        "another opacity image passed: {a:?}"
    );
}
