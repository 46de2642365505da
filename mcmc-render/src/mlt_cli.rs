//! Command-line glue for the Metropolis integrators: the `render` flags of
//! PSSMLT, the run with its JSON statistics and NaN dump, and `--replay`.
//!
//! Kept out of `main.rs` so that the renderer's CLI only needs a few
//! registration lines.

use crate::color::Rgb;
use crate::image_io::{write_exr, write_png};
use crate::integrators::bdpt::{Bdpt, MisHeuristic};
use crate::integrators::pssmlt::{
    DepthAcceptance, MltObserver, MltResult, Normalization, PssmltSettings, render_family,
    render_pssmlt,
};
use crate::integrators::pt::PathTracer;
use crate::pss::{MmltDepth, Mutation, PathSample, PssTarget, SmallStepKind};
use crate::scene::Scene;
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use mcmc_core::rng::stream_rng;
use mcmc_core::space::TorusPoint;
use mcmc_core::target::Evaluation;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// Small-step law on the command line.
#[derive(Clone, Copy, Debug, ValueEnum, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum SmallStepArg {
    /// Kelemen et al. 2002 (s1, s2).
    Kelemen,
    /// pbrt-v4's Gaussian (sigma).
    Gaussian,
    /// Hachisuka & Jensen's adaptive power step.
    Adaptive,
}

/// Normalisation on the command line.
#[derive(Clone, Copy, Debug, ValueEnum, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum NormalizationArg {
    /// b* from the start-up bootstrap (pbrt).
    Bootstrap,
    /// Running estimate over bootstrap and large steps.
    Running,
}

/// The path sampler PSSMLT runs over.
#[derive(Clone, Copy, Debug, ValueEnum, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum MltBase {
    /// Path tracing.
    Pt,
    /// Bidirectional path tracing, all techniques of one sample.
    Bdpt,
}

/// Which Metropolis integrator runs.
#[derive(Clone, Copy, Debug, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum MltKind {
    /// PSSMLT (over `--mlt-base`).
    Pssmlt,
    /// Multiplexed MLT.
    Mmlt,
}

/// Flags of the Metropolis integrators (`render --integrator pssmlt|mmlt`).
#[derive(Args, Clone, Debug)]
pub struct MltArgs {
    /// MLT small step (default: gaussian for mmlt, as pbrt-v4's `mlt`;
    /// kelemen for pssmlt, as Kelemen et al. 2002).
    #[arg(long, value_enum)]
    pub small_step: Option<SmallStepArg>,
    /// Kelemen's smallest step.
    #[arg(long, default_value_t = 1.0 / 1024.0)]
    pub s1: f64,
    /// Kelemen's largest step.
    #[arg(long, default_value_t = 1.0 / 64.0)]
    pub s2: f64,
    /// Gaussian small-step standard deviation.
    #[arg(long, default_value_t = 0.01)]
    pub sigma: f64,
    /// Probability of a large step.
    #[arg(long, default_value_t = 0.3, allow_negative_numbers = true)]
    pub large_step_probability: f64,
    /// Bootstrap candidates for start-up bias elimination and b*.
    #[arg(long, default_value_t = 100_000)]
    pub bootstrap: usize,
    /// Number of Markov chains.
    #[arg(long, default_value_t = 1000)]
    pub chains: usize,
    /// Mutations per pixel (default 100 unless --time is given).
    #[arg(long)]
    pub mutations_per_pixel: Option<u64>,
    /// Kelemen's MIS combination of large steps.
    #[arg(long)]
    pub kelemen_mis: bool,
    /// Image normalisation (default: bootstrap for pssmlt, as pbrt-v4;
    /// running for mmlt, see [`MltArgs::normalization_for`]).
    #[arg(long, value_enum)]
    pub normalization: Option<NormalizationArg>,
    /// Path sampler under PSSMLT.
    #[arg(long, value_enum, default_value = "pt")]
    pub mlt_base: MltBase,
    /// Longest path in segments for pssmlt/mmlt (default: the scene's
    /// max_depth; pbrt-v4's `maxdepth 5` counts bounces, i.e. 6 here).
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// Re-trace one primary-sample vector (a NaN/inf dump) and print it.
    #[arg(long, value_name = "FILE")]
    pub replay: Option<PathBuf>,
}

impl MltArgs {
    /// The small step of `kind` when `--small-step` is not given: MMLT
    /// uses pbrt-v4's Gaussian step. (A lazily updated coordinate that
    /// missed `n` small steps costs one draw with the Gaussian law, but `n`
    /// draws with Kelemen's; MMLT's chains leave many coordinates unread
    /// for long stretches, e.g. the light subpath while `s = 0`.)
    pub fn small_step_for(&self, kind: MltKind) -> SmallStepArg {
        self.small_step.unwrap_or(match kind {
            MltKind::Pssmlt => SmallStepArg::Kelemen,
            MltKind::Mmlt => SmallStepArg::Gaussian,
        })
    }

    /// The normalisation of `kind` when `--normalization` is not given.
    /// MMLT uses the running estimate, which pools the bootstrap's
    /// candidates with every later large step: each depth's `b_d` is
    /// otherwise fixed at start-up, and for a rarely sampled depth its
    /// bootstrap error is large (38% for door-ajar's depth 2 with 100 000
    /// candidates) and never shrinks. On door-ajar at 60 s this lowered
    /// MMLT's relMSE from 0.0063 to 0.0046 (docs/rendering-results.md).
    pub fn normalization_for(&self, kind: MltKind) -> NormalizationArg {
        self.normalization.unwrap_or(match kind {
            MltKind::Pssmlt => NormalizationArg::Bootstrap,
            MltKind::Mmlt => NormalizationArg::Running,
        })
    }

    /// The PSSMLT settings these flags describe.
    pub fn settings(&self, time: Option<f64>, seed: u64) -> Result<PssmltSettings, String> {
        self.settings_for(MltKind::Pssmlt, time, seed)
    }

    /// The settings these flags describe for `kind` (the defaults differ
    /// in the small step, see [`MltArgs::small_step_for`]).
    pub fn settings_for(
        &self,
        kind: MltKind,
        time: Option<f64>,
        seed: u64,
    ) -> Result<PssmltSettings, String> {
        let small = match self.small_step_for(kind) {
            SmallStepArg::Kelemen => SmallStepKind::Kelemen {
                s1: self.s1,
                s2: self.s2,
            },
            SmallStepArg::Gaussian => SmallStepKind::Gaussian { sigma: self.sigma },
            SmallStepArg::Adaptive => SmallStepKind::Adaptive,
        };
        let mutation = Mutation {
            small,
            large_step_probability: self.large_step_probability,
        };
        mutation
            .kernel::<()>()
            .map_err(|e| format!("MLT mutation: {e}"))?;
        if self.chains == 0 {
            return Err("--chains must be at least 1".into());
        }
        if self.bootstrap == 0 {
            return Err("--bootstrap must be at least 1".into());
        }
        if self.mutations_per_pixel == Some(0) {
            return Err("--mutations-per-pixel must be at least 1".into());
        }
        let mutations_per_pixel = match (self.mutations_per_pixel, time) {
            (Some(m), _) => Some(m),
            (None, Some(_)) => None,
            (None, None) => Some(100),
        };
        Ok(PssmltSettings {
            mutation,
            bootstrap: self.bootstrap,
            chains: self.chains,
            mutations_per_pixel,
            time_budget: time.map(Duration::from_secs_f64),
            seed,
            mis_large_steps: self.kelemen_mis,
            normalization: match self.normalization_for(kind) {
                NormalizationArg::Bootstrap => Normalization::Bootstrap,
                NormalizationArg::Running => Normalization::Running,
            },
            ..PssmltSettings::default()
        })
    }
}

/// Acceptance of one kernel component, for the JSON statistics.
#[derive(Serialize)]
struct ComponentJson {
    name: String,
    proposed: u64,
    accepted: u64,
    acceptance: f64,
}

/// One member of the chain family (MMLT: one path depth), for the JSON
/// statistics.
#[derive(Serialize)]
struct FamilyJson {
    /// MMLT: path depth in segments; PSSMLT: 0.
    depth: usize,
    chains: usize,
    mutations: u64,
    b_bootstrap: f64,
    b_bootstrap_standard_error: f64,
    b_running: f64,
    b_running_standard_error: f64,
    scale: f64,
}

/// The run statistics written beside a PSSMLT image.
#[derive(Serialize)]
struct MltSidecar<'a> {
    scene: &'a str,
    integrator: &'static str,
    mlt_base: MltBase,
    seconds: f64,
    bootstrap_seconds: f64,
    mutations: u64,
    mutations_per_second: f64,
    mutations_per_pixel: f64,
    width: u32,
    height: u32,
    seed: u64,
    threads: usize,
    max_depth: i64,
    rr_depth: u32,
    small_step: SmallStepArg,
    large_step_probability: f64,
    bootstrap_candidates: usize,
    chains: usize,
    kelemen_mis: bool,
    normalization: NormalizationArg,
    b_bootstrap: f64,
    b_bootstrap_standard_error: f64,
    b_running: f64,
    b_running_standard_error: f64,
    scale: f64,
    acceptance: f64,
    acceptance_per_component: Vec<ComponentJson>,
    acceptance_per_depth: Vec<DepthAcceptance>,
    families: Vec<FamilyJson>,
    nonfinite_contributions: u64,
    nonfinite_bootstrap_candidates: usize,
    nonfinite_dump: Option<String>,
    interrupted: bool,
}

struct CliMltObserver {
    bar: ProgressBar,
    preview: PathBuf,
    width: u32,
    height: u32,
    budget: Option<Duration>,
    start: Instant,
    lock: Mutex<()>,
}

impl MltObserver for CliMltObserver {
    fn mutations_done(&self, n: u64) {
        match self.budget {
            Some(b) => self
                .bar
                .set_position((self.start.elapsed().as_millis() as u64).min(b.as_millis() as u64)),
            None => self.bar.inc(n),
        }
    }

    fn preview(&self, image: &[Rgb], mutations: u64) {
        let _g = self.lock.lock().unwrap_or_else(|p| p.into_inner());
        self.bar.set_message(format!("{mutations} mutations"));
        // A failed preview must not stop the render; the final write reports errors.
        let _ = write_png(&self.preview, self.width, self.height, image);
    }
}

/// Everything a PSSMLT run from the command line needs.
pub struct MltJob<'a> {
    /// The loaded scene.
    pub scene: &'a Scene,
    /// Its name for the statistics.
    pub scene_name: &'a str,
    /// The flags.
    pub args: &'a MltArgs,
    /// PSSMLT or MMLT.
    pub kind: MltKind,
    /// Time budget in seconds.
    pub time: Option<f64>,
    /// Seed.
    pub seed: u64,
    /// Worker threads.
    pub threads: usize,
    /// Output EXR (PNG, JSON and NaN dump beside it).
    pub out: &'a Path,
    /// No progress bar.
    pub quiet: bool,
}

/// Runs PSSMLT over the path tracer and writes the image, preview,
/// statistics and (if any) the primary-sample vector of the first NaN/inf
/// contribution (`<out>.nonfinite.pss`, for `--replay`).
pub fn run_pssmlt(job: &MltJob<'_>, stop: &AtomicBool) -> Result<MltResult, String> {
    let scene = job.scene;
    let settings = job.args.settings_for(job.kind, job.time, job.seed)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(job.threads)
        .build()
        .map_err(|e| format!("cannot start {} threads: {e}", job.threads))?;
    let (w, h) = (scene.film.width, scene.film.height);
    let bar = if job.quiet {
        ProgressBar::hidden()
    } else {
        match (settings.mutations_per_pixel, settings.time_budget) {
            (Some(m), _) => ProgressBar::new(m * w as u64 * h as u64),
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
    let observer = CliMltObserver {
        bar,
        preview: png_path.clone(),
        width: w,
        height: h,
        budget: if settings.mutations_per_pixel.is_none() {
            settings.time_budget
        } else {
            None
        },
        start: Instant::now(),
        lock: Mutex::new(()),
    };
    let max_depth = job.args.max_depth.unwrap_or(scene.integrator.max_depth);
    let rr_depth = scene.integrator.rr_depth;
    let bdpt = Bdpt {
        max_depth,
        rr_depth,
        heuristic: MisHeuristic::Power,
    };
    let result = match (job.kind, job.args.mlt_base) {
        (MltKind::Pssmlt, MltBase::Pt) => {
            let pt = PathTracer {
                max_depth,
                rr_depth,
            };
            pool.install(|| render_pssmlt(scene, pt, &settings, stop, &observer))
        }
        (MltKind::Pssmlt, MltBase::Bdpt) => {
            pool.install(|| render_pssmlt(scene, bdpt, &settings, stop, &observer))
        }
        (MltKind::Mmlt, _) => {
            if max_depth == u32::MAX || max_depth == 0 {
                return Err("mmlt needs a finite max_depth ≥ 1 (give --max-depth)".into());
            }
            let depths: Vec<MmltDepth> = (1..=max_depth as usize)
                .map(|depth| MmltDepth { bdpt, depth })
                .collect();
            pool.install(|| render_family(scene, depths, &settings, stop, &observer))
        }
    }
    .map_err(|e| e.to_string())?;
    observer.bar.finish_and_clear();

    let image = result.image();
    write_exr(job.out, w, h, &image)?;
    write_png(&png_path, w, h, &image)?;
    let dump = match &result.first_nonfinite {
        Some(v) => {
            let path = job.out.with_extension("nonfinite.pss");
            let sampler = match (job.kind, job.args.mlt_base) {
                (MltKind::Pssmlt, MltBase::Pt) => DumpSampler::Pt,
                (MltKind::Pssmlt, MltBase::Bdpt) => DumpSampler::Bdpt,
                (MltKind::Mmlt, _) => DumpSampler::Mmlt,
            };
            let dump = PssDump {
                sampler,
                max_depth: Some(max_depth),
                coords: v.clone(),
            };
            write_pss(&path, &dump)?;
            Some(path.display().to_string())
        }
        None => None,
    };
    let cs = &result.chain_stats;
    let sidecar = MltSidecar {
        scene: job.scene_name,
        integrator: match job.kind {
            MltKind::Pssmlt => "pssmlt",
            MltKind::Mmlt => "mmlt",
        },
        mlt_base: job.args.mlt_base,
        seconds: result.seconds,
        bootstrap_seconds: result.bootstrap_seconds,
        mutations: result.mutations,
        mutations_per_second: rate(result.mutations, result.seconds - result.bootstrap_seconds),
        mutations_per_pixel: result.mutations_per_pixel,
        width: w,
        height: h,
        seed: job.seed,
        threads: job.threads,
        max_depth: if max_depth == u32::MAX {
            -1
        } else {
            max_depth as i64
        },
        rr_depth: scene.integrator.rr_depth,
        small_step: job.args.small_step_for(job.kind),
        large_step_probability: settings.mutation.large_step_probability,
        bootstrap_candidates: settings.bootstrap,
        chains: settings.chains,
        kelemen_mis: settings.mis_large_steps,
        normalization: job.args.normalization_for(job.kind),
        b_bootstrap: result.bootstrap_b.0,
        b_bootstrap_standard_error: result.bootstrap_b.1,
        b_running: result.running_b.0,
        b_running_standard_error: result.running_b.1,
        scale: result.scale,
        acceptance: cs.acceptance_rate(),
        acceptance_per_component: cs
            .components
            .iter()
            .map(|c| ComponentJson {
                name: c.name.clone(),
                proposed: c.proposed,
                accepted: c.accepted,
                acceptance: c.acceptance_rate(),
            })
            .collect(),
        acceptance_per_depth: result.per_depth.clone(),
        families: result
            .families
            .iter()
            .enumerate()
            .map(|(d, f)| FamilyJson {
                depth: match job.kind {
                    MltKind::Pssmlt => 0,
                    MltKind::Mmlt => d + 1,
                },
                chains: f.chains,
                mutations: f.mutations,
                b_bootstrap: f.bootstrap_b.0,
                b_bootstrap_standard_error: f.bootstrap_b.1,
                b_running: f.running_b.0,
                b_running_standard_error: f.running_b.1,
                scale: f.scale,
            })
            .collect(),
        nonfinite_contributions: cs.invalid_density,
        nonfinite_bootstrap_candidates: result.bootstrap_invalid,
        nonfinite_dump: dump,
        interrupted: result.interrupted,
    };
    let json_path = job.out.with_extension("json");
    let text = serde_json::to_string_pretty(&sidecar).map_err(|e| e.to_string())?;
    std::fs::write(&json_path, text + "\n")
        .map_err(|e| format!("cannot write {}: {e}", json_path.display()))?;
    if !job.quiet {
        eprintln!(
            "{} mutations in {:.2} s ({:.3} M mutations/s, bootstrap {:.2} s), b* = {:.5} ± {:.5}{} -> {}",
            result.mutations,
            result.seconds,
            sidecar.mutations_per_second / 1e6,
            result.bootstrap_seconds,
            result.bootstrap_b.0,
            result.bootstrap_b.1,
            if result.interrupted {
                ", stopped early"
            } else {
                ""
            },
            job.out.display()
        );
    }
    Ok(result)
}

fn rate(n: u64, seconds: f64) -> f64 {
    if seconds > 0.0 {
        n as f64 / seconds
    } else {
        0.0
    }
}

/// The path sampler a primary-sample dump was traced with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DumpSampler {
    /// PSSMLT over the path tracer.
    Pt,
    /// PSSMLT over BDPT (all techniques of one sample).
    Bdpt,
    /// Multiplexed MLT (one target per path depth).
    Mmlt,
}

impl DumpSampler {
    fn name(self) -> &'static str {
        match self {
            DumpSampler::Pt => "pt",
            DumpSampler::Bdpt => "bdpt",
            DumpSampler::Mmlt => "mmlt",
        }
    }
}

/// A dumped primary-sample vector and what it must be replayed with.
#[derive(Clone, Debug, PartialEq)]
pub struct PssDump {
    /// The path sampler of the run.
    pub sampler: DumpSampler,
    /// The run's longest path in segments (`None`: the scene's).
    pub max_depth: Option<u32>,
    /// The coordinates, in `[0, 1)`.
    pub coords: Vec<f64>,
}

/// Writes a primary-sample dump: `# sampler` and `# max_depth` header
/// lines, then one coordinate per line (shortest round-trip decimal form).
pub fn write_pss(path: &Path, dump: &PssDump) -> Result<(), String> {
    let mut text = String::from("# mcmc-render primary-sample vector (one coordinate per line)\n");
    text.push_str(&format!("# sampler {}\n", dump.sampler.name()));
    if let Some(d) = dump.max_depth {
        text.push_str(&format!("# max_depth {d}\n"));
    }
    for c in &dump.coords {
        text.push_str(&format!("{c:?}\n"));
    }
    std::fs::write(path, text).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// Reads a file written by [`write_pss`]. A file without a `# sampler`
/// line is taken as a path-tracer dump at the scene's depth.
pub fn read_pss(path: &Path) -> Result<PssDump, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let mut dump = PssDump {
        sampler: DumpSampler::Pt,
        max_depth: None,
        coords: Vec::new(),
    };
    for (n, line) in text.lines().enumerate() {
        let t = line.trim();
        let at = || format!("{}:{}", path.display(), n + 1);
        if let Some(comment) = t.strip_prefix('#') {
            let comment = comment.trim();
            if let Some(name) = comment.strip_prefix("sampler ") {
                dump.sampler = match name.trim() {
                    "pt" => DumpSampler::Pt,
                    "bdpt" => DumpSampler::Bdpt,
                    "mmlt" => DumpSampler::Mmlt,
                    other => {
                        return Err(format!(
                            "{}: unknown sampler `{other}` (pt, bdpt or mmlt)",
                            at()
                        ));
                    }
                };
            } else if let Some(d) = comment.strip_prefix("max_depth ") {
                let d: u32 = d
                    .trim()
                    .parse()
                    .map_err(|_| format!("{}: max_depth is not a count: {}", at(), d.trim()))?;
                dump.max_depth = Some(d);
            }
            continue;
        }
        if t.is_empty() {
            continue;
        }
        let v: f64 = t
            .parse()
            .map_err(|_| format!("{}: not a number: {t}", at()))?;
        if !(0.0..1.0).contains(&v) {
            return Err(format!("{}: coordinate {v} is outside [0, 1)", at()));
        }
        dump.coords.push(v);
    }
    if dump.coords.is_empty() {
        return Err(format!("{}: no coordinates", path.display()));
    }
    Ok(dump)
}

/// Re-traces the path of a dumped primary-sample vector with the sampler
/// recorded in the dump and prints what it contributes. Coordinates beyond
/// the file are drawn from a fixed seed (a NaN path reads only dumped
/// ones). An MMLT dump does not record the path depth of its chain, so it
/// is traced at every depth.
pub fn replay(scene: &Scene, file: &Path) -> Result<(), String> {
    let dump = read_pss(file)?;
    let coords = &dump.coords;
    let point = TorusPoint::from_values(coords, stream_rng(0, 0));
    let max_depth = dump.max_depth.unwrap_or(scene.integrator.max_depth);
    let rr_depth = scene.integrator.rr_depth;
    let bdpt = Bdpt {
        max_depth,
        rr_depth,
        heuristic: MisHeuristic::Power,
    };
    println!("sampler             {}", dump.sampler.name());
    let evals: Vec<(Option<usize>, Evaluation<PathSample>)> = match dump.sampler {
        DumpSampler::Pt => {
            let sampler = PathTracer {
                max_depth,
                rr_depth,
            };
            vec![(None, PssTarget { scene, sampler }.trace(&point))]
        }
        DumpSampler::Bdpt => vec![(
            None,
            PssTarget {
                scene,
                sampler: bdpt,
            }
            .trace(&point),
        )],
        DumpSampler::Mmlt => {
            if max_depth == u32::MAX || max_depth == 0 {
                return Err(format!(
                    "{}: an mmlt dump needs a finite max_depth ≥ 1",
                    file.display()
                ));
            }
            (1..=max_depth as usize)
                .map(|depth| {
                    let sampler = MmltDepth { bdpt, depth };
                    (Some(depth), PssTarget { scene, sampler }.trace(&point))
                })
                .collect()
        }
    };
    println!(
        "coordinates read    {} (file has {})",
        point.len(),
        coords.len()
    );
    for (target_depth, e) in &evals {
        if let Some(d) = target_depth {
            println!("mmlt depth          {d}");
        }
        println!("depth               {}", e.payload.depth);
        println!("ln I                {}", e.log_density);
        // PssTarget maps a NaN or infinite contribution to ln I = NaN.
        println!(
            "contribution        {}",
            if e.log_density.is_nan() {
                "non-finite"
            } else if e.log_density == f64::NEG_INFINITY {
                "zero"
            } else {
                "finite"
            }
        );
        for s in &e.payload.splats {
            println!(
                "splat               raster ({}, {})  L = ({}, {}, {})",
                s.p.x, s.p.y, s.l.r, s.l.g, s.l.b
            );
        }
    }
    Ok(())
}

/// Splits an integrator name of the `convergence` command,
/// `BASE[+MODIFIER]...` (e.g. `mmlt+running+mis`), into the base name and
/// the MLT settings its modifiers give, so that variants of one
/// integrator can be compared within one run. Modifiers: `running` or
/// `bootstrap` (normalisation), `mis` (Kelemen's MIS of large steps),
/// `kelemen` (s1 = 1/1024, s2 = 1/64) or `gaussian` (sigma 0.01) or
/// `sigma=S` (Gaussian) small step, `plarge=P`, `chains=N`, `candidates=N` (bootstrap
/// candidates), `alloc=G` (chains per depth `∝ b_d^G`).
pub fn mlt_variant(name: &str, base: &PssmltSettings) -> Result<(String, PssmltSettings), String> {
    let mut parts = name.split('+');
    let head = parts.next().unwrap_or_default().to_string();
    let mut s = base.clone();
    for m in parts {
        let (key, value) = match m.split_once('=') {
            Some((k, v)) => (k, Some(v)),
            None => (m, None),
        };
        let number = |what: &str| -> Result<f64, String> {
            value
                .and_then(|v| v.parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("modifier `{m}` of `{name}` needs a number ({what})"))
        };
        let count = |what: &str| -> Result<usize, String> {
            value
                .and_then(|v| v.parse::<usize>().ok())
                .filter(|&v| v > 0)
                .ok_or_else(|| {
                    format!("modifier `{m}` of `{name}` needs a positive integer ({what})")
                })
        };
        match key {
            "running" => s.normalization = Normalization::Running,
            "bootstrap" => s.normalization = Normalization::Bootstrap,
            "mis" => s.mis_large_steps = true,
            "kelemen" => {
                s.mutation.small = SmallStepKind::Kelemen {
                    s1: 1.0 / 1024.0,
                    s2: 1.0 / 64.0,
                }
            }
            "gaussian" => s.mutation.small = SmallStepKind::Gaussian { sigma: 0.01 },
            "sigma" => {
                s.mutation.small = SmallStepKind::Gaussian {
                    sigma: number("the Gaussian small step's sigma")?,
                }
            }
            "plarge" => s.mutation.large_step_probability = number("large-step probability")?,
            "chains" => s.chains = count("chains")?,
            "alloc" => s.depth_allocation_exponent = number("depth allocation exponent")?,
            "candidates" => s.bootstrap = count("bootstrap candidates")?,
            _ => {
                return Err(format!(
                    "unknown modifier `{m}` in `{name}` (known: running, bootstrap, mis, kelemen, gaussian, sigma=S, plarge=P, chains=N, candidates=N, alloc=G)"
                ));
            }
        }
    }
    s.mutation
        .kernel::<()>()
        .map_err(|e| format!("`{name}`: {e}"))?;
    Ok((head, s))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variant_modifiers_set_the_settings() {
        let base = PssmltSettings::default();
        let (name, s) = mlt_variant(
            "mmlt+running+mis+plarge=0.1+chains=10+candidates=50+alloc=0.5",
            &base,
        )
        .expect("valid variant");
        assert_eq!(name, "mmlt");
        assert_eq!(s.normalization, Normalization::Running);
        assert!(s.mis_large_steps);
        assert_eq!(s.mutation.large_step_probability, 0.1);
        assert_eq!((s.chains, s.bootstrap), (10, 50));
        assert_eq!(s.depth_allocation_exponent, 0.5);
        let (_, g) = mlt_variant("pssmlt+sigma=0.02", &base).expect("valid variant");
        assert_eq!(g.mutation.small, SmallStepKind::Gaussian { sigma: 0.02 });
        let (plain, same) = mlt_variant("pt", &base).expect("no modifiers");
        assert_eq!(plain, "pt");
        assert_eq!(same.chains, base.chains);
        for bad in [
            "mmlt+fast",
            "mmlt+plarge=x",
            "mmlt+plarge=2",
            "mmlt+chains=0",
            "mmlt+sigma=inf",
        ] {
            assert!(mlt_variant(bad, &base).is_err(), "{bad} accepted");
        }
    }

    #[test]
    fn mmlt_defaults_to_the_gaussian_small_step_and_running_normalisation() {
        use clap::Parser;
        #[derive(Parser)]
        struct Cli {
            #[command(flatten)]
            mlt: MltArgs,
        }
        let cli = Cli::parse_from(["x"]);
        let m = cli
            .mlt
            .settings_for(MltKind::Mmlt, None, 0)
            .expect("defaults are valid");
        assert_eq!(m.mutation.small, SmallStepKind::Gaussian { sigma: 0.01 });
        assert_eq!(m.normalization, Normalization::Running);
        assert_eq!(m.mutation.large_step_probability, 0.3);
        assert_eq!(
            (m.bootstrap, m.chains, m.mutations_per_pixel),
            (100_000, 1000, Some(100))
        );
        let p = cli.mlt.settings(None, 0).expect("defaults are valid");
        assert!(matches!(p.mutation.small, SmallStepKind::Kelemen { .. }));
        assert_eq!(p.normalization, Normalization::Bootstrap);
        let k = Cli::parse_from([
            "x",
            "--small-step",
            "kelemen",
            "--normalization",
            "bootstrap",
        ]);
        let m = k.mlt.settings_for(MltKind::Mmlt, None, 0).expect("valid");
        assert!(matches!(m.mutation.small, SmallStepKind::Kelemen { .. }));
        assert_eq!(m.normalization, Normalization::Bootstrap);
    }
}
