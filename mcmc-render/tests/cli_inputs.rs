//! Input files that are not files: a mesh, scene, image, PSS dump or
//! convergence CSV path naming a directory, a FIFO or a device is refused
//! with one line before it is opened (a FIFO would block the open, a
//! device never end), never a hang.
//! And malformed PLY files are one line naming the file, not the reader's
//! multi-line dump.

mod cli_support;

use cli_support::{BIN, assert_clean_failure, floor_scene, run, run_ok, scratch, write};
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// Runs the binary; fails the test (killing the child) if it has not
/// finished within 30 s, the symptom these tests guard against.
fn run_bounded(args: &[&str], cwd: &Path) -> Output {
    let mut child = Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary runs");
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(30) {
            child.kill().unwrap();
            panic!("{args:?} hangs");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

fn mkfifo(path: &Path) {
    let status = Command::new("mkfifo").arg(path).status().unwrap();
    assert!(status.success(), "mkfifo failed");
}

/// The floor scene plus a mesh shape of `kind` reading `file`.
fn mesh_scene(kind: &str, file: &str) -> String {
    floor_scene(8, 6).replace(
        "</scene>",
        &format!(
            "<shape type=\"{kind}\"><string name=\"filename\" value=\"{file}\"/></shape>\n</scene>"
        ),
    )
}

#[test]
fn mesh_paths_that_are_not_files_are_refused_before_reading() {
    let dir = scratch("inputs-mesh");
    std::fs::create_dir(dir.join("folder.obj")).unwrap();
    mkfifo(&dir.join("pipe.obj"));
    let cases = [
        ("folder.obj", "a directory"),
        ("pipe.obj", "a FIFO"),
        ("/dev/zero", "a device"),
    ];
    for kind in ["obj", "ply", "serialized"] {
        for (file, what) in cases {
            write(&dir, "s.xml", &mesh_scene(kind, file));
            let out = run_bounded(&["info", "s.xml"], &dir);
            assert_clean_failure(&out, &["s.xml:", file, what, "not a regular file"]);
        }
    }
    // Control: a regular mesh file loads.
    write(&dir, "tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    write(&dir, "s.xml", &mesh_scene("obj", "tri.obj"));
    assert!(run_ok(&["info", "s.xml"], &dir).contains("1 obj"));
}

#[test]
fn scene_and_image_paths_that_are_not_files_are_refused() {
    let dir = scratch("inputs-other");
    mkfifo(&dir.join("scene.xml"));
    mkfifo(&dir.join("image.exr"));
    std::fs::create_dir(dir.join("inc.xml")).unwrap();
    let out = run_bounded(&["info", "scene.xml"], &dir);
    assert_clean_failure(&out, &["scene.xml is a FIFO"]);
    // An <include> of a directory.
    write(
        &dir,
        "s.xml",
        &floor_scene(8, 6).replace("</scene>", "<include filename=\"inc.xml\"/>\n</scene>"),
    );
    let out = run_bounded(&["info", "s.xml"], &dir);
    assert_clean_failure(&out, &["inc.xml is a directory"]);
    let out = run_bounded(&["compare", "image.exr", "image.exr"], &dir);
    assert_clean_failure(&out, &["image.exr is a FIFO"]);
    // The replay dump and the convergence CSV.
    mkfifo(&dir.join("dump.pss"));
    mkfifo(&dir.join("c.csv"));
    write(&dir, "f.xml", &floor_scene(8, 6));
    let out = run_bounded(&["render", "f.xml", "--replay", "dump.pss"], &dir);
    assert_clean_failure(&out, &["dump.pss is a FIFO"]);
    let out = run_bounded(&["convergence", "--replot", "c.csv"], &dir);
    assert_clean_failure(&out, &["c.csv is a FIFO"]);
}

#[test]
fn malformed_ply_files_are_one_line_naming_the_file() {
    let dir = scratch("inputs-ply");
    let header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    let binary = header.replace("ascii", "binary_little_endian");
    let cases: [(String, &str); 5] = [
        (
            format!("{header}0 0 0\n1 0 abc\n0 1 0\n3 0 1 2\n"),
            "Line 11",
        ),
        (format!("{header}0 0 0\n1 0 0\n"), "Unexpected end of file"),
        (format!("{binary}\u{0}\u{0}"), "failed to fill whole buffer"),
        (
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty floot x\nend_header\n".into(),
            "at 'property floot x'",
        ),
        ("plx\n".into(), "Expected magic number"),
    ];
    write(&dir, "s.xml", &mesh_scene("ply", "m.ply"));
    for (text, needle) in &cases {
        write(&dir, "m.ply", text);
        let out = run(&["info", "s.xml"], &dir);
        assert_clean_failure(&out, &["s.xml:", "m.ply", "PLY parse error", needle]);
    }
    // Control: the well-formed file loads.
    write(
        &dir,
        "m.ply",
        &format!("{header}0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"),
    );
    assert!(run_ok(&["info", "s.xml"], &dir).contains("1 ply"));
}

/// Texture images (`bitmap`, and the `envmap` emitter that reads the same
/// formats) and `--checkpoint` files: a FIFO or a device is refused before
/// it is opened. Before the bitmap check a FIFO named `tex.png` blocked
/// the scene load forever; `--checkpoint /dev/zero` read until memory ran
/// out.
#[cfg(unix)]
#[test]
fn texture_and_checkpoint_paths_that_are_not_files_are_refused() {
    let dir = scratch("inputs-texture-checkpoint");
    mkfifo(&dir.join("tex.png"));
    mkfifo(&dir.join("sky.exr"));
    let bitmap = floor_scene(8, 6).replace(
        "<shape type=\"rectangle\"><bsdf type=\"diffuse\"/></shape>",
        "<shape type=\"rectangle\"><bsdf type=\"diffuse\"><texture type=\"bitmap\" \
         name=\"reflectance\"><string name=\"filename\" value=\"tex.png\"/></texture>\
         </bsdf></shape>",
    );
    write(&dir, "bitmap.xml", &bitmap);
    let out = run_bounded(&["info", "bitmap.xml"], &dir);
    assert_clean_failure(&out, &["tex.png is a FIFO"]);
    let envmap = floor_scene(8, 6).replace(
        "</scene>",
        "<emitter type=\"envmap\"><string name=\"filename\" value=\"sky.exr\"/></emitter>\n</scene>",
    );
    write(&dir, "envmap.xml", &envmap);
    let out = run_bounded(&["info", "envmap.xml"], &dir);
    assert_clean_failure(&out, &["sky.exr is a FIFO"]);
    write(&dir, "s.xml", &floor_scene(8, 6));
    mkfifo(&dir.join("run.ckpt"));
    // Both checkpoint readers: the per-pixel driver's (`pt`) and the
    // Markov-chain driver's (`pssmlt`; it read `/dev/zero` until memory
    // ran out and blocked on the FIFO until session 17).
    for integrator in ["pt", "pssmlt"] {
        for (ckpt, what) in [("run.ckpt", "a FIFO"), ("/dev/zero", "a device")] {
            let args = [
                "render",
                "s.xml",
                "--spp",
                "1",
                "--integrator",
                integrator,
                "--checkpoint",
                ckpt,
            ];
            let out = run_bounded(&[&args[..], &["--quiet"]].concat(), &dir);
            assert_clean_failure(&out, &[ckpt, what]);
            assert!(!dir.join("render.exr").exists());
        }
    }
}
