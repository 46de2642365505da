//! Every subcommand with its standard output closed by the reader (as in
//! `mcmc-render compare A B | head -1`) exits quietly with status 0; a
//! standard output that cannot be written for another reason (a full
//! device) is one `error:` line and status 1. A closed standard error
//! changes nothing. Never a panic.

mod cli_support;

use cli_support::{floor_scene, run_ok, scratch, write};
use std::path::Path;
use std::process::{Command, Output, Stdio};

/// Runs the binary with a standard output whose reading end is closed
/// before the child starts, so that its first write meets a broken pipe
/// whatever the timing.
fn run_closed_stdout(args: &[&str], cwd: &Path) -> Output {
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    Command::new(cli_support::BIN)
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(writer)
        .output()
        .expect("the binary runs")
}

/// Asserts status 0 and nothing on stderr.
fn assert_quiet(out: &Output, what: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{what}: {stderr}");
    assert!(stderr.trim().is_empty(), "{what}: stderr: {stderr}");
}

/// A directory with `s.xml` (an 8×6 floor), `a.exr`, `b.exr` (renders of
/// it) and `c.csv` (a convergence study).
fn fixture(name: &str) -> std::path::PathBuf {
    let dir = scratch(name);
    write(&dir, "s.xml", &floor_scene(8, 6));
    for (out, seed) in [("a.exr", "1"), ("b.exr", "2")] {
        run_ok(
            &[
                "render",
                "s.xml",
                "--spp",
                "2",
                "--seed",
                seed,
                "--threads",
                "1",
                "--out",
                out,
                "--quiet",
            ],
            &dir,
        );
    }
    dir
}

const CONVERGENCE: &[&str] = &[
    "convergence",
    "s.xml",
    "--reference",
    "a.exr",
    "--integrators",
    "pt",
    "--time",
    "0.05",
    "--checkpoints",
    "2",
    "--threads",
    "1",
    "--out",
    "c.csv",
];

#[test]
fn every_subcommand_exits_quietly_on_a_closed_stdout() {
    let dir = fixture("stdout-closed");
    // A primary-sample vector for `--replay` (any coordinates in [0, 1)).
    write(
        &dir,
        "d.pss",
        "# sampler pt\n# max_depth 3\n0.5\n0.25\n0.75\n0.125\n0.625\n0.375\n",
    );
    let reports: &[&[&str]] = &[
        &["compare", "a.exr", "b.exr"],
        &["compare", "a.exr", "b.exr", "--json"],
        &["info", "s.xml"],
        &["integrators"],
        CONVERGENCE,
        &["convergence", "--replot", "c.csv"],
        &["render", "s.xml", "--replay", "d.pss"],
    ];
    for args in reports {
        // Control: with an open pipe each of these does write to stdout,
        // so the closed pipe below is met (a subcommand that printed
        // nothing would pass the closed-pipe check vacuously).
        let open = run_ok(args, &dir);
        assert!(!open.trim().is_empty(), "{args:?} printed nothing");
        assert_quiet(&run_closed_stdout(args, &dir), &format!("{args:?}"));
    }
    // `render` reports on stderr and writes files: a closed stdout does
    // not stop it.
    let _ = std::fs::remove_file(dir.join("r.exr"));
    let out = run_closed_stdout(
        &[
            "render",
            "s.xml",
            "--spp",
            "1",
            "--threads",
            "1",
            "--out",
            "r.exr",
            "--quiet",
        ],
        &dir,
    );
    assert_quiet(&out, "render");
    assert!(dir.join("r.exr").is_file(), "render wrote no image");
}

#[test]
fn a_full_stdout_is_one_error_line() {
    let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") else {
        return; // not Linux: no device that always reports ENOSPC
    };
    let dir = scratch("stdout-full");
    let out = Command::new(cli_support::BIN)
        .arg("integrators")
        .current_dir(&dir)
        .stdout(full)
        .output()
        .expect("the binary runs");
    cli_support::assert_clean_failure(&out, &["error: cannot write to standard output"]);
    assert_eq!(out.status.code(), Some(1));
}

#[test]
fn a_closed_stderr_is_no_panic() {
    let dir = scratch("stderr-closed");
    write(&dir, "s.xml", &floor_scene(8, 6));
    // The progress bar and summary of `render`, and an error line, go to
    // a stderr whose reader has gone: the status is what it would be.
    for (args, code) in [
        (
            &[
                "render",
                "s.xml",
                "--spp",
                "1",
                "--threads",
                "1",
                "--out",
                "r.exr",
            ][..],
            0,
        ),
        (&["info", "missing.xml"][..], 1),
    ] {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = Command::new(cli_support::BIN)
            .args(args)
            .current_dir(&dir)
            .stderr(writer)
            .output()
            .expect("the binary runs");
        assert_eq!(out.status.code(), Some(code), "{args:?}");
    }
}
