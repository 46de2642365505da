//! Primary sample space Metropolis light transport (Kelemen et al. 2002) on
//! `mcmc-core`.
//!
//! - **Target**: `ln I(u)`, the log luminance of the contribution of the
//!   path traced from the primary-sample vector `u` ([`PssTarget`]).
//! - **Mutation**: `mcmc-core`'s [`Mixture`] of a
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
//! - **Families** (MMLT): one target per path depth `d`, each with its own
//!   bootstrap `b_d`, chains, film and mutation count; the image is the sum
//!   of the members' images, each normalised by its own mutations
//!   ([`render_family`]). The bootstrap `b_d` of a rare depth can be far
//!   off (on the door-ajar scene, 100 000 candidates give the direct-light
//!   depth a relative standard error near 40%); the running estimate keeps
//!   improving with the large steps.
//!
//! # Parallelism and determinism
//!
//! The chains are cut into about [`PssmltSettings::tasks`] tasks (a number
//! independent of the thread count), each holding chains of one family
//! member; each task owns its chains, one film
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
    /// Chains go to family members in proportion to `b_d^γ`, `γ` this
    /// exponent: 1 (default) is pbrt-v4's share (what a single chain over
    /// all depths spends per depth); 0 gives every member the same number.
    pub depth_allocation_exponent: f64,
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
            depth_allocation_exponent: 1.0,
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

/// What one member of a family (an MMLT depth; the single PSSMLT target)
/// ran and contributes.
#[derive(Clone, Debug)]
pub struct FamilyResult {
    /// Splat film of this member's chains, not yet scaled.
    pub film: Film,
    /// Mutations done by this member's chains.
    pub mutations: u64,
    /// Chains this member ran.
    pub chains: usize,
    /// The scale applied to this member's developed film: its `b_d`
    /// (bootstrap or running, see [`Normalization`]), or 1 with Kelemen's
    /// MIS (where `b_d` is inside the splat weights).
    pub scale: f64,
    /// Bootstrap `b_d` and its standard error.
    pub bootstrap_b: (f64, f64),
    /// Running `⟨b_d⟩` (bootstrap and large steps) and its standard error.
    pub running_b: (f64, f64),
}

impl FamilyResult {
    /// This member's image: its film over its own mutations per pixel,
    /// times its scale (see [`render_family`] for why per member).
    pub fn image(&self) -> Vec<Rgb> {
        develop(&self.film, self.mutations, self.scale)
    }
}

/// The outcome of a PSSMLT render.
#[derive(Clone, Debug)]
pub struct MltResult {
    /// Per member of the family (one for PSSMLT, one per depth for MMLT).
    pub families: Vec<FamilyResult>,
    /// Mutations done.
    pub mutations: u64,
    /// Mutations per pixel (all members).
    pub mutations_per_pixel: f64,
    /// The sum of the members' scales (`b` unless MIS).
    pub scale: f64,
    /// Bootstrap `b* = Σ_d b_d` and its standard error.
    pub bootstrap_b: (f64, f64),
    /// Running `⟨b⟩ = Σ_d ⟨b_d⟩` (bootstrap and large steps) and its
    /// standard error.
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
    /// The developed image, row-major: the sum of the members' images.
    pub fn image(&self) -> Vec<Rgb> {
        sum_images(self.families.iter().map(FamilyResult::image))
    }
}

/// The pixel-wise sum of images of equal size.
fn sum_images(images: impl Iterator<Item = Vec<Rgb>>) -> Vec<Rgb> {
    let mut out: Option<Vec<Rgb>> = None;
    for img in images {
        match out.as_mut() {
            None => out = Some(img),
            Some(o) => {
                for (a, b) in o.iter_mut().zip(img) {
                    *a += b;
                }
            }
        }
    }
    out.unwrap_or_default()
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
    remaining: Option<u64>,
}

/// A work unit: chains of one family member, run one after another.
struct Task {
    family: usize,
    chains: Vec<ChainSlot>,
    film: Film,
    running: RunningNormalization,
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

/// `ln I(u_j)` of the `count` candidates of every member, evaluated in
/// parallel and collected in order; candidate `j` belongs to member
/// `j / count`.
fn bootstrap_log_densities<F: PssPathSampler>(
    targets: &[PssTarget<'_, F>],
    count: usize,
    seed: u64,
) -> Vec<f64> {
    (0..count * targets.len())
        .into_par_iter()
        .map(|j| {
            targets[j / count]
                .trace(&bootstrap_point(seed, j))
                .log_density
        })
        .collect()
}

/// The `mcmc-core` bootstrap over candidate indices `offset..offset +
/// log_i.len()` with densities `log_i` (the reference density of PSS is 1,
/// ln p₀ = 0).
fn index_bootstrap(log_i: &[f64], offset: usize) -> Result<Bootstrap<usize, ()>, MltError> {
    let lookup = |i: usize| log_i[i - offset];
    let mut next = offset;
    // The sampler hands out indices in order; the generator is not used.
    let mut rng = stream_rng(0, RESAMPLE_STREAM);
    Ok(Bootstrap::from_sampler(
        &lookup,
        log_i.len(),
        &mut rng,
        |_| {
            let i = next;
            next += 1;
            (i, 0.0)
        },
    )?)
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
    let log_i = bootstrap_log_densities(targets, count, seed);
    let boot = index_bootstrap(&log_i, 0)?;
    Ok((boot, log_i))
}

/// Chains per member: proportional to `share[d]` (by default `b_d`, the
/// share a single chain over the joint space would spend there, as
/// pbrt-v4's per-chain draw of the depth gives on average), rounded by
/// largest remainder, with at least one chain for every member with a
/// positive share while chains last.
fn allocate_chains(chains: usize, b: &[f64]) -> Vec<usize> {
    let total: f64 = b.iter().sum();
    let quota: Vec<f64> = b.iter().map(|&x| chains as f64 * x / total).collect();
    let mut n: Vec<usize> = quota.iter().map(|q| q.floor() as usize).collect();
    let positive: Vec<usize> = (0..b.len()).filter(|&d| b[d] > 0.0).collect();
    if chains >= positive.len() {
        for &d in &positive {
            n[d] = n[d].max(1);
        }
    }
    let mut assigned: usize = n.iter().sum();
    // Largest fractional remainder first (ties: lower index).
    let mut order = positive.clone();
    order.sort_by(|&a, &c| {
        let (ra, rc) = (quota[a] - quota[a].floor(), quota[c] - quota[c].floor());
        rc.total_cmp(&ra).then(a.cmp(&c))
    });
    for &d in order.iter().cycle().take(chains.saturating_sub(assigned)) {
        n[d] += 1;
        assigned += 1;
    }
    // The minimum of one chain can overshoot: take back from the largest.
    while assigned > chains {
        let d = (0..n.len())
            .max_by_key(|&d| (n[d], usize::MAX - d))
            .unwrap_or(0);
        n[d] -= 1;
        assigned -= 1;
    }
    n
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
/// one per path depth), each with its own normalisation.
///
/// The bootstrap draws `settings.bootstrap` candidates per member `d`,
/// which give `b_d = ∫ I_d` and that member's chain starts (resampled
/// `∝ I_d` among its own candidates). Chains are allocated to members in
/// proportion to `b_d` (`allocate_chains`) and stay with their member.
/// The image is `Σ_d b_d · film_d / (M_d / pixels)`, with `M_d` the
/// mutations member `d` actually ran. pbrt-v4 instead scales one film by
/// `b = Σ_d b_d` over all mutations, which is right only if every member's
/// share of the mutations equals `b_d / b`; with chains drawn at random
/// (and time budgets cutting rounds short) it does not, and each depth's
/// brightness is then off by the relative error of its chain count — a
/// bias that more mutations do not remove.
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
    if settings.chains == 0 || settings.tasks == 0 {
        return Err(MltError::Setting(
            "chains and tasks must be at least 1".into(),
        ));
    }
    if settings.bootstrap == 0 {
        return Err(MltError::Setting(
            "the bootstrap needs at least one candidate".into(),
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

    // Start-up bias elimination, per member.
    let seed = settings.seed;
    let count = settings.bootstrap;
    let log_i = bootstrap_log_densities(&targets, count, seed);
    let boots: Vec<Bootstrap<usize, ()>> = (0..members)
        .map(|d| index_bootstrap(&log_i[d * count..(d + 1) * count], d * count))
        .collect::<Result<_, _>>()?;
    let b_d: Vec<f64> = boots.iter().map(|b| b.b()).collect();
    let b_star: f64 = b_d.iter().sum();
    let invalid: usize = boots.iter().map(|b| b.invalid_candidates()).sum();
    if b_star == 0.0 || !b_star.is_finite() {
        return Err(MltError::BlackScene {
            candidates: count * members,
            invalid,
        });
    }
    let b_star_se = boots
        .iter()
        .map(|b| b.standard_error().powi(2))
        .sum::<f64>()
        .sqrt();
    let mut boot_running = vec![RunningNormalization::new(); members];
    for (j, &lw) in log_i.iter().enumerate() {
        boot_running[j / count].add(lw);
    }
    let gamma = settings.depth_allocation_exponent;
    if !gamma.is_finite() || gamma < 0.0 {
        return Err(MltError::Setting(format!(
            "the depth allocation exponent must be finite and ≥ 0, got {gamma}"
        )));
    }
    let shares: Vec<f64> = b_d
        .iter()
        .map(|&b| if b > 0.0 { b.powf(gamma) } else { 0.0 })
        .collect();
    let chains_of = allocate_chains(settings.chains, &shares);
    let mut starts: Vec<Vec<usize>> = Vec::with_capacity(members);
    for (d, boot) in boots.iter().enumerate() {
        let mut rng = stream_rng(seed, RESAMPLE_STREAM + 1 + d as u64);
        let s = if chains_of[d] == 0 {
            Vec::new()
        } else {
            boot.resample(chains_of[d], &mut rng)?
        };
        starts.push(s.into_iter().map(|x| x.state).collect());
    }
    let bootstrap_seconds = start.elapsed().as_secs_f64();

    // Chains, numbered member by member, grouped into tasks of one member
    // each (about `settings.tasks` in all) in contiguous blocks.
    let total = settings.mutations_per_pixel.map(|m| m * pixels);
    let per_chain = |c: usize| {
        total.map(|t| {
            let n = settings.chains as u64;
            t / n + u64::from((c as u64) < t % n)
        })
    };
    let filter = Arc::new(Filter::new(scene.film.filter, width, height));
    let mut tasks: Vec<Task> = Vec::new();
    let mut c = 0usize;
    for (d, member_starts) in starts.iter().enumerate() {
        let n = member_starts.len();
        if n == 0 {
            continue;
        }
        let k = ((settings.tasks * n + settings.chains / 2) / settings.chains).clamp(1, n);
        let first = tasks.len();
        for _ in 0..k {
            tasks.push(Task {
                family: d,
                chains: Vec::new(),
                film: Film::new(width, height, filter.clone()),
                running: RunningNormalization::new(),
                per_depth: Vec::new(),
                mutations: 0,
                first_nonfinite: None,
            });
        }
        for (i, &candidate) in member_starts.iter().enumerate() {
            let chain = Chain::new(
                &targets[d],
                bootstrap_point(seed, candidate),
                MetropolisHastings::new(settings.mutation.kernel::<PathSample>()?),
                stream_rng(seed, c as u64),
            )?;
            tasks[first + i * k / n].chains.push(ChainSlot {
                chain,
                remaining: per_chain(c),
            });
            c += 1;
        }
    }

    let weights: Vec<Weights> = b_d
        .iter()
        .map(|&b| Weights {
            mis: settings.mis_large_steps,
            p_large: settings.mutation.large_step_probability,
            b,
        })
        .collect();
    // Previews and the final image gather the same per-depth films.
    let gather_now = |tasks: &[Task]| {
        gather(
            tasks,
            settings,
            &boots,
            &boot_running,
            &chains_of,
            &filter,
            (width, height),
        )
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
                family,
                chains,
                film,
                running,
                per_depth,
                mutations,
                first_nonfinite,
            } = task;
            let target = &targets[*family];
            let w = &weights[*family];
            for slot in chains.iter_mut() {
                if aborted.load(Ordering::Relaxed) || stop.load(Ordering::Relaxed) || out_of_time()
                {
                    aborted.store(true, Ordering::Relaxed);
                    return;
                }
                let n = slot.remaining.map_or(ROUND, |r| r.min(ROUND));
                for _ in 0..n {
                    slot.chain.step_with(target, |t| {
                        observe(t, w, film, running, per_depth, first_nonfinite);
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
            let families = gather_now(&tasks);
            let mutations = families.iter().map(|f| f.mutations).sum();
            observer.preview(
                &sum_images(families.iter().map(FamilyResult::image)),
                mutations,
            );
        }
    }

    let families = gather_now(&tasks);
    let mutations: u64 = families.iter().map(|f| f.mutations).sum();
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
    let running_b = (
        families.iter().map(|f| f.running_b.0).sum(),
        families
            .iter()
            .map(|f| f.running_b.1.powi(2))
            .sum::<f64>()
            .sqrt(),
    );
    Ok(MltResult {
        scale: families.iter().map(|f| f.scale).sum(),
        families,
        mutations,
        mutations_per_pixel: mutations as f64 / pixels as f64,
        bootstrap_b: (b_star, b_star_se),
        running_b,
        chain_stats: chain_stats.unwrap_or_else(|| ChainStatistics::new(Vec::new())),
        per_depth,
        bootstrap_invalid: invalid,
        first_nonfinite,
        bootstrap_seconds,
        seconds: start.elapsed().as_secs_f64(),
        interrupted,
    })
}

/// Sums the task films and counters of every member, in task order.
fn gather(
    tasks: &[Task],
    settings: &PssmltSettings,
    boots: &[Bootstrap<usize, ()>],
    boot_running: &[RunningNormalization],
    chains_of: &[usize],
    filter: &Arc<Filter>,
    (w, h): (u32, u32),
) -> Vec<FamilyResult> {
    let mut films: Vec<Film> = (0..boots.len())
        .map(|_| Film::new(w, h, filter.clone()))
        .collect();
    let mut running = boot_running.to_vec();
    let mut mutations = vec![0u64; boots.len()];
    for t in tasks {
        films[t.family].add_film(&t.film);
        running[t.family].merge(&t.running);
        mutations[t.family] += t.mutations;
    }
    films
        .into_iter()
        .enumerate()
        .map(|(d, film)| {
            let bootstrap_b = (boots[d].b(), boots[d].standard_error());
            let running_b = (running[d].b(), running[d].standard_error());
            let scale = if settings.mis_large_steps {
                1.0
            } else {
                match settings.normalization {
                    Normalization::Bootstrap => bootstrap_b.0,
                    Normalization::Running => running_b.0,
                }
            };
            FamilyResult {
                film,
                mutations: mutations[d],
                chains: chains_of[d],
                scale,
                bootstrap_b,
                running_b,
            }
        })
        .collect()
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
            // `I(y)` itself (ln I is its logarithm): saves an `exp` per state.
            let i = y.payload.luminance();
            splat_all(film, &y.payload, w.of(t.alpha, large, i));
        }
        // A black proposal (I = 0) contributes nothing, in either weighting.
    }
    let x = t.current;
    let ix = x.payload.luminance();
    splat_all(film, &x.payload, w.of(1.0 - t.alpha, false, ix));
}

#[cfg(test)]
mod tests {
    use super::allocate_chains;

    #[test]
    fn chains_follow_the_shares_and_every_positive_member_gets_one() {
        // Exact quotas are met exactly.
        assert_eq!(allocate_chains(10, &[1.0, 3.0, 6.0]), vec![1, 3, 6]);
        // Largest remainder: quotas 3.33, 3.33, 3.33 -> the first gets the spare.
        assert_eq!(allocate_chains(10, &[1.0, 1.0, 1.0]), vec![4, 3, 3]);
        // Zero shares get no chain; a tiny positive share still gets one,
        // taken from the largest member.
        assert_eq!(allocate_chains(100, &[0.0, 1e-6, 1.0]), vec![0, 1, 99]);
        // More positive members than chains: no minimum, still `chains` in all.
        // (quotas 0.25, 0.25, 0.25, 1.25: floors 0, 0, 0, 1, the spare to the first tie)
        assert_eq!(allocate_chains(2, &[1.0, 1.0, 1.0, 5.0]), vec![1, 0, 0, 1]);
        // Always exactly `chains`, never more than the quota plus one.
        let shares = [0.023, 0.048, 0.035, 0.031, 0.023, 0.0];
        let n = allocate_chains(1000, &shares);
        assert_eq!(n.iter().sum::<usize>(), 1000);
        let total: f64 = shares.iter().sum();
        for (k, s) in n.iter().zip(shares) {
            let quota = 1000.0 * s / total;
            assert!((*k as f64 - quota).abs() < 1.0, "{k} vs {quota}");
        }
    }
}
