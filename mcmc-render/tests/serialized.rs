//! Mitsuba `.serialized` meshes: the committed files of
//! `tests/data/serialized/` (written by `scenes/tools/make_serialized.py`
//! and checked there with Mitsuba 3's own reader) load to the same mesh as
//! their OBJ copies and render bit for bit the same; every malformed file
//! is one error line naming the scene line and the mesh file.

mod cli_support;

use cli_support::{assert_clean_failure, exr, run, run_ok, scratch, write};
use flate2::Compression;
use flate2::write::ZlibEncoder;
use glam::Vec3;
use mcmc_render::scene::mesh::{RawMesh, load_obj};
use mcmc_render::scene::serialized::load_serialized;
use std::io::Write;
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/serialized")
        .join(name)
}

/// The triangles as (position, normal) corners: the OBJ reader numbers
/// vertices in its own order, so meshes are compared corner by corner.
fn corners(m: &RawMesh) -> Vec<(Vec3, Option<Vec3>)> {
    m.indices
        .iter()
        .flatten()
        .map(|&i| {
            let i = i as usize;
            (m.positions[i], m.normals.as_ref().map(|n| n[i]))
        })
        .collect()
}

fn assert_same_mesh(a: &RawMesh, b: &RawMesh, what: &str) {
    assert_eq!(a.indices.len(), b.indices.len(), "{what}: triangle count");
    assert_eq!(a.normals.is_some(), b.normals.is_some(), "{what}: normals");
    assert_eq!(corners(a), corners(b), "{what}: triangles differ");
}

#[test]
fn committed_files_read_as_their_obj_copies() {
    let patch = load_obj(&data("patch.obj")).unwrap();
    let bare = load_obj(&data("patch-no-normals.obj")).unwrap();
    let tet = load_obj(&data("tetrahedron.obj")).unwrap();
    assert!(patch.normals.is_some() && bare.normals.is_none());
    let v4 = data("meshes-v4.serialized");
    let v3 = data("meshes-v3-double.serialized");
    // Version 4, float32, normals and UVs.
    let s = load_serialized(&v4, 0).unwrap();
    assert!(!s.face_normals);
    assert_same_mesh(&s.mesh, &patch, "v4 shape 0");
    assert_same_mesh(&load_serialized(&v4, 1).unwrap().mesh, &tet, "v4 shape 1");
    // Version 3, float64, UVs and colours, no normals.
    assert_same_mesh(&load_serialized(&v3, 0).unwrap().mesh, &bare, "v3 shape 0");
    assert_same_mesh(&load_serialized(&v3, 1).unwrap().mesh, &tet, "v3 shape 1");
    // Texture coordinates: the generator's grid (i/6, j/6), written as
    // float32 (v4) and float64 (v3); none on the tetrahedron.
    let grid: Vec<glam::Vec2> = (0..7)
        .flat_map(|j| (0..7).map(move |i| (i, j)))
        .map(|(i, j)| glam::Vec2::new((i as f64 / 6.0) as f32, (j as f64 / 6.0) as f32))
        .collect();
    assert_eq!(
        load_serialized(&v4, 0).unwrap().mesh.uvs,
        Some(grid.clone())
    );
    assert_eq!(load_serialized(&v3, 0).unwrap().mesh.uvs, Some(grid));
    assert_eq!(load_serialized(&v4, 1).unwrap().mesh.uvs, None);
    // Control: the two shapes differ, so shape_index is honoured.
    assert_ne!(
        corners(&load_serialized(&v4, 0).unwrap().mesh),
        corners(&tet)
    );
}

/// A scene with the patch under a light, the patch given by `shape`.
fn patch_scene(shape: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0.5,-3,2.5" target="0,0,0" up="0,0,1"/></transform>
        <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
        <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="16"/></film>
    </sensor>
    <shape type="rectangle"><transform name="to_world"><scale value="3"/><translate z="-0.5"/></transform><bsdf type="diffuse"/></shape>
    {shape}
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.5"/><rotate x="1" angle="180"/><translate z="2"/></transform>
        <emitter type="area"><rgb name="radiance" value="4"/></emitter>
    </shape>
</scene>"#
    )
}

/// Renders `shape` in the patch scene, returns the pixels.
fn render_patch(dir: &Path, name: &str, shape: &str) -> Vec<mcmc_render::color::Rgb> {
    write(dir, &format!("{name}.xml"), &patch_scene(shape));
    run_ok(
        &[
            "render",
            &format!("{name}.xml"),
            "--seed",
            "3",
            "--threads",
            "1",
            "--out",
            &format!("{name}.exr"),
            "--quiet",
        ],
        dir,
    );
    exr(&dir.join(format!("{name}.exr"))).2
}

#[test]
fn serialized_renders_bit_for_bit_as_obj() {
    let dir = scratch("serialized-render");
    let file = |n: &str| data(n).display().to_string();
    let trafo = r#"<transform name="to_world"><rotate z="1" angle="30"/><scale x="1.2" y="0.8" z="1.5"/><translate z="0.1"/></transform>"#;
    let cases = [
        // Smooth normals from the file, a to_world with non-uniform scale.
        (
            format!(
                r#"<shape type="serialized"><string name="filename" value="{}"/>{trafo}<bsdf type="diffuse"/></shape>"#,
                file("meshes-v4.serialized")
            ),
            format!(
                r#"<shape type="obj"><string name="filename" value="{}"/>{trafo}<bsdf type="diffuse"/></shape>"#,
                file("patch.obj")
            ),
        ),
        // Computed normals (none in the file), flipped.
        (
            format!(
                r#"<shape type="serialized"><string name="filename" value="{}"/><boolean name="flip_normals" value="true"/><bsdf type="twosided"><bsdf type="diffuse"/></bsdf></shape>"#,
                file("meshes-v3-double.serialized")
            ),
            format!(
                r#"<shape type="obj"><string name="filename" value="{}"/><boolean name="flip_normals" value="true"/><bsdf type="twosided"><bsdf type="diffuse"/></bsdf></shape>"#,
                file("patch-no-normals.obj")
            ),
        ),
        // face_normals discards the file's normals; shape_index 1.
        (
            format!(
                r#"<shape type="serialized"><string name="filename" value="{}"/><boolean name="face_normals" value="true"/><integer name="shape_index" value="1"/><bsdf type="diffuse"/></shape>"#,
                file("meshes-v4.serialized")
            ),
            format!(
                r#"<shape type="obj"><string name="filename" value="{}"/><boolean name="face_normals" value="true"/><bsdf type="diffuse"/></shape>"#,
                file("tetrahedron.obj")
            ),
        ),
    ];
    let mut images = Vec::new();
    for (i, (ser, obj)) in cases.iter().enumerate() {
        let a = render_patch(&dir, &format!("ser{i}"), ser);
        let b = render_patch(&dir, &format!("obj{i}"), obj);
        assert!(a == b, "case {i}: serialized and OBJ renders differ");
        images.push(a);
    }
    // Control: the cases render differently (the comparison can fail).
    assert!(images[0] != images[1] && images[0] != images[2]);
}

/// Flags of the format.
const NORMALS: u32 = 0x1;
const SINGLE: u32 = 0x1000;
const DOUBLE: u32 = 0x2000;

/// One shape's bytes: header, then the zlib stream of `body`.
fn shape_bytes(version: u16, body: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(&0x041Cu16.to_le_bytes());
    out.extend_from_slice(&version.to_le_bytes());
    let mut z = ZlibEncoder::new(Vec::new(), Compression::default());
    z.write_all(body).unwrap();
    out.extend(z.finish().unwrap());
    out
}

/// The body of a version-4 shape: flags, name, counts, then `data`.
fn body(flags: u32, vertices: u64, triangles: u64, data: &[u8]) -> Vec<u8> {
    let mut b = flags.to_le_bytes().to_vec();
    b.extend_from_slice(b"s\0");
    b.extend_from_slice(&vertices.to_le_bytes());
    b.extend_from_slice(&triangles.to_le_bytes());
    b.extend_from_slice(data);
    b
}

/// A triangle's worth of float32 positions and the given indices.
fn triangle_data(indices: [u32; 3]) -> Vec<u8> {
    let mut d = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        d.extend_from_slice(&v.to_le_bytes());
    }
    for i in indices {
        d.extend_from_slice(&i.to_le_bytes());
    }
    d
}

/// Shapes concatenated, with a version-4 end-of-file dictionary.
fn file_bytes(shapes: &[Vec<u8>]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut offsets = Vec::new();
    for s in shapes {
        offsets.push(out.len() as u64);
        out.extend_from_slice(s);
    }
    for o in offsets {
        out.extend_from_slice(&o.to_le_bytes());
    }
    out.extend_from_slice(&(shapes.len() as u32).to_le_bytes());
    out
}

/// `info` on a scene holding `mesh.serialized` (with `extra` parameters)
/// must fail with one line naming the scene line, the mesh and `needle`.
fn assert_refused(dir: &Path, bytes: &[u8], extra: &str, needle: &str) {
    std::fs::write(dir.join("mesh.serialized"), bytes).unwrap();
    let shape = format!(
        "<shape type=\"serialized\">\n<string name=\"filename\" value=\"mesh.serialized\"/>{extra}</shape>"
    );
    write(dir, "s.xml", &patch_scene(&shape));
    let out = run(&["info", "s.xml"], dir);
    assert_clean_failure(&out, &["s.xml:", "mesh.serialized", needle]);
}

#[test]
fn malformed_files_are_one_line_naming_the_file() {
    let dir = scratch("serialized-bad");
    let good = shape_bytes(4, &body(SINGLE, 3, 1, &triangle_data([0, 1, 2])));
    // Control: the well-formed file loads.
    std::fs::write(
        dir.join("mesh.serialized"),
        file_bytes(std::slice::from_ref(&good)),
    )
    .unwrap();
    let shape =
        r#"<shape type="serialized"><string name="filename" value="mesh.serialized"/></shape>"#;
    write(&dir, "s.xml", &patch_scene(shape));
    assert!(run_ok(&["info", "s.xml"], &dir).contains("1 serialized"));

    let mut bad_magic = file_bytes(std::slice::from_ref(&good));
    bad_magic[0] = 0x1D;
    assert_refused(&dir, &bad_magic, "", "format id 0x041d");
    let mut v5 = file_bytes(std::slice::from_ref(&good));
    v5[2] = 5;
    assert_refused(&dir, &v5, "", "unsupported serialized version 5");
    assert_refused(&dir, &[0x1C], "", "shorter than the 4-byte header");
    assert_refused(&dir, &good[..good.len() / 2], "", "truncated");
    assert_refused(&dir, &[], "", "truncated");
    // Counts that promise more than the data holds.
    let short = shape_bytes(4, &body(SINGLE, 4, 1, &triangle_data([0, 1, 2])));
    assert_refused(&dir, &file_bytes(&[short]), "", "truncated");
    let absurd = shape_bytes(4, &body(SINGLE, 1 << 31, 1 << 40, &[]));
    assert_refused(&dir, &file_bytes(&[absurd]), "", "compressed bytes");
    let huge = shape_bytes(4, &body(SINGLE, 1 << 33, 1, &[]));
    assert_refused(&dir, &file_bytes(&[huge]), "", "more than 2^32 - 1");
    let empty = shape_bytes(4, &body(SINGLE, 0, 0, &[]));
    assert_refused(&dir, &file_bytes(&[empty]), "", "nothing to render");
    // Flags.
    let both = shape_bytes(4, &body(SINGLE | DOUBLE, 3, 1, &triangle_data([0, 1, 2])));
    assert_refused(&dir, &file_bytes(&[both]), "", "both single and double");
    let unknown = shape_bytes(4, &body(SINGLE | 0x4, 3, 1, &triangle_data([0, 1, 2])));
    assert_refused(&dir, &file_bytes(&[unknown]), "", "unknown flags 0x4");
    let no_normals = shape_bytes(4, &body(SINGLE | NORMALS, 3, 1, &triangle_data([0, 1, 2])));
    assert_refused(&dir, &file_bytes(&[no_normals]), "", "truncated");
    // Indices out of range.
    let oob = shape_bytes(4, &body(SINGLE, 3, 1, &triangle_data([0, 1, 3])));
    assert_refused(
        &dir,
        &file_bytes(&[oob]),
        "",
        "refers to vertex 3, but there are 3",
    );
    // Not zlib.
    let mut garbage = good[..4].to_vec();
    garbage.extend_from_slice(&[0xFF; 64]);
    assert_refused(&dir, &garbage, "", "corrupt compressed data");
    // shape_index and the end-of-file dictionary.
    let two = file_bytes(&[good.clone(), good.clone()]);
    let index = |i: &str| format!(r#"<integer name="shape_index" value="{i}"/>"#);
    assert_refused(
        &dir,
        &two,
        &index("2"),
        "shape_index 2 is out of range: the file holds 2",
    );
    assert_refused(&dir, &two, &index("-1"), "shape_index must be in 0..2^32");
    let mut lying_count = two.clone();
    let n = lying_count.len();
    lying_count[n - 4..].copy_from_slice(&u32::MAX.to_le_bytes());
    assert_refused(&dir, &lying_count, &index("1"), "claims 4294967295 shapes");
    let mut lying_offset = two.clone();
    lying_offset[n - 12..n - 4].copy_from_slice(&(1u64 << 40).to_le_bytes());
    assert_refused(
        &dir,
        &lying_offset,
        &index("1"),
        "end-of-file dictionary places shape 1",
    );
    let mut misplaced = two.clone();
    misplaced[n - 12..n - 4].copy_from_slice(&8u64.to_le_bytes());
    assert_refused(&dir, &misplaced, &index("1"), "format id");
}

mod mutated {
    //! Arbitrary damage to a shape's decompressed body (any byte changed,
    //! the body cut anywhere), recompressed so that it reaches the parser:
    //! the reader returns a mesh whose indices are in range, or an error;
    //! it never panics.
    use super::*;
    use proptest::prelude::*;

    /// A valid body with normals: flags, name, counts, positions, normals
    /// and two triangles.
    fn valid_body() -> Vec<u8> {
        let mut data = Vec::new();
        for v in [
            0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0,
        ] {
            data.extend_from_slice(&v.to_le_bytes());
        }
        for _ in 0..4 {
            for v in [0.0f32, 0.0, 1.0] {
                data.extend_from_slice(&v.to_le_bytes());
            }
        }
        for i in [0u32, 1, 2, 1, 3, 2] {
            data.extend_from_slice(&i.to_le_bytes());
        }
        body(SINGLE | NORMALS, 4, 2, &data)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        #[test]
        fn damaged_bodies_never_panic(
            edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..4),
            cut in any::<prop::sample::Index>(),
            truncate in any::<bool>(),
        ) {
            let dir = std::env::temp_dir().join(format!("mcmc-render-ser-prop-{}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            let mut b = valid_body();
            for (at, byte) in &edits {
                let i = at.index(b.len());
                b[i] = *byte;
            }
            if truncate {
                b.truncate(cut.index(b.len()));
            }
            let path = dir.join("m.serialized");
            std::fs::write(&path, file_bytes(&[shape_bytes(4, &b)])).unwrap();
            if let Ok(s) = load_serialized(&path, 0) {
                let n = s.mesh.positions.len();
                prop_assert!(s.mesh.indices.iter().flatten().all(|&i| (i as usize) < n));
                prop_assert!(s.mesh.normals.as_ref().is_none_or(|v| v.len() == n));
            }
        }
    }
}
