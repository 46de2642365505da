//! Helpers shared by the `cli_*` tests: scratch directories, running the
//! binary, clean-failure checks, reading the JSON sidecar and the EXR.
// Each test binary uses a different subset of these helpers.
#![allow(dead_code)]

use mcmc_render::color::Rgb;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The `mcmc-render` binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_mcmc-render");

/// A fresh directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mcmc-render-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs the binary in `cwd` to completion.
pub fn run(args: &[&str], cwd: &Path) -> Output {
    Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("the binary runs")
}

/// Asserts success and returns stdout.
pub fn run_ok(args: &[&str], cwd: &Path) -> String {
    let out = run(args, cwd);
    assert!(
        out.status.success(),
        "{args:?} failed ({}): {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Asserts a clean failure: non-zero status, no panic, exactly one stderr
/// line, containing every one of `needles`.
pub fn assert_clean_failure(out: &Output, needles: &[&str]) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "expected failure, stderr: {stderr}");
    assert_ne!(out.status.code(), Some(101), "panicked: {stderr}");
    assert!(!stderr.contains("panicked"), "panicked: {stderr}");
    let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "expected one line, got: {stderr}");
    for n in needles {
        assert!(lines[0].contains(n), "'{n}' missing from: {}", lines[0]);
    }
}

/// Writes `text` to `dir/name`.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Reads a JSON sidecar.
pub fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap()
}

/// Reads an EXR: (width, height, pixels).
pub fn exr(path: &Path) -> (u32, u32, Vec<Rgb>) {
    mcmc_render::image_io::read_exr(path).unwrap()
}

/// Mean luminance of an image.
pub fn mean_luminance(pixels: &[Rgb]) -> f64 {
    pixels.iter().map(|p| p.luminance() as f64).sum::<f64>() / pixels.len() as f64
}

/// A small scene: a diffuse floor lit by a rectangle facing it, box
/// filter (each camera sample and splat lands in exactly one pixel, so
/// image means of pixel-driven and splatting integrators are comparable).
pub fn floor_scene(width: u32, height: u32) -> String {
    format!(
        r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="4"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="{width}"/><integer name="height" value="{height}"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <shape type="rectangle"><bsdf type="diffuse"/></shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.3"/><rotate x="1" angle="180"/><translate z="2"/></transform>
        <emitter type="area"><rgb name="radiance" value="1"/></emitter>
    </shape>
</scene>"#
    )
}
