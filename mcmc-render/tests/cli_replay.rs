//! NaN/inf paths end to end: a scene whose contributions overflow f32 is
//! rendered with PSSMLT (over PT and over BDPT) and MMLT; the run finishes
//! with a finite image, counts the non-finite contributions in the JSON and
//! dumps the primary-sample vector of the first one, and `--replay DUMP`
//! re-traces it with the run's sampler and reports the non-finite value.

mod cli_support;

use cli_support::{assert_clean_failure, exr, json, run, run_ok, scratch, write};
use std::path::Path;

/// A diffuse floor under a large emitter 0.5 above it, seen from the side.
/// With radiance 3e38 (near f32::MAX), next-event estimation near the
/// emitter's edge multiplies it by G·A/π > 1 (cos·cos·area/d² with d
/// small) and overflows to inf; with radiance 1 every path is finite.
fn overflow_scene(radiance: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="3"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="60"/>
        <transform name="to_world"><lookat origin="0,-3,0.25" target="0,0,0.1" up="0,0,1"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="12"/></film>
    </sensor>
    <shape type="rectangle"><bsdf type="diffuse"/></shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="180"/><translate z="0.5"/></transform>
        <emitter type="area"><rgb name="radiance" value="{radiance}"/></emitter>
    </shape>
</scene>"#
    )
}

/// Runs `render` with the MLT flags `mlt` and the output `out`.
fn render_mlt(dir: &Path, scene: &str, mlt: &[&str], out: &str) {
    let mut args = vec![
        "render",
        scene,
        "--bootstrap",
        "2000",
        "--seed",
        "1",
        "--threads",
        "1",
        "--out",
        out,
        "--quiet",
    ];
    args.extend_from_slice(mlt);
    run_ok(&args, dir);
}

/// Renders, checks the JSON, the finite image and the dump, replays it and
/// returns the replay's stdout.
fn dump_and_replay(dir: &Path, mlt: &[&str], name: &str, sampler: &str) -> String {
    let out = format!("{name}.exr");
    render_mlt(dir, "inf.xml", mlt, &out);
    let j = json(&dir.join(format!("{name}.json")));
    let nonfinite = j["nonfinite_contributions"].as_u64().unwrap();
    assert!(nonfinite > 0, "{name}: no non-finite contribution: {j}");
    // Non-finite proposals are rejected: far fewer than all mutations.
    assert!(nonfinite < j["mutations"].as_u64().unwrap());
    let (_, _, img) = exr(&dir.join(&out));
    assert!(
        img.iter().all(|p| p.is_finite()),
        "{name}: non-finite pixels in the image"
    );
    let dump = format!("{name}.nonfinite.pss");
    assert_eq!(j["nonfinite_dump"].as_str(), Some(dump.as_str()));
    let text = std::fs::read_to_string(dir.join(&dump)).unwrap();
    assert!(text.contains(&format!("# sampler {sampler}\n")), "{text}");

    let stdout = run_ok(&["render", "inf.xml", "--replay", &dump], dir);
    assert!(
        stdout.contains(&format!("sampler             {sampler}")),
        "{stdout}"
    );
    stdout
}

/// A short PSSMLT run over path tracing.
const SMALL_PSSMLT: &[&str] = &[
    "--integrator",
    "pssmlt",
    "--chains",
    "16",
    "--mutations-per-pixel",
    "20",
];

#[test]
fn pssmlt_over_pt_dumps_and_replays_a_nonfinite_path() {
    let dir = scratch("replay-pt");
    write(&dir, "inf.xml", &overflow_scene("3e38"));
    let stdout = dump_and_replay(&dir, SMALL_PSSMLT, "p", "pt");
    assert!(stdout.contains("ln I                NaN"), "{stdout}");
    assert!(
        stdout.contains("contribution        non-finite"),
        "{stdout}"
    );
    assert!(stdout.contains("inf"), "{stdout}");

    // The same scene at radiance 1: no NaN/inf, hence no dump.
    write(&dir, "one.xml", &overflow_scene("1"));
    render_mlt(&dir, "one.xml", SMALL_PSSMLT, "one.exr");
    let j = json(&dir.join("one.json"));
    assert_eq!(j["nonfinite_contributions"], 0);
    assert!(j["nonfinite_dump"].is_null());
    assert!(!dir.join("one.nonfinite.pss").exists());
}

#[test]
fn pssmlt_over_bdpt_dump_replays_with_bdpt() {
    let dir = scratch("replay-bdpt");
    write(&dir, "inf.xml", &overflow_scene("3e38"));
    let stdout = dump_and_replay(
        &dir,
        &[
            "--integrator",
            "pssmlt",
            "--mlt-base",
            "bdpt",
            "--chains",
            "16",
            "--mutations-per-pixel",
            "20",
        ],
        "b",
        "bdpt",
    );
    assert!(
        stdout.contains("contribution        non-finite"),
        "{stdout}"
    );
}

#[test]
fn mmlt_dump_replays_at_every_depth_and_one_is_nonfinite() {
    let dir = scratch("replay-mmlt");
    write(&dir, "inf.xml", &overflow_scene("3e38"));
    let stdout = dump_and_replay(
        &dir,
        // 64 chains: resampled in proportion to each depth's b_d, a few
        // land on depth 2, where next-event estimation overflows (with 16
        // all start on depth 1, the emitter seen directly, which is finite).
        &[
            "--integrator",
            "mmlt",
            "--chains",
            "64",
            "--mutations-per-pixel",
            "200",
        ],
        "m",
        "mmlt",
    );
    // max_depth 3: the dump is traced at depths 1, 2, 3.
    assert_eq!(stdout.matches("mmlt depth").count(), 3, "{stdout}");
    assert!(
        stdout.contains("contribution        non-finite"),
        "{stdout}"
    );
}

#[test]
fn malformed_dumps_are_refused_with_one_line() {
    let dir = scratch("replay-bad");
    write(&dir, "inf.xml", &overflow_scene("1"));
    let cases = [
        (
            "text.pss",
            "# sampler pt\n0.25\nzero point five\n",
            "text.pss:3",
        ),
        ("range.pss", "0.25\n1.5\n", "outside [0, 1)"),
        ("sampler.pss", "# sampler warp\n0.5\n", "unknown sampler"),
        ("empty.pss", "# sampler pt\n", "no coordinates"),
    ];
    for (file, text, needle) in cases {
        write(&dir, file, text);
        let out = run(&["render", "inf.xml", "--replay", file], &dir);
        assert_clean_failure(&out, &["error:", file, needle]);
    }
    let out = run(&["render", "inf.xml", "--replay", "missing.pss"], &dir);
    assert_clean_failure(&out, &["error:", "missing.pss"]);
}
