//! `mcmc-render render --integrator bdpt` writes the image and its JSON
//! statistics, with the throughput.

use std::process::Command;

#[test]
fn render_with_bdpt_writes_image_and_statistics() {
    let dir = std::env::temp_dir().join(format!("mcmc-render-bdpt-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let out = dir.join("bdpt.exr");
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box.xml");
    let status = Command::new(env!("CARGO_BIN_EXE_mcmc-render"))
        .args(["render", scene.to_str().expect("utf-8 path")])
        .args([
            "--integrator",
            "bdpt",
            "--spp",
            "2",
            "--quiet",
            "--threads",
            "2",
        ])
        .args(["-D", "width=16", "-D", "height=16"])
        .arg("--out")
        .arg(&out)
        .status()
        .expect("runs");
    assert!(status.success());
    assert!(out.exists() && out.with_extension("png").exists());
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.with_extension("json")).expect("json written"),
    )
    .expect("valid json");
    assert_eq!(json["integrator"], "bdpt");
    assert_eq!(json["spp"], 2);
    assert_eq!(json["samples"], 2 * 16 * 16);
    assert!(json["samples_per_second"].as_f64().expect("number") > 0.0);
    assert_eq!(json["nonfinite_samples"], 0);
    let _ = std::fs::remove_dir_all(&dir);
}
