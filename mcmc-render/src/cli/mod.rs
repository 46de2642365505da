//! The `mcmc-render` command line: argument parsing, progress bars, file
//! naming and the subcommands. The library never depends on this module.
//!
//! - `mcmc-render`: renders the embedded default scene to `render.exr` and `render.png`.
//! - `mcmc-render render SCENE.xml [--integrator NAME] [--set NAME=VALUE]… [--spp N | --time S]
//!   [--seed K] [--threads T] [--out FILE.exr] [-D name=value]…`: the integrator is the
//!   flag's, else the scene's `<integrator>`, else `pt`
//! - `mcmc-render render SCENE.xml --replay DUMP.pss`: re-trace a NaN/inf
//!   primary-sample dump of `pssmlt` or `mmlt`
//! - `mcmc-render convergence SCENE.xml --reference REF.exr [--integrators …]
//!   [--time S] [--checkpoints K] [--out FILE.csv]`, or `convergence --replot FILE.csv`
//! - `mcmc-render compare REF.exr TEST.exr [--json]`
//!   (`compare` and `convergence` also take the reference's own noise:
//!   `--reference-variance VAR.exr --reference-spp N` or `--second-reference R2.exr`)
//! - `mcmc-render info SCENE.xml`
//! - `mcmc-render integrators`: every integrator with its parameters and defaults
//!
//! Ctrl-C (SIGINT) during `render` stops early and writes what was rendered
//! so far (normalised by it), with `"interrupted": true` in the JSON, and
//! exits with status 0; a second Ctrl-C exits at once with status 130.
//! Every failure prints one line `error: …` on stderr
//! and exits with status 1 (2 for unusable arguments). A standard output
//! closed by its reader (`… | head -1`) ends any subcommand quietly with
//! status 0 (see `cli/stdout.rs`).

pub mod convergence;
mod info;
mod progress;
mod render_cmd;
mod stdout;

use crate::compare::{Comparison, Corrected, ReferenceNoise, compare, compare_with_noise};
use crate::image_io::read_exr;
use clap::{Args, Parser, Subcommand};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use stdout::{Failure, err, out};

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

/// The older named flags of the Metropolis integrators. Each is the
/// assignment of the parameter named in its help (`--sigma 0.02` is
/// `--set sigma=0.02`), checked by the integrator's settings.
#[derive(Args, Clone, Debug, Default)]
pub struct ParamFlags {
    /// Set an integrator parameter (repeatable); `mcmc-render integrators` lists them.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    set: Vec<String>,
    /// MLT small step: kelemen, gaussian, adaptive or hachisuka (`small_step`).
    #[arg(long, value_name = "LAW")]
    small_step: Option<String>,
    /// Kelemen's smallest step (`s1`).
    #[arg(long, allow_negative_numbers = true)]
    s1: Option<String>,
    /// Kelemen's largest step (`s2`).
    #[arg(long, allow_negative_numbers = true)]
    s2: Option<String>,
    /// Gaussian small-step standard deviation (`sigma`).
    #[arg(long, allow_negative_numbers = true)]
    sigma: Option<String>,
    /// Probability of a large step (`large_step_probability`).
    #[arg(long, allow_negative_numbers = true)]
    large_step_probability: Option<String>,
    /// Bootstrap candidates (`bootstrap`).
    #[arg(long, allow_negative_numbers = true)]
    bootstrap: Option<String>,
    /// Number of Markov chains (`chains`).
    #[arg(long, allow_negative_numbers = true)]
    chains: Option<String>,
    /// Mutations per pixel (`mutations_per_pixel`).
    #[arg(long, allow_negative_numbers = true)]
    mutations_per_pixel: Option<String>,
    /// Kelemen's MIS combination of large steps (`kelemen_mis=true`).
    #[arg(long)]
    kelemen_mis: bool,
    /// Image normalisation: running, bootstrap, ratios or filmed (`normalization`).
    #[arg(long, value_name = "KIND")]
    normalization: Option<String>,
    /// Path sampler under PSSMLT: pt or bdpt (`base`).
    #[arg(long, value_name = "BASE")]
    mlt_base: Option<String>,
    /// Longest path in segments (`max_depth`; default: the scene's).
    #[arg(long, allow_negative_numbers = true)]
    max_depth: Option<String>,
}

/// The reference's own noise (`compare`, `convergence`): with either form,
/// the errors are also given with the reference's share taken out
/// ([`crate::compare::compare_with_noise`]).
#[derive(Args, Clone, Debug, Default)]
pub struct NoiseFlags {
    /// Per-sample variance of the reference, per pixel and channel (EXR, as
    /// `scenes/tools/mitsuba_reference.py --variance` and
    /// `scenes/tools/average_exr.py --variance` write it); needs `--reference-spp`.
    #[arg(
        long,
        value_name = "EXR",
        requires = "reference_spp",
        conflicts_with = "second_reference"
    )]
    reference_variance: Option<PathBuf>,
    /// Samples per pixel of the reference: the variance image is divided by
    /// it (1 if the image already holds the variance of the reference's pixels).
    #[arg(long, value_name = "N", requires = "reference_variance")]
    reference_spp: Option<f64>,
    /// A second reference, rendered independently of the first (other seed)
    /// with the same expectation.
    #[arg(long, value_name = "EXR")]
    second_reference: Option<PathBuf>,
}

impl NoiseFlags {
    /// Reads the noise image the flags name, checked against the reference's
    /// size `(width, height)`; `None` without these flags.
    pub(crate) fn load(&self, size: (u32, u32)) -> Result<Option<ReferenceNoise>, String> {
        let read = |path: &Path, what: &str| {
            let (w, h, pixels) = read_exr(path)?;
            if (w, h) != size {
                return Err(format!(
                    "{what} {} is {w}x{h}, the reference {}x{}",
                    path.display(),
                    size.0,
                    size.1
                ));
            }
            Ok(pixels)
        };
        if let Some(path) = &self.second_reference {
            return Ok(Some(ReferenceNoise::Independent(read(
                path,
                "the second reference",
            )?)));
        }
        let (Some(path), Some(spp)) = (&self.reference_variance, self.reference_spp) else {
            return Ok(None);
        };
        if !(spp > 0.0 && spp.is_finite()) {
            return Err(format!(
                "--reference-spp must be a positive number, got {spp}"
            ));
        }
        let var = read(path, "the variance image")?;
        if let Some(i) = var.iter().position(|v| v.r < 0.0 || v.g < 0.0 || v.b < 0.0) {
            return Err(format!(
                "the variance image {} is negative at pixel ({}, {})",
                path.display(),
                i as u32 % size.0,
                i as u32 / size.0
            ));
        }
        let per_pixel = (1.0 / spp) as f32;
        Ok(Some(ReferenceNoise::Variance(
            var.into_iter().map(|v| v * per_pixel).collect(),
        )))
    }
}

impl ParamFlags {
    /// The flags as parameter assignments, named flags first, then `--set`
    /// in order (so `--set` wins).
    pub fn assignments(&self) -> Result<Vec<(String, String)>, String> {
        let named = [
            ("small_step", &self.small_step),
            ("s1", &self.s1),
            ("s2", &self.s2),
            ("sigma", &self.sigma),
            ("large_step_probability", &self.large_step_probability),
            ("bootstrap", &self.bootstrap),
            ("chains", &self.chains),
            ("mutations_per_pixel", &self.mutations_per_pixel),
            ("normalization", &self.normalization),
            ("base", &self.mlt_base),
            ("max_depth", &self.max_depth),
        ];
        let mut out: Vec<(String, String)> = named
            .into_iter()
            .filter_map(|(k, v)| v.as_ref().map(|v| (k.to_string(), v.clone())))
            .collect();
        if self.kelemen_mis {
            out.push(("kelemen_mis".into(), "true".into()));
        }
        for s in &self.set {
            out.push(crate::integrators::registry::parse_assignment(s)?);
        }
        Ok(out)
    }
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene file.
    Render(render_cmd::RenderArgs),
    /// Compare a test EXR against a reference EXR.
    Compare {
        /// Reference image.
        reference: PathBuf,
        /// Test image.
        test: PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        /// The reference's own noise.
        #[command(flatten)]
        noise: NoiseFlags,
    },
    /// Error against time of several integrators at equal time budgets (CSV + log-log PNG).
    Convergence(convergence::ConvergenceArgs),
    /// Describe what a scene file loads to.
    Info {
        /// Mitsuba 3 XML scene.
        scene: PathBuf,
        /// Override a `<default name=…>` value: -D name=value.
        #[arg(short = 'D', value_name = "NAME=VALUE")]
        define: Vec<String>,
    },
    /// List the integrators with their parameters and defaults.
    Integrators,
}

/// Runs the command line and exits.
pub fn main() {
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
            err!("{line}");
            std::process::exit(2);
        }
    };
    match run(cli) {
        Ok(()) | Err(Failure::StdoutClosed) => {}
        Err(Failure::Message(e)) => {
            err!("error: {e}");
            std::process::exit(1);
        }
    }
}

fn run(cli: Cli) -> Result<(), Failure> {
    match cli.command {
        None => Ok(render_cmd::default_scene()?),
        Some(Command::Render(args)) => render_cmd::run(args),
        Some(Command::Compare {
            reference,
            test,
            json,
            noise,
        }) => compare_images(&reference, &test, json, &noise),
        Some(Command::Convergence(args)) => convergence::command(args),
        Some(Command::Info { scene, define }) => {
            let defines = parse_defines(&define)?;
            let s = crate::scene::Scene::load(&scene, &defines).map_err(|e| e.to_string())?;
            info::print_info(&scene, &s)
        }
        Some(Command::Integrators) => info::print_integrators(),
    }
}

fn compare_images(
    reference: &Path,
    test: &Path,
    json: bool,
    noise: &NoiseFlags,
) -> Result<(), Failure> {
    let (rw, rh, r) = read_exr(reference)?;
    let (tw, th, t) = read_exr(test)?;
    if (rw, rh) != (tw, th) {
        return Err(format!("image sizes differ: {rw}x{rh} vs {tw}x{th}").into());
    }
    let noise = noise.load((rw, rh))?;
    let c = compare(&r, &t)?;
    let corrected = match &noise {
        Some(n) => Some(compare_with_noise(&r, n, &t)?),
        None => None,
    };
    if json {
        /// `compare --json`: the comparison, and the corrected errors when
        /// the reference's noise is given.
        #[derive(serde::Serialize)]
        struct Report<'a> {
            #[serde(flatten)]
            comparison: &'a Comparison,
            #[serde(skip_serializing_if = "Option::is_none")]
            corrected: Option<Corrected>,
        }
        let report = Report {
            comparison: &c,
            corrected,
        };
        out!(
            "{}",
            serde_json::to_string_pretty(&report).map_err(|e| e.to_string())?
        )?;
    } else {
        out!("relMSE              {:.6e}", c.rel_mse)?;
        out!("RMSE                {:.6e}", c.rmse)?;
        out!(
            "mean rel. diff      R {:+.4}%  G {:+.4}%  B {:+.4}%",
            100.0 * c.mean_rel_diff[0],
            100.0 * c.mean_rel_diff[1],
            100.0 * c.mean_rel_diff[2]
        )?;
        out!(
            "reference mean      {:.6} {:.6} {:.6}",
            c.ref_mean[0],
            c.ref_mean[1],
            c.ref_mean[2]
        )?;
        out!(
            "test mean           {:.6} {:.6} {:.6}",
            c.test_mean[0],
            c.test_mean[1],
            c.test_mean[2]
        )?;
        out!(
            "non-finite pixels   reference {}  test {}",
            c.ref_nonfinite,
            c.test_nonfinite
        )?;
        if let Some(k) = corrected {
            out!(
                "relMSE corrected    {:.6e}  (reference's share {:.6e})",
                k.rel_mse,
                k.rel_mse_floor
            )?;
            out!(
                "MSE corrected       {:.6e}  (reference's share {:.6e}; RMSE² {:.6e})",
                k.mse,
                k.mse_floor,
                k.mse + k.mse_floor
            )?;
        }
    }
    Ok(())
}

/// Ctrl-C sets [`STOP`]: the run finishes with what it has and writes it.
/// A second Ctrl-C (e.g. during an MLT bootstrap, which does not poll the
/// flag) exits at once with status 130.
fn stop_on_ctrl_c() {
    // Ignore a failure to install the handler (e.g. set twice): rendering
    // still works, only Ctrl-C falls back to the default action.
    let _ = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::SeqCst) {
            err!("error: interrupted twice; exiting without writing");
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

/// Fails early (before a long render) when the output cannot be written,
/// or when its name does not end in `.ext`: the outputs beside it (PNG
/// preview, JSON statistics, layers) are named by replacing the
/// extension, so with any other name one of them would overwrite it.
fn check_writable(out: &Path, ext: &str) -> Result<(), String> {
    match out.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case(ext) => {}
        _ => {
            return Err(format!(
                "--out {} must end in .{ext} (the other outputs are written beside it under the same name)",
                out.display()
            ));
        }
    }
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

/// The worker threads: `threads`, or every core. At most 8 per core (and
/// at least 64 allowed): more only costs time to start them.
fn thread_count(threads: Option<usize>) -> Result<usize, String> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let limit = (8 * cores).max(64);
    match threads {
        Some(0) => Err("--threads must be at least 1".into()),
        Some(n) if n > limit => Err(format!(
            "--threads {n} is more than {limit} (8 per core of the {cores} here, at least 64)"
        )),
        Some(n) => Ok(n),
        None => Ok(cores),
    }
}
