//! `mcmc-render convergence`: the CSV and the plot of a short study on a
//! 16×16 Cornell box, `--replot`, and its refusals of bad input.

mod cli_support;

use cli_support::{assert_clean_failure, run, run_ok, scratch, write};
use mcmc_render::cli::convergence::{Record, read_csv, write_csv};
use mcmc_render::color::Rgb;
use mcmc_render::compare::Corrected;
use std::path::Path;

/// The Cornell box fixture of the test suite.
fn cornell() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/scenes/cornell-box.xml")
        .display()
        .to_string()
}

/// Writes `ref.exr`: the 16×16 box path traced at 1024 spp, with another
/// seed than the study (seed 0): the same seed would replay the reference's
/// own samples and make the early error artificially small.
fn reference(dir: &Path) {
    let scene = cornell();
    run_ok(
        &[
            "render", &scene, "-D", "res=16", "--spp", "1024", "--seed", "7", "--out", "ref.exr",
            "--quiet",
        ],
        dir,
    );
}

/// Decodes a PNG and returns its size.
fn png_size(path: &Path) -> (u32, u32) {
    let file = std::fs::File::open(path).unwrap();
    let decoder = png::Decoder::new(std::io::BufReader::new(file));
    let mut reader = decoder.read_info().expect("a valid PNG header");
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).expect("valid PNG data");
    (info.width, info.height)
}

const INTEGRATORS: [&str; 4] = ["pt", "bdpt", "pssmlt", "mmlt"];
const CHECKPOINTS: usize = 3;

#[test]
fn convergence_writes_csv_and_plot_for_four_integrators() {
    let dir = scratch("convergence");
    reference(&dir);
    let scene = cornell();
    let stdout = run_ok(
        &[
            "convergence",
            &scene,
            "-D",
            "res=16",
            "--reference",
            "ref.exr",
            "--integrators",
            &INTEGRATORS.join(","),
            "--time",
            "1",
            "--checkpoints",
            &CHECKPOINTS.to_string(),
            // A small bootstrap (8 depths × 1000 for mmlt) so that the
            // chains start well within the 1 s budget on a loaded machine.
            "--bootstrap",
            "1000",
            "--chains",
            "16",
            "--threads",
            "2",
            "--out",
            "c.csv",
        ],
        &dir,
    );
    let text = std::fs::read_to_string(dir.join("c.csv")).unwrap();
    assert_eq!(
        text.lines().next(),
        Some("integrator,seconds,samples,rel_mse,rmse")
    );
    let records = read_csv(&dir.join("c.csv")).unwrap();
    assert_eq!(records.len(), text.lines().count() - 1);
    // One stdout line per record.
    assert_eq!(stdout.lines().count(), records.len());
    for name in INTEGRATORS {
        let rows: Vec<&Record> = records.iter().filter(|r| r.integrator == name).collect();
        // A record at the first image after each of the K checkpoint times
        // that the run reaches, and one at the end.
        assert!(
            !rows.is_empty() && rows.len() <= CHECKPOINTS + 1,
            "{name}: {} rows",
            rows.len()
        );
        for r in &rows {
            assert!(r.seconds > 0.0 && r.seconds.is_finite(), "{r:?}");
            assert!(r.samples > 0, "{r:?}");
            assert!(r.rel_mse > 0.0 && r.rel_mse.is_finite(), "{r:?}");
            assert!(r.rmse > 0.0 && r.rmse.is_finite(), "{r:?}");
        }
        for pair in rows.windows(2) {
            assert!(pair[0].seconds < pair[1].seconds, "{name}: {pair:?}");
            assert!(pair[0].samples <= pair[1].samples, "{name}: {pair:?}");
        }
    }
    // Records come integrator by integrator, in the order asked for.
    let order: Vec<&str> =
        records
            .iter()
            .map(|r| r.integrator.as_str())
            .fold(Vec::new(), |mut v, n| {
                if v.last() != Some(&n) {
                    v.push(n);
                }
                v
            });
    assert_eq!(order, INTEGRATORS);
    assert_eq!(png_size(&dir.join("c.png")), (800, 600));

    // --replot redraws the plot from the CSV alone.
    std::fs::remove_file(dir.join("c.png")).unwrap();
    run_ok(
        &["convergence", "--replot", "c.csv", "--title", "box"],
        &dir,
    );
    assert_eq!(png_size(&dir.join("c.png")), (800, 600));
}

/// `--images DIR`: each integrator's final image, its statistics and its
/// per-pixel relative-error maps. The JSON's relMSE is the one `compare`
/// computes on the written EXR against the reference (a separate command
/// reading both files), and the error EXR's mean is that relMSE; a
/// modifier's `+` and `=` become `_` in file names.
#[test]
fn convergence_writes_final_images_and_error_maps() {
    use mcmc_render::image_io::read_exr;
    let dir = scratch("convergence-images");
    reference(&dir);
    let scene = cornell();
    run_ok(
        &[
            "convergence",
            &scene,
            "-D",
            "res=16",
            "--reference",
            "ref.exr",
            "--integrators",
            "pt,mmlt+plarge=0.5",
            "--time",
            "1",
            "--checkpoints",
            "1",
            "--bootstrap",
            "1000",
            "--chains",
            "16",
            "--threads",
            "2",
            "--out",
            "c.csv",
            "--images",
            "final",
        ],
        &dir,
    );
    for stem in ["pt", "mmlt_plarge_0.5"] {
        let f = dir.join("final");
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(f.join(format!("{stem}.json"))).unwrap())
                .unwrap();
        let rel = json["rel_mse"].as_f64().unwrap();
        assert!(json["samples"].as_u64().unwrap() > 0, "{json}");
        // What ran: the variant's own setting (`plarge`, an alias) and
        // the study's flags.
        let (registered, plarge) = match stem {
            "pt" => ("pt", None),
            _ => ("mmlt", Some(0.5)),
        };
        assert_eq!(json["registered"], registered, "{json}");
        assert_eq!(json["seed"], 0, "{json}");
        if let Some(p) = plarge {
            assert_eq!(json["settings"]["large_step_probability"], p, "{json}");
            assert_eq!(json["settings"]["bootstrap"], 1000, "{json}");
            assert_eq!(json["settings"]["chains"], 16, "{json}");
        }
        let out = run_ok(
            &["compare", "ref.exr", &format!("final/{stem}.exr"), "--json"],
            &dir,
        );
        let c: serde_json::Value = serde_json::from_str(&out).unwrap();
        let rel_c = c["rel_mse"].as_f64().unwrap();
        assert!(
            (rel - rel_c).abs() <= 1e-12 * rel_c,
            "{stem}: {rel} vs {rel_c}"
        );
        let (w, h, e) = read_exr(&f.join(format!("{stem}.relerr.exr"))).unwrap();
        assert_eq!((w, h), (16, 16));
        // The map holds the f32 terms of the f64 mean.
        let mean = e.iter().map(|p| f64::from(p.r)).sum::<f64>() / e.len() as f64;
        assert!(
            (mean - rel).abs() <= 1e-6 * rel,
            "{stem}: map mean {mean} vs {rel}"
        );
        assert_eq!(png_size(&f.join(format!("{stem}.relerr.png"))), (16, 16));
    }
}

#[test]
fn csv_round_trips_through_read_csv() {
    let dir = scratch("convergence-csv");
    let records = vec![
        Record {
            integrator: "pt".into(),
            seconds: 0.5,
            samples: 1024,
            rel_mse: 1.25e-2,
            rmse: 3.5e-3,
            corrected: None,
        },
        Record {
            integrator: "mmlt".into(),
            seconds: 1.25,
            samples: 4096,
            rel_mse: 2.5e-3,
            rmse: 1.5e-3,
            corrected: None,
        },
    ];
    let path = dir.join("r.csv");
    write_csv(&path, &records).unwrap();
    // The CSV keeps 4 decimals of seconds and 7 significant digits of the
    // errors: exact for these values.
    assert_eq!(read_csv(&path).unwrap(), records);
    // With corrected errors: four more columns (negative values allowed:
    // they are estimates).
    let corrected: Vec<Record> = records
        .into_iter()
        .map(|r| Record {
            corrected: Some(Corrected {
                rel_mse: -2.5e-4,
                rel_mse_floor: 1.5e-3,
                mse: 1.25e-6,
                mse_floor: 7.5e-7,
            }),
            ..r
        })
        .collect();
    write_csv(&path, &corrected).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.starts_with(
        "integrator,seconds,samples,rel_mse,rmse,rel_mse_floor,rel_mse_corrected,mse_floor,mse_corrected\n"
    ));
    assert_eq!(read_csv(&path).unwrap(), corrected);
}

/// `--reference-variance`/`--reference-spp` and `--second-reference` add the
/// corrected errors to `convergence` (CSV columns, stdout) and to `compare`;
/// plain = corrected + floor; bad noise input is refused with one line.
#[test]
fn convergence_and_compare_take_the_references_noise_out() {
    let dir = scratch("convergence-noise");
    reference(&dir);
    let scene = cornell();
    run_ok(
        &[
            "render", &scene, "-D", "res=16", "--spp", "256", "--seed", "8", "--out", "ref2.exr",
            "--quiet",
        ],
        &dir,
    );
    // A variance image: constant per-sample variance 0.04 (so 0.04/1024 per
    // pixel of the 1024-spp reference), and a 16×16 one with a negative pixel.
    let write = |name: &str, size: u32, v: f32| {
        let mut pixels = vec![Rgb::splat(0.04); (size * size) as usize];
        pixels[3] = Rgb::splat(v);
        mcmc_render::image_io::write_exr(&dir.join(name), size, size, &pixels).unwrap();
    };
    write("var.exr", 16, 0.04);
    write("neg.exr", 16, -1.0);
    write("small.exr", 8, 0.04);
    let study = |extra: &[&'static str]| {
        let mut a = vec![
            "convergence",
            scene.as_str(),
            "-D",
            "res=16",
            "--reference",
            "ref.exr",
            "--integrators",
            "pt",
            "--time",
            "0.2",
            "--checkpoints",
            "2",
            "--out",
            "n.csv",
        ];
        a.extend_from_slice(extra);
        a
    };
    for (extra, floor) in [
        (
            &["--reference-variance", "var.exr", "--reference-spp", "1024"][..],
            Some(0.04 / 1024.0),
        ),
        (&["--second-reference", "ref2.exr"][..], None),
    ] {
        let stdout = run_ok(&study(extra), &dir);
        assert!(stdout.contains("corrected relMSE"), "{stdout}");
        let records = read_csv(&dir.join("n.csv")).unwrap();
        assert!(!records.is_empty());
        for r in &records {
            let k = r.corrected.expect("corrected columns");
            // 7 significant digits in the CSV.
            let mse = r.rmse * r.rmse;
            assert!((k.mse + k.mse_floor - mse).abs() <= 1e-5 * mse, "{r:?}");
            assert!(
                (k.rel_mse + k.rel_mse_floor - r.rel_mse).abs() <= 1e-5 * r.rel_mse,
                "{r:?}"
            );
            if let Some(f) = floor {
                assert!((k.mse_floor - f).abs() <= 1e-5 * f, "{r:?}");
            }
        }
    }
    let compared = run_ok(
        &[
            "compare",
            "ref.exr",
            "ref2.exr",
            "--second-reference",
            "ref2.exr",
        ],
        &dir,
    );
    assert!(compared.contains("MSE corrected"), "{compared}");
    let json = run_ok(
        &[
            "compare",
            "ref.exr",
            "ref2.exr",
            "--json",
            "--reference-variance",
            "var.exr",
            "--reference-spp",
            "1024",
        ],
        &dir,
    );
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert!(
        v["corrected"]["mse_floor"].as_f64().unwrap() > 0.0,
        "{json}"
    );
    assert!(v["rel_mse"].as_f64().unwrap() > 0.0, "{json}");

    let out = run(
        &study(&["--reference-variance", "neg.exr", "--reference-spp", "4"]),
        &dir,
    );
    assert_clean_failure(&out, &["error:", "neg.exr", "negative at pixel (3, 0)"]);
    let out = run(
        &study(&["--reference-variance", "small.exr", "--reference-spp", "4"]),
        &dir,
    );
    assert_clean_failure(&out, &["error:", "8x8"]);
    let out = run(
        &study(&["--reference-variance", "var.exr", "--reference-spp", "0"]),
        &dir,
    );
    assert_clean_failure(
        &out,
        &["error:", "--reference-spp must be a positive number"],
    );
    let out = run(&study(&["--reference-variance", "var.exr"]), &dir);
    assert_clean_failure(&out, &["--reference-spp"]);
    assert_eq!(out.status.code(), Some(2));
    let out = run(
        &study(&[
            "--reference-variance",
            "var.exr",
            "--reference-spp",
            "4",
            "--second-reference",
            "ref2.exr",
        ]),
        &dir,
    );
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn convergence_refuses_bad_input_with_one_line() {
    let dir = scratch("convergence-bad");
    reference(&dir);
    let scene = cornell();
    let base = |extra: &[&'static str]| -> Vec<String> {
        let mut a: Vec<String> = [
            "convergence",
            scene.as_str(),
            "--time",
            "0.2",
            "--checkpoints",
            "2",
            "--out",
            "c.csv",
        ]
        .iter()
        .map(|x| x.to_string())
        .collect();
        a.extend(extra.iter().map(|x| x.to_string()));
        a
    };
    let run = |args: Vec<String>| {
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        run(&refs, &dir)
    };

    let out = run(base(&["-D", "res=16", "--reference", "missing.exr"]));
    assert_clean_failure(&out, &["error:", "missing.exr"]);

    let out = run(base(&["-D", "res=8", "--reference", "ref.exr"]));
    assert_clean_failure(&out, &["error:", "16x16", "8x8"]);

    let out = run(base(&[
        "-D",
        "res=16",
        "--reference",
        "ref.exr",
        "--integrators",
        "pt,warp",
    ]));
    assert_clean_failure(&out, &["error:", "warp"]);
    assert!(!dir.join("c.csv").exists(), "a refused study wrote a CSV");

    // Without a reference (and without --replot), clap refuses.
    let out = run(vec!["convergence".into(), scene.clone()]);
    assert_clean_failure(&out, &["--reference"]);
    assert_eq!(out.status.code(), Some(2));

    write(&dir, "bad.csv", "integrator,seconds\npt,1\n");
    let out = run(vec![
        "convergence".into(),
        "--replot".into(),
        "bad.csv".into(),
    ]);
    assert_clean_failure(&out, &["error:", "bad.csv:1"]);
    write(
        &dir,
        "bad2.csv",
        "integrator,seconds,samples,rel_mse,rmse\npt,1,x,0.1,0.1\n",
    );
    let out = run(vec![
        "convergence".into(),
        "--replot".into(),
        "bad2.csv".into(),
    ]);
    assert_clean_failure(&out, &["error:", "bad2.csv:2"]);
}

#[test]
fn an_integrator_without_records_is_reported() {
    let dir = scratch("convergence-empty");
    reference(&dir);
    let scene = cornell();
    // erpt's first pass (a chain of 100 000 mutations per path-traced
    // sample, seconds) outlasts the 0.05 s budget and is dropped, so it
    // renders nothing; pt records its passes. (Until session 32 this was
    // mmlt's bootstrap; its start-up now stops at half the budget.)
    let out = run(
        &[
            "convergence",
            &scene,
            "-D",
            "res=16",
            "--reference",
            "ref.exr",
            "--integrators",
            "pt,erpt+chain_length=100000",
            "--time",
            "0.05",
            "--checkpoints",
            "2",
            "--threads",
            "2",
            "--out",
            "c.csv",
        ],
        &dir,
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("warning: erpt+chain_length=100000 has no record"),
        "stderr: {stderr}"
    );
    let records = read_csv(&dir.join("c.csv")).unwrap();
    assert!(records.iter().any(|r| r.integrator == "pt"));
    assert!(records.iter().all(|r| !r.integrator.starts_with("erpt")));
}
