//! Surface UVs as Mitsuba 3 defines them, checked at hand-computed points:
//! `rectangle` (u = (x+1)/2, v = (y+1)/2), `cube` (each face onto [0,1]²),
//! `disk` (u = r, v = φ/2π), `sphere` (u = φ/2π, v = θ/π in object space),
//! OBJ UVs (v flipped by default) and PLY UVs (three property spellings),
//! and meshes without UVs (the barycentrics (b1, b2)). The expected values
//! were also confirmed with Mitsuba 3.9 (`scalar_rgb`, `si.uv` of the same
//! rays).

use glam::{Vec2, Vec3};
use mcmc_render::geometry::Ray;
use mcmc_render::scene::Scene;
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mcmc-render-uv-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A scene holding the shapes of `body` (files resolved in `dir`).
fn scene(dir: &Path, body: &str) -> Scene {
    let text = format!("<scene version=\"3.0.0\"><sensor type=\"perspective\"/>{body}</scene>");
    Scene::load_str(&text, Path::new("uv.xml"), dir).expect("loads")
}

/// UV and shape of the first hit from `o` along `d`.
#[track_caller]
fn uv_at(s: &Scene, o: [f32; 3], d: [f32; 3]) -> (Vec2, u32) {
    let ray = Ray::new(Vec3::from(o), Vec3::from(d).normalize());
    let hit = s.intersect(&ray).expect("the ray hits");
    (hit.sp.uv, hit.sp.shape)
}

#[track_caller]
fn close(got: Vec2, want: [f32; 2]) {
    assert!(
        (got - Vec2::from(want)).abs().max_element() < 1e-5,
        "uv {got} != {want:?}"
    );
}

#[test]
fn rectangle_uv_is_the_affine_map_of_its_square() {
    let s = scene(
        Path::new("."),
        r#"<shape type="rectangle"><transform name="to_world"><scale x="2" y="3"/></transform></shape>"#,
    );
    // World (1, −1.5) is object (0.5, −0.5): uv ((0.5+1)/2, (−0.5+1)/2).
    close(
        uv_at(&s, [1.0, -1.5, 5.0], [0.0, 0.0, -1.0]).0,
        [0.75, 0.25],
    );
    // Near the corners (−1, −1) and (1, 1).
    close(
        uv_at(&s, [-1.998, -2.997, 5.0], [0.0, 0.0, -1.0]).0,
        [0.0005, 0.0005],
    );
    close(
        uv_at(&s, [1.998, 2.997, 5.0], [0.0, 0.0, -1.0]).0,
        [0.9995, 0.9995],
    );
}

#[test]
fn cube_faces_each_map_onto_the_unit_square() {
    let s = scene(Path::new("."), r#"<shape type="cube"/>"#);
    // (origin, direction, uv): the face's corner UVs are (0,1), (1,1),
    // (1,0), (0,0) in Mitsuba's corner order, which makes u and v these
    // affine functions of the two in-face coordinates.
    let cases = [
        // +z: u = (y+1)/2, v = (x+1)/2 at (x, y) = (0.3, 0.2).
        ([0.3, 0.2, 5.0], [0.0, 0.0, -1.0], [0.6, 0.65]),
        // −z: u = (1−y)/2, v = (x+1)/2.
        ([0.3, 0.2, -5.0], [0.0, 0.0, 1.0], [0.4, 0.65]),
        // +x: u = (y+1)/2, v = (1−z)/2 at (y, z) = (0.3, 0.2).
        ([5.0, 0.3, 0.2], [-1.0, 0.0, 0.0], [0.65, 0.4]),
        // −x: u = (y+1)/2, v = (z+1)/2.
        ([-5.0, 0.3, 0.2], [1.0, 0.0, 0.0], [0.65, 0.6]),
        // +y: u = (1−x)/2, v = (1−z)/2 at (x, z) = (0.3, 0.2).
        ([0.3, 5.0, 0.2], [0.0, -1.0, 0.0], [0.35, 0.4]),
        // −y: u = (z+1)/2, v = (x+1)/2.
        ([0.3, -5.0, 0.2], [0.0, 1.0, 0.0], [0.6, 0.65]),
    ];
    for (o, d, want) in cases {
        close(uv_at(&s, o, d).0, want);
    }
}

#[test]
fn disk_uv_is_polar() {
    let s = scene(Path::new("."), r#"<shape type="disk"/>"#);
    let down = [0.0, 0.0, -1.0];
    close(uv_at(&s, [0.5, 0.0, 1.0], down).0, [0.5, 0.0]);
    close(uv_at(&s, [0.0, 0.5, 1.0], down).0, [0.5, 0.25]);
    close(uv_at(&s, [-0.5, 0.0, 1.0], down).0, [0.5, 0.5]);
    // r = 0.5, φ = π + atan(4/3).
    let phi = std::f32::consts::PI + (4.0f32 / 3.0).atan();
    close(
        uv_at(&s, [-0.3, -0.4, 1.0], down).0,
        [0.5, phi / (2.0 * std::f32::consts::PI)],
    );
}

#[test]
fn sphere_uv_is_spherical_in_object_space() {
    let s = scene(
        Path::new("."),
        r#"<shape type="sphere"><point name="center" x="1" y="2" z="3"/><float name="radius" value="2"/></shape>"#,
    );
    // The pole +z: θ = 0.
    close(uv_at(&s, [1.0, 2.0, 10.0], [0.0, 0.0, -1.0]).0, [0.0, 0.0]);
    // +y on the equator: φ = π/2, θ = π/2.
    close(uv_at(&s, [1.0, 10.0, 3.0], [0.0, -1.0, 0.0]).0, [0.25, 0.5]);
    // −y: φ = 3π/2.
    close(uv_at(&s, [1.0, -10.0, 3.0], [0.0, 1.0, 0.0]).0, [0.75, 0.5]);
    // (0.3, 0.4, √0.75) on the unit sphere: φ = atan(4/3), θ = π/6.
    let n = Vec3::new(0.3, 0.4, 0.75f32.sqrt());
    let o = Vec3::new(1.0, 2.0, 3.0) + n * 10.0;
    close(
        uv_at(&s, o.into(), (-n).into()).0,
        [
            (4.0f32 / 3.0).atan() / (2.0 * std::f32::consts::PI),
            1.0 / 6.0,
        ],
    );
    // Rotated 90° about z: object (cos 30°, sin 30°, 0) lies along world
    // (−sin 30°, cos 30°, 0), and world −x is object +y (φ = π/2).
    let s = scene(
        Path::new("."),
        r#"<shape type="sphere"><transform name="to_world"><rotate z="1" angle="90"/></transform></shape>"#,
    );
    let w = Vec3::new(-0.5, 0.75f32.sqrt(), 0.0);
    close(
        uv_at(&s, (w * 5.0).into(), (-w).into()).0,
        [1.0 / 12.0, 0.5],
    );
    close(uv_at(&s, [-5.0, 0.0, 0.0], [1.0, 0.0, 0.0]).0, [0.25, 0.5]);
}

#[test]
fn mesh_uvs_from_obj_and_ply() {
    let dir = scratch("meshes");
    let quad = "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n";
    std::fs::write(
        dir.join("uv.obj"),
        format!("{quad}vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"),
    )
    .unwrap();
    std::fs::write(dir.join("bare.obj"), format!("{quad}f 1 2 3\nf 1 3 4\n")).unwrap();
    let ply = |u: &str, v: &str| {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float {u}\nproperty float {v}\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n-1 -1 0 0 0\n1 -1 0 1 0\n1 1 0 1 1\n-1 1 0 0 1\n3 0 1 2\n3 0 2 3\n"
        )
    };
    for (name, u, v) in [
        ("uv", "u", "v"),
        ("st", "s", "t"),
        ("tex", "texture_u", "texture_v"),
    ] {
        std::fs::write(dir.join(format!("{name}.ply")), ply(u, v)).unwrap();
    }
    // Each shape is moved to its own z so one ray meets one shape.
    let shape = |kind: &str, file: &str, extra: &str, z: u32| {
        format!(
            r#"<shape type="{kind}"><string name="filename" value="{file}"/>{extra}<transform name="to_world"><translate z="{z}"/></transform></shape>"#
        )
    };
    let body = [
        shape("obj", "uv.obj", "", 0),
        shape(
            "obj",
            "uv.obj",
            r#"<boolean name="flip_tex_coords" value="false"/>"#,
            10,
        ),
        shape("obj", "bare.obj", "", 20),
        shape(
            "obj",
            "bare.obj",
            r#"<boolean name="face_normals" value="true"/>"#,
            30,
        ),
        shape("ply", "uv.ply", "", 40),
        shape("ply", "st.ply", "", 50),
        shape(
            "ply",
            "tex.ply",
            r#"<boolean name="flip_tex_coords" value="true"/>"#,
            60,
        ),
    ]
    .concat();
    let s = scene(&dir, &body);
    let at = |z: f32, x: f32, y: f32| uv_at(&s, [x, y, z + 1.0], [0.0, 0.0, -1.0]);
    // (0.5, −0.5) has file UV (0.75, 0.25); OBJ flips v by default.
    close(at(0.0, 0.5, -0.5).0, [0.75, 0.75]);
    close(at(10.0, 0.5, -0.5).0, [0.75, 0.25]);
    // No UVs: the barycentrics (b1, b2) of the hit in its triangle. In
    // triangle (v1, v2, v3), (0.5, −0.5) = v1 + b1·(2, 0) + b2·(2, 2):
    // b2 = 0.25, b1 = 0.5. Both the vertex-normal and the flat path.
    close(at(20.0, 0.5, -0.5).0, [0.5, 0.25]);
    close(at(30.0, 0.5, -0.5).0, [0.5, 0.25]);
    // In triangle (v1, v3, v4), (−0.5, 0.5) = v1 + b1·(2, 2) + b2·(0, 2).
    close(at(30.0, -0.5, 0.5).0, [0.25, 0.5]);
    // PLY: as stored, unless asked to flip.
    close(at(40.0, 0.5, -0.5).0, [0.75, 0.25]);
    close(at(50.0, 0.2, 0.1).0, [0.6, 0.55]);
    close(at(60.0, 0.2, 0.1).0, [0.6, 0.45]);
}

#[test]
fn non_finite_uvs_are_refused_with_the_file_named() {
    let dir = scratch("nan");
    std::fs::write(
        dir.join("nan.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt nan 0\nvt 0 1\nf 1/1 2/2 3/3\n",
    )
    .unwrap();
    let text = r#"<scene version="3.0.0"><sensor type="perspective"/><shape type="obj"><string name="filename" value="nan.obj"/></shape></scene>"#;
    let e = Scene::load_str(text, Path::new("uv.xml"), &dir)
        .err()
        .expect("refused")
        .to_string();
    assert!(
        e.contains("nan.obj") && e.contains("texture coordinate 1"),
        "{e}"
    );
}
