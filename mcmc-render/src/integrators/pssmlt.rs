//! Primary sample space Metropolis light transport (Kelemen et al. 2002) on
//! `mcmc-core`.
//!
//! - **Target**: `ln I(u)`, the log luminance of the contribution of the
//!   path traced from the primary-sample vector `u` ([`PssTarget`]).
//! - **Mutation**: `mcmc-core`'s [`Mixture`](mcmc_core::kernel::Mixture) of a
//!   torus small step and an independent large step ([`Mutation`]).
//! - **Start-up**: `N` independent candidates, `b* = (1/N) Σ I(u_i)` and
//!   chain starts resampled `∝ I(u_i)` (`mcmc_core::startup::Bootstrap`),
//!   which removes start-up bias (spec seed000 §3.6).
//! - **Estimator** (expected values, spec seed000 §3.7): every mutation
//!   splats the proposal `y` with weight `α·b/I(y)` and the current state
//!   `x` with `(1−α)·b/I(x)`; the image is the splat film divided by the
//!   mutations per pixel. With `mis_large_steps` (Kelemen's combination),
//!   the weights are `(α + [large])/(I(y)/b + p_large)` and
//!   `(1−α)/(I(x)/b + p_large)`: the large steps then also count as an
//!   independent Monte Carlo estimate, combined by the balance heuristic.
//! - **Normalisation**: the film is kept without the factor `b`, so the
//!   image can be developed with the bootstrap `b*` (pbrt) or with the
//!   running estimate over bootstrap candidates and all large steps so far
//!   (`mcmc_core::startup::RunningNormalization`), e.g. for previews.
//!   (With `mis_large_steps` `b*` is part of the weights and is used.)
//!
//! # Parallelism and determinism
//!
//! The chains are cut into a fixed number of tasks ([`PssmltSettings::tasks`],
//! independent of the thread count); each task owns its chains, one film
//! and its counters, and runs its chains one after another in rounds. Films
//! and counters are summed in task order, the bootstrap is evaluated in
//! parallel but collected in candidate order, and every chain draws from
//! its own stream, so one seed gives a bit-identical image for any number
//! of threads.

use crate::color::Rgb;
use crate::film::{Film, Filter};
use crate::pss::{LARGE_STEP_COMPONENT, Mutation, PathSample, PssPathSampler, PssTarget};
use crate::scene::Scene;
use mcmc_core::chain::{Chain, Transition};
use mcmc_core::kernel::Mixture;
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::rng::stream_rng;
use mcmc_core::space::TorusPoint;
use mcmc_core::startup::{Bootstrap, RunningNormalization};
use mcmc_core::stats::ChainStatistics;
use rayon::prelude::*;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use thiserror::Error;

/// Why a PSSMLT render could not run.
#[derive(Debug, Error)]
pub enum MltError {
    /// Every bootstrap path carried zero (or invalid) contribution.
    #[error(
        "the scene looks black: all {candidates} bootstrap paths have zero contribution ({invalid} NaN/inf); nothing to render with MLT"
    )]
    BlackScene {
        /// Bootstrap size.
        candidates: usize,
        /// Candidates with a NaN or infinite contribution.
        invalid: usize,
    },
    /// A setting is out of range.
    #[error("invalid MLT setting: {0}")]
    Setting(String),
    /// An error from `mcmc-core`.
    #[error(transparent)]
    Core(#[from] mcmc_core::CoreError),
}

/// How the image is scaled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Normalization {
    /// `b*` from the start-up bootstrap (pbrt).
    Bootstrap,
    /// Running estimate over the bootstrap and all large steps so far.
    Running,
}

/// PSSMLT settings (pbrt-v4's `mlt` defaults where they apply).
#[derive(Clone, Debug)]
pub struct PssmltSettings {
    /// Mutation kernel.
    pub mutation: Mutation,
    /// Bootstrap candidates (default 100 000).
    pub bootstrap: usize,
    /// Number of chains (default 1000).
    pub chains: usize,
    /// Mutations per pixel (default 100); `None` with a time budget means
    /// "until the budget is spent".
    pub mutations_per_pixel: Option<u64>,
    /// Wall-clock budget.
    pub time_budget: Option<Duration>,
    /// Seed of every stream.
    pub seed: u64,
    /// Kelemen's MIS combination of large steps.
    pub mis_large_steps: bool,
    /// Scaling of the final image.
    pub normalization: Normalization,
    /// Fixed number of work units the chains are grouped into.
    pub tasks: usize,
    /// Time between previews ([`MltObserver::preview`]).
    pub preview_every: Duration,
}

impl Default for PssmltSettings {
    fn default() -> Self {
        PssmltSettings {
            mutation: Mutation::default(),
            bootstrap: 100_000,
            chains: 1000,
            mutations_per_pixel: Some(100),
            time_budget: None,
            seed: 0,
            mis_large_steps: false,
            normalization: Normalization::Bootstrap,
            tasks: 16,
            preview_every: Duration::from_secs(5),
        }
    }
}

/// Notified while rendering (progress bars, previews).
pub trait MltObserver: Sync {
    /// A chain finished `n` mutations (called from worker threads).
    fn mutations_done(&self, _n: u64) {}
    /// A correctly scaled image of everything so far (every
    /// [`PssmltSettings::preview_every`], at the end of a round).
    fn preview(&self, _image: &[Rgb], _mutations: u64) {}
}

/// An observer that ignores everything.
pub struct NoMltObserver;
impl MltObserver for NoMltObserver {}

/// Proposals and acceptances of one path depth.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct DepthAcceptance {
    /// Proposals of this depth (valid ones).
    pub proposed: u64,
    /// Accepted proposals of this depth.
    pub accepted: u64,
}

/// The outcome of a PSSMLT render.
#[derive(Clone, Debug)]
pub struct MltResult {
    /// Splat film, not yet scaled by `b`.
    pub film: Film,
    /// Mutations done.
    pub mutations: u64,
    /// Mutations per pixel (the splat normalisation).
    pub mutations_per_pixel: f64,
    /// The scale applied to the developed film.
    pub scale: f64,
    /// Bootstrap `b*` and its standard error.
    pub bootstrap_b: (f64, f64),
    /// Running `⟨b⟩` (bootstrap and large steps) and its standard error.
    pub running_b: (f64, f64),
    /// Statistics of all chains (per kernel component, NaN/inf count).
    pub chain_stats: ChainStatistics,
    /// Acceptance per path depth (index = depth).
    pub per_depth: Vec<DepthAcceptance>,
    /// Bootstrap candidates with a NaN/inf contribution.
    pub bootstrap_invalid: usize,
    /// The primary-sample vector of the first NaN/inf proposal, if any.
    pub first_nonfinite: Option<Vec<f64>>,
    /// Seconds spent in the bootstrap.
    pub bootstrap_seconds: f64,
    /// Seconds spent in total.
    pub seconds: f64,
    /// Stopped by Ctrl-C or the time budget before the requested mutations.
    pub interrupted: bool,
}

impl MltResult {
    /// The developed image, row-major.
    pub fn image(&self) -> Vec<Rgb> {
        develop(&self.film, self.mutations, self.scale)
    }
}

/// The image of a splat film after `mutations` mutations, scaled by `scale`.
pub fn develop(film: &Film, mutations: u64, scale: f64) -> Vec<Rgb> {
    let pixels = film.width as f64 * film.height as f64;
    if mutations == 0 {
        return vec![Rgb::BLACK; pixels as usize];
    }
    let ppp = mutations as f64 / pixels;
    film.develop(ppp)
        .into_iter()
        .map(|c| c * scale as f32)
        .collect()
}

type PssChain = Chain<
    TorusPoint,
    PathSample,
    MetropolisHastings<Mixture<TorusPoint, PathSample>, TorusPoint, PathSample>,
>;

struct ChainSlot {
    chain: PssChain,
    family: usize,
    remaining: Option<u64>,
}

struct Task {
    chains: Vec<ChainSlot>,
    film: Film,
    running: Vec<RunningNormalization>,
    per_depth: Vec<DepthAcceptance>,
    mutations: u64,
    first_nonfinite: Option<Vec<f64>>,
}

/// Mutations per chain per round (bounds the time between previews).
const ROUND: u64 = 256;

/// Stream offsets that keep the bootstrap, resampling and chain streams apart.
const BOOTSTRAP_STREAM: u64 = 1 << 40;
const RESAMPLE_STREAM: u64 = 1 << 41;

/// The primary-sample point of bootstrap candidate `i`.
pub fn bootstrap_point(seed: u64, i: usize) -> TorusPoint {
    TorusPoint::fresh(stream_rng(seed, BOOTSTRAP_STREAM + i as u64))
}

/// Runs the bootstrap: `ln I(u_i)` of every candidate, evaluated in
/// parallel and collected in order, and the `mcmc-core` bootstrap over the
/// candidate indices.
pub fn bootstrap<F: PssPathSampler>(
    target: &PssTarget<'_, F>,
    count: usize,
    seed: u64,
) -> Result<(Bootstrap<usize, ()>, Vec<f64>), MltError> {
    bootstrap_family(std::slice::from_ref(target), count, seed)
}

/// The joint bootstrap of a family: `count` candidates per member;
/// candidate `j` belongs to member `j / count`. Its `b*` is the mean of
/// the members' `b_d`.
pub fn bootstrap_family<F: PssPathSampler>(
    targets: &[PssTarget<'_, F>],
    count: usize,
    seed: u64,
) -> Result<(Bootstrap<usize, ()>, Vec<f64>), MltError> {
    if count == 0 {
        return Err(MltError::Setting(
            "the bootstrap needs at least one candidate".into(),
        ));
    }
    let total = count * targets.len();
    let log_i: Vec<f64> = (0..total)
        .into_par_iter()
        .map(|j| {
            targets[j / count]
                .trace(&bootstrap_point(seed, j))
                .log_density
        })
        .collect();
    // The candidates are indices; their density is the precomputed I(u_i)
    // and the reference density of PSS is 1 (ln p₀ = 0).
    let lookup = |i: usize| log_i[i];
    let mut next = 0usize;
    let mut rng = stream_rng(seed, RESAMPLE_STREAM);
    let boot = Bootstrap::from_sampler(&lookup, total, &mut rng, |_| {
        let i = next;
        next += 1;
        (i, 0.0)
    })?;
    Ok((boot, log_i))
}

/// Renders `scene` with PSSMLT over `sampler`.
pub fn render_pssmlt<F: PssPathSampler>(
    scene: &Scene,
    sampler: F,
    settings: &PssmltSettings,
    stop: &AtomicBool,
    observer: &dyn MltObserver,
) -> Result<MltResult, MltError> {
    render_family(scene, vec![sampler], settings, stop, observer)
}

/// Renders `scene` with a family of PSS targets (one per sampler; MMLT:
/// one per path depth). The bootstrap draws `settings.bootstrap`
/// candidates per member, chain starts are resampled jointly (so members
/// get chains in proportion to their `b_d`), each chain stays with its
/// member, and the image scale is `b = Σ_d b_d`, i.e. `b*` of the joint
/// bootstrap times the number of members (pbrt-v4's `mlt`).
pub fn render_family<F: PssPathSampler>(
    scene: &Scene,
    samplers: Vec<F>,
    settings: &PssmltSettings,
    stop: &AtomicBool,
    observer: &dyn MltObserver,
) -> Result<MltResult, MltError> {
    if samplers.is_empty() {
        return Err(MltError::Setting("no path sampler".into()));
    }
    if samplers.len() > 1 && settings.mis_large_steps {
        return Err(MltError::Setting(
            "Kelemen's MIS combination needs a single target (not MMLT)".into(),
        ));
    }
    if settings.chains == 0 || settings.tasks == 0 {
        return Err(MltError::Setting(
            "chains and tasks must be at least 1".into(),
        ));
    }
    if settings.mutations_per_pixel.is_none() && settings.time_budget.is_none() {
        return Err(MltError::Setting(
            "give a number of mutations per pixel or a time budget".into(),
        ));
    }
    settings.mutation.kernel::<PathSample>()?;
    let start = Instant::now();
    let deadline = settings.time_budget.map(|b| start + b);
    let out_of_time = || deadline.is_some_and(|d| Instant::now() >= d);
    let members = samplers.len();
    let targets: Vec<PssTarget<'_, F>> = samplers
        .into_iter()
        .map(|sampler| PssTarget { scene, sampler })
        .collect();
    let (width, height) = (scene.film.width, scene.film.height);
    let pixels = width as u64 * height as u64;

    // Start-up bias elimination.
    let seed = settings.seed;
    let (boot, log_i) = bootstrap_family(&targets, settings.bootstrap, seed)?;
    if boot.b() == 0.0 || !boot.b().is_finite() {
        return Err(MltError::BlackScene {
            candidates: boot.len(),
            invalid: boot.invalid_candidates(),
        });
    }
    let b_star = boot.b() * members as f64;
    let mut boot_running = vec![RunningNormalization::new(); members];
    for (j, &lw) in log_i.iter().enumerate() {
        boot_running[j / settings.bootstrap].add(lw);
    }
    let mut rng = stream_rng(seed, RESAMPLE_STREAM + 1);
    let starts = boot.resample(settings.chains, &mut rng)?;
    let bootstrap_seconds = start.elapsed().as_secs_f64();

    // Chains, grouped into tasks in contiguous blocks.
    let total = settings.mutations_per_pixel.map(|m| m * pixels);
    let per_chain = |c: usize| {
        total.map(|t| {
            let n = settings.chains as u64;
            t / n + u64::from((c as u64) < t % n)
        })
    };
    let filter = Arc::new(Filter::new(scene.film.filter, width, height));
    let tasks_n = settings.tasks.min(settings.chains);
    let mut tasks: Vec<Task> = (0..tasks_n)
        .map(|_| Task {
            chains: Vec::new(),
            film: Film::new(width, height, filter.clone()),
            running: vec![RunningNormalization::new(); members],
            per_depth: Vec::new(),
            mutations: 0,
            first_nonfinite: None,
        })
        .collect();
    for (c, s) in starts.iter().enumerate() {
        let kernel = settings.mutation.kernel::<PathSample>()?;
        let family = s.state / settings.bootstrap;
        let chain = Chain::new(
            &targets[family],
            bootstrap_point(seed, s.state),
            MetropolisHastings::new(kernel),
            stream_rng(seed, c as u64),
        )?;
        tasks[c * tasks_n / settings.chains].chains.push(ChainSlot {
            chain,
            family,
            remaining: per_chain(c),
        });
    }

    let weights = Weights {
        mis: settings.mis_large_steps,
        p_large: settings.mutation.large_step_probability,
        b: b_star,
    };
    let mut interrupted = false;
    let mut last_preview = Instant::now();
    loop {
        let all_done = tasks
            .iter()
            .all(|t| t.chains.iter().all(|c| c.remaining == Some(0)));
        if all_done {
            break;
        }
        if stop.load(Ordering::Relaxed) || out_of_time() {
            interrupted = true;
            break;
        }
        let aborted = AtomicBool::new(false);
        tasks.par_iter_mut().for_each(|task| {
            let Task {
                chains,
                film,
                running,
                per_depth,
                mutations,
                first_nonfinite,
            } = task;
            for slot in chains.iter_mut() {
                if aborted.load(Ordering::Relaxed) || stop.load(Ordering::Relaxed) || out_of_time()
                {
                    aborted.store(true, Ordering::Relaxed);
                    return;
                }
                let n = slot.remaining.map_or(ROUND, |r| r.min(ROUND));
                let target = &targets[slot.family];
                let running = &mut running[slot.family];
                for _ in 0..n {
                    slot.chain.step_with(target, |t| {
                        observe(t, &weights, film, running, per_depth, first_nonfinite);
                    });
                }
                if let Some(r) = slot.remaining.as_mut() {
                    *r -= n;
                }
                *mutations += n;
                observer.mutations_done(n);
            }
        });
        if aborted.load(Ordering::Relaxed) {
            interrupted = true;
            break;
        }
        if last_preview.elapsed() >= settings.preview_every {
            last_preview = Instant::now();
            let (film, mutations, running) = gather(&tasks, &filter, width, height, &boot_running);
            let scale = scale_of(settings, &weights, &running);
            observer.preview(&develop(&film, mutations, scale), mutations);
        }
    }

    let (film, mutations, running) = gather(&tasks, &filter, width, height, &boot_running);
    let mut chain_stats: Option<ChainStatistics> = None;
    let mut per_depth: Vec<DepthAcceptance> = Vec::new();
    let mut first_nonfinite = None;
    for t in &tasks {
        for s in &t.chains {
            match chain_stats.as_mut() {
                Some(cs) => cs.merge(s.chain.stats()),
                None => chain_stats = Some(s.chain.stats().clone()),
            }
        }
        if per_depth.len() < t.per_depth.len() {
            per_depth.resize(t.per_depth.len(), DepthAcceptance::default());
        }
        for (d, a) in t.per_depth.iter().enumerate() {
            per_depth[d].proposed += a.proposed;
            per_depth[d].accepted += a.accepted;
        }
        if first_nonfinite.is_none() {
            first_nonfinite.clone_from(&t.first_nonfinite);
        }
    }
    let scale = scale_of(settings, &weights, &running);
    Ok(MltResult {
        film,
        mutations,
        mutations_per_pixel: mutations as f64 / pixels as f64,
        scale,
        bootstrap_b: (b_star, boot.standard_error()),
        running_b: (
            running.iter().map(|r| r.b()).sum(),
            running
                .iter()
                .map(|r| r.standard_error().powi(2))
                .sum::<f64>()
                .sqrt(),
        ),
        chain_stats: chain_stats.unwrap_or_else(|| ChainStatistics::new(Vec::new())),
        per_depth,
        bootstrap_invalid: boot.invalid_candidates(),
        first_nonfinite,
        bootstrap_seconds,
        seconds: start.elapsed().as_secs_f64(),
        interrupted,
    })
}

fn scale_of(settings: &PssmltSettings, w: &Weights, running: &[RunningNormalization]) -> f64 {
    if w.mis {
        1.0
    } else {
        match settings.normalization {
            Normalization::Bootstrap => w.b,
            Normalization::Running => running.iter().map(|r| r.b()).sum(),
        }
    }
}

/// Sums the task films and counters in task order.
fn gather(
    tasks: &[Task],
    filter: &Arc<Filter>,
    width: u32,
    height: u32,
    boot_running: &[RunningNormalization],
) -> (Film, u64, Vec<RunningNormalization>) {
    let mut film = Film::new(width, height, filter.clone());
    let mut running = boot_running.to_vec();
    let mut mutations = 0;
    for t in tasks {
        film.add_film(&t.film);
        for (r, tr) in running.iter_mut().zip(&t.running) {
            r.merge(tr);
        }
        mutations += t.mutations;
    }
    (film, mutations, running)
}

struct Weights {
    mis: bool,
    p_large: f64,
    b: f64,
}

impl Weights {
    /// Splat weight (without the factor `b` unless MIS) of a state with
    /// contribution `i` carrying expected-value weight `a`.
    fn of(&self, a: f64, large: bool, i: f64) -> f64 {
        if self.mis {
            (a + f64::from(u8::from(large))) / (i / self.b + self.p_large)
        } else {
            a / i
        }
    }
}

fn splat_all(film: &mut Film, s: &PathSample, w: f64) {
    if w > 0.0 && w.is_finite() {
        for sp in &s.splats {
            film.splat(sp.p, sp.l * w as f32);
        }
    }
}

/// Expected-value splatting and statistics of one transition.
fn observe(
    t: &Transition<'_, TorusPoint, PathSample>,
    w: &Weights,
    film: &mut Film,
    running: &mut RunningNormalization,
    per_depth: &mut Vec<DepthAcceptance>,
    first_nonfinite: &mut Option<Vec<f64>>,
) {
    let large = t.component == LARGE_STEP_COMPONENT;
    if let Some(y) = t.proposal {
        if large {
            // ln I(y) − ln p(y) with p = 1 on PSS; NaN counts as zero.
            running.add(y.log_density);
        }
        if y.log_density.is_nan() || y.log_density == f64::INFINITY {
            if first_nonfinite.is_none() {
                *first_nonfinite = Some(y.state.materialize());
            }
        } else if y.log_density > f64::NEG_INFINITY {
            let d = y.payload.depth as usize;
            if per_depth.len() <= d {
                per_depth.resize(d + 1, DepthAcceptance::default());
            }
            per_depth[d].proposed += 1;
            per_depth[d].accepted += u64::from(t.accepted);
            let i = y.log_density.exp();
            splat_all(film, &y.payload, w.of(t.alpha, large, i));
        }
        // A black proposal (I = 0) contributes nothing, in either weighting.
    }
    let x = t.current;
    let ix = x.log_density.exp();
    splat_all(film, &x.payload, w.of(1.0 - t.alpha, false, ix));
}
