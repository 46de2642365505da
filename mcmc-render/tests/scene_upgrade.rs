//! Mitsuba 0.x scene files, upgraded on load: the 0.6 Cornell box
//! (`tests/scenes/cornell-box-0.6.xml`, checked with Mitsuba 3 by
//! `scenes/tools/check_legacy_scene.py`) loads and renders exactly as
//! `scenes/cornell-box.xml`; the 0.6 value forms read as 0.6 meant them;
//! what cannot be upgraded is one line with its file and line.

mod cli_support;

use cli_support::{assert_clean_failure, exr, run, run_ok, scratch, write};
use mcmc_render::color::Rgb;
use mcmc_render::scene::xml::{Child, Plugin, Value, parse_str};
use std::path::{Path, PathBuf};

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
}

const NEW: &str = "scenes/cornell-box.xml";
const OLD: &str = "mcmc-render/tests/scenes/cornell-box-0.6.xml";

/// `info` without the lines that name the file or time the BVH build.
fn info(path: &Path) -> String {
    run_ok(&["info", &path.display().to_string()], Path::new("."))
        .lines()
        .filter(|l| !l.starts_with("scene ") && !l.starts_with("bvh "))
        .collect::<Vec<_>>()
        .join("\n")
}

fn render(path: &Path, dir: &Path, out: &str, defines: &[&str]) -> Vec<Rgb> {
    let scene = path.display().to_string();
    let mut args = vec![
        "render",
        &scene,
        "--seed",
        "5",
        "--threads",
        "1",
        "--out",
        out,
        "--quiet",
    ];
    for d in defines {
        args.extend(["-D", d]);
    }
    run_ok(&args, dir);
    exr(&dir.join(out)).2
}

#[test]
fn cornell_box_06_loads_and_renders_as_the_mitsuba3_file() {
    let dir = scratch("upgrade-cornell");
    let new = repo(NEW);
    let old = repo(OLD);
    // The fixture keeps <lookat> (Mitsuba 3.9 refuses <lookAt>); a copy
    // with 0.6's <lookAt> must read the same.
    let text = std::fs::read_to_string(&old).unwrap();
    assert!(text.contains("<lookat "));
    let camel = write(&dir, "camel.xml", &text.replace("<lookat ", "<lookAt "));
    let reference = info(&new);
    assert!(reference.contains("max_depth=8, rr_depth=5"), "{reference}");
    assert_eq!(info(&old), reference);
    assert_eq!(info(&camel), reference);
    let small = ["width=32", "height=24", "spp=2"];
    let a = render(&new, &dir, "new.exr", &small);
    assert!(
        a == render(&old, &dir, "old.exr", &small),
        "0.6 render differs"
    );
    assert!(
        a == render(&camel, &dir, "camel.exr", &small),
        "<lookAt> render differs"
    );
    // Control: a real difference in the 0.6 file shows (max_depth 2).
    let direct = render(
        &old,
        &dir,
        "direct.exr",
        &["width=32", "height=24", "spp=2", "max_depth=2"],
    );
    assert!(a != direct);
}

/// The first plugin of a scene text.
fn first_plugin(text: &str) -> Plugin {
    let children = parse_str(text, Path::new("t.xml")).unwrap();
    match children.into_iter().next() {
        Some(Child::Plugin(p)) => p,
        other => panic!("expected a plugin, got {other:?}"),
    }
}

fn rgb_param(p: &Plugin, name: &str) -> Rgb {
    match p.params.iter().find(|q| q.name == name).map(|q| &q.value) {
        Some(Value::Rgb(c)) => *c,
        other => panic!("{name}: {other:?}"),
    }
}

/// The sRGB decoding (IEC 61966-2-1), written out here in f64.
fn linear(encoded: f64) -> f32 {
    (if encoded <= 0.04045 {
        encoded / 12.92
    } else {
        ((encoded + 0.055) / 1.055).powf(2.4)
    }) as f32
}

#[test]
fn legacy_values_read_as_06_meant_them() {
    let p = first_plugin(
        r##"<scene version="0.6.0"><bsdf type="diffuse">
            <srgb name="diffuseReflectance" value="#80ff00"/>
            <srgb name="specularReflectance" value="0.5, 0.02, 1"/>
            <spectrum name="intIOR" value="0.1, 0.2, 0.3"/>
            <spectrum name="extIOR" value="0.25"/>
            <float name="uscale" value="2"/><float name="voffset" value="0.5"/>
        </bsdf></scene>"##,
    );
    // diffuseReflectance of a diffuse BSDF is Mitsuba 3's reflectance.
    let c = rgb_param(&p, "reflectance");
    let want = [linear(128.0 / 255.0), 1.0, 0.0];
    for (got, want) in [c.r, c.g, c.b].into_iter().zip(want) {
        assert!((got - want).abs() <= 1e-6 * want.max(1e-3), "{c:?}");
    }
    let s = rgb_param(&p, "specular_reflectance");
    assert!((s.r - linear(0.5)).abs() < 1e-6 && (s.g - linear(0.02)).abs() < 1e-9);
    assert_eq!(rgb_param(&p, "int_ior"), Rgb::new(0.1, 0.2, 0.3));
    assert_eq!(rgb_param(&p, "ext_ior"), Rgb::splat(0.25));
    // uscale/voffset became one to_uv: (u, v) -> (2u, v + 0.5).
    let names: Vec<&str> = p.params.iter().map(|q| q.name.as_str()).collect();
    assert!(!names.contains(&"uscale") && !names.contains(&"voffset"));
    let Some(Value::Transform(m)) = p
        .params
        .iter()
        .find(|q| q.name == "to_uv")
        .map(|q| &q.value)
    else {
        panic!("no to_uv in {names:?}");
    };
    let uv = m.transform_point3(glam::Vec3::new(0.25, 0.25, 0.0));
    assert_eq!((uv.x, uv.y), (0.5, 0.75));
    // Nested plugins' names are upgraded too (Mitsuba's rule applies to
    // every `name` attribute).
    let outer = first_plugin(
        r#"<scene version="0.6.0"><bsdf type="twosided"><bsdf type="diffuse" name="innerBsdf"><float name="diffuseReflectance" value="0.5"/></bsdf></bsdf></scene>"#,
    );
    let Some(Child::Plugin(inner)) = outer.children.first() else {
        panic!("no nested bsdf");
    };
    assert_eq!(inner.name.as_deref(), Some("inner_bsdf"));
    assert_eq!(inner.params[0].name, "reflectance");
    // …including diffuse's diffuseReflectance given as a nested plugin
    // (a texture, in real files; the reader does not look at the tag).
    let diffuse = first_plugin(
        r#"<scene version="0.6.0"><bsdf type="diffuse"><bsdf type="x" name="diffuseReflectance"/></bsdf></scene>"#,
    );
    let Some(Child::Plugin(tex)) = diffuse.children.first() else {
        panic!("no nested plugin");
    };
    assert_eq!(tex.name.as_deref(), Some("reflectance"));
    // Control: a Mitsuba 3 file keeps its names as written.
    let q = first_plugin(
        r#"<scene version="3.0.0"><bsdf type="diffuse"><rgb name="diffuseReflectance" value="1"/></bsdf></scene>"#,
    );
    assert_eq!(q.params[0].name, "diffuseReflectance");
}

/// A minimal scene around `body`, in file version `version`.
fn scene(version: &str, body: &str) -> String {
    format!(
        "<scene version=\"{version}\">\n<sensor type=\"perspective\"><film type=\"hdrfilm\"><integer name=\"width\" value=\"8\"/><integer name=\"height\" value=\"8\"/></film></sensor>\n{body}\n</scene>\n"
    )
}

#[test]
fn what_cannot_be_upgraded_is_one_line_with_its_place() {
    let dir = scratch("upgrade-refused");
    let shape = |bsdf: &str| format!("<shape type=\"sphere\">\n{bsdf}\n</shape>");
    let cases: Vec<(String, &str, &str)> = vec![
        (
            r#"<scene version="0.6"><shape type="sphere"/></scene>"#.into(),
            "t.xml:1",
            "not of the form major.minor.patch",
        ),
        // A 0.6 parameter that Mitsuba 3 dropped (its snake_case name is refused).
        (
            scene(
                "0.6.0",
                r#"<integrator type="path"><boolean name="strictNormals" value="true"/></integrator>"#,
            ),
            "t.xml:3",
            "strict_normals",
        ),
        (
            scene(
                "0.6.0",
                &shape(
                    r#"<bsdf type="diffuse"><spectrum name="reflectance" value="400:0.1, 700:0.5"/></bsdf>"#,
                ),
            ),
            "t.xml:4",
            "wavelength:value pairs",
        ),
        (
            scene(
                "0.6.0",
                &shape(
                    r#"<bsdf type="diffuse"><spectrum name="reflectance" filename="r.spd"/></bsdf>"#,
                ),
            ),
            "t.xml:4",
            "unsupported attribute 'filename'",
        ),
        (
            scene(
                "0.6.0",
                &shape(
                    r##"<bsdf type="diffuse"><srgb name="reflectance" value="#12345"/></bsdf>"##,
                ),
            ),
            "t.xml:4",
            "not #rrggbb",
        ),
        (
            scene(
                "0.6.0",
                &shape(r#"<bsdf type="diffuse"><float name="uvscale" value="2"/></bsdf>"#),
            ),
            "t.xml:4",
            "unsupported parameter 'uvscale'",
        ),
        (
            scene("0.6.0", &shape(r#"<bsdf type="phong"/>"#)),
            "t.xml:4",
            "unsupported bsdf \"phong\"",
        ),
        // 0.6-only forms in a Mitsuba 3 file.
        (
            scene(
                "3.0.0",
                &shape(r#"<bsdf type="diffuse"><srgb name="reflectance" value="0.5"/></bsdf>"#),
            ),
            "t.xml:4",
            "unsupported element <srgb>",
        ),
        (
            scene(
                "3.0.0",
                &shape(
                    r#"<bsdf type="diffuse"><spectrum name="reflectance" value="0.1 0.2 0.3"/></bsdf>"#,
                ),
            ),
            "t.xml:4",
            "needs one number",
        ),
        (
            scene(
                "3.0.0",
                r#"<integrator type="path"><integer name="maxDepth" value="3"/></integrator>"#,
            ),
            "t.xml:3",
            "maxDepth",
        ),
    ];
    for (text, place, needle) in &cases {
        write(&dir, "t.xml", text);
        let out = run(&["info", "t.xml"], &dir);
        assert_clean_failure(&out, &[place, needle]);
    }
    // Control: the same scene with an upgradable 0.6 parameter loads.
    write(
        &dir,
        "t.xml",
        &scene(
            "0.6.0",
            r#"<integrator type="path"><integer name="maxDepth" value="3"/></integrator><shape type="sphere"/>"#,
        ),
    );
    assert!(run_ok(&["info", "t.xml"], &dir).contains("max_depth=3"));
}
