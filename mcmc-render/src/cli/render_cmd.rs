//! `render` (and the no-argument default render): choose and configure the
//! integrator, run it with a progress bar, write EXR, PNG, JSON sidecar and
//! the NaN dump; `--replay` re-traces a dump.

use super::progress::CliObserver;
use super::stdout::{Failure, err, out};
use super::{ParamFlags, STOP, check_writable, parse_defines, stop_on_ctrl_c, thread_count};
use crate::image_io::{write_exr, write_png};
use crate::integrators::registry::{self, Configured};
use crate::integrators::{Rendered, RunSettings};
use crate::pss_dump::{read_pss, replay, write_pss};
use crate::scene::Scene;
use clap::Args;
use serde_json::{Map, Value, json};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

/// The embedded default scene.
const DEFAULT_SCENE: &str = include_str!("../../scenes/default.xml");

/// Flags of `render`.
#[derive(Args)]
pub struct RenderArgs {
    /// Mitsuba 3 XML scene.
    scene: PathBuf,
    /// Integrator (default: the scene's `<integrator>`, else pt); `mcmc-render integrators` lists them.
    #[arg(long)]
    integrator: Option<String>,
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
    /// Re-trace one primary-sample vector (a NaN/inf dump) and print it.
    #[arg(long, value_name = "FILE")]
    replay: Option<PathBuf>,
    /// Save progress to FILE after every pass (pt, lt, bdpt, erpt, vcm, and
    /// guided's last iteration) or round
    /// (pssmlt, mmlt, tempered-pssmlt, tempered-mmlt, relt, pre-trained
    /// mcmc-pg) and, if FILE
    /// exists, continue from it (docs/distributed.md).
    #[arg(long, value_name = "FILE")]
    checkpoint: Option<PathBuf>,
    #[command(flatten)]
    params: ParamFlags,
}

/// One render as the command line runs it.
struct Job<'a> {
    scene: &'a Scene,
    scene_name: &'a str,
    integrator: &'a dyn Configured,
    run: RunSettings,
    threads: usize,
    out: &'a Path,
    quiet: bool,
}

/// `mcmc-render` with no arguments: the embedded scene with its integrator.
pub fn default_scene() -> Result<(), String> {
    let scene = Scene::load_str(DEFAULT_SCENE, Path::new("<default scene>"), Path::new("."))
        .map_err(|e| e.to_string())?;
    let integrator = registry::configure(scene.integrator_element.as_ref(), None, &[])?;
    render_job(&Job {
        scene: &scene,
        scene_name: "<default scene>",
        integrator: integrator.as_ref(),
        run: RunSettings {
            spp: Some(scene.sample_count),
            ..RunSettings::default()
        },
        threads: thread_count(None)?,
        out: Path::new("render.exr"),
        quiet: false,
    })
}

/// `mcmc-render render …`.
pub fn run(args: RenderArgs) -> Result<(), Failure> {
    let spp = match args.spp {
        Some(n) if n <= 0 => {
            return Err(format!("--spp must be a positive integer, got {n}").into());
        }
        Some(n) => Some(u32::try_from(n).map_err(|_| format!("--spp {n} is too large"))?),
        None => None,
    };
    let time_budget = match args.time {
        Some(t) if !(t > 0.0 && t.is_finite()) => {
            return Err(format!("--time must be a positive number of seconds, got {t}").into());
        }
        Some(t) => {
            Some(Duration::try_from_secs_f64(t).map_err(|_| format!("--time {t:e} is too large"))?)
        }
        None => None,
    };
    let threads = thread_count(args.threads)?;
    let defines = parse_defines(&args.define)?;
    if let Some(file) = &args.replay {
        // Replay writes nothing: no output check.
        let scene = Scene::load(&args.scene, &defines).map_err(|e| e.to_string())?;
        return print_replay(&scene, file);
    }
    // Under `mpirun` (feature `mpi`) every rank sets up alone, then all
    // agree (`distributed::agree_on_inputs`) before any renders.
    #[cfg(feature = "mpi")]
    let session = crate::distributed::start()?;
    let setup = || -> Result<_, String> {
        if crate::cluster::is_root() {
            check_writable(&args.out, "exr")?;
        }
        let scene = Scene::load(&args.scene, &defines).map_err(|e| e.to_string())?;
        // The per-pixel driver's film, its light-path films and the image.
        let (w, h) = (scene.film.width, scene.film.height);
        crate::resources::check_memory(
            &format!("film {w}×{h}"),
            crate::resources::film_bytes(w, h, 10),
        )?;
        let integrator = registry::configure(
            scene.integrator_element.as_ref(),
            args.integrator.as_deref(),
            &args.params.assignments()?,
        )?;
        let checkpoint = match &args.checkpoint {
            Some(path) => {
                let run = RunSettings {
                    spp,
                    time_budget,
                    ..RunSettings::default()
                };
                let budget = run.samples_per_pixel(scene.sample_count).map(u64::from);
                Some(open_checkpoint(
                    path,
                    &scene,
                    &args,
                    &defines,
                    integrator.as_ref(),
                    budget,
                )?)
            }
            None => None,
        };
        Ok((scene, integrator, checkpoint))
    };
    #[cfg(not(feature = "mpi"))]
    let (scene, integrator, checkpoint) = setup()?;
    #[cfg(feature = "mpi")]
    let (scene, integrator, checkpoint) = {
        let inputs = setup().map(|(scene, integ, checkpoint)| {
            let mut parts = input_parts(&args, &defines, integ.as_ref());
            parts.push(format!("{spp:?} {time_budget:?}"));
            ((scene, integ, checkpoint), parts)
        });
        match crate::distributed::agree_on_inputs(inputs) {
            Ok(v) => v,
            // Rank 0 reports another rank's failure; that rank reports its
            // own. Printed before MPI ends: once a rank exits non-zero,
            // `mpirun` kills the others, and a message printed after
            // `MPI_Finalize` (as `main` prints) could be lost (stop 50).
            Err((e, own)) => {
                if own || crate::cluster::is_root() {
                    err!("error: {e}");
                }
                drop(session);
                std::process::exit(1);
            }
        }
    };
    let rendered = render_job(&Job {
        scene: &scene,
        scene_name: &args.scene.display().to_string(),
        integrator: integrator.as_ref(),
        run: RunSettings {
            spp,
            time_budget,
            seed: args.seed,
            checkpoint,
            ..RunSettings::default()
        },
        threads,
        out: &args.out,
        quiet: args.quiet,
    });
    // As above: the error is printed while every rank is still running.
    #[cfg(feature = "mpi")]
    if let Err(e) = &rendered {
        err!("error: {e}");
        drop(session);
        std::process::exit(1);
    }
    Ok(rendered?)
}

/// What makes the image (scene file text, defines, integrator, its
/// settings, seed), as text: what a checkpoint and the ranks of a
/// distributed run must agree on.
fn input_parts(
    args: &RenderArgs,
    defines: &std::collections::HashMap<String, String>,
    integrator: &dyn Configured,
) -> Vec<String> {
    vec![
        std::fs::read_to_string(&args.scene).unwrap_or_default(),
        // Sorted: a hash map's order differs between processes.
        format!(
            "{:?}",
            defines.iter().collect::<std::collections::BTreeMap<_, _>>()
        ),
        integrator.name().to_string(),
        Value::Object(integrator.settings_json()).to_string(),
        args.seed.to_string(),
    ]
}

/// The checkpoint of `--checkpoint path`: for the integrators that can
/// be checkpointed only (the per-pixel ones and some on the Markov-chain
/// driver), tied to the scene text, defines, integrator, settings and
/// seed; rank 0 loads the progress it holds, if any (one line when it
/// belongs to another render). `budget`: the run's samples per pixel
/// (`None`: a time budget alone), which `guided`'s schedule follows.
fn open_checkpoint(
    path: &Path,
    scene: &Scene,
    args: &RenderArgs,
    defines: &std::collections::HashMap<String, String>,
    integrator: &dyn Configured,
    budget: Option<u64>,
) -> Result<crate::checkpoint::Checkpoint, String> {
    use crate::checkpoint::{
        CHAIN_INTEGRATORS, Checkpoint, INTEGRATORS, OWN_FORMAT_INTEGRATORS, fingerprint, load,
    };
    let name = integrator.name();
    let chains = CHAIN_INTEGRATORS.contains(&name);
    let own_format = OWN_FORMAT_INTEGRATORS.contains(&name);
    if !INTEGRATORS.contains(&name) && !chains && !own_format {
        return Err(format!(
            "--checkpoint: {name} cannot be checkpointed yet (only {}, {}, {})",
            INTEGRATORS.join(", "),
            CHAIN_INTEGRATORS.join(", "),
            OWN_FORMAT_INTEGRATORS.join(", ")
        ));
    }
    if name == "guided" && budget.is_none() {
        return Err(
            "--checkpoint: guided needs a sample budget (--spp): a time budget alone sets its iterations by the clock, so a resumed run could not repeat them"
                .into(),
        );
    }
    if let Some(output) = shares_an_output(path, &args.out) {
        return Err(format!(
            "--checkpoint {} is the path of an output ({output}); give it its own name, such as {}",
            path.display(),
            args.out.with_extension("ckpt").display()
        ));
    }
    let fingerprint = fingerprint(&input_parts(args, defines, integrator));
    let size = (scene.film.width, scene.film.height);
    let mut checkpoint = Checkpoint {
        path: path.to_path_buf(),
        fingerprint,
        resume: None,
        chains: None,
    };
    if crate::cluster::is_root() {
        if own_format {
            // `smcmc` reads its file when it starts (rank 0, then a
            // broadcast); checked here too, before the ranks' handshake,
            // so that a bad file stops every rank with one line.
            crate::smcmc::checkpoint::load(path, fingerprint, size)?;
        } else if chains {
            let filter = Arc::new(crate::film::Filter::new(scene.film.filter, size.0, size.1));
            checkpoint.chains =
                crate::markov::checkpoint::load(path, fingerprint, size, &filter)?.map(Arc::new);
        } else {
            checkpoint.resume = load(path, fingerprint, size)?.map(Arc::new);
            // The integrators' own words, checked here, before the ranks'
            // handshake, so that a bad file stops every rank with one error.
            if let Some(p) = &checkpoint.resume {
                let checked = match name {
                    "erpt" => crate::integrators::erpt::check_checkpoint(p),
                    "vcm" => crate::integrators::vcm::check_checkpoint(p),
                    "guided" => crate::integrators::guided::check_checkpoint(p, budget),
                    "mcmc-vcm" => crate::integrators::mcmc_vcm::check_checkpoint(
                        p,
                        integrator.as_any(),
                        scene,
                    ),
                    _ => Ok(()),
                };
                checked.map_err(|e| format!("checkpoint {}: {e}", path.display()))?;
            }
        }
    }
    Ok(checkpoint)
}

/// Which of the outputs `render --out out` writes (the EXR, its PNG
/// preview, JSON sidecar, `NAME.exr` layers and NaN dump, all named after
/// `out`) `checkpoint` would overwrite, if any. Paths are compared made
/// absolute (not resolving links).
fn shares_an_output(checkpoint: &Path, out: &Path) -> Option<&'static str> {
    let abs = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let (ck, out) = (abs(checkpoint), abs(out));
    let named = [
        ("the image", out.clone()),
        ("the PNG preview", out.with_extension("png")),
        ("the JSON sidecar", out.with_extension("json")),
        ("the NaN dump", out.with_extension("nonfinite.pss")),
    ];
    if let Some((what, _)) = named.iter().find(|(_, p)| *p == ck) {
        return Some(what);
    }
    // Layers: `stem.NAME.exr` beside the image.
    let stem = out.file_stem()?.to_str()?;
    let is_layer = ck.parent() == out.parent()
        && ck.extension().is_some_and(|e| e == "exr")
        && ck
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with(&format!("{stem}.")));
    is_layer.then_some("an image layer")
}

fn render_job(job: &Job<'_>) -> Result<(), String> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(job.threads)
        .build()
        .map_err(|e| format!("cannot start {} threads: {e}", job.threads))?;
    stop_on_ctrl_c();
    let scene = job.scene;
    let (w, h) = (scene.film.width, scene.film.height);
    let png = job.out.with_extension("png");
    let cli_observer = CliObserver::new(
        job.integrator.planned_samples(scene, &job.run),
        job.run.time_budget,
        job.quiet,
        png.clone(),
        (w, h),
    );
    // In a distributed run only rank 0 shows progress and writes files.
    let root = crate::cluster::is_root();
    let observer: &dyn crate::observer::Observer = match root {
        true => &cli_observer,
        false => &crate::observer::NoObserver,
    };
    let result = pool.install(|| job.integrator.render(scene, &job.run, &STOP, observer));
    cli_observer.finish();
    let rendered = result.map_err(|e| e.to_string())?;
    if !root {
        return Ok(());
    }
    if let Some(e) = rendered
        .statistics
        .get("checkpoint")
        .and_then(|c| c["error"].as_str())
    {
        err!("warning: the checkpoint was not saved: {e}");
    }
    write_exr(job.out, w, h, &rendered.image)?;
    write_png(&png, w, h, &rendered.image)?;
    for (name, image) in &rendered.layers {
        write_exr(&job.out.with_extension(format!("{name}.exr")), w, h, image)?;
    }
    let dump = match &rendered.nonfinite_dump {
        Some(d) => {
            let path = job.out.with_extension("nonfinite.pss");
            write_pss(&path, d)?;
            Some(path.display().to_string())
        }
        None => None,
    };
    let json_path = job.out.with_extension("json");
    let text =
        serde_json::to_string_pretty(&sidecar(job, &rendered, dump)).map_err(|e| e.to_string())?;
    mcmc_core::checkpoint::write_bytes(&json_path, (text + "\n").as_bytes())?;
    if !job.quiet {
        err!("{} -> {}", rendered.summary, job.out.display());
    }
    Ok(())
}

/// The run statistics written beside the image: what ran (scene,
/// integrator, its settings, budget), then the integrator's statistics.
fn sidecar(job: &Job<'_>, r: &Rendered, dump: Option<String>) -> Value {
    let mut m = Map::new();
    let scene = job.scene;
    m.insert("scene".into(), json!(job.scene_name));
    m.insert("integrator".into(), json!(job.integrator.name()));
    m.insert("seconds".into(), json!(r.seconds));
    m.insert("samples".into(), json!(r.samples));
    m.insert("width".into(), json!(scene.film.width));
    m.insert("height".into(), json!(scene.film.height));
    m.insert("seed".into(), json!(job.run.seed));
    m.insert("threads".into(), json!(job.threads));
    m.insert(
        "time_budget".into(),
        json!(job.run.time_budget.map(|b| b.as_secs_f64())),
    );
    m.insert("interrupted".into(), json!(r.interrupted));
    m.insert("image_hash".into(), json!(image_hash(&r.image)));
    m.extend(r.statistics.clone());
    m.insert("nonfinite_dump".into(), json!(dump));
    m.insert(
        "settings".into(),
        Value::Object(job.integrator.settings_json()),
    );
    Value::Object(m)
}

/// A hash of the image's bits (hex), to check that two runs made the same
/// image (the EXR files of equal images can differ: blocks are compressed
/// in parallel and written in the order they finish).
fn image_hash(image: &[crate::color::Rgb]) -> String {
    use std::hash::{DefaultHasher, Hasher};
    let mut h = DefaultHasher::new();
    for p in image {
        for c in [p.r, p.g, p.b] {
            h.write_u32(c.to_bits());
        }
    }
    format!("{:016x}", h.finish())
}

/// Re-traces a dump and prints what its path contributes.
fn print_replay(scene: &Scene, file: &Path) -> Result<(), Failure> {
    let dump = read_pss(file)?;
    let r = replay(scene, &dump).map_err(|e| format!("{}: {e}", file.display()))?;
    out!("sampler             {}", dump.sampler.name())?;
    out!(
        "coordinates read    {} (file has {})",
        r.coordinates_read,
        dump.coords.len()
    )?;
    for t in &r.traces {
        let e = &t.evaluation;
        if let Some(d) = t.target_depth {
            out!("mmlt depth          {d}")?;
        }
        out!("depth               {}", e.payload.depth)?;
        out!("ln I                {}", e.log_density)?;
        // PssTarget maps a NaN or infinite contribution to ln I = NaN.
        out!(
            "contribution        {}",
            if e.log_density.is_nan() {
                "non-finite"
            } else if e.log_density == f64::NEG_INFINITY {
                "zero"
            } else {
                "finite"
            }
        )?;
        for s in &e.payload.splats {
            out!(
                "splat               raster ({}, {})  L = ({}, {}, {})",
                s.p.x,
                s.p.y,
                s.l.r,
                s.l.g,
                s.l.b
            )?;
        }
    }
    Ok(())
}
