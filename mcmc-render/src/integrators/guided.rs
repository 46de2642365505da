//! Guided path tracing (Müller, Gross, Novák 2017): unidirectional path
//! tracing whose directions come, at every non-specular vertex, from a
//! one-sample mixture of the BSDF and a learnt SD-tree
//! ([`crate::guiding`]), trained in iterations of doubling length.
//!
//! # Iterations
//! Iteration `k` (from 1) renders `2^(k−1)` samples per pixel, guided by
//! the tree that the iterations before it trained, and records into the
//! tree's building half; then [`SdTree::end_iteration`] splits, swaps and
//! refines. Iteration 1 samples the BSDF alone (nothing is trained yet).
//! With a budget of `N` samples per pixel an iteration is the **last** when
//! the one after it would not fit: when `3·2^(k−1)` exceeds what is left,
//! this one takes all of it (`N = 2^K − 1` gives the paper's schedule
//! `1, 2, …, 2^(K−1)`). With a time budget, the same rule on time: the
//! next iteration is the last when three times its predicted duration
//! (twice the previous one's) exceeds the time left, and it runs until the
//! deadline. Only the **last iteration's** samples make the image (the
//! thesis's choice; not the paper's inverse-variance combination). A run
//! stopped early (Ctrl-C, deadline) returns the iteration in progress when
//! it holds at least as many samples per pixel as the one before, else the
//! one before; stopped passes are discarded as in [`crate::render`].
//!
//! # Checkpoints
//! With `--checkpoint FILE` (session 19) rank 0 saves after every pass of
//! the **last** iteration, in the per-pixel driver's format
//! ([`crate::checkpoint`]): that iteration's film (the image is made of it
//! alone), the passes and samples per pixel done, the non-finite count
//! and, as the integrator's words, the iteration's index, the samples per
//! pixel before it, its length and the samples of it done. The SD-tree is
//! not saved (it is megabytes, far beyond the format's 256 words): a
//! resumed run trains it again — the training iterations are fixed by the
//! sample budget and seed alone, so it is the same tree bit for bit — and
//! then continues the last iteration after its saved passes, with the
//! same `(seed, pass, tile)` streams, into the saved accumulators. So a
//! resumed run ends with the uninterrupted run's bits, at the cost of
//! repeating the training (under half the samples of a budget of
//! `2^K − 1`), and a run stopped during the training has saved nothing.
//! The schedule must be the same: checkpoints need a sample budget
//! (`--spp` or the scene's; a time budget alone decides the iterations by
//! the clock), and a resumed run with another budget is refused
//! ([`check_checkpoint`]).
//!
//! # Radiance records
//! Every vertex whose direction was not sampled from a delta lobe records,
//! into the spatial leaf at its position, the radiance the path collected
//! after it, divided by the throughput up to and including that vertex's
//! scattering (Müller's `L_i = thr(X)/thr(x_k)·Le`, per channel, then the
//! channel mean) and by the mixture density of its direction, so that a
//! quadtree node's sum estimates the flux through it whatever sampled it.
//! With next-event estimation on, what a vertex sees is the MIS-weighted
//! sum (emission found by the sampled ray weighted against light
//! sampling, and the light samples of the vertices after it).
//!
//! # Determinism
//! Work units are the per-pixel driver's tiles, seeded from
//! `(seed, pass, tile)`; each pass's tile films are added and its record
//! buffers merged in tile order, and passes are fixed by the spp budget
//! alone (at most 2¹⁹ camera samples per training pass, to bound record
//! memory). One seed gives the same image and tree on any thread count.
//!
//! # Order in which random numbers are consumed
//! Per camera sample: `next_2d` position in the pixel (`next_2d` lens for a
//! thin lens), then for every surface vertex that is not the last one
//! allowed by `max_depth`, 8 numbers: `next_1d` light selection and
//! `next_2d` light position (drawn even without next-event estimation),
//! `next_1d` tree-or-BSDF choice, `next_1d` BSDF lobe, `next_2d` direction
//! (the tree's or the BSDF's), `next_1d` Russian roulette.

use super::pt::{ScatterOrigin, camera_ray, emitter_hit, environment_hit, next_event};
use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings, SampleStats, rr_probability};
use crate::checkpoint::Progress;
use crate::color::Rgb;
use crate::deadline::Deadline;
use crate::film::{Film, Filter};
use crate::geometry::Ray;
use crate::guiding::{ExactRecords, LeafId, Mixture, RecordBuffer, SdTree};
use crate::observer::Observer;
use crate::render::{image_tiles, unit_source};
use crate::sampling::RandomSource;
use crate::scene::Scene;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Camera samples per training pass at most (record memory: about 16
/// bytes per guided vertex).
const TRAINING_PASS_SAMPLES: u64 = 1 << 19;
/// Samples per pixel per pass at most (as the per-pixel driver).
const PASS_SPP: u64 = 16;

/// The guided path tracer of one iteration.
#[derive(Clone, Copy, Debug)]
pub struct GuidedPathTracer {
    /// Longest path in segments (`u32::MAX` = unbounded).
    pub max_depth: u32,
    /// Depth from which Russian roulette applies.
    pub rr_depth: u32,
    /// Next-event estimation (light sampling, power heuristic against the
    /// mixture density).
    pub nee: bool,
    /// Probability `q` of sampling the tree at a trained, non-specular vertex.
    pub tree_probability: f32,
}

/// A vertex waiting for the radiance of the rest of its path.
#[derive(Clone, Copy, Debug)]
struct PendingVertex {
    leaf: LeafId,
    dir: Vec3,
    /// Throughput after this vertex's scattering, before roulette.
    beta: Rgb,
    pdf: f32,
    /// Radiance collected before this vertex scattered.
    l_before: Rgb,
}

/// Where one work unit's training paths leave their records.
#[derive(Debug, Default)]
pub struct Training {
    /// The records, for [`SdTree::merge`].
    pub records: RecordBuffer,
    path: Vec<PendingVertex>,
}

impl Training {
    /// Records every pending vertex of a path that collected `l` in all.
    fn finish(&mut self, l: Rgb) {
        for v in self.path.drain(..) {
            let d = l - v.l_before;
            let ratio = |a: f32, b: f32| if b > 0.0 { a / b } else { 0.0 };
            let li = (ratio(d.r, v.beta.r) + ratio(d.g, v.beta.g) + ratio(d.b, v.beta.b)) / 3.0;
            self.records.push(v.leaf, v.dir, li / v.pdf);
        }
    }
}

impl GuidedPathTracer {
    /// Radiance arriving along `ray`, guided by `tree`'s sampling half;
    /// with `training`, the path's radiance records are added to it.
    pub fn li<S: RandomSource + ?Sized>(
        &self,
        scene: &Scene,
        ray: Ray,
        source: &mut S,
        tree: &SdTree,
        mut training: Option<&mut Training>,
    ) -> Rgb {
        if self.max_depth == 0 {
            return Rgb::BLACK;
        }
        let mut l = Rgb::BLACK;
        let mut beta = Rgb::WHITE;
        let mut eta_scale = 1.0f32;
        let mut ray = ray;
        let mut depth: u32 = 0;
        let mut from = ScatterOrigin::CAMERA;
        loop {
            let Some(its) = scene.intersect(&ray) else {
                l += environment_hit(scene, beta, ray.d, &from, self.nee);
                break;
            };
            let sp = its.sp;
            let wo_world = -ray.d;
            l += emitter_hit(scene, beta, &sp, wo_world, &from, self.nee);
            if depth.saturating_add(1) >= self.max_depth {
                break;
            }

            let bsdf = scene.bsdf_at(&sp);
            let frame = scene.shading_frame(&sp);
            let wo = frame.to_local(wo_world);
            let mixture = Mixture::new(tree, sp.p, &bsdf, self.tree_probability);

            let u_sel = source.next_1d();
            let u_light = source.next_2d();
            if self.nee {
                l += next_event(
                    scene,
                    beta,
                    &sp,
                    &frame,
                    &bsdf,
                    wo,
                    (u_sel, u_light),
                    |wi, bsdf_pdf| mixture.pdf(wi, bsdf_pdf),
                );
            }

            let u_guide = source.next_1d();
            let u_lobe = source.next_1d();
            let u_dir = source.next_2d();
            let u_rr = source.next_1d();
            let Some(s) = mixture.sample(&bsdf, &frame, wo, u_guide, u_lobe, u_dir) else {
                break;
            };
            if !(s.pdf > 0.0) || s.weight.is_black() {
                break;
            }
            beta *= s.weight;
            eta_scale *= s.eta * s.eta;
            if let Some(t) = training.as_deref_mut()
                && let Some(leaf) = mixture.leaf()
                && !s.is_delta
            {
                t.path.push(PendingVertex {
                    leaf,
                    dir: s.wi_world,
                    beta,
                    pdf: s.pdf,
                    l_before: l,
                });
            }
            from = ScatterOrigin {
                p: sp.p,
                pdf: s.pdf,
                delta: s.is_delta,
            };
            ray = sp.spawn_ray(s.wi_world);
            depth += 1;

            if depth >= self.rr_depth {
                let q = rr_probability(beta, eta_scale);
                if !(u_rr < q) {
                    break;
                }
                beta = beta / q;
            }
            if beta.is_black() {
                break;
            }
        }
        if let Some(t) = training {
            t.finish(l);
        }
        l
    }

    /// Renders `spp` samples of every pixel of `tile` into `film`.
    #[allow(clippy::too_many_arguments)]
    fn render_tile<S: RandomSource + ?Sized>(
        &self,
        scene: &Scene,
        tree: &SdTree,
        (x0, y0, x1, y1): (u32, u32, u32, u32),
        spp: u32,
        source: &mut S,
        film: &mut Film,
        mut training: Option<&mut Training>,
        stats: &mut SampleStats,
    ) {
        for y in y0..y1 {
            for x in x0..x1 {
                for _ in 0..spp {
                    let (raster, ray) = camera_ray(scene, (x, y), source);
                    let l = self.li(scene, ray, source, tree, training.as_deref_mut());
                    if l.is_finite() {
                        film.add_sample(raster, l);
                    } else {
                        stats.nonfinite += 1;
                    }
                }
            }
        }
    }
}

crate::settings! {
    /// Guided path tracer settings, as the registry fills them.
    pub struct GuidedSettings {
        /// Next-event estimation (light sampling, MIS against the guided directions); the thesis's guided tracer has none.
        pub nee: bool = false;
        /// Probability q of sampling the SD-tree instead of the BSDF at a trained non-specular vertex, in [0, 1).
        pub tree_probability: f64 = 0.5, check check_tree_probability;
        /// Spatial split threshold c: a leaf splits after more than c·√(2^k) records in iteration k.
        pub spatial_threshold: f64 = 12000.0, check crate::settings::check::positive;
        /// Quadtree refinement threshold ρ: a node subdivides when its share of the leaf's energy exceeds ρ.
        pub quadtree_threshold: f64 = 0.01, check check_share;
        /// Levels of the initial full spatial tree (2^depth leaves), at most 48.
        pub initial_depth: u32 = 5, check check_initial_depth;
        flatten {
            /// Path depth.
            pub depth: DepthParams = DepthParams::default();
        }
    }
}

/// `q ∈ [0, 1)`: the BSDF must keep a positive probability (delta lobes,
/// directions where the tree has no energy).
fn check_tree_probability(v: &f64) -> Result<(), String> {
    if (0.0..1.0).contains(v) {
        Ok(())
    } else {
        Err("must lie in [0, 1)".into())
    }
}

/// `ρ ∈ (0, 1]`.
fn check_share(v: &f64) -> Result<(), String> {
    if *v > 0.0 && *v <= 1.0 {
        Ok(())
    } else {
        Err("must lie in (0, 1]".into())
    }
}

/// At most [`crate::guiding::sd_tree::MAX_SPATIAL_DEPTH`].
fn check_initial_depth(v: &u32) -> Result<(), String> {
    if *v <= crate::guiding::sd_tree::MAX_SPATIAL_DEPTH {
        Ok(())
    } else {
        Err(format!(
            "must be at most {}",
            crate::guiding::sd_tree::MAX_SPATIAL_DEPTH
        ))
    }
}

/// The doubling schedule (see the module documentation): the length of
/// the next iteration, whose nominal length is `nominal` (`2^(k−1)`), in
/// samples per pixel (`None`: until the deadline), and whether it is the
/// last. `budget`: samples per pixel in all (`None`: a time budget ending
/// at `deadline`), of which `done` are spent; `previous_seconds`: how long
/// the previous iteration took. `mcmc-pg`'s online variant runs the same
/// schedule on mutations per pixel.
pub fn next_iteration(
    budget: Option<u64>,
    done: u64,
    nominal: u64,
    deadline: Deadline,
    previous_seconds: Option<f64>,
) -> (Option<u64>, bool) {
    match budget {
        Some(n) => {
            let (length, last) = spp_iteration(n, done, nominal);
            (Some(length), last)
        }
        None => {
            let left = deadline.time_left().map_or(0.0, |d| d.as_secs_f64());
            if previous_seconds.is_some_and(|t| 3.0 * 2.0 * t > left) {
                (None, true)
            } else {
                (Some(nominal), false)
            }
        }
    }
}

/// [`next_iteration`] under a budget of `n` samples per pixel: the
/// iteration's length and whether it is the last.
fn spp_iteration(n: u64, done: u64, nominal: u64) -> (u64, bool) {
    let left = n.saturating_sub(done);
    if nominal.saturating_mul(3) > left {
        (left, true)
    } else {
        (nominal, false)
    }
}

/// The last iteration of a run of `n` samples per pixel (the doubling
/// schedule of [`next_iteration`]): its index `k` (from 1), the samples
/// per pixel before it and its length.
fn last_iteration(n: u64) -> (u64, u64, u64) {
    let (mut k, mut done, mut nominal) = (1, 0, 1u64);
    loop {
        match spp_iteration(n, done, nominal) {
            (length, true) => return (k, done, length),
            (length, false) => {
                done += length;
                k += 1;
                nominal = nominal.saturating_mul(2);
            }
        }
    }
}

/// Where a checkpoint stands in the last iteration: its index, the
/// samples per pixel before it, its length and the samples of it done
/// (`guided`'s words in the file, [`Progress::extra`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct LastIteration {
    k: u64,
    start: u64,
    length: u64,
    done: u64,
}

impl LastIteration {
    /// The words a checkpoint keeps.
    fn words(&self) -> Vec<u64> {
        vec![self.k, self.start, self.length, self.done]
    }

    /// What `progress` holds: refused (one line) unless a `guided` run of
    /// `budget` samples per pixel could have written it: four words, the
    /// last iteration of that budget's schedule, no more of it done than
    /// its length, and the samples per pixel the film holds.
    fn of(progress: &Progress, budget: Option<u64>) -> Result<LastIteration, String> {
        let Some(n) = budget else {
            return Err("guided resumes only with a sample budget (--spp or the scene's): a time budget alone sets its iterations by the clock".into());
        };
        let [k, start, length, done] = progress.extra[..] else {
            return Err(format!(
                "holds {} words of the integrator's, guided keeps 4: not a checkpoint of guided",
                progress.extra.len()
            ));
        };
        let planned = last_iteration(n);
        if (k, start, length) != planned {
            return Err(format!(
                "holds iteration {k} from {start} spp, {length} spp long; the last iteration of a {n}-spp run is iteration {} from {} spp, {} long: resume with the --spp the checkpoint was written with",
                planned.0, planned.1, planned.2
            ));
        }
        if done > length || progress.spp_done != start + done {
            return Err(format!(
                "impossible counts: {done} of the last iteration's {length} spp done, {} spp in all from {start}",
                progress.spp_done
            ));
        }
        Ok(LastIteration {
            k,
            start,
            length,
            done,
        })
    }
}

/// Checks that a checkpoint's `progress` is one a `guided` run of
/// `budget` samples per pixel (`None`: a time budget alone) wrote (one
/// line if not). The command line checks it on rank 0 before the ranks'
/// start-up handshake, so that a bad file stops every rank with one
/// error; the render checks it too.
pub fn check_checkpoint(progress: &Progress, budget: Option<u64>) -> Result<(), String> {
    LastIteration::of(progress, budget).map(|_| ())
}

/// Where a checkpointed run resumes.
struct Resumed {
    /// The position in the last iteration.
    at: LastIteration,
    /// Passes done.
    pass: u64,
    /// The last iteration's film and the non-finite count: rank 0's (the
    /// only rank that adds into them), `None` on the others.
    sums: Option<(Film, u64)>,
}

/// Where a checkpointed run resumes, from rank 0's checkpoint; on a
/// cluster every rank is told the position and passes (a broadcast).
/// `None`: a fresh start. Collective on a cluster.
fn resume_point(
    run: &RunSettings,
    budget: Option<u64>,
    filter: &Arc<Filter>,
) -> Result<Option<Resumed>, RenderError> {
    let Some(checkpoint) = &run.checkpoint else {
        return Ok(None);
    };
    let local = match &checkpoint.resume {
        Some(p) => {
            let at = LastIteration::of(p, budget).map_err(RenderError::Invalid)?;
            let film = p.film(filter.clone()).map_err(RenderError::Invalid)?;
            Some((at, p.pass, film, p.nonfinite))
        }
        None => None,
    };
    let words = local.as_ref().map_or(Vec::new(), |(at, pass, ..)| {
        let mut w = at.words();
        w.push(*pass);
        w
    });
    let words = match crate::cluster::current() {
        Some(c) => c.broadcast_u64s(words),
        None => words,
    };
    let [k, start, length, done, pass] = words[..] else {
        return Ok(None);
    };
    Ok(Some(Resumed {
        at: LastIteration {
            k,
            start,
            length,
            done,
        },
        pass,
        sums: local.map(|(.., film, n)| (film, n)),
    }))
}

/// One finished (or interrupted) iteration, for the statistics.
#[derive(Clone, Debug, serde::Serialize)]
struct IterationStats {
    spp: u64,
    seconds: f64,
    records: u64,
}

impl GuidedSettings {
    /// The scene's tree before any training (over the scene's box).
    pub fn untrained_tree(&self, scene: &Scene) -> SdTree {
        let bounds = scene
            .geometry
            .bounds()
            .unwrap_or((Vec3::splat(-1.0), Vec3::splat(1.0)));
        SdTree::new(bounds, self.initial_depth)
    }

    /// The per-iteration tracer these settings describe.
    pub fn tracer(&self) -> GuidedPathTracer {
        GuidedPathTracer {
            max_depth: self.depth.limit(),
            rr_depth: self.depth.rr_depth,
            nee: self.nee,
            tree_probability: self.tree_probability as f32,
        }
    }
}

impl IntegratorSettings for GuidedSettings {
    const NAME: &'static str = "guided";
    const ALIASES: &'static [&'static str] = &["guided_path"];
    const DESCRIPTION: &'static str = "Path tracing guided by an SD-tree learnt in doubling iterations (Müller et al. 2017); the last iteration makes the image.";

    fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError> {
        self.render_and_train(scene, run, stop, observer, false)
            .map(|(rendered, _)| rendered)
    }
}

impl GuidedSettings {
    /// Renders as [`IntegratorSettings::render`] and returns the tree too.
    /// With `train_last`, the last iteration also records and ends with
    /// [`SdTree::end_iteration`], so that every sample trains the returned
    /// tree (`mcmc-pg`'s pre-training, where the image is not wanted).
    pub fn render_and_train(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
        train_last: bool,
    ) -> Result<(Rendered, SdTree), RenderError> {
        let start = Instant::now();
        let (width, height) = (scene.film.width, scene.film.height);
        let pixels = u64::from(width) * u64::from(height);
        let filter = Arc::new(Filter::new(scene.film.filter, width, height));
        let mut tree = self.untrained_tree(scene);
        let tracer = self.tracer();
        let budget_spp = run.samples_per_pixel(scene.sample_count).map(u64::from);
        let deadline = Deadline::new(start, run.time_budget);
        let out_of_time = || deadline.passed();
        let tiles = image_tiles(width, height);
        let training_pass_spp = (TRAINING_PASS_SAMPLES / pixels.max(1)).clamp(1, PASS_SPP);

        let mut iterations: Vec<IterationStats> = Vec::new();
        let mut previous: Option<(Vec<Rgb>, u64)> = None;
        let mut image: Option<(Vec<Rgb>, u64)> = None;
        let mut spp_done = 0u64;
        let mut pass = 0u64;
        let mut stats = SampleStats::default();
        let mut interrupted = false;
        let mut nominal = 1u64;
        let cluster = crate::cluster::current();
        // A checkpoint is written in the last iteration only (module docs).
        let saves = run.checkpoint.is_some() && !train_last;
        let mut resume = if saves {
            resume_point(run, budget_spp, &filter)?
        } else {
            None
        };
        // The samples per pixel resumed from, once the run got there.
        let mut resumed_from = None;
        let mut checkpoint_error: Option<String> = None;
        for k in 1u32.. {
            // Is this the last iteration, and how long is it? (On a
            // cluster rank 0's clock decides for every rank.)
            let (iteration_spp, last) = next_iteration(
                budget_spp,
                spp_done,
                nominal,
                deadline,
                iterations.last().map(|it| it.seconds),
            );
            let (iteration_spp, last) = agreed_iteration(iteration_spp, last);
            let iteration_start = Instant::now();
            let mut film = Film::new(width, height, filter.clone());
            let mut done = 0u64;
            let mut records = 0u64;
            // The planned last iteration of a sample budget is saved, and
            // a resumed run continues it after its saved passes.
            let saving = saves && last && iteration_spp.is_some();
            let resumed_here = if saving { resume.take() } else { None };
            if let Some(Resumed {
                at,
                pass: saved_pass,
                sums: saved,
            }) = resumed_here
            {
                let here = (u64::from(k), spp_done, iteration_spp.unwrap_or(0));
                if here != (at.k, at.start, at.length) {
                    return Err(RenderError::Invalid(format!(
                        "checkpoint: holds iteration {} from {} spp, this run's last is iteration {} from {} spp",
                        at.k, at.start, here.0, here.1
                    )));
                }
                done = at.done;
                spp_done += at.done;
                pass = saved_pass;
                resumed_from = Some(spp_done);
                if let Some((saved_film, nonfinite)) = saved {
                    film = saved_film;
                    stats.nonfinite = nonfinite;
                }
            }
            loop {
                if iteration_spp.is_some_and(|n| done >= n) {
                    break;
                }
                let halt = stop.load(Ordering::Relaxed) || out_of_time();
                if cluster.map_or(halt, |c| c.any(halt)) {
                    interrupted = true;
                    break;
                }
                let record = !last || train_last;
                let cap = if record { training_pass_spp } else { PASS_SPP };
                let spp = iteration_spp.map_or(cap, |n| (n - done).min(cap)) as u32;
                let aborted = AtomicBool::new(false);
                let check_abort = || {
                    if stop.load(Ordering::Relaxed) || out_of_time() {
                        aborted.store(true, Ordering::Relaxed);
                    }
                    aborted.load(Ordering::Relaxed)
                };
                let tree_ref = &tree;
                // On a cluster this rank renders the tiles dealt to it.
                let results: Vec<(usize, Film, Option<Training>, SampleStats)> = tiles
                    .par_iter()
                    .enumerate()
                    .filter(|(i, _)| crate::cluster::owns(cluster, *i))
                    .map(|(i, &(x0, y0, x1, y1))| {
                        let mut tile =
                            Film::for_tile(width, height, x0, y0, x1, y1, filter.clone());
                        let mut st = SampleStats::default();
                        let mut training = record.then(Training::default);
                        if check_abort() {
                            return (i, tile, training, st);
                        }
                        let mut src = unit_source(run.seed, pass, i as u64);
                        tracer.render_tile(
                            scene,
                            tree_ref,
                            (x0, y0, x1, y1),
                            spp,
                            &mut src,
                            &mut tile,
                            training.as_mut(),
                            &mut st,
                        );
                        observer.progress(u64::from((x1 - x0) * (y1 - y0)) * u64::from(spp));
                        (i, tile, training, st)
                    })
                    .collect();
                let aborted = aborted.load(Ordering::Relaxed);
                if cluster.map_or(aborted, |c| c.any(aborted)) {
                    interrupted = true;
                    break;
                }
                // Tile films and counters in tile order (every rank's on
                // rank 0); every rank merges every tile's records.
                let units = results.iter().map(|(i, tile, _, st)| (*i, tile, *st));
                for st in &crate::render::reduce_pass(&mut film, units, &filter) {
                    stats.merge(st);
                }
                if record {
                    let local = results
                        .iter()
                        .filter_map(|r| Some((r.0, &r.2.as_ref()?.records)));
                    let gathered = cluster.map(|c| all_tile_records(c, local.clone()));
                    let buffers: Vec<&RecordBuffer> = match &gathered {
                        Some(all) => all.iter().collect(),
                        None => local.map(|(_, b)| b).collect(),
                    };
                    records += buffers.iter().map(|b| b.len() as u64).sum::<u64>();
                    tree.merge(buffers.iter().copied());
                }
                done += u64::from(spp);
                spp_done += u64::from(spp);
                pass += 1;
                if let Some(c) = &run.checkpoint
                    && saving
                    && crate::cluster::is_root()
                    && checkpoint_error.is_none()
                {
                    let at = LastIteration {
                        k: u64::from(k),
                        start: spp_done - done,
                        length: iteration_spp.unwrap_or(0),
                        done,
                    };
                    let mut progress = Progress::of(pass, spp_done, stats.nonfinite, &film);
                    progress.extra = at.words();
                    checkpoint_error =
                        crate::checkpoint::save(&c.path, c.fingerprint, &progress).err();
                }
                let best = |film: &Film| match &previous {
                    Some((img, n)) if *n > done => img.clone(),
                    _ => film.develop(0.0),
                };
                observer.snapshot(&|| best(&film), spp_done * pixels);
            }
            iterations.push(IterationStats {
                spp: done,
                seconds: iteration_start.elapsed().as_secs_f64(),
                records,
            });
            // The iteration in progress is the result if it holds at least
            // as many samples as the one before.
            let current = (done > 0 && previous.as_ref().is_none_or(|(_, n)| done >= *n))
                .then(|| (film.develop(0.0), done));
            if last || interrupted {
                image = current.or(previous.take());
                if train_last && records > 0 {
                    tree.end_iteration(k, self.spatial_threshold, self.quadtree_threshold);
                }
                break;
            }
            previous = current;
            tree.end_iteration(k, self.spatial_threshold, self.quadtree_threshold);
            nominal = nominal.saturating_mul(2);
        }

        let seconds = start.elapsed().as_secs_f64();
        let (image, image_spp) = image.unwrap_or_else(|| (vec![Rgb::BLACK; pixels as usize], 0));
        let size = tree.size();
        let samples = spp_done * pixels;
        let samples_per_second = if seconds > 0.0 {
            samples as f64 / seconds
        } else {
            0.0
        };
        let mut statistics = serde_json::json!({
            "samples_per_second": samples_per_second,
            "spp": image_spp,
            "spp_total": spp_done,
            "iterations": iterations.len(),
            "spp_per_iteration": iterations.iter().map(|i| i.spp).collect::<Vec<_>>(),
            "seconds_per_iteration": iterations.iter().map(|i| i.seconds).collect::<Vec<_>>(),
            "records_per_iteration": iterations.iter().map(|i| i.records).collect::<Vec<_>>(),
            "tree_nodes": size.spatial_nodes + size.sampling_nodes + size.building_nodes,
            "tree_memory_bytes": size.bytes,
            "tree": size,
            "nonfinite_samples": stats.nonfinite,
            "bvh_build_seconds": scene.geometry.build_time.as_secs_f64(),
            "triangles": scene.geometry.triangles,
        });
        if let (Some(c), true) = (&run.checkpoint, saves) {
            statistics["checkpoint"] =
                c.statistics("spp", resumed_from, spp_done, &checkpoint_error);
        }
        let rendered = Rendered {
            image,
            seconds,
            samples,
            interrupted,
            statistics: match statistics {
                serde_json::Value::Object(m) => m,
                _ => serde_json::Map::new(),
            },
            nonfinite_dump: None,
            layers: Vec::new(),
            summary: format!(
                "{} iterations, {} spp in the image ({} in all) in {:.2} s, tree {} spatial leaves, {:.1} MB{}",
                iterations.len(),
                image_spp,
                spp_done,
                seconds,
                size.spatial_leaves,
                size.bytes as f64 / 1e6,
                if interrupted { ", stopped early" } else { "" }
            ),
        };
        Ok((rendered, tree))
    }
}

/// An iteration's length and whether it is the last ([`next_iteration`]),
/// on a cluster rank 0's for every rank (with a time budget the ranks'
/// clocks could disagree).
pub(crate) fn agreed_iteration(length: Option<u64>, last: bool) -> (Option<u64>, bool) {
    match crate::cluster::current() {
        Some(c) => {
            let agreed = c.broadcast_u64s(vec![length.unwrap_or(u64::MAX), u64::from(last)]);
            ((agreed[0] != u64::MAX).then_some(agreed[0]), agreed[1] == 1)
        }
        None => (length, last),
    }
}

/// Every rank's tile record buffers (`local`: this rank's, with their
/// tile indices), in tile order, on every rank: bit-exact, so every rank
/// merges the same records into its tree in the same order.
fn all_tile_records<'a>(
    cluster: &dyn crate::cluster::Cluster,
    local: impl Iterator<Item = (usize, &'a RecordBuffer)>,
) -> Vec<RecordBuffer> {
    let mut numbers = Vec::new();
    for (tile, buffer) in local {
        numbers.extend([tile as f64, buffer.len() as f64]);
        buffer.to_f64s(&mut numbers);
    }
    let all = cluster.all_gather_f64s(numbers);
    let mut input = &all[..];
    let mut tiles = Vec::new();
    while let [tile, n, rest @ ..] = input {
        input = rest;
        // Every rank runs the same binary (checked at start-up): a short
        // message is a bug, not an input error.
        let buffer = RecordBuffer::from_f64s(&mut input, *n as usize).expect("a tile's records");
        tiles.push((*tile as usize, buffer));
    }
    tiles.sort_by_key(|t| t.0);
    tiles.into_iter().map(|t| t.1).collect()
}

/// Records of paths that MCMC chains trace with the guided tracer
/// (`mcmc-pg` online, `smcmc`'s guided shift online): per-thread slots,
/// each with the tracer's path buffer and exact fixed-point sums per
/// building quadtree leaf ([`ExactRecords`]), whose integer totals do not
/// depend on which thread recorded what, or in which order, so one seed
/// trains the same tree on any thread count. A thread locks only its own
/// slot (its index in the pool), so the locks are uncontended.
#[derive(Default)]
pub struct RecordSink {
    slots: Vec<Mutex<RecordSlot>>,
}

/// One thread's records: the tracer's path buffer and the exact sums.
#[derive(Default)]
struct RecordSlot {
    training: Training,
    exact: ExactRecords,
}

impl RecordSink {
    /// One slot per thread of the current pool, plus one for callers
    /// outside it.
    pub fn new() -> Self {
        let n = rayon::current_num_threads() + 1;
        RecordSink {
            slots: (0..n).map(|_| Mutex::default()).collect(),
        }
    }

    /// Runs `trace` with the calling thread's path buffer and adds the
    /// records it made to the thread's exact sums over `tree`'s building
    /// leaves; returns what `trace` returns.
    pub fn record<T>(&self, tree: &SdTree, trace: impl FnOnce(&mut Training) -> T) -> T {
        let last = self.slots.len() - 1;
        let i = rayon::current_thread_index().map_or(last, |i| i.min(last));
        let mut slot = self.slots[i].lock().unwrap_or_else(|e| e.into_inner());
        let RecordSlot { training, exact } = &mut *slot;
        let out = trace(training);
        tree.accumulate(&mut training.records, exact);
        out
    }

    /// The exact sums of every slot, for [`SdTree::merge_exact`]; on a
    /// cluster, every rank's (each rank's chains recorded only its share;
    /// exact sums merge in any order). Collective on a cluster: every rank
    /// calls it for the same iterations.
    pub fn into_parts(self) -> Vec<ExactRecords> {
        let parts: Vec<ExactRecords> = self
            .slots
            .into_iter()
            .map(|m| m.into_inner().unwrap_or_else(|e| e.into_inner()).exact)
            .collect();
        match crate::cluster::current() {
            Some(_) => all_exact_records(parts),
            None => parts,
        }
    }
}

/// Every rank's record sums, on every rank (bit-exact). Collective.
fn all_exact_records(parts: Vec<ExactRecords>) -> Vec<ExactRecords> {
    let mut words = Vec::new();
    parts.iter().for_each(|p| p.to_words(&mut words));
    let all = crate::cluster::all_gather_words(words);
    let mut input = &all[..];
    let mut out = Vec::new();
    while !input.is_empty() {
        // Every rank runs the same binary: a short message is a bug.
        out.push(ExactRecords::from_words(&mut input).expect("a rank's record sums"));
    }
    out
}
