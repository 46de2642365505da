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
    *s.bsdf_at(&hit.sp).model()
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
                r#"<bsdf type="roughplastic"><texture type="checkerboard" name="alpha"/></bsdf>"#,
            ),
            &["t.xml:3", "'alpha' must be a number here", "roughplastic"][..],
        ),
        (
            shape(
                r#"<bsdf type="roughconductor"><float name="alpha" value="0.2"/><texture type="checkerboard" name="alpha"/></bsdf>"#,
            ),
            &["t.xml:3", "'alpha' is given twice"][..],
        ),
        (
            shape(
                r#"<bsdf type="roughdielectric"><texture type="checkerboard" name="alpha_u"/></bsdf>"#,
            ),
            &[
                "t.xml:3",
                "give either 'alpha' or both 'alpha_u' and 'alpha_v'",
            ][..],
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

/// `normalmap` and `bumpmap` refusals: one line with the line number.
#[test]
fn perturbation_refusals_name_the_line() {
    let shape = |bsdf: &str| format!("<shape type=\"rectangle\">\n{bsdf}\n</shape>");
    let bumps = r#"<texture type="bitmap"><string name="filename" value="../scenes/textures/bumps.png"/></texture>"#;
    for (body, needles) in [
        (
            shape(
                r#"<bsdf type="normalmap"><texture type="checkerboard" name="normalmap"/></bsdf>"#,
            ),
            &["t.xml:3", "normalmap needs a nested <bsdf>"][..],
        ),
        (
            shape(r#"<bsdf type="normalmap"><bsdf type="diffuse"/></bsdf>"#),
            &["t.xml:3", "normalmap needs a <texture name=\"normalmap\">"][..],
        ),
        (
            shape(
                "<bsdf type=\"bumpmap\">\n<texture type=\"checkerboard\"/><bsdf type=\"diffuse\"/></bsdf>",
            ),
            &["t.xml:4", "bumpmap needs a bitmap texture"][..],
        ),
        (
            shape(&format!(
                r#"<bsdf type="bumpmap">{bumps}<bsdf type="diffuse"/><bsdf type="diffuse"/></bsdf>"#
            )),
            &["t.xml:3", "exactly one nested"][..],
        ),
        (
            shape(&format!(
                r#"<bsdf type="bumpmap">{bumps}<bsdf type="normalmap"><texture type="checkerboard" name="normalmap"/><bsdf type="diffuse"/></bsdf></bsdf>"#
            )),
            &["t.xml:3", "cannot wrap another normalmap or bumpmap"][..],
        ),
        (
            shape(&format!(
                r#"<bsdf type="twosided"><bsdf type="bumpmap">{bumps}<bsdf type="diffuse"/></bsdf></bsdf>"#
            )),
            &["t.xml:3", "twosided cannot wrap normalmap, bumpmap or mask"][..],
        ),
        (
            shape(&format!(
                r#"<bsdf type="bumpmap">{bumps}<ref id="nothing"/></bsdf>"#
            )),
            &["t.xml:3", "no <bsdf id=\"nothing\">"][..],
        ),
        (
            shape(
                "<bsdf type=\"bumpmap\"><texture type=\"bitmap\">\n<string name=\"filename\" value=\"missing.png\"/></texture><bsdf type=\"diffuse\"/></bsdf>",
            ),
            &["t.xml:4", "cannot load texture", "missing.png"][..],
        ),
        (
            shape(&format!(
                r#"<bsdf type="bumpmap">{bumps}<float name="strength" value="2"/><bsdf type="diffuse"/></bsdf>"#
            )),
            &["t.xml:3", "strength"][..],
        ),
    ] {
        let e = load(&body).err().expect("refused");
        assert!(!e.contains('\n'), "not one line: {e}");
        for n in needles {
            assert!(e.contains(n), "'{n}' missing from: {e}");
        }
    }
}

/// A constant normal map (0.8, 0.5, 0.8) tilts the rectangle's frame
/// towards its ∂p/∂u (object +x): the radiance-mode value times the
/// cosine about the shading normal is the nested diffuse value times the
/// cosine about the normalised (0.6, 0, 0.6) — Mitsuba's definition —
/// and an untilted map (0.5, 0.5, 1) gives the nested BSDF back.
#[test]
fn a_constant_normal_map_tilts_the_frame_towards_dp_du() {
    use mcmc_render::bsdf::TransportMode;
    use mcmc_render::frame::Frame;
    let scene = |c: &str| {
        load(&format!(
            r#"<shape type="rectangle"><bsdf type="normalmap"><boolean name="use_shadowing_function" value="false"/>
<texture type="checkerboard" name="normalmap"><rgb name="color0" value="{c}"/><rgb name="color1" value="{c}"/></texture>
<bsdf type="diffuse"><rgb name="reflectance" value="0.6"/></bsdf></bsdf></shape>"#
        ))
        .expect("loads")
    };
    let (tilted, flat) = (scene("0.8, 0.5, 0.8"), scene("0.5, 0.5, 1"));
    let n = Vec3::new(0.6, 0.0, 0.6).normalize();
    let mode = TransportMode::Radiance;
    for (x, y) in [(0.1f32, 0.2f32), (-0.5, 0.7)] {
        for s in [&tilted, &flat] {
            let hit = s
                .intersect(&Ray::new(Vec3::new(x, y, 1.0), Vec3::NEG_Z))
                .expect("hit");
            let frame = Frame::from_normal(hit.sp.ns);
            let b = s.bsdf_at(&hit.sp);
            let wo = frame.to_local(Vec3::new(0.0, 0.3, 1.0).normalize());
            let wi_world = Vec3::new(-0.2, 0.4, 0.8).normalize();
            let wi = frame.to_local(wi_world);
            let f = b.eval(wo, wi, mode).r * wi.z;
            let want = if std::ptr::eq(s, &tilted) {
                0.6 / std::f32::consts::PI * wi_world.dot(n)
            } else {
                0.6 / std::f32::consts::PI * wi_world.z
            };
            assert!((f - want).abs() < 1e-5, "{f} vs {want}");
        }
    }
}

/// `mask` refusals: one line with the line number.
#[test]
fn mask_refusals_name_the_line() {
    let shape = |bsdf: &str| format!("<shape type=\"rectangle\">\n{bsdf}\n</shape>");
    for (body, needles) in [
        (
            shape(r#"<bsdf type="mask"><float name="opacity" value="0.3"/></bsdf>"#),
            &["t.xml:3", "mask needs a nested <bsdf>"][..],
        ),
        (
            shape(
                r#"<bsdf type="twosided"><bsdf type="mask"><bsdf type="diffuse"/></bsdf></bsdf>"#,
            ),
            &["t.xml:3", "twosided cannot wrap normalmap, bumpmap or mask"][..],
        ),
        (
            shape(
                r#"<bsdf type="normalmap"><texture type="checkerboard" name="normalmap"/><bsdf type="mask"><bsdf type="diffuse"/></bsdf></bsdf>"#,
            ),
            &["t.xml:3", "cannot wrap a mask"][..],
        ),
        (
            shape(r#"<bsdf type="mask"><bsdf type="mask"><bsdf type="diffuse"/></bsdf></bsdf>"#),
            &["t.xml:3", "mask cannot wrap another mask"][..],
        ),
        (
            shape(
                "<bsdf type=\"mask\"><bsdf type=\"diffuse\"/>\n<texture type=\"checkerboard\" name=\"alpha\"/></bsdf>",
            ),
            &["t.xml:4", "mask takes one <texture name=\"opacity\">"][..],
        ),
        (
            shape(
                "<bsdf type=\"mask\"><bsdf type=\"diffuse\"/><texture type=\"bitmap\" name=\"opacity\">\n<string name=\"filename\" value=\"leaf-missing.png\"/></texture></bsdf>",
            ),
            &["t.xml:4", "cannot load texture", "leaf-missing.png"][..],
        ),
    ] {
        let e = load(&body).err().expect("refused");
        assert!(!e.contains('\n'), "not one line: {e}");
        for n in needles {
            assert!(e.contains(n), "'{n}' missing from: {e}");
        }
    }
}

/// The microfacet roughness of the model at the unit rectangle's object
/// point (x, y), and the `mask` opacity there (1 without a mask).
fn alpha_at(s: &Scene, x: f32, y: f32) -> ((f32, f32), f32) {
    use mcmc_render::bsdf::textured::BsdfAt;
    let hit = s
        .intersect(&Ray::new(Vec3::new(x, y, 1.0), Vec3::NEG_Z))
        .expect("hit");
    let at = s.bsdf_at(&hit.sp);
    let opacity = match at {
        BsdfAt::Wrapped(_, w) => w.opacity,
        _ => 1.0,
    };
    let alpha = match at.model() {
        Bsdf::RoughConductor(c) | Bsdf::TwoSided(OneSided::RoughConductor(c)) => {
            c.distribution.alpha()
        }
        Bsdf::RoughDielectric(d) => d.distribution.alpha(),
        b => panic!("{b:?}"),
    };
    (alpha, opacity)
}

/// Roughness textures (`alpha`, `alpha_u`, `alpha_v`) of the models
/// Mitsuba 3 takes them for, as every integrator sees them through
/// `Scene::bsdf_at` (inside `twosided`, under `bumpmap` and `mask` too).
/// The checkerboard's scalar lookup is Mitsuba 3.9.1's: `color1` where its
/// colour lookup gives `color0` (uv = ((x+1)/2, (y+1)/2); at (−0.5, −0.5)
/// the colour lookup is color0). A roughness of 0 is clamped to 1e-4.
#[test]
fn textured_roughness_at_a_hit() {
    let board = r#"<texture type="checkerboard" name="NAME"><float name="color0" value="0.05"/><float name="color1" value="0.5"/></texture>"#;
    let tex = |name: &str| board.replace("NAME", name);
    let cases = [
        format!(r#"<bsdf type="roughconductor">{}</bsdf>"#, tex("alpha")),
        format!(
            r#"<bsdf type="twosided"><bsdf type="roughconductor"><string name="distribution" value="ggx"/>{}</bsdf></bsdf>"#,
            tex("alpha")
        ),
        format!(r#"<bsdf type="roughdielectric">{}</bsdf>"#, tex("alpha")),
        format!(
            r#"<bsdf type="bumpmap"><texture type="bitmap"><string name="filename" value="../scenes/textures/bumps.png"/></texture><bsdf type="roughconductor">{}</bsdf></bsdf>"#,
            tex("alpha")
        ),
        format!(
            r#"<bsdf type="mask"><float name="opacity" value="0.7"/><bsdf type="roughdielectric">{}</bsdf></bsdf>"#,
            tex("alpha")
        ),
    ];
    for bsdf in &cases {
        let s = load_in_crate(&format!("<shape type=\"rectangle\">{bsdf}</shape>")).unwrap();
        assert_eq!(alpha_at(&s, -0.5, -0.5).0, (0.5, 0.5), "{bsdf}");
        assert_eq!(alpha_at(&s, 0.5, -0.5).0, (0.05, 0.05), "{bsdf}");
    }
    // Anisotropic: alpha_u textured, alpha_v a number; then both textured,
    // alpha_v by a black board (clamped to 1e-4, as Mitsuba clamps).
    let s = load(&format!(
        r#"<shape type="rectangle"><bsdf type="roughdielectric">{}<float name="alpha_v" value="0.3"/></bsdf></shape>"#,
        tex("alpha_u")
    ))
    .unwrap();
    assert_eq!(alpha_at(&s, -0.5, -0.5).0, (0.5, 0.3));
    assert_eq!(alpha_at(&s, 0.5, -0.5).0, (0.05, 0.3));
    let s = load(&format!(
        r#"<shape type="rectangle"><bsdf type="roughconductor">{}<texture type="checkerboard" name="alpha_v"><float name="color0" value="0"/><float name="color1" value="0"/></texture></bsdf></shape>"#,
        tex("alpha_u")
    ))
    .unwrap();
    assert_eq!(alpha_at(&s, 0.5, -0.5).0, (0.05, 1e-4));
    // The description holds the texture's mean (what `info` prints).
    let Bsdf::RoughConductor(c) = s.bsdfs[0] else {
        panic!("{:?}", s.bsdfs[0]);
    };
    let (au, av) = c.distribution.alpha();
    assert!((au - 0.275).abs() < 1e-6 && av == 1e-4, "{au} {av}");
}

/// Loads with relative paths resolved against the crate directory.
fn load_in_crate(body: &str) -> Result<Scene, String> {
    let text = format!("<scene version=\"3.0.0\"><sensor type=\"perspective\"/>\n{body}\n</scene>");
    Scene::load_str(
        &text,
        Path::new("t.xml"),
        Path::new(env!("CARGO_MANIFEST_DIR")),
    )
    .map_err(|e| e.to_string())
}

/// Scene-level `<texture id=…>` referenced with `<ref id=… name=…>` as a
/// colour, a roughness, a mask's opacity, a checkerboard's colour and a
/// normal map, as Mitsuba 3 resolves them; the values at a hit are the
/// ones the inline textures give.
#[test]
fn scene_level_textures_by_reference() {
    let s = load(
        r#"<texture type="checkerboard" id="board"><float name="color0" value="0.05"/><float name="color1" value="0.5"/></texture>
<texture type="checkerboard" id="outer"><ref id="board" name="color0"/><rgb name="color1" value="0.9, 0.1, 0.1"/></texture>
<bsdf type="roughconductor" id="metal"><ref id="board" name="alpha"/></bsdf>
<shape type="rectangle"><ref id="metal"/></shape>"#,
    )
    .unwrap();
    assert_eq!(alpha_at(&s, -0.5, -0.5).0, (0.5, 0.5));
    assert_eq!(alpha_at(&s, 0.5, -0.5).0, (0.05, 0.05));
    let s = load(
        r#"<texture type="checkerboard" id="board"><float name="color0" value="0.05"/><float name="color1" value="0.5"/></texture>
<texture type="checkerboard" id="outer"><ref id="board" name="color0"/><rgb name="color1" value="0.9, 0.1, 0.1"/><transform name="to_uv"><scale value="0.5"/></transform></texture>
<shape type="rectangle"><bsdf type="diffuse"><ref id="outer" name="reflectance"/></bsdf></shape>"#,
    )
    .unwrap();
    let refl = |x, y| match bsdf_at(&s, x, y) {
        Bsdf::Diffuse(d) => d.reflectance,
        b => panic!("{b:?}"),
    };
    // The outer board (cells of 2 in uv) is color0 everywhere on [0,1]²:
    // the inner board by reference.
    assert_eq!(refl(-0.5, -0.5), Rgb::splat(0.05));
    assert_eq!(refl(0.5, -0.5), Rgb::splat(0.5));
    // Opacity by reference: the scalar lookup (0.5 where the colour
    // lookup gives 0.05), as Mitsuba's mask reads it.
    let s = load(
        r#"<texture type="checkerboard" id="board"><float name="color0" value="0.05"/><float name="color1" value="0.5"/></texture>
<shape type="rectangle"><bsdf type="mask"><ref id="board" name="opacity"/><bsdf type="roughconductor"/></bsdf></shape>"#,
    )
    .unwrap();
    assert_eq!(alpha_at(&s, -0.5, -0.5).1, 0.5);
    assert_eq!(alpha_at(&s, 0.5, -0.5).1, 0.05);
    // A normal map by reference equals the same map inline.
    let nm = r#"<texture type="checkerboard" name="normalmap" id="nm"><rgb name="color0" value="0.8, 0.5, 0.8"/><rgb name="color1" value="0.5, 0.5, 1"/></texture>"#;
    let by_ref = load(&format!(
        r#"{nm}<shape type="rectangle"><bsdf type="normalmap"><ref id="nm" name="normalmap"/><bsdf type="diffuse"/></bsdf></shape>"#
    ))
    .unwrap();
    let inline = load(&format!(
        r#"<shape type="rectangle"><bsdf type="normalmap">{}<bsdf type="diffuse"/></bsdf></shape>"#,
        nm.replace(r#" id="nm""#, "")
    ))
    .unwrap();
    for (x, y) in [(-0.5f32, -0.5f32), (0.5, -0.5)] {
        let n = |s: &Scene| {
            let hit = s
                .intersect(&Ray::new(Vec3::new(x, y, 1.0), Vec3::NEG_Z))
                .expect("hit");
            s.bsdf_at(&hit.sp).perturbed().map(|p| format!("{p:?}"))
        };
        assert!(n(&by_ref).is_some());
        assert_eq!(n(&by_ref), n(&inline));
    }
}

/// Mistyped, unknown, unnamed and duplicate references: one line with
/// the file and line, as Mitsuba 3 refuses them.
#[test]
fn reference_errors_name_the_line() {
    let board = r#"<texture type="checkerboard" id="board"/>"#;
    for (body, needles) in [
        (
            format!("{board}\n<shape type=\"rectangle\"><bsdf type=\"diffuse\">\n<ref id=\"bord\" name=\"reflectance\"/></bsdf></shape>"),
            &["t.xml:4", "no <texture id=\"bord\">"][..],
        ),
        (
            "<bsdf type=\"diffuse\" id=\"white\"/>\n<shape type=\"rectangle\"><bsdf type=\"diffuse\">\n<ref id=\"white\" name=\"reflectance\"/></bsdf></shape>".to_string(),
            &["t.xml:4", "\"white\" is a <bsdf>, but a <texture> is expected"][..],
        ),
        (
            format!("{board}\n<shape type=\"rectangle\">\n<ref id=\"board\"/></shape>"),
            &["t.xml:4", "\"board\" is a <texture>, but a <bsdf> is expected"][..],
        ),
        (
            format!("{board}\n<shape type=\"rectangle\"><bsdf type=\"mask\">\n<ref id=\"board\"/></bsdf></shape>"),
            &["t.xml:4", "\"board\" is a <texture>, but a <bsdf> is expected"][..],
        ),
        (
            format!("{board}\n<shape type=\"rectangle\"><bsdf type=\"diffuse\">\n<ref id=\"board\"/></bsdf></shape>"),
            &["t.xml:4", "needs a 'name'"][..],
        ),
        (
            format!("{board}\n<shape type=\"rectangle\"><bsdf type=\"dielectric\">\n<ref id=\"board\" name=\"int_ior\"/></bsdf></shape>"),
            &["t.xml:4", "parameter 'int_ior'", "cannot be a texture"][..],
        ),
        (
            format!("{board}\n<shape type=\"rectangle\"><bsdf type=\"roughplastic\">\n<ref id=\"board\" name=\"alpha\"/></bsdf></shape>"),
            &["t.xml:4", "'alpha' must be a number here"][..],
        ),
        (
            format!("{board}\n<bsdf type=\"diffuse\" id=\"board\"/>"),
            &["t.xml:3", "duplicate id \"board\"", "t.xml:2"][..],
        ),
        (
            "<texture type=\"checkerboard\"/>".to_string(),
            &["t.xml:2", "scene-level <texture> needs an 'id'"][..],
        ),
        (
            "<texture type=\"bitmap\" id=\"t\">\n<string name=\"filename\" value=\"missing.png\"/></texture>".to_string(),
            &["t.xml:3", "cannot load texture", "missing.png"][..],
        ),
    ] {
        let e = load(&body).err().expect("refused");
        assert!(!e.contains('\n'), "not one line: {e}");
        for n in needles {
            assert!(e.contains(n), "'{n}' missing from: {e}");
        }
    }
}
