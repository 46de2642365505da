//! Limits on what a user's word can make the CLI do (issue 23): numbers
//! that would overflow, thread counts, memory estimates before any
//! allocation, and output names that would let one output overwrite
//! another. Each gives one line naming the problem, never a panic.

mod cli_support;

use cli_support::{BIN, assert_clean_failure, floor_scene, json, run, scratch, write};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn setup(name: &str) -> std::path::PathBuf {
    let dir = scratch(name);
    write(&dir, "s.xml", &floor_scene(8, 6));
    dir
}

#[test]
fn a_time_budget_too_large_for_a_duration_is_refused() {
    let dir = setup("limits-time");
    let out = run(&["render", "s.xml", "--time", "1e300", "--quiet"], &dir);
    assert_clean_failure(&out, &["--time", "1e300", "too large"]);
}

/// A `--time` that fits a `Duration` but not the clock (`start + budget`
/// past an `Instant`'s range) panicked ("overflow when adding duration to
/// instant") in every integrator that computed its deadline: each such
/// driver (per-pixel passes, VCM, the Markov-chain driver, guided and
/// mcmc-pg's schedules) renders with it now, as with no budget.
#[test]
fn a_time_budget_past_the_clocks_range_renders() {
    let dir = setup("limits-time-far");
    // With a time budget the chains run until it is spent unless
    // mutations_per_pixel is set.
    let chains = ["--set", "chains=4", "--set", "mutations_per_pixel=1"];
    for args in [
        &["pt", "--spp", "1"][..],
        &["vcm", "--spp", "1"],
        &[&["pssmlt", "--set", "bootstrap=100"][..], &chains].concat(),
        &["guided", "--spp", "1"],
        &[&["mcmc-pg", "--set", "bootstrap=10000"][..], &chains].concat(),
    ] {
        let head = [
            "render",
            "s.xml",
            "--time",
            "1e19",
            "--quiet",
            "--integrator",
        ];
        let out = run(&[&head[..], args].concat(), &dir);
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

/// `convergence` converted `--time` before checking it: a negative value
/// panicked. Checked with the other flags now, before any file is read
/// (`r.exr` does not exist).
#[test]
fn a_convergence_time_budget_out_of_range_is_refused() {
    let dir = setup("limits-convergence-time");
    for (time, needles) in [
        (
            "-1",
            &["--time must be a positive number of seconds, got -1"][..],
        ),
        ("1e300", &["--time 1e300 is too large"][..]),
        ("NaN", &["--time must be a positive", "NaN"][..]),
    ] {
        let out = run(
            &[
                "convergence",
                "s.xml",
                "--reference",
                "r.exr",
                "--time",
                time,
            ],
            &dir,
        );
        assert_clean_failure(&out, needles);
    }
}

#[test]
fn a_sample_count_too_large_for_u32_is_refused() {
    let dir = setup("limits-spp");
    let out = run(&["render", "s.xml", "--spp", "5000000000", "--quiet"], &dir);
    assert_clean_failure(&out, &["--spp 5000000000", "too large"]);
}

#[test]
fn thousands_of_threads_are_refused() {
    let dir = setup("limits-threads");
    let out = run(&["render", "s.xml", "--threads", "100000", "--quiet"], &dir);
    assert_clean_failure(&out, &["--threads 100000", "per core"]);
    let out = run(
        &[
            "convergence",
            "s.xml",
            "--reference",
            "r.exr",
            "--threads",
            "100000",
        ],
        &dir,
    );
    assert_clean_failure(&out, &["--threads 100000"]);
}

#[test]
fn an_output_named_like_its_sidecars_is_refused() {
    // The JSON statistics (`.json`) and the PNG preview (`.png`) are named
    // by replacing the extension: `--out x.json` would be overwritten.
    let dir = setup("limits-out");
    for name in ["x.json", "x.png", "x"] {
        let out = run(&["render", "s.xml", "--out", name, "--quiet"], &dir);
        assert_clean_failure(&out, &[name, "must end in .exr"]);
        assert!(!dir.join(name).exists(), "{name} was written");
    }
    let out = run(
        &["render", "s.xml", "--out", "X.EXR", "--spp", "1", "--quiet"],
        &dir,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = run(
        &[
            "convergence",
            "s.xml",
            "--reference",
            "X.EXR",
            "--out",
            "c.png",
        ],
        &dir,
    );
    assert_clean_failure(&out, &["c.png", "must end in .csv"]);
}

/// `--checkpoint` naming one of the render's outputs (the image, its
/// preview, sidecar, layers or NaN dump) is refused: the outputs written
/// at the end would overwrite the checkpoint, or the checkpoint an earlier
/// image. Control: a name of its own renders and leaves a checkpoint.
#[test]
fn a_checkpoint_named_like_an_output_is_refused() {
    let dir = setup("limits-checkpoint");
    for name in [
        "x.exr",
        "x.png",
        "x.json",
        "./x.nonfinite.pss",
        "x.albedo.exr",
    ] {
        let args = ["render", "s.xml", "--out", "x.exr", "--checkpoint", name];
        let out = run(&[&args[..], &["--spp", "1", "--quiet"]].concat(), &dir);
        assert_clean_failure(&out, &[name, "is the path of an output", "x.ckpt"]);
        assert!(!dir.join("x.exr").exists(), "{name}: rendered");
    }
    let args = [
        "render",
        "s.xml",
        "--out",
        "x.exr",
        "--checkpoint",
        "x.ckpt",
    ];
    let out = run(&[&args[..], &["--spp", "1", "--quiet"]].concat(), &dir);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.join("x.exr").exists() && dir.join("x.ckpt").exists());
}

#[test]
fn memory_beyond_the_machine_is_refused_before_allocating() {
    let dir = setup("limits-memory");
    let out = run(
        &[
            "render",
            "s.xml",
            "--integrator",
            "pssmlt",
            "--set",
            "bootstrap=100000000000",
            "--quiet",
        ],
        &dir,
    );
    assert_clean_failure(
        &out,
        &["100000000000 bootstrap candidates", "needs", "available"],
    );
    let out = run(
        &[
            "render",
            "s.xml",
            "--integrator",
            "mmlt",
            "--set",
            "max_depth=5",
            "--set",
            "chains=10000000000",
            "--quiet",
        ],
        &dir,
    );
    assert_clean_failure(&out, &["10000000000 chains", "needs", "available"]);
    // RELT's population annealing: 10^15 particles aborted on a 16 PB
    // allocation ("memory allocation of 16000000000000000 bytes failed").
    let out = run(
        &[
            "render",
            "s.xml",
            "--integrator",
            "relt",
            "--set",
            "annealing_particles=1000000000000000",
            "--quiet",
        ],
        &dir,
    );
    assert_clean_failure(
        &out,
        &["1000000000000000 annealing particles", "needs", "available"],
    );
    // mept's BDPT start-up (10^15 draws: a 32 PB allocation), smcmc's
    // global start-up (10^15 states: 8 PB) and mcmc-vcm's units and
    // candidates aborted the same way. (erpt's luminance estimate, 8 PB,
    // keeps nothing per walk now: see
    // `erpt_work_sized_by_a_setting_stops_at_the_time_budget`.)
    for (integrator, setting, extra, needle) in [
        (
            "mept",
            "bootstrap",
            "max_depth=5",
            "a BDPT start-up of 1000000000000000 draws",
        ),
        (
            "smcmc",
            "init_bootstrap",
            "init=global",
            "1000000000000000 bootstrap states",
        ),
        ("mcmc-vcm", "units", "max_depth=5", "1000000000000000 units"),
        (
            "mcmc-vcm",
            "candidates",
            "max_depth=5",
            "1000000000000000 candidates",
        ),
    ] {
        let set = format!("{setting}=1000000000000000");
        let args = ["render", "s.xml", "--integrator", integrator, "--set", &set];
        let out = run(&[&args[..], &["--set", extra, "--quiet"]].concat(), &dir);
        assert_clean_failure(&out, &[needle, "needs", "available"]);
    }
    write(&dir, "huge.xml", &floor_scene(65536, 65536));
    let out = run(&["render", "huge.xml", "--quiet"], &dir);
    assert_clean_failure(&out, &["film 65536×65536 needs", "available"]);
}

#[test]
fn deeply_nested_plugins_are_refused_not_a_stack_overflow() {
    let dir = scratch("limits-nesting");
    let n = 10_000;
    let text = format!(
        r#"<scene version="3.0.0">{}{}</scene>"#,
        r#"<shape type="sphere">"#.repeat(n),
        "</shape>".repeat(n)
    );
    write(&dir, "deep.xml", &text);
    let out = run(&["render", "deep.xml", "--quiet"], &dir);
    assert_clean_failure(&out, &["deep.xml:1", "nested more than 32 deep"]);
}

#[test]
fn an_include_graph_that_fans_out_is_refused() {
    // Each of 12 files includes the next one 10 times: 10^11 inclusions
    // if followed.
    let dir = scratch("limits-includes");
    for i in 0..12 {
        let includes = if i < 11 {
            format!(r#"<include filename="f{}.xml"/>"#, i + 1).repeat(10)
        } else {
            String::new()
        };
        write(
            &dir,
            &format!("f{i}.xml"),
            &format!(r#"<scene version="3.0.0">{includes}</scene>"#),
        );
    }
    let out = run(&["render", "f0.xml", "--quiet"], &dir);
    assert_clean_failure(&out, &["more than 1000 <include>d files"]);
}

/// The time budget of the tests below (seconds).
const BUDGET: f64 = 0.5;

/// Seconds a run may take before [`render_within_budget`] kills it: a
/// watchdog, not a speed test. Without a deadline the work these tests ask
/// for takes hours, so any bound far above the budget tells the two apart,
/// and one this far above it does not fail on a loaded machine.
const WATCHDOG: Duration = Duration::from_secs(300);

/// Seconds past its budget a render's own clock (`seconds` in the JSON)
/// may show: the work after the deadline is milliseconds of CPU in these
/// tests; the runs they guard against took 25 s of CPU (mcmc-vcm) to
/// hours.
const PAST_THE_BUDGET: f64 = 5.0;

/// The Cornell box's size flags of the Markov start-up tests: 16×16.
const BOX_16: [&str; 4] = ["-D", "width=16", "-D", "height=16"];

/// A scratch directory `name` holding the repo's Cornell box as `s.xml`.
fn cornell_box_in(name: &str) -> std::path::PathBuf {
    let dir = scratch(name);
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/cornell-box.xml");
    std::fs::copy(scene, dir.join("s.xml")).expect("the Cornell box copies");
    dir
}

/// Renders `s.xml` in `dir` with `--time budget` and `args` (settings),
/// fails the test if the run outlives [`WATCHDOG`], fails, writes no image
/// or its clock shows more than [`PAST_THE_BUDGET`] past the budget, and
/// returns the JSON statistics.
fn render_within_budget(dir: &std::path::Path, budget: f64, args: &[&str]) -> serde_json::Value {
    let _ = std::fs::remove_file(dir.join("render.exr"));
    let mut child = Command::new(BIN)
        .args(["render", "s.xml", "--quiet", "--time", &budget.to_string()])
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary runs");
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        if start.elapsed() > WATCHDOG {
            let _ = child.kill();
            panic!("{args:?} ran {WATCHDOG:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr).unwrap();
    assert!(status.success(), "{args:?}: {stderr}");
    assert!(dir.join("render.exr").is_file(), "{args:?}: no image");
    let stats = json(&dir.join("render.json"));
    let seconds = stats["seconds"].as_f64().expect("seconds");
    assert!(
        seconds < budget + PAST_THE_BUDGET,
        "{args:?}: {seconds} s for a budget of {budget} s"
    );
    stats
}

/// `smcmc`'s global start-up (`init=global`) with a bootstrap of 20
/// million states (≈ 5 s here) stops at half of `--time` as the Markov
/// driver's does, so the tiles still run: before session 33 its bootstrap
/// was drawn at once, uncut, a `--time 2` run took 13 s, and the tiles
/// made no mutation (black image).
#[test]
fn smcmc_global_start_up_stops_at_the_time_budget() {
    let dir = cornell_box_in("limits-smcmc-global");
    let stats = render_within_budget(
        &dir,
        BUDGET,
        &[
            &BOX_16[..],
            &[
                "--integrator",
                "smcmc",
                "--set",
                "init=global",
                "--set",
                "init_bootstrap=20000000",
            ],
        ]
        .concat(),
    );
    let drawn = stats["global_init"]["drawn_bootstrap"]
        .as_u64()
        .expect("drawn_bootstrap");
    // Rounds of 4096 (`STARTUP_ROUND` in `markov/startup.rs`).
    assert!(
        drawn < 20_000_000 && drawn.is_multiple_of(4096),
        "{drawn} of 20 000 000"
    );
    let mutations = stats["mutations"].as_u64().expect("mutations");
    assert!(mutations > 0, "no tile step in {stats}");
}

/// A RELT replica that no bootstrap path reaches (the specific one, L0,
/// on the box with direct light only) does not hold the start-up past
/// `--time`: the cut start-up ends without it, RELT drops it, and the
/// run without it gets what is left of the budget (before session 32 the
/// start-up made all its draws — ≈ 25 s at this bootstrap — and the
/// second run restarted the budget).
#[test]
fn a_relt_replica_without_light_does_not_hold_the_start_up_past_the_budget() {
    let dir = cornell_box_in("limits-relt-dropped");
    let args = ["-D", "max_depth=2", "--integrator", "relt"];
    let stats = render_within_budget(
        &dir,
        BUDGET,
        &[&BOX_16[..], &args, &["--set", "bootstrap=20000000"]].concat(),
    );
    assert_eq!(stats["dropped_replicas"], serde_json::json!(["specific"]));
    // The first run's start-up reached its share of the budget
    // (`STARTUP_SHARE`: its 20 million draws take seconds), and the second
    // runs on the first's clock, so its start-up's share was past before
    // it began: it stopped after its first round of draws
    // (`STARTUP_ROUND`), once every replica it kept was lit (a restarted
    // budget would draw for another 0.25 s, ≈ 50 rounds).
    assert_eq!(stats["bootstrap_candidates"], 4096, "{stats}");
    // Its clock counts both runs, and its chains ran.
    let seconds = stats["seconds"].as_f64().expect("seconds");
    assert!(seconds >= BUDGET, "{seconds} s");
    assert!(
        stats["mutations"].as_u64().expect("mutations") > 0,
        "{stats}"
    );
}

/// Work sized by a setting stops at `--time` (issue 23, item 3): `mlt`'s
/// direct-lighting and specular-chain passes at 10^9 samples per pixel
/// (hours on this film) end at the budget with the samples per pixel they
/// finished, and the run writes its image.
#[test]
fn mlt_passes_sized_by_a_setting_stop_at_the_time_budget() {
    let dir = setup("limits-mlt-passes");
    let stats = render_within_budget(
        &dir,
        1.0,
        &[
            "--integrator",
            "mlt",
            "--set",
            "direct_samples=1000000000",
            "--set",
            "specular_samples=1000000000",
        ],
    );
    for pass in ["direct_pass", "specular_pass"] {
        let spp = stats[pass]["samples_per_pixel"]
            .as_u64()
            .unwrap_or_else(|| panic!("no {pass} in {stats}"));
        assert!(spp < 1_000_000_000, "{pass}: {spp} spp");
    }
}

/// `erpt`'s luminance estimate of 10^15 camera walks (it kept one value
/// per walk and was refused for its 8 PB) and a chain of 10^15 mutations
/// (no check inside a chain: the first pass never ended) stop at `--time`:
/// the estimate with the walks it took, the pass in flight dropped.
#[test]
fn erpt_work_sized_by_a_setting_stops_at_the_time_budget() {
    let dir = setup("limits-erpt");
    let stats = render_within_budget(
        &dir,
        BUDGET,
        &[
            "--integrator",
            "erpt",
            "--set",
            "luminance_samples=1000000000000000",
        ],
    );
    let walks = stats["luminance_samples"].as_u64().expect("walks");
    assert!(walks < 1_000_000_000_000_000, "{walks} walks");
    // The estimate stops at half the budget (`STARTUP_SHARE`), so passes
    // run (at the whole budget none did and the image was black).
    let passes = stats["passes"].as_u64().expect("passes");
    assert!(passes > 0, "no pass after the luminance estimate: {stats}");
    let stats = render_within_budget(
        &dir,
        BUDGET,
        &[
            "--integrator",
            "erpt",
            "--set",
            "chain_length=1000000000000000",
            "--set",
            "luminance_samples=1000",
        ],
    );
    assert_eq!(stats["luminance_samples"], 1000, "{stats}");
    assert_eq!(stats["passes"], 0, "{stats}");
}

/// `smcmc`'s alignment at 10^15 Jacobi sweeps (run at every develop, the
/// last one after the deadline) stops at `--time` once the default's 200
/// sweeps are done, and says so.
#[test]
fn smcmc_solver_sweeps_stop_at_the_time_budget() {
    let dir = setup("limits-smcmc");
    let stats = render_within_budget(
        &dir,
        BUDGET,
        &[
            "--integrator",
            "smcmc",
            "--set",
            "solver_iterations=1000000000000000",
        ],
    );
    let solver = &stats["solver"];
    let sweeps = solver["iterations"].as_u64().expect("sweeps");
    assert!((200..1_000_000_000_000_000).contains(&sweeps), "{solver}");
    assert_eq!(solver["planned_iterations"], 1_000_000_000_000_000u64);
}

/// `mcmc-vcm` restarted every chain pair by importance resampling over all
/// candidates before looking at the deadline: with more pairs than pixels
/// most pairs have no step of their own, and 30 000 pairs over 100 000
/// candidates kept a 0.5 s run going for minutes. The iteration in flight
/// is dropped at the deadline.
#[test]
fn mcmc_vcm_chain_pairs_stop_at_the_time_budget() {
    let dir = scratch("limits-mcmc-vcm");
    // A 2×2 film: the pairs' images stay small (60 MB in all).
    write(&dir, "s.xml", &floor_scene(2, 2));
    let stats = render_within_budget(
        &dir,
        BUDGET,
        &[
            "--integrator",
            "mcmc-vcm",
            "--set",
            "units=30000",
            "--set",
            "candidates=100000",
            "--set",
            "vis_pdf=false",
        ],
    );
    assert_eq!(stats["units"], 30000, "{stats}");
    assert_eq!(stats["iterations"], 0, "{stats}");
}

/// `mcmc-vcm`'s start-up sized by `candidates` (the pilot that fixes the
/// MIS scale, the first iteration's restart pool; 2·10^7 each, ≈ 20 s
/// here) stops drawing at half of `--time` (the pilot at a quarter), so
/// the first iteration ends within the budget: before session 34 the pool
/// was drawn until the deadline, the iteration in flight was dropped and
/// the image was black. A budget of 2 s, not [`BUDGET`]: a round of
/// candidates takes tens of milliseconds, and the first iteration must
/// fit after two of them on a loaded machine.
#[test]
fn mcmc_vcm_start_up_stops_at_the_time_budget() {
    let dir = cornell_box_in("limits-mcmc-vcm-start-up");
    let stats = render_within_budget(
        &dir,
        2.0,
        &[
            &BOX_16[..],
            &["--integrator", "mcmc-vcm", "--set", "candidates=20000000"],
        ]
        .concat(),
    );
    // Cut between rounds of 16 blocks × 4096 (`CANDIDATE_ROUND`).
    for phase in ["pilot_drawn", "first_pool_drawn"] {
        let drawn = stats[phase]
            .as_u64()
            .unwrap_or_else(|| panic!("{phase}: {stats}"));
        assert!(
            drawn < 20_000_000 && drawn.is_multiple_of(16 * 4096),
            "{phase}: {drawn} of 20 000 000"
        );
    }
    let iterations = stats["iterations"].as_u64().expect("iterations");
    assert!(iterations > 0, "no iteration in {stats}");
}

/// `relt`'s start-up phases sized by a setting (`l0_search` draws,
/// `annealing_sweeps` per particle) stop at `--time` like the chains,
/// and the JSON says how much of them was done. One run per phase, so
/// that each is cut by itself (the annealing comes first and would
/// otherwise leave the search nothing). So does the search continued
/// during the run (`l0_search_rate`: 10^9 draws per mutation, in units
/// of 2 draws, owed after the chains' first round).
#[test]
fn relt_start_up_phases_sized_by_a_setting_stop_at_the_time_budget() {
    let dir = cornell_box_in("limits-relt-start-up");
    for (phase, setting) in [
        ("search", "l0_search=1000000000000"),
        ("annealing", "annealing_sweeps=1000000000"),
        ("continued search", "l0_search_rate=1000000000"),
    ] {
        let stats = render_within_budget(
            &dir,
            BUDGET,
            &[
                "-D",
                "width=8",
                "-D",
                "height=8",
                "--integrator",
                "relt",
                "--set",
                "bootstrap=2000",
                "--set",
                "annealing_particles=200",
                "--set",
                "l0_search=20000",
                // Two replica sets: rounds of 512 mutations, so that the
                // chains finish some before the budget.
                "--set",
                "chains=8",
                "--set",
                setting,
            ],
        );
        let search = &stats["searches"][3];
        let draws = search["draws"]
            .as_u64()
            .unwrap_or_else(|| panic!("no search of the specific replica in {stats}"));
        let steps: Vec<u64> = stats["annealing"]
            .as_array()
            .unwrap_or_else(|| panic!("no annealing in {stats}"))
            .iter()
            .map(|m| m["steps"].as_u64().expect("annealing steps"))
            .collect();
        assert_eq!(steps.len(), 4, "{stats}");
        match phase {
            "search" => {
                assert!(draws < 1_000_000_000_000, "{draws} draws");
                // The annealing comes first. It is not cut (200 particles
                // × 1 sweep) unless the budget has passed before the
                // search (a starved machine), and then the search, which
                // looks at the clock before each block, makes no draw.
                assert!(
                    steps[1..] == [200, 200, 200] || draws == 0,
                    "{steps:?}, {draws} draws"
                );
            }
            "annealing" => {
                assert!(steps[1..].iter().all(|&s| s < 200_000_000_000), "{steps:?}")
            }
            _ => {
                // The start-up whole, then some of the continued draws.
                assert_eq!(draws, 20_000, "{stats}");
                assert_eq!(steps[1..], [200, 200, 200]);
                let run = search["run_draws"].as_u64().expect("run draws");
                let mutations = stats["mutations"].as_u64().expect("mutations");
                assert!(run > 0 && run < 1_000_000_000 * mutations, "{stats}");
            }
        }
    }
}

/// The Markov driver's start-up stops at `--time` (issue 13): a bootstrap
/// of 20 million candidates (≈ 20 s on two cores for `pssmlt` on this
/// film, 2 million for the 8 levels of `tempered-pssmlt`, traced once and
/// weighed for every level) ends at the end of the round in flight, and
/// so does `mept`'s BDPT start-up of as many draws. The JSON reports the
/// candidates drawn (`bootstrap_candidates`; the search's `draws`), and
/// the run writes its image.
#[test]
fn markov_start_ups_sized_by_a_setting_stop_at_the_time_budget() {
    let dir = cornell_box_in("limits-markov-start-up");
    // `STARTUP_ROUND` in `markov/startup.rs`: the start-up draws in rounds.
    const ROUND: u64 = 4096;
    for (integrator, candidates) in [
        ("pssmlt", 20_000_000),
        ("tempered-pssmlt", 2_000_000),
        ("mept", 20_000_000),
    ] {
        let bootstrap = format!("bootstrap={candidates}");
        let stats = render_within_budget(
            &dir,
            BUDGET,
            &[
                &BOX_16[..],
                &["--integrator", integrator, "--set", &bootstrap],
            ]
            .concat(),
        );
        // `mept`'s draws are its BDPT start-up's (its driver bootstrap is
        // one candidate).
        let drawn = match integrator {
            "mept" => &stats["searches"][0]["draws"],
            _ => &stats["bootstrap_candidates"],
        };
        let drawn = drawn
            .as_u64()
            .unwrap_or_else(|| panic!("{integrator}: no start-up draws in {stats}"));
        assert!(
            drawn < candidates && drawn.is_multiple_of(ROUND),
            "{integrator}: {drawn} of {candidates}"
        );
        // The start-up stops at half the budget (`STARTUP_SHARE`), so the
        // chains run and the image is not black (at the whole budget they
        // had made no mutation).
        let mutations = stats["mutations"].as_u64().expect("mutations");
        assert!(mutations > 0, "{integrator}: no mutation in {stats}");
    }
}
