//! Error against time: each integrator renders a scene for the same time
//! budget, and at every checkpoint its current image is compared with a
//! reference ([`crate::compare`]: relMSE and RMSE). The records go to a
//! CSV and a log–log PNG plot (title, axis and tick labels, legend; the
//! text is drawn with an embedded DejaVu Sans, so no system font is needed).
//!
//! Checkpoints are taken where an integrator can show an image: after a
//! pass (`pt`, `lt`) or after a round of mutations (`pssmlt`), at the first
//! such point after each `k·T/K`. The time of a record is the wall-clock
//! time since that integrator started, start-up (bootstrap) included.

use crate::color::Rgb;
use crate::compare::compare;
use crate::film::Film;
use crate::integrators::bdpt::{Bdpt, MisHeuristic};
use crate::integrators::pssmlt::{MltObserver, PssmltSettings, render_family, render_pssmlt};
use crate::integrators::{Integrator, lt::LightTracer, pt::PathTracer};
use crate::pss::MmltDepth;
use crate::render::{RenderObserver, RenderSettings, render};
use crate::scene::Scene;
use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

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
}

/// Collects records at checkpoints.
struct Recorder<'a> {
    name: &'a str,
    reference: &'a [Rgb],
    start: Instant,
    step: f64,
    state: Mutex<(u32, Vec<Record>)>,
    pixels: u64,
}

impl Recorder<'_> {
    fn offer(&self, samples: u64, image: impl FnOnce() -> Vec<Rgb>, force: bool) {
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
        if let Ok(c) = compare(self.reference, &image()) {
            g.1.push(Record {
                integrator: self.name.to_string(),
                seconds: t,
                samples,
                rel_mse: c.rel_mse,
                rmse: c.rmse,
            });
        }
        g.0 = (t / self.step).floor() as u32 + 1;
    }
}

impl RenderObserver for Recorder<'_> {
    fn pass_done(&self, film: &Film, spp_done: u64, paths_per_pixel: f64) {
        self.offer(
            spp_done * self.pixels,
            || film.develop(paths_per_pixel),
            false,
        );
    }
}

impl MltObserver for Recorder<'_> {
    fn preview(&self, image: &[Rgb], mutations: u64) {
        self.offer(mutations, || image.to_vec(), false);
    }
}

/// Integrators the study knows.
pub const KNOWN: &[&str] = &["pt", "lt", "bdpt", "pssmlt", "pssmlt-bdpt", "mmlt"];

/// What a convergence study runs.
#[derive(Clone, Debug)]
pub struct Study {
    /// Integrator names (see [`KNOWN`]), each optionally with MLT
    /// modifiers (`mmlt+running`, see [`crate::mlt_cli::mlt_variant`]).
    pub integrators: Vec<String>,
    /// Seconds per integrator.
    pub seconds: f64,
    /// Checkpoints per integrator.
    pub checkpoints: u32,
    /// Seed.
    pub seed: u64,
    /// PSSMLT settings (budget, seed and preview interval are overridden).
    pub mlt: PssmltSettings,
    /// MMLT settings (its default small step differs from PSSMLT's).
    pub mmlt: PssmltSettings,
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
        mlt,
        mmlt,
    } = study;
    let (seconds, checkpoints, seed) = (*seconds, *checkpoints, *seed);
    if !(seconds > 0.0 && seconds.is_finite()) {
        return Err(format!(
            "--time must be a positive number of seconds, got {seconds}"
        ));
    }
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
    for name in integrators {
        let (base, _) = crate::mlt_cli::mlt_variant(name, mlt)?;
        if !KNOWN.contains(&base.as_str()) {
            return Err(format!(
                "integrator `{name}` is not available for convergence (known: {})",
                KNOWN.join(", ")
            ));
        }
    }
    let mut all = Vec::new();
    let budget = Duration::from_secs_f64(seconds);
    let step = seconds / checkpoints as f64;
    for name in integrators {
        let rec = Recorder {
            name,
            reference,
            start: Instant::now(),
            step,
            state: Mutex::new((1, Vec::new())),
            pixels,
        };
        let it = scene.integrator;
        let bdpt = Bdpt {
            max_depth: it.max_depth,
            rr_depth: it.rr_depth,
            heuristic: MisHeuristic::Power,
        };
        // `BASE+MODIFIER...` names variants of the MLT settings.
        let family = if name.split('+').next() == Some("mmlt") {
            mmlt
        } else {
            mlt
        };
        let (base, mlt) = crate::mlt_cli::mlt_variant(name, family)?;
        match base.as_str() {
            "pt" | "lt" | "bdpt" => {
                let integ: Box<dyn Integrator> = match base.as_str() {
                    "pt" => Box::new(PathTracer {
                        max_depth: it.max_depth,
                        rr_depth: it.rr_depth,
                    }),
                    "lt" => Box::new(LightTracer {
                        max_depth: it.max_depth,
                        rr_depth: it.rr_depth,
                    }),
                    _ => Box::new(bdpt),
                };
                let settings = RenderSettings {
                    spp: None,
                    time_budget: Some(budget),
                    seed,
                };
                let r = render(scene, integ.as_ref(), &settings, stop, &rec);
                rec.offer(r.samples, || r.image(), true);
            }
            _ => {
                let settings = PssmltSettings {
                    mutations_per_pixel: None,
                    time_budget: Some(budget),
                    seed,
                    preview_every: Duration::from_secs_f64(step / 4.0),
                    ..mlt
                };
                let pt = PathTracer {
                    max_depth: it.max_depth,
                    rr_depth: it.rr_depth,
                };
                let r = match base.as_str() {
                    "pssmlt" => render_pssmlt(scene, pt, &settings, stop, &rec),
                    "pssmlt-bdpt" => render_pssmlt(scene, bdpt, &settings, stop, &rec),
                    _ => {
                        if it.max_depth == u32::MAX {
                            return Err("mmlt needs a finite max_depth".into());
                        }
                        let depths: Vec<MmltDepth> = (1..=it.max_depth as usize)
                            .map(|depth| MmltDepth { bdpt, depth })
                            .collect();
                        render_family(scene, depths, &settings, stop, &rec)
                    }
                }
                .map_err(|e| e.to_string())?;
                rec.offer(r.mutations, || r.image(), true);
            }
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

/// Writes the records as CSV.
pub fn write_csv(path: &Path, records: &[Record]) -> Result<(), String> {
    let mut text = String::from("integrator,seconds,samples,rel_mse,rmse\n");
    for r in records {
        text.push_str(&format!(
            "{},{:.4},{},{:.6e},{:.6e}\n",
            r.integrator, r.seconds, r.samples, r.rel_mse, r.rmse
        ));
    }
    std::fs::write(path, text).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// Reads records written by [`write_csv`] (for re-plotting a study).
pub fn read_csv(path: &Path) -> Result<Vec<Record>, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h)) if h.trim() == "integrator,seconds,samples,rel_mse,rmse" => {}
        _ => {
            return Err(format!(
                "{}:1: expected the header integrator,seconds,samples,rel_mse,rmse",
                path.display()
            ));
        }
    }
    let mut out = Vec::new();
    for (n, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let bad = || format!("{}:{}: malformed record: {line}", path.display(), n + 1);
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if f.len() != 5 || f[0].is_empty() {
            return Err(bad());
        }
        out.push(Record {
            integrator: f[0].to_string(),
            seconds: f[1].parse().map_err(|_| bad())?,
            samples: f[2].parse().map_err(|_| bad())?,
            rel_mse: f[3].parse().map_err(|_| bad())?,
            rmse: f[4].parse().map_err(|_| bad())?,
        });
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
    let file =
        std::fs::File::create(path).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header().map_err(|e| e.to_string())?;
    writer.write_image_data(rgb).map_err(|e| e.to_string())
}
