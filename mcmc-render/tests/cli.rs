//! The `mcmc-render` binary on bad input: one clear line on stderr, a
//! non-zero exit status, never a panic. Plus the happy paths of `render`,
//! `info` and `compare` on a tiny scene.

mod cli_support;

use cli_support::{assert_clean_failure, run, scratch, write};

/// A tiny valid scene: a diffuse floor lit by a rectangle, `extra` added inside `<scene>`.
fn scene_text(film: &str, extra: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="2"/></sampler>
        {film}
    </sensor>
    <shape type="rectangle"><bsdf type="diffuse"/></shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.3"/><rotate x="1" angle="180"/><translate z="2"/></transform>
        <emitter type="area"><rgb name="radiance" value="1"/></emitter>
    </shape>
    {extra}
</scene>"#
    )
}

const SMALL_FILM: &str = r#"<film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/></film>"#;

#[test]
fn malformed_xml_is_refused_with_its_line() {
    let dir = scratch("malformed");
    write(
        &dir,
        "bad.xml",
        "<scene version=\"3.0.0\">\n  <shape type=\"sphere\">\n</scene>\n",
    );
    let out = run(&["render", "bad.xml"], &dir);
    assert_clean_failure(&out, &["bad.xml:", "malformed XML"]);
}

#[test]
fn missing_mesh_file_is_refused() {
    let dir = scratch("missing-mesh");
    let extra = r#"<shape type="obj"><string name="filename" value="nowhere.obj"/></shape>"#;
    write(&dir, "s.xml", &scene_text(SMALL_FILM, extra));
    let out = run(&["render", "s.xml"], &dir);
    assert_clean_failure(&out, &["s.xml:13", "nowhere.obj"]);
}

#[test]
fn unsupported_plugin_is_refused_with_name_and_line() {
    let dir = scratch("plugin");
    let extra = r#"<shape type="sphere"><bsdf type="principled"/></shape>"#;
    write(&dir, "s.xml", &scene_text(SMALL_FILM, extra));
    let out = run(&["info", "s.xml"], &dir);
    assert_clean_failure(&out, &["s.xml:13", "principled"]);
}

#[test]
fn unsupported_element_is_refused() {
    let dir = scratch("element");
    let extra = r#"<shape type="sphere"><medium type="homogeneous"/></shape>"#;
    write(&dir, "s.xml", &scene_text(SMALL_FILM, extra));
    let out = run(&["info", "s.xml"], &dir);
    assert_clean_failure(&out, &["s.xml:13", "<medium>"]);
}

#[test]
fn unsupported_parameter_is_refused() {
    let dir = scratch("param");
    let extra = r#"<shape type="sphere">
        <float name="sparkle" value="2"/>
    </shape>"#;
    write(&dir, "s.xml", &scene_text(SMALL_FILM, extra));
    let out = run(&["info", "s.xml"], &dir);
    assert_clean_failure(&out, &["s.xml:14", "sparkle"]);
}

#[test]
fn unsupported_attribute_is_refused() {
    let dir = scratch("attr");
    let extra = r#"<shape type="sphere" colour="red"/>"#;
    write(&dir, "s.xml", &scene_text(SMALL_FILM, extra));
    let out = run(&["info", "s.xml"], &dir);
    assert_clean_failure(&out, &["s.xml:13", "colour"]);
}

#[test]
fn nan_vertex_is_refused() {
    let dir = scratch("nan");
    write(&dir, "nan.obj", "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n");
    let extra = r#"<shape type="obj"><string name="filename" value="nan.obj"/></shape>"#;
    write(&dir, "s.xml", &scene_text(SMALL_FILM, extra));
    let out = run(&["info", "s.xml"], &dir);
    assert_clean_failure(&out, &["s.xml:13", "NaN"]);
}

#[test]
fn degenerate_triangles_are_dropped_and_counted() {
    let dir = scratch("degenerate");
    // One good triangle, one with three collinear vertices.
    write(
        &dir,
        "deg.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\n",
    );
    let extra = r#"<shape type="obj"><string name="filename" value="deg.obj"/></shape>"#;
    write(&dir, "s.xml", &scene_text(SMALL_FILM, extra));
    let out = run(&["info", "s.xml"], &dir);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line = stdout
        .lines()
        .find(|l| l.starts_with("dropped triangles"))
        .expect("info reports dropped triangles");
    assert!(line.contains(" 1 "), "{line}");

    // A mesh made only of degenerate triangles is an error.
    write(&dir, "all.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n");
    let extra = r#"<shape type="obj"><string name="filename" value="all.obj"/></shape>"#;
    write(&dir, "t.xml", &scene_text(SMALL_FILM, extra));
    let out = run(&["info", "t.xml"], &dir);
    assert_clean_failure(&out, &["t.xml:13", "zero area"]);
}

#[test]
fn zero_resolution_is_refused() {
    let dir = scratch("zero-res");
    let film = r#"<film type="hdrfilm"><integer name="width" value="0"/><integer name="height" value="6"/></film>"#;
    write(&dir, "s.xml", &scene_text(film, ""));
    let out = run(&["render", "s.xml"], &dir);
    assert_clean_failure(&out, &["s.xml:6", "resolution"]);
}

#[test]
fn unwritable_output_is_refused_before_rendering() {
    let dir = scratch("unwritable");
    write(&dir, "s.xml", &scene_text(SMALL_FILM, ""));
    let out = run(
        &["render", "s.xml", "--out", "no/such/dir/out.exr", "--quiet"],
        &dir,
    );
    assert_clean_failure(&out, &["no/such/dir/out.exr"]);
}

#[test]
fn negative_spp_is_refused() {
    let dir = scratch("negative-spp");
    write(&dir, "s.xml", &scene_text(SMALL_FILM, ""));
    let out = run(&["render", "s.xml", "--spp", "-4"], &dir);
    assert_clean_failure(&out, &["--spp", "-4"]);
    let out = run(&["render", "s.xml", "--spp", "0"], &dir);
    assert_clean_failure(&out, &["--spp"]);
}

#[test]
fn undefined_substitution_is_refused() {
    let dir = scratch("subst");
    let film = r#"<film type="hdrfilm"><integer name="width" value="$w"/></film>"#;
    write(&dir, "s.xml", &scene_text(film, ""));
    let out = run(&["info", "s.xml"], &dir);
    assert_clean_failure(&out, &["s.xml:6", "$w"]);
}

#[test]
fn render_writes_exr_png_and_json_then_compare_reads_them() {
    let dir = scratch("happy");
    write(&dir, "s.xml", &scene_text(SMALL_FILM, ""));
    for (integrator, name) in [("pt", "a.exr"), ("lt", "b.exr")] {
        let out = run(
            &[
                "render",
                "s.xml",
                "--integrator",
                integrator,
                "--spp",
                "4",
                "--seed",
                "3",
                "--threads",
                "2",
                "--out",
                name,
                "--quiet",
            ],
            &dir,
        );
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    for f in ["a.exr", "a.png", "a.json", "b.exr", "b.png", "b.json"] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("a.json")).unwrap()).unwrap();
    for key in [
        "integrator",
        "seconds",
        "samples",
        "samples_per_second",
        "width",
        "height",
        "seed",
        "threads",
    ] {
        assert!(json.get(key).is_some(), "sidecar lacks {key}");
    }
    assert_eq!(json["integrator"], "pt");
    assert_eq!(json["width"], 8);
    assert_eq!(json["height"], 6);
    assert_eq!(json["samples"], 8 * 6 * 4);
    assert_eq!(json["seed"], 3);

    let out = run(&["compare", "a.exr", "b.exr", "--json"], &dir);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let c: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(c["rel_mse"].as_f64().unwrap().is_finite());
    assert_eq!(c["test_nonfinite"], 0);

    // Comparing an image with itself gives exactly zero error.
    let out = run(&["compare", "a.exr", "a.exr", "--json"], &dir);
    let c: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(c["rel_mse"].as_f64().unwrap(), 0.0);
    assert_eq!(c["rmse"].as_f64().unwrap(), 0.0);
}

#[test]
fn compare_refuses_missing_files() {
    let dir = scratch("compare-missing");
    let out = run(&["compare", "nope.exr", "nada.exr"], &dir);
    assert_clean_failure(&out, &["nope.exr"]);
}

#[test]
fn no_arguments_renders_the_default_scene() {
    let dir = scratch("default");
    let out = run(&[], &dir);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.join("render.exr").is_file());
    assert!(dir.join("render.png").is_file());
}

#[test]
fn time_budget_writes_a_normalised_partial_render() {
    let dir = scratch("time");
    let film = r#"<film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="48"/></film>"#;
    write(&dir, "s.xml", &scene_text(film, ""));
    let out = run(
        &[
            "render", "s.xml", "--time", "1", "--out", "t.exr", "--quiet",
        ],
        &dir,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("t.json")).unwrap()).unwrap();
    assert!(json["spp"].as_u64().unwrap() >= 1);
    assert_eq!(json["interrupted"], true);
    assert!(json["seconds"].as_f64().unwrap() < 60.0);
    // Whatever the number of passes, the image is normalised by them: its
    // mean matches a fixed-spp render (both have thousands of samples, so
    // their means differ by well under 5%).
    let out = run(
        &[
            "render", "s.xml", "--spp", "16", "--out", "r.exr", "--quiet",
        ],
        &dir,
    );
    assert!(out.status.success());
    let out = run(&["compare", "r.exr", "t.exr", "--json"], &dir);
    let c: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for ch in 0..3 {
        let d = c["mean_rel_diff"][ch].as_f64().unwrap();
        assert!(d.abs() < 0.05, "channel {ch}: {d}");
    }
}
