//! Scene loading: Mitsuba defaults, `$name` substitution, includes,
//! transform order, BSDF parsing, meshes (OBJ, ASCII and binary PLY), and
//! the camera mapping.

use glam::{Vec2, Vec3};
use mcmc_render::bsdf::{BsdfDesc, MicrofacetKind};
use mcmc_render::color::Rgb;
use mcmc_render::geometry::Ray;
use mcmc_render::scene::loader::Loader;
use mcmc_render::scene::{FilterKind, SceneDesc, ShapeGeometry, xml};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mcmc-render-scene-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

const SENSOR: &str = r#"<sensor type="perspective"><float name="fov" value="40"/></sensor>"#;

fn desc_in(dir: &Path, body: &str, defines: &[(&str, &str)]) -> Result<SceneDesc, String> {
    let path = dir.join("scene.xml");
    std::fs::write(
        &path,
        format!("<scene version=\"3.0.0\">\n{SENSOR}\n{body}\n</scene>\n"),
    )
    .unwrap();
    let defs: HashMap<String, String> = defines
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    let tree = xml::parse_file(&path, &defs).map_err(|e| e.to_string())?;
    Loader::new(dir)
        .load(&tree, "scene.xml")
        .map_err(|e| e.to_string())
}

fn desc(body: &str) -> SceneDesc {
    desc_in(&scratch("desc"), body, &[]).expect("loads")
}

#[test]
fn mitsuba_defaults() {
    let d = desc("");
    assert_eq!((d.film.width, d.film.height), (768, 576));
    assert_eq!(d.film.filter, FilterKind::Gaussian { stddev: 0.5 });
    assert_eq!(d.sample_count, 4);
    assert_eq!(d.integrator.max_depth, u32::MAX);
    assert_eq!(d.integrator.rr_depth, 5);
    assert_eq!(d.camera.near_clip, 0.01);
}

#[test]
fn defaults_substitution_and_overrides() {
    let dir = scratch("subst");
    let body = r#"<default name="w" value="64"/>
<default name="md" value="3"/>
<integrator type="path"><integer name="max_depth" value="$md"/></integrator>
<shape type="sphere"><float name="radius" value="$w"/></shape>"#;
    let d = desc_in(&dir, body, &[]).unwrap();
    assert_eq!(d.integrator.max_depth, 3);
    let d = desc_in(&dir, body, &[("md", "7")]).unwrap();
    assert_eq!(d.integrator.max_depth, 7);
    match d.shapes[0].geometry {
        ShapeGeometry::Sphere { radius, .. } => assert_eq!(radius, 64.0),
        _ => panic!("not a sphere"),
    }
}

#[test]
fn include_splices_the_other_file() {
    let dir = scratch("include");
    std::fs::write(
        dir.join("part.xml"),
        r#"<scene version="3.0.0"><bsdf type="diffuse" id="grey"><rgb name="reflectance" value="0.25"/></bsdf></scene>"#,
    )
    .unwrap();
    let d = desc_in(
        &dir,
        r#"<include filename="part.xml"/><shape type="sphere"><ref id="grey"/></shape>"#,
        &[],
    )
    .unwrap();
    assert_eq!(
        d.bsdfs[d.shapes[0].bsdf],
        BsdfDesc::Diffuse {
            reflectance: Rgb::splat(0.25)
        }
    );
}

#[test]
fn transforms_apply_in_file_order() {
    // scale, then rotate 90° about z, then translate: (1,0,0) -> (2,0,0) -> (0,2,0) -> (0,2,5).
    let d = desc(
        r#"<shape type="rectangle"><transform name="to_world">
        <scale value="2"/><rotate z="1" angle="90"/><translate z="5"/>
    </transform></shape>"#,
    );
    let ShapeGeometry::Mesh(m) = &d.shapes[0].geometry else {
        panic!("rectangle is a mesh")
    };
    // Rectangle corner (1, -1, 0) -> (2, -2, 0) -> (2, 2, 0) -> (2, 2, 5).
    let p = m.positions[1];
    assert!((p - Vec3::new(2.0, 2.0, 5.0)).length() < 1e-5, "{p}");
    // A row-major <matrix> equals the same translation.
    let d = desc(
        r#"<shape type="sphere"><transform name="to_world">
        <matrix value="1 0 0 1  0 1 0 2  0 0 1 3  0 0 0 1"/></transform></shape>"#,
    );
    match d.shapes[0].geometry {
        ShapeGeometry::Sphere { center, .. } => assert_eq!(center, Vec3::new(1.0, 2.0, 3.0)),
        _ => panic!("not a sphere"),
    }
}

#[test]
fn bsdf_parsing_fills_mitsuba_defaults() {
    let d = desc(
        r#"<bsdf type="conductor" id="mirror"/>
<bsdf type="conductor" id="gold"><string name="material" value="Au"/></bsdf>
<bsdf type="roughconductor" id="rough"/>
<bsdf type="dielectric" id="glass"/>
<bsdf type="roughdielectric" id="frosted">
    <string name="distribution" value="ggx"/><float name="alpha" value="0.3"/>
    <string name="int_ior" value="water"/>
</bsdf>
<bsdf type="twosided" id="two"><bsdf type="diffuse"/></bsdf>"#,
    );
    assert_eq!(d.bsdfs[0], BsdfDesc::PerfectMirror);
    match &d.bsdfs[1] {
        BsdfDesc::Conductor { eta, k, .. } => {
            // Mitsuba 3 scalar_rgb's values for gold.
            assert!((eta.r - 0.143_036).abs() < 1e-5 && (k.b - 1.603_36).abs() < 1e-5);
        }
        other => panic!("{other:?}"),
    }
    match &d.bsdfs[2] {
        BsdfDesc::RoughConductor {
            distribution,
            alpha_u,
            alpha_v,
            eta,
            k,
            ..
        } => {
            assert_eq!(*distribution, MicrofacetKind::Beckmann);
            assert_eq!((*alpha_u, *alpha_v), (0.1, 0.1));
            assert_eq!((*eta, *k), (Rgb::splat(0.0), Rgb::WHITE));
        }
        other => panic!("{other:?}"),
    }
    match &d.bsdfs[3] {
        BsdfDesc::Dielectric {
            int_ior, ext_ior, ..
        } => assert_eq!((*int_ior, *ext_ior), (1.5046, 1.000_277)),
        other => panic!("{other:?}"),
    }
    match &d.bsdfs[4] {
        BsdfDesc::RoughDielectric {
            distribution,
            alpha_u,
            int_ior,
            ..
        } => {
            assert_eq!(*distribution, MicrofacetKind::Ggx);
            assert_eq!(*alpha_u, 0.3);
            assert_eq!(*int_ior, 1.333);
        }
        other => panic!("{other:?}"),
    }
    assert!(
        matches!(&d.bsdfs[5], BsdfDesc::TwoSided { inner } if matches!(**inner, BsdfDesc::Diffuse { .. }))
    );
}

#[test]
fn plastic_and_thin_dielectric_parse_with_mitsuba_defaults() {
    let d = desc(
        r#"<bsdf type="plastic" id="p"/>
<bsdf type="roughplastic" id="rp">
    <string name="distribution" value="ggx"/><float name="alpha" value="0.2"/>
    <boolean name="sample_visible" value="false"/><boolean name="nonlinear" value="true"/>
    <rgb name="diffuse_reflectance" value="0.1, 0.2, 0.3"/><string name="int_ior" value="water"/>
</bsdf>
<bsdf type="thindielectric" id="t"/>"#,
    );
    assert_eq!(
        d.bsdfs[0],
        BsdfDesc::Plastic {
            diffuse_reflectance: Rgb::splat(0.5),
            specular_reflectance: Rgb::WHITE,
            int_ior: 1.49,
            ext_ior: 1.000_277,
            nonlinear: false,
        }
    );
    assert_eq!(
        d.bsdfs[1],
        BsdfDesc::RoughPlastic {
            distribution: MicrofacetKind::Ggx,
            alpha: 0.2,
            sample_visible: false,
            diffuse_reflectance: Rgb::new(0.1, 0.2, 0.3),
            specular_reflectance: Rgb::WHITE,
            int_ior: 1.333,
            ext_ior: 1.000_277,
            nonlinear: true,
        }
    );
    assert_eq!(
        d.bsdfs[2],
        BsdfDesc::ThinDielectric {
            int_ior: 1.5046,
            ext_ior: 1.000_277,
            specular_reflectance: Rgb::WHITE,
            specular_transmittance: Rgb::WHITE,
        }
    );
    let dir = scratch("refuse-plastic");
    for (body, needle) in [
        (
            r#"<bsdf type="roughplastic"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.2"/></bsdf>"#,
            "anisotropic",
        ),
        (
            r#"<bsdf type="plastic"><float name="alpha" value="0.1"/></bsdf>"#,
            "'alpha'",
        ),
        (
            r#"<bsdf type="plastic"><float name="int_ior" value="1.2"/><float name="ext_ior" value="1.2"/></bsdf>"#,
            "differ",
        ),
        (
            r#"<bsdf type="roughplastic"><rgb name="diffuse_reflectance" value="1.5"/></bsdf>"#,
            "[0, 1]",
        ),
        (
            r#"<bsdf type="thindielectric"><string name="int_ior" value="unobtainium"/></bsdf>"#,
            "unobtainium",
        ),
        (
            r#"<bsdf type="twosided"><bsdf type="thindielectric"/></bsdf>"#,
            "transmission",
        ),
    ] {
        let e = desc_in(&dir, body, &[]).expect_err(body);
        assert!(e.contains("scene.xml:3"), "{e}");
        assert!(e.contains(needle), "{e}");
    }
}

#[test]
fn refusals_name_the_line() {
    let dir = scratch("refuse");
    let cases = [
        (
            r#"<bsdf type="conductor"><string name="material" value="Unobtainium"/></bsdf>"#,
            "Unobtainium",
        ),
        (
            r#"<bsdf type="conductor"><string name="material" value="Au"/><rgb name="eta" value="1"/></bsdf>"#,
            "not both",
        ),
        (
            r#"<shape type="sphere"><transform name="to_world"><scale x="1" y="2"/></transform></shape>"#,
            "non-uniformly",
        ),
        (r#"<emitter type="envmap"/>"#, "envmap"),
        (r#"<integrator type="volpath"/>"#, "volpath"),
        (
            r#"<shape type="sphere"><ref id="nothing"/></shape>"#,
            "nothing",
        ),
        // Negative reflectance was accepted (negative radiance was not).
        (
            r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.5, -0.1, 0.5"/></bsdf>"#,
            "'reflectance' must be finite and non-negative",
        ),
        // Children of parameter tags and transform operations were ignored.
        (
            r#"<shape type="sphere"><transform name="to_world"><translate x="1"><scale value="2"/></translate></transform></shape>"#,
            "unexpected <scale> inside <translate>",
        ),
        (
            r#"<shape type="sphere"><float name="radius" value="1"><float name="x" value="2"/></float></shape>"#,
            "unexpected <float> inside <float>",
        ),
        (
            r#"<shape type="sphere"><float name="radius" value="1">2</float></shape>"#,
            "unexpected text inside <float>",
        ),
    ];
    for (body, needle) in cases {
        let e = desc_in(&dir, body, &[]).expect_err(body);
        assert!(e.contains("scene.xml:3"), "{e}");
        assert!(e.contains(needle), "{e}");
    }
}

fn write_ply_binary(path: &Path) {
    let mut data = Vec::new();
    data.extend_from_slice(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n",
    );
    for v in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        for c in v {
            data.extend_from_slice(&c.to_le_bytes());
        }
        for c in [0.0f32, 0.0, 1.0] {
            data.extend_from_slice(&c.to_le_bytes());
        }
    }
    data.push(3);
    for i in [0i32, 1, 2] {
        data.extend_from_slice(&i.to_le_bytes());
    }
    std::fs::write(path, data).unwrap();
}

#[test]
fn meshes_load_with_the_normals_the_file_asks_for() {
    let dir = scratch("meshes");
    std::fs::write(
        dir.join("quad.ply"),
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n",
    )
    .unwrap();
    write_ply_binary(&dir.join("tri.ply"));
    std::fs::write(
        dir.join("tri.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n",
    )
    .unwrap();
    let d = desc_in(
        &dir,
        r#"<shape type="ply"><string name="filename" value="quad.ply"/></shape>
<shape type="ply"><string name="filename" value="tri.ply"/></shape>
<shape type="obj"><string name="filename" value="tri.obj"/></shape>
<shape type="obj"><string name="filename" value="tri.obj"/><boolean name="face_normals" value="true"/></shape>"#,
        &[],
    )
    .unwrap();
    let mesh = |i: usize| match &d.shapes[i].geometry {
        ShapeGeometry::Mesh(m) => m.clone(),
        _ => panic!("mesh"),
    };
    // ASCII quad: fan-triangulated, normals computed (none in the file).
    let quad = mesh(0);
    assert_eq!(quad.indices.len(), 2);
    assert!(
        quad.normals
            .as_ref()
            .unwrap()
            .iter()
            .all(|n| (*n - Vec3::Z).length() < 1e-6)
    );
    // Binary PLY with normals.
    let tri = mesh(1);
    assert_eq!(tri.indices.len(), 1);
    assert_eq!(tri.normals.as_ref().unwrap()[0], Vec3::Z);
    // OBJ with normals, then with face_normals: vertex normals discarded.
    assert!(mesh(2).normals.is_some());
    assert!(mesh(3).normals.is_none());
}

#[test]
fn camera_rays_and_raster_positions_round_trip() {
    let text = r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="50"/><string name="fov_axis" value="y"/>
        <transform name="to_world"><lookat origin="1,2,3" target="0,0,0" up="0,0,1"/></transform>
        <film type="hdrfilm"><integer name="width" value="40"/><integer name="height" value="30"/></film>
    </sensor>
    <shape type="sphere"/>
</scene>"#;
    let scene =
        mcmc_render::scene::Scene::load_str(text, Path::new("cam.xml"), Path::new(".")).unwrap();
    let cam = &scene.camera;
    for raster in [
        Vec2::new(0.5, 0.5),
        Vec2::new(20.0, 15.0),
        Vec2::new(39.2, 3.7),
    ] {
        let ray: Ray = cam.generate_ray(raster);
        let (back, _) = cam.raster_of(ray.d).expect("on the image");
        assert!((back - raster).length() < 1e-3, "{raster} -> {back}");
    }
    // The image centre looks at the target.
    let c = cam.generate_ray(Vec2::new(20.0, 15.0));
    let want = (Vec3::ZERO - Vec3::new(1.0, 2.0, 3.0)).normalize();
    assert!((c.d - want).length() < 1e-5);
    // fov_axis = y: the top edge is 25° above the centre ray.
    let top = cam.generate_ray(Vec2::new(20.0, 0.0));
    let angle = top.d.dot(c.d).acos().to_degrees();
    assert!((angle - 25.0).abs() < 1e-3, "{angle}");
    // The directional pdf of camera rays integrates to one over the image
    // (midpoint rule over pixels; a pixel's solid angle is its area on the
    // plane z = 1 times cos³θ).
    let mut total = 0.0f64;
    let (w, h) = cam.resolution();
    for y in 0..h {
        for x in 0..w {
            let ray = cam.generate_ray(Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
            let (_, pdf_dir) = cam.pdf_we(ray.o, ray.d);
            // Solid angle of the pixel: its plane area times cos³ (plane at distance 1).
            let (_, cos) = cam.raster_of(ray.d).unwrap();
            let tan_y = 25f32.to_radians().tan();
            let plane_area = (2.0 * tan_y * w as f32 / h as f32) * (2.0 * tan_y) / (w * h) as f32;
            total += (pdf_dir * plane_area * cos * cos * cos) as f64;
        }
    }
    assert!((total - 1.0).abs() < 1e-3, "{total}");
}

#[test]
fn emitters_at_infinity_load_and_bad_ones_are_refused() {
    let dir = scratch("infinite");
    let black = dir.join("black.exr");
    mcmc_render::image_io::write_exr(&black, 4, 3, &[Rgb::BLACK; 12]).unwrap();
    let sky = dir.join("sky.exr");
    mcmc_render::image_io::write_exr(&sky, 4, 3, &[Rgb::new(1.0, 2.0, 3.0); 12]).unwrap();
    std::fs::write(dir.join("garbage.exr"), b"not an exr file at all").unwrap();
    std::fs::write(dir.join("sky.png"), b"").unwrap();

    let d = desc_in(
        &dir,
        r#"<emitter type="envmap"><string name="filename" value="sky.exr"/><float name="scale" value="2"/></emitter>
           <emitter type="directional"><vector name="direction" value="0, -2, 0"/></emitter>"#,
        &[],
    )
    .expect("loads");
    assert_eq!(d.infinite_lights.len(), 2);
    match &d.infinite_lights[1] {
        mcmc_render::scene::InfiniteLightDesc::Directional {
            direction,
            irradiance,
        } => {
            assert_eq!(*direction, Vec3::new(0.0, -1.0, 0.0));
            assert_eq!(*irradiance, Rgb::WHITE);
        }
        other => panic!("{other:?}"),
    }
    match &d.infinite_lights[0] {
        mcmc_render::scene::InfiniteLightDesc::Environment(env) => {
            // Scale applied: every direction sees 2 × (1, 2, 3).
            assert_eq!(
                env.eval(Vec3::new(0.3, 0.8, -0.52).normalize()),
                Rgb::new(2.0, 4.0, 6.0)
            );
        }
        other => panic!("{other:?}"),
    }

    let env = |file: &str| {
        format!(r#"<emitter type="envmap"><string name="filename" value="{file}"/></emitter>"#)
    };
    let cases = [
        (env("missing.exr"), "missing.exr"),
        (env("garbage.exr"), "garbage.exr"),
        (env("sky.png"), "sky.png"),
        (env("black.exr"), "black everywhere"),
        (
            format!("{}\n{}", env("sky.exr"), r#"<emitter type="constant"/>"#),
            "only one environment",
        ),
        (
            r#"<emitter type="constant"><transform name="to_world"><scale value="2"/></transform></emitter>"#.to_string(),
            "rotation",
        ),
        (
            r#"<emitter type="constant"><rgb name="radiance" value="-1"/></emitter>"#.to_string(),
            "non-negative",
        ),
        (
            r#"<emitter type="directional"><vector name="direction" value="0,0,1"/><transform name="to_world"><rotate x="1" angle="3"/></transform></emitter>"#.to_string(),
            "not both",
        ),
        (
            r#"<emitter type="directional"><vector name="direction" value="0,0,0"/></emitter>"#.to_string(),
            "zero",
        ),
        (
            r#"<emitter type="spot"><float name="cutoff_angle" value="100"/></emitter>"#.to_string(),
            "cutoff_angle",
        ),
        (
            r#"<emitter type="spot"><float name="beam_width" value="25"/></emitter>"#.to_string(),
            "beam_width",
        ),
        (r#"<emitter type="spot"><float name="radius" value="1"/></emitter>"#.to_string(), "radius"),
    ];
    for (body, needle) in cases {
        let e = desc_in(&dir, &body, &[]).expect_err(&body);
        assert!(e.contains("scene.xml:"), "{e}");
        assert!(e.contains(needle), "{body}: {e}");
        assert_eq!(e.lines().count(), 1, "{e}");
    }
}

#[test]
fn thin_lens_crop_and_tent_parse_and_bad_values_are_refused() {
    let dir = scratch("lens");
    let sensor = |attrs: &str, film: &str| {
        format!(
            r#"<scene version="3.0.0"><sensor type="thinlens">{attrs}<film type="hdrfilm"><integer name="width" value="40"/><integer name="height" value="30"/>{film}</film></sensor></scene>"#
        )
    };
    let load = |text: String| -> Result<SceneDesc, String> {
        let path = dir.join("lens.xml");
        std::fs::write(&path, text).unwrap();
        let tree = xml::parse_file(&path, &HashMap::new()).map_err(|e| e.to_string())?;
        Loader::new(&dir)
            .load(&tree, "lens.xml")
            .map_err(|e| e.to_string())
    };
    let d = load(sensor(
        r#"<float name="aperture_radius" value="0.1"/>"#,
        r#"<integer name="crop_offset_x" value="5"/><integer name="crop_width" value="10"/><rfilter type="tent"/>"#,
    ))
    .expect("loads");
    assert_eq!(d.camera.aperture_radius, 0.1);
    assert_eq!(d.camera.focus_distance, d.camera.far_clip);
    assert_eq!((d.film.width, d.film.height), (10, 30));
    assert_eq!((d.film.full_width, d.film.full_height), (40, 30));
    assert_eq!(d.film.crop_offset, (5, 0));
    assert_eq!(d.film.filter, FilterKind::Tent { radius: 1.0 });
    let cases = [
        (sensor("", ""), "aperture_radius"),
        (
            sensor(r#"<float name="aperture_radius" value="-1"/>"#, ""),
            "aperture_radius",
        ),
        (
            sensor(
                r#"<float name="aperture_radius" value="0.1"/><float name="focus_distance" value="0"/>"#,
                "",
            ),
            "focus_distance",
        ),
        (
            sensor(
                r#"<float name="aperture_radius" value="0.1"/>"#,
                r#"<integer name="crop_offset_x" value="35"/><integer name="crop_width" value="10"/>"#,
            ),
            "crop window",
        ),
        (
            sensor(
                r#"<float name="aperture_radius" value="0.1"/>"#,
                r#"<integer name="crop_height" value="-3"/>"#,
            ),
            "crop window",
        ),
        (
            sensor(
                r#"<float name="aperture_radius" value="0.1"/>"#,
                r#"<boolean name="sample_border" value="true"/>"#,
            ),
            "sample_border",
        ),
        (
            sensor(
                r#"<float name="aperture_radius" value="0.1"/>"#,
                r#"<rfilter type="tent"><float name="radius" value="0"/></rfilter>"#,
            ),
            "radius",
        ),
    ];
    for (text, needle) in cases {
        let e = load(text.clone()).expect_err(&text);
        assert!(e.contains("lens.xml:"), "{e}");
        assert!(e.contains(needle), "{text}: {e}");
        assert_eq!(e.lines().count(), 1, "{e}");
    }
}

/// Every scene file in the repo's `scenes/` loads with its own defaults
/// (a renamed mesh or texture, or a scene written for a feature the loader
/// refuses, fails here first).
#[test]
fn every_repo_scene_loads() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let mut names: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "xml"))
        .collect();
    names.sort();
    assert!(names.len() >= 20, "{} scenes", names.len());
    for path in &names {
        if let Err(e) = mcmc_render::scene::Scene::load(path, &HashMap::new()) {
            panic!("{}: {e}", path.display());
        }
    }
}

/// A sample count beyond `u32` was clamped to 4294967295; it is refused
/// at its line, as 0 is.
#[test]
fn a_sample_count_beyond_u32_is_refused_not_clamped() {
    for value in ["4294967296", "0"] {
        let text = format!(
            "<scene version=\"3.0.0\">\n<sensor type=\"perspective\"><sampler type=\"independent\"><integer name=\"sample_count\" value=\"{value}\"/></sampler></sensor>\n</scene>\n"
        );
        let e = mcmc_render::scene::Scene::load_str(&text, Path::new("s.xml"), Path::new("."))
            .err()
            .expect("refused")
            .to_string();
        let needle = format!("sample_count must be between 1 and 4294967295, got {value}");
        assert!(e.contains("s.xml:2") && e.contains(&needle), "{e}");
        assert!(!e.contains('\n'), "{e}");
    }
}
