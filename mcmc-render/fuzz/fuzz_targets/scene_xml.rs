//! Scene files: the XML reader with `<include>` and `<default>`, the
//! loader and the scene build, as `render SCENE.xml` runs them.
//!
//! The input is the main file, optionally followed by a NUL byte and the
//! text of `inc.xml` (XML cannot hold NUL, so the split loses nothing).
//! Both live in a temporary directory that also holds the repository's
//! meshes and textures under the names its scenes use, so includes,
//! meshes and bitmaps resolve.
#![no_main]
use libfuzzer_sys::fuzz_target;
use mcmc_render::scene::Scene;
use std::path::Path;
use std::sync::OnceLock;

/// Files a fuzzed scene can name, at the paths the repository's scenes use.
const FILES: &[(&str, &[u8])] = &[
    (
        "meshes/sphere.obj",
        include_bytes!("../../../scenes/meshes/sphere.obj"),
    ),
    (
        "meshes/ring.obj",
        include_bytes!("../../../scenes/meshes/ring.obj"),
    ),
    (
        "meshes/smallvcm-green.obj",
        include_bytes!("../../../scenes/meshes/smallvcm-green.obj"),
    ),
    (
        "meshes/smallvcm-light.obj",
        include_bytes!("../../../scenes/meshes/smallvcm-light.obj"),
    ),
    (
        "meshes/smallvcm-red.obj",
        include_bytes!("../../../scenes/meshes/smallvcm-red.obj"),
    ),
    (
        "meshes/smallvcm-white.obj",
        include_bytes!("../../../scenes/meshes/smallvcm-white.obj"),
    ),
    (
        "textures/grid.png",
        include_bytes!("../../../scenes/textures/grid.png"),
    ),
    (
        "textures/bumps.png",
        include_bytes!("../../../scenes/textures/bumps.png"),
    ),
    (
        "textures/leaf.png",
        include_bytes!("../../../scenes/textures/leaf.png"),
    ),
    (
        "textures/normals.png",
        include_bytes!("../../../scenes/textures/normals.png"),
    ),
    (
        "textures/sky.exr",
        include_bytes!("../../../scenes/textures/sky.exr"),
    ),
    (
        "tetrahedron.obj",
        include_bytes!("../../tests/data/serialized/tetrahedron.obj"),
    ),
    (
        "meshes-v4.serialized",
        include_bytes!("../../tests/data/serialized/meshes-v4.serialized"),
    ),
];

fn dir() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = tempfile::tempdir().expect("a temporary directory");
        for (name, bytes) in FILES {
            let path = d.path().join(name);
            std::fs::create_dir_all(path.parent().expect("a parent")).expect("mkdir");
            std::fs::write(path, bytes).expect("write");
        }
        d
    })
    .path()
}

fuzz_target!(|data: &[u8]| {
    let (main, included) = match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, &[][..]),
    };
    let Ok(main) = std::str::from_utf8(main) else {
        return;
    };
    let d = dir();
    std::fs::write(d.join("inc.xml"), included).expect("write inc.xml");
    let _ = Scene::load_str(main, &d.join("main.xml"), d);
});
