//! MCMC with path guiding (MCMC-PG, seed 003 §10): primary sample space
//! MLT whose path sampler is the guided path tracer
//! ([`super::guided::GuidedPathTracer`]) over an SD-tree.
//!
//! # Target
//! A primary-sample point `u` is mapped by the guided tracer (no NEE by
//! default, as the thesis) to a path whose contribution is
//! `f_PG = Π f_j |cos| / (q p_tree + (1 − q) p_bsdf) · Le` (Eq. 4.2): the
//! guided density enters only through the PSS-to-path map, so the
//! acceptance stays `min(1, I_PG(v)/I_PG(u))` for the symmetric PSS
//! proposals and nothing else changes: start-up, estimator, normalisation
//! and the kernels are the Markov driver's and `mcmc-core`'s, exactly as
//! for `pssmlt` ([`super::pssmlt::render_pssmlt`]). Large steps stay
//! uniform in primary sample space; through the guided map they become
//! guided independent proposals, which is where the gain is meant to come
//! from (Table 4.2: large-step acceptance on Veach-ajar 0.003 → 0.089).
//!
//! # Variants (`training`)
//! - **`pretrained`** (Alg. 8): guided path tracing on the `guided`
//!   integrator's doubling schedule trains the tree with a share
//!   `training_share` (1/8, the thesis's 512 of 4096 spp) of the budget;
//!   every training iteration records, the last one included; the
//!   training samples do not enter the image. The tree is then frozen and
//!   PSSMLT runs over the guided tracer with the rest of the budget: one
//!   fixed target, a valid MCMC.
//! - **`online`** (Alg. 9): iterations of doubling length `2^(k−1)`
//!   mutations per pixel on the same schedule (on mutations instead of
//!   samples). Each iteration bootstraps anew (new seeds) with the current
//!   sampling tree, starts its chains from that bootstrap, and every
//!   traced path (bootstrap candidates and every proposal, accepted or
//!   not, large or small, unweighted by the acceptance) records into the
//!   building tree; then the tree is updated. Only the last iteration's
//!   image is kept, and the last iteration does not record (its records
//!   would train nothing).
//!
//! **How the target change is handled (online).** The sampling half of
//! the tree is read-only during an iteration (records go to the building
//! half, which the tracer never reads), so within an iteration the target
//! `I_PG` is fixed and the iteration is an ordinary PSSMLT run with its
//! own start-up and normalisation `b_k`. Between iterations the map from
//! `u` to paths changes, so a chain state of iteration `k` is not
//! distributed as iteration `k + 1`'s target: carrying states over would
//! bring back a start-up bias that no normalisation removes. As Alg. 9
//! does, chains are therefore not carried over but re-seeded from a new
//! bootstrap `∝ I_PG` of the current tree (the driver's resampled start,
//! which removes start-up bias), and only the last iteration's image,
//! scaled by its own `b`, is the result: it is unbiased whatever the
//! earlier iterations did, because the tree only shapes the sampler. What
//! the online records are *not* is an unbiased flux estimate: proposals
//! follow the chains, not the guided sampler, so bright regions are
//! over-recorded (spec §14.15); that costs efficiency, not correctness.
//!
//! # Determinism
//! The pre-trained tree is the `guided` integrator's (deterministic per
//! seed). Online records come from chains the scheduler spreads over
//! threads, so their order is not fixed; each thread sums them in fixed
//! point per building quadtree leaf ([`ExactRecords`]), whose integer sums
//! do not depend on order: one seed gives the same trees and image on any
//! thread count.
//!
//! # Checkpoints
//! With `--checkpoint FILE` (session 19; `training = pretrained` and a
//! mutation budget only) the chains save and resume as `pssmlt`'s do on
//! the Markov driver ([`crate::markov::checkpoint`]); the SD-tree is not
//! saved: a resumed run trains it again, which gives the same tree bit for
//! bit (the training's samples per pixel follow from the budget, its
//! streams from the seed), so the chains' targets, start-up and the image
//! are the uninterrupted run's. A run stopped in the training has saved
//! nothing.
//!
//! Online training (session 21) is checkpointed the same way: only its
//! last iteration, the one that makes the image, saves its chains; a
//! resumed run makes the training iterations before it again. They are a
//! function of the seed and the mutation budget alone (each iteration's
//! length follows from the budget, its chains' seed from its index, its
//! records are exact sums that do not depend on the order of the threads
//! or ranks), so the tree the last iteration samples, and with it the
//! chains' target, start-up and image, are the uninterrupted run's. For
//! that the clock must not cut a training iteration: with a checkpoint
//! they run to their mutation counts whatever the time budget
//! ([`markov::startup_deadline`]), as RELT's start-up does; Ctrl-C still
//! stops them (and nothing is saved). The repeated training costs a
//! quarter to a half of the budget's mutations on every resume (before a
//! last iteration of `left ∈ [2^K, 3·2^K)` mutations per pixel the
//! training did `2^K − 1`), and its chains also record.
//!
//! # Random numbers per state
//! Coordinates 0–1 the raster position (2–3 the lens of a thin-lens
//! camera), then 8 per scattering vertex as [`super::guided`] documents.

use super::guided::{
    GuidedPathTracer, GuidedSettings, RecordSink, agreed_iteration, next_iteration,
};
use super::registry::IntegratorSettings;
use super::{RenderError, Rendered, RunSettings};
use crate::checkpoint::Checkpoint;
use crate::deadline::Deadline;
use crate::guiding::{ExactRecords, SdTree};
use crate::markov::{self, ChainParams, MltResult};
use crate::observer::Observer;
use crate::pss::{
    LARGE_STEP_COMPONENT, MutationParams, PssPathSampler, PssSource, Splat, raster_of,
};
use crate::pss_dump::DumpSampler;
use crate::sampling::RandomSource;
use crate::scene::Scene;
use mcmc_core::rng::splitmix64;
use serde_json::{Value, json};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Numbers the guided tracer reads per scattering vertex.
const NUMBERS_PER_VERTEX: usize = 8;
/// Stream offset from which the online iterations' seeds are derived.
const ONLINE_STREAM: u64 = 1 << 44;

crate::choice! {
    /// When the SD-tree is trained.
    pub enum TrainingMode {
        /// Guided path tracing first, then MCMC with the frozen tree (Alg. 8).
        Pretrained = "pretrained",
        /// Refined between MCMC iterations from the chains' paths (Alg. 9; `smcmc`'s guided shift: Alg. 10).
        Online = "online",
    }
}

crate::settings! {
    /// MCMC-PG settings.
    pub struct McmcPg {
        /// pretrained (guided path tracing trains, then MCMC with the frozen tree) or online (iterations of MCMC train the tree; the last makes the image).
        pub training: TrainingMode = TrainingMode::Pretrained;
        /// Pretrained: the share of the budget (mutations per pixel as samples per pixel, or time) spent on training, in (0, 1).
        pub training_share: f64 = 0.125, check check_share;
        flatten {
            /// The guided tracer and its tree.
            pub guiding: GuidedSettings = GuidedSettings::default();
            /// The mutation.
            pub mutation: MutationParams = MutationParams::default();
            /// The driver.
            pub chain: ChainParams = ChainParams::default();
        }
    }
}

/// `share ∈ (0, 1)`.
fn check_share(v: &f64) -> Result<(), String> {
    if *v > 0.0 && *v < 1.0 {
        Ok(())
    } else {
        Err("must lie in (0, 1)".into())
    }
}

/// The guided path tracer as a primary-sample path sampler, over a tree
/// whose sampling half stays fixed while it is used; with a sink, every
/// traced path records into it.
#[derive(Clone, Copy)]
pub struct GuidedPss<'t> {
    /// The tracer.
    pub tracer: GuidedPathTracer,
    /// The tree it samples.
    pub tree: &'t SdTree,
    sink: Option<&'t RecordSink>,
}

impl<'t> GuidedPss<'t> {
    /// The sampler over the frozen `tree`.
    pub fn frozen(tracer: GuidedPathTracer, tree: &'t SdTree) -> Self {
        GuidedPss {
            tracer,
            tree,
            sink: None,
        }
    }
}

impl PssPathSampler for GuidedPss<'_> {
    fn streams(&self) -> usize {
        1
    }

    fn trace(&self, scene: &Scene, source: &mut PssSource<'_>, out: &mut Vec<Splat>) -> u32 {
        let p = raster_of(scene, source);
        let (ray, lens_numbers) = if scene.camera.has_lens() {
            (scene.camera.generate_ray_lens(p, source.next_2d()), 2)
        } else {
            (scene.camera.generate_ray(p), 0)
        };
        let l = match self.sink {
            None => self.tracer.li(scene, ray, source, self.tree, None),
            Some(sink) => sink.record(self.tree, |training| {
                self.tracer
                    .li(scene, ray, source, self.tree, Some(training))
            }),
        };
        out.push(Splat { p, l, class: 0 });
        ((source.consumed(0) - 2 - lens_numbers) / NUMBERS_PER_VERTEX) as u32
    }
}

/// Forwards progress but no snapshots: training images are not MCMC-PG's
/// image, so `convergence` must not record them.
pub(crate) struct ProgressOnly<'a>(pub(crate) &'a dyn Observer);

impl Observer for ProgressOnly<'_> {
    fn progress(&self, n: u64) {
        self.0.progress(n);
    }
}

/// One MCMC phase (online: one iteration), for the statistics.
#[derive(Clone, Debug, serde::Serialize)]
struct PhaseStats {
    iteration: u32,
    mutations_per_pixel: f64,
    seconds: f64,
    acceptance_large: f64,
    acceptance_small: f64,
    records: u64,
    tree_memory_bytes: usize,
}

/// What a variant hands back for the report.
struct Outcome {
    /// The run that makes the image.
    result: MltResult,
    /// The tree it sampled.
    tree: SdTree,
    /// The MCMC phases (online: every iteration; pre-trained: one).
    phases: Vec<PhaseStats>,
    /// The pre-training's per-iteration figures (`guided`'s).
    pretraining: Option<Value>,
    /// Seconds spent on what does not make the image.
    training_seconds: f64,
}

/// Acceptance of the small and the large step of a PSSMLT run.
fn acceptances(result: &MltResult) -> (f64, f64) {
    let c = &result.chain_stats.components;
    let rate = |i: usize| c.get(i).map_or(f64::NAN, |c| c.acceptance_rate());
    (rate(1 - LARGE_STEP_COMPONENT), rate(LARGE_STEP_COMPONENT))
}

impl McmcPg {
    /// PSSMLT over `sampler` with `mutations_per_pixel` and a time budget
    /// ending at `deadline`.
    fn chains(
        &self,
        scene: &Scene,
        sampler: GuidedPss<'_>,
        (mutations_per_pixel, deadline, seed): (Option<u64>, Deadline, u64),
        (snapshot_every, checkpoint): (Duration, Option<Checkpoint>),
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<MltResult, RenderError> {
        let mutation = self.mutation.mutation().map_err(RenderError::Invalid)?;
        let run = RunSettings {
            seed,
            snapshot_every,
            checkpoint,
            ..RunSettings::default()
        };
        let mut settings = self.chain.chain_settings(mutation, &run);
        settings.mutations_per_pixel = mutations_per_pixel;
        // At least a moment, so that a budget spent in training still
        // ends (the driver needs a budget).
        settings.time_budget = deadline
            .time_left()
            .map(|left| left.max(Duration::from_millis(1)));
        Ok(super::pssmlt::render_pssmlt(
            scene, sampler, &settings, stop, observer,
        )?)
    }

    /// Alg. 8: train, freeze, run the chains.
    fn render_pretrained(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Outcome, RenderError> {
        let start = Instant::now();
        let deadline = Deadline::new(start, run.time_budget);
        let budget = self.chain.mutations_per_pixel(run);
        let (train_run, chain_mpp) = match budget {
            Some(m) => {
                let t =
                    ((m as f64 * self.training_share).round() as u64).clamp(1, u64::from(u32::MAX));
                let train = RunSettings {
                    spp: Some(t as u32),
                    time_budget: None,
                    ..run.clone()
                };
                (train, Some(m.saturating_sub(t).max(1)))
            }
            None => {
                let train = RunSettings {
                    spp: None,
                    time_budget: run.time_budget.map(|b| b.mul_f64(self.training_share)),
                    ..run.clone()
                };
                (train, None)
            }
        };
        let (trained, tree) = self.guiding.render_and_train(
            scene,
            &train_run,
            stop,
            &ProgressOnly(observer),
            true,
        )?;
        let training_seconds = start.elapsed().as_secs_f64();
        let sampler = GuidedPss::frozen(self.guiding.tracer(), &tree);
        // With a checkpoint the chains save and resume as `pssmlt`'s; the
        // tree is trained again on resume, the same bits (a sample budget
        // fixes the training).
        let result = self.chains(
            scene,
            sampler,
            (chain_mpp, deadline, run.seed),
            (run.snapshot_every, run.checkpoint.clone()),
            stop,
            observer,
        )?;
        let (small, large) = acceptances(&result);
        let stat = |key: &str| trained.statistics.get(key).cloned().unwrap_or(Value::Null);
        let phases = vec![PhaseStats {
            // The tree after this many training iterations.
            iteration: stat("iterations").as_u64().unwrap_or(0) as u32,
            mutations_per_pixel: result.mutations_per_pixel,
            seconds: result.seconds,
            acceptance_large: large,
            acceptance_small: small,
            records: 0,
            tree_memory_bytes: tree.size().bytes,
        }];
        let pretraining = json!({
            "spp_per_iteration": stat("spp_per_iteration"),
            "seconds_per_iteration": stat("seconds_per_iteration"),
            "records_per_iteration": stat("records_per_iteration"),
        });
        Ok(Outcome {
            result,
            tree,
            phases,
            pretraining: Some(pretraining),
            training_seconds,
        })
    }

    /// Alg. 9: iterations of MCMC on the current tree, each training the
    /// next; the last makes the image.
    fn render_online(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Outcome, RenderError> {
        let start = Instant::now();
        let deadline = Deadline::new(start, run.time_budget);
        let budget = self.chain.mutations_per_pixel(run);
        let tracer = self.guiding.tracer();
        let mut tree = self.guiding.untrained_tree(scene);
        let mut phases: Vec<PhaseStats> = Vec::new();
        let mut previous: Option<MltResult> = None;
        let mut training_seconds = 0.0;
        let checkpointed = run.checkpoint.is_some();
        let mut done = 0u64;
        let mut nominal = 1u64;
        for k in 1u32.. {
            let (mpp, last) = next_iteration(
                budget,
                done,
                nominal,
                deadline,
                phases.last().map(|p| p.seconds),
            );
            let (mpp, last) = agreed_iteration(mpp, last);
            let iteration_start = Instant::now();
            let sink = (!last).then(RecordSink::new);
            let sampler = GuidedPss {
                tracer,
                tree: &tree,
                sink: sink.as_ref(),
            };
            let seed = splitmix64(run.seed ^ splitmix64(ONLINE_STREAM + u64::from(k)));
            let progress = ProgressOnly(observer);
            let shown: &dyn Observer = if last { observer } else { &progress };
            // With a checkpoint only the last iteration saves; the
            // training iterations before it are made again on resume, so
            // the clock must not cut them (module docs).
            let (iteration_deadline, checkpoint) = match last {
                true => (deadline, run.checkpoint.clone()),
                false => (markov::startup_deadline(deadline, checkpointed), None),
            };
            let result = self.chains(
                scene,
                sampler,
                (mpp, iteration_deadline, seed),
                (run.snapshot_every, checkpoint),
                stop,
                shown,
            )?;
            let seconds = iteration_start.elapsed().as_secs_f64();
            let (small, large) = acceptances(&result);
            let interrupted = result.interrupted && !last;
            // Every rank's records (the sink exists in the same iterations
            // on every rank: `agreed_iteration`).
            let parts: Vec<ExactRecords> = sink.map(RecordSink::into_parts).unwrap_or_default();
            phases.push(PhaseStats {
                iteration: k,
                mutations_per_pixel: result.mutations_per_pixel,
                seconds,
                acceptance_large: large,
                acceptance_small: small,
                records: parts.iter().map(ExactRecords::len).sum(),
                tree_memory_bytes: tree.size().bytes,
            });
            if last || interrupted {
                // A stopped iteration is the result if it holds at least
                // as many mutations as the one before.
                let keep = previous
                    .take()
                    .filter(|p| !last && p.mutations > result.mutations);
                return Ok(Outcome {
                    result: keep.unwrap_or(result),
                    tree,
                    phases,
                    pretraining: None,
                    training_seconds,
                });
            }
            training_seconds += seconds;
            tree.merge_exact(parts);
            tree.end_iteration(
                k,
                self.guiding.spatial_threshold,
                self.guiding.quadtree_threshold,
            );
            previous = Some(result);
            done += mpp.unwrap_or(0);
            nominal = nominal.saturating_mul(2);
        }
        unreachable!("the schedule ends")
    }
}

impl IntegratorSettings for McmcPg {
    const NAME: &'static str = "mcmc-pg";
    const DESCRIPTION: &'static str = "PSSMLT over the SD-tree guided path tracer (seed 003 §10), tree pre-trained (Alg. 8) or trained online (Alg. 9).";

    fn validate(&self) -> Result<(), String> {
        self.mutation.mutation().map(|_| ())
    }

    fn planned_samples(&self, scene: &Scene, run: &RunSettings) -> Option<u64> {
        self.chain.planned_mutations(scene, run)
    }

    fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError> {
        let start = Instant::now();
        // Checkpoints: the chains of the run that makes the image, the
        // tree trained again on resume (module docs).
        if run.checkpoint.is_some() && self.chain.mutations_per_pixel(run).is_none() {
            return Err(RenderError::Invalid(
                "--checkpoint: mcmc-pg needs a mutation budget (--spp or mutations_per_pixel): a time budget alone sets its training by the clock, so a resumed run could not repeat it".into(),
            ));
        }
        let Outcome {
            result,
            tree,
            phases,
            pretraining,
            training_seconds,
        } = match self.training {
            TrainingMode::Pretrained => self.render_pretrained(scene, run, stop, observer)?,
            TrainingMode::Online => self.render_online(scene, run, stop, observer)?,
        };
        let seconds = start.elapsed().as_secs_f64();
        let mut rendered =
            markov::report::rendered(&result, DumpSampler::Pt, self.guiding.depth.limit(), false);
        // A dump could not be replayed without the tree.
        rendered.nonfinite_dump = None;
        rendered.seconds = seconds;
        rendered.interrupted |= stop.load(Ordering::Relaxed);
        let (small, large) = acceptances(&result);
        let size = tree.size();
        let s = &mut rendered.statistics;
        s.insert("training".into(), json!(self.training.name()));
        s.insert("acceptance_large".into(), json!(large));
        s.insert("acceptance_small".into(), json!(small));
        s.insert("iterations".into(), json!(phases));
        if let Some(p) = pretraining {
            s.insert("pretraining".into(), p);
        }
        s.insert("training_seconds".into(), json!(training_seconds));
        s.insert(
            "training_time_share".into(),
            json!(if seconds > 0.0 {
                training_seconds / seconds
            } else {
                0.0
            }),
        );
        s.insert("tree_memory_bytes".into(), json!(size.bytes));
        s.insert("tree".into(), json!(size));
        rendered.summary = format!(
            "{}; {} training, {:.2} s of {:.2} s; large-step acceptance {:.4}, small {:.3}; tree {:.1} MB",
            rendered.summary,
            self.training.name(),
            training_seconds,
            seconds,
            large,
            small,
            size.bytes as f64 / 1e6
        );
        Ok(rendered)
    }
}
