//! Energy redistribution path tracing (Cline, Talbot & Egbert 2005;
//! Mitsuba 0.6's `erpt`): path-traced seed paths, each starting a number
//! of short Metropolis chains in proportion to its energy, every chain step
//! depositing the same energy.
//!
//! # Seeds
//!
//! Every pass draws one camera walk per pixel (a raster position uniform
//! in the pixel, no Russian roulette, at most `max_depth + 1` vertices;
//! 64 when unbounded) and, at every prefix of it, the two paths path
//! tracing with next-event estimation forms: the walk ending on an emitter
//! (`s = 0`; an escaped walk ends on the environment, at infinity) and the
//! walk connected to an emitter point drawn as BDPT draws it (`s = 1`; at
//! infinity, a direction). Each is a path state ([`crate::path_space::Path`])
//! with energy `e(x) = lum f(x) / (p_0(x) + p_1(x))`, `p_s` the path's
//! density under technique `s` ([`Path::log_regrowth_density`]; `p_1 = 0`
//! for a path of one segment, which `s = 1` never forms: it connects to a
//! camera-walk vertex, not to the camera): the balance heuristic over the
//! two techniques, so the energies of one camera walk sum to its pixel's
//! path-traced luminance estimate.
//!
//! # Chains and the equal-deposition rule
//!
//! A seed starts `n_c(x) = ⌊ξ + e(x) / (n_m e_d)⌋` chains (`ξ` uniform,
//! capped by `max_chains` when it is set: biased, as in Mitsuba), each of
//! `n_m = chain_length` Metropolis–Hastings steps of the path-space
//! mutation mixture run by `mcmc-core` (`MetropolisHastings` over
//! [`Path`]s with [`PathTarget`]: no acceptance test here). Every step
//! deposits `e_d · f(y)/lum f(y)` at the raster position of the state it
//! moves to, as expected values (`α` at the proposal, `1 − α` at the
//! current state). With `e_d = L̄ / (n_m · num_chains)`, `L̄` the mean
//! pixel luminance estimated beforehand from `luminance_samples`
//! independent camera walks, a pass starts `num_chains` chains per pixel
//! on average; the chains start in proportion to `lum f` and MH keeps that
//! distribution, so one pass's deposits are an unbiased image (for any
//! `e_d`: it sets the count of chains, not the mean). The image is the
//! mean of the passes.
//!
//! # Defaults (Mitsuba 0.6 `erpt`)
//!
//! `numChains` 1, `maxChains` 0 (no cap), `chainLength` 100 (its code;
//! its doc block says 1), `luminanceSamples` 15 000, `bidirectionalMutation`
//! off, the lens, caustic and multi-chain perturbations on (the last two
//! since session 20), manifold perturbation off. Mitsuba's direct-lighting
//! pass (`directSamples`, 16 there) is `direct_samples`, −1 (off) here
//! (session 21; [`super::chain_passes`], shared with `mlt`): paths of one
//! and two segments by path tracing at `direct_samples` spp, and the seeds,
//! the luminance estimate and the chains on three segments or more, as
//! Mitsuba's `separateDirect`. The estimate `L̄` then holds the chains'
//! paths alone, so a pass still starts `num_chains` chains per pixel on
//! average.
//!
//! Each chain draws from its own stream, seeded by one draw of its band's
//! stream (session 20): the band's stream then gives the same seeds and
//! chain counts whatever the mutations consume, so two mixtures run on the
//! same seeds differ by their redistribution alone (the paired agreement
//! test in `tests/erpt.rs`).
//!
//! Work units are bands of rows with their own streams, summed in order,
//! so an image is bit-identical for any thread count; Ctrl-C and `--time`
//! stop after the last complete pass (a pass interrupted midway is
//! dropped; its mutations are reported as `dropped_pass_mutations`). They
//! are checked before every chain step, and between blocks of the
//! luminance estimate, which then uses the walks it took (reported as
//! `luminance_samples`), so no setting (`chain_length` or
//! `luminance_samples` of 10^15) keeps a run past `--time`.
//!
//! On a cluster ([`crate::cluster`], `mpirun`) band `b` of every pass is
//! rendered by rank `b mod K`, and rank 0 adds the bands' films and
//! counters in band order, as one process does; each block of the
//! luminance estimate's walks is split over the ranks and gathered in walk
//! order. Every rank agrees (one all-gather of a flag) before each block
//! of walks, before each pass and after it whether any rank was stopped,
//! so all ranks end at the same pass and rank 0 writes the passes done:
//! the image is the single process's for any number of ranks.
//!
//! With `--checkpoint FILE` (session 18) rank 0 saves after every pass, in
//! the per-pixel driver's format ([`crate::checkpoint`]), the film's splats,
//! the passes done and, as the integrator's words, the seeds and chains
//! counted, the luminance estimate and the chain statistics; a resumed run
//! takes the estimate from the file (its walks are not redrawn) and goes on
//! from the next pass, whose streams `(seed, pass, band)` and additions are
//! the uninterrupted run's, so it ends with its bits.

use super::chain_passes::{
    WithPasses, add_pass, check_direct_depth, check_pass_samples, direct_pass, min_segments,
    pass_samples,
};
use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings};
use crate::checkpoint::{Checkpoint, Progress};
use crate::cluster::Cluster;
use crate::color::Rgb;
use crate::deadline::Deadline;
use crate::film::{Film, Filter};
use crate::integrators::bdpt::generate_camera_subpath;
use crate::integrators::path_vertex::{Vertex, VertexKind};
use crate::observer::Observer;
use crate::path_space::proposal_clock::{ProposalClock, mutation_types};
use crate::path_space::walk::{ChainSource, light_walk};
use crate::path_space::{Path, PathMutations, PathTarget};
use crate::pss::PathSample;
use crate::scene::Scene;
use crate::settings::check;
use glam::Vec2;
use mcmc_core::chain::{Algorithm, ChainState};
use mcmc_core::kernel::{Kernel, Mixture};
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::rng::{ChainRng, child_rng, splitmix64, stream_rng, uniform};
use mcmc_core::sample::Sample;
use mcmc_core::stats::ChainStatistics;
use rayon::prelude::*;
use serde_json::json;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

crate::settings! {
    /// Energy redistribution path tracing (Mitsuba 0.6's `erpt` names, snake case).
    pub struct Erpt {
        /// Average number of chains started per pixel and pass (Mitsuba's numChains).
        pub num_chains: f64 = 1.0, check check::positive;
        /// Most chains one seed path may start, 0: no cap (Mitsuba's maxChains; a cap biases bright paths).
        pub max_chains: usize = 0;
        /// Mutations per chain (Mitsuba's chainLength).
        pub chain_length: usize = 100, check check::count;
        /// Camera walks of the estimate of the mean pixel luminance that sets the deposited energy (Mitsuba's luminanceSamples).
        pub luminance_samples: usize = 15_000, check check::count;
        /// Selection weight of Veach's bidirectional mutation (Mitsuba's erpt: off).
        pub bidirectional_mutation: f64 = 0.0, check check::non_negative;
        /// Selection weight of the lens perturbation (Mitsuba: on).
        pub lens_perturbation: f64 = 1.0, check check::non_negative;
        /// Selection weight of the manifold perturbation (Mitsuba: off; MEPT turns it on).
        pub manifold_perturbation: f64 = 0.0, check check::non_negative;
        /// Selection weight of the caustic perturbation (Mitsuba: on; 1 here since session 20).
        pub caustic_perturbation: f64 = 1.0, check check::non_negative;
        /// Selection weight of the multi-chain perturbation (Mitsuba: on; 1 here since session 20).
        pub multi_chain_perturbation: f64 = 1.0, check check::non_negative;
        /// Samples per pixel of the direct-lighting pass (path tracing of paths up to two segments; the seeds and chains take the rest); -1: off, the chains do everything (Mitsuba's default is 16).
        pub direct_samples: i64 = -1, check check_pass_samples;
        flatten {
            /// Path depth (rr_depth applies to the direct pass only: seeds are walked without roulette).
            pub depth: DepthParams = DepthParams::default();
        }
    }
}

/// Vertices of a camera walk when the depth is unbounded.
const UNBOUNDED_WALK: usize = 64;

/// Bands of rows per pass (work units).
const BANDS: u32 = 32;

impl Erpt {
    /// The mutation mixture the chains run.
    pub fn mutations(&self) -> PathMutations {
        PathMutations {
            bidirectional: self.bidirectional_mutation,
            lens_perturbation: self.lens_perturbation,
            manifold_perturbation: self.manifold_perturbation,
            caustic_perturbation: self.caustic_perturbation,
            multi_chain_perturbation: self.multi_chain_perturbation,
            ..PathMutations::default()
        }
    }

    /// Camera-walk vertices: `max_depth + 1`.
    fn walk_vertices(&self) -> usize {
        if self.depth.max_depth < 0 {
            UNBOUNDED_WALK
        } else {
            self.depth.max_depth as usize + 1
        }
    }

    /// Shortest path of the seeds and chains: 3 segments with the direct
    /// pass.
    fn min_segments(&self) -> usize {
        min_segments(self.direct_samples)
    }

    fn kernel<'s>(
        &self,
        clock: Option<&Arc<ProposalClock>>,
    ) -> Result<Mixture<Path<'s>, PathSample>, String> {
        let max = (self.depth.max_depth >= 0).then_some(self.depth.max_depth as usize);
        self.mutations()
            .kernel_timed(self.min_segments(), max, clock)
    }
}

/// The seeds of one camera walk through `raster`: paths of `min_segments`
/// segments or more with their energies (module docs).
fn seeds<'s>(
    scene: &'s Scene,
    raster: Vec2,
    (min_segments, vertices): (usize, usize),
    rng: &mut ChainRng,
    camera: &mut Vec<Vertex>,
    light: &mut Vec<Vertex>,
) -> Vec<(Path<'s>, f64)> {
    let mut out = Vec::new();
    let mut source = ChainSource::new(rng);
    let made = generate_camera_subpath(scene, raster, &mut source, vertices, None, camera);
    for t in 2..=made {
        let end = &camera[t - 1];
        // A walk that escaped into the environment ends there: its last
        // vertex (at infinity) is an emitter, not a vertex to connect from.
        let escaped = end.kind == VertexKind::Infinite;
        if end.kind != VertexKind::Surface && !escaped {
            break;
        }
        let mut candidates = Vec::with_capacity(2);
        if end.is_light() {
            candidates.push(Path::from_subpaths(scene, &[], &camera[..t]));
        }
        if !escaped && t < vertices && light_walk(scene, &mut source, 1, light) == 1 {
            let path = Path::from_subpaths(scene, &light[..1], &camera[..t]);
            if path.connectible(0) && path.connectible(1) && path.edge_visible(0) {
                candidates.push(path);
            }
        }
        // The shorter paths are the direct pass's.
        for path in candidates
            .into_iter()
            .filter(|p| p.segments() >= min_segments)
        {
            let i = path.luminance();
            if !(i > 0.0) || !path.contribution.is_finite() {
                continue;
            }
            let k = path.segments();
            // The seeds' techniques only: `s = 1` connects to a camera-walk
            // vertex (`t = k ≥ 2`), never to the camera itself, so a path
            // of one segment (an emitter or the sky seen directly) has the
            // camera walk's density alone (session 19: with `(s, t) = (1,
            // 1)` counted, the sky's pixels were ≈ 5% dark).
            let p: f64 = (0..=1)
                .filter(|&s| k + 1 - s >= 2)
                .map(|s| path.log_regrowth_density(0, k, s).exp())
                .sum();
            let e = i / p;
            if e.is_finite() && e > 0.0 {
                out.push((path, e));
            }
        }
    }
    out
}

/// A raster position uniform in pixel `(x, y)`.
fn in_pixel(x: u32, y: u32, rng: &mut ChainRng) -> Vec2 {
    Vec2::new(
        x as f32 + uniform(rng) as f32,
        y as f32 + uniform(rng) as f32,
    )
}

/// What one band of one pass produced.
struct Band {
    film: Film,
    stats: ChainStatistics,
    seeds: u64,
    chains: u64,
    stopped: bool,
}

impl IntegratorSettings for Erpt {
    const NAME: &'static str = "erpt";
    const DESCRIPTION: &'static str = "Energy redistribution path tracing (Cline et al. 2005): path-traced seeds start short path-space Metropolis chains that deposit equal energy.";

    fn validate(&self) -> Result<(), String> {
        if self.depth.max_depth == 0 {
            return Err("erpt needs max_depth ≥ 1 or -1 (unbounded)".into());
        }
        check_direct_depth(Self::NAME, self.direct_samples, self.depth.max_depth)?;
        self.mutations().check_weights()
    }

    fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError> {
        IntegratorSettings::validate(self).map_err(RenderError::Invalid)?;
        let start = Instant::now();
        let (w, h) = (scene.film.width, scene.film.height);
        let walk = (self.min_segments(), self.walk_vertices());
        let deadline = Deadline::new(start, run.time_budget);
        let time_up = || stop.load(Ordering::Relaxed) || deadline.passed();
        // Whether any rank is stopped: every rank then stops at the same
        // point (collective; without a cluster, `time_up` itself).
        let any_time_up = || crate::cluster::any_rank(time_up());
        // The luminance estimate is the start-up: it stops at the Markov
        // driver's share of the budget (`markov::STARTUP_SHARE`), so the
        // passes get the rest (at the whole budget a large
        // `luminance_samples` left them none, session 33).
        let lum_deadline = crate::markov::startup_end(start, run.time_budget);
        let lum_time_up =
            || crate::cluster::any_rank(stop.load(Ordering::Relaxed) || lum_deadline.passed());
        let cluster = crate::cluster::current();
        let filter = Arc::new(Filter::new(scene.film.filter, w, h));
        let names = self
            .kernel(None)
            .map_err(RenderError::Invalid)?
            .component_names();
        let resumed = match &run.checkpoint {
            Some(c) => resume_point(c, cluster, &filter, &names).map_err(RenderError::Invalid)?,
            None => None,
        };
        // The direct pass first (module docs): with a checkpoint it is
        // rendered again on resume, to its sample count whatever the
        // clock; its image is added to every snapshot and to the result.
        let direct = pass_samples(self.direct_samples).map(|spp| {
            direct_pass(
                scene,
                run,
                (spp, self.depth.rr_depth),
                crate::markov::startup_deadline(deadline, run.checkpoint.is_some()),
                stop,
                &WithPasses::progress_only(observer),
            )
        });
        let observer = WithPasses::new(observer, direct.iter().map(|(_, d)| d.image.as_slice()));
        // L̄: mean pixel luminance from independent camera walks (a resumed
        // run's from its checkpoint, on every rank).
        let lum = match &resumed {
            Some(r) => r.lum,
            None => estimate_luminance(
                self.luminance_samples,
                splitmix64(run.seed ^ 0x4c55_4d49),
                &lum_time_up,
                |mut rng| {
                    let (mut camera, mut light) = (Vec::new(), Vec::new());
                    let raster = in_pixel(
                        (uniform(&mut rng) * w as f64) as u32 % w,
                        (uniform(&mut rng) * h as f64) as u32 % h,
                        &mut rng,
                    );
                    seeds(scene, raster, walk, &mut rng, &mut camera, &mut light)
                        .iter()
                        .map(|s| s.1)
                        .sum()
                },
            ),
        };
        let mean_lum = lum.mean;
        let e_d = mean_lum / (self.chain_length as f64 * self.num_chains);
        let mut film = Film::new_splat_only(w, h, filter.clone());
        let clock = ProposalClock::new();
        let mut stats = ChainStatistics::new(names);
        let (mut passes, mut seeds_total, mut chains_total) = (0u64, 0u64, 0u64);
        let resumed_from = resumed.as_ref().map(|r| r.passes);
        if let Some(r) = resumed {
            passes = r.passes;
            // Rank 0's film and counters (the other ranks add nothing).
            if let Some(saved) = r.sums {
                (film, seeds_total, chains_total, stats) = saved;
            }
        }
        let mut checkpoint_error: Option<String> = None;
        let planned = run.spp.map(u64::from);
        let mut interrupted = false;
        // Mutations of the pass the stop or the deadline cut (not in the
        // image: a part of a pass is not an estimate).
        let mut dropped_mutations = 0u64;
        // This rank's share: bands, mutations, seconds rendering.
        let (mut own_bands, mut own_mutations, mut busy) = (0u64, 0u64, 0.0f64);
        while mean_lum > 0.0 && planned.is_none_or(|p| passes < p) {
            if any_time_up() {
                // The time budget ends a run without a sample count as
                // planned; Ctrl-C, or the budget before the count, stops it.
                interrupted = stop.load(Ordering::Relaxed) || planned.is_some();
                break;
            }
            let pass_seed = splitmix64(run.seed.wrapping_add(passes.wrapping_mul(0x9e37_79b9)));
            let render_band = |band: usize, mut rng: ChainRng| {
                let mut out = Band {
                    film: Film::new_splat_only(w, h, filter.clone()),
                    stats: stats_like(&stats),
                    seeds: 0,
                    chains: 0,
                    stopped: false,
                };
                let Ok(kernel) = self.kernel(Some(&clock)) else {
                    return out;
                };
                let mut mh = MetropolisHastings::new(kernel);
                let (mut camera, mut light) = (Vec::new(), Vec::new());
                let rows = (band as u32 * h / BANDS)..((band as u32 + 1) * h / BANDS);
                for y in rows {
                    if time_up() {
                        out.stopped = true;
                        return out;
                    }
                    for x in 0..w {
                        let raster = in_pixel(x, y, &mut rng);
                        for (path, e) in
                            seeds(scene, raster, walk, &mut rng, &mut camera, &mut light)
                        {
                            out.seeds += 1;
                            let mut chains =
                                (uniform(&mut rng) + e / (self.chain_length as f64 * e_d)) as usize;
                            if self.max_chains > 0 {
                                chains = chains.min(self.max_chains);
                            }
                            let seed = Sample {
                                log_density: path.log_density(),
                                payload: path.sample(),
                                state: path,
                            };
                            for _ in 0..chains {
                                out.chains += 1;
                                let mut chain = ChainState {
                                    current: seed.clone(),
                                    rng: child_rng(&mut rng),
                                    stats: std::mem::take(&mut out.stats),
                                };
                                let film = &mut out.film;
                                for _ in 0..self.chain_length {
                                    // A chain of 10^15 steps never ended:
                                    // the deadline drops the pass here as
                                    // it does between rows.
                                    if time_up() {
                                        out.stats = chain.stats;
                                        out.stopped = true;
                                        return out;
                                    }
                                    mh.step(&mut chain, &PathTarget::default(), &mut |t| {
                                        deposit(film, t.current, 1.0 - t.alpha, e_d);
                                        if let Some(y) = t.proposal {
                                            deposit(film, y, t.alpha, e_d);
                                        }
                                    });
                                }
                                out.stats = chain.stats;
                            }
                        }
                    }
                }
                out
            };
            // This rank's bands (all of them in one process), each from
            // its own stream `(pass_seed, band)`.
            let t = Instant::now();
            let bands: Vec<(usize, Band)> = (0..BANDS as usize)
                .filter(|&b| crate::cluster::owns(cluster, b))
                .collect::<Vec<_>>()
                .into_par_iter()
                .map(|b| (b, render_band(b, stream_rng(pass_seed, b as u64))))
                .collect();
            busy += t.elapsed().as_secs_f64();
            if crate::cluster::any_rank(bands.iter().any(|(_, b)| b.stopped)) {
                let own: u64 = bands.iter().map(|(_, b)| b.stats.steps).sum();
                // Every rank's (a collective: all ranks drop the pass here).
                dropped_mutations = match cluster {
                    Some(c) => c.all_gather_f64s(vec![own as f64]).iter().sum::<f64>() as u64,
                    None => own,
                };
                interrupted = stop.load(Ordering::Relaxed) || planned.is_some();
                break;
            }
            own_bands += bands.len() as u64;
            own_mutations += bands.iter().map(|(_, b)| b.stats.steps).sum::<u64>();
            // Films and counters in band order (on a cluster every rank's,
            // on rank 0; the other ranks add nothing).
            let counters = crate::cluster::reduce_units(
                &mut film,
                bands.iter().map(|(u, b)| (*u, &b.film, band_counters(b))),
                &filter,
            );
            for (_, counts) in counters {
                let (band_seeds, band_chains, band_stats) =
                    band_of_counters(&counts).map_err(RenderError::Invalid)?;
                stats.merge(&band_stats);
                seeds_total += band_seeds;
                chains_total += band_chains;
            }
            passes += 1;
            if let Some(c) = &run.checkpoint
                && crate::cluster::is_root()
                && checkpoint_error.is_none()
            {
                let progress = Progress {
                    pass: passes,
                    spp_done: passes,
                    nonfinite: stats.invalid_density,
                    size: (w, h),
                    samples: vec![[0.0; 4]; w as usize * h as usize],
                    splats: film.accumulators().1.to_vec(),
                    extra: saved_words(seeds_total, chains_total, &lum, &stats),
                    more_films: Vec::new(),
                };
                checkpoint_error = crate::checkpoint::save(&c.path, c.fingerprint, &progress).err();
            }
            observer.progress(u64::from(w) * u64::from(h));
            observer.snapshot(&|| film.develop(passes as f64), stats.steps);
        }
        let seconds = start.elapsed().as_secs_f64();
        let image = if passes > 0 {
            film.develop(passes as f64)
        } else {
            vec![Rgb::BLACK; (w * h) as usize]
        };
        let mut statistics = json!({
            "passes": passes,
            "seeds": seeds_total,
            "chains": chains_total,
            "chains_per_pixel_per_pass": chains_total as f64 / (passes.max(1) as f64 * f64::from(w * h)),
            "mutations": stats.steps,
            "mutations_per_second": stats.steps as f64 / seconds,
            "dropped_pass_mutations": dropped_mutations,
            "luminance_samples": lum.walks,
            "mean_pixel_luminance": mean_lum,
            "mean_pixel_luminance_standard_error": lum.standard_error,
            "deposit_energy": e_d,
            "acceptance": stats.acceptance_rate(),
            "acceptance_per_component": stats.components.iter().map(|c| json!({
                "name": c.name,
                "proposed": c.proposed,
                "accepted": c.accepted,
                "acceptance": c.acceptance_rate(),
            })).collect::<Vec<_>>(),
            "failed_proposals": stats.failed,
            "nonfinite_contributions": stats.invalid_density,
            "mutation_types": mutation_types(
                stats.components.iter().map(|c| (c.name.clone(), c.proposed, c.accepted)),
                &clock,
                seconds,
            ),
        });
        if let Some(c) = &run.checkpoint {
            statistics["checkpoint"] =
                c.statistics("passes", resumed_from, passes, &checkpoint_error);
        }
        // On a cluster, every rank's share (on rank 0; collective).
        let statistics = crate::cluster::with_ranks(
            statistics,
            json!({
                "units": own_bands,
                "mutations": own_mutations,
                "busy_seconds": busy,
            }),
        );
        let serde_json::Value::Object(statistics) = statistics else {
            unreachable!("json! of an object literal is an object")
        };
        let mut out = Rendered {
            image,
            seconds,
            samples: stats.steps,
            interrupted,
            statistics,
            nonfinite_dump: None,
            layers: Vec::new(),
            summary: format!(
                "{passes} passes, {chains_total} chains, {} mutations in {seconds:.2} s, e_d = {e_d:.3e}{}{}",
                stats.steps,
                if lum.walks < self.luminance_samples {
                    format!(
                        ", luminance estimate cut at {} of {} walks",
                        lum.walks, self.luminance_samples
                    )
                } else {
                    String::new()
                },
                if interrupted { ", stopped early" } else { "" }
            ),
        };
        if let Some((spp, pass)) = &direct {
            add_pass(&mut out, pass, "direct_pass", "direct pass", *spp, start);
        }
        Ok(out)
    }
}

/// Camera walks per block of the luminance estimate: the stop flag and the
/// deadline are checked between blocks.
const LUMINANCE_BLOCK: usize = 1024;

/// The estimate of the mean pixel luminance `L̄` that sets the deposited
/// energy.
#[derive(Clone, Copy, Debug)]
struct LuminanceEstimate {
    /// Camera walks taken (fewer than asked when the time ran out).
    walks: usize,
    /// Their mean luminance (0 without walks: no pass runs).
    mean: f64,
    /// The mean's standard error (NaN below two walks).
    standard_error: f64,
}

/// `L̄` from up to `walks` independent camera walks, `walk(rng)` giving
/// one walk's luminance, in blocks of [`LUMINANCE_BLOCK`] walks until
/// `time_up()` (on a cluster a collective: each block's walks are split
/// over the ranks and gathered in order, and every rank gets the same
/// estimate). Nothing is kept per walk (10^15 walks aborted on an 8 PB
/// allocation when the luminances were collected), and a cut estimate is
/// the mean of the walks taken: `e_d` only sets how many chains start, and
/// any `e_d > 0` leaves a pass unbiased (module docs). Each walk has its
/// own stream (`run_chains`' streams of `seed`) and the sum runs in walk
/// order, so the estimate does not depend on the thread count.
fn estimate_luminance(
    walks: usize,
    seed: u64,
    time_up: &dyn Fn() -> bool,
    walk: impl Fn(ChainRng) -> f64 + Sync + Send,
) -> LuminanceEstimate {
    let (mut done, mut sum) = (0usize, 0.0f64);
    // Welford's running mean and sum of squared deviations: the standard
    // error without keeping the walks.
    let (mut running_mean, mut squares) = (0.0f64, 0.0f64);
    while done < walks && !time_up() {
        let (first, n) = (done, LUMINANCE_BLOCK.min(walks - done));
        let block = crate::cluster::evaluate_split(n, 1, |i| {
            vec![walk(stream_rng(seed, (first + i) as u64))]
        });
        for l in block {
            done += 1;
            sum += l;
            let delta = l - running_mean;
            running_mean += delta / done as f64;
            squares += delta * (l - running_mean);
        }
    }
    let n = done as f64;
    LuminanceEstimate {
        walks: done,
        mean: if done > 0 { sum / n } else { 0.0 },
        standard_error: (squares / (n * (n - 1.0))).sqrt(),
    }
}

/// A band's counters for the reduction: its seeds, chains and chain
/// statistics (bit-exactly).
fn band_counters(band: &Band) -> crate::cluster::Counters {
    let mut counts = vec![band.seeds, band.chains];
    crate::markov::checkpoint::stats_words(&band.stats, &mut counts);
    (Vec::new(), counts)
}

/// The seeds, chains and statistics [`band_counters`] wrote.
fn band_of_counters(counts: &[u64]) -> Result<(u64, u64, ChainStatistics), String> {
    let mut words = counts.iter().copied();
    let mut next = || {
        words
            .next()
            .ok_or_else(|| "a band's counters are cut".to_string())
    };
    Ok((
        next()?,
        next()?,
        crate::markov::checkpoint::stats_from_words(&mut next)?,
    ))
}

/// `erpt`'s words in a checkpoint ([`Progress::extra`]): the seeds and
/// chains counted, the luminance estimate (walks, mean, standard error),
/// then the chain statistics, bit-exactly.
fn saved_words(
    seeds: u64,
    chains: u64,
    lum: &LuminanceEstimate,
    stats: &ChainStatistics,
) -> Vec<u64> {
    let mut out = vec![
        seeds,
        chains,
        lum.walks as u64,
        lum.mean.to_bits(),
        lum.standard_error.to_bits(),
    ];
    crate::markov::checkpoint::stats_words(stats, &mut out);
    out
}

/// What an `erpt` checkpoint holds besides the passes and the film.
struct Saved {
    seeds: u64,
    chains: u64,
    lum: LuminanceEstimate,
    /// Chain statistics, components unnamed.
    stats: ChainStatistics,
}

impl Saved {
    /// The state `progress` holds: refused (one line) unless an `erpt` run
    /// could have written it: a splat-only film (camera-sample
    /// accumulators all zero), as many samples per pixel as passes, the
    /// words [`saved_words`] writes, counts within 2^53 and a finite,
    /// non-negative luminance estimate.
    fn of(progress: &Progress) -> Result<Saved, String> {
        if progress.samples.iter().any(|s| *s != [0.0; 4]) {
            return Err("holds camera samples: not a checkpoint of erpt".into());
        }
        if progress.spp_done != progress.pass {
            return Err(format!(
                "holds {} passes and {} samples per pixel: not a checkpoint of erpt (one sample a pass)",
                progress.pass, progress.spp_done
            ));
        }
        let mut words = progress.extra.iter().copied();
        let mut next = || {
            words
                .next()
                .ok_or_else(|| "erpt's words are cut: not a checkpoint of erpt".to_string())
        };
        let (seeds, chains, walks) = (next()?, next()?, next()?);
        let (mean, standard_error) = (f64::from_bits(next()?), f64::from_bits(next()?));
        let stats = crate::markov::checkpoint::stats_from_words(&mut next)?;
        if next().is_ok() {
            return Err("erpt's words run on: not a checkpoint of erpt".into());
        }
        let max = crate::checkpoint::MAX_COUNT;
        if seeds > max || chains > max || walks > max || !(mean.is_finite() && mean >= 0.0) {
            return Err(format!(
                "impossible counts: {seeds} seeds, {chains} chains, {walks} walks of mean luminance {mean} (at most 2^53, a finite mean ≥ 0)"
            ));
        }
        Ok(Saved {
            seeds,
            chains,
            lum: LuminanceEstimate {
                walks: walks as usize,
                mean,
                standard_error,
            },
            stats,
        })
    }
}

/// Checks that a checkpoint's `progress` is one an `erpt` run wrote (one
/// line if not). The command line checks it on rank 0 before the ranks'
/// start-up handshake, so that a bad file stops every rank with one error.
pub fn check_checkpoint(progress: &Progress) -> Result<(), String> {
    Saved::of(progress).map(|_| ())
}

/// What a resumed run continues from.
struct Resumed {
    passes: u64,
    lum: LuminanceEstimate,
    /// The film, seeds, chains and chain statistics: rank 0's (the only
    /// rank that adds into them), `None` on the others.
    sums: Option<(Film, u64, u64, ChainStatistics)>,
}

/// Where a checkpointed run starts: rank 0's checkpoint, read (its film
/// rebuilt with `filter`, its statistics' components named `names`), and
/// on a cluster every rank told the passes done and the luminance
/// estimate (a broadcast). `None`: a fresh start. Collective on a cluster.
fn resume_point(
    checkpoint: &Checkpoint,
    cluster: Option<&dyn Cluster>,
    filter: &Arc<Filter>,
    names: &[String],
) -> Result<Option<Resumed>, String> {
    let local = match &checkpoint.resume {
        None => None,
        Some(p) => {
            let mut saved = Saved::of(p)?;
            if saved.stats.components.len() != names.len() {
                return Err("the checkpoint's chains ran another mutation mixture".into());
            }
            for (k, name) in saved.stats.components.iter_mut().zip(names) {
                k.name.clone_from(name);
            }
            let (w, h) = p.size;
            let film = Film::from_accumulators(
                [w, h, 0, 0, w, h],
                filter.clone(),
                Vec::new(),
                p.splats.clone(),
            )?;
            Some((p.pass, saved, film))
        }
    };
    let words = local.as_ref().map_or(Vec::new(), |(pass, saved, _)| {
        let lum = &saved.lum;
        vec![
            *pass,
            lum.walks as u64,
            lum.mean.to_bits(),
            lum.standard_error.to_bits(),
        ]
    });
    let words = match cluster {
        Some(c) => c.broadcast_u64s(words),
        None => words,
    };
    let (passes, walks, mean, standard_error) = match words[..] {
        [p, w, m, s] => (p, w, m, s),
        _ => return Ok(None),
    };
    Ok(Some(Resumed {
        passes,
        lum: LuminanceEstimate {
            walks: walks as usize,
            mean: f64::from_bits(mean),
            standard_error: f64::from_bits(standard_error),
        },
        sums: local.map(|(_, s, film)| (film, s.seeds, s.chains, s.stats)),
    }))
}

/// Empty statistics with the components of `like`.
fn stats_like(like: &ChainStatistics) -> ChainStatistics {
    ChainStatistics::new(like.components.iter().map(|c| c.name.clone()).collect())
}

/// Deposits `weight · e_d · f/lum f` of `s` at its raster position.
fn deposit(film: &mut Film, s: &Sample<Path<'_>, PathSample>, weight: f64, e_d: f64) {
    let i = s.state.luminance();
    if !(weight > 0.0 && i > 0.0) {
        return;
    }
    film.splat(
        s.state.raster,
        s.state.contribution * ((weight * e_d / i) as f32),
    );
}
