//! MCMC over the light subpaths of vertex connection and merging (Šik's
//! thesis, chapter 6, "Robust light transport simulation via Metropolised
//! bidirectional estimators"; spec `seed000-ch5-6.md` §6.2–6.5, App. 6.B).
//!
//! # One iteration (Fig. 6.8)
//! 1. **Camera pass.** One stratified camera subpath per pixel (the
//!    `N` pixels in `TILE`² tiles), every vertex kept with its MIS
//!    quantities ([`CameraSet`]); at each vertex the path-tracing techniques
//!    (emitter found, next-event estimation with a fresh light sample) are
//!    evaluated at once, independent of the light subpaths
//!    (`Vcm::path_tracing_at`, `vcm`'s code). A hash grid over the
//!    connectible camera vertices serves the merges.
//! 2. **Restart.** `candidates` independent light subpaths (uniform
//!    primary-sample points, each with a uniformly chosen camera subpath)
//!    are evaluated; each chain pair starts by importance resampling from
//!    them: the contribution chain ∝ `lum C^Ω`, the visibility chain
//!    uniformly among those with `C^Ω > 0` (§6.3.2), with
//!    `restart = weighted` (the default) among those other than the
//!    contribution chain's, and the iteration's light side carries the
//!    pool's weight (below).
//! 3. **Chains.** `units` independent pairs, each running its share of
//!    the iteration's `light_subpaths · N` light subpaths (default one
//!    per pixel, as the thesis runs, §6.4), alternating the two chains
//!    (Fig. 6.10). Each step: a camera subpath chosen uniformly for the
//!    connections; one Metropolis–Hastings step of `mcmc-core`
//!    ([`MetropolisHastings`] with Hachisuka & Jensen's adaptive small step
//!    [`AdaptiveTorusStep`], target acceptance 0.234, and in the visibility
//!    chain only a large step with probability `large_step`); expected-value
//!    splats of the current state and the proposal; one replica-exchange
//!    attempt between the two chains (`mcmc-core`'s
//!    [`swap_log_acceptance`] and [`accept`], Eq. 4.11).
//!
//! # The light-subpath contribution (Eq. 6.1)
//! [`light_contribution`]: the light subpath traced from a primary-sample
//! point ([`Vcm::trace_light_subpath`], which also connects each vertex to
//! the camera), its connections to the one chosen camera subpath, and its
//! merges with every stored camera vertex within the radius — `vcm`'s
//! techniques with `vcm`'s MIS weights, so that `N` independent subpaths
//! give `vcm`'s light-side image exactly. Its parts keep where they land
//! (a camera sample or a raster splat); the same value is the chains'
//! target (its luminance) and what is splatted.
//!
//! The camera subpath chosen for the connections is not part of the
//! state: each step draws a fresh one and the current state keeps the value
//! it was evaluated with. This is Metropolis–Hastings on the joint space
//! (point, camera subpath) with an independent uniform proposal of the
//! camera subpath (a pseudo-marginal move), so both targets are exact
//! densities there: `π_con = lum C^Ω(u, k)` (Eq. 6.2) and
//! `π_vis = 1[lum C^Ω(u, k) > 0]` (Eq. 6.3).
//!
//! # Estimator
//! With `n_c` steps of chain `c` in the iteration and the normalisations
//! `b_c = ∫ π_c` (Eq. 6.4: running means over every independent light
//! subpath of the render — the restart candidates and the large-step
//! proposals — frozen at the start of each iteration), a state `u` with
//! acceptance weight `w` (α for the proposal, 1 − α for the current state)
//! adds `w · N · C^Ω(u) / (n_vis π_vis(u)/b_vis + n_con π_con(u)/b_con)`:
//! the balance heuristic over the two chains (Eq. 6.5, Fig. 6.10 line 20,
//! which has `n_c = N/2`). Parts that land on camera sample `k` are added to
//! its estimate (as `vcm` adds connections and merges), raster parts are
//! splats.
//!
//! # Restarts (`restart`, default `weighted`)
//! The estimator above holds when each chain's states follow its target
//! `π_c/b_c`. A restart by importance resampling from `M` candidates does
//! not start there: it draws candidate `i` with probability
//! `lum_i / Σ_j lum_j`, which under-represents the bright tail of
//! `lum C^Ω` (a bright candidate's share of its pool is smaller than its
//! share of the target), more so the fewer visible candidates a pool
//! holds and the heavier the tail. The contribution chain, whose small
//! steps do not reach that tail within an iteration, starts too dim and
//! hands its dim states to the visibility chain through the exchanges;
//! the image then reads low by an amount that shrinks with `M` but not
//! with the iterations (docs/vcm.md, sessions 17–18). `restart =
//! resampled` is that rule (the thesis's, which dropped the start-up
//! weight, §6.3.2).
//!
//! `weighted` uses importance resampling's proper weight: with
//! `W = (1/M) Σ_j lum_j`, `E[W h(x₀)] = ∫ h π_con` for any `M`, and since
//! `W · P(i chosen) = lum_i / M`, under that weighting the other
//! candidates stay independent draws of the tracing density. So the
//! visibility chain starts uniformly among the visible candidates *other*
//! than the contribution chain's (when there is none, from a fresh light
//! subpath drawn until it is visible, one per iteration), and the pair's start
//! `(x₀, y₀)`, weighted by `W`, is `b_con` times the product of the two
//! targets; Metropolis–Hastings steps and exchanges keep that, so every
//! later state is properly weighted too. Iteration `i`'s light side `G_i`
//! (splats and camera-sample parts) is therefore weighted by its pool's
//! `W_i`, and the image's light side is `Σ_i W_i G_i / Σ_i W_i` (a
//! self-normalised mean over iterations: consistent in the iterations at
//! any `M`, and `b_con` keeps setting the level, so the weights do not
//! add the noise of a per-iteration normalisation). An iteration without
//! a visible candidate has `W = 0`, so it is no longer a bias either. The
//! visibility chain's mean luminance (`con_estimate = visibility`) is
//! weighted the same way. The cost is the spread of the weights: the
//! sidecar's `restart_weight_ess` is the effective share of the
//! iterations, `(Σ W)² / (n Σ W²)`. With `normalisation = iteration` the
//! restarts are `resampled` (each iteration's normalisation comes from its
//! own pool, PSSMLT's start-up weight with `direct`).
//!
//! `b_vis`, `b_con` of an iteration come from the earlier iterations (the
//! first iterations, before any visible subpath, from their own), so that
//! they do not share the pool that sets its weight.
//!
//! # MIS between path tracing and the chains (§6.3.4)
//! The visibility chain draws light subpaths with density `p/b_vis`, the
//! contribution chain with (approximately, as PSSMLT assumes) `p`: their
//! mixture has `k = (n_vis/b_vis + n_con)/N` times the tracing density.
//! With `vis_pdf = true` every light-subpath technique's density in the
//! VCM weights is multiplied by `k` ([`MisFactors::with_light_density_scale`]),
//! in the path-tracing weights as in `C^Ω`, so the weights still sum to one
//! over all techniques. `b_vis` for `k` is estimated once, before the first
//! iteration, from its own `candidates` light subpaths, and `k` then stays
//! fixed, so that every `C^Ω` of the render — and the running `b_con` — use
//! the same weights.
//!
//! # Estimating `b_con` (`con_estimate`, default `transfer`)
//! `direct` (Eq. 6.4) is the mean of `lum C^Ω` over the independent light
//! subpaths. Only the visible ones (`b_vis`, under 1% on an interior)
//! carry it, so it is `b_vis` times the mean luminance of a few dozen
//! visible subpaths per iteration. The visibility chain samples exactly
//! the visible subpaths uniformly (`π_vis/b_vis`; it restarts in
//! stationarity, uniformly among the visible candidates), thousands per
//! iteration: `b_con = b_vis · E_vis[lum C^Ω]` (`visibility`), with the
//! chain's mean taken from the expected value `(1 − α) lum(x) + α lum(y)`
//! of each step. Both estimate the same constant; `combined` weighs them
//! by their inverse squared standard errors (iteration batches). With
//! `visibility` the denominator of Eq. 6.5 becomes
//! `(n_vis π_vis + n_con lum/E_vis[lum]) / b_vis`: the image level then
//! hangs on `b_vis` alone. Estimates use earlier iterations only (frozen
//! per iteration as Eq. 6.4's); before the visibility chain has run, and
//! for `combined` before two iterations, `direct` is used.
//!
//! `transfer` (the default since session 16) attacks what makes `direct`
//! noisy: the scale `k` of the MIS
//! (above) hands the light-subpath techniques the paths that path tracing
//! samples well, and independent light subpaths, drawn with density `p`,
//! not `k·p`, estimate those paths' share badly (session 16: on an
//! interior `k ≈ 120` raised `b_con` from 0.0125 to 0.0216 and its
//! relative error from ~2.3% to ~4.5%, and the image level follows
//! `b_con`). The weights sum to one over all techniques for any `k`, so
//! `b_con(k) = b_con(1) + Δ`, where `b_con(1)` is Eq. 6.4 with the tracing
//! density's weights (`k = 1`; only visible subpaths need the second
//! evaluation) and `Δ`, per light subpath, is the mean over the camera
//! samples of `lum(PT with k = 1 weights − PT with k weights)`: the energy
//! that `k` moves off path tracing, measured where path tracing sees it.
//! Both terms are estimated with the weights that suit their samples.
//! With merging the identity holds up to the difference of the merge
//! kernel's bias under the two weightings (it vanishes with the radius);
//! the image total then converges to `vcm`'s (`k = 1`) total instead of
//! that of the `k`-weighted techniques.
//!
//! Determinism: every random number comes from a stream keyed by the seed,
//! the iteration and the unit (tile, candidate block, chain pair), and
//! results are joined in unit order: one seed gives the same image on any
//! thread count.
//!
//! Distributed ([`crate::cluster`], `mpirun`): every rank makes every
//! iteration's camera pass, the pilot, the restart candidates and the
//! fresh visible subpath (every chain pair reads them all; the pool's
//! restart weight `W` follows from them, so every rank holds it) but runs
//! only the chain pairs dealt to it (pair `p` on rank `p mod K`; its
//! chains live there for the whole run). After each iteration every rank
//! gets every pair's normalisation sums, the visibility chain's already
//! weighted by `W` (an all-gather, bit-exact), and merges them in pair
//! order, so all hold the single process's `b_vis`, `b_con` for the next
//! iteration; rank 0 gets every pair's splat film and camera-sample
//! estimates and adds them in pair order into the light side's own film,
//! the additions one process makes. The ranks agree (an all-gather of a
//! flag) wherever a stop is checked between the phases, so all drop the
//! same iteration: the image is the single process's for any number of
//! ranks, with either restart rule.
//!
//! # Checkpoints
//! With `--checkpoint FILE` (session 20) rank 0 saves after every
//! iteration, in the per-pixel driver's format ([`crate::checkpoint`],
//! version 3: two films and more words than version 2 allowed), the
//! path-tracing film, the light side's film, the iterations done and, as
//! the integrator's words (`McmcVcm::saved_words`), everything an
//! iteration reads from the ones before it: the MIS scale `k`, the restart
//! weights, the running normalisation with its per-iteration batches (8
//! numbers an iteration), the tally and, per chain pair, its report
//! (tally, swaps, chain statistics), each chain's random stream and its
//! adaptive small step's state ([`Kernel::state_words`]). A chain's
//! current state is not saved: every iteration restarts both chains from
//! its own pool before their first step. On a cluster rank 0 gathers the
//! pairs' records, and on resume broadcasts the words; every rank restores
//! every pair (it runs its own), rank 0 the films.

use super::bdpt::SubpathBuffers;
use super::path_vertex::{Vertex, VertexKind};
use super::registry::IntegratorSettings;
use super::vcm::{
    LightVertex, MergePoint, MisFactors, PartialMis, TECHNIQUE_NAMES, Tally, Technique, Vcm,
    VcmMode, VcmSettings, connections_at,
};
use super::{RenderError, Rendered, RunSettings};
use crate::checkpoint::{Checkpoint, Progress};
use crate::cluster::{Counters, Parcel, owns};
use crate::color::Rgb;
use crate::deadline::Deadline;
use crate::film::{Film, Filter};
use crate::hash_grid::HashGrid;
use crate::observer::Observer;
use crate::pss::PssSource;
use crate::render::unit_source;
use crate::sampling::RandomSource;
use crate::scene::Scene;
use glam::Vec2;
use mcmc_core::chain::{Algorithm, Chain, Transition};
use mcmc_core::kernel::{AdaptiveTorusStep, Independent, Kernel, Mixture};
use mcmc_core::mh::{MetropolisHastings, accept};
use mcmc_core::replica::swap_log_acceptance;
use mcmc_core::rng::{ChainRng, child_rng, rng_from_words, rng_words, stream_rng, uniform};
use mcmc_core::sample::Sample;
use mcmc_core::space::{PrimarySampleSpace, TorusPoint};
use mcmc_core::stats::ChainStatistics;
use mcmc_core::target::{Evaluation, Target};
use rayon::prelude::*;
use std::cell::RefCell;
use std::f32::consts::PI;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Tile edge of the camera pass, in pixels.
const TILE: u32 = 32;
/// Blocks the restart candidates are traced in (fixed: the image must not
/// depend on the thread count).
const CANDIDATE_BLOCKS: usize = 16;
/// Light subpaths between two checks of the stop flag.
const STOP_CHECK: usize = 256;
/// Candidates per block in a round of [`McmcVcm::trace_candidates`]: the
/// pool can be cut between rounds (16 × 4096 candidates, tens of
/// milliseconds on two cores).
const CANDIDATE_ROUND: usize = 4096;
/// Fresh light subpaths per candidate tried for the visibility chains'
/// restart when the pool's one visible candidate went to the contribution
/// chains ([`Restart::Weighted`]): a pool with one visible candidate
/// suggests about `candidates` are needed; 16 times that fail with
/// probability about e^−16.
const FRESH_TRIES: usize = 16;
/// Stream tags of the random streams (mixed with iteration and unit).
const STREAM_CANDIDATES: u64 = 1 << 40;
const STREAM_CHAINS: u64 = 2 << 40;
const STREAM_STEPS: u64 = 3 << 40;
const STREAM_PILOT: u64 = 4 << 40;
const STREAM_FRESH: u64 = 5 << 40;

/// Where one part of a light subpath's contribution lands.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Landing {
    /// Added to the estimate of camera sample (subpath) `k` of the
    /// iteration: connections and merges.
    Camera(u32),
    /// Splatted at a raster position: light tracing.
    Raster(Vec2),
}

/// One technique's contribution of a light subpath.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Part {
    /// Where it lands.
    pub at: Landing,
    /// RGB, MIS-weighted, normalised as `vcm` adds it.
    pub l: Rgb,
    /// The technique.
    pub technique: Technique,
}

/// `C^Ω` of one light subpath (Eq. 6.1): its parts and their total luminance.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LightContribution {
    /// Every technique's contribution with where it lands.
    pub parts: Vec<Part>,
    /// `lum C^Ω`: the luminance of the sum (no pixel filter).
    pub luminance: f64,
    /// False when a part was NaN or infinite (the target is then invalid).
    pub finite: bool,
}

/// The camera subpaths of one tile, every vertex kept. Its buffers are
/// kept from one iteration to the next (cleared, not freed): a fresh
/// tile's growth cost ≈ 1000 page faults an iteration (docs/vcm.md,
/// "Session 24").
#[derive(Debug, Default)]
struct TileSubpaths {
    vertices: Vec<Vertex>,
    mis: Vec<PartialMis>,
    /// Subpath `k` holds `vertices[starts[k]..starts[k + 1]]`.
    starts: Vec<u32>,
    /// Raster position of each camera sample.
    rasters: Vec<Vec2>,
    /// Path-tracing estimate of each camera sample.
    estimates: Vec<Rgb>,
}

impl TileSubpaths {
    /// Number of camera subpaths.
    fn len(&self) -> usize {
        self.starts.len().saturating_sub(1)
    }

    /// Subpath `k`: its vertices and their MIS quantities.
    fn subpath(&self, k: usize) -> (&[Vertex], &[PartialMis]) {
        let r = self.starts[k] as usize..self.starts[k + 1] as usize;
        (&self.vertices[r.clone()], &self.mis[r])
    }

    /// Clears it for a tile of `pixels` camera samples (the per-sample
    /// buffers at their exact size: a tile's size never changes).
    fn clear(&mut self, pixels: usize) {
        self.vertices.clear();
        self.mis.clear();
        self.rasters.clear();
        self.rasters.reserve_exact(pixels);
        self.estimates.clear();
        self.estimates.reserve_exact(pixels);
        self.starts.clear();
        self.starts.reserve_exact(pixels + 1);
        self.starts.push(0);
    }

    /// Appends a subpath with its raster position and estimate.
    fn push(&mut self, z: &[Vertex], mis: &[PartialMis], raster: Vec2, estimate: Rgb) {
        self.vertices.extend_from_slice(z);
        self.mis.extend_from_slice(mis);
        self.starts.push(self.vertices.len() as u32);
        self.rasters.push(raster);
        self.estimates.push(estimate);
    }
}

/// The camera subpaths of one iteration, every vertex kept, in the tiles
/// that traced them (not joined into one list: no copy, and each tile's
/// buffers serve the next iteration).
#[derive(Debug, Default)]
pub struct CameraSet {
    /// The tiles in tile order: camera sample `k` is subpath
    /// `k − first[t]` of tile `t = tile_of[k]`.
    tiles: Vec<TileSubpaths>,
    first: Vec<u32>,
    tile_of: Vec<u32>,
    /// (subpath, vertex index) of every connectible camera vertex, in the
    /// order of the grid's indices.
    merge_points: Vec<(u32, u32)>,
    /// Their positions, the grid's input (kept for the next iteration).
    points: Vec<glam::Vec3>,
    grid: HashGrid,
}

impl CameraSet {
    /// Number of camera subpaths.
    pub fn len(&self) -> usize {
        self.tile_of.len()
    }

    /// True when it holds no subpath.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Subpath `k`: its vertices and their MIS quantities.
    pub fn subpath(&self, k: usize) -> (&[Vertex], &[PartialMis]) {
        let t = self.tile_of[k] as usize;
        self.tiles[t].subpath(k - self.first[t] as usize)
    }

    /// Indexes the tiles' subpaths after they were traced.
    fn index(&mut self) {
        self.first.clear();
        self.tile_of.clear();
        for (t, tile) in self.tiles.iter().enumerate() {
            self.first.push(self.tile_of.len() as u32);
            self.tile_of
                .extend(std::iter::repeat_n(t as u32, tile.len()));
        }
    }

    /// Builds the merge grid over the connectible surface vertices (those
    /// `vcm` merges at), for radius `radius`.
    fn build_grid(&mut self, scene: &Scene, radius: f32) {
        self.merge_points.clear();
        self.points.clear();
        let subpaths = self
            .tiles
            .iter()
            .flat_map(|tile| (0..tile.len()).map(|k| tile.subpath(k).0));
        for (k, z) in subpaths.enumerate() {
            for (j, v) in z.iter().enumerate().skip(1) {
                if v.kind != VertexKind::Surface {
                    break;
                }
                if v.is_connectible(scene) {
                    self.merge_points.push((k as u32, j as u32));
                    self.points.push(v.p());
                }
            }
        }
        self.grid.build(self.points.iter().copied(), radius);
    }
}

/// One iteration's camera pass.
#[derive(Debug, Default)]
pub struct CameraPass {
    /// The camera subpaths (subpath `k` is camera sample `k`).
    pub cameras: CameraSet,
    /// Raster position of each camera sample.
    pub rasters: Vec<Vec2>,
    /// Path-tracing estimate of each camera sample.
    pub estimates: Vec<Rgb>,
    /// With `con_estimate = transfer` and a light-density scale `k ≠ 1`:
    /// Σ over the camera samples of `lum` of their path-tracing estimate
    /// with `k = 1` weights minus that with `k` (module docs); else 0.
    pub transfer: f64,
    tally: Tally,
}

/// What the light-subpath contribution of one iteration reads.
pub struct Iteration<'a> {
    /// The VCM integrator (depth, mode, heuristic).
    pub vcm: &'a Vcm,
    /// The MIS constants of the iteration.
    pub factors: MisFactors,
    /// `1/(π r² N)`: the merge kernel normalised by the light subpaths.
    pub merge_norm: f32,
    /// The stored camera subpaths.
    pub cameras: &'a CameraSet,
}

impl<'a> Iteration<'a> {
    /// The iteration of `vcm` with merge radius `radius` over `cameras`
    /// (`N` = their number light subpaths), light-subpath densities scaled
    /// by `light_scale` in the MIS weights.
    pub fn new(vcm: &'a Vcm, cameras: &'a CameraSet, radius: f32, light_scale: f32) -> Self {
        let n = cameras.len();
        Iteration {
            vcm,
            factors: MisFactors::new(vcm.mode, vcm.heuristic, radius, n as f64)
                .with_light_density_scale(light_scale),
            merge_norm: 1.0 / (PI * radius * radius * n as f32),
            cameras,
        }
    }
}

/// Per-thread storage of [`light_contribution`].
#[derive(Default)]
struct Scratch {
    paths: SubpathBuffers,
    light_mis: Vec<PartialMis>,
    store: Vec<LightVertex>,
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// `C^Ω` (Eq. 6.1) of the light subpath traced from `source`: its light
/// tracing, its connections to camera subpath `camera` and its merges with
/// every stored camera vertex within the radius, into `out`. The one
/// function behind both the chains' targets and the image.
pub fn light_contribution(
    scene: &Scene,
    it: &Iteration,
    source: &mut dyn RandomSource,
    camera: usize,
    out: &mut LightContribution,
) {
    out.parts.clear();
    let vcm = it.vcm;
    let f = &it.factors;
    let max_depth = vcm.max_depth as usize;
    let mut tally = Tally::default();
    SCRATCH.with_borrow_mut(|s| {
        s.store.clear();
        vcm.trace_light_subpath(
            scene,
            f,
            source,
            &mut s.paths,
            &mut s.light_mis,
            &mut s.store,
            |technique, raster, l| {
                out.parts.push(Part {
                    at: Landing::Raster(raster),
                    l,
                    technique,
                })
            },
        );
        if s.store.is_empty() {
            return;
        }
        if vcm.mode.connects() && camera < it.cameras.len() {
            let (z, mis) = it.cameras.subpath(camera);
            let mut l = Rgb::BLACK;
            for j in 1..z.len() {
                if z[j].kind != VertexKind::Surface {
                    break;
                }
                if z[j].is_connectible(scene) {
                    connections_at(
                        scene, f, &s.store, z, mis, j, max_depth, 1.0, &mut l, &mut tally,
                    );
                }
            }
            if !l.is_black() {
                out.parts.push(Part {
                    at: Landing::Camera(camera as u32),
                    l,
                    technique: Technique::Connection,
                });
            }
        }
        if vcm.mode.merges() {
            for y in &s.store {
                it.cameras.grid.query(y.v.p(), |index, _| {
                    let (k, j) = it.cameras.merge_points[index as usize];
                    let j = j as usize;
                    if y.depth as usize + j > max_depth {
                        return;
                    }
                    let (z, mis) = it.cameras.subpath(k as usize);
                    let c = MergePoint::new(scene, z, j).merge(f, y, &mis[j], false);
                    if !c.is_black() {
                        out.parts.push(Part {
                            at: Landing::Camera(k),
                            l: z[j].beta * c * it.merge_norm,
                            technique: Technique::Merge,
                        });
                    }
                });
            }
        }
    });
    out.finite = tally.nonfinite == 0 && out.parts.iter().all(|p| p.l.is_finite());
    out.luminance = out.parts.iter().map(|p| f64::from(p.l.luminance())).sum();
}

/// The two chains' targets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChainKind {
    /// `π_con = lum C^Ω` (Eq. 6.2).
    Contribution = 0,
    /// `π_vis = 1[lum C^Ω > 0]` (Eq. 6.3).
    Visibility = 1,
}

impl ChainKind {
    /// `ln π` of a contribution: NaN when it is invalid, `−∞` when black.
    pub fn log_density(self, c: &LightContribution) -> f64 {
        if !c.finite || !c.luminance.is_finite() {
            f64::NAN
        } else if !(c.luminance > 0.0) {
            f64::NEG_INFINITY
        } else {
            match self {
                ChainKind::Contribution => c.luminance.ln(),
                ChainKind::Visibility => 0.0,
            }
        }
    }
}

/// One chain's target for one step: the light subpath of a primary-sample
/// point with camera subpath `camera` for the connections.
pub struct LightTarget<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// The iteration.
    pub it: &'a Iteration<'a>,
    /// The camera subpath for the connections.
    pub camera: usize,
    /// Which target.
    pub kind: ChainKind,
}

impl Target<TorusPoint> for LightTarget<'_> {
    type Payload = LightContribution;

    fn evaluate(&self, point: &TorusPoint) -> Evaluation<LightContribution> {
        let mut c = LightContribution::default();
        light_contribution(
            self.scene,
            self.it,
            &mut PssSource::new(point, 1),
            self.camera,
            &mut c,
        );
        Evaluation::new(self.kind.log_density(&c), c)
    }
}

/// A kernel component of a light-subpath chain.
type LightKernel = Box<dyn Kernel<TorusPoint, LightContribution> + Send>;

/// A light-subpath chain's algorithm: `mcmc-core`'s Metropolis–Hastings
/// with a mixture of the adaptive small step and (optionally) a large step.
pub type LightAlgorithm =
    MetropolisHastings<Mixture<TorusPoint, LightContribution>, TorusPoint, LightContribution>;

/// A chain over light subpaths.
pub type LightChain = Chain<TorusPoint, LightContribution, LightAlgorithm>;

/// A restart candidate: an independent light subpath (its point is the
/// fresh primary-sample point of `rng`, re-made when it is chosen).
struct Candidate {
    rng: ChainRng,
    camera: usize,
    luminance: f64,
    /// `lum C^Ω` with the tracing density's weights (`k = 1`), for
    /// `con_estimate = transfer`; `luminance` otherwise.
    unscaled: f64,
}

/// One block of restart candidates being traced: its stream, the
/// indices still to draw, the candidates drawn.
struct CandidateBlock {
    rng: ChainRng,
    range: std::ops::Range<usize>,
    out: Vec<Candidate>,
}

/// An iteration's restart pool as the chain pairs' restarts see it: the
/// candidates' cumulative luminances (the contribution chain's
/// importance resampling) and the indices of the visible ones (the
/// visibility chain's), built once per iteration (module docs,
/// "Restarts").
#[derive(Debug, Default)]
pub struct RestartPool {
    cumulative: Vec<f64>,
    visible: Vec<u32>,
}

impl RestartPool {
    /// Rebuilds it for candidates of luminances `luminances` (in pool
    /// order; non-negative, 0 for a black or invalid candidate).
    pub fn rebuild(&mut self, luminances: impl Iterator<Item = f64>) {
        self.cumulative.clear();
        self.visible.clear();
        let mut total = 0.0;
        for (i, l) in luminances.enumerate() {
            total += l;
            self.cumulative.push(total);
            if l > 0.0 {
                self.visible.push(i as u32);
            }
        }
    }

    /// The number of visible candidates.
    pub fn visible(&self) -> usize {
        self.visible.len()
    }

    /// The pool's mean luminance: the restart weight `W` of the
    /// contribution chain's resampled start (`E[W h(x₀)] = ∫ h π_con` for
    /// any pool size: importance resampling's proper weight).
    pub fn weight(&self) -> f64 {
        match self.cumulative.last() {
            Some(&total) => total / self.cumulative.len() as f64,
            None => 0.0,
        }
    }

    /// The candidate the contribution chain restarts from, `∝ lum` for
    /// `u` uniform in [0, 1); the pool must hold a visible candidate.
    pub fn contribution(&self, u: f64) -> usize {
        let x = u * self.cumulative.last().copied().unwrap_or(0.0);
        self.cumulative
            .partition_point(|&c| c <= x)
            .min(self.cumulative.len() - 1)
    }

    /// The candidate the visibility chain restarts from: uniform (by `u`)
    /// among the visible ones other than `exclude`; `None` when there is
    /// none.
    pub fn visibility(&self, u: f64, exclude: Option<usize>) -> Option<usize> {
        let skip = exclude.and_then(|e| self.visible.binary_search(&(e as u32)).ok());
        let n = self.visible.len() - usize::from(skip.is_some());
        if n == 0 {
            return None;
        }
        let mut r = ((u * n as f64) as usize).min(n - 1);
        if skip.is_some_and(|s| r >= s) {
            r += 1;
        }
        Some(self.visible[r] as usize)
    }
}

/// Running sums of the normalisations (Eq. 6.4) with per-iteration
/// batches for their standard errors.
#[derive(Clone, Debug, Default)]
struct Normalisation {
    count: f64,
    vis: f64,
    con: f64,
    /// Σ `lum C^Ω` with `k = 1` weights (`con_estimate = transfer`).
    con_unscaled: f64,
    /// Visibility-chain steps.
    chain_steps: f64,
    /// Σ over those steps of the expected `lum C^Ω` of the next state.
    chain_lum: f64,
    /// Camera samples and their Σ [`CameraPass::transfer`].
    cameras: f64,
    transfer: f64,
    /// The sums above per iteration, columns [`COUNT`] … [`TRANSFER`].
    batches: Vec<[f64; COLUMNS]>,
}

/// Columns of [`Normalisation::batches`].
const COUNT: usize = 0;
const VIS: usize = 1;
const CON: usize = 2;
const CHAIN_STEPS: usize = 3;
const CHAIN_LUM: usize = 4;
const CON_UNSCALED: usize = 5;
const CAMERAS: usize = 6;
const TRANSFER: usize = 7;
const COLUMNS: usize = 8;

/// The sum of ratios `Σ_t (Σ num_t / Σ den_t)` over `batches` for the
/// column pairs `terms` and its standard error, treating the batches
/// (iterations) as independent: the ratio estimator linearised, batch `i`
/// contributing `Σ_t (num_t,i − r_t den_t,i) / Σ den_t`; NaN below two
/// batches. A ratio whose denominators sum to 0 counts as 0.
fn batch_ratios<const N: usize>(batches: &[[f64; N]], terms: &[(usize, usize)]) -> (f64, f64) {
    let sums: Vec<(f64, f64)> = terms
        .iter()
        .map(|&(num, den)| {
            let (sn, sd) = batches
                .iter()
                .fold((0.0, 0.0), |(a, b), x| (a + x[num], b + x[den]));
            (if sd > 0.0 { sn / sd } else { 0.0 }, sd)
        })
        .collect();
    let r = sums.iter().map(|s| s.0).sum();
    let k = batches.len() as f64;
    if batches.len() < 2 || sums.iter().any(|s| !(s.1 > 0.0)) {
        return (r, f64::NAN);
    }
    let s: f64 = batches
        .iter()
        .map(|x| {
            terms
                .iter()
                .zip(&sums)
                .map(|(&(num, den), &(r, sd))| (x[num] - r * x[den]) / sd)
                .sum::<f64>()
                .powi(2)
        })
        .sum();
    (r, (s * k / (k - 1.0)).sqrt())
}

/// One ratio `Σ num / Σ den` of [`batch_ratios`].
fn batch_ratio<const N: usize>(batches: &[[f64; N]], num: usize, den: usize) -> (f64, f64) {
    batch_ratios(batches, &[(num, den)])
}

/// Inverse-variance combination of two estimates of one quantity with
/// standard errors `se_a`, `se_b`; the first alone unless both are
/// positive and finite.
fn inverse_variance(a: f64, se_a: f64, b: f64, se_b: f64) -> (f64, f64) {
    if !(se_a > 0.0 && se_a.is_finite() && se_b > 0.0 && se_b.is_finite()) {
        return (a, se_a);
    }
    let (wa, wb) = (se_a.powi(-2), se_b.powi(-2));
    ((wa * a + wb * b) / (wa + wb), (wa + wb).sqrt().recip())
}

impl Normalisation {
    /// One independent light subpath of luminance `luminance`, `unscaled`
    /// with `k = 1` weights.
    fn add(&mut self, luminance: f64, unscaled: f64) {
        self.count += 1.0;
        if luminance > 0.0 {
            self.vis += 1.0;
            self.con += luminance;
            self.con_unscaled += unscaled;
        }
    }

    /// One camera pass of `cameras` samples with its transfer.
    fn add_cameras(&mut self, cameras: f64, transfer: f64) {
        self.cameras += cameras;
        self.transfer += transfer;
    }

    /// The running sums as one batch.
    fn batch(&self) -> [f64; COLUMNS] {
        let mut b = [0.0; COLUMNS];
        b[COUNT] = self.count;
        b[VIS] = self.vis;
        b[CON] = self.con;
        b[CHAIN_STEPS] = self.chain_steps;
        b[CHAIN_LUM] = self.chain_lum;
        b[CON_UNSCALED] = self.con_unscaled;
        b[CAMERAS] = self.cameras;
        b[TRANSFER] = self.transfer;
        b
    }

    /// The running sums a [`Normalisation::batch`] holds (no batches of
    /// its own): how a chain pair's sums travel between ranks.
    fn from_batch(b: &[f64]) -> Normalisation {
        Normalisation {
            count: b[COUNT],
            vis: b[VIS],
            con: b[CON],
            con_unscaled: b[CON_UNSCALED],
            chain_steps: b[CHAIN_STEPS],
            chain_lum: b[CHAIN_LUM],
            cameras: b[CAMERAS],
            transfer: b[TRANSFER],
            batches: Vec::new(),
        }
    }

    /// One visibility-chain step whose next state has expected luminance
    /// `luminance`.
    fn add_chain(&mut self, luminance: f64) {
        self.chain_steps += 1.0;
        self.chain_lum += luminance;
    }

    /// Weighs the visibility-chain sums by the restart weight of their
    /// iteration (the chain states' proper weight, [`Restart::Weighted`]).
    fn weigh_chain(&mut self, weight: f64) {
        self.chain_steps *= weight;
        self.chain_lum *= weight;
    }

    fn merge(&mut self, o: &Normalisation) {
        self.count += o.count;
        self.vis += o.vis;
        self.con += o.con;
        self.con_unscaled += o.con_unscaled;
        self.chain_steps += o.chain_steps;
        self.chain_lum += o.chain_lum;
        self.cameras += o.cameras;
        self.transfer += o.transfer;
    }

    /// `b_con` by `how` with its standard error (NaN below two batches).
    fn con(&self, how: ConEstimate) -> (f64, f64) {
        if how == ConEstimate::Transfer {
            let ratio = |num: f64, den: f64| if den > 0.0 { num / den } else { 0.0 };
            return (
                ratio(self.con_unscaled, self.count) + ratio(self.transfer, self.cameras),
                batch_ratios(&self.batches, &[(CON_UNSCALED, COUNT), (TRANSFER, CAMERAS)]).1,
            );
        }
        let direct = (self.estimates().1, self.standard_errors().1);
        if how == ConEstimate::Direct || !(self.chain_steps > 0.0) {
            return direct;
        }
        let visibility = self.con_from_visibility();
        match how {
            ConEstimate::Visibility => visibility,
            _ => inverse_variance(direct.0, direct.1, visibility.0, visibility.1),
        }
    }

    /// `b_vis · E_vis[lum C^Ω]` and its standard error (the two factors'
    /// relative errors added in quadrature: they come from different
    /// light subpaths, though of the same camera subpaths).
    fn con_from_visibility(&self) -> (f64, f64) {
        let b_vis = self.estimates().0;
        let se_vis = self.standard_errors().0;
        let (m, se_m) = batch_ratio(&self.batches, CHAIN_LUM, CHAIN_STEPS);
        let b = b_vis * m;
        (
            b,
            b * ((se_vis / b_vis).powi(2) + (se_m / m).powi(2)).sqrt(),
        )
    }

    /// `(b_vis, b_con)` so far (zeros before any sample).
    fn estimates(&self) -> (f64, f64) {
        if self.count > 0.0 {
            (self.vis / self.count, self.con / self.count)
        } else {
            (0.0, 0.0)
        }
    }

    /// Standard errors of `(b_vis, b_con)` from the iteration batches
    /// (ratio estimator; the samples of one iteration share its camera
    /// subpaths, so they are not independent); NaN below two batches.
    fn standard_errors(&self) -> (f64, f64) {
        (
            batch_ratio(&self.batches, VIS, COUNT).1,
            batch_ratio(&self.batches, CON, COUNT).1,
        )
    }
}

/// `lum C^Ω` of the light subpath of `point` (camera subpath `camera`)
/// with `unscaled`'s weights when given and the subpath is visible (its
/// `luminance` positive: with `k ≥ 1` a subpath black with `k`'s weights is
/// black with `k = 1`'s too), else `luminance`; an invalid value counts
/// as 0.
fn unscaled_luminance(
    scene: &Scene,
    unscaled: Option<&Iteration>,
    point: &TorusPoint,
    camera: usize,
    luminance: f64,
) -> f64 {
    match unscaled {
        Some(it) if luminance > 0.0 => {
            let mut c = LightContribution::default();
            light_contribution(scene, it, &mut PssSource::new(point, 1), camera, &mut c);
            if c.finite { c.luminance } else { 0.0 }
        }
        _ => luminance,
    }
}

/// One pair of chains with what it accumulates in an iteration.
struct Unit {
    chains: [Option<LightChain>; 2],
    /// Per camera sample: the light-side estimate of this unit.
    camera: Vec<Rgb>,
    /// Light-tracing splats.
    splats: Film,
    norm: Normalisation,
    tally: Tally,
    swaps: u64,
    swaps_accepted: u64,
    swap_alpha: f64,
    invalid: u64,
}

/// Statistics of a run.
#[derive(Default)]
struct Totals {
    tally: Tally,
    swaps: u64,
    swaps_accepted: u64,
    swap_alpha: f64,
    invalid: u64,
    skipped_iterations: u64,
}

/// The restart weights of the iterations so far ([`Restart::Weighted`];
/// one each otherwise).
#[derive(Clone, Copy, Debug, Default)]
struct RestartWeights {
    sum: f64,
    sum_squares: f64,
    iterations: f64,
}

impl RestartWeights {
    /// One iteration's weight.
    fn add(&mut self, weight: f64) {
        self.sum += weight;
        self.sum_squares += weight * weight;
        self.iterations += 1.0;
    }

    /// Kish's effective number of iterations as a fraction of the
    /// iterations, `(Σ W)² / (n Σ W²)`: the share of the iterations'
    /// worth that weighing them leaves; NaN before a positive weight.
    fn effective_fraction(&self) -> f64 {
        if self.sum_squares > 0.0 {
            self.sum * self.sum / (self.iterations * self.sum_squares)
        } else {
            f64::NAN
        }
    }
}

/// The image after `iterations` iterations: path tracing's mean (`film`)
/// plus the light side's restart-weighted mean `Σ_i W_i G_i / Σ_i W_i`
/// (`light` holds the `W_i G_i`; with weights of one it is the plain mean).
fn develop(film: &Film, light: &Film, weights: &RestartWeights, iterations: u64) -> Vec<Rgb> {
    let n = iterations as f64;
    let scale = if weights.sum > 0.0 {
        (n / weights.sum) as f32
    } else {
        0.0
    };
    film.develop(n)
        .into_iter()
        .zip(light.develop(n))
        .map(|(pt, l)| pt + l * scale)
        .collect()
}

/// Adds `factor · C^Ω` to the camera-sample estimates `camera` and the
/// splat film, counting each part's energy in `tally`.
fn deposit(
    camera: &mut [Rgb],
    splats: &mut Film,
    tally: &mut Tally,
    c: &LightContribution,
    factor: f32,
) {
    for part in &c.parts {
        let l = part.l * factor;
        if !tally.take(part.technique, l) {
            continue;
        }
        match part.at {
            Landing::Camera(k) => camera[k as usize] += l,
            Landing::Raster(r) => splats.splat(r, l),
        }
    }
}

/// What one chain pair adds to a run's statistics.
struct PairReport {
    tally: Tally,
    swaps: u64,
    swaps_accepted: u64,
    swap_alpha: f64,
    invalid: u64,
    /// Its chains' statistics, indexed by [`ChainKind`] (`None`: not run).
    chains: [Option<ChainStatistics>; 2],
}

impl PairReport {
    /// The report of `unit`.
    fn of(unit: &Unit) -> PairReport {
        PairReport {
            tally: unit.tally.clone(),
            swaps: unit.swaps,
            swaps_accepted: unit.swaps_accepted,
            swap_alpha: unit.swap_alpha,
            invalid: unit.invalid,
            chains: unit
                .chains
                .each_ref()
                .map(|c| c.as_ref().map(|c| c.stats().clone())),
        }
    }

    /// The report as a distributed run sends it, bit-exactly: the tally's
    /// counters followed by the swap sum, and the swap and invalid counts,
    /// each chain's presence and statistics.
    fn to_counters(&self) -> Counters {
        let (mut numbers, mut counts) = self.tally.to_counters();
        numbers.push(self.swap_alpha);
        counts.extend([self.swaps, self.swaps_accepted, self.invalid]);
        for chain in &self.chains {
            counts.push(u64::from(chain.is_some()));
            if let Some(stats) = chain {
                crate::markov::checkpoint::stats_words(stats, &mut counts);
            }
        }
        (numbers, counts)
    }

    /// The report [`PairReport::to_counters`] sent, its chains' component
    /// names from `names` (by kind).
    fn from_counters(
        (numbers, counts): Counters,
        names: &[Vec<String>; 2],
    ) -> Result<PairReport, String> {
        let cut = || "a chain pair's report is cut".to_string();
        // The tally's counts: non-finite samples and light vertices.
        let tallied = 2;
        let (&swap_alpha, energies) = numbers.split_last().ok_or_else(cut)?;
        if energies.len() != TECHNIQUE_NAMES.len() || counts.len() < tallied + 3 {
            return Err(cut());
        }
        let tally = Tally::from_counters((energies.to_vec(), counts[..tallied].to_vec()));
        let mut words = counts[tallied..].iter().copied();
        let mut next = || words.next().ok_or_else(cut);
        let (swaps, swaps_accepted, invalid) = (next()?, next()?, next()?);
        let mut chains: [Option<ChainStatistics>; 2] = [None, None];
        for (chain, names) in chains.iter_mut().zip(names) {
            if next()? == 1 {
                let mut stats = crate::markov::checkpoint::stats_from_words(&mut next)?;
                for (c, name) in stats.components.iter_mut().zip(names) {
                    c.name.clone_from(name);
                }
                *chain = Some(stats);
            }
        }
        Ok(PairReport {
            tally,
            swaps,
            swaps_accepted,
            swap_alpha,
            invalid,
            chains,
        })
    }
}

/// Adds the iteration's chain pairs' sums in pair order and clears them
/// for the next iteration: their normalisation sums, the visibility
/// chain's weighted by the iteration's restart weight `weight`, into
/// `norm` and `batch` (every rank: they set the next iteration's `b`),
/// their splat films into the light side's film `light_film` and their
/// camera-sample estimates into the returned light-side estimate per
/// camera sample (rank 0; on the other ranks of a cluster it stays black
/// and the film unchanged, as neither is written). Collective on a
/// cluster (module docs).
fn join_units(
    units: &mut [Unit],
    light_film: &mut Film,
    norm: &mut Normalisation,
    batch: &mut Normalisation,
    weight: f64,
    filter: &Arc<Filter>,
) -> Vec<Rgb> {
    let mut light = vec![Rgb::BLACK; light_film.width as usize * light_film.height as usize];
    let Some(cluster) = crate::cluster::current() else {
        for unit in units {
            for (a, c) in light.iter_mut().zip(&mut unit.camera) {
                *a += *c;
                *c = Rgb::BLACK;
            }
            light_film.add_film(&unit.splats);
            unit.splats.clear();
            // Large steps of this iteration join the running sums, the
            // visibility chain's states with their restart weight.
            unit.norm.weigh_chain(weight);
            norm.merge(&unit.norm);
            batch.merge(&unit.norm);
            unit.norm = Normalisation::default();
        }
        return light;
    };
    let mine = |p: &usize| owns(Some(cluster), *p);
    // Every pair's normalisation sums (weighted where they are made: the
    // same product) to every rank, each after its pair's index (exact in
    // an f64), merged in pair order.
    let mut tagged = Vec::new();
    for (p, unit) in units.iter_mut().enumerate().filter(|(p, _)| mine(p)) {
        unit.norm.weigh_chain(weight);
        tagged.push(p as f64);
        tagged.extend(unit.norm.batch());
    }
    let mut sums: Vec<(f64, Normalisation)> = (cluster.all_gather_f64s(tagged))
        .chunks_exact(COLUMNS + 1)
        .map(|c| (c[0], Normalisation::from_batch(&c[1..])))
        .collect();
    sums.sort_by(|a, b| a.0.total_cmp(&b.0));
    for (_, n) in &sums {
        norm.merge(n);
        batch.merge(n);
    }
    // Splat films and camera-sample estimates (as f64: exact) to rank 0,
    // added in pair order.
    let parcels = (units.iter().enumerate())
        .filter(|(p, _)| mine(p))
        .map(|(p, unit)| {
            let camera = unit.camera.iter().flat_map(|c| [c.r, c.g, c.b]);
            (
                p,
                &unit.splats,
                (camera.map(f64::from).collect(), Vec::new()),
            )
        });
    for (numbers, _) in crate::cluster::reduce_units(light_film, parcels, filter) {
        for (a, c) in light.iter_mut().zip(numbers.chunks_exact(3)) {
            *a += Rgb::new(c[0] as f32, c[1] as f32, c[2] as f32);
        }
    }
    for (_, unit) in units.iter_mut().enumerate().filter(|(p, _)| mine(p)) {
        unit.camera.fill(Rgb::BLACK);
        unit.splats.clear();
        unit.norm = Normalisation::default();
    }
    light
}

/// The gathered records of every chain pair, `record(unit)` each, in
/// pair order: this process's, or on a cluster every rank's (each its own
/// pairs'), on rank 0 (`None` on the other ranks). Collective on a
/// cluster.
fn gather_pairs(
    units: &[Unit],
    filter: &Arc<Filter>,
    record: impl Fn(&Unit) -> Counters,
) -> Option<Vec<Counters>> {
    let Some(cluster) = crate::cluster::current() else {
        return Some(units.iter().map(record).collect());
    };
    let parcels = (units.iter().enumerate())
        .filter(|(p, _)| owns(Some(cluster), *p))
        .map(|(p, unit)| {
            let (numbers, counts) = record(unit);
            Parcel {
                unit: p,
                films: Vec::new(),
                numbers,
                counts,
            }
        })
        .collect();
    let all = cluster.gather(parcels, filter)?;
    Some(all.into_iter().map(|p| (p.numbers, p.counts)).collect())
}

/// A chain pair's record in a checkpoint: its report's numbers, and as
/// counts the length of its chains' part, that part — per chain that
/// runs: its kind, its random stream (4 words), its kernel's state
/// ([`Kernel::state_words`], after its length) — then the report's counts
/// ([`PairReport::to_counters`]). The chains' current states are not
/// saved: each iteration restarts them before they step.
fn unit_record(unit: &Unit) -> Counters {
    let (numbers, counts) = PairReport::of(unit).to_counters();
    let mut tail = Vec::new();
    for (kind, chain) in unit.chains.iter().enumerate() {
        if let Some(chain) = chain {
            tail.push(kind as u64);
            tail.extend(rng_words(chain.rng()));
            let mut state = Vec::new();
            chain.algorithm().kernel().state_words(&mut state);
            tail.push(state.len() as u64);
            tail.extend(state);
        }
    }
    let mut out = vec![tail.len() as u64];
    out.extend(tail);
    out.extend(counts);
    (numbers, out)
}

/// Appends `counters` to `out`: the numbers' count and bits, the counts'
/// count and the counts.
fn push_counters(out: &mut Vec<u64>, (numbers, counts): &Counters) {
    out.push(numbers.len() as u64);
    out.extend(numbers.iter().map(|x| x.to_bits()));
    out.push(counts.len() as u64);
    out.extend(counts);
}

/// A checkpoint's words read one after the other.
struct Words<'a>(&'a [u64]);

impl<'a> Words<'a> {
    /// The error of words that end too soon or do not fit.
    fn bad(&self) -> String {
        "mcmc-vcm's words are cut or do not fit: not a checkpoint of mcmc-vcm".into()
    }

    /// The next word.
    fn next(&mut self) -> Result<u64, String> {
        let all: &'a [u64] = self.0;
        let (&w, rest) = all.split_first().ok_or_else(|| self.bad())?;
        self.0 = rest;
        Ok(w)
    }

    /// The next `n` words.
    fn take(&mut self, n: u64) -> Result<&'a [u64], String> {
        let all: &'a [u64] = self.0;
        let n = usize::try_from(n).ok().filter(|&n| n <= all.len());
        let (taken, rest) = all.split_at(n.ok_or_else(|| self.bad())?);
        self.0 = rest;
        Ok(taken)
    }

    /// Counters [`push_counters`] wrote.
    fn counters(&mut self) -> Result<Counters, String> {
        let n = self.next()?;
        let numbers = self.take(n)?.iter().map(|&x| f64::from_bits(x)).collect();
        let n = self.next()?;
        Ok((numbers, self.take(n)?.to_vec()))
    }
}

/// What a checkpoint holds besides the films, decoded
/// ([`McmcVcm::decode`]).
struct Resumed {
    light_scale: f32,
    weights: RestartWeights,
    skipped_iterations: u64,
    tally: Tally,
    norm: Normalisation,
    units: Vec<SavedUnit>,
    /// The path-tracing and light-side films (rank 0 only: the only rank
    /// that adds into them).
    films: Option<(Film, Film)>,
}

/// A chain pair as a checkpoint holds it: its report, and per chain kind
/// that runs its stream and its kernel with the saved adaptation.
struct SavedUnit {
    report: PairReport,
    chains: [Option<(ChainRng, LightAlgorithm)>; 2],
}

impl SavedUnit {
    /// Puts the saved pair into `unit`: its counters, and each chain
    /// re-made with its stream, kernel and statistics at a placeholder
    /// state (the iteration's restart replaces it before the first step).
    fn restore(self, unit: &mut Unit) {
        let SavedUnit { report, chains } = self;
        unit.tally = report.tally;
        (unit.swaps, unit.swaps_accepted) = (report.swaps, report.swaps_accepted);
        (unit.swap_alpha, unit.invalid) = (report.swap_alpha, report.invalid);
        for ((slot, saved), stats) in unit.chains.iter_mut().zip(chains).zip(report.chains) {
            *slot = saved.map(|(rng, algorithm)| {
                let placeholder = Sample {
                    state: TorusPoint::fresh(stream_rng(0, 0)),
                    log_density: 0.0,
                    payload: LightContribution::default(),
                };
                let mut chain = Chain::from_sample(placeholder, algorithm, rng)
                    .expect("a placeholder of finite density");
                chain.parts_mut().stats = stats.expect("decode matched chains and statistics");
                chain
            });
        }
    }
}

/// Checks that a checkpoint's `progress` is one an `mcmc-vcm` run with
/// `integrator`'s settings on `scene` wrote (one line if not): one sample
/// per pixel an iteration, two films, and words that decode for those
/// settings (`McmcVcm::decode`). The command line checks it on rank 0 before the ranks' start-up
/// handshake, so that a bad file stops every rank with one error; the
/// render checks it too.
pub fn check_checkpoint(
    progress: &Progress,
    integrator: &dyn std::any::Any,
    scene: &Scene,
) -> Result<(), String> {
    let Some(settings) = integrator.downcast_ref::<McmcVcmSettings>() else {
        return Err("not a checkpoint of mcmc-vcm".into());
    };
    if progress.spp_done != progress.pass {
        return Err(format!(
            "holds {} iterations and {} samples per pixel: not a checkpoint of mcmc-vcm (one sample an iteration)",
            progress.pass, progress.spp_done
        ));
    }
    if progress.more_films.len() != 1 {
        return Err(format!(
            "holds {} films, mcmc-vcm keeps 2: not a checkpoint of mcmc-vcm",
            1 + progress.more_films.len()
        ));
    }
    (settings.integrator(scene))
        .decode(progress.pass, &progress.extra)
        .map(|_| ())
}

/// The integrator.
pub struct McmcVcm {
    /// VCM (techniques, radius, MIS, depth).
    pub vcm: Vcm,
    /// Which chains run.
    pub chains: LightChains,
    /// Large-step probability of the chain that explores globally.
    pub large_step: f64,
    /// Target acceptance of the adaptive small step.
    pub target_acceptance: f64,
    /// Restart candidates per iteration.
    pub candidates: usize,
    /// Chain pairs.
    pub units: usize,
    /// Over which light subpaths `b_vis`, `b_con` are averaged.
    pub normalisation: NormalisationScope,
    /// Scale the light-subpath techniques' MIS densities by the chains'
    /// mixture density (§6.3.4).
    pub vis_pdf: bool,
    /// How `b_con` is estimated (module docs).
    pub con_estimate: ConEstimate,
    /// How the chains restart (module docs).
    pub restart: Restart,
}

impl McmcVcm {
    /// The kernel of a chain: the adaptive small step, with a large step
    /// of probability `large_step` when `large`.
    pub fn algorithm(&self, large: bool) -> LightAlgorithm {
        let small: LightKernel = Box::new(
            AdaptiveTorusStep::new(0.5, self.target_acceptance).expect("checked settings"),
        );
        let mut parts = vec![(1.0 - if large { self.large_step } else { 0.0 }, small)];
        if large && self.large_step > 0.0 {
            let big: LightKernel = Box::new(Independent::new(PrimarySampleSpace));
            parts.push((self.large_step, big));
        }
        MetropolisHastings::new(Mixture::new(parts).expect("valid weights"))
    }

    /// The chain kinds that run and whether each takes large steps.
    fn kinds(&self) -> &'static [(ChainKind, bool)] {
        match self.chains {
            LightChains::Both => &[
                (ChainKind::Contribution, false),
                (ChainKind::Visibility, true),
            ],
            LightChains::Contribution => &[(ChainKind::Contribution, true)],
            LightChains::Independent => &[],
        }
    }

    /// `count` independent light subpaths of iteration `it` in fixed
    /// blocks, each with a uniformly chosen camera subpath; the visible
    /// ones evaluated with `unscaled`'s weights too when given.
    ///
    /// The blocks advance in lock-step rounds of [`CANDIDATE_ROUND`]
    /// each, and after every round `cut` (collective on a cluster: every
    /// rank calls it once per round) may end the pool there: a pool cut
    /// between rounds is the same on every rank and for any thread count,
    /// and importance resampling from fewer candidates is still exact.
    /// `abort` (a stop: the iteration is dropped) ends a block's round
    /// early.
    #[allow(clippy::too_many_arguments)]
    fn trace_candidates(
        &self,
        scene: &Scene,
        it: &Iteration,
        unscaled: Option<&Iteration>,
        seed: u64,
        stream: u64,
        count: usize,
        abort: &(dyn Fn() -> bool + Sync),
        cut: &dyn Fn() -> bool,
    ) -> Vec<Candidate> {
        let n = it.cameras.len();
        let mut blocks: Vec<CandidateBlock> = (0..CANDIDATE_BLOCKS)
            .map(|b| {
                let range = count * b / CANDIDATE_BLOCKS..count * (b + 1) / CANDIDATE_BLOCKS;
                CandidateBlock {
                    rng: stream_rng(seed, stream + b as u64),
                    out: Vec::with_capacity(range.len()),
                    range,
                }
            })
            .collect();
        loop {
            blocks.par_iter_mut().for_each(|block| {
                let mut c = LightContribution::default();
                let (rng, round_end) = (&mut block.rng, block.range.start + CANDIDATE_ROUND);
                for i in block.range.start..round_end.min(block.range.end) {
                    if i % STOP_CHECK == 0 && abort() {
                        break;
                    }
                    let point_rng = child_rng(rng);
                    let point = TorusPoint::fresh(point_rng.clone());
                    let camera = ((uniform(rng) * n as f64) as usize).min(n - 1);
                    light_contribution(scene, it, &mut PssSource::new(&point, 1), camera, &mut c);
                    // An invalid candidate counts as black and is never chosen.
                    let luminance = if c.finite { c.luminance } else { 0.0 };
                    block.out.push(Candidate {
                        rng: point_rng,
                        camera,
                        luminance,
                        unscaled: unscaled_luminance(scene, unscaled, &point, camera, luminance),
                    });
                    block.range.start = i + 1;
                }
            });
            // (`cut` first: it is collective, and a rank whose blocks an
            // abort left unfinished must not call it once more than the
            // others.)
            if cut() || blocks.iter().all(|b| b.range.is_empty()) {
                break;
            }
        }
        // Joined into a vector of the exact size, each block freed once
        // copied (collecting the flattened blocks grew the vector by
        // doubling: up to 3× the candidates' bytes at the peak).
        let mut pool = Vec::with_capacity(blocks.iter().map(|b| b.out.len()).sum());
        for block in blocks {
            pool.extend(block.out);
        }
        pool
    }

    /// A light subpath of iteration `it` (with a uniformly chosen camera
    /// subpath) drawn afresh until one is visible — rejection sampling,
    /// exactly `π_vis/b_vis` — at most `tries` times; `None` when none is
    /// or the run stops.
    fn fresh_visible(
        &self,
        scene: &Scene,
        it: &Iteration,
        seed: u64,
        iteration: u64,
        tries: usize,
        abort: &(dyn Fn() -> bool + Sync),
    ) -> Option<Candidate> {
        let n = it.cameras.len();
        let mut rng = stream_rng(seed, STREAM_FRESH ^ (iteration << 24));
        let mut c = LightContribution::default();
        for t in 0..tries {
            if t % STOP_CHECK == 0 && abort() {
                return None;
            }
            let point_rng = child_rng(&mut rng);
            let point = TorusPoint::fresh(point_rng.clone());
            let camera = ((uniform(&mut rng) * n as f64) as usize).min(n - 1);
            light_contribution(scene, it, &mut PssSource::new(&point, 1), camera, &mut c);
            if c.finite && c.luminance > 0.0 {
                return Some(Candidate {
                    rng: point_rng,
                    camera,
                    luminance: c.luminance,
                    unscaled: c.luminance,
                });
            }
        }
        None
    }

    /// Renders to `run`'s budget in whole iterations (one camera subpath
    /// and one light subpath per pixel each); stopping discards the
    /// iteration in flight.
    pub fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Rendered {
        let vcm = &self.vcm;
        let (width, height) = (scene.film.width, scene.film.height);
        let pixels = width as usize * height as usize;
        let filter = Arc::new(Filter::new(scene.film.filter, width, height));
        // Path tracing, and apart from it the light side weighted by the
        // restart weights (normalised by their sum in `develop`).
        let mut film = Film::new(width, height, filter.clone());
        let mut light_film = Film::new(width, height, filter.clone());
        let start = Instant::now();
        let deadline = Deadline::new(start, run.time_budget);
        let target = run.samples_per_pixel(scene.sample_count).map(u64::from);
        let aborted = AtomicBool::new(false);
        let abort = || {
            if stop.load(Ordering::Relaxed) || deadline.passed() {
                aborted.store(true, Ordering::Relaxed);
            }
            aborted.load(Ordering::Relaxed)
        };
        let mut units: Vec<Unit> = (0..self.units)
            .map(|_| Unit {
                chains: [None, None],
                camera: vec![Rgb::BLACK; pixels],
                splats: Film::new_splat_only(width, height, filter.clone()),
                norm: Normalisation::default(),
                tally: Tally::default(),
                swaps: 0,
                swaps_accepted: 0,
                swap_alpha: 0.0,
                invalid: 0,
            })
            .collect();
        let mut pass = CameraPass::default();
        let mut restarts = RestartPool::default();
        let mut weights = RestartWeights::default();
        let mut norm = Normalisation::default();
        let mut totals = Totals::default();
        // Independent light subpaths are VCM's estimator: with L light
        // subpaths of N camera subpaths its MIS scale is `vcm`'s k = L/N
        // (the chains' k comes from the pilot below).
        let mut light_scale = match self.chains {
            LightChains::Independent => self.vcm.light_density_scale(pixels),
            _ => 1.0f32,
        };
        let mut pilot_done = false;
        let mut iterations = 0u64;
        let mut interrupted = false;
        // A checkpoint's progress replaces the fresh state (module docs).
        let resumed = run
            .checkpoint
            .as_ref()
            .and_then(|c| self.resume_point(c, &filter));
        let resumed_from = resumed.as_ref().map(|r| r.0);
        if let Some((done, saved)) = resumed {
            if let Some(films) = saved.films {
                (film, light_film) = films;
            }
            iterations = done;
            pilot_done = true;
            light_scale = saved.light_scale;
            weights = saved.weights;
            norm = saved.norm;
            totals.tally = saved.tally;
            totals.skipped_iterations = saved.skipped_iterations;
            for (unit, saved) in units.iter_mut().zip(saved.units) {
                saved.restore(unit);
            }
        }
        let mut checkpoint_error: Option<String> = None;
        // On a cluster this rank runs the chain pairs dealt to it (module
        // docs), and every stop below is decided by all ranks alike (a
        // collective; in one process the flag itself).
        let cluster = crate::cluster::current();
        let any_abort = || crate::cluster::any_rank(abort());
        // A start-up sized by `candidates` (the pilot, the first
        // iteration's pool) stops drawing at the Markov driver's share of
        // the budget (`markov::STARTUP_SHARE`; the pilot at half of it),
        // so that the first iteration ends in time: with 2·10^7 candidates
        // under `--time 2` the iteration in flight was dropped and the
        // image black (session 34). Never when checkpointed: a resumed
        // run must redo what the uninterrupted one did.
        let checkpointed = run.checkpoint.is_some();
        let pilot_end = Deadline::new(
            start,
            (run.time_budget).map(|b| b.mul_f64(crate::markov::STARTUP_SHARE / 2.0)),
        );
        let startup_end = crate::markov::startup_end(start, run.time_budget);
        let (mut pilot_drawn, mut first_pool_drawn) = (None, None);
        let mut busy = 0.0f64;
        while target.is_none_or(|t| iterations < t) && vcm.max_depth > 0 && pixels > 0 {
            if any_abort() {
                interrupted = true;
                break;
            }
            let radius = vcm.radius_at(iterations);

            self.camera_pass(scene, radius, light_scale, run.seed, iterations, &mut pass);
            if any_abort() {
                interrupted = true;
                break;
            }
            let cameras = &pass.cameras;

            // The MIS scale k, fixed for the render by a pilot set of
            // light subpaths before the first iteration (module docs).
            if !pilot_done && self.vis_pdf && self.chains == LightChains::Both {
                pilot_done = true;
                let pilot = Iteration::new(vcm, cameras, radius, 1.0);
                let c = self.trace_candidates(
                    scene,
                    &pilot,
                    None,
                    run.seed,
                    STREAM_PILOT,
                    self.candidates,
                    &abort,
                    &|| crate::cluster::any_rank(abort() || (!checkpointed && pilot_end.passed())),
                );
                pilot_drawn = Some(c.len());
                // A pilot cut short on one rank would give it another
                // scale: the ranks agree before using it.
                if any_abort() {
                    interrupted = true;
                    break;
                }
                let visible = c.iter().filter(|c| c.luminance > 0.0).count();
                if visible > 0 {
                    let b_vis = visible as f64 / c.len() as f64;
                    let (n_con, n_vis) = self.steps_per_kind(pixels);
                    light_scale = ((n_vis as f64 / b_vis + n_con as f64) / pixels as f64) as f32;
                }
                if light_scale != 1.0 {
                    // The path-tracing estimates of this iteration were
                    // weighted with k = 1: redo the camera pass.
                    continue;
                }
            }
            totals.tally.add(&pass.tally);
            observer.progress(pixels as u64);
            let it = Iteration::new(vcm, cameras, radius, light_scale);
            // `con_estimate = transfer`: the same iteration with the
            // tracing density's weights (module docs).
            let unscaled = self
                .transfers(light_scale)
                .then(|| Iteration::new(vcm, cameras, radius, 1.0));

            // Restart candidates; they join the running normalisation.
            let independent = self.chains == LightChains::Independent;
            let pool = self.trace_candidates(
                scene,
                &it,
                unscaled.as_ref(),
                run.seed,
                STREAM_CANDIDATES ^ (iterations << 24),
                if independent { 0 } else { self.candidates },
                &abort,
                &|| {
                    let first = iterations == 0 && !checkpointed;
                    crate::cluster::any_rank(abort() || (first && startup_end.passed()))
                },
            );
            if iterations == 0 {
                first_pool_drawn = Some(pool.len());
            }
            if any_abort() {
                interrupted = true;
                break;
            }
            let mut batch = Normalisation::default();
            for c in &pool {
                batch.add(c.luminance, c.unscaled);
            }
            batch.add_cameras(pixels as f64, pass.transfer);
            // Frozen before this iteration's candidates join: with
            // `weighted` restarts they set the iteration's weight, and a
            // normalisation computed from them too would correlate with it.
            // Until a visible subpath is seen (the first iteration), they
            // are all there is.
            let prior =
                (norm.vis > 0.0).then(|| (norm.estimates().0, norm.con(self.con_estimate).0));
            norm.merge(&batch);
            let b = match self.normalisation {
                NormalisationScope::Render => {
                    prior.unwrap_or_else(|| (norm.estimates().0, norm.con(self.con_estimate).0))
                }
                NormalisationScope::Iteration => {
                    (batch.estimates().0, batch.con(self.con_estimate).0)
                }
            };
            restarts.rebuild(pool.iter().map(|c| c.luminance));
            let weight = if self.weighs_restarts() {
                restarts.weight()
            } else {
                1.0
            };
            // With `weighted` restarts and one visible candidate, every
            // contribution chain restarts from it and the visibility
            // chains from a fresh visible light subpath (module docs).
            let fresh = (self.weighs_restarts()
                && self.chains == LightChains::Both
                && restarts.visible() == 1)
                .then(|| {
                    let tries = FRESH_TRIES * pool.len();
                    self.fresh_visible(scene, &it, run.seed, iterations, tries, &abort)
                })
                .flatten();
            // The chains need a visible candidate to restart from. (A rank
            // whose fresh subpath was cut by a stop runs no pair: `run_unit`
            // checks the stop first, and the iteration is dropped below.)
            let t = Instant::now();
            if batch.vis > 0.0 || independent {
                units
                    .par_iter_mut()
                    .enumerate()
                    .filter(|(p, _)| owns(cluster, *p))
                    .for_each(|(p, unit)| {
                        self.run_unit(
                            scene,
                            &it,
                            unscaled.as_ref(),
                            &pool,
                            &restarts,
                            fresh.as_ref(),
                            weight,
                            b,
                            unit,
                            p,
                            run.seed,
                            iterations,
                            &abort,
                        );
                    });
            } else {
                totals.skipped_iterations += 1;
            }
            busy += t.elapsed().as_secs_f64();
            if crate::cluster::any_rank(aborted.load(Ordering::Relaxed)) {
                interrupted = true;
                break;
            }
            let light = join_units(
                &mut units,
                &mut light_film,
                &mut norm,
                &mut batch,
                weight,
                &filter,
            );
            norm.batches.push(batch.batch());
            for ((&raster, &pt), &l) in pass.rasters.iter().zip(&pass.estimates).zip(&light) {
                film.add_sample(raster, pt);
                light_film.add_sample(raster, l);
            }
            weights.add(weight);
            iterations += 1;
            if let Some(c) = &run.checkpoint {
                // Collective: rank 0 gathers the pairs' records.
                let records = gather_pairs(&units, &filter, unit_record);
                if let Some(records) = records.filter(|_| checkpoint_error.is_none()) {
                    let mut progress =
                        Progress::of(iterations, iterations, totals.tally.nonfinite, &film);
                    let (samples, splats) = light_film.accumulators();
                    progress.more_films = vec![(samples.to_vec(), splats.to_vec())];
                    progress.extra =
                        Self::saved_words(light_scale, &weights, &totals, &norm, &records);
                    checkpoint_error =
                        crate::checkpoint::save(&c.path, c.fingerprint, &progress).err();
                }
            }
            observer.snapshot(
                &|| develop(&film, &light_film, &weights, iterations),
                iterations * pixels as u64,
            );
        }
        // The light side's energies carry the restart weights: normalised
        // by their mean, as the image is (`develop`).
        let mean_weight = weights.sum / weights.iterations;
        let scale = if mean_weight > 0.0 {
            mean_weight.recip()
        } else {
            0.0
        };
        let reports = self.pair_reports(&units, &filter);
        for r in &reports {
            let mut tally = r.tally.clone();
            tally.energy.iter_mut().for_each(|e| *e *= scale);
            totals.tally.add(&tally);
            totals.swaps += r.swaps;
            totals.swaps_accepted += r.swaps_accepted;
            totals.swap_alpha += r.swap_alpha;
            totals.invalid += r.invalid;
        }
        let seconds = start.elapsed().as_secs_f64();
        let mut rendered = self.report(
            develop(&film, &light_film, &weights, iterations),
            &reports,
            &norm,
            &totals,
            &weights,
            light_scale,
            iterations,
            seconds,
            interrupted,
            pixels,
        );
        // How much of the start-up was drawn (less than `candidates` when
        // cut by the budget; null when not drawn in this run).
        rendered
            .statistics
            .insert("pilot_drawn".into(), pilot_drawn.into());
        rendered
            .statistics
            .insert("first_pool_drawn".into(), first_pool_drawn.into());
        if let Some(c) = &run.checkpoint {
            rendered.statistics.insert(
                "checkpoint".into(),
                c.statistics("iterations", resumed_from, iterations, &checkpoint_error),
            );
        }
        // On a cluster, every rank's share (on rank 0; collective).
        let pairs = (0..self.units).filter(|&p| owns(cluster, p)).count();
        if let serde_json::Value::Object(m) = crate::cluster::with_ranks(
            serde_json::Value::Object(std::mem::take(&mut rendered.statistics)),
            serde_json::json!({"pairs": pairs, "busy_seconds": busy, "seconds": seconds}),
        ) {
            rendered.statistics = m;
        }
        rendered
    }

    /// Every chain pair's report in pair order: this process's pairs, or
    /// on a cluster every rank's, on rank 0 (the other ranks get none:
    /// only rank 0 writes the statistics). Collective on a cluster.
    fn pair_reports(&self, units: &[Unit], filter: &Arc<Filter>) -> Vec<PairReport> {
        let names = self.component_names();
        let all = gather_pairs(units, filter, |u| PairReport::of(u).to_counters());
        all.unwrap_or_default()
            .into_iter()
            .map(|c| {
                PairReport::from_counters(c, &names)
                    .expect("every rank runs the same binary (the start-up handshake)")
            })
            .collect()
    }

    /// The kernels' component names by chain kind (not sent: every rank
    /// knows them).
    fn component_names(&self) -> [Vec<String>; 2] {
        let mut names: [Vec<String>; 2] = Default::default();
        for &(kind, large) in self.kinds() {
            names[kind as usize] = self.algorithm(large).component_names();
        }
        names
    }

    /// A checkpoint's words ([`crate::checkpoint::Progress::extra`]): the
    /// MIS scale `k` (bits), the restart weights (3), the skipped
    /// iterations, the tally (its counters after their counts), the
    /// running normalisation (8 sums, the batch count, 8 numbers a batch),
    /// then the pair count and every pair's record ([`unit_record`], in
    /// pair order, its counters after their counts).
    fn saved_words(
        light_scale: f32,
        weights: &RestartWeights,
        totals: &Totals,
        norm: &Normalisation,
        records: &[Counters],
    ) -> Vec<u64> {
        let mut out = vec![u64::from(light_scale.to_bits())];
        out.extend([weights.sum, weights.sum_squares, weights.iterations].map(f64::to_bits));
        out.push(totals.skipped_iterations);
        push_counters(&mut out, &totals.tally.to_counters());
        out.extend(norm.batch().map(f64::to_bits));
        out.push(norm.batches.len() as u64);
        out.extend(norm.batches.iter().flatten().map(|x| x.to_bits()));
        out.push(records.len() as u64);
        for r in records {
            push_counters(&mut out, r);
        }
        out
    }

    /// What the words of a checkpoint of `iterations` iterations hold, for
    /// this run's settings: refused (one line) unless a run with them
    /// could have written them (finite sums, a batch per iteration, a
    /// record per chain pair whose chains are the run's kinds, streams
    /// not all zero, kernel states the kernels take, no word left over).
    fn decode(&self, iterations: u64, words: &[u64]) -> Result<Resumed, String> {
        let mut w = Words(words);
        let light_scale = f32::from_bits(u32::try_from(w.next()?).map_err(|_| w.bad())?);
        let [sum, sum_squares, count] = [w.next()?, w.next()?, w.next()?].map(f64::from_bits);
        let weights = RestartWeights {
            sum,
            sum_squares,
            iterations: count,
        };
        let skipped_iterations = w.next()?;
        let (energy, counts) = w.counters()?;
        if energy.len() != TECHNIQUE_NAMES.len() || counts.len() != 2 {
            return Err(w.bad());
        }
        let tally = Tally::from_counters((energy, counts));
        let sums: Vec<f64> = w
            .take(COLUMNS as u64)?
            .iter()
            .map(|&x| f64::from_bits(x))
            .collect();
        let mut norm = Normalisation::from_batch(&sums);
        let batches = w.next()?;
        if batches != iterations {
            return Err(format!(
                "holds {batches} batches of the normalisation for {iterations} iterations: not a checkpoint of mcmc-vcm"
            ));
        }
        let batch_len = batches.checked_mul(COLUMNS as u64).ok_or_else(|| w.bad())?;
        let batch_words = w.take(batch_len)?;
        norm.batches = (batch_words.chunks_exact(COLUMNS))
            .map(|b| std::array::from_fn(|i| f64::from_bits(b[i])))
            .collect();
        let mut numbers = [light_scale as f64, sum, sum_squares, count]
            .into_iter()
            .chain(sums.iter().copied())
            .chain(norm.batches.iter().flatten().copied())
            .chain(tally.energy);
        if numbers.any(|x| !x.is_finite()) || !(light_scale > 0.0) {
            return Err("holds a sum that is not finite or a MIS scale not positive: not a checkpoint of mcmc-vcm".into());
        }
        let pairs = w.next()?;
        if pairs != self.units as u64 {
            return Err(format!(
                "holds {pairs} chain pairs, the run has {}",
                self.units
            ));
        }
        let units = (0..pairs)
            .map(|_| self.unit_of(w.counters()?))
            .collect::<Result<Vec<_>, String>>()?;
        if !w.0.is_empty() {
            return Err(format!(
                "holds {} words after its last chain pair: not a checkpoint of mcmc-vcm",
                w.0.len()
            ));
        }
        Ok(Resumed {
            light_scale,
            weights,
            skipped_iterations,
            tally,
            norm,
            units,
            films: None,
        })
    }

    /// A chain pair's record ([`unit_record`]) decoded for this run's
    /// chain kinds: its report, and each chain's stream and kernel with
    /// its saved adaptation.
    fn unit_of(&self, (numbers, counts): Counters) -> Result<SavedUnit, String> {
        let mut w = Words(&counts);
        let tail_len = w.next()?;
        let mut tail = Words(w.take(tail_len)?);
        let rest = w.0.to_vec();
        let report = PairReport::from_counters((numbers, rest.clone()), &self.component_names())?;
        if report.to_counters().1 != rest {
            return Err("a chain pair's report has words left over".into());
        }
        let mut chains: [Option<(ChainRng, LightAlgorithm)>; 2] = [None, None];
        while !tail.0.is_empty() {
            let kind = tail.next()?;
            let Some(&(k, large)) = self.kinds().iter().find(|k| k.0 as u64 == kind) else {
                return Err(format!(
                    "holds a chain of kind {kind}, which the run does not have"
                ));
            };
            let rng = rng_from_words([tail.next()?, tail.next()?, tail.next()?, tail.next()?])
                .ok_or("a chain's stream is all zero")?;
            let len = tail.next()?;
            let mut state = tail.take(len)?;
            let mut algorithm = self.algorithm(large);
            if !algorithm.kernel_mut().restore_words(&mut state) || !state.is_empty() {
                return Err("a chain's kernel state does not decode".into());
            }
            if chains[k as usize].replace((rng, algorithm)).is_some() {
                return Err(format!("holds two chains of kind {kind} in one pair"));
            }
        }
        for (chain, stats) in chains.iter().zip(&report.chains) {
            let fits = match (chain, stats) {
                (Some((_, a)), Some(s)) => a.component_names().len() == s.components.len(),
                (None, None) => true,
                _ => false,
            };
            if !fits {
                return Err("a chain pair's report does not match its chains".into());
            }
        }
        Ok(SavedUnit { report, chains })
    }

    /// Where a checkpointed run starts: `None` for a fresh start, else
    /// the iterations done and what they left (every rank: rank 0 reads
    /// the file and broadcasts its words), and on rank 0 the two films
    /// rebuilt with `filter`. Collective on a cluster. The progress must
    /// have passed [`check_checkpoint`].
    fn resume_point(
        &self,
        checkpoint: &Checkpoint,
        filter: &Arc<Filter>,
    ) -> Option<(u64, Resumed)> {
        let local = checkpoint.resume.as_ref();
        let words = local.map_or(Vec::new(), |p| {
            let mut w = vec![p.pass];
            w.extend(&p.extra);
            w
        });
        let words = match crate::cluster::current() {
            Some(c) => c.broadcast_u64s(words),
            None => words,
        };
        let (&iterations, extra) = words.split_first()?;
        let mut resumed = (self.decode(iterations, extra))
            .expect("rank 0 checked the checkpoint (check_checkpoint)");
        resumed.films = local.map(|p| {
            let film = |f: Result<Film, String>| f.expect("checked against the scene");
            (
                film(p.film(filter.clone())),
                film(p.more_film(0, filter.clone())),
            )
        });
        Some((iterations, resumed))
    }

    /// Whether the chains' restarts carry their pool's weight
    /// ([`Restart::Weighted`] with the render-wide normalisation; with
    /// `normalisation = iteration` the restarts are `resampled`: each
    /// iteration's normalisation comes from its own pool). Independent
    /// light subpaths have no restarts: weight one.
    fn weighs_restarts(&self) -> bool {
        self.restart == Restart::Weighted
            && self.normalisation == NormalisationScope::Render
            && self.chains != LightChains::Independent
    }

    /// Whether `b_con` is estimated by `transfer` with a scale `k ≠ 1`
    /// (with `k = 1` it is `direct`).
    fn transfers(&self, light_scale: f32) -> bool {
        self.con_estimate == ConEstimate::Transfer
            && light_scale != 1.0
            && self.chains != LightChains::Independent
    }

    /// Light subpaths (steps) of unit `p` per iteration: its share of
    /// [`Vcm::light_paths`].
    fn unit_steps(&self, pixels: usize, p: usize) -> usize {
        share(self.vcm.light_paths(pixels), self.units, p)
    }

    /// `(n_con, n_vis)`: steps of each chain per iteration over all units.
    fn steps_per_kind(&self, pixels: usize) -> (u64, u64) {
        let (mut n_con, mut n_vis) = (0, 0);
        for p in 0..self.units {
            let steps = self.unit_steps(pixels, p) as u64;
            match self.chains {
                LightChains::Both => {
                    n_con += steps.div_ceil(2);
                    n_vis += steps / 2;
                }
                LightChains::Contribution => n_con += steps,
                LightChains::Independent => {}
            }
        }
        (n_con, n_vis)
    }

    /// The camera pass of iteration `iteration` (from 0) into `out`: one
    /// stratified camera subpath per pixel, in tiles (the samples numbered
    /// in tile order), with the path-tracing techniques weighted for
    /// light-subpath density scale `light_scale`, and the merge grid of
    /// radius `radius`.
    pub fn camera_pass(
        &self,
        scene: &Scene,
        radius: f32,
        light_scale: f32,
        seed: u64,
        iteration: u64,
        out: &mut CameraPass,
    ) {
        let (width, height) = (scene.film.width, scene.film.height);
        let pixels = width as usize * height as usize;
        let unscaled = MisFactors::new(self.vcm.mode, self.vcm.heuristic, radius, pixels as f64);
        let f = unscaled.with_light_density_scale(light_scale);
        let unscaled = self.transfers(light_scale).then_some(unscaled);
        let tiles: Vec<(u32, u32, u32, u32)> = (0..height.div_ceil(TILE))
            .flat_map(|ty| {
                (0..width.div_ceil(TILE)).map(move |tx| {
                    let (x0, y0) = (tx * TILE, ty * TILE);
                    (x0, y0, (x0 + TILE).min(width), (y0 + TILE).min(height))
                })
            })
            .collect();
        // Each tile traces into its own buffers, kept from the last
        // iteration (no allocation once they have grown, and no join copy).
        let cameras = &mut out.cameras;
        cameras
            .tiles
            .resize_with(tiles.len(), TileSubpaths::default);
        let results: Vec<(f64, Tally)> = cameras
            .tiles
            .par_iter_mut()
            .zip(&tiles)
            .enumerate()
            .map(|(t, (buffers, &tile))| {
                self.camera_tile(
                    scene,
                    &f,
                    unscaled.as_ref(),
                    tile,
                    seed,
                    iteration,
                    t,
                    buffers,
                )
            })
            .collect();
        cameras.index();
        out.rasters.clear();
        out.estimates.clear();
        out.transfer = 0.0;
        out.tally = Tally::default();
        out.rasters.reserve_exact(pixels);
        out.estimates.reserve_exact(pixels);
        for (tile, (transfer, tally)) in out.cameras.tiles.iter().zip(results) {
            out.rasters.extend_from_slice(&tile.rasters);
            out.estimates.extend_from_slice(&tile.estimates);
            out.transfer += transfer;
            out.tally.add(&tally);
        }
        if self.vcm.mode.merges() {
            out.cameras.build_grid(scene, radius);
        }
    }

    /// One tile of camera subpaths into `out` (cleared first): the
    /// subpaths, their raster positions and path-tracing estimates; it
    /// returns their transfer (Σ `lum` of the estimates with the
    /// `unscaled` weights minus with `f`'s; 0 without `unscaled`) and the
    /// technique tally.
    #[allow(clippy::too_many_arguments)]
    fn camera_tile(
        &self,
        scene: &Scene,
        f: &MisFactors,
        unscaled: Option<&MisFactors>,
        (x0, y0, x1, y1): (u32, u32, u32, u32),
        seed: u64,
        iteration: u64,
        tile: usize,
        out: &mut TileSubpaths,
    ) -> (f64, Tally) {
        out.clear(((x1 - x0) * (y1 - y0)) as usize);
        let mut transfer = 0.0;
        let mut tally = Tally::default();
        let mut src = unit_source(seed, 2 * iteration, tile as u64);
        let (mut z, mut mis) = (Vec::new(), Vec::new());
        for y in y0..y1 {
            for x in x0..x1 {
                let u = src.next_2d();
                let raster = Vec2::new(x as f32 + u.0, y as f32 + u.1);
                let n = self
                    .vcm
                    .trace_camera_subpath(scene, f, raster, &mut src, &mut z, &mut mis);
                let (mut l, mut l_unscaled) = (Rgb::BLACK, Rgb::BLACK);
                for j in 1..n {
                    if !self.vcm.path_tracing_at(
                        scene,
                        f,
                        &z[..n],
                        &mis,
                        j,
                        false,
                        &mut src,
                        &mut l,
                        &mut tally,
                        unscaled.map(|u| (u, &mut l_unscaled)),
                    ) {
                        break;
                    }
                }
                if unscaled.is_some() {
                    transfer += f64::from(l_unscaled.luminance()) - f64::from(l.luminance());
                }
                out.push(&z[..n], &mis[..n], raster, l);
            }
        }
        (transfer, tally)
    }

    /// The chain pair `p` for one iteration: restart from `pool` (seen
    /// through `restarts`; `fresh`, when the pool holds one visible
    /// candidate, for the visibility chain), then its share of the
    /// iteration's light subpaths, each splat multiplied by the restart
    /// weight `weight`.
    #[allow(clippy::too_many_arguments)]
    fn run_unit(
        &self,
        scene: &Scene,
        it: &Iteration,
        unscaled: Option<&Iteration>,
        pool: &[Candidate],
        restarts: &RestartPool,
        fresh: Option<&Candidate>,
        weight: f64,
        (b_vis, b_con): (f64, f64),
        unit: &mut Unit,
        p: usize,
        seed: u64,
        iteration: u64,
        abort: &(dyn Fn() -> bool + Sync),
    ) {
        // Checked before the restart too: a unit with no step of its own
        // (units > pixels) never reached the check in its steps, and
        // 10^6 such units' restarts kept a run long past `--time`.
        if abort() {
            return;
        }
        let pixels = it.cameras.len();
        let kinds = self.kinds();
        let weighted = self.weighs_restarts();
        let mut rng = stream_rng(seed, STREAM_STEPS ^ (iteration << 24) ^ p as u64);
        let steps = self.unit_steps(pixels, p);
        if self.chains == LightChains::Independent {
            // Independent light subpaths, weight N/L each for L light
            // subpaths of N pixels (one with L = N): VCM's estimator.
            let weight = (pixels as f64 / self.vcm.light_paths(pixels) as f64) as f32;
            let mut c = LightContribution::default();
            for s in 0..steps {
                if s % STOP_CHECK == 0 && abort() {
                    return;
                }
                let point = TorusPoint::fresh(child_rng(&mut rng));
                let camera = ((uniform(&mut rng) * pixels as f64) as usize).min(pixels - 1);
                light_contribution(scene, it, &mut PssSource::new(&point, 1), camera, &mut c);
                if !c.finite {
                    unit.invalid += 1;
                    unit.norm.add(0.0, 0.0);
                    continue;
                }
                unit.norm.add(c.luminance, c.luminance);
                deposit(
                    &mut unit.camera,
                    &mut unit.splats,
                    &mut unit.tally,
                    &c,
                    weight,
                );
            }
            return;
        }
        // Restart by importance resampling (the contribution chain ∝ lum,
        // the visibility chain uniform among the visible candidates; with
        // `weighted`, other than the contribution chain's, module docs).
        let mut con_index = None;
        for &(kind, large) in kinds {
            let target = move |camera: usize| LightTarget {
                scene,
                it,
                camera,
                kind,
            };
            let resampled = |i: usize| {
                Sample::evaluate(
                    &target(pool[i].camera),
                    TorusPoint::fresh(pool[i].rng.clone()),
                )
            };
            let sample = match kind {
                ChainKind::Contribution => {
                    let i = restarts.contribution(uniform(&mut rng));
                    con_index = Some(i);
                    resampled(i)
                }
                ChainKind::Visibility => {
                    let exclude = if weighted { con_index } else { None };
                    match restarts.visibility(uniform(&mut rng), exclude) {
                        Some(i) => resampled(i),
                        // The pool's one visible candidate is the
                        // contribution chain's: the iteration's fresh
                        // visible light subpath, or failing that the
                        // contribution chain's (a bias this rare case
                        // leaves).
                        None => match fresh {
                            Some(c) => Sample::evaluate(
                                &target(c.camera),
                                TorusPoint::fresh(c.rng.clone()),
                            ),
                            None => resampled(con_index.expect("drawn first")),
                        },
                    }
                }
            };
            let slot = &mut unit.chains[kind as usize];
            match slot {
                Some(chain) => chain.parts_mut().current = sample,
                None => {
                    let chain_rng = stream_rng(seed, STREAM_CHAINS + 2 * p as u64 + kind as u64);
                    *slot = Some(
                        Chain::from_sample(sample, self.algorithm(large), chain_rng)
                            .expect("a resampled candidate has a finite density"),
                    );
                }
            }
        }
        let (n_con, n_vis) = self.steps_per_kind(pixels);
        // The balance heuristic's denominator over the two chains (×1/N).
        let scale = pixels as f64;
        let mix = |c: &LightContribution| {
            let vis = if c.luminance > 0.0 { 1.0 } else { 0.0 };
            n_vis as f64 * vis / b_vis + n_con as f64 * c.luminance / b_con
        };
        let Unit {
            chains,
            camera: acc,
            splats,
            norm,
            tally,
            swaps,
            swaps_accepted,
            swap_alpha,
            invalid,
        } = unit;
        for s in 0..steps {
            if s % STOP_CHECK == 0 && abort() {
                return;
            }
            let kind = kinds[s % kinds.len()].0;
            let camera = ((uniform(&mut rng) * pixels as f64) as usize).min(pixels - 1);
            let target = LightTarget {
                scene,
                it,
                camera,
                kind,
            };
            let chain = chains[kind as usize].as_mut().expect("started");
            let large_component = 1;
            let info = chain.step_with(
                &target,
                |t: &Transition<'_, TorusPoint, LightContribution>| {
                    let mut splat = |c: &LightContribution, w: f64| {
                        if w > 0.0 && c.luminance > 0.0 && c.finite {
                            deposit(acc, splats, tally, c, (w * weight * scale / mix(c)) as f32);
                        }
                    };
                    splat(&t.current.payload, 1.0 - t.alpha);
                    let lum = |c: &LightContribution| {
                        if c.finite && c.luminance > 0.0 {
                            c.luminance
                        } else {
                            0.0
                        }
                    };
                    if kind == ChainKind::Visibility {
                        // E_vis[lum C^Ω] for `con_estimate` (Rao–Blackwellised:
                        // the expected luminance of the next state).
                        let next = (1.0 - t.alpha) * lum(&t.current.payload)
                            + t.proposal.map_or(0.0, |y| t.alpha * lum(&y.payload));
                        norm.add_chain(next);
                    }
                    if let Some(y) = t.proposal {
                        splat(&y.payload, t.alpha);
                        if t.component == large_component {
                            let l = lum(&y.payload);
                            norm.add(l, unscaled_luminance(scene, unscaled, &y.state, camera, l));
                        }
                    }
                },
            );
            if info.outcome == mcmc_core::stats::Outcome::InvalidDensity {
                *invalid += 1;
            }
            if kinds.len() == 2 {
                let [con, vis] = chains;
                let (con, vis) = (
                    con.as_mut().expect("started"),
                    vis.as_mut().expect("started"),
                );
                let (x_con, x_vis) = (&con.current().payload, &vis.current().payload);
                let log_alpha = swap_log_acceptance(
                    con.current().log_density,
                    vis.current().log_density,
                    ChainKind::Contribution.log_density(x_vis),
                    ChainKind::Visibility.log_density(x_con),
                );
                *swaps += 1;
                *swap_alpha += log_alpha.exp();
                if accept(log_alpha, &mut rng) {
                    *swaps_accepted += 1;
                    std::mem::swap(&mut con.parts_mut().current, &mut vis.parts_mut().current);
                    for (chain, kind) in
                        [(con, ChainKind::Contribution), (vis, ChainKind::Visibility)]
                    {
                        let current = &mut chain.parts_mut().current;
                        current.log_density = kind.log_density(&current.payload);
                    }
                }
            }
        }
    }

    /// The registry's result with the JSON statistics.
    #[allow(clippy::too_many_arguments)]
    fn report(
        &self,
        image: Vec<Rgb>,
        reports: &[PairReport],
        norm: &Normalisation,
        totals: &Totals,
        weights: &RestartWeights,
        light_scale: f32,
        iterations: u64,
        seconds: f64,
        interrupted: bool,
        pixels: usize,
    ) -> Rendered {
        let samples = iterations * pixels as u64;
        let per_second = |n: f64| if seconds > 0.0 { n / seconds } else { 0.0 };
        let total: f64 = totals.tally.energy.iter().sum();
        let shares: serde_json::Map<String, serde_json::Value> = TECHNIQUE_NAMES
            .iter()
            .zip(&totals.tally.energy)
            .map(|(name, e)| {
                let share = if total > 0.0 { e / total } else { 0.0 };
                (name.to_string(), share.into())
            })
            .collect();
        let mut chains = serde_json::Map::new();
        for &(kind, _) in self.kinds() {
            let mut stats: Option<ChainStatistics> = None;
            for r in reports {
                if let Some(chain) = &r.chains[kind as usize] {
                    match &mut stats {
                        Some(s) => s.merge(chain),
                        None => stats = Some(chain.clone()),
                    }
                }
            }
            let name = match kind {
                ChainKind::Contribution => "contribution",
                ChainKind::Visibility => "visibility",
            };
            if let Some(s) = stats {
                let components: serde_json::Map<String, serde_json::Value> = s
                    .components
                    .iter()
                    .map(|c| {
                        (
                            c.name.clone(),
                            serde_json::json!({
                                "proposed": c.proposed,
                                "acceptance": c.acceptance_rate(),
                            }),
                        )
                    })
                    .collect();
                chains.insert(
                    name.into(),
                    serde_json::json!({
                        "steps": s.steps,
                        "acceptance": s.acceptance_rate(),
                        "outside_support": s.outside_support,
                        "invalid_density": s.invalid_density,
                        "components": components,
                    }),
                );
            }
        }
        let (b_vis, b_con_direct) = norm.estimates();
        let (se_vis, se_con_direct) = norm.standard_errors();
        let (b_con, se_con) = norm.con(self.con_estimate);
        let (b_con_vis, se_con_vis) = if norm.chain_steps > 0.0 {
            norm.con_from_visibility()
        } else {
            (f64::NAN, f64::NAN)
        };
        let (b_con_transfer, se_con_transfer) = if self.con_estimate == ConEstimate::Transfer {
            norm.con(ConEstimate::Transfer)
        } else {
            (f64::NAN, f64::NAN)
        };
        let finite_or_null = |x: f64| {
            if x.is_finite() {
                serde_json::json!(x)
            } else {
                serde_json::Value::Null
            }
        };
        let last_radius = self.vcm.radius_at(iterations.saturating_sub(1));
        let exchange_rate = if totals.swaps > 0 {
            totals.swaps_accepted as f64 / totals.swaps as f64
        } else {
            0.0
        };
        let statistics = serde_json::json!({
            "iterations": iterations,
            "spp": iterations,
            "iterations_per_second": per_second(iterations as f64),
            "samples_per_second": per_second(samples as f64),
            "mode": self.vcm.mode.name(),
            "light_chains": self.chains.name(),
            "radius_initial": self.vcm.radius,
            "radius_final": last_radius,
            "alpha": self.vcm.alpha,
            "exchange_attempts": totals.swaps,
            "exchange_rate": exchange_rate,
            "exchange_mean_alpha": if totals.swaps > 0 { totals.swap_alpha / totals.swaps as f64 } else { 0.0 },
            "chains": chains,
            "b_vis": b_vis,
            "b_vis_standard_error": finite_or_null(se_vis),
            "b_con": b_con,
            "b_con_standard_error": finite_or_null(se_con),
            "con_estimate": self.con_estimate.name(),
            "b_con_direct": b_con_direct,
            "b_con_direct_standard_error": finite_or_null(se_con_direct),
            "b_con_visibility": finite_or_null(b_con_vis),
            "b_con_visibility_standard_error": finite_or_null(se_con_vis),
            "b_con_transfer": finite_or_null(b_con_transfer),
            "b_con_transfer_standard_error": finite_or_null(se_con_transfer),
            "visibility_chain_steps": norm.chain_steps,
            "normalisation_samples": norm.count,
            "light_density_scale": light_scale,
            "candidates": self.candidates,
            "restart": self.restart.name(),
            "restart_weight_ess": finite_or_null(weights.effective_fraction()),
            "units": self.units,
            "skipped_iterations": totals.skipped_iterations,
            "energy_shares": shares,
            "nonfinite_samples": totals.tally.nonfinite,
            "invalid_proposals": totals.invalid,
        });
        Rendered {
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
                "{iterations} iterations in {seconds:.2} s ({:.2} it/s), exchange rate {:.1}%, b_vis {b_vis:.3e}, b_con {b_con:.3e}{}",
                per_second(iterations as f64),
                100.0 * exchange_rate,
                if interrupted { ", stopped early" } else { "" }
            ),
        }
    }
}

crate::choice! {
    /// Which light-subpath chains run.
    pub enum LightChains {
        /// The contribution and the visibility chain, coupled by replica exchange (the thesis's method).
        Both = "both",
        /// The contribution chain alone, with the large steps (ablation).
        Contribution = "contribution",
        /// No chains: independent light subpaths, each once (VCM's estimator with merging at the camera vertices; ablation).
        Independent = "independent",
    }
}

crate::choice! {
    /// Which light subpaths the normalisations `b_vis`, `b_con` average.
    pub enum NormalisationScope {
        /// Every independent light subpath of the render so far (Eq. 6.4: restart candidates and large-step proposals).
        Render = "render",
        /// The restart candidates of the iteration alone (the targets change with each iteration's camera subpaths).
        Iteration = "iteration",
    }
}

crate::choice! {
    /// How the normalisation `b_con` is estimated (module docs).
    pub enum ConEstimate {
        /// The mean of lum C^Ω over the independent light subpaths (Eq. 6.4).
        Direct = "direct",
        /// b_vis times the visibility chain's mean of lum C^Ω.
        Visibility = "visibility",
        /// Both, weighted by their inverse squared standard errors.
        Combined = "combined",
        /// b_con with the tracing density's weights (k = 1) from the independent light subpaths, plus the energy the MIS scale k moves off path tracing, measured on the camera subpaths.
        Transfer = "transfer",
    }
}

crate::choice! {
    /// How the light-subpath chains restart each iteration (module docs).
    pub enum Restart {
        /// Importance resampling with the pool's mean luminance as the weight of the iteration's light side (properly weighted: unbiased for any pool size); the visibility chain from a visible candidate other than the contribution chain's.
        Weighted = "weighted",
        /// Importance resampling alone, each chain in stationarity assumed (the thesis, Fig. 6.8: biased for a finite pool).
        Resampled = "resampled",
    }
}

/// `target_acceptance` lies in (0, 1).
fn check_acceptance(v: &f64) -> Result<(), String> {
    if *v > 0.0 && *v < 1.0 {
        Ok(())
    } else {
        Err("must lie in (0, 1)".into())
    }
}

/// Unit `p`'s share when `n` items are dealt in order over `units` units
/// (the shares differ by at most one and sum to `n`).
fn share(n: usize, units: usize, p: usize) -> usize {
    n * (p + 1) / units - n * p / units
}

crate::settings! {
    /// MCMC over VCM's light subpaths, as the registry fills it.
    pub struct McmcVcmSettings {
        /// Light subpaths: both (contribution and visibility chains, replica exchange), contribution (that chain alone, with the large steps) or independent (no MCMC).
        pub light_chains: LightChains = LightChains::Both;
        /// Large-step probability of the visibility chain (of the contribution chain when it runs alone).
        pub large_step: f64 = 0.3, check crate::settings::check::probability;
        /// Target acceptance of the adaptive small step (Hachisuka & Jensen 2011).
        pub target_acceptance: f64 = 0.234, check check_acceptance;
        /// Independent light subpaths per iteration the chains restart from (importance resampling).
        pub candidates: usize = 10_000, check crate::settings::check::count;
        /// Chain pairs, each running its share of an iteration's light subpaths.
        pub units: usize = 8, check crate::settings::check::count;
        /// Normalisations b_vis, b_con: running means over the render (render, Eq. 6.4) or the iteration's restart candidates (iteration).
        pub normalisation: NormalisationScope = NormalisationScope::Render;
        /// Scale the light-subpath techniques' densities in the MIS weights by the chains' mixture density (the visibility chain's exact p/b_vis).
        pub vis_pdf: bool = true;
        /// b_con from the independent light subpaths (direct, Eq. 6.4), from b_vis and the visibility chain's mean luminance (visibility), both by inverse variance (combined), or with k = 1 weights plus the camera subpaths' transfer (transfer).
        pub con_estimate: ConEstimate = ConEstimate::Transfer;
        /// Chain restarts: weighted (each iteration's light side weighted by its restart pool's mean luminance, the contribution chain's proper weight; the visibility chain from another candidate) or resampled (the thesis's importance resampling alone, biased for a finite pool). With normalisation = iteration the restarts are resampled.
        pub restart: Restart = Restart::Weighted;
        flatten {
            /// VCM: mode, radius, reduction (alpha: 1 here, a fixed radius as the thesis runs), heuristic, light subpaths per pixel (here the chains' steps of an iteration over all pairs), depth.
            pub vcm: VcmSettings = VcmSettings {
                alpha: 1.0,
                ..VcmSettings::default()
            };
        }
    }
}

/// Heap bytes of one chain pair beyond its two images: the `Unit`, its
/// two chains (state with its lazily drawn coordinates, the adaptive
/// kernel, statistics) and their current states' contributions `C^Ω`.
/// An estimate of the same kind as `markov`'s bytes per chain, set from
/// what was measured (docs/vcm.md "Session 17": about 3.4 KB of heap per
/// pair on the Cornell box at `max_depth` 5 in `tests/mcmc_vcm_memory.rs`;
/// 3.8 KB and 5.5 KB of resident set per pair on the interior at
/// `max_depth` 6 and 20) with room for longer paths; a state's
/// contribution holds one 28-byte part per merged camera vertex, so a
/// radius spanning many pixels can exceed it.
pub const BYTES_PER_UNIT: u128 = 8192;

/// Mean camera vertices per subpath assumed with an unbounded depth
/// (Russian roulette ends the walks; with a bounded depth the bound,
/// `max_depth + 1`, is used).
pub const UNBOUNDED_CAMERA_VERTICES: u128 = 16;

/// [`McmcVcmSettings::memory_bytes`]: a render's peak heap, by part.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryEstimate {
    /// The output film, the light side's film apart from it and the
    /// iteration's light-side sum (68 B a pixel).
    pub films: u128,
    /// The chain pairs: two images each (24 B a pixel) and [`BYTES_PER_UNIT`].
    pub units: u128,
    /// One iteration's camera subpaths: every vertex with its MIS
    /// quantities twice (the tiles' buffers, kept across iterations, grow
    /// by doubling and are not shrunk: at most twice what they hold), the
    /// merge grid over them (48 B a vertex with its construction and its
    /// point list), and per pixel its raster position and estimate
    /// (twice: the tile's and the pass's), start index and tile index.
    pub cameras: u128,
    /// The restart candidates (the blocks and the joined pool, 2 ×
    /// 56 B each) and the restart pool's cumulative luminances and
    /// visible indices (12 B per candidate).
    pub candidates: u128,
}

impl MemoryEstimate {
    /// The sum of the parts.
    pub fn total(&self) -> u128 {
        self.films
            .saturating_add(self.units)
            .saturating_add(self.cameras)
            .saturating_add(self.candidates)
    }
}

impl McmcVcmSettings {
    /// The heap a render of `scene` with these settings takes at its peak
    /// (an estimate, by part; the scene itself is not counted; it does not
    /// depend on the thread count). Checked against the memory available before the render
    /// allocates anything (docs/errors.md).
    pub fn memory_bytes(&self, scene: &Scene) -> MemoryEstimate {
        let size = |bytes: usize| bytes as u128;
        let pixels = u128::from(scene.film.width) * u128::from(scene.film.height);
        let rgb = size(std::mem::size_of::<Rgb>());
        let depth = u128::from(self.vcm.depth.limit());
        let vertices = if depth < UNBOUNDED_CAMERA_VERTICES {
            depth + 1
        } else {
            UNBOUNDED_CAMERA_VERTICES
        };
        let vertex = size(std::mem::size_of::<Vertex>() + std::mem::size_of::<PartialMis>());
        // The grid's entry (position, index), bucket start, bucket of each
        // point and next slot while sorting, the point list it is built
        // from, and the (subpath, vertex) of each merge point.
        let grid = 16 + 4 + 4 + 4 + 12 + 8;
        let per_pixel = size(std::mem::size_of::<Vec2>()) + rgb + 4;
        let candidate = size(std::mem::size_of::<Candidate>());
        // Saturating: 2^64 − 1 pairs on a 2^32 × 2^32 film would overflow
        // even 128 bits (and are refused all the same).
        MemoryEstimate {
            films: pixels * (2 * u128::from(crate::resources::FILM_BYTES_PER_PIXEL) + rgb),
            units: (self.units as u128).saturating_mul(pixels * 2 * rgb + BYTES_PER_UNIT),
            cameras: pixels * (vertices * (2 * vertex + grid) + 2 * per_pixel),
            candidates: self.candidates as u128 * (2 * candidate + 12),
        }
    }

    /// The integrator these settings describe for `scene`.
    pub fn integrator(&self, scene: &Scene) -> McmcVcm {
        McmcVcm {
            vcm: self.vcm.integrator(scene),
            chains: self.light_chains,
            large_step: self.large_step,
            target_acceptance: self.target_acceptance,
            candidates: self.candidates,
            units: self.units,
            normalisation: self.normalisation,
            vis_pdf: self.vis_pdf,
            con_estimate: self.con_estimate,
            restart: self.restart,
        }
    }
}

impl IntegratorSettings for McmcVcmSettings {
    const NAME: &'static str = "mcmc-vcm";
    const DESCRIPTION: &'static str = "MCMC over VCM's light subpaths (Šik, ch. 6): contribution and visibility chains with replica exchange, stratified camera subpaths.";

    fn validate(&self) -> Result<(), String> {
        if self.vcm.mode == VcmMode::Ppm {
            return Err("`mode` must be vcm or bpt for mcmc-vcm".into());
        }
        if self.normalisation == NormalisationScope::Render && self.vcm.alpha < 1.0 {
            return Err(
                "`normalisation = render` needs a fixed radius (`alpha = 1`): with radius reduction the targets change with each iteration; use `normalisation = iteration`".into(),
            );
        }
        if matches!(
            self.con_estimate,
            ConEstimate::Visibility | ConEstimate::Combined
        ) && (self.normalisation == NormalisationScope::Iteration
            || self.light_chains != LightChains::Both)
        {
            return Err(
                "`con_estimate` visibility or combined needs the visibility chain (`light_chains = both`) and `normalisation = render`".into(),
            );
        }
        if self.light_chains == LightChains::Contribution && !(self.large_step > 0.0) {
            return Err("the contribution chain alone needs `large_step` > 0".into());
        }
        Ok(())
    }

    fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError> {
        // 10^15 units or candidates aborted on allocations of 10^18 and
        // 3·10^15 bytes; the estimate is checked before anything sized by
        // them or by the film is allocated.
        let (w, h) = (scene.film.width, scene.film.height);
        let bytes = self.memory_bytes(scene).total();
        crate::resources::check_memory(
            &format!(
                "mcmc-vcm: {w}×{h} with {} units and {} candidates",
                self.units, self.candidates
            ),
            bytes,
        )
        .map_err(RenderError::Invalid)?;
        if let Some(p) = run.checkpoint.as_ref().and_then(|c| c.resume.as_ref()) {
            check_checkpoint(p, self, scene).map_err(RenderError::Invalid)?;
        }
        let mut out = self.integrator(scene).render(scene, run, stop, observer);
        // Reported so that the estimate can be set against the resident
        // set a run measures (docs/vcm.md, "Session 17").
        out.statistics
            .insert("memory_estimate_bytes".into(), (bytes as f64).into());
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chain pair's report and normalisation sums cross ranks as
    /// numbers and counts; they must come back with the same bits (the
    /// image and statistics of a distributed run are the single process's
    /// only then). Values with awkward bits (−0, a subnormal, 1/3); the
    /// visibility chain absent, as with `light_chains = contribution`. A
    /// report cut by one word is refused.
    #[test]
    fn a_pair_report_and_its_sums_cross_ranks_bit_exactly() {
        let mut stats = ChainStatistics::new(vec!["small".into(), "large".into()]);
        (stats.steps, stats.accepted, stats.evaluations) = (7, 3, 9);
        (stats.invalid_density, stats.outside_support, stats.failed) = (1, 2, 4);
        stats.components[1].proposed = 5;
        stats.components[1].accepted = 2;
        stats.components[1].sum_alpha = 1.0 / 3.0;
        let report = PairReport {
            tally: Tally {
                energy: [-0.0, 1e-310, 1.0 / 3.0, 2.5, f64::MAX],
                nonfinite: 6,
                light_vertices: 11,
            },
            swaps: 13,
            swaps_accepted: 8,
            swap_alpha: 0.1 + 0.2,
            invalid: 3,
            chains: [Some(stats.clone()), None],
        };
        let names = [vec!["small".to_string(), "large".to_string()], Vec::new()];
        let back = PairReport::from_counters(report.to_counters(), &names).unwrap();
        let bits = |e: &[f64]| e.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back.tally.energy), bits(&report.tally.energy));
        assert_eq!((back.tally.nonfinite, back.tally.light_vertices), (6, 11));
        assert_eq!((back.swaps, back.swaps_accepted, back.invalid), (13, 8, 3));
        assert_eq!(back.swap_alpha.to_bits(), report.swap_alpha.to_bits());
        let chain = back.chains[0].as_ref().expect("the contribution chain");
        assert_eq!((chain.steps, chain.accepted, chain.evaluations), (7, 3, 9));
        assert_eq!(
            (chain.invalid_density, chain.outside_support, chain.failed),
            (1, 2, 4)
        );
        let c = &chain.components[1];
        assert_eq!((c.name.as_str(), c.proposed, c.accepted), ("large", 5, 2));
        assert_eq!(c.sum_alpha.to_bits(), (1.0f64 / 3.0).to_bits());
        assert!(back.chains[1].is_none());
        let (numbers, mut counts) = report.to_counters();
        counts.pop();
        assert!(PairReport::from_counters((numbers, counts), &names).is_err());

        let mut n = Normalisation::default();
        n.add(1.0 / 3.0, 0.1);
        n.add(0.0, 0.0);
        n.add_cameras(6144.0, -1e-300);
        n.add_chain(0.7);
        n.weigh_chain(1.0 / 7.0);
        let back = Normalisation::from_batch(&n.batch());
        assert_eq!(bits(&back.batch()), bits(&n.batch()));
    }

    /// The batch ratio and its standard error against values worked by
    /// hand: batches (num, den) = (1, 2), (3, 2): r = 4/4 = 1; residuals
    /// −1, 1; s = 2; SE = √(2 · 2/1)/4 = 0.5.
    #[test]
    fn batch_ratio_matches_hand_values() {
        let b = [[2.0, 1.0, 0.0, 0.0, 0.0], [2.0, 3.0, 0.0, 0.0, 0.0]];
        let (r, se) = batch_ratio(&b, 1, 0);
        assert_eq!(r, 1.0);
        assert!((se - 0.5).abs() < 1e-12, "{se}");
        assert!(batch_ratio(&b[..1], 1, 0).1.is_nan());
    }

    /// Two ratios summed, against values worked by hand: batches
    /// (num₁, den₁, num₂, den₂) = (1, 2, 0, 1), (3, 2, 2, 1): r₁ = 4/4 = 1,
    /// r₂ = 2/2 = 1, sum 2; linearised residuals (1 − 2)/4 + (0 − 1)/2 =
    /// −0.75 and (3 − 2)/4 + (2 − 1)/2 = 0.75; SE = √(2 · 1.125) = 1.5. One
    /// term alone is `batch_ratio`.
    #[test]
    fn batch_ratios_sum_and_linearise() {
        let b = [[1.0, 2.0, 0.0, 1.0], [3.0, 2.0, 2.0, 1.0]];
        let (r, se) = batch_ratios(&b, &[(0, 1), (2, 3)]);
        assert_eq!(r, 2.0);
        assert!((se - 1.5).abs() < 1e-12, "{se}");
        assert_eq!(batch_ratios(&b, &[(0, 1)]), batch_ratio(&b, 0, 1));
        assert!(batch_ratios(&b[..1], &[(0, 1), (2, 3)]).1.is_nan());
    }

    /// Inverse variance: SEs 1 and 2 give weights 4:1 (estimate
    /// (4·1 + 1·6)/5 = 2, SE 1/√(1.25)); a missing SE keeps the first.
    #[test]
    fn inverse_variance_weights_by_squared_errors() {
        let (c, se) = inverse_variance(1.0, 1.0, 6.0, 2.0);
        assert!((c - 2.0).abs() < 1e-12 && (se - 1.25f64.sqrt().recip()).abs() < 1e-12);
        assert_eq!(inverse_variance(1.0, f64::NAN, 6.0, 2.0).0, 1.0);
    }
}
