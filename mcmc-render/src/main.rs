//! The `mcmc-render` command line.
//!
//! - `mcmc-render`: renders the embedded default scene to `render.exr` and `render.png`.
//! - `mcmc-render render SCENE.xml [--integrator pt|lt|bdpt] [--spp N | --time S] [--seed K]
//!   [--threads T] [--out FILE.exr] [-D name=value]…`
//! - `mcmc-render render SCENE.xml --replay DUMP.pss`: re-trace a NaN/inf
//!   primary-sample dump of `--integrator pssmlt|mmlt`
//! - `mcmc-render convergence SCENE.xml --reference REF.exr [--integrators …]
//!   [--time S] [--checkpoints K] [--out FILE.csv]`, or `convergence --replot FILE.csv`
//! - `mcmc-render compare REF.exr TEST.exr [--json]`
//! - `mcmc-render info SCENE.xml`
//!
//! Ctrl-C (SIGINT) during `render` stops early and writes what was rendered
//! so far (normalised by it), with `"interrupted": true` in the JSON, and
//! exits with status 0; a second Ctrl-C exits at once with status 130.
//! Every failure prints one line `error: …` on stderr
//! and exits with status 1 (2 for unusable arguments).

use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use mcmc_render::compare::compare;
use mcmc_render::film::Film;
use mcmc_render::image_io::{read_exr, write_exr, write_png};
use mcmc_render::integrators::{
    Integrator,
    bdpt::{Bdpt, MisHeuristic},
    lt::LightTracer,
    pt::PathTracer,
};
use mcmc_render::render::{RenderObserver, RenderSettings, render};
use mcmc_render::scene::Scene;
use serde::Serialize;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The embedded default scene.
const DEFAULT_SCENE: &str = include_str!("../scenes/default.xml");

/// Set by Ctrl-C: finish with what has been rendered.
static STOP: AtomicBool = AtomicBool::new(false);

#[derive(Parser)]
#[command(
    name = "mcmc-render",
    version,
    about = "Physically based renderer (Mitsuba 3 XML subset)"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Clone, Copy, Debug, ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
enum IntegratorArg {
    /// Path tracing with next-event estimation and MIS.
    Pt,
    /// Light tracing.
    Lt,
    /// Primary sample space MLT over pt or bdpt (see the MLT flags).
    Pssmlt,
    /// Multiplexed MLT over BDPT techniques (see the MLT flags).
    Mmlt,
    /// Bidirectional path tracing (all techniques, power-heuristic MIS).
    Bdpt,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene file.
    Render {
        /// Mitsuba 3 XML scene.
        scene: PathBuf,
        /// Integrator.
        #[arg(long, value_enum, default_value = "pt")]
        integrator: IntegratorArg,
        /// Samples per pixel (light paths per pixel for lt); default: the scene's sample_count.
        #[arg(long, allow_negative_numbers = true)]
        spp: Option<i64>,
        /// Time budget in seconds (renders until then unless --spp is reached first).
        #[arg(long, allow_negative_numbers = true)]
        time: Option<f64>,
        /// Seed of the random streams.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Output EXR; the PNG preview and JSON statistics go beside it.
        #[arg(long, default_value = "render.exr")]
        out: PathBuf,
        /// Override a `<default name=…>` value: -D name=value.
        #[arg(short = 'D', value_name = "NAME=VALUE")]
        define: Vec<String>,
        /// Do not show a progress bar.
        #[arg(long)]
        quiet: bool,
        #[command(flatten)]
        mlt: mcmc_render::mlt_cli::MltArgs,
    },
    /// Compare a test EXR against a reference EXR.
    Compare {
        /// Reference image.
        reference: PathBuf,
        /// Test image.
        test: PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Error against time of several integrators at equal time budgets (CSV + log-log PNG).
    Convergence {
        /// Mitsuba 3 XML scene.
        #[arg(required_unless_present = "replot")]
        scene: Option<PathBuf>,
        /// Reference EXR (e.g. a long `render --integrator pt` run).
        #[arg(long, required_unless_present = "replot")]
        reference: Option<PathBuf>,
        /// Only redraw the plot of an existing CSV (written beside it as PNG).
        #[arg(long, value_name = "CSV", conflicts_with_all = ["scene", "reference"])]
        replot: Option<PathBuf>,
        /// Plot title (default: the scene's or CSV's file stem).
        #[arg(long)]
        title: Option<String>,
        /// Comma-separated integrators (pt, lt, bdpt, pssmlt, pssmlt-bdpt, mmlt).
        #[arg(long, default_value = "pt,pssmlt")]
        integrators: String,
        /// Seconds per integrator.
        #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
        time: f64,
        /// Checkpoints per integrator.
        #[arg(long, default_value_t = 8)]
        checkpoints: u32,
        /// Seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Output CSV; the plot goes beside it as PNG.
        #[arg(long, default_value = "convergence.csv")]
        out: PathBuf,
        /// Override a `<default name=…>` value: -D name=value.
        #[arg(short = 'D', value_name = "NAME=VALUE")]
        define: Vec<String>,
        #[command(flatten)]
        mlt: mcmc_render::mlt_cli::MltArgs,
    },
    /// Describe what a scene file loads to.
    Info {
        /// Mitsuba 3 XML scene.
        scene: PathBuf,
        /// Override a `<default name=…>` value: -D name=value.
        #[arg(short = 'D', value_name = "NAME=VALUE")]
        define: Vec<String>,
    },
}

fn main() {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            // Help and version are not errors.
            if matches!(
                e.kind(),
                clap::error::ErrorKind::DisplayHelp | clap::error::ErrorKind::DisplayVersion
            ) {
                let _ = e.print();
                std::process::exit(0);
            }
            // clap's message is a paragraph (e.g. "required arguments were
            // not provided:" then the arguments) before the usage; keep the
            // paragraph, on one line.
            let msg = e.to_string();
            let para: Vec<&str> = msg
                .lines()
                .map(str::trim)
                .take_while(|l| !l.is_empty())
                .collect();
            let line = if para.is_empty() {
                "error: invalid arguments".to_string()
            } else {
                para.join(" ")
            };
            eprintln!("{line}");
            std::process::exit(2);
        }
    };
    if let Err(e) = run(cli) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<(), String> {
    match cli.command {
        None => {
            let scene =
                Scene::load_str(DEFAULT_SCENE, Path::new("<default scene>"), Path::new("."))
                    .map_err(|e| e.to_string())?;
            let spp = scene.sample_count;
            do_render(RenderJob {
                scene,
                integrator: IntegratorArg::Pt,
                spp: Some(spp),
                time: None,
                seed: 0,
                threads: None,
                out: PathBuf::from("render.exr"),
                scene_name: "<default scene>".into(),
                quiet: false,
            })
        }
        Some(Command::Render {
            scene,
            integrator,
            spp,
            time,
            seed,
            threads,
            out,
            define,
            quiet,
            mlt,
        }) => {
            let spp = match spp {
                Some(n) if n <= 0 => {
                    return Err(format!("--spp must be a positive integer, got {n}"));
                }
                Some(n) if n > u32::MAX as i64 => return Err(format!("--spp {n} is too large")),
                Some(n) => Some(n as u32),
                None => None,
            };
            if let Some(t) = time
                && !(t > 0.0 && t.is_finite())
            {
                return Err(format!(
                    "--time must be a positive number of seconds, got {t}"
                ));
            }
            if threads == Some(0) {
                return Err("--threads must be at least 1".into());
            }
            let defines = parse_defines(&define)?;
            if let Some(file) = &mlt.replay {
                // Replay writes nothing: no output check.
                let loaded = Scene::load(&scene, &defines).map_err(|e| e.to_string())?;
                return mcmc_render::mlt_cli::replay(&loaded, file);
            }
            check_writable(&out)?;
            let loaded = Scene::load(&scene, &defines).map_err(|e| e.to_string())?;
            if matches!(integrator, IntegratorArg::Pssmlt | IntegratorArg::Mmlt) {
                stop_on_ctrl_c();
                let job = mcmc_render::mlt_cli::MltJob {
                    scene: &loaded,
                    scene_name: &scene.display().to_string(),
                    args: &mlt,
                    kind: if matches!(integrator, IntegratorArg::Mmlt) {
                        mcmc_render::mlt_cli::MltKind::Mmlt
                    } else {
                        mcmc_render::mlt_cli::MltKind::Pssmlt
                    },
                    time,
                    seed,
                    threads: threads.unwrap_or_else(|| {
                        std::thread::available_parallelism().map_or(1, |n| n.get())
                    }),
                    out: &out,
                    quiet,
                };
                return mcmc_render::mlt_cli::run_pssmlt(&job, &STOP).map(|_| ());
            }
            let spp = match (spp, time) {
                (Some(n), _) => Some(n),
                (None, Some(_)) => None,
                (None, None) => Some(loaded.sample_count),
            };
            do_render(RenderJob {
                scene: loaded,
                integrator,
                spp,
                time,
                seed,
                threads,
                out,
                scene_name: scene.display().to_string(),
                quiet,
            })
        }
        Some(Command::Compare {
            reference,
            test,
            json,
        }) => {
            let (rw, rh, r) = read_exr(&reference)?;
            let (tw, th, t) = read_exr(&test)?;
            if (rw, rh) != (tw, th) {
                return Err(format!("image sizes differ: {rw}x{rh} vs {tw}x{th}"));
            }
            let c = compare(&r, &t)?;
            if json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&c).map_err(|e| e.to_string())?
                );
            } else {
                println!("relMSE              {:.6e}", c.rel_mse);
                println!("RMSE                {:.6e}", c.rmse);
                println!(
                    "mean rel. diff      R {:+.4}%  G {:+.4}%  B {:+.4}%",
                    100.0 * c.mean_rel_diff[0],
                    100.0 * c.mean_rel_diff[1],
                    100.0 * c.mean_rel_diff[2]
                );
                println!(
                    "reference mean      {:.6} {:.6} {:.6}",
                    c.ref_mean[0], c.ref_mean[1], c.ref_mean[2]
                );
                println!(
                    "test mean           {:.6} {:.6} {:.6}",
                    c.test_mean[0], c.test_mean[1], c.test_mean[2]
                );
                println!(
                    "non-finite pixels   reference {}  test {}",
                    c.ref_nonfinite, c.test_nonfinite
                );
            }
            Ok(())
        }
        Some(Command::Convergence {
            scene,
            reference,
            replot,
            title,
            integrators,
            time,
            checkpoints,
            seed,
            threads,
            out,
            define,
            mlt,
        }) => {
            let stem = |p: &Path| {
                p.file_stem()
                    .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
            };
            if let Some(csv) = replot {
                let records = mcmc_render::convergence::read_csv(&csv)?;
                let names = mcmc_render::convergence::integrators_of(&records);
                let title = title.unwrap_or_else(|| stem(&csv));
                let png = csv.with_extension("png");
                mcmc_render::convergence::write_plot(&png, &records, &names, &title)?;
                println!("{}", png.display());
                return Ok(());
            }
            // clap requires both unless --replot is given.
            let (Some(scene), Some(reference)) = (scene, reference) else {
                return Err("convergence needs SCENE and --reference (or --replot CSV)".into());
            };
            let title = title.unwrap_or_else(|| stem(&scene));
            check_writable(&out)?;
            let defines = parse_defines(&define)?;
            let loaded = Scene::load(&scene, &defines).map_err(|e| e.to_string())?;
            let (rw, rh, r) = read_exr(&reference)?;
            if (rw, rh) != (loaded.film.width, loaded.film.height) {
                return Err(format!(
                    "reference is {rw}x{rh}, the scene renders {}x{}",
                    loaded.film.width, loaded.film.height
                ));
            }
            let names: Vec<String> = integrators
                .split(',')
                .map(|s| s.trim().to_string())
                .collect();
            let settings = mlt.settings(Some(time), seed)?;
            let mmlt = mlt.settings_for(mcmc_render::mlt_cli::MltKind::Mmlt, Some(time), seed)?;
            let threads = threads.unwrap_or(0);
            stop_on_ctrl_c();
            let records = mcmc_core::runner::with_threads(threads, || {
                let study = mcmc_render::convergence::Study {
                    integrators: names.clone(),
                    seconds: time,
                    checkpoints,
                    seed,
                    mlt: settings,
                    mmlt,
                };
                mcmc_render::convergence::run(&loaded, &r, &study, &STOP)
            })?;
            mcmc_render::convergence::write_csv(&out, &records)?;
            mcmc_render::convergence::write_plot(
                &out.with_extension("png"),
                &records,
                &names,
                &title,
            )?;
            if !STOP.load(Ordering::SeqCst) {
                for name in names
                    .iter()
                    .filter(|n| !records.iter().any(|r| &r.integrator == *n))
                {
                    eprintln!(
                        "warning: {name} has no record: its start-up (bootstrap) outlasted --time {time}"
                    );
                }
            }
            for rec in &records {
                println!(
                    "{:8} {:8.2} s {:>12} relMSE {:.4e} RMSE {:.4e}",
                    rec.integrator, rec.seconds, rec.samples, rec.rel_mse, rec.rmse
                );
            }
            Ok(())
        }
        Some(Command::Info { scene, define }) => {
            let defines = parse_defines(&define)?;
            let s = Scene::load(&scene, &defines).map_err(|e| e.to_string())?;
            print_info(&scene, &s);
            Ok(())
        }
    }
}

/// Ctrl-C sets [`STOP`]: the run finishes with what it has and writes it.
/// A second Ctrl-C (e.g. during an MLT bootstrap, which does not poll the
/// flag) exits at once with status 130, writing nothing.
fn stop_on_ctrl_c() {
    // Ignore a failure to install the handler (e.g. set twice): rendering
    // still works, only Ctrl-C falls back to the default action.
    let _ = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::SeqCst) {
            eprintln!("error: interrupted twice; exiting without writing");
            std::process::exit(130);
        }
    });
}

fn parse_defines(defs: &[String]) -> Result<HashMap<String, String>, String> {
    defs.iter()
        .map(|d| {
            d.split_once('=')
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .ok_or_else(|| format!("-D expects NAME=VALUE, got \"{d}\""))
        })
        .collect()
}

/// Fails early (before a long render) when the output cannot be written.
fn check_writable(out: &Path) -> Result<(), String> {
    let existed = out.exists();
    std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(false)
        .open(out)
        .map_err(|e| format!("cannot write output {}: {e}", out.display()))?;
    if !existed {
        let _ = std::fs::remove_file(out);
    }
    Ok(())
}

fn print_info(path: &Path, s: &Scene) {
    let mut kinds: Vec<(String, usize)> = Vec::new();
    for sh in &s.shapes {
        match kinds.iter_mut().find(|(k, _)| *k == sh.kind) {
            Some((_, n)) => *n += 1,
            None => kinds.push((sh.kind.clone(), 1)),
        }
    }
    let shapes: Vec<String> = kinds.iter().map(|(k, n)| format!("{n} {k}")).collect();
    let area = s
        .lights
        .lights
        .iter()
        .filter(|l| matches!(l, mcmc_render::light::Light::Area { .. }))
        .count();
    println!("scene               {}", path.display());
    println!(
        "shapes              {} ({})",
        s.shapes.len(),
        shapes.join(", ")
    );
    println!("triangles           {}", s.geometry.triangles);
    println!("dropped triangles   {} (zero area)", s.dropped_degenerate);
    println!("bsdfs               {}", s.bsdf_descs.len());
    for (i, d) in s.bsdf_descs.iter().enumerate() {
        println!("  [{i}] {d:?}");
    }
    println!(
        "lights              {} ({} area, {} point)",
        s.lights.lights.len(),
        area,
        s.lights.lights.len() - area
    );
    println!(
        "film                {}x{} {:?}, {} spp",
        s.film.width, s.film.height, s.film.filter, s.sample_count
    );
    let md = s.integrator.max_depth;
    println!(
        "integrator          path, max_depth {}, rr_depth {}",
        if md == u32::MAX {
            "-1 (unbounded)".to_string()
        } else {
            md.to_string()
        },
        s.integrator.rr_depth
    );
    println!(
        "bvh                 {} primitives, built in {:.3} ms, {:.2} MiB",
        s.geometry.primitive_count(),
        s.geometry.build_time.as_secs_f64() * 1e3,
        s.geometry.bvh_bytes() as f64 / (1024.0 * 1024.0)
    );
}

struct RenderJob {
    scene: Scene,
    integrator: IntegratorArg,
    spp: Option<u32>,
    time: Option<f64>,
    seed: u64,
    threads: Option<usize>,
    out: PathBuf,
    scene_name: String,
    quiet: bool,
}

/// The run statistics written beside the image.
#[derive(Serialize)]
struct Sidecar<'a> {
    scene: &'a str,
    integrator: IntegratorArg,
    seconds: f64,
    samples: u64,
    samples_per_second: f64,
    spp: u64,
    width: u32,
    height: u32,
    seed: u64,
    threads: usize,
    max_depth: i64,
    rr_depth: u32,
    interrupted: bool,
    nonfinite_samples: u64,
    bvh_build_seconds: f64,
    triangles: usize,
}

/// Progress bar and periodic previews.
struct CliObserver {
    bar: ProgressBar,
    preview: PathBuf,
    last_preview: Mutex<Instant>,
    budget: Option<Duration>,
    start: Instant,
}

impl RenderObserver for CliObserver {
    fn unit_done(&self, samples: u64) {
        match self.budget {
            Some(b) if self.bar.length() == Some(b.as_millis() as u64) => {
                self.bar.set_position(
                    (self.start.elapsed().as_millis() as u64).min(b.as_millis() as u64),
                );
            }
            _ => self.bar.inc(samples),
        }
    }

    fn pass_done(&self, film: &Film, spp_done: u64, paths_per_pixel: f64) {
        self.bar.set_message(format!("{spp_done} spp"));
        let mut last = self.last_preview.lock().unwrap_or_else(|p| p.into_inner());
        if last.elapsed() >= Duration::from_secs(5) {
            *last = Instant::now();
            let img = film.develop(paths_per_pixel);
            // A failed preview must not stop the render; the final write reports errors.
            let _ = write_png(&self.preview, film.width, film.height, &img);
        }
    }
}

fn do_render(job: RenderJob) -> Result<(), String> {
    let threads = job.threads.unwrap_or_else(|| {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    });
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| format!("cannot start {threads} threads: {e}"))?;
    stop_on_ctrl_c();

    let scene = &job.scene;
    let pixels = scene.film.width as u64 * scene.film.height as u64;
    let integ: Box<dyn Integrator> = match job.integrator {
        IntegratorArg::Pt => Box::new(PathTracer {
            max_depth: scene.integrator.max_depth,
            rr_depth: scene.integrator.rr_depth,
        }),
        IntegratorArg::Lt => Box::new(LightTracer {
            max_depth: scene.integrator.max_depth,
            rr_depth: scene.integrator.rr_depth,
        }),
        IntegratorArg::Pssmlt | IntegratorArg::Mmlt => {
            return Err("pssmlt and mmlt run through mlt_cli".into());
        }
        IntegratorArg::Bdpt => Box::new(Bdpt {
            max_depth: scene.integrator.max_depth,
            rr_depth: scene.integrator.rr_depth,
            heuristic: MisHeuristic::Power,
        }),
    };
    let budget = job.time.map(Duration::from_secs_f64);
    let bar = if job.quiet {
        ProgressBar::hidden()
    } else {
        match (job.spp, budget) {
            (Some(spp), _) => ProgressBar::new(spp as u64 * pixels),
            (None, Some(b)) => ProgressBar::new(b.as_millis() as u64),
            (None, None) => ProgressBar::new(0),
        }
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {wide_bar} {percent:>3}% ETA {eta} {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let png_path = job.out.with_extension("png");
    let json_path = job.out.with_extension("json");
    let observer = CliObserver {
        bar,
        preview: png_path.clone(),
        last_preview: Mutex::new(Instant::now()),
        budget: if job.spp.is_none() { budget } else { None },
        start: Instant::now(),
    };
    let settings = RenderSettings {
        spp: job.spp,
        time_budget: budget,
        seed: job.seed,
    };
    let result = pool.install(|| render(scene, integ.as_ref(), &settings, &STOP, &observer));
    observer.bar.finish_and_clear();

    let image = result.image();
    let (w, h) = (scene.film.width, scene.film.height);
    write_exr(&job.out, w, h, &image)?;
    write_png(&png_path, w, h, &image)?;
    let md = scene.integrator.max_depth;
    let sidecar = Sidecar {
        scene: &job.scene_name,
        integrator: job.integrator,
        seconds: result.seconds,
        samples: result.samples,
        samples_per_second: if result.seconds > 0.0 {
            result.samples as f64 / result.seconds
        } else {
            0.0
        },
        spp: result.spp_done,
        width: w,
        height: h,
        seed: job.seed,
        threads,
        max_depth: if md == u32::MAX { -1 } else { md as i64 },
        rr_depth: scene.integrator.rr_depth,
        interrupted: result.interrupted,
        nonfinite_samples: result.stats.nonfinite,
        bvh_build_seconds: scene.geometry.build_time.as_secs_f64(),
        triangles: scene.geometry.triangles,
    };
    let text = serde_json::to_string_pretty(&sidecar).map_err(|e| e.to_string())?;
    std::fs::write(&json_path, text + "\n")
        .map_err(|e| format!("cannot write {}: {e}", json_path.display()))?;
    if !job.quiet {
        eprintln!(
            "{} spp in {:.2} s ({:.3} M samples/s){} -> {}",
            result.spp_done,
            result.seconds,
            sidecar.samples_per_second / 1e6,
            if result.interrupted {
                ", stopped early"
            } else {
                ""
            },
            job.out.display()
        );
    }
    Ok(())
}
