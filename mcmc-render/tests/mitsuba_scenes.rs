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
//!
//! Where the reference has a per-pixel variance image (`NAME.var.exr`,
//! `mitsuba_reference.py --variance`), the pixels are compared too: the
//! relMSE between our mean image and Mitsuba's must be the one the two
//! renders' own noise predicts ([`RelMseCheck`]); its control is our image
//! shifted by one pixel, which keeps the mean and must fail.

mod common;

use common::{MeanAgreement, image_mean, mean_se, pt_of, render_image};
use mcmc_render::color::Rgb;
use mcmc_render::scene::Scene;
use statrs::distribution::{ContinuousCDF, StudentsT};
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

/// Our PT images, 16 seeds at the reference's default settings.
fn ours(name: &str, spp: u32) -> Vec<Vec<Rgb>> {
    ours_with(name, spp, &HashMap::new())
}

/// [`ours`] with `<default>` values overridden by `defines`.
fn ours_with(name: &str, spp: u32, defines: &HashMap<String, String>) -> Vec<Vec<Rgb>> {
    let scene = Scene::load(&common::repo_scene_path(&format!("{name}.xml")), defines)
        .expect("scene loads");
    let pt = pt_of(&scene);
    (0..16)
        .map(|s| render_image(&scene, &pt, spp, 50 + s))
        .collect()
}

/// The per-channel image means of replicate images.
fn means(images: &[Vec<Rgb>]) -> Vec<[f64; 3]> {
    images.iter().map(|i| image_mean(i)).collect()
}

/// The pixel comparison of our replicate images with Mitsuba's reference.
///
/// Per pixel p and channel c, with r the reference, t̄ the mean of our K
/// replicates, w = 1/(r² + 0.01) (the weight of `mcmc-render compare`'s
/// relMSE, taken per channel since the variance images are per channel),
/// v_t = s²/K (s² our replicates' unbiased sample variance) and v_r =
/// σ₁²/N (σ₁² Mitsuba's per-sample variance, `NAME.var.exr`, N its total
/// samples per pixel, `total_spp`):
///
///   E[w (t̄ − r)²] = w (v_t + v_r + δ²),
///
/// δ the difference between the two renderers' expected pixels. So the
/// predicted relMSE is mean w (v_t + v_r), the observed one mean w (t̄ −
/// r)², and e = w ((t̄ − r)² − v_t − v_r) is an unbiased estimate of w δ²,
/// zero when both converge to the same image. (The weights use the
/// 4096-spp reference; their correlation with its own noise changes the
/// expectation by a relative O(v_r/r²), far below the tolerance.) The
/// excess, the mean of e, gets its standard error from the spread of its
/// means over 4 × 4-pixel tiles (384 on a 96 × 64 image). Neighbouring
/// pixels share samples through the reconstruction filter (within 2
/// pixels, weights ≤ e⁻² beyond one), so pixels are not independent; but
/// e is quadratic in the pixel errors, whose correlation ρ between
/// neighbours enters as ρ² (a few percent), and only tile borders share
/// samples, so the tiles are independent to that order. The check passes
/// when the excess lies within Student's t quantile (two-sided 1e-3, B − 1
/// degrees of freedom) of that standard error. Small tiles matter for
/// power: a difference confined to edges (a one-pixel shift) lands in a
/// fraction f of the B tiles and is found at about √(B f/(1 − f))
/// standard errors.
#[derive(Debug)]
struct RelMseCheck {
    observed: f64,
    predicted: f64,
    excess: f64,
    se: f64,
    tiles: usize,
    /// The tiles with the largest excess: (x, y) of the tile's corner
    /// in pixels, its mean excess (diagnostics, printed by the tests).
    worst: Vec<(u32, u32, f64)>,
}

/// Side of the square tiles of [`RelMseCheck`], in pixels.
const TILE: u32 = 4;

impl RelMseCheck {
    fn new(name: &str, images: &[Vec<Rgb>]) -> RelMseCheck {
        let dir = common::repo_scene_path("reference");
        let (w, h, reference) =
            mcmc_render::image_io::read_exr(&dir.join(format!("{name}.exr"))).expect("reference");
        let (vw, vh, var1) = mcmc_render::image_io::read_exr(&dir.join(format!("{name}.var.exr")))
            .expect("variance image");
        let json: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join(format!("{name}.json"))).expect("reference JSON"),
        )
        .expect("valid JSON");
        let n_ref = json["total_spp"].as_f64().expect("total_spp");
        assert_eq!((w, h), (vw, vh));
        assert_eq!(images[0].len(), (w * h) as usize, "resolution");
        assert!(w % TILE == 0 && h % TILE == 0);
        let k = images.len() as f64;
        let tiles_x = w / TILE;
        let mut tiles = vec![0.0f64; (tiles_x * (h / TILE)) as usize];
        let (mut observed, mut predicted) = (0.0, 0.0);
        for y in 0..h {
            for x in 0..w {
                let i = (y * w + x) as usize;
                for c in 0..3 {
                    let ch = |p: &Rgb| p.to_array()[c] as f64;
                    let r = ch(&reference[i]);
                    let mean = images.iter().map(|img| ch(&img[i])).sum::<f64>() / k;
                    let s2 = images
                        .iter()
                        .map(|img| (ch(&img[i]) - mean).powi(2))
                        .sum::<f64>()
                        / (k - 1.0);
                    let weight = 1.0 / (r * r + 0.01);
                    let d2 = weight * (mean - r).powi(2);
                    let v = weight * (s2 / k + ch(&var1[i]) / n_ref);
                    observed += d2;
                    predicted += v;
                    tiles[((y / TILE) * tiles_x + x / TILE) as usize] += d2 - v;
                }
            }
        }
        let n = (w * h * 3) as f64;
        let per_tile = (TILE * TILE * 3) as f64;
        let tiles: Vec<f64> = tiles.iter().map(|t| t / per_tile).collect();
        let (excess, se) = common::mean_se1(&tiles);
        let mut worst: Vec<(u32, u32, f64)> = tiles
            .iter()
            .enumerate()
            .map(|(i, &e)| {
                let i = i as u32;
                ((i % tiles_x) * TILE, (i / tiles_x) * TILE, e)
            })
            .collect();
        worst.sort_by(|a, b| b.2.total_cmp(&a.2));
        worst.truncate(5);
        RelMseCheck {
            observed: observed / n,
            predicted: predicted / n,
            excess,
            se,
            tiles: tiles.len(),
            worst,
        }
    }

    /// True when the excess is within the noise (see [`RelMseCheck`]).
    fn passes(&self) -> bool {
        let t = StudentsT::new(0.0, 1.0, (self.tiles - 1) as f64)
            .expect("valid")
            .inverse_cdf(1.0 - 0.5e-3);
        self.excess.abs() <= t * self.se
    }
}

/// Our images shifted one pixel right and one down (the first row and
/// column repeated), so that edges of either orientation move: the image
/// mean barely changes, the pixels do.
fn shifted(images: &[Vec<Rgb>], width: usize) -> Vec<Vec<Rgb>> {
    images
        .iter()
        .map(|img| {
            (0..img.len())
                .map(|i| {
                    let (x, y) = (i % width, i / width);
                    img[y.saturating_sub(1) * width + x.saturating_sub(1)]
                })
                .collect()
        })
        .collect()
}

/// The pixel check of scene `name` against its reference, and its
/// control: `control` (by default our images shifted by a pixel
/// diagonally) must fail.
fn check_pixels(name: &str, images: &[Vec<Rgb>], control: Option<&[Vec<Rgb>]>) {
    let check = RelMseCheck::new(name, images);
    eprintln!(
        "{name}: relMSE observed/predicted {:.4}, {check:?}",
        check.observed / check.predicted
    );
    eprintln!("{name}: tiles with the largest excess {:?}", check.worst);
    assert!(check.passes(), "{name}: relMSE beyond the noise: {check:?}");
    let moved = match control {
        Some(control) => RelMseCheck::new(name, control),
        None => {
            let width = mcmc_render::image_io::read_exr(
                &common::repo_scene_path("reference").join(format!("{name}.exr")),
            )
            .expect("reference")
            .0 as usize;
            RelMseCheck::new(name, &shifted(images, width))
        }
    };
    eprintln!("{name}, control: {moved:?}");
    assert!(!moved.passes(), "{name}: the control passed: {moved:?}");
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
    check_images(name, &ours(name, spp), None);
}

/// [`check_scene`] on our replicate `images`, with `pixel_control` in
/// place of the shifted images as the pixel check's control.
fn check_images(name: &str, images: &[Vec<Rgb>], pixel_control: Option<&[Vec<Rgb>]>) {
    let reps = means(images);
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
    if common::repo_scene_path("reference")
        .join(format!("{name}.var.exr"))
        .exists()
    {
        check_pixels(name, images, pixel_control);
    }
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
        &means(&ours_with("normalmap-bumpmap", 16, &flat)),
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
    let a = against_mitsuba("mask-leaves", &means(&ours_with("mask-leaves", 16, &other)));
    eprintln!("other mask: rel {:?}", a.rel());
    assert!(
        !a.failures(4.0, 0.01).is_empty(),
        "another opacity image passed: {a:?}"
    );
}

#[test]
fn textured_roughness_and_scene_level_textures_match_mitsuba() {
    check_scene("textured-roughness", 32);
    // Control: the floor's roughness board replaced by a constant 0.2
    // (`-D floor_rough=flat_rough`): the means move by about 1% (Mitsuba
    // 16 spp), and the pixels far more.
    let flat = [("floor_rough".to_string(), "flat_rough".to_string())].into();
    let images = ours_with("textured-roughness", 32, &flat);
    let a = against_mitsuba("textured-roughness", &means(&images));
    let pixels = RelMseCheck::new("textured-roughness", &images);
    eprintln!("flat floor roughness: rel {:?}, {pixels:?}", a.rel());
    assert!(
        !pixels.passes(),
        "a constant floor roughness passed: {pixels:?}"
    );
}

#[test]
fn anisotropic_roughness_follows_the_uv_tangent_as_in_mitsuba() {
    // The floor, cube, analytic sphere, UV mesh and UV-less mesh all carry
    // anisotropic microfacet BSDFs; an arbitrary tangent (as before this
    // test) or swapped roughnesses move the means by a few percent.
    // Control: alpha_u and alpha_v swapped (-4.3/-2.8/+3.0% at 256 spp).
    // It replaces the shifted image as the pixel control, which the
    // bright, sharp cube-top highlight makes too heavy-tailed to reject.
    let swapped = [
        ("au".to_string(), "0.4".to_string()),
        ("av".to_string(), "0.04".to_string()),
    ]
    .into();
    let swapped = ours_with("anisotropic", 16, &swapped);
    check_images("anisotropic", &ours("anisotropic", 64), Some(&swapped));
    let b = against_mitsuba("anisotropic", &means(&swapped));
    eprintln!("swapped roughness: rel {:?}", b.rel());
    assert!(
        !b.failures(4.0, 0.01).is_empty(),
        "swapped roughness passed: {b:?}"
    );
    // BDPT builds its frames elsewhere (path vertices, connections).
    let scene = Scene::load(&common::repo_scene_path("anisotropic.xml"), &HashMap::new())
        .expect("scene loads");
    let bdpt = common::bdpt_of(&scene);
    let reps: Vec<[f64; 3]> = (0..16)
        .map(|s| image_mean(&render_image(&scene, &bdpt, 8, 70 + s)))
        .collect();
    let a = against_mitsuba("anisotropic", &reps);
    eprintln!("anisotropic bdpt: rel {:?}", a.rel());
    assert!(
        a.failures(4.0, 0.01).is_empty(),
        "bdpt differs from Mitsuba: {a:?}"
    );
}

/// The pixel check alone (no means: at 64×64 with the light in view, 1% of
/// the mean takes more samples than the default suite affords) on the
/// 64×64 feature boxes, whose variance images are 8 × 64-spp Mitsuba runs.
/// Ignored for its budget (~40 s). With the exact Gaussian in our film
/// instead of Mitsuba's discretized table it failed on `textured.xml`
/// (relMSE observed/predicted 1.30, excess 3.9 standard errors, at the
/// ceiling light's edges); see the issue 12 status in docs/rendering.md.
/// `cargo test -p mcmc-render --test mitsuba_scenes -- --ignored --nocapture`
#[test]
#[ignore]
fn pixels_of_the_64_pixel_boxes_match_mitsuba() {
    let mut failed = Vec::new();
    for (name, spp) in [
        ("cornell-plastic", 32),
        ("cornell-roughplastic", 32),
        ("cornell-thindielectric", 32),
        ("textured", 32),
    ] {
        let c = RelMseCheck::new(name, &ours(name, spp));
        eprintln!(
            "{name}: relMSE observed/predicted {:.3}, {c:?}",
            c.observed / c.predicted
        );
        if !c.passes() {
            failed.push(name);
        }
    }
    assert!(failed.is_empty(), "relMSE beyond the noise: {failed:?}");
}

/// The film's Gaussian weights are Mitsuba 3.9.1's discretized filter
/// (`eval_discretized`, which its CPU `ImageBlock::put` uses; the values
/// below were printed by Mitsuba for the default `gaussian`), not the
/// exact Gaussian, which differs by up to 8% (e.g. 0.8822 at 0.25).
/// Tolerance: Mitsuba's fast exponential differs from the exact one
/// (measured against Mitsuba's own `eval`: 0.999247 against 1 − e⁻⁸ at 0,
/// 1.1e-3 relative at 1.5, 1e-5 absolute at 1.75), so 2e-3 relative plus
/// 2e-5 absolute; the exact Gaussian differs from the table by 5–10% near
/// the peak and by 1.2e-4 at 1.75, so the check tells them apart.
#[test]
fn film_weights_are_mitsubas_discretized_filter() {
    use mcmc_render::film::Filter;
    use mcmc_render::scene::FilterKind;
    let f = Filter::new(FilterKind::Gaussian { stddev: 0.5 }, 8, 8);
    for (x, mitsuba) in [
        (0.0f32, 0.999_247_1f32),
        (0.2, 0.927_350),
        (0.25, 0.927_350),
        (-0.5, 0.664_957),
        (0.75, 0.364_836),
        (-0.8, 0.301_145),
        (1.0, 0.153_261),
        (1.25, 0.049_200),
        (1.5, 0.011_880),
        (1.75, 0.001_969),
        (1.99, 0.000_220_8),
        (2.01, 0.0),
    ] {
        let ours = f.eval_1d(x);
        assert!(
            (ours - mitsuba).abs() <= 2e-3 * mitsuba + 2e-5,
            "x = {x}: {ours} against Mitsuba's {mitsuba}"
        );
    }
}
