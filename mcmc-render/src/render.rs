//! The render driver: runs an integrator over the image in passes of work
//! units on a rayon pool, with a sample or time budget and a stop flag.
//!
//! Determinism: the work of a pass is cut into units that do not depend on
//! the thread count (image tiles for pixel-driven integrators, fixed chunks
//! of light paths for splatting ones). Each unit seeds its own generator
//! from `(seed, pass, unit)`, renders into a private film, and the unit
//! films are added into the image in unit order. One seed therefore gives
//! a bit-identical image on 1 or 8 threads.
//!
//! Stopping (Ctrl-C or the time budget) discards the pass in flight, so the
//! result always holds whole passes and is normalised by what it holds.
//!
//! Distributed runs ([`crate::cluster`]): every rank runs every pass but
//! renders only the units [`owns`] deals it; rank 0 gathers the pass's unit
//! films and adds them in unit order, as one process does, so the image is
//! bit-identical for any number of ranks. A pass stopped on any rank is
//! discarded on all of them.
//!
//! Checkpoints ([`crate::checkpoint`]): with one set, rank 0 saves the
//! film and the pass count after every pass, and a run that finds one
//! continues after its last pass, ending with the uninterrupted run's bits.

use crate::checkpoint::{Checkpoint, Progress};
use crate::cluster::{Cluster, owns};
use crate::deadline::Deadline;
use crate::film::{Film, Filter};
use crate::integrators::{Integrator, Rendered, RunSettings, SampleDomain, SampleStats};
use crate::observer::Observer;
use crate::sampling::{IndependentSource, PixelSource};
use crate::scene::Scene;
use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Tile edge in pixels for pixel-driven integrators.
const TILE: u32 = 32;
/// Light-path chunks per pass for splatting integrators (fixed, so that the
/// image does not depend on the thread count).
const LIGHT_CHUNKS: usize = 8;

/// What to render and for how long.
#[derive(Clone, Debug)]
pub struct RenderSettings {
    /// Samples per pixel (light paths per pixel for light tracing).
    /// `None` with a time budget means "until the budget is spent".
    pub spp: Option<u32>,
    /// Wall-clock budget.
    pub time_budget: Option<Duration>,
    /// Seed of every random stream.
    pub seed: u64,
}

/// The outcome of a render.
#[derive(Clone, Debug)]
pub struct RenderResult {
    /// Accumulated film.
    pub film: Film,
    /// Completed samples per pixel.
    pub spp_done: u64,
    /// Total samples (camera samples or light paths).
    pub samples: u64,
    /// Splat normalisation: light paths per pixel (0 for pixel-driven integrators).
    pub paths_per_pixel: f64,
    /// Wall-clock seconds spent rendering.
    pub seconds: f64,
    /// True when stopped early (Ctrl-C or time budget) before the requested spp.
    pub interrupted: bool,
    /// Sampler counters.
    pub stats: SampleStats,
    /// This rank's share of a distributed run: work units rendered and
    /// seconds spent rendering them (zeros without a cluster).
    pub rank_work: (u64, f64),
    /// With a checkpoint: samples per pixel it resumed from, and the first
    /// error writing it (the run goes on without).
    pub checkpoint: Option<(u64, Option<String>)>,
}

impl RenderResult {
    /// The developed image, row-major.
    pub fn image(&self) -> Vec<crate::color::Rgb> {
        self.film.develop(self.paths_per_pixel)
    }
}

/// SplitMix64 finaliser: decorrelates seeds built from small integers.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The generator of one work unit `unit` of pass `pass` (also used by
/// integrators that run their own passes, such as `vcm` and `guided`).
pub fn unit_source(seed: u64, pass: u64, unit: u64) -> PixelSource {
    let s = mix(mix(mix(seed) ^ pass) ^ unit.wrapping_mul(0x2545_f491_4f6c_dd1d));
    IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(s))
}

/// Samples per pixel of each pass: small first passes for quick previews,
/// then at most `cap`; fixed by `total` alone (never by timing or threads).
fn pass_schedule(pass: u64, cap: u32) -> u32 {
    (1u32 << pass.min(8)).min(cap)
}

/// The work units of pixel-driven integrators: `TILE`-pixel squares
/// `(x0, y0, x1, y1)` (half-open) in scanline order, fixed by the image
/// size alone.
pub(crate) fn image_tiles(width: u32, height: u32) -> Vec<(u32, u32, u32, u32)> {
    (0..height.div_ceil(TILE))
        .flat_map(|ty| {
            (0..width.div_ceil(TILE)).map(move |tx| {
                let x0 = tx * TILE;
                let y0 = ty * TILE;
                (x0, y0, (x0 + TILE).min(width), (y0 + TILE).min(height))
            })
        })
        .collect()
}

/// Adds a pass's unit films into `film` in unit order and returns their
/// counters ([`crate::cluster::reduce_units`]: every rank's on rank 0).
pub(crate) fn reduce_pass<'a>(
    film: &mut Film,
    units: impl Iterator<Item = (usize, &'a Film, SampleStats)>,
    filter: &Arc<Filter>,
) -> Vec<SampleStats> {
    let units = units.map(|(i, f, st)| (i, f, (Vec::new(), vec![st.nonfinite])));
    crate::cluster::reduce_units(film, units, filter)
        .into_iter()
        .map(|(_, counts)| SampleStats {
            nonfinite: counts[0],
        })
        .collect()
}

/// A light-path pass's unit films (this rank's chunks) with their counters.
fn light_units<'a>(
    films: &'a [Film],
    stats: Vec<SampleStats>,
    cluster: Option<&dyn Cluster>,
) -> Vec<(usize, &'a Film, SampleStats)> {
    films
        .iter()
        .zip(stats)
        .enumerate()
        .filter(|(i, _)| owns(cluster, *i))
        .map(|(i, (f, st))| (i, f, st))
        .collect()
}

/// Where a checkpointed run starts: `(pass, spp done, non-finite count,
/// film)` from rank 0's checkpoint, every rank told the counts (the film
/// stays on rank 0, the only one that adds into it).
fn resume_point(
    checkpoint: &Checkpoint,
    cluster: Option<&dyn Cluster>,
    filter: &Arc<Filter>,
) -> Option<(u64, u64, u64, Option<Film>)> {
    let local = checkpoint.resume.as_ref().map(|p| {
        let film = p
            .film(filter.clone())
            .expect("the command line checked the checkpoint against the scene");
        (p.pass, p.spp_done, p.nonfinite, film)
    });
    let Some(c) = cluster else {
        return local.map(|(a, b, n, f)| (a, b, n, Some(f)));
    };
    let counts = local.as_ref().map_or(vec![], |&(a, b, n, _)| vec![a, b, n]);
    match c.broadcast_u64s(counts)[..] {
        [pass, spp_done, nonfinite] => Some((pass, spp_done, nonfinite, local.map(|l| l.3))),
        _ => None,
    }
}

/// Renders `scene` with `integrator`. `stop` aborts (the pass in flight is discarded).
pub fn render(
    scene: &Scene,
    integrator: &dyn Integrator,
    settings: &RenderSettings,
    stop: &AtomicBool,
    observer: &dyn Observer,
) -> RenderResult {
    render_checkpointed(scene, integrator, settings, None, stop, observer)
}

/// [`render`], saving its progress to `checkpoint` after every pass and
/// continuing from the progress the checkpoint was loaded with.
pub fn render_checkpointed(
    scene: &Scene,
    integrator: &dyn Integrator,
    settings: &RenderSettings,
    checkpoint: Option<&Checkpoint>,
    stop: &AtomicBool,
    observer: &dyn Observer,
) -> RenderResult {
    let (width, height) = (scene.film.width, scene.film.height);
    let filter = Arc::new(Filter::new(scene.film.filter, width, height));
    let mut film = Film::new(width, height, filter.clone());
    let cluster = crate::cluster::current();
    let start = Instant::now();
    let deadline = Deadline::new(start, settings.time_budget);
    let target = settings.spp.map(u64::from);
    let pixels = width as u64 * height as u64;
    let domain = integrator.domain();
    let cap = match domain {
        SampleDomain::Pixels => 16,
        SampleDomain::LightPaths | SampleDomain::PixelsWithSplats => 4,
    };
    let splats = domain != SampleDomain::Pixels;
    let mut spp_done = 0u64;
    let mut stats = SampleStats::default();
    let mut interrupted = false;
    let mut pass = 0u64;
    let mut checkpoint_state = None;
    if let Some(c) = checkpoint {
        let mut resumed_spp = 0;
        if let Some((p, s, n, f)) = resume_point(c, cluster, &filter) {
            (pass, spp_done, stats.nonfinite, resumed_spp) = (p, s, n, s);
            if let Some(f) = f {
                film = f;
            }
        }
        checkpoint_state = Some((resumed_spp, None));
    }
    let out_of_time = || deadline.passed();
    let mine = |unit: usize| owns(cluster, unit);

    let tiles = image_tiles(width, height);
    let units = if splats { LIGHT_CHUNKS } else { tiles.len() };
    let my_units = (0..units).filter(|&i| mine(i)).count() as u64;
    let mut rank_work = (0u64, 0.0f64);
    let mut light_films: Vec<Film> = if splats {
        (0..LIGHT_CHUNKS)
            .map(|_| {
                // BDPT also adds camera samples: it needs both accumulators.
                if domain == SampleDomain::PixelsWithSplats {
                    Film::new(width, height, filter.clone())
                } else {
                    Film::new_splat_only(width, height, filter.clone())
                }
            })
            .collect()
    } else {
        Vec::new()
    };

    loop {
        if let Some(t) = target
            && spp_done >= t
        {
            break;
        }
        // On a cluster every rank must stop before the same pass.
        let stopping = stop.load(Ordering::Relaxed) || out_of_time();
        if cluster.map_or(stopping, |c| c.any(stopping)) {
            interrupted = target.is_none_or(|t| spp_done < t);
            break;
        }
        let mut spp = pass_schedule(pass, cap);
        if let Some(t) = target {
            spp = spp.min((t - spp_done) as u32);
        }
        let aborted = AtomicBool::new(false);
        let check_abort = || {
            if stop.load(Ordering::Relaxed) || out_of_time() {
                aborted.store(true, Ordering::Relaxed);
            }
            aborted.load(Ordering::Relaxed)
        };
        let seed = settings.seed;
        let pass_start = Instant::now();
        let busy = std::cell::Cell::new(0.0);
        // Called once the local units are done: the time they took, and
        // whether any rank stopped (then every rank discards the pass).
        let pass_aborted = |aborted: &AtomicBool| {
            busy.set(pass_start.elapsed().as_secs_f64());
            let local = aborted.load(Ordering::Relaxed);
            let any = cluster.map_or(local, |c| c.any(local));
            aborted.store(any, Ordering::Relaxed);
            any
        };
        // This rank's unit films of the pass (tiles are made per pass, the
        // light-path films are reused).
        let tile_films: Vec<(usize, Film, SampleStats)>;
        let pass_units: Vec<(usize, &Film, SampleStats)> = match domain {
            SampleDomain::Pixels => {
                tile_films = tiles
                    .par_iter()
                    .enumerate()
                    .filter(|&(i, _)| mine(i))
                    .map(|(i, &(x0, y0, x1, y1))| {
                        let mut tile =
                            Film::for_tile(width, height, x0, y0, x1, y1, filter.clone());
                        let mut st = SampleStats::default();
                        if check_abort() {
                            return (i, tile, st);
                        }
                        let mut src = unit_source(seed, pass, i as u64);
                        integrator.render_pixels(
                            scene,
                            (x0, y0, x1, y1),
                            spp,
                            &mut src,
                            &mut tile,
                            &mut st,
                        );
                        observer.progress(((x1 - x0) * (y1 - y0)) as u64 * spp as u64);
                        (i, tile, st)
                    })
                    .collect();
                tile_films.iter().map(|(i, t, st)| (*i, t, *st)).collect()
            }
            SampleDomain::PixelsWithSplats => {
                // Splats land anywhere, so each chunk renders the rows
                // y ≡ chunk (mod LIGHT_CHUNKS) into a whole-image film.
                let results: Vec<SampleStats> = light_films
                    .par_iter_mut()
                    .enumerate()
                    .map(|(i, f)| {
                        f.clear();
                        let mut st = SampleStats::default();
                        if !mine(i) {
                            return st;
                        }
                        let mut src = unit_source(seed, pass, i as u64);
                        for y in (i as u32..height).step_by(LIGHT_CHUNKS) {
                            if check_abort() {
                                return st;
                            }
                            for x in 0..width {
                                for _ in 0..spp {
                                    integrator.sample(scene, Some((x, y)), &mut src, f, &mut st);
                                }
                            }
                            observer.progress(width as u64 * spp as u64);
                        }
                        st
                    })
                    .collect();
                light_units(&light_films, results, cluster)
            }
            SampleDomain::LightPaths => {
                let paths = pixels * spp as u64;
                let per = paths / LIGHT_CHUNKS as u64;
                let extra = paths % LIGHT_CHUNKS as u64;
                let results: Vec<SampleStats> = light_films
                    .par_iter_mut()
                    .enumerate()
                    .map(|(i, f)| {
                        f.clear();
                        let mut st = SampleStats::default();
                        if !mine(i) {
                            return st;
                        }
                        let n = per + u64::from((i as u64) < extra);
                        let mut src = unit_source(seed, pass, i as u64);
                        let mut done = 0u64;
                        while done < n {
                            if check_abort() {
                                return st;
                            }
                            let batch = (n - done).min(65_536);
                            for _ in 0..batch {
                                integrator.sample(scene, None, &mut src, f, &mut st);
                            }
                            done += batch;
                            observer.progress(batch);
                        }
                        st
                    })
                    .collect();
                light_units(&light_films, results, cluster)
            }
        };
        // Whole passes only: a pass stopped on any rank is discarded.
        if pass_aborted(&aborted) {
            interrupted = true;
            break;
        }
        let pass_stats = reduce_pass(&mut film, pass_units.into_iter(), &filter);
        rank_work.0 += my_units;
        rank_work.1 += busy.get();
        for st in &pass_stats {
            stats.merge(st);
        }
        spp_done += spp as u64;
        pass += 1;
        if let (Some(c), Some((_, error))) = (checkpoint, &mut checkpoint_state)
            && crate::cluster::is_root()
            && error.is_none()
        {
            let progress = Progress::of(pass, spp_done, stats.nonfinite, &film);
            *error = crate::checkpoint::save(&c.path, c.fingerprint, &progress).err();
        }
        let ppp = if splats { spp_done as f64 } else { 0.0 };
        observer.snapshot(&|| film.develop(ppp), spp_done * pixels);
    }
    let paths_per_pixel = if splats { spp_done as f64 } else { 0.0 };
    RenderResult {
        film,
        spp_done,
        samples: spp_done * pixels,
        paths_per_pixel,
        seconds: start.elapsed().as_secs_f64(),
        interrupted,
        stats,
        rank_work,
        checkpoint: checkpoint_state,
    }
}

/// Renders `scene` with a per-pixel `integrator` to `run`'s budget (the
/// scene's `sample_count` when neither samples nor time are given) and
/// reports it for the registry.
pub fn run_per_pixel(
    scene: &Scene,
    integrator: &dyn Integrator,
    run: &RunSettings,
    stop: &AtomicBool,
    observer: &dyn Observer,
) -> Rendered {
    let spp = run.samples_per_pixel(scene.sample_count);
    let settings = RenderSettings {
        spp,
        time_budget: run.time_budget,
        seed: run.seed,
    };
    let r = render_checkpointed(
        scene,
        integrator,
        &settings,
        run.checkpoint.as_ref(),
        stop,
        observer,
    );
    let samples_per_second = if r.seconds > 0.0 {
        r.samples as f64 / r.seconds
    } else {
        0.0
    };
    let statistics = serde_json::json!({
        "samples_per_second": samples_per_second,
        "spp": r.spp_done,
        "nonfinite_samples": r.stats.nonfinite,
        "bvh_build_seconds": scene.geometry.build_time.as_secs_f64(),
        "triangles": scene.geometry.triangles,
    });
    let mut statistics = statistics;
    if let (Some(c), Some((resumed, error))) = (&run.checkpoint, &r.checkpoint) {
        statistics["checkpoint"] = c.statistics("spp", resumed, r.spp_done, error);
    }
    let statistics = crate::cluster::with_ranks(
        statistics,
        serde_json::json!({"units": r.rank_work.0, "busy_seconds": r.rank_work.1, "seconds": r.seconds}),
    );
    Rendered {
        image: r.image(),
        seconds: r.seconds,
        samples: r.samples,
        interrupted: r.interrupted,
        statistics: match statistics {
            serde_json::Value::Object(m) => m,
            _ => serde_json::Map::new(),
        },
        nonfinite_dump: None,
        layers: Vec::new(),
        summary: format!(
            "{} spp in {:.2} s ({:.3} M samples/s){}",
            r.spp_done,
            r.seconds,
            samples_per_second / 1e6,
            if r.interrupted { ", stopped early" } else { "" }
        ),
    }
}
