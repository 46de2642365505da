//! Textures in scene files: what the loader builds (nested textures,
//! `to_uv`, textures inside `twosided` and on specular parameters, as
//! seen through `Scene::bsdf_at` at a hit) and what it refuses, with the
//! line.

use glam::Vec3;
use mcmc_render::bsdf::{Bsdf, OneSided};
use mcmc_render::color::Rgb;
use mcmc_render::geometry::Ray;
use mcmc_render::scene::Scene;
use std::path::Path;

fn load(body: &str) -> Result<Scene, String> {
    let text = format!("<scene version=\"3.0.0\"><sensor type=\"perspective\"/>\n{body}\n</scene>");
    Scene::load_str(&text, Path::new("t.xml"), Path::new(".")).map_err(|e| e.to_string())
}

/// The BSDF at the point of the unit rectangle (z = 0) at object (x, y).
fn bsdf_at(s: &Scene, x: f32, y: f32) -> Bsdf {
    let hit = s
        .intersect(&Ray::new(Vec3::new(x, y, 1.0), Vec3::NEG_Z))
        .expect("hit");
    *s.bsdf_at(&hit.sp)
}

#[test]
fn nested_checkerboards_inside_twosided() {
    // Outer board: 2×2 cells over the rectangle (to_uv scale 1); its
    // color0 is itself a board with 4×4 cells (scale 2) of 0.9 / 0.1.
    let s = load(
        r#"<shape type="rectangle"><bsdf type="twosided"><bsdf type="diffuse">
  <texture type="checkerboard" name="reflectance">
    <texture type="checkerboard" name="color0">
      <rgb name="color0" value="0.9"/><rgb name="color1" value="0.1"/>
      <transform name="to_uv"><scale x="2" y="2"/></transform>
    </texture>
    <rgb name="color1" value="0.5, 0.25, 0"/>
  </texture>
</bsdf></bsdf></shape>"#,
    )
    .unwrap();
    let refl = |x, y| match bsdf_at(&s, x, y) {
        Bsdf::TwoSided(OneSided::Diffuse(d)) => d.reflectance,
        b => panic!("{b:?}"),
    };
    // uv = ((x+1)/2, (y+1)/2). (−0.9, −0.9): uv (0.05, 0.05), outer
    // color0; inner uv (0.1, 0.1): color0 = 0.9.
    assert_eq!(refl(-0.9, -0.9), Rgb::splat(0.9));
    // (−0.4, −0.9): uv (0.3, 0.05), outer color0; inner (0.6, 0.1): 0.1.
    assert_eq!(refl(-0.4, -0.9), Rgb::splat(0.1));
    // (0.5, −0.9): uv (0.75, 0.05): outer color1.
    assert_eq!(refl(0.5, -0.9), Rgb::new(0.5, 0.25, 0.0));
}

#[test]
fn textured_specular_reflectance_of_a_conductor() {
    let s = load(
        r#"<shape type="rectangle"><bsdf type="roughconductor">
  <texture type="checkerboard" name="specular_reflectance"/>
</bsdf></shape>"#,
    )
    .unwrap();
    let spec = |x, y| match bsdf_at(&s, x, y) {
        Bsdf::RoughConductor(c) => c.specular_reflectance,
        b => panic!("{b:?}"),
    };
    // Mitsuba's defaults 0.4 and 0.2.
    assert_eq!(spec(-0.5, -0.5), Rgb::splat(0.4));
    assert_eq!(spec(0.5, -0.5), Rgb::splat(0.2));
}

#[test]
fn refusals_name_the_line() {
    let shape = |bsdf: &str| format!("<shape type=\"rectangle\">\n{bsdf}\n</shape>");
    for (body, needles) in [
        (
            shape(
                r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.5"/><texture type="checkerboard" name="reflectance"/></bsdf>"#,
            ),
            &["t.xml:3", "'reflectance' is given twice"][..],
        ),
        (
            shape(
                r#"<bsdf type="roughconductor"><texture type="checkerboard" name="alpha"/></bsdf>"#,
            ),
            &["t.xml:3", "'alpha'", "cannot be a texture"][..],
        ),
        (
            shape(r#"<bsdf type="diffuse"><texture type="checkerboard"/></bsdf>"#),
            &["t.xml:3", "needs a 'name'"][..],
        ),
        (
            shape(r#"<bsdf type="diffuse"><texture type="noise" name="reflectance"/></bsdf>"#),
            &["t.xml:3", "unsupported texture \"noise\""][..],
        ),
        (
            shape(
                "<bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\">\n<string name=\"filename\" value=\"x.png\"/>\n<string name=\"wrap_mode\" value=\"wrap\"/></texture></bsdf>",
            ),
            &["t.xml:5", "unknown wrap_mode \"wrap\""][..],
        ),
        (
            shape(r#"<bsdf type="diffuse"><texture type="bitmap" name="reflectance"/></bsdf>"#),
            &["t.xml:3", "needs a 'filename'"][..],
        ),
        (
            shape(
                r#"<bsdf type="diffuse"><texture type="checkerboard" name="reflectance"><transform name="to_uv"><matrix value="1 0 0 0  0 1 0 0  0 0 1 0  1 0 0 1"/></transform></texture></bsdf>"#,
            ),
            &["t.xml:3", "to_uv"][..],
        ),
    ] {
        let e = load(&body).err().expect("refused");
        for n in needles {
            assert!(e.contains(n), "'{n}' missing from: {e}");
        }
    }
}
