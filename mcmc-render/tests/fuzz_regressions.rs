//! Inputs found by the fuzz targets of `mcmc-render/fuzz/` (see
//! docs/fuzzing.md), each fed to the same entry point the target calls:
//! every one must give a clean `Err` naming the problem, never a panic, a
//! hang or an allocation on the input's word. CI runs these, not the
//! fuzzer. Also the in-memory entry points the targets use, checked
//! against the file readers they share their code with.

use mcmc_render::scene::mesh::{load_obj, load_ply, obj_from_bytes, ply_from_bytes};
use mcmc_render::scene::serialized::{load_serialized, serialized_from_bytes};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/serialized")
        .join(name)
}

fn seed(target: &str, name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/seeds")
        .join(target)
        .join(name)
}

/// Runs `f` on a thread and fails if it does not return within `secs`
/// (a regression to a hang then fails instead of stalling the suite).
fn within<T: Send + 'static>(secs: u64, what: &str, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(Duration::from_secs(secs))
        .unwrap_or_else(|_| panic!("{what}: no answer within {secs} s"))
}

/// `err` is one line and contains `needle`.
fn assert_clean_err(err: &str, needle: &str) {
    assert!(!err.contains('\n'), "error spans lines: {err:?}");
    assert!(
        err.contains(needle),
        "error {err:?} does not name {needle:?}"
    );
}

#[test]
fn in_memory_readers_read_what_the_file_readers_read() {
    let path = data("tetrahedron.obj");
    let a = load_obj(&path).unwrap();
    let b = obj_from_bytes(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!((a.positions, a.indices), (b.positions, b.indices));
    let path = seed("ply", "quad-binary_little_endian.ply");
    let a = load_ply(&path).unwrap();
    let b = ply_from_bytes(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(
        (a.positions, a.indices, a.uvs),
        (b.positions, b.indices, b.uvs)
    );
    let path = data("meshes-v4.serialized");
    let bytes = std::fs::read(&path).unwrap();
    for index in 0..2 {
        let a = load_serialized(&path, index).unwrap().mesh;
        let b = serialized_from_bytes(&bytes, index).unwrap().mesh;
        assert_eq!((a.positions, a.indices), (b.positions, b.indices));
    }
}

/// An OBJ's `mtllib` is not opened (materials are not used): one naming
/// `/dev/zero` made the OBJ reader read an endless line until memory ran
/// out (found while writing the OBJ target, which reads from memory).
#[cfg(unix)]
#[test]
fn obj_mtllib_naming_a_device_is_not_followed() {
    let dir = std::env::temp_dir().join(format!("mcmc-fuzz-mtllib-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("zero.obj");
    std::fs::write(
        &path,
        "mtllib /dev/zero\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    let mesh = within(20, "mtllib /dev/zero", move || load_obj(&path)).unwrap();
    assert_eq!(mesh.indices.len(), 1);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A study CSV with an infinite time: `write_csv` never writes one, and
/// plotting it looped over 2^31 decades of tick positions (a hang).
#[test]
fn convergence_csv_infinite_seconds_is_refused() {
    use mcmc_render::cli::convergence::parse_csv;
    let header = "integrator,seconds,samples,rel_mse,rmse\n";
    for (row, needle) in [
        (
            "pt,inf,10,0.5,0.1\n",
            "seconds must be finite and non-negative, got inf",
        ),
        (
            "pt,-1,10,0.5,0.1\n",
            "seconds must be finite and non-negative, got -1",
        ),
        (
            "pt,NaN,10,0.5,0.1\n",
            "seconds must be finite and non-negative, got NaN",
        ),
        (
            "pt,1,10,-0.5,0.1\n",
            "rel_mse and rmse must be non-negative",
        ),
    ] {
        let err = parse_csv(&format!("{header}{row}"), Path::new("s.csv")).unwrap_err();
        assert_clean_err(&err, needle);
        assert_clean_err(&err, "s.csv:2:");
    }
    // What write_csv writes for a non-finite image still reads.
    let ok = parse_csv(
        &format!("{header}pt,1.0000,10,NaN,inf\n"),
        Path::new("s.csv"),
    )
    .unwrap();
    assert!(ok[0].rel_mse.is_nan());
}

/// Records whose values a log axis cannot span (a subnormal time, a huge
/// error) are refused by the plot instead of looping over 2^31 decades.
#[test]
fn convergence_plot_of_extreme_values_is_refused() {
    use mcmc_render::cli::convergence::{Record, write_plot};
    let dir = std::env::temp_dir().join(format!("mcmc-fuzz-plot-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (seconds, rel_mse) in [(1e-310, 0.5), (1.0, 1e300), (1e35, 0.5)] {
        let records = vec![Record {
            integrator: "pt".into(),
            seconds,
            samples: 1,
            rel_mse,
            rmse: 0.1,
            corrected: None,
        }];
        let png = dir.join("plot.png");
        let err = within(20, "plot of extreme values", move || {
            write_plot(&png, &records, &["pt".to_string()], "t")
        })
        .unwrap_err();
        assert_clean_err(&err, "cannot plot pt at");
        assert_clean_err(&err, "the log axes span 1e-30 to 1e30");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

fn cornell() -> mcmc_render::scene::Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box.xml");
    mcmc_render::scene::Scene::load(&path, &Default::default()).unwrap()
}

/// An MMLT dump traces one path per depth `1..=max_depth`: a dump with
/// `max_depth 4294967294` (found by the `pss_replay` target) asked for a
/// 240 GB vector and aborted. MMLT's depth is now bounded, for the
/// integrator and its dumps alike.
#[test]
fn pss_replay_mmlt_dump_with_a_huge_depth_is_refused() {
    use mcmc_render::pss_dump::{parse_pss, replay};
    let dump = parse_pss(
        "# sampler mmlt\n# max_depth 4294967294\n0.5\n",
        Path::new("d.pss"),
    )
    .unwrap();
    let err = replay(&cornell(), &dump).err().expect("refused");
    assert_clean_err(
        &err,
        "max_depth must be at most 1024 (mmlt's limit), got 4294967294",
    );
    // The limit itself still replays.
    let dump = parse_pss(
        "# sampler mmlt\n# max_depth 3\n0.5\n0.25\n",
        Path::new("d.pss"),
    )
    .unwrap();
    assert_eq!(replay(&cornell(), &dump).unwrap().traces.len(), 3);
}

/// The same bound on the integrator: `--max-depth 4294967294` with mmlt
/// would build one chain family member per depth.
#[test]
fn mmlt_with_a_huge_max_depth_is_refused() {
    use mcmc_render::integrators::registry;
    let err = registry::configure(
        None,
        Some("mmlt"),
        &[("max_depth".into(), "4294967294".into())],
    )
    .err()
    .expect("refused");
    assert_clean_err(&err, "max_depth must be at most 1024");
    assert!(
        registry::configure(None, Some("mmlt"), &[("max_depth".into(), "1024".into())]).is_ok()
    );
}

/// EXR headers claiming gigapixel images (the `exr` target's findings in
/// `tests/data/fuzz/exr-*.exr`, 0.9–7.6 KB files asking for 4–309 GB)
/// made `read_exr` allocate the claimed image and abort (the three
/// `exr-oom-*` files kept apart at first grew past 2 GB: the same class,
/// refused by the same check, 5 MB peak for all three). The header's
/// sizes are now checked against the file's length and the memory
/// available before anything is allocated.
#[test]
fn exr_headers_claiming_more_than_the_file_holds_are_refused() {
    use mcmc_render::image_io::exr_from_bytes;
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "exr"))
        .collect();
    files.sort();
    assert!(files.len() >= 4, "the committed findings are missing");
    for path in files {
        let bytes = std::fs::read(&path).unwrap();
        let name = path.display().to_string();
        let err = within(20, &name, move || {
            exr_from_bytes(&bytes, Path::new("x.exr")).map(|_| ())
        })
        .err()
        .unwrap_or_else(|| panic!("{name} was accepted"));
        assert_clean_err(&err, "cannot read x.exr: ");
    }
    // A real image still reads.
    let sky = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/textures/sky.exr");
    let (w, h, px) = exr_from_bytes(&std::fs::read(&sky).unwrap(), &sky).unwrap();
    assert_eq!(px.len(), w as usize * h as usize);
}

/// PLY findings of the `ply` target (`tests/data/fuzz/ply-*.ply`, session
/// 15: 11 out-of-memory, 4 over the 10 s timeout): binary files declaring
/// an element with a huge count and no properties (`element face
/// 614891469123651`). Such entries take no bytes, so the file's end never
/// stopped ply-rs, which read them into memory until the fuzzer's 2 GB
/// limit or its clock. They are refused from the header.
#[test]
fn ply_elements_without_properties_are_refused() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.file_name().unwrap().to_string_lossy().starts_with("ply-"))
        .collect();
    files.sort();
    assert!(files.len() >= 3, "the committed findings are missing");
    for path in files {
        let bytes = std::fs::read(&path).unwrap();
        let name = path.display().to_string();
        let err = within(20, &name, move || ply_from_bytes(&bytes).map(|_| ()))
            .err()
            .unwrap_or_else(|| panic!("{name} was accepted"));
        assert_clean_err(&err, "but no properties");
    }
    // An ASCII element without properties is bounded by its lines: read.
    let ascii = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nelement note 2\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n\n\n";
    assert_eq!(ply_from_bytes(ascii.as_bytes()).unwrap().indices.len(), 1);
}

/// OBJ findings of the `obj` target (`tests/data/fuzz/obj-*.obj`): a
/// relative face index reaching before the first texture coordinate or
/// normal overflowed `vt * 2` / `vn * 3` inside tobj 4.0.5 (`lib.rs:852`,
/// `:860`): a panic where overflow checks are on (debug and test builds), a
/// wrapped, wrong index in release. Face indices are now checked before
/// tobj reads the text; each finding is one line naming the line and the
/// corner.
#[test]
fn obj_face_indices_out_of_range_are_refused() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "obj"))
        .collect();
    files.sort();
    assert_eq!(files.len(), 6, "the committed findings are missing");
    for path in files {
        let bytes = std::fs::read(&path).unwrap();
        let r = std::panic::catch_unwind(|| obj_from_bytes(&bytes).map(|_| ()));
        let err = match r {
            Ok(Err(e)) => e,
            other => panic!("{}: {other:?}", path.display()),
        };
        assert_clean_err(&err, "line ");
        assert_clean_err(&err, "index");
    }
    // Through the scene loader the error names the scene, the mesh, its
    // line and the corner.
    let dir = std::env::temp_dir().join(format!("mcmc-fuzz-objidx-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join("m.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//-5 3//1\n",
    )
    .unwrap();
    let xml = r#"<scene version="3.0.0">
<shape type="obj"><string name="filename" value="m.obj"/></shape>
</scene>"#;
    std::fs::write(dir.join("s.xml"), xml).unwrap();
    let err = mcmc_render::scene::Scene::load(&dir.join("s.xml"), &Default::default())
        .err()
        .expect("refused")
        .to_string();
    assert_clean_err(
        &err,
        "cannot load mesh \"m.obj\": line 5: relative normal index -5 in face corner '2//-5' reaches before the first normal (1 read so far)",
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// tobj's own errors carry no position; the reader adds the line it
/// stopped at.
#[test]
fn obj_parse_errors_name_their_line() {
    let err = obj_from_bytes(b"v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n").unwrap_err();
    assert_clean_err(&err, "line 2: position parse error");
    let err = obj_from_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n\xff\n").unwrap_err();
    assert_clean_err(&err, "line 5: not UTF-8 text");
    // A bad index before a line that is not UTF-8 is the error reported.
    let err = obj_from_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n\xff\n").unwrap_err();
    assert_clean_err(&err, "line 4: relative vertex index -4");
}

/// The face-index check (`scene/obj_indices.rs`) on each kind of index.
const OBJ_HEAD: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n";

fn obj_err(faces: &str) -> String {
    obj_from_bytes(format!("{OBJ_HEAD}{faces}").as_bytes()).unwrap_err()
}

#[test]
fn obj_valid_face_indices_pass() {
    for faces in [
        "f 1 2 3\n",
        "f -3 -2 -1\n",
        "f 1/1/1 2/1/1 3//1\n",
        "f 1/-1/-1 2/1 3\nl 1 2\n",
        // A face may name a vertex listed after it (tobj exports at the
        // object's end).
        "f 1 2 4\nv 1 1 0\n",
    ] {
        obj_from_bytes(format!("{OBJ_HEAD}{faces}").as_bytes()).unwrap();
    }
}

#[test]
fn obj_every_kind_of_bad_face_index_is_one_line_naming_line_and_value() {
    for (faces, needle) in [
        (
            "f 1/1/-5 2 3\n",
            "line 6: relative normal index -5 in face corner '1/1/-5' reaches before the first normal (1 read so far)",
        ),
        (
            "f 1/-2 2 3\n",
            "line 6: relative texture coordinate index -2",
        ),
        ("f -4 2 3\n", "line 6: relative vertex index -4"),
        (
            "f 1/0 2 3\n",
            "line 6: texture coordinate index 0 in face corner '1/0' (OBJ indices start at 1)",
        ),
        (
            "f 1/9223372036854775807 2 3\n",
            "line 6: texture coordinate index 9223372036854775807 in face corner '1/9223372036854775807', but the file has 1 texture coordinates",
        ),
        (
            "f 1 2 3\nf 1 2 4\n",
            "line 7: vertex index 4 in face corner '4', but the file has 3 vertices",
        ),
        (
            "f 1 2 99999999999999999999\n",
            "line 6: vertex index '99999999999999999999' of face corner '99999999999999999999' is not an integer",
        ),
        (
            "f 1/1/1/1 2 3\n",
            "line 6: face corner '1/1/1/1' has more than three indices",
        ),
        ("f\n", "line 6: 'f' with no indices"),
        ("l 1 -9\n", "line 6: relative vertex index -9"),
        // CRLF line ends.
        (
            "f 1 2 3\r\nf 1 2 5\r\n",
            "line 7: vertex index 5 in face corner '5'",
        ),
    ] {
        let e = obj_err(faces);
        assert!(!e.contains('\n'), "{e}");
        assert!(e.contains(needle), "{e:?} lacks {needle:?}");
    }
}

/// The texture reader's in-memory entry point (the `texture` target's)
/// reads what the file reader reads, by content or by the format given.
#[test]
fn texture_reader_in_memory_reads_what_the_file_reader_reads() {
    use mcmc_render::texture::{linear_from_bytes, read_linear};
    let textures = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/textures");
    for (name, format) in [
        ("grid.png", image::ImageFormat::Png),
        ("sky.exr", image::ImageFormat::OpenExr),
    ] {
        let path = textures.join(name);
        let bytes = std::fs::read(&path).unwrap();
        let from_file = read_linear(&path, false).unwrap();
        assert_eq!(linear_from_bytes(&bytes, None, false).unwrap(), from_file);
        assert_eq!(
            linear_from_bytes(&bytes, Some(format), false).unwrap(),
            from_file
        );
    }
}

/// A texture image whose header claims more than the `image` crate's
/// 512 MiB limit (a PNG claiming 100000×100000 grey pixels, 10 GB, in 57
/// bytes) is one line, nothing allocated; one claiming less but with no
/// pixel data is one line too.
#[test]
fn texture_headers_claiming_huge_images_are_one_line() {
    use mcmc_render::texture::linear_from_bytes;
    // Signature, IHDR (width, height, 8-bit grey), CRC, empty IDAT, IEND.
    let png = |w: u32, h: u32| {
        let mut ihdr = b"IHDR".to_vec();
        ihdr.extend_from_slice(&w.to_be_bytes());
        ihdr.extend_from_slice(&h.to_be_bytes());
        ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
        let mut f = b"\x89PNG\r\n\x1a\n".to_vec();
        f.extend_from_slice(&13u32.to_be_bytes());
        f.extend_from_slice(&ihdr);
        f.extend_from_slice(&crc32(&ihdr).to_be_bytes());
        for chunk in [&b"IDAT"[..], b"IEND"] {
            f.extend_from_slice(&0u32.to_be_bytes());
            f.extend_from_slice(chunk);
            f.extend_from_slice(&crc32(chunk).to_be_bytes());
        }
        f
    };
    for (w, h, needle) in [(100_000, 100_000, "limit"), (64, 64, "")] {
        let bytes = png(w, h);
        let err = within(20, "png", move || {
            linear_from_bytes(&bytes, None, false).map(|_| ())
        })
        .expect_err("an image without pixels was accepted");
        assert_clean_err(&err, needle);
    }
}

/// CRC-32 (PNG's chunk checksum), bit by bit.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// 64-bit FNV-1a (the checkpoints' checksum), byte by byte.
fn fnv1a(bytes: &[u8]) -> u64 {
    (bytes.iter()).fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// A per-pixel checkpoint's bytes (format 2): magic, the eight words, a
/// ninth (no words of the integrator's), `floats`, then the checksum of
/// all before it (so that the reader gets past it to the words).
fn checkpoint_bytes(words: [u64; 8], floats: &[f32]) -> Vec<u8> {
    let mut b = b"mcmcPX02".to_vec();
    for w in words.into_iter().chain([0]) {
        b.extend_from_slice(&w.to_le_bytes());
    }
    for f in floats {
        b.extend_from_slice(&f.to_le_bytes());
    }
    let checksum = fnv1a(&b);
    b.extend_from_slice(&checksum.to_le_bytes());
    b
}

/// Checkpoints (`render --checkpoint`) whose words disagree with their
/// image: `load` accepted any counts whose floats filled the file, so a
/// file with 0 sample and 12 splat accumulators for a 4×3 image loaded and
/// then panicked the render (`expect("the command line checked the
/// checkpoint")`), a count of 2^62 accumulators overflowed `4 * n` (a
/// panic with overflow checks), NaN accumulators resumed into a NaN image
/// and a pass count above the samples done, or counts past 2^64 samples,
/// overflowed the render's counters. Each is one line now, naming the file;
/// a consistent file still loads and resumes.
#[test]
fn checkpoints_whose_counts_do_not_fit_the_image_are_refused() {
    use mcmc_render::checkpoint::{load, progress_from_bytes};
    let path = Path::new("x.ckpt");
    let ok = [7, 2, 3, 0, 4, 3, 12, 12];
    let floats = vec![0.5f32; 12 * 7];
    let good = progress_from_bytes(&checkpoint_bytes(ok, &floats), path, 7, (4, 3)).unwrap();
    assert_eq!((good.pass, good.spp_done, good.samples.len()), (2, 3, 12));
    // The fuzz target's per-pixel seeds are of the current format and load.
    for name in ["after-two-passes", "fresh", "nonfinite-counted"] {
        let bytes = std::fs::read(seed("checkpoint", &format!("{name}.ckpt"))).unwrap();
        let fingerprint = u64::from_le_bytes(bytes[8..16].try_into().unwrap());
        if let Err(e) = progress_from_bytes(&bytes, path, fingerprint, (4, 3)) {
            panic!("the seed {name}: {e}");
        }
    }
    let mut nan = floats.clone();
    nan[50] = f32::NAN;
    for (words, floats, needle) in [
        (
            [7, 2, 3, 0, 4, 3, 0, 12],
            &floats[..36],
            "0 sample and 12 splat",
        ),
        (
            [7, 2, 3, 0, 4, 3, 12, 0],
            &floats[..48],
            "12 sample and 0 splat",
        ),
        (
            [7, 2, 3, 0, 4, 3, 1 << 62, 12],
            &floats[..],
            "4611686018427387904 sample",
        ),
        (
            [7, 2, 3, 0, 4, 3, 12, 12],
            &nan[..],
            "accumulator 50 is NaN",
        ),
        (
            [7, 9, 3, 0, 4, 3, 12, 12],
            &floats[..],
            "impossible counts: 9 passes",
        ),
        (
            [7, 2, u64::MAX, 0, 4, 3, 12, 12],
            &floats[..],
            "impossible counts",
        ),
        (
            [7, 2, 3, u64::MAX, 4, 3, 12, 12],
            &floats[..],
            "impossible counts",
        ),
        (
            [7, 2, 3, 0, 4, 3, 12, 12],
            &floats[1..],
            "truncated or padded",
        ),
    ] {
        let bytes = checkpoint_bytes(words, floats);
        let err = progress_from_bytes(&bytes, path, 7, (4, 3))
            .err()
            .unwrap_or_else(|| panic!("{words:?} was accepted"));
        assert_clean_err(&err, "checkpoint x.ckpt: ");
        assert_clean_err(&err, needle);
    }
    // More words of the integrator's than any keeps.
    let mut many = b"mcmcPX02".to_vec();
    for w in ok.into_iter().chain([257]) {
        many.extend_from_slice(&w.to_le_bytes());
    }
    many.extend(std::iter::repeat_n(0u8, 8 * 257));
    for f in &floats {
        many.extend_from_slice(&f.to_le_bytes());
    }
    let checksum = fnv1a(&many);
    many.extend_from_slice(&checksum.to_le_bytes());
    let err = progress_from_bytes(&many, path, 7, (4, 3)).unwrap_err();
    assert_clean_err(&err, "holds 257 words of the integrator's");
    // A file longer than any checkpoint of the image (88 bytes of frame,
    // 256 words of the integrator's, 28 bytes a pixel) is refused unread.
    let dir = std::env::temp_dir().join(format!("mcmc-fuzz-ckpt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("long.ckpt");
    let good = checkpoint_bytes(ok, &floats);
    let mut long = good.clone();
    long.resize(88 + 8 * 256 + 28 * 12 + 1, 0);
    std::fs::write(&file, &long).unwrap();
    let err = load(&file, 7, (4, 3)).unwrap_err();
    assert_clean_err(
        &err,
        "2473 bytes, more than the 2472 a checkpoint of a 4×3 image can have",
    );
    std::fs::write(&file, &good).unwrap();
    assert!(load(&file, 7, (4, 3)).unwrap().is_some());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The `texture` target's finding (`tests/data/fuzz/texture-crash-*.exr`,
/// `scenes/textures/sky.exr` with its data window's `xMax` mutated to
/// −83886017 behind the 64×32 display window): the `image` crate sized the
/// image by its display window, passed its 512 MiB limit, and the `exr`
/// crate then allocated 32 GB for one PIZ block and aborted. EXR textures'
/// headers are now checked as `compare`'s EXR reader checks them.
#[test]
fn texture_exr_whose_data_window_exceeds_the_file_is_refused() {
    use mcmc_render::texture::linear_from_bytes;
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz");
    let bytes = std::fs::read(dir.join("texture-crash-24add2.exr")).unwrap();
    for format in [None, Some(image::ImageFormat::OpenExr)] {
        let b = bytes.clone();
        let err = within(20, "texture exr", move || {
            linear_from_bytes(&b, format, false).map(|_| ())
        })
        .expect_err("the mutated EXR was accepted");
        assert_clean_err(&err, "more than a file of 7627 bytes can hold");
    }
}

/// The `checkpoint` target's scene (the Cornell box on a 4×3 film) and
/// its Markov-chain reader: a file's progress, with the fingerprint taken
/// from the file (the word after the magic) as the target takes it.
#[allow(clippy::type_complexity)]
fn checkpoint_target_box() -> (
    mcmc_render::scene::Scene,
    impl Fn(&Path) -> Result<mcmc_render::markov::checkpoint::ChainProgress, String>,
) {
    use mcmc_render::film::Filter;
    use mcmc_render::markov::checkpoint::progress_from_bytes;
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box.xml"),
    )
    .unwrap()
    .replace("name=\"width\" value=\"256\"", "name=\"width\" value=\"4\"")
    .replace(
        "name=\"height\" value=\"256\"",
        "name=\"height\" value=\"3\"",
    );
    let scene =
        mcmc_render::scene::Scene::load_str(&text, Path::new("cornell-box.xml"), Path::new("."))
            .unwrap();
    let size = (scene.film.width, scene.film.height);
    let filter = std::sync::Arc::new(Filter::new(scene.film.filter, size.0, size.1));
    let read = move |path: &Path| {
        let bytes = std::fs::read(path).unwrap();
        let fingerprint = u64::from_le_bytes(bytes[8..16].try_into().unwrap());
        progress_from_bytes(&bytes, path, fingerprint, size, &filter)
    };
    (scene, read)
}

/// Session 18's `checkpoint` findings (2 files in 600 s): chains whose
/// saved current sample the reader took, but which panicked once the
/// resumed `pssmlt` ran on (`attempt to multiply with overflow` indexing
/// the sample-count image at a position far outside it). Each file must
/// now be refused by the reader with one line, or resume and finish as
/// the target runs it (2 chains, 100 mutations per pixel); the control,
/// the target's seed, resumes and finishes too.
#[test]
fn forged_markov_checkpoints_resume_or_are_refused() {
    use mcmc_render::checkpoint::Checkpoint;
    use mcmc_render::integrators::{RunSettings, registry};
    use mcmc_render::observer::NoObserver;
    use std::sync::atomic::AtomicBool;
    let (scene, read) = checkpoint_target_box();
    let dir = tempfile::tempdir().unwrap();
    let resume = |path: &Path| -> Result<(), String> {
        let progress = read(path)?;
        let sets = [
            ("bootstrap", "1000"),
            ("chains", "2"),
            ("mutations_per_pixel", "100"),
        ]
        .map(|(k, v)| (k.to_string(), v.to_string()));
        let run = RunSettings {
            checkpoint: Some(Checkpoint {
                path: dir.path().join("run.ckpt"),
                fingerprint: u64::from_le_bytes(
                    std::fs::read(path).unwrap()[8..16].try_into().unwrap(),
                ),
                resume: None,
                chains: Some(std::sync::Arc::new(progress)),
            }),
            ..RunSettings::default()
        };
        let integrator = registry::configure(None, Some("pssmlt"), &sets).unwrap();
        integrator
            .render(&scene, &run, &AtomicBool::new(false), &NoObserver)
            .map(|_| ())
            .map_err(|e| e.to_string())
    };
    resume(&seed("checkpoint", "pssmlt-complete-mpp50.ckpt")).expect("the seed resumes");
    let found = fuzz_findings("resumed-checkpoint-");
    assert_eq!(found.len(), 2, "the findings: {found:?}");
    for (path, _) in &found {
        if let Err(err) = resume(path) {
            // Refused by the reader (the error names the file) or by the
            // resume (it names the run's checkpoint).
            assert_clean_err(&err, "checkpoint");
        }
    }
}

/// The committed findings `tests/data/fuzz/PREFIX*.ckpt`, with their names.
fn fuzz_findings(prefix: &str) -> Vec<(PathBuf, String)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz");
    let mut found: Vec<(PathBuf, String)> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .map(|path| {
            let name = path.file_name().unwrap().to_string_lossy().to_string();
            (path, name)
        })
        .filter(|(_, name)| name.starts_with(prefix) && name.ends_with(".ckpt"))
        .collect();
    found.sort();
    found
}

/// The `checkpoint` target's findings in the Markov-chain driver's
/// reader (session 17: 361 of 177 k inputs in 600 s): its task records
/// are the parcels the ranks of a distributed run exchange, which the
/// reader trusted. Forged files (`tests/data/fuzz/checkpoint-*.ckpt`, one
/// per kind found, rewritten to format 3 with their checksum recomputed)
/// made it allocate what a length claimed (petabytes, or a capacity
/// overflow), run off the end of a task's sums, overflow counters near
/// 2^64 when the resumed chains counted on, or index a film or the
/// sample-count image outside itself. Each is now one line from the
/// reader; the control, the target's seed (a complete `pssmlt` run of the
/// same 4×3 box), still loads.
#[test]
fn forged_markov_checkpoints_are_refused_by_the_reader() {
    let (_, read) = checkpoint_target_box();
    let control = read(&seed("checkpoint", "pssmlt-complete-mpp50.ckpt")).expect("the seed loads");
    assert_eq!(control.mutations(), 600);
    let found = fuzz_findings("checkpoint-");
    assert_eq!(found.len(), 11, "the findings: {found:?}");
    for (path, name) in &found {
        let err = read(path).map(|p| p.tasks.len()).expect_err(name);
        assert_clean_err(&err, name);
    }
}
