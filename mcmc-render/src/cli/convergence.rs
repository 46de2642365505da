//! Error against time: each integrator renders a scene for the same time
//! budget, and at every checkpoint its current image is compared with a
//! reference ([`crate::compare`]: relMSE and RMSE). The records go to a
//! CSV and a log–log PNG plot (title, axis and tick labels, legend; the
//! text is drawn with an embedded DejaVu Sans, so no system font is needed).
//! Given the reference's own noise (a variance image or a second
//! reference, [`super::NoiseFlags`]), every record also carries the errors
//! with the reference's share taken out and that share
//! ([`crate::compare::compare_with_noise`]): four more CSV columns.
//!
//! Checkpoints are taken where an integrator can show an image: after a
//! pass (`pt`, `lt`) or after a round of mutations (`pssmlt`), at the first
//! such point after each `k·T/K`. The time of a record is the wall-clock
//! time since that integrator started, start-up (bootstrap) included.

use super::stdout::{Failure, err, out};
use super::{NoiseFlags, ParamFlags, STOP, check_writable, parse_defines, stop_on_ctrl_c};
use crate::color::Rgb;
use crate::compare::{Corrected, ReferenceNoise, compare, compare_with_noise};
use crate::image_io::read_exr;
use crate::integrators::RunSettings;
use crate::integrators::registry::{self, Configured};
use crate::observer::Observer;
use crate::scene::Scene;
use clap::Args;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Flags of `convergence`.
#[derive(Args)]
pub struct ConvergenceArgs {
    /// Mitsuba 3 XML scene.
    #[arg(required_unless_present = "replot")]
    scene: Option<PathBuf>,
    /// Reference EXR (e.g. a long `render --integrator pt` run).
    #[arg(long, required_unless_present = "replot")]
    reference: Option<PathBuf>,
    /// Only redraw the plot of an existing CSV (written beside it as PNG).
    #[arg(
        long,
        value_name = "CSV",
        conflicts_with_all = ["scene", "reference", "reference_variance", "second_reference"]
    )]
    replot: Option<PathBuf>,
    /// Plot title (default: the scene's or CSV's file stem).
    #[arg(long)]
    title: Option<String>,
    /// Comma-separated integrators, each `NAME[+MODIFIER]...` (see `variant`).
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
    /// Also write each integrator's final image (`DIR/NAME.exr`), its run
    /// statistics (`DIR/NAME.json`) and its per-pixel relative error
    /// against the reference (`DIR/NAME.relerr.exr`, and a log-scale map
    /// `DIR/NAME.relerr.png`).
    #[arg(long, value_name = "DIR")]
    images: Option<PathBuf>,
    /// Parameters, applied to every integrator that has them.
    #[command(flatten)]
    params: ParamFlags,
    /// The reference's own noise: adds the corrected errors.
    #[command(flatten)]
    noise: NoiseFlags,
}

/// `mcmc-render convergence …`.
pub(crate) fn command(args: ConvergenceArgs) -> Result<(), Failure> {
    let stem = |p: &Path| {
        p.file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
    };
    if let Some(csv) = &args.replot {
        let records = read_csv(csv)?;
        let names = integrators_of(&records);
        let title = args.title.clone().unwrap_or_else(|| stem(csv));
        let png = csv.with_extension("png");
        write_plot(&png, &records, &names, &title)?;
        out!("{}", png.display())?;
        return Ok(());
    }
    // clap requires both unless --replot is given.
    let (Some(scene), Some(reference)) = (&args.scene, &args.reference) else {
        return Err("convergence needs SCENE and --reference (or --replot CSV)".into());
    };
    let title = args.title.clone().unwrap_or_else(|| stem(scene));
    // Flags first, then files.
    let threads = super::thread_count(args.threads)?;
    time_budget(args.time)?;
    check_writable(&args.out, "csv")?;
    let defines = parse_defines(&args.define)?;
    let loaded = Scene::load(scene, &defines).map_err(|e| e.to_string())?;
    let (rw, rh, r) = read_exr(reference)?;
    if (rw, rh) != (loaded.film.width, loaded.film.height) {
        return Err(format!(
            "reference is {rw}x{rh}, the scene renders {}x{}",
            loaded.film.width, loaded.film.height
        )
        .into());
    }
    let noise = args.noise.load((rw, rh))?;
    let names: Vec<String> = args
        .integrators
        .split(',')
        .map(|s| s.trim().to_string())
        .collect();
    let study = Study {
        integrators: names.clone(),
        seconds: args.time,
        checkpoints: args.checkpoints,
        seed: args.seed,
        assignments: args.params.assignments()?,
        images: args.images.clone(),
        noise,
    };
    stop_on_ctrl_c();
    let records = mcmc_core::runner::with_threads(threads, || run(&loaded, &r, &study, &STOP))?;
    write_csv(&args.out, &records)?;
    write_plot(&args.out.with_extension("png"), &records, &names, &title)?;
    if !STOP.load(Ordering::SeqCst) {
        for name in names
            .iter()
            .filter(|n| !records.iter().any(|r| &r.integrator == *n))
        {
            err!(
                "warning: {name} has no record: its start-up or first unit of work outlasted --time {}",
                args.time
            );
        }
    }
    for rec in &records {
        let corrected = rec.corrected.map_or_else(String::new, |k| {
            format!(
                " | corrected relMSE {:.4e} (reference {:.2e}) MSE {:.4e} (reference {:.2e})",
                k.rel_mse, k.rel_mse_floor, k.mse, k.mse_floor
            )
        });
        out!(
            "{:8} {:8.2} s {:>12} relMSE {:.4e} RMSE {:.4e}{corrected}",
            rec.integrator,
            rec.seconds,
            rec.samples,
            rec.rel_mse,
            rec.rmse
        )?;
    }
    Ok(())
}

/// One checkpoint of one integrator.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Record {
    /// Integrator name.
    pub integrator: String,
    /// Seconds since the integrator started.
    pub seconds: f64,
    /// Camera samples, light paths or mutations so far.
    pub samples: u64,
    /// relMSE against the reference.
    pub rel_mse: f64,
    /// RMSE against the reference.
    pub rmse: f64,
    /// The errors with the reference's own share taken out, when the study
    /// was given the reference's noise.
    pub corrected: Option<Corrected>,
}

/// Collects records at checkpoints.
struct Recorder<'a> {
    name: &'a str,
    reference: &'a [Rgb],
    noise: Option<&'a ReferenceNoise>,
    start: Instant,
    step: f64,
    state: Mutex<(u32, Vec<Record>)>,
}

impl Recorder<'_> {
    fn offer(&self, samples: u64, image: &dyn Fn() -> Vec<Rgb>, force: bool) {
        let t = self.start.elapsed().as_secs_f64();
        let mut g = self.state.lock().unwrap_or_else(|p| p.into_inner());
        let next = g.0 as f64 * self.step;
        if !force && t < next {
            return;
        }
        // The final (forced) offer adds nothing when the last checkpoint
        // already holds the same samples (the run ended on a checkpoint) or
        // when nothing was rendered (stopped at once).
        if force && (samples == 0 || g.1.last().is_some_and(|r| r.samples == samples)) {
            return;
        }
        let image = image();
        if let Ok(c) = compare(self.reference, &image) {
            let corrected = self
                .noise
                .and_then(|n| compare_with_noise(self.reference, n, &image).ok());
            g.1.push(Record {
                integrator: self.name.to_string(),
                seconds: t,
                samples,
                rel_mse: c.rel_mse,
                rmse: c.rmse,
                corrected,
            });
        }
        g.0 = (t / self.step).floor() as u32 + 1;
    }
}

impl Observer for Recorder<'_> {
    fn snapshot(&self, image: &dyn Fn() -> Vec<Rgb>, samples: u64) {
        self.offer(samples, image, false);
    }
}

/// What a convergence study runs.
#[derive(Clone, Debug)]
pub struct Study {
    /// Integrator names, each optionally with modifiers (`mmlt+running`,
    /// see [`variant`]).
    pub integrators: Vec<String>,
    /// Seconds per integrator.
    pub seconds: f64,
    /// Checkpoints per integrator.
    pub checkpoints: u32,
    /// Seed.
    pub seed: u64,
    /// Parameter assignments from the command line, applied to every
    /// integrator that has the parameter.
    pub assignments: Vec<(String, String)>,
    /// Where to write each integrator's final image, statistics and error
    /// maps ([`write_final`]); `None`: nowhere.
    pub images: Option<PathBuf>,
    /// The reference's own noise; `Some`: the records carry the corrected
    /// errors too.
    pub noise: Option<ReferenceNoise>,
}

/// The assignments a modifier of [`variant`] stands for.
fn modifier(m: &str, name: &str) -> Result<Vec<(String, String)>, String> {
    let pair = |k: &str, v: &str| (k.to_string(), v.to_string());
    let (key, value) = match m.split_once('=') {
        Some((k, v)) => (k, Some(v)),
        None => (m, None),
    };
    let value_of = |what: &str| {
        value.ok_or_else(|| format!("modifier `{m}` of `{name}` needs a value ({what})"))
    };
    Ok(match key {
        // (`bootstrap=N` is the parameter: the candidates' count.)
        "running" | "bootstrap" if value.is_none() => vec![pair("normalization", key)],
        "mis" => vec![pair("kelemen_mis", "true")],
        "kelemen" => vec![
            pair("small_step", "kelemen"),
            pair("s1", "0.0009765625"),
            pair("s2", "0.015625"),
        ],
        "gaussian" => vec![pair("small_step", "gaussian"), pair("sigma", "0.01")],
        "sigma" => vec![
            pair("small_step", "gaussian"),
            pair("sigma", value_of("the Gaussian small step's sigma")?),
        ],
        "plarge" => vec![pair(
            "large_step_probability",
            value_of("large-step probability")?,
        )],
        "candidates" => vec![pair("bootstrap", value_of("bootstrap candidates")?)],
        "alloc" => vec![pair(
            "depth_allocation",
            value_of("depth allocation exponent")?,
        )],
        _ => match value {
            Some(v) => vec![pair(key, v)],
            None => {
                return Err(format!(
                    "unknown modifier `{m}` in `{name}` (known: running, bootstrap, mis, kelemen, gaussian, sigma=S, plarge=P, candidates=N, alloc=G, or any PARAMETER=VALUE)"
                ));
            }
        },
    })
}

/// Configures an integrator of the study from its name
/// `BASE[+MODIFIER]...`, so that variants of one integrator can be compared
/// within one run: `BASE` is a registered name (or `pssmlt-bdpt`, PSSMLT
/// over BDPT); a modifier is `PARAMETER=VALUE` or one of the short forms
/// `running`, `bootstrap` (normalisation), `mis` (Kelemen's MIS of large
/// steps), `kelemen` (s1 = 1/1024, s2 = 1/64), `gaussian` (sigma 0.01),
/// `sigma=S` (Gaussian), `plarge=P`, `candidates=N` (bootstrap candidates),
/// `alloc=G` (chains per depth `∝ b_d^G`); a short form with a value whose
/// parameters `BASE` lacks sets `BASE`'s own parameter of its name if it
/// has one (`mcmc-vcm+candidates=N`). The scene's `<integrator>` and
/// `assignments` (where the integrator has the parameter) come first.
pub fn variant(
    name: &str,
    scene: &Scene,
    assignments: &[(String, String)],
) -> Result<Box<dyn Configured>, String> {
    let mut parts = name.split('+');
    let head = parts.next().unwrap_or_default();
    let mut own: Vec<(String, String)> = Vec::new();
    let base = if head == "pssmlt-bdpt" {
        own.push(("base".into(), "bdpt".into()));
        "pssmlt"
    } else {
        head
    };
    let defaults = (registry::find(base)?.new)();
    let known: Vec<&str> = defaults.params().iter().map(|p| p.name).collect();
    for m in parts {
        // A short form whose parameters the integrator lacks gives way to
        // its own parameter of that name (`mcmc-vcm+candidates=N` sets its
        // restart candidates, not a bootstrap it does not have).
        let short = modifier(m, name)?;
        match m.split_once('=') {
            Some((k, v))
                if known.contains(&k)
                    && short.iter().any(|(p, _)| !known.contains(&p.as_str())) =>
            {
                own.push((k.into(), v.into()))
            }
            _ => own.extend(short),
        }
    }
    let mut all: Vec<(String, String)> = assignments
        .iter()
        .filter(|(k, _)| known.contains(&k.as_str()))
        .cloned()
        .collect();
    all.extend(own);
    registry::configure(scene.integrator_element.as_ref(), Some(base), &all)
        .map_err(|e| format!("`{name}`: {e}"))
}

/// `--time` as a budget: positive, finite and within a `Duration`, checked
/// before it is converted (a negative or huge value panicked there).
fn time_budget(seconds: f64) -> Result<Duration, String> {
    if !(seconds > 0.0 && seconds.is_finite()) {
        return Err(format!(
            "--time must be a positive number of seconds, got {seconds}"
        ));
    }
    Duration::try_from_secs_f64(seconds).map_err(|_| format!("--time {seconds:e} is too large"))
}

/// Runs the study on `scene` against `reference`. Setting `stop` ends the
/// integrator in flight (its records so far are kept) and skips the rest.
pub fn run(
    scene: &Scene,
    reference: &[Rgb],
    study: &Study,
    stop: &AtomicBool,
) -> Result<Vec<Record>, String> {
    let Study {
        integrators,
        seconds,
        checkpoints,
        seed,
        assignments,
        images,
        noise,
    } = study;
    let (seconds, checkpoints, seed) = (*seconds, *checkpoints, *seed);
    let budget = time_budget(seconds)?;
    if checkpoints == 0 {
        return Err("--checkpoints must be at least 1".into());
    }
    let pixels = scene.film.width as u64 * scene.film.height as u64;
    if reference.len() as u64 != pixels {
        return Err(format!(
            "the reference has {} pixels, the scene renders {pixels}",
            reference.len()
        ));
    }
    if let Some(ReferenceNoise::Variance(v) | ReferenceNoise::Independent(v)) = noise
        && v.len() != reference.len()
    {
        return Err(format!(
            "the reference's noise image has {} pixels, the reference {}",
            v.len(),
            reference.len()
        ));
    }
    for (k, _) in assignments {
        let anyone = integrators.iter().any(|n| {
            let base = n.split('+').next().unwrap_or_default();
            let base = if base == "pssmlt-bdpt" {
                "pssmlt"
            } else {
                base
            };
            registry::find(base).is_ok_and(|r| (r.new)().params().iter().any(|p| p.name == k))
        });
        if !anyone {
            return Err(format!("no integrator of the study has a parameter `{k}`"));
        }
    }
    let configured: Vec<Box<dyn Configured>> = integrators
        .iter()
        .map(|n| variant(n, scene, assignments))
        .collect::<Result<_, _>>()?;
    let mut all = Vec::new();
    let step = seconds / checkpoints as f64;
    for (name, integrator) in integrators.iter().zip(&configured) {
        let rec = Recorder {
            name,
            reference,
            noise: noise.as_ref(),
            start: Instant::now(),
            step,
            state: Mutex::new((1, Vec::new())),
        };
        let run = RunSettings {
            spp: None,
            time_budget: Some(budget),
            seed,
            snapshot_every: Duration::from_secs_f64(step / 4.0),
            checkpoint: None,
        };
        let r = integrator
            .render(scene, &run, stop, &rec)
            .map_err(|e| e.to_string())?;
        rec.offer(r.samples, &|| r.image.clone(), true);
        if let Some(dir) = images {
            write_final(
                dir,
                name,
                &**integrator,
                seed,
                scene,
                reference,
                noise.as_ref(),
                &r,
            )?;
        }
        let (_, records) = rec.state.into_inner().unwrap_or_else(|p| p.into_inner());
        all.extend(records);
        // Ctrl-C ends the study: the integrators not started yet are skipped.
        if stop.load(Ordering::Relaxed) {
            break;
        }
    }
    Ok(all)
}

/// Writes integrator `name`'s final image `r` into `dir` (created if
/// needed): `NAME.exr`, `NAME.json` (what ran — the registered integrator,
/// every setting as `render`'s sidecar records them, the seed — then
/// seconds, samples, relMSE, RMSE, the corrected errors when `noise` is
/// given, the integrator's statistics),
/// `NAME.relerr.exr` (per-pixel
/// `(t − r)² / (r² + 0.01)` on luminance, the terms relMSE averages) and
/// `NAME.relerr.png` (the same on a log scale, black at 1e-4 through red
/// and yellow to white at 10, equal for every integrator). Characters of
/// `name` other than letters, digits, `-` and `.` become `_`.
#[allow(clippy::too_many_arguments)] // (each is one thing the files record)
pub fn write_final(
    dir: &Path,
    name: &str,
    ran: &dyn Configured,
    seed: u64,
    scene: &Scene,
    reference: &[Rgb],
    noise: Option<&ReferenceNoise>,
    r: &crate::integrators::Rendered,
) -> Result<(), String> {
    use crate::compare::rel_sq_error;
    use crate::image_io::{write_exr, write_png};
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let stem: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect();
    let (w, h) = (scene.film.width, scene.film.height);
    write_exr(&dir.join(format!("{stem}.exr")), w, h, &r.image)?;
    let errors: Vec<f64> = reference
        .iter()
        .zip(&r.image)
        .map(|(a, b)| rel_sq_error(a, b))
        .collect();
    let gray: Vec<Rgb> = errors.iter().map(|&e| Rgb::splat(e as f32)).collect();
    write_exr(&dir.join(format!("{stem}.relerr.exr")), w, h, &gray)?;
    let ramp: Vec<Rgb> = errors
        .iter()
        .map(|&e| {
            // log10 e from −4 to 1 onto [0, 1]; NaN (a NaN pixel) is white.
            let t = if e.is_nan() {
                1.0
            } else {
                ((e.max(1e-30).log10() + 4.0) / 5.0).clamp(0.0, 1.0) as f32
            };
            let c = |x: f32| x.clamp(0.0, 1.0);
            Rgb::new(c(3.0 * t), c(3.0 * t - 1.0), c(3.0 * t - 2.0))
        })
        .collect();
    write_png(&dir.join(format!("{stem}.relerr.png")), w, h, &ramp)?;
    let c = compare(reference, &r.image)?;
    let corrected = match noise {
        Some(n) => Some(compare_with_noise(reference, n, &r.image)?),
        None => None,
    };
    let json = serde_json::json!({
        "integrator": name,
        "registered": ran.name(),
        "settings": ran.settings_json(),
        "seed": seed,
        "seconds": r.seconds,
        "samples": r.samples,
        "rel_mse": c.rel_mse,
        "rmse": c.rmse,
        "corrected": corrected,
        "statistics": r.statistics,
    });
    let text = serde_json::to_string_pretty(&json).map_err(|e| e.to_string())?;
    let path = dir.join(format!("{stem}.json"));
    std::fs::write(&path, text).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// The CSV header of a study.
const HEADER: &str = "integrator,seconds,samples,rel_mse,rmse";
/// The columns a study given the reference's noise adds to [`HEADER`]
/// ([`Corrected`]: `mse_*` are squared RMSEs over all channels).
const CORRECTED_COLUMNS: &str = "rel_mse_floor,rel_mse_corrected,mse_floor,mse_corrected";

/// Writes the records as CSV: `HEADER`'s columns, and
/// `CORRECTED_COLUMNS` when any record has corrected errors (NaN in a
/// record without).
pub fn write_csv(path: &Path, records: &[Record]) -> Result<(), String> {
    let extended = records.iter().any(|r| r.corrected.is_some());
    let mut text = if extended {
        format!("{HEADER},{CORRECTED_COLUMNS}\n")
    } else {
        format!("{HEADER}\n")
    };
    for r in records {
        text.push_str(&format!(
            "{},{:.4},{},{:.6e},{:.6e}",
            r.integrator, r.seconds, r.samples, r.rel_mse, r.rmse
        ));
        if extended {
            let k = r.corrected.unwrap_or(Corrected {
                rel_mse: f64::NAN,
                rel_mse_floor: f64::NAN,
                mse: f64::NAN,
                mse_floor: f64::NAN,
            });
            text.push_str(&format!(
                ",{:.6e},{:.6e},{:.6e},{:.6e}",
                k.rel_mse_floor, k.rel_mse, k.mse_floor, k.mse
            ));
        }
        text.push('\n');
    }
    mcmc_core::checkpoint::write_bytes(path, text.as_bytes())
}

/// Reads records written by [`write_csv`] (for re-plotting a study).
pub fn read_csv(path: &Path) -> Result<Vec<Record>, String> {
    crate::resources::regular_file(path)?;
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    parse_csv(&text, path)
}

/// Parses the text of a study's CSV, as [`read_csv`] reads it from a file;
/// `path` names it in messages.
pub fn parse_csv(text: &str, path: &Path) -> Result<Vec<Record>, String> {
    let mut lines = text.lines().enumerate();
    let extended_header = format!("{HEADER},{CORRECTED_COLUMNS}");
    let extended = match lines.next() {
        Some((_, h)) if h.trim() == HEADER => false,
        Some((_, h)) if h.trim() == extended_header => true,
        _ => {
            return Err(format!(
                "{}:1: expected the header {HEADER} (optionally followed by ,{CORRECTED_COLUMNS})",
                path.display()
            ));
        }
    };
    let fields = if extended { 9 } else { 5 };
    let mut out = Vec::new();
    for (n, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let bad = || format!("{}:{}: malformed record: {line}", path.display(), n + 1);
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if f.len() != fields || f[0].is_empty() {
            return Err(bad());
        }
        let number = |i: usize| f[i].parse::<f64>().map_err(|_| bad());
        // Corrected errors and a second reference's floor are estimates:
        // any sign (and NaN where a record had none).
        let corrected = if extended {
            Some(Corrected {
                rel_mse_floor: number(5)?,
                rel_mse: number(6)?,
                mse_floor: number(7)?,
                mse: number(8)?,
            })
        } else {
            None
        };
        let record = Record {
            integrator: f[0].to_string(),
            seconds: number(1)?,
            samples: f[2].parse().map_err(|_| bad())?,
            rel_mse: number(3)?,
            rmse: number(4)?,
            corrected,
        };
        // What `write_csv` writes: finite non-negative times; errors
        // non-negative (NaN or +inf for a non-finite image).
        if !(record.seconds.is_finite() && record.seconds >= 0.0) {
            return Err(format!(
                "{}:{}: seconds must be finite and non-negative, got {}",
                path.display(),
                n + 1,
                f[1]
            ));
        }
        if record.rel_mse < 0.0 || record.rmse < 0.0 {
            return Err(format!(
                "{}:{}: rel_mse and rmse must be non-negative, got {} and {}",
                path.display(),
                n + 1,
                f[3],
                f[4]
            ));
        }
        out.push(record);
    }
    Ok(out)
}

/// The integrators of `records` in order of first appearance.
pub fn integrators_of(records: &[Record]) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for r in records {
        if !names.contains(&r.integrator) {
            names.push(r.integrator.clone());
        }
    }
    names
}

/// Line colours, by position in the integrator list.
pub const COLOURS: [(u8, u8, u8); 6] = [
    (31, 119, 180),
    (214, 39, 40),
    (44, 160, 44),
    (148, 103, 189),
    (255, 127, 14),
    (23, 190, 207),
];

/// Registers the embedded DejaVu Sans as plotters' `sans-serif` family.
///
/// plotters' `ab_glyph` text backend draws only fonts registered by the
/// program; the font comes from the `dejavu` crate, so no system font (and
/// no fontconfig) is needed on a clean machine.
fn register_font() -> Result<(), String> {
    use std::sync::OnceLock;
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(
            "sans-serif",
            plotters::style::FontStyle::Normal,
            dejavu::sans::regular(),
        )
        .is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err("the embedded plot font could not be loaded".into())
    }
}

/// The values `m·10^k` (m in `mantissas`) within `[lo, hi]`: the tick
/// positions of a log axis.
fn log_ticks(lo: f64, hi: f64, mantissas: &[f64]) -> Vec<f64> {
    let (k0, k1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    (k0..=k1)
        .flat_map(|k| mantissas.iter().map(move |m| m * 10f64.powi(k)))
        .filter(|v| (lo..=hi).contains(v))
        .collect()
}

/// Tick label of a log axis (`m·10^k` with a one-digit `m`): plain
/// decimals between 0.001 and 10000, `2e-5` beyond.
fn log_tick(v: f64) -> String {
    if !(v > 0.0 && v.is_finite()) {
        return String::new();
    }
    let k = v.log10().floor() as i32;
    let m = (v / 10f64.powi(k)).round();
    if (-3..=4).contains(&k) {
        format!("{:.*}", (-k).max(0) as usize, m * 10f64.powi(k))
    } else {
        format!("{m}e{k}")
    }
}

/// Seconds and relMSE values a plot can show (a study's lie far inside).
pub const PLOT_RANGE: std::ops::RangeInclusive<f64> = 1e-30..=1e30;

/// Draws relMSE against seconds on log–log axes, one line per integrator
/// (colours in [`COLOURS`] order), with `title`, axis labels, tick labels
/// at the powers of ten and a legend naming the integrators.
pub fn write_plot(
    path: &Path,
    records: &[Record],
    integrators: &[String],
    title: &str,
) -> Result<(), String> {
    use plotters::coord::combinators::BindKeyPoints;
    use plotters::prelude::*;
    // Labelled ticks at 1, 2, 3, 5 × 10^k; light grid lines at every m × 10^k.
    const LABELLED: &[f64] = &[1.0, 2.0, 3.0, 5.0];
    const GRID: &[f64] = &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0];
    register_font()?;
    let (w, h) = (800u32, 600u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let pos: Vec<&Record> = records
        .iter()
        .filter(|r| r.seconds > 0.0 && r.rel_mse > 0.0 && r.rel_mse.is_finite())
        .collect();
    if pos.is_empty() {
        return Err("no positive records to plot".into());
    }
    // The axes span the data widened by at most a decade and a half; far
    // from 1 their bounds (and tick loops) would leave the f64 range.
    if let Some(r) = pos
        .iter()
        .find(|r| !(PLOT_RANGE.contains(&r.seconds) && PLOT_RANGE.contains(&r.rel_mse)))
    {
        return Err(format!(
            "cannot plot {} at {} s with relMSE {}: the log axes span {:e} to {:e}",
            r.integrator,
            r.seconds,
            r.rel_mse,
            PLOT_RANGE.start(),
            PLOT_RANGE.end()
        ));
    }
    let (t0, t1) = pos.iter().fold((f64::MAX, 0.0f64), |(a, b), r| {
        (a.min(r.seconds), b.max(r.seconds))
    });
    let (e0, e1) = pos.iter().fold((f64::MAX, 0.0f64), |(a, b), r| {
        (a.min(r.rel_mse), b.max(r.rel_mse))
    });
    // Widen each range to at least one decade around its data so that the
    // log axes always carry a few labelled ticks.
    let widen = |lo: f64, hi: f64| {
        let (a, b) = (lo.log10(), hi.log10());
        let pad = ((1.0 - (b - a)) / 2.0).max(0.0) + 0.1;
        (10f64.powf(a - pad), 10f64.powf(b + pad))
    };
    let (x0, x1) = widen(t0, t1);
    let (y0, y1) = widen(e0, e1);
    // Headroom above the data for the legend (upper right): a third more
    // decades on top.
    let y1 = y1 * (y1 / y0).powf(1.0 / 3.0);
    let err = |e: &dyn std::fmt::Display| format!("cannot draw the plot: {e}");
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 24))
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .build_cartesian_2d(
                (x0..x1)
                    .log_scale()
                    .with_key_points(log_ticks(x0, x1, LABELLED))
                    .with_light_points(log_ticks(x0, x1, GRID)),
                (y0..y1)
                    .log_scale()
                    .with_key_points(log_ticks(y0, y1, LABELLED))
                    .with_light_points(log_ticks(y0, y1, GRID)),
            )
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("seconds (wall clock, start-up included)")
            .y_desc("relMSE")
            .x_label_formatter(&|v| log_tick(*v))
            .y_label_formatter(&|v| log_tick(*v))
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 17))
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(200, 200, 200))
            .draw()
            .map_err(|e| err(&e))?;
        for (i, name) in integrators.iter().enumerate() {
            let (r, g, b) = COLOURS[i % COLOURS.len()];
            let colour = RGBColor(r, g, b);
            let pts: Vec<(f64, f64)> = pos
                .iter()
                .filter(|x| &x.integrator == name)
                .map(|x| (x.seconds, x.rel_mse))
                .collect();
            if pts.is_empty() {
                continue;
            }
            chart
                .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                .map_err(|e| err(&e))?
                .label(name.as_str())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 24, y)], colour.stroke_width(3))
                });
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 4, colour.filled())))
                .map_err(|e| err(&e))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font(("sans-serif", 16))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
    }
    write_rgb8_png(path, w, h, &buf)
}

fn write_rgb8_png(path: &Path, w: u32, h: u32, rgb: &[u8]) -> Result<(), String> {
    mcmc_core::checkpoint::write_atomically(path, |tmp| {
        let file = std::fs::File::create(tmp)
            .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
        let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header().map_err(|e| e.to_string())?;
        writer.write_image_data(rgb).map_err(|e| e.to_string())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrators::mcmc_vcm::McmcVcmSettings;
    use crate::integrators::mmlt::Mmlt;
    use crate::integrators::pssmlt::{MltBase, Pssmlt};
    use crate::markov::Normalization;
    use crate::pss::SmallStepLaw;

    fn scene() -> Scene {
        let text = r#"<scene version="3.0.0">
            <integrator type="path"><integer name="max_depth" value="5"/></integrator>
            <sensor type="perspective"><film type="hdrfilm">
                <integer name="width" value="4"/><integer name="height" value="4"/>
            </film></sensor>
            <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
        </scene>"#;
        Scene::load_str(text, Path::new("s.xml"), Path::new(".")).expect("test scene")
    }

    fn settings<T: 'static + Clone>(c: &dyn Configured) -> T {
        c.as_any().downcast_ref::<T>().expect("type").clone()
    }

    #[test]
    fn variant_modifiers_set_the_settings() {
        let s = scene();
        let m: Mmlt = settings(
            variant(
                "mmlt+running+mis+plarge=0.1+chains=10+candidates=50+alloc=0.5",
                &s,
                &[],
            )
            .expect("valid variant")
            .as_ref(),
        );
        assert_eq!(m.chain.normalization, Normalization::Running);
        assert!(m.chain.kelemen_mis);
        assert_eq!(m.mutation.large_step_probability, 0.1);
        assert_eq!((m.chain.chains, m.chain.bootstrap), (10, 50));
        assert_eq!(m.chain.depth_allocation, 0.5);
        // The scene's max_depth carries over from its `path` element.
        assert_eq!(m.depth.max_depth, 5);
        let g: Pssmlt = settings(variant("pssmlt+sigma=0.02", &s, &[]).unwrap().as_ref());
        assert_eq!(
            (g.mutation.small_step, g.mutation.sigma),
            (SmallStepLaw::Gaussian, 0.02)
        );
        let b: Pssmlt = settings(variant("pssmlt-bdpt+bootstrap", &s, &[]).unwrap().as_ref());
        assert_eq!(
            (b.base, b.chain.normalization),
            (MltBase::Bdpt, Normalization::Bootstrap)
        );
        // With a value, `bootstrap` is the parameter, not the short form.
        let n: Pssmlt = settings(variant("pssmlt+bootstrap=5000", &s, &[]).unwrap().as_ref());
        assert_eq!(n.chain.bootstrap, 5000);
        assert_eq!(n.chain.normalization, Pssmlt::default().chain.normalization);
        // `candidates=N` is the bootstrap's short form only where there is
        // a bootstrap: `mcmc-vcm` has its own `candidates`.
        let v: McmcVcmSettings = settings(
            variant("mcmc-vcm+candidates=2000", &s, &[])
                .unwrap()
                .as_ref(),
        );
        assert_eq!(v.candidates, 2000);
        // Command-line assignments reach only the integrators that have them.
        let flags = [("sigma".to_string(), "0.03".to_string())];
        let p: Pssmlt = settings(variant("pssmlt", &s, &flags).unwrap().as_ref());
        assert_eq!(p.mutation.sigma, 0.03);
        assert_eq!(variant("pt", &s, &flags).unwrap().name(), "pt");
        for bad in [
            "mmlt+fast",
            "mmlt+plarge=x",
            "mmlt+plarge=2",
            "mmlt+chains=0",
            "mmlt+sigma=inf",
            "nope",
        ] {
            assert!(variant(bad, &s, &[]).is_err(), "{bad} accepted");
        }
    }

    #[test]
    fn metropolis_defaults_are_the_documented_ones() {
        let p = Pssmlt::default();
        assert_eq!(p.mutation.small_step, SmallStepLaw::Kelemen);
        assert_eq!((p.mutation.s1, p.mutation.s2), (1.0 / 1024.0, 1.0 / 64.0));
        let m = Mmlt::default();
        assert_eq!(
            (m.mutation.small_step, m.mutation.sigma),
            (SmallStepLaw::Gaussian, 0.01)
        );
        for c in [&p.chain, &m.chain] {
            assert_eq!(c.normalization, Normalization::Running);
            assert_eq!(
                (c.bootstrap, c.chains, c.mutations_per_pixel),
                (100_000, 1000, None)
            );
        }
        assert_eq!(m.mutation.large_step_probability, 0.3);
        // `auto` mutations per pixel: 100 without a time budget.
        let run = RunSettings::default();
        assert_eq!(
            p.chain.chain_settings((), &run).mutations_per_pixel,
            Some(100)
        );
    }
}
