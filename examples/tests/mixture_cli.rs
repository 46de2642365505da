//! The `mixture` example as a process: exit codes and output streams.
//!
//! `cargo test` builds the package's examples next to its test binaries
//! (`target/<profile>/examples/`), so the binary is found from this test's
//! own path. The sampling logic itself is tested in-process by
//! `tests/tests/mixture_example.rs`.

use std::path::PathBuf;
use std::process::{Command, Output};

fn example_binary() -> PathBuf {
    let exe = std::env::current_exe().expect("test binary path");
    // target/<profile>/deps/<test> → target/<profile>/examples/mixture
    let profile_dir = exe
        .parent()
        .and_then(|deps| deps.parent())
        .expect("target/<profile>");
    let bin = profile_dir
        .join("examples")
        .join(format!("mixture{}", std::env::consts::EXE_SUFFIX));
    assert!(
        bin.exists(),
        "{} not found: run through `cargo test`, which builds the examples",
        bin.display()
    );
    bin
}

fn run(args: &[&str]) -> Output {
    Command::new(example_binary())
        .args(args)
        .output()
        .expect("run the example")
}

fn target(name: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("mixture/targets")
        .join(name)
        .to_string_lossy()
        .into_owned()
}

#[test]
fn success_prints_one_json_line_and_exits_0() {
    let out = run(&[
        "--target",
        &target("correlated-2d.json"),
        "--evaluations",
        "4000",
        "--json",
    ]);
    assert_eq!(out.status.code(), Some(0));
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert_eq!(stdout.lines().count(), 1);
    assert!(stdout.starts_with('{') && stdout.contains("\"rhat\""));
    assert!(out.stderr.is_empty());
}

#[test]
fn usage_errors_print_one_line_and_exit_2() {
    let bimodal = target("bimodal-1d.json");
    let cases: [&[&str]; 4] = [
        &["--target", &bimodal, "--frobnicate"],
        &["--target", &bimodal, "--scale", "0"],
        &["--target", &bimodal, "--kernel", "kelemen"],
        &["--target", "/nonexistent/target.json"],
    ];
    for args in cases {
        let out = run(args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let stderr = String::from_utf8(out.stderr).unwrap();
        assert_eq!(stderr.lines().count(), 1, "{args:?}: {stderr}");
        assert!(stderr.starts_with("error: "), "{stderr}");
        assert!(out.stdout.is_empty());
    }
}
