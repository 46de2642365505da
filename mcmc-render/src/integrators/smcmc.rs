//! Stratified MCMC (Gruson, West and Hachisuka 2020; spec seed003 §8) with
//! the random replay, BDPT, rBDPT, MMLT and guided shifts (`shift`).
//!
//! - **Chains**: one per pixel `s`, over primary sample space, targeting
//!   the tile's summed luminance `π̃_s` ([`crate::smcmc::TileTarget`]);
//!   the kernel is `mcmc-core`'s Metropolis–Hastings with the PSS mutation
//!   ([`crate::pss::Mutation`]: small step, large step with probability
//!   `large_step_probability`).
//! - **Estimator, alignment, image**: [`crate::smcmc`] (mean-value
//!   substitution per tile, Jacobi alignment of Eq. 3.38, `Î(j)` averaged over
//!   the tiles containing `j`).
//! - **Tile exchange** (§8.6): every `exchange_every` iterations, the
//!   states of neighbouring tiles are swapped with
//!   `r = min(1, π̃_s(u_t) π̃_t(u_s) / (π̃_s(u_s) π̃_t(u_t)))`
//!   (`mcmc_core::replica::swap_log_acceptance`, decided by
//!   `mcmc_core::mh::accept_probability`); rounds cycle through horizontal
//!   pairs from even columns, vertical pairs from even rows, then both
//!   from odd ones, so each tile meets all four neighbours. An exchange
//!   splats both states with weights `r` and `1 − r`. A running tile next
//!   to one that never started hands it a copy of its state (§8.7,
//!   start-up bias, consistent).
//! - **Initialisation** (§8.7): with `init=global`, global chains over the
//!   film hand their states to the tiles they visit
//!   ([`crate::smcmc::global_init`]); otherwise (and for tiles they miss)
//!   each tile draws `init_candidates` uniform states (which also feed
//!   `Ĩ`) and starts from one resampled `∝ π̃_s`; a tile whose candidates
//!   are all black draws one more uniform state per iteration until one
//!   carries light (or receives a neighbour's state).
//! - **Stopping**: the stop flag and the time budget are checked before
//!   every tile step, exchange pair and start-up draw, so a run ends
//!   mid-iteration with a valid image (each tile is normalised by its own
//!   transition count), and before every alignment sweep after the
//!   default's [`DEFAULT_SOLVER_ITERATIONS`]: the statistics' `solver`
//!   `iterations` against `planned_iterations` show a cut (fewer sweeps
//!   leave more of the seams between tiles; the image-wide brightness is
//!   where `b⁰` puts it either way: see [`crate::smcmc::solver`]).
//! - **Determinism**: every tile owns its streams (seeded from the run's
//!   seed and its index); tiles step in parallel, exchange pairs are
//!   disjoint, and all sums are reduced in a fixed order, so a seed gives
//!   the same image on any thread count.
//! - **Distributed** ([`crate::cluster`], `mpirun`): rank `r` of `K` holds
//!   the tiles of rows `⌊rH/K⌋..⌊(r+1)H/K⌋` (a contiguous block, so only
//!   the blocks' edges pair across ranks), starts and steps them, and makes
//!   the exchanges among them. A vertical pair across two blocks is
//!   decided by the rank of its upper tile, with that tile's stream, once
//!   the ranks have all-gathered the two boundary rows' chain states; the
//!   lower tile's rank evaluates the upper state in its tile and applies
//!   the decision (`r` and the outcome, a second all-gather), so both tiles
//!   end as one process leaves them (`Sampler::cross_exchange`). The global
//!   start-up (`init=global`) runs on every rank. At the end rank 0 gathers
//!   every tile's sums, steps and chain statistics, aligns and develops the
//!   image: the single process's for any number of ranks. The ranks agree
//!   (an all-gather of a flag) before every iteration and every vertical
//!   exchange round whether any is stopped. No snapshots on a cluster (a
//!   develop needs every tile); the exchange statistics are summed per rank,
//!   so `mean_alpha` may differ from one process's in the last bits.

mod resume;

use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings};
use crate::cluster::Parcel;
use crate::deadline::Deadline;
use crate::film::Filter;
use crate::guiding::ExactRecords;
use crate::integrators::bdpt::{Bdpt, MisHeuristic};
use crate::integrators::guided::{GuidedSettings, RecordSink, agreed_iteration, next_iteration};
use crate::integrators::mcmc_pg::{ProgressOnly, TrainingMode};
use crate::integrators::mmlt::MAX_DEPTH as MMLT_MAX_DEPTH;
use crate::integrators::pt::PathTracer;
use crate::markov::CHECKPOINT_EVERY;
use crate::observer::Observer;
use crate::pss::{LARGE_STEP_COMPONENT, Mutation, MutationParams, SmallStepLaw};
use crate::scene::Scene;
use crate::settings::check;
use crate::smcmc::bdpt_shift::BdptShift;
use crate::smcmc::global_init::{GlobalInit, Visits};
use crate::smcmc::guided_shift::GuidedShift;
use crate::smcmc::mmlt_shift::MmltShift;
use crate::smcmc::random_replay::RandomReplay;
use crate::smcmc::rbdpt_shift::RbdptShift;
use crate::smcmc::{
    AlignmentChannels, FilterSplat, MAX_TILE_PIXELS, TileShape, TileShift, TileSums, TileTarget,
    TileValues, Tiling, accumulate, develop,
};
use mcmc_core::chain::Chain;
use mcmc_core::kernel::{Kernel, Mixture};
use mcmc_core::mh::{MetropolisHastings, accept_probability};
use mcmc_core::replica::swap_log_acceptance;
use mcmc_core::rng::{ChainRng, splitmix64, stream_rng, uniform};
use mcmc_core::sample::Sample;
use mcmc_core::space::TorusPoint;
use mcmc_core::stats::ChainStatistics;
use rayon::prelude::*;
use serde_json::{Value, json};
use std::collections::HashMap;
use std::ops::{AddAssign, Range};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

crate::choice! {
    /// The shift operator that evaluates a tile from one state.
    pub enum SmcmcShift {
        /// Random replay over the path tracer (same numbers, pixel moved).
        Rr = "rr",
        /// BDPT with one light subpath shared by the tile, t ≥ 2, MIS renormalised.
        Bdpt = "bdpt",
        /// MMLT shift, uniform technique pmf.
        Ummlt = "ummlt",
        /// MMLT shift, technique pmf ∝ s + 1.
        Lmmlt = "lmmlt",
        /// MMLT shift, technique pmf ∝ (s + 1)².
        Qmmlt = "qmmlt",
        /// MMLT shift, technique pmf ∝ (s + 1)³.
        Cmmlt = "cmmlt",
        /// Random-strategy BDPT: the bdpt shift with one uniform technique per path length.
        Rbdpt = "rbdpt",
        /// Random replay over the guided path tracer with an SD-tree trained first (SMCMC-PG).
        Guided = "guided",
    }
}

impl SmcmcShift {
    /// The exponent `n` of an MMLT shift's technique pmf `∝ (s + 1)^n`.
    pub fn technique_exponent(self) -> Option<u32> {
        match self {
            SmcmcShift::Ummlt => Some(0),
            SmcmcShift::Lmmlt => Some(1),
            SmcmcShift::Qmmlt => Some(2),
            SmcmcShift::Cmmlt => Some(3),
            SmcmcShift::Rr | SmcmcShift::Bdpt | SmcmcShift::Rbdpt | SmcmcShift::Guided => None,
        }
    }

    /// Whether the shift needs a finite `max_depth` (it draws per length).
    pub fn needs_finite_depth(self) -> bool {
        self.technique_exponent().is_some() || self == SmcmcShift::Rbdpt
    }
}

crate::choice! {
    /// How the tiles' chains find their first lit state (spec §8.7).
    pub enum SmcmcInit {
        /// `init_candidates` uniform states per tile, one resampled.
        Naive = "naive",
        /// Global PSSMLT chains over the film hand their states to the tiles they visit.
        Global = "global",
    }
}

/// Jacobi sweeps of the tile alignment by default (the thesis's 200), and
/// the sweeps a develop runs even past the run's end (stop flag or
/// deadline), where it stops larger counts: what a run with the default
/// always spent there.
pub const DEFAULT_SOLVER_ITERATIONS: usize = 200;

/// SMCMC's default mutation: Hachisuka and Jensen's adaptive small step
/// (`small_step=adaptive`) instead of the fixed Kelemen step `pssmlt` and
/// `mmlt` share (1/1024 to 1/64), large steps as theirs. A tile chain's
/// target is five pixels wide, and the fixed step is accepted 55–96% of the
/// time and barely moves the chain; the adaptive step settles each tile
/// near 0.234 and lowered the relMSE at equal work on `door-ajar`,
/// `interior-window` and the glossy/glass box, where a fixed 4× larger
/// Kelemen range was worse on one scene (docs/smcmc.md "Session 25").
pub fn smcmc_mutation() -> MutationParams {
    MutationParams {
        small_step: SmallStepLaw::Adaptive,
        ..MutationParams::default()
    }
}

crate::settings! {
    /// Stratified MCMC settings (defaults from spec seed003 §13).
    pub struct Smcmc {
        /// Shift operator: rr (random replay over pt), bdpt (shared light subpath, t ≥ 2), the MMLT shifts ummlt, lmmlt, qmmlt, cmmlt (one uniform length, one technique ∝ (s+1)^n, n = 0..3), rbdpt (bdpt with one uniform technique per length), or guided (random replay over the guided tracer, SD-tree trained first).
        pub shift: SmcmcShift = SmcmcShift::Rr;
        /// Tile shape: plus (the five-pixel t shape) or square (3×3).
        pub tile: TileShape = TileShape::Plus;
        /// Replica exchange between neighbouring tiles.
        pub exchange: bool = true;
        /// Iterations between two exchange rounds (2: every other iteration).
        pub exchange_every: u32 = 2, check check::positive_count;
        /// Weight α of the large-step estimate in the tile alignment (Eq. 3.38); 0.3 since session 28 (Gruson's code: 0.05), measured better on three scenes.
        pub alpha: f64 = 0.3, check check::positive;
        /// What the tile alignment solves on: rgb (one solve per colour channel, as Gruson's code; the default since session 32: luminance's one b_s for all channels moved energy between colours, −0.7% in blue on the glossy box) or luminance.
        pub alignment_channels: AlignmentChannels = AlignmentChannels::Rgb;
        /// Jacobi sweeps of the tile alignment (the thesis's 200).
        pub solver_iterations: usize = DEFAULT_SOLVER_ITERATIONS;
        /// Uniform candidates per tile at start-up (the start state is resampled from them).
        pub init_candidates: usize = 16, check check::count;
        /// Start-up: naive (per-tile uniform candidates) or global (global chains; tiles they miss then draw init_candidates).
        pub init: SmcmcInit = SmcmcInit::Naive;
        /// Global start-up: number of global chains.
        pub init_chains: usize = 8, check check::count;
        /// Global start-up: uniform states of the bootstrap population the chains start from.
        pub init_bootstrap: usize = 10000, check check::count;
        /// Global start-up: global mutations per pixel (all chains together).
        pub init_mutations: f64 = 4.0, check check::positive;
        /// Guided shift: share of the budget (iterations as samples per pixel, or time) spent training the SD-tree by guided path tracing, in (0, 1).
        pub guide_share: f64 = 0.125, check check_guide_share;
        /// Guided shift: next-event estimation in the guided tracer (the thesis's has none).
        pub guide_nee: bool = false;
        /// Guided shift: pretrained (guided path tracing trains the SD-tree, then the tiles run with it frozen) or online (Alg. 10: iterations of doubling length from 32 train it from the tiles' own paths; the last makes the image).
        pub guide_training: TrainingMode = TrainingMode::Pretrained;
        /// Iterations, each one mutation of every tile (auto: 100, or until the time budget is spent).
        pub mutations_per_pixel: Option<u64> = None, check check::auto_or_at_least_one;
        flatten {
            /// Path depth.
            pub depth: DepthParams = DepthParams::default();
            /// The mutation (its own small-step default, [`smcmc_mutation`]).
            pub mutation: MutationParams = smcmc_mutation();
        }
    }
}

impl IntegratorSettings for Smcmc {
    const NAME: &'static str = "smcmc";
    const DESCRIPTION: &'static str = "Stratified MCMC (Gruson et al. 2020): one chain per pixel on a tile, random replay, BDPT, rBDPT, MMLT or guided shifts, tile exchange and alignment.";

    fn validate(&self) -> Result<(), String> {
        if self.shift.needs_finite_depth() && !(1..=MMLT_MAX_DEPTH).contains(&self.depth.limit()) {
            return Err(format!(
                "smcmc: shift={} needs a finite max_depth from 1 to {MMLT_MAX_DEPTH} (give --max-depth)",
                self.shift.name()
            ));
        }
        self.mutation.mutation().map(|_| ())
    }

    fn planned_samples(&self, scene: &Scene, run: &RunSettings) -> Option<u64> {
        let pixels = u64::from(scene.film.width) * u64::from(scene.film.height);
        self.iterations(run).map(|m| m * pixels)
    }

    fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError> {
        let mutation = self.mutation.mutation().map_err(RenderError::Invalid)?;
        let pt = PathTracer {
            max_depth: self.depth.limit(),
            rr_depth: self.depth.rr_depth,
        };
        let bdpt = Bdpt {
            max_depth: pt.max_depth,
            rr_depth: pt.rr_depth,
            heuristic: MisHeuristic::Power,
        };
        IntegratorSettings::validate(self).map_err(RenderError::Invalid)?;
        if let Some(exponent) = self.shift.technique_exponent() {
            let shift = MmltShift { bdpt, exponent };
            return self.run(scene, &shift, &mutation, run, stop, observer);
        }
        if self.shift == SmcmcShift::Guided {
            return match self.guide_training {
                TrainingMode::Pretrained => {
                    self.render_guided(scene, &mutation, run, stop, observer)
                }
                TrainingMode::Online => {
                    self.render_guided_online(scene, &mutation, run, stop, observer)
                }
            };
        }
        let bdpt = BdptShift { bdpt };
        match self.shift {
            SmcmcShift::Rr => self.run(scene, &RandomReplay { pt }, &mutation, run, stop, observer),
            SmcmcShift::Rbdpt => {
                self.run(scene, &RbdptShift { bdpt }, &mutation, run, stop, observer)
            }
            _ => self.run(scene, &bdpt, &mutation, run, stop, observer),
        }
    }
}

/// `share ∈ (0, 1)`.
fn check_guide_share(v: &f64) -> Result<(), String> {
    if *v > 0.0 && *v < 1.0 {
        Ok(())
    } else {
        Err("must lie in (0, 1)".into())
    }
}

type TileKernel = Mixture<TorusPoint, TileValues>;
type TileChain =
    Chain<TorusPoint, TileValues, MetropolisHastings<TileKernel, TorusPoint, TileValues>>;

/// One tile's chain (once started), streams and sums.
struct Tile {
    chain: Option<TileChain>,
    /// Seed of the tile's streams: 0 for the chain, `1 + k` for its `k`-th
    /// uniform draw.
    seed: u64,
    draws: u64,
    /// Iterations this tile took part in (a stop can end an iteration
    /// before every tile has stepped).
    steps: u64,
    sums: TileSums,
}

/// Exchange counts of a round.
#[derive(Clone, Copy, Debug, Default)]
struct ExchangeCounts {
    attempts: u64,
    accepted: u64,
    alpha_sum: f64,
    copies: u64,
    /// Whether a stop left pairs of the round out (its iteration is then
    /// not whole, and not checkpointed).
    cut: bool,
}

impl AddAssign for ExchangeCounts {
    fn add_assign(&mut self, o: Self) {
        self.attempts += o.attempts;
        self.accepted += o.accepted;
        self.alpha_sum += o.alpha_sum;
        self.copies += o.copies;
        self.cut |= o.cut;
    }
}

/// Stream offset of the tiles' seeds.
const TILE_STREAM: u64 = 1 << 44;
/// Start-up draws per tile in one round over the tiles
/// (`Sampler::start_tiles`): a round of a 64×48 film is about 25 000 path
/// samples, tens of milliseconds on two cores.
const START_ROUND: usize = 8;
/// Stream offset from which the online guided iterations' seeds are
/// derived (apart from the tiles' own).
const GUIDE_ONLINE_STREAM: u64 = 1 << 46;
/// Mutations per pixel of the first online guided iteration (Alg. 10's
/// `samplesPerIt = 32`); each next one is twice as long.
const GUIDE_ONLINE_FIRST: u64 = 32;

/// The seed of tile `s`'s streams in a run of `seed`.
fn tile_seed(seed: u64, s: usize) -> u64 {
    splitmix64(seed ^ splitmix64(TILE_STREAM + s as u64))
}

/// The tile sampler of one run.
struct Sampler<'a, S> {
    scene: &'a Scene,
    shift: &'a S,
    tiling: Tiling,
    mutation: Mutation,
    /// The scene's filter, unless it is the box.
    filter: Option<FilterSplat>,
}

impl<S: TileShift> Sampler<'_, S> {
    fn target(&self, s: usize) -> TileTarget<'_, S> {
        TileTarget {
            scene: self.scene,
            shift: self.shift,
            pixels: self.tiling.slot_pixels(s),
            slots: self.tiling.slots(),
        }
    }

    /// A chain of tile `s` started at `current` (which carries light).
    fn start_chain(&self, tile: &Tile, current: Sample<TorusPoint, TileValues>) -> TileChain {
        let kernel = self
            .mutation
            .kernel()
            .expect("the mutation was checked by validate");
        Chain::from_sample(
            current,
            MetropolisHastings::new(kernel),
            stream_rng(tile.seed, 0),
        )
        .expect("a state with light starts a chain")
    }

    /// Adds the mean-value splat `weight · f_q(values)` to tile `s`'s sums.
    fn splat(&self, s: usize, sums: &mut TileSums, values: &TileValues, weight: f64) {
        let pixels = self.tiling.slot_pixels(s);
        let slots = self.tiling.slots();
        sums.splat(values, weight, &pixels[..slots], self.filter.as_ref());
    }

    /// The next uniform draw of `tile`, evaluated, counted in its
    /// large-step sums.
    fn draw(&self, s: usize, tile: &mut Tile) -> Sample<TorusPoint, TileValues> {
        tile.draws += 1;
        let x = Sample::evaluate(
            &self.target(s),
            TorusPoint::fresh(stream_rng(tile.seed, tile.draws)),
        );
        tile.sums.large_samples += 1;
        if !x.log_density.is_nan() {
            accumulate(&mut tile.sums.large, &x.payload, 1.0);
        }
        x
    }

    /// Tiles `tiles` started: each from the first state of the global
    /// start-up `visits` (its own pixel first, then the others in slot
    /// order) that carries light in the tile; failing that, with
    /// `candidates` uniform draws, started from one resampled `∝ π̃_s` if
    /// any carries light.
    ///
    /// The draws go round the tiles, [`START_ROUND`] per tile at a time,
    /// so a stop (`halt`) leaves every tile with about as many as the
    /// others: the image of a run stopped in its start-up is then `Ĩ` from
    /// the draws made, over the whole film (drawn tile after tile, a
    /// Ctrl-C at 3 s had left 99% of it black, session 34). A tile keeps
    /// its draws' weights only, 8 B each, and evaluates the one it picks
    /// again (a draw is its stream's: the same state); so the pick, and the
    /// image of an uncut run, are those of drawing the tile's candidates
    /// at once.
    fn start_tiles(
        &self,
        seed: u64,
        tiles: Range<usize>,
        candidates: usize,
        visits: Option<&Visits>,
        halt: &(dyn Fn() -> bool + Sync),
    ) -> Vec<Tile> {
        let mut started: Vec<(usize, Tile, Vec<f64>)> = tiles
            .into_par_iter()
            .map(|s| (s, self.visited_tile(seed, s, visits, halt), Vec::new()))
            .collect();
        let weight = |x: &Sample<TorusPoint, TileValues>| {
            if x.log_density.is_finite() {
                x.payload.total
            } else {
                0.0
            }
        };
        // A stop during start-up leaves the remaining candidates undrawn.
        let mut drawn = 0;
        while drawn < candidates && !halt() {
            let round = START_ROUND.min(candidates - drawn);
            started
                .par_iter_mut()
                .filter(|(_, tile, _)| tile.chain.is_none())
                .for_each(|(s, tile, weights)| {
                    for _ in 0..round {
                        if halt() {
                            break;
                        }
                        weights.push(weight(&self.draw(*s, tile)));
                    }
                });
            drawn += round;
        }
        started
            .into_par_iter()
            .map(|(s, mut tile, weights)| {
                let total: f64 = weights.iter().sum();
                if tile.chain.is_none() && total > 0.0 {
                    let mut rng: ChainRng = stream_rng(tile.seed, u64::MAX);
                    let mut u = uniform(&mut rng) * total;
                    let mut pick = None;
                    for (k, &w) in weights.iter().enumerate() {
                        if w > 0.0 {
                            pick = Some(k);
                            if u < w {
                                break;
                            }
                            u -= w;
                        }
                    }
                    // Draw `k` of the tile's candidates was its stream
                    // `1 + k` (`draw`; `visited_tile` draws none).
                    let k = pick.expect("a candidate carries light") as u64;
                    let point = TorusPoint::fresh(stream_rng(tile.seed, 1 + k));
                    let start = Sample::evaluate(&self.target(s), point);
                    tile.chain = Some(self.start_chain(&tile, start));
                    tile.sums.active = true;
                }
                tile
            })
            .collect()
    }

    /// Tile `s` with no draw yet, started from the first state of the
    /// global start-up `visits` that carries light in it, if any.
    fn visited_tile(
        &self,
        seed: u64,
        s: usize,
        visits: Option<&Visits>,
        halt: &dyn Fn() -> bool,
    ) -> Tile {
        let mut tile = Tile {
            chain: None,
            seed: tile_seed(seed, s),
            draws: 0,
            steps: 0,
            sums: TileSums::new(self.filter.as_ref(), self.tiling.slots()),
        };
        if let Some(v) = visits {
            for (_, p) in self.tiling.pixels(s) {
                if halt() {
                    return tile;
                }
                if let Some(state) = v.state(p, stream_rng(tile.seed, u64::MAX - 1)) {
                    let x = Sample::evaluate(&self.target(s), state);
                    if x.log_density.is_finite() {
                        tile.chain = Some(self.start_chain(&tile, x));
                        tile.sums.active = true;
                        return tile;
                    }
                }
            }
        }
        tile
    }

    /// One mutation of tile `s` (or one more uniform draw if it has not
    /// started), splatted with the expected-value weights.
    fn step(&self, s: usize, tile: &mut Tile) {
        tile.steps += 1;
        let target = self.target(s);
        let Some(chain) = &mut tile.chain else {
            let x = self.draw(s, tile);
            if x.log_density.is_finite() {
                tile.chain = Some(self.start_chain(tile, x));
                tile.sums.active = true;
            }
            return;
        };
        let sums = &mut tile.sums;
        chain.step_with(&target, |tr| {
            let a = tr.alpha;
            if let Some(p) = tr.proposal {
                if tr.component == LARGE_STEP_COMPONENT {
                    sums.large_samples += 1;
                    if !p.log_density.is_nan() {
                        accumulate(&mut sums.large, &p.payload, 1.0);
                    }
                }
                if a > 0.0 {
                    self.splat(s, sums, &p.payload, a / p.payload.total);
                }
            }
            if a < 1.0 {
                let current = &tr.current.payload;
                self.splat(s, sums, current, (1.0 - a) / current.total);
            }
            sums.samples += 1;
        });
    }

    /// A replica exchange between tiles `s` and `t` (§8.6), or the copy of
    /// a running tile's state into one that has not started.
    fn exchange_pair(&self, s: usize, a: &mut Tile, t: usize, b: &mut Tile) -> ExchangeCounts {
        let mut counts = ExchangeCounts::default();
        match (a.chain.is_some(), b.chain.is_some()) {
            (true, true) => {
                let (ca, cb) = (a.chain.as_mut().unwrap(), b.chain.as_mut().unwrap());
                // π̃_s(u_t) and π̃_t(u_s).
                let xa = self.swapped(s, t, cb.current());
                let xb = self.swapped(t, s, ca.current());
                let log_r = swap_log_acceptance(
                    ca.current().log_density,
                    cb.current().log_density,
                    xa.log_density,
                    xb.log_density,
                );
                let (r, accepted) = accept_probability(log_r, ca.rng_mut());
                for (tile, sums, current, swapped) in [
                    (s, &mut a.sums, ca.current(), &xa),
                    (t, &mut b.sums, cb.current(), &xb),
                ] {
                    self.swap_splat(tile, sums, current, swapped, r);
                }
                if accepted {
                    ca.parts_mut().current = xa;
                    cb.parts_mut().current = xb;
                }
                counts.attempts = 1;
                counts.accepted = u64::from(accepted);
                counts.alpha_sum = r;
            }
            (true, false) => counts.copies = self.copy_into(running(a), t, b),
            (false, true) => counts.copies = self.copy_into(running(b), s, a),
            (false, false) => {}
        }
        counts
    }

    /// Tile `t`'s current state `from` evaluated in tile `s`, reusing its
    /// values at the pixels the two tiles share (two of the five of
    /// neighbouring plus tiles, six of nine of square ones): the same
    /// evaluation as tracing every slot ([`TileTarget::evaluate_known`]),
    /// for fewer paths per exchange.
    fn swapped(
        &self,
        s: usize,
        t: usize,
        from: &Sample<TorusPoint, TileValues>,
    ) -> Sample<TorusPoint, TileValues> {
        let slots = self.tiling.slots();
        let (ps, pt) = (self.tiling.slot_pixels(s), self.tiling.slot_pixels(t));
        let known = std::array::from_fn(|k| {
            let p = ps[..slots].get(k).copied().flatten()?;
            let j = pt[..slots].iter().position(|&q| q == Some(p))?;
            Some(from.payload.f[j])
        });
        let state = from.state.clone();
        let e = self.target(s).evaluate_known(&state, &known);
        Sample {
            state,
            log_density: e.log_density,
            payload: e.payload,
        }
    }

    /// The splats of one side of an exchange with acceptance probability
    /// `r` into tile `tile`'s `sums`: the `swapped` state (the partner's,
    /// evaluated in this tile) with weight `r`, its `current` one with
    /// `1 − r`.
    fn swap_splat(
        &self,
        tile: usize,
        sums: &mut TileSums,
        current: &Sample<TorusPoint, TileValues>,
        swapped: &Sample<TorusPoint, TileValues>,
        r: f64,
    ) {
        if r > 0.0 {
            self.splat(tile, sums, &swapped.payload, r / swapped.payload.total);
        }
        if r < 1.0 {
            let current = &current.payload;
            self.splat(tile, sums, current, (1.0 - r) / current.total);
        }
        sums.samples += 1;
    }

    /// Starts tile `t` at `state` (a running neighbour's) if it carries
    /// light there.
    fn copy_into(&self, state: &TorusPoint, t: usize, to: &mut Tile) -> u64 {
        let x = Sample::evaluate(&self.target(t), state.clone());
        if x.log_density.is_finite() {
            to.chain = Some(self.start_chain(to, x));
            to.sums.active = true;
            1
        } else {
            0
        }
    }

    /// Exchange round `round` among `tiles`, the tiles of whole rows from
    /// row `row0` on: horizontal pairs on even rounds, vertical on odd ones,
    /// from even columns/rows on rounds `≡ 0, 1 (mod 4)`. Pairs left when
    /// `halt()` turns true are skipped. A vertical pair whose lower row is
    /// not among these rows is another rank's ([`Sampler::cross_exchange`]).
    fn exchange_round(
        &self,
        tiles: &mut [Tile],
        row0: usize,
        round: u64,
        halt: &(dyn Fn() -> bool + Sync),
    ) -> ExchangeCounts {
        let w = self.tiling.width as usize;
        let parity = ((round / 2) % 2) as usize;
        let sum = |a: ExchangeCounts, b: ExchangeCounts| {
            let mut a = a;
            a += b;
            a
        };
        if round.is_multiple_of(2) {
            tiles
                .par_chunks_mut(w)
                .enumerate()
                .map(|(i, row)| {
                    let y = row0 + i;
                    let mut c = ExchangeCounts::default();
                    let mut x = parity;
                    while x + 1 < w && !halt() {
                        let (left, right) = row.split_at_mut(x + 1);
                        c += self.exchange_pair(
                            y * w + x,
                            &mut left[x],
                            y * w + x + 1,
                            &mut right[0],
                        );
                        x += 2;
                    }
                    c.cut |= x + 1 < w;
                    c
                })
                .collect::<Vec<_>>()
                .into_iter()
                .fold(ExchangeCounts::default(), sum)
        } else {
            // The first of these rows `≡ parity (mod 2)`.
            let skip = (parity + row0) % 2;
            let first = (skip * w).min(tiles.len());
            tiles[first..]
                .par_chunks_mut(2 * w)
                .enumerate()
                .map(|(i, rows)| {
                    let mut c = ExchangeCounts::default();
                    if rows.len() < 2 * w {
                        return c;
                    }
                    let y = row0 + skip + 2 * i;
                    let (top, bottom) = rows.split_at_mut(w);
                    let mut done = 0;
                    for x in (0..w).take_while(|_| !halt()) {
                        c += self.exchange_pair(
                            y * w + x,
                            &mut top[x],
                            (y + 1) * w + x,
                            &mut bottom[x],
                        );
                        done += 1;
                    }
                    c.cut |= done < w;
                    c
                })
                .collect::<Vec<_>>()
                .into_iter()
                .fold(ExchangeCounts::default(), sum)
        }
    }

    /// The vertical pairs of exchange round `round` whose tiles two ranks
    /// hold: this rank's `tiles` are those of `rows`; its last row pairs
    /// with the next rank's first, its first with the previous rank's
    /// last, when the round pairs them. Each rank sends its rows' chain
    /// states (an all-gather of words); the rank of the upper tile decides
    /// the exchange with its tile's stream, as [`Sampler::exchange_pair`]
    /// does, and sends `r` and the outcome (a second all-gather); the rank
    /// of the lower tile evaluates the upper state in its tile and splats
    /// as the pair does. So both tiles end as one process leaves them. A
    /// copy into a tile not started is made by that tile's rank. Skipped on
    /// every rank when any rank is stopped. Collective on a cluster: every
    /// rank calls it every round; in one process there is no such pair.
    fn cross_exchange(
        &self,
        tiles: &mut [Tile],
        rows: &Range<usize>,
        round: u64,
        halt: &dyn Fn() -> bool,
    ) -> ExchangeCounts {
        let mut counts = ExchangeCounts::default();
        let (w, h) = (self.tiling.width as usize, self.tiling.height as usize);
        let parity = ((round / 2) % 2) as usize;
        if round.is_multiple_of(2) {
            return counts;
        }
        // Rows `y ≡ parity` pair with `y + 1`.
        let upper = (!rows.is_empty() && rows.end < h && (rows.end - 1) % 2 == parity)
            .then(|| rows.end - 1);
        let lower = (!rows.is_empty() && rows.start > 0 && (rows.start - 1) % 2 == parity)
            .then_some(rows.start);
        if crate::cluster::any_rank(halt()) {
            counts.cut = upper.is_some() || lower.is_some();
            return counts;
        }
        let at = |y: usize, x: usize| (y - rows.start) * w + x;
        // Every boundary tile: its index, whether it runs, then its current
        // `ln π̃` and state.
        let mut words = Vec::new();
        for y in upper.into_iter().chain(lower) {
            for x in 0..w {
                words.push((y * w + x) as u64);
                match &tiles[at(y, x)].chain {
                    Some(c) => {
                        words.extend([1, c.current().log_density.to_bits()]);
                        c.state().to_words(&mut words);
                    }
                    None => words.push(0),
                }
            }
        }
        let remote = boundary_states(&crate::cluster::all_gather_words(words));
        let partner = |t: usize| {
            remote
                .get(&t)
                .expect("the neighbouring rank sends its boundary row")
        };
        // Upper tiles: the exchange decided here.
        let mut decisions = Vec::new();
        if let Some(y) = upper {
            for x in 0..w {
                let (s, t) = (y * w + x, (y + 1) * w + x);
                let a = &mut tiles[at(y, x)];
                match (a.chain.is_some(), partner(t)) {
                    (true, Some((log_b, state_b))) => {
                        let Tile { chain, sums, .. } = a;
                        let ca = chain.as_mut().expect("running");
                        // π̃_s(u_t) and π̃_t(u_s).
                        let xa = Sample::evaluate(&self.target(s), state_b.clone());
                        let xb = Sample::evaluate(&self.target(t), ca.state().clone());
                        let log_r = swap_log_acceptance(
                            ca.current().log_density,
                            *log_b,
                            xa.log_density,
                            xb.log_density,
                        );
                        let (r, accepted) = accept_probability(log_r, ca.rng_mut());
                        self.swap_splat(s, sums, ca.current(), &xa, r);
                        if accepted {
                            ca.parts_mut().current = xa;
                        }
                        counts.attempts += 1;
                        counts.accepted += u64::from(accepted);
                        counts.alpha_sum += r;
                        decisions.extend([s as u64, r.to_bits(), u64::from(accepted)]);
                    }
                    (false, Some((_, state_b))) => counts.copies += self.copy_into(state_b, s, a),
                    _ => {}
                }
            }
        }
        let decisions = crate::cluster::all_gather_words(decisions);
        let decided: HashMap<usize, (f64, bool)> = (decisions.chunks_exact(3))
            .map(|d| (d[0] as usize, (f64::from_bits(d[1]), d[2] == 1)))
            .collect();
        // Lower tiles: the upper rank's decision applied here.
        if let Some(y) = lower {
            for x in 0..w {
                let (s, t) = ((y - 1) * w + x, y * w + x);
                let b = &mut tiles[at(y, x)];
                match (partner(s), b.chain.is_some()) {
                    (Some((_, state_a)), true) => {
                        let &(r, accepted) =
                            decided.get(&s).expect("the upper rank decides every pair");
                        let Tile { chain, sums, .. } = b;
                        let cb = chain.as_mut().expect("running");
                        let xb = Sample::evaluate(&self.target(t), state_a.clone());
                        self.swap_splat(t, sums, cb.current(), &xb, r);
                        if accepted {
                            cb.parts_mut().current = xb;
                        }
                    }
                    (Some((_, state_a)), false) => counts.copies += self.copy_into(state_a, t, b),
                    _ => {}
                }
            }
        }
        counts
    }
}

/// The state of a running tile's chain.
fn running(tile: &Tile) -> &TorusPoint {
    tile.chain.as_ref().expect("running").state()
}

/// The boundary tiles [`Sampler::cross_exchange`]'s words describe: tile
/// index → its current `ln π̃` and state, `None` when it has not started.
fn boundary_states(words: &[u64]) -> HashMap<usize, Option<(f64, TorusPoint)>> {
    let mut input = words;
    let mut out = HashMap::new();
    // Every rank runs the same binary (checked at start-up): words that do
    // not decode are a bug, not an input error.
    while let Some((&s, rest)) = input.split_first() {
        let (&started, rest) = rest.split_first().expect("a boundary tile's flag");
        input = rest;
        let state = (started == 1).then(|| {
            let (&log_density, rest) = input.split_first().expect("a boundary tile's ln π");
            input = rest;
            let point = TorusPoint::from_words(&mut input).expect("a boundary tile's state");
            (f64::from_bits(log_density), point)
        });
        out.insert(s as usize, state);
    }
    out
}

/// The rows of a `height`-row image this process renders: a contiguous
/// block per rank (so only the blocks' edges pair across ranks), all of
/// them in one process.
fn own_rows(height: usize) -> Range<usize> {
    let (rank, size) = crate::cluster::current().map_or((0, 1), |c| (c.rank(), c.size()));
    height * rank / size..height * (rank + 1) / size
}

/// What the tiles hand to the image and the statistics at the end of a
/// run, in tile order.
struct TileResults {
    sums: Vec<TileSums>,
    steps: Vec<u64>,
    /// The chains' statistics (`None`: the tile never started).
    stats: Vec<Option<ChainStatistics>>,
}

impl TileResults {
    /// The results of `tiles` (tiles `first..` of the image): in one
    /// process, theirs; on a cluster every rank's, on rank 0 (`None` on the
    /// other ranks), their chains' component names taken from `names`.
    /// Collective on a cluster.
    fn gather(
        tiles: Vec<Tile>,
        first: usize,
        names: &[String],
        filter: &Arc<Filter>,
    ) -> Option<TileResults> {
        let Some(cluster) = crate::cluster::current() else {
            let mut out = TileResults {
                sums: Vec::with_capacity(tiles.len()),
                steps: Vec::with_capacity(tiles.len()),
                stats: Vec::with_capacity(tiles.len()),
            };
            for t in tiles {
                out.sums.push(t.sums);
                out.steps.push(t.steps);
                out.stats.push(t.chain.map(|c| c.stats().clone()));
            }
            return Some(out);
        };
        let parcels = (tiles.into_iter().enumerate())
            .map(|(i, t)| {
                let sums = &t.sums;
                let mut numbers = sums.g.as_flattened().to_vec();
                numbers.extend(sums.large.as_flattened());
                numbers.extend(sums.filtered.as_flattened());
                let stats = t.chain.as_ref().map(|c| c.stats());
                let mut counts = vec![
                    sums.samples,
                    sums.large_samples,
                    u64::from(sums.active),
                    t.steps,
                    u64::from(stats.is_some()),
                ];
                if let Some(stats) = stats {
                    crate::markov::checkpoint::stats_words(stats, &mut counts);
                }
                Parcel {
                    unit: first + i,
                    films: Vec::new(),
                    numbers,
                    counts,
                }
            })
            .collect();
        let all = cluster.gather(parcels, filter)?;
        let mut out = TileResults {
            sums: Vec::with_capacity(all.len()),
            steps: Vec::with_capacity(all.len()),
            stats: Vec::with_capacity(all.len()),
        };
        for p in all {
            // g, large, then the spread sums, three numbers a slot or cell.
            let n = &p.numbers;
            let triple = |i: usize| [n[3 * i], n[3 * i + 1], n[3 * i + 2]];
            let mut sums = TileSums {
                g: std::array::from_fn(triple),
                large: std::array::from_fn(|k| triple(MAX_TILE_PIXELS + k)),
                filtered: (2 * MAX_TILE_PIXELS..n.len() / 3).map(triple).collect(),
                ..TileSums::default()
            };
            let mut words = p.counts.iter().copied();
            let mut next = || {
                words
                    .next()
                    .ok_or_else(|| "a tile's counts are cut".to_string())
            };
            // Every rank runs the same binary: a parcel that does not
            // decode is a bug, not an input error.
            let (steps, stats) = read_tile_counts(&mut next, &mut sums, names)
                .unwrap_or_else(|e| panic!("a rank's tile results: {e}"));
            out.sums.push(sums);
            out.steps.push(steps);
            out.stats.push(stats);
        }
        Some(out)
    }
}

/// A tile's counters as [`TileResults::gather`] sends them, read into
/// `sums`: its transition and uniform-sample counts and whether it runs;
/// returns its steps and its chain's statistics (components named by
/// `names`).
fn read_tile_counts(
    next: &mut impl FnMut() -> Result<u64, String>,
    sums: &mut TileSums,
    names: &[String],
) -> Result<(u64, Option<ChainStatistics>), String> {
    sums.samples = next()?;
    sums.large_samples = next()?;
    sums.active = next()? == 1;
    let steps = next()?;
    if next()? == 0 {
        return Ok((steps, None));
    }
    let mut stats = crate::markov::checkpoint::stats_from_words(next)?;
    for (c, name) in stats.components.iter_mut().zip(names) {
        c.name.clone_from(name);
    }
    Ok((steps, Some(stats)))
}

impl Smcmc {
    /// Iterations under `run`: the setting, or 100 without a time budget;
    /// `None`: until the budget is spent.
    fn iterations(&self, run: &RunSettings) -> Option<u64> {
        match (self.mutations_per_pixel, run.time_budget) {
            (Some(m), _) => Some(m),
            (None, Some(_)) => None,
            (None, None) => Some(100),
        }
    }

    /// The guided shift: the SD-tree is trained by the `guided` integrator
    /// on its doubling schedule with `guide_share` of the budget (of the
    /// iterations, as samples per pixel; or of the time), every training
    /// iteration recording (the last included), then frozen for the tile
    /// chains, which get the rest of the time (all the iterations).
    fn render_guided(
        &self,
        scene: &Scene,
        mutation: &Mutation,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError> {
        let start = Instant::now();
        let guiding = self.guiding();
        // The training is not saved: a resumed run trains the tree again,
        // which gives the same tree only on a sample budget.
        if run.checkpoint.is_some() && self.iterations(run).is_none() {
            return Err(RenderError::Invalid(
                "--checkpoint: smcmc's guided shift needs mutations_per_pixel: a time budget alone trains its SD-tree by the clock, so a resumed run could not repeat it".into(),
            ));
        }
        let train_run = match self.iterations(run) {
            Some(m) => RunSettings {
                spp: Some(
                    ((m as f64 * self.guide_share).round() as u64).clamp(1, u64::from(u32::MAX))
                        as u32,
                ),
                time_budget: None,
                checkpoint: None,
                ..run.clone()
            },
            None => RunSettings {
                spp: None,
                time_budget: run.time_budget.map(|b| b.mul_f64(self.guide_share)),
                checkpoint: None,
                ..run.clone()
            },
        };
        let (trained, tree) =
            guiding.render_and_train(scene, &train_run, stop, &ProgressOnly(observer), true)?;
        let training_seconds = start.elapsed().as_secs_f64();
        let chains_run = RunSettings {
            time_budget: run.time_budget.map(|b| {
                b.saturating_sub(start.elapsed())
                    .max(std::time::Duration::from_millis(1))
            }),
            ..run.clone()
        };
        let shift = GuidedShift {
            tracer: guiding.tracer(),
            tree: &tree,
            sink: None,
        };
        let mut rendered = self.run(scene, &shift, mutation, &chains_run, stop, observer)?;
        let stat = |key: &str| trained.statistics.get(key).cloned().unwrap_or(Value::Null);
        rendered.statistics.insert(
            "guiding".into(),
            json!({
                "nee": self.guide_nee,
                "training_seconds": training_seconds,
                "training_spp_per_iteration": stat("spp_per_iteration"),
                "training_seconds_per_iteration": stat("seconds_per_iteration"),
                "tree_memory_bytes": tree.size().bytes,
                "tree": tree.size(),
            }),
        );
        rendered.seconds += training_seconds;
        rendered.interrupted |= trained.interrupted && stop.load(Ordering::Relaxed);
        rendered.summary = format!(
            "{}; SD-tree trained in {training_seconds:.2} s ({:.1} MB)",
            rendered.summary,
            tree.size().bytes as f64 / 1e6
        );
        Ok(rendered)
    }

    /// The guided tracer's settings of the guided shift.
    fn guiding(&self) -> GuidedSettings {
        GuidedSettings {
            nee: self.guide_nee,
            depth: self.depth.clone(),
            ..GuidedSettings::default()
        }
    }

    /// The guided shift trained online (Alg. 10, spec §11.4): iterations of
    /// doubling length from [`GUIDE_ONLINE_FIRST`] mutations per pixel (on
    /// the `guided` integrator's schedule, [`next_iteration`]), each a whole
    /// SMCMC run (its own start-up and seeds) over the current tree whose
    /// every traced path records into the tree's building half; the tree is
    /// updated between iterations and the last iteration (which does not
    /// record) makes the image. Module docs of [`crate::smcmc::guided_shift`]
    /// say why this is valid.
    fn render_guided_online(
        &self,
        scene: &Scene,
        mutation: &Mutation,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError> {
        if run.checkpoint.is_some() {
            return Err(RenderError::Invalid(
                "--checkpoint: smcmc's guided shift with guide_training=online is not checkpointed (its training iterations are not saved); use guide_training=pretrained".into(),
            ));
        }
        let cluster = crate::cluster::current().is_some();
        if cluster && self.init == SmcmcInit::Global {
            return Err(RenderError::Invalid(
                "smcmc: guide_training=online with init=global does not run on a cluster (every rank makes the global start-up, so its paths would train the tree once per rank); use init=naive".into(),
            ));
        }
        let start = Instant::now();
        let deadline = Deadline::new(start, run.time_budget);
        let guiding = self.guiding();
        let tracer = guiding.tracer();
        let mut tree = guiding.untrained_tree(scene);
        let budget = self.iterations(run);
        let mut phases: Vec<Value> = Vec::new();
        let mut previous: Option<Rendered> = None;
        let mut last_seconds = None;
        let (mut done, mut nominal) = (0u64, GUIDE_ONLINE_FIRST);
        for k in 1u32.. {
            let (mpp, last) = next_iteration(budget, done, nominal, deadline, last_seconds);
            let (mpp, last) = agreed_iteration(mpp, last);
            let iteration_start = Instant::now();
            let sink = (!last).then(RecordSink::new);
            let shift = GuidedShift {
                tracer,
                tree: &tree,
                sink: sink.as_ref(),
            };
            let settings = Smcmc {
                mutations_per_pixel: mpp,
                ..self.clone()
            };
            let iteration_run = RunSettings {
                seed: splitmix64(run.seed ^ splitmix64(GUIDE_ONLINE_STREAM + u64::from(k))),
                time_budget: deadline
                    .time_left()
                    .map(|left| left.max(std::time::Duration::from_millis(1))),
                ..run.clone()
            };
            let progress = ProgressOnly(observer);
            let shown: &dyn Observer = if last { observer } else { &progress };
            let rendered = settings.run(scene, &shift, mutation, &iteration_run, stop, shown)?;
            let seconds = iteration_start.elapsed().as_secs_f64();
            // Every rank's records (the sink exists in the same iterations
            // on every rank: `agreed_iteration`).
            let parts = sink.map(RecordSink::into_parts).unwrap_or_default();
            let acceptance = &rendered.statistics["acceptance_per_shift"]["guided"];
            phases.push(json!({
                "iteration": k,
                "mutations_per_pixel": rendered.statistics["iterations"],
                "seconds": seconds,
                "acceptance_large": acceptance["large"],
                "acceptance_small": acceptance["small"],
                "records": parts.iter().map(ExactRecords::len).sum::<u64>(),
                "tree_memory_bytes": tree.size().bytes,
            }));
            let interrupted = rendered.interrupted && !last;
            if last || interrupted {
                // A stopped iteration is the result if it holds at least
                // as many mutations as the one before.
                let keep = previous
                    .take()
                    .filter(|p| !last && p.samples > rendered.samples);
                let mut rendered = keep.unwrap_or(rendered);
                rendered.statistics.insert(
                    "guiding".into(),
                    json!({
                        "nee": self.guide_nee,
                        "training": "online",
                        "iterations": phases,
                        "tree_memory_bytes": tree.size().bytes,
                        "tree": tree.size(),
                    }),
                );
                rendered.seconds = start.elapsed().as_secs_f64();
                rendered.interrupted |= interrupted;
                rendered.summary = format!(
                    "{}; SD-tree trained online in {} iterations ({:.1} MB)",
                    rendered.summary,
                    k - 1,
                    tree.size().bytes as f64 / 1e6
                );
                return Ok(rendered);
            }
            tree.merge_exact(parts);
            tree.end_iteration(k, guiding.spatial_threshold, guiding.quadtree_threshold);
            previous = Some(rendered);
            last_seconds = Some(seconds);
            done += mpp.unwrap_or(0);
            nominal = nominal.saturating_mul(2);
        }
        unreachable!("the schedule ends")
    }

    fn run<S: TileShift>(
        &self,
        scene: &Scene,
        shift: &S,
        mutation: &Mutation,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError> {
        let start = Instant::now();
        let tiling = Tiling::new(scene.film.width, scene.film.height, self.tile);
        let n = tiling.tiles();
        let sampler = Sampler {
            scene,
            shift,
            tiling,
            mutation: *mutation,
            filter: FilterSplat::new(scene),
        };
        // Checked before every tile step, exchange pair and start-up
        // candidate, so a stop or the end of the time budget is seen within
        // one mutation's time, mid-iteration: each tile's histogram is
        // normalised by its own transition count, so tiles that took one
        // step fewer than their neighbours still give a valid estimate.
        let deadline = Deadline::new(start, run.time_budget);
        let halt = || stop.load(Ordering::Relaxed) || deadline.passed();
        // With a checkpoint the start-up is not cut by the time budget (a
        // resumed run makes the global start-up again for its statistics,
        // and a run whose tiles started short would be saved as such); a
        // stop still cuts it, and then nothing is saved.
        // The start-up stops at its share of the budget, as the Markov
        // driver's (`markov::STARTUP_SHARE`), so that the tiles get the
        // rest: at the whole budget a large `init_bootstrap` left them none
        // and the image black (session 33).
        let checkpointed = run.checkpoint.is_some();
        let startup_deadline = crate::markov::startup_end(start, run.time_budget);
        let startup_halt =
            || stop.load(Ordering::Relaxed) || (!checkpointed && startup_deadline.passed());
        // The tiles' start-up keeps every draw's weight until its tile
        // picks a start (`Sampler::start_tiles`): 8 B per candidate and
        // tile (a tile the global start-up starts draws none).
        let tiles = scene.film.width as u128 * scene.film.height as u128;
        crate::resources::check_memory(
            &format!(
                "smcmc: a start-up of {} candidates for each of {tiles} tiles",
                self.init_candidates
            ),
            tiles * self.init_candidates as u128 * 8,
        )
        .map_err(RenderError::Invalid)?;
        if self.init == SmcmcInit::Global {
            // The global start-up keeps one weight per bootstrap state and
            // one walk per chain (10^15 states aborted on an 8 PB
            // allocation); a walk is sized like the Markov driver's chains.
            let bytes = self.init_bootstrap as u128 * 8
                + self.init_chains as u128 * crate::markov::BYTES_PER_CHAIN;
            crate::resources::check_memory(
                &format!(
                    "smcmc: a global start-up of {} bootstrap states and {} chains",
                    self.init_bootstrap, self.init_chains
                ),
                bytes,
            )
            .map_err(RenderError::Invalid)?;
        }
        let visits = (self.init == SmcmcInit::Global).then(|| {
            GlobalInit {
                chains: self.init_chains,
                bootstrap: self.init_bootstrap,
                mutations_per_pixel: self.init_mutations,
            }
            .run(scene, shift, mutation, run.seed, &startup_halt)
        });
        // On a cluster this rank holds the tiles of a block of rows (module
        // docs), tiles `first..` of the image; in one process all of them.
        let cluster = crate::cluster::current();
        let rows = own_rows(scene.film.height as usize);
        let first = rows.start * scene.film.width as usize;
        let own_tiles = first..rows.end * scene.film.width as usize;
        let filter = Arc::new(Filter::new(
            scene.film.filter,
            scene.film.width,
            scene.film.height,
        ));
        let every = u64::from(self.exchange_every);
        let rounds_of = |iterations: u64| if self.exchange { iterations / every } else { 0 };
        let resumed = match &run.checkpoint {
            Some(ck) => (sampler.resume(ck, run.seed, own_tiles.clone(), &rounds_of))
                .map_err(RenderError::Invalid)?,
            None => None,
        };
        let resumed_from = resumed.as_ref().map(|(c, _)| c.iterations);
        let (mut counters, mut tiles) = match resumed {
            Some((counters, tiles)) => {
                observer.progress(tiles.iter().map(|t| t.steps).sum());
                (counters, tiles)
            }
            None => {
                let (n, v) = (self.init_candidates, visits.as_ref());
                let tiles = sampler.start_tiles(run.seed, own_tiles, n, v, &startup_halt);
                let started = tiles.iter().filter(|t| t.chain.is_some()).count() as u64;
                (
                    resume::Counters {
                        started_at_init: started,
                        ..Default::default()
                    },
                    tiles,
                )
            }
        };
        // A start-up cut by a stop is not saved (its tiles are not what a
        // resumed run's start-up would give).
        let startup_whole = !stop.load(Ordering::Relaxed);
        let start_seconds = start.elapsed().as_secs_f64();
        let develop_now = |sums: &[TileSums]| {
            // Past the run's end (stop flag or deadline) the sweeps stop
            // after the default's count: 10^15 sweeps kept a run for ever
            // past `--time`, and no run has fewer sweeps than before.
            develop(
                &sampler.tiling,
                sums,
                self.alignment_channels,
                self.alpha,
                (self.solver_iterations, &|i| {
                    i < DEFAULT_SOLVER_ITERATIONS || !halt()
                }),
                sampler.filter.as_ref(),
            )
        };

        let planned = self.iterations(run);
        let mut checkpoint_error: Option<String> = None;
        // `None`: nothing saved yet, so the first whole iteration is (a
        // run stopped soon after its start-up has something to resume).
        let (mut last_save, mut save_cost) = (None::<Instant>, std::time::Duration::ZERO);
        let mut last_preview = Instant::now();
        // Wall-clock seconds in tile steps, exchange rounds and snapshots
        // (the observer's develop and whatever it does with the image).
        let mut profile = [0.0f64; 3];
        // (On a cluster the ranks agree on stopping: a collective.)
        while planned.is_none_or(|m| counters.iterations < m) && !crate::cluster::any_rank(halt()) {
            let t0 = Instant::now();
            let stepped: usize = (tiles.par_iter_mut().enumerate())
                .map(|(i, tile)| {
                    if halt() {
                        return 0;
                    }
                    sampler.step(first + i, tile);
                    observer.progress(1);
                    1
                })
                .sum();
            counters.iterations += 1;
            let mut whole = stepped == tiles.len();
            let t1 = Instant::now();
            profile[0] += (t1 - t0).as_secs_f64();
            if self.exchange && counters.iterations.is_multiple_of(every) {
                let rounds = counters.rounds;
                let mut c = sampler.exchange_round(&mut tiles, rows.start, rounds, &halt);
                c += sampler.cross_exchange(&mut tiles, &rows, rounds, &halt);
                whole &= !c.cut;
                counters.exchange += c;
                counters.rounds += 1;
            }
            let t2 = Instant::now();
            profile[1] += (t2 - t1).as_secs_f64();
            // A snapshot needs every tile: not made on a cluster.
            if cluster.is_none() && last_preview.elapsed() >= run.snapshot_every && !halt() {
                last_preview = Instant::now();
                let done = tiles.iter().map(|t| t.steps).sum();
                let sums: Vec<TileSums> = tiles.iter().map(|t| t.sums.clone()).collect();
                observer.snapshot(&|| develop_now(&sums[..]).image, done);
                profile[2] += t2.elapsed().as_secs_f64();
            }
            // Checkpoints: whole iterations only (on every rank), at the
            // end, when stopped (here, after the snapshot, where an
            // observer may stop the run), and in between at most once per
            // `CHECKPOINT_EVERY` and 20 saves' time (≤ 5% of the run),
            // the first whole iteration at once.
            if let Some(ck) = &run.checkpoint {
                let whole = startup_whole && !crate::cluster::any_rank(!whole);
                let due =
                    last_save.is_none_or(|t| t.elapsed() >= CHECKPOINT_EVERY.max(20 * save_cost));
                let due = crate::cluster::any_rank(due && crate::cluster::is_root());
                let end = planned.is_some_and(|m| counters.iterations >= m)
                    || crate::cluster::any_rank(halt());
                if whole && (due || end) {
                    let t = Instant::now();
                    if let Err(e) = sampler.save(ck, &counters, &tiles, &filter) {
                        checkpoint_error.get_or_insert(e);
                    }
                    (last_save, save_cost) = (Some(Instant::now()), t.elapsed());
                }
            }
        }
        let develop_start = Instant::now();
        // This rank's share (the sidecar's `ranks` on a cluster), then the
        // counts every rank adds: the tiles started at start-up and the
        // exchanges (a pair across ranks counted by one of them).
        let own = json!({
            "rows": rows.len(),
            "mutations": tiles.iter().map(|t| t.steps).sum::<u64>(),
            "seconds_in_steps": profile[0],
            "seconds_in_exchange": profile[1],
        });
        let (iterations, rounds) = (counters.iterations, counters.rounds);
        let pooled = crate::cluster::all_gather_words(vec![
            counters.started_at_init,
            counters.exchange.attempts,
            counters.exchange.accepted,
            counters.exchange.copies,
            counters.exchange.alpha_sum.to_bits(),
        ]);
        let mut started_at_init = 0u64;
        let mut exchange = ExchangeCounts::default();
        for r in pooled.chunks_exact(5) {
            started_at_init += r[0];
            exchange += ExchangeCounts {
                attempts: r[1],
                accepted: r[2],
                copies: r[3],
                alpha_sum: f64::from_bits(r[4]),
                cut: false,
            };
        }
        // The chains' component names (not sent between ranks).
        let names = (mutation.kernel::<TileValues>())
            .expect("the mutation was checked by validate")
            .component_names();
        let Some(results) = TileResults::gather(tiles, first, &names, &filter) else {
            // Not rank 0: only rank 0 develops and writes the image.
            let statistics = crate::cluster::with_ranks(json!({}), own);
            return Ok(Rendered {
                image: vec![crate::color::Rgb::BLACK; n],
                seconds: start.elapsed().as_secs_f64(),
                samples: 0,
                interrupted: false,
                statistics: statistics.as_object().cloned().unwrap_or_default(),
                nonfinite_dump: None,
                layers: Vec::new(),
                summary: String::new(),
            });
        };
        // Every tile steps once per iteration (a tile not started draws),
        // so a tile short of the plan means the run was stopped.
        let interrupted = planned.is_none_or(|m| results.steps.iter().any(|&s| s < m));
        let developed = develop_now(&results.sums[..]);
        let develop_seconds = develop_start.elapsed().as_secs_f64();
        let mutations: u64 = results.steps.iter().sum();
        let seconds = start.elapsed().as_secs_f64();

        let mut stats: Option<ChainStatistics> = None;
        for c in results.stats.iter().flatten() {
            match stats.as_mut() {
                Some(s) => s.merge(c),
                None => stats = Some(c.clone()),
            }
        }
        let cs = stats.unwrap_or_else(|| ChainStatistics::new(Vec::new()));
        let started = results.stats.iter().filter(|s| s.is_some()).count();
        let large_samples: u64 = results.sums.iter().map(|t| t.large_samples).sum();
        let mut density: Vec<f64> = developed.samples.iter().map(|c| f64::from(c.r)).collect();
        density.sort_by(f64::total_cmp);
        let median = density.get(density.len() / 2).copied().unwrap_or(0.0);
        let max = density.last().copied().unwrap_or(0.0);
        let per_second = if seconds > start_seconds {
            mutations as f64 / (seconds - start_seconds)
        } else {
            0.0
        };
        let component = |k: usize| cs.components.get(k).map(|c| c.acceptance_rate());
        let statistics = json!({
            "shift": shift.name(),
            "tile": self.tile.name(),
            "tiles": n,
            "iterations": iterations,
            "mutations": mutations,
            "mutations_per_second": per_second,
            "start_seconds": start_seconds,
            "initialised_tiles_at_start": started_at_init as f64 / n as f64,
            "init": self.init.name(),
            "global_init": visits.as_ref().map(|v| json!({
                "chains": self.init_chains,
                "mutations": v.mutations,
                "lit_bootstrap": v.lit_bootstrap,
                "drawn_bootstrap": v.drawn_bootstrap,
                "visited_pixels": v.visited as f64 / n as f64,
                "acceptance": v.stats.as_ref().map(|s| s.acceptance_rate()),
            })),
            "initialised_tiles": started as f64 / n as f64,
            "acceptance": cs.acceptance_rate(),
            "acceptance_per_component": cs.components.iter().map(|c| json!({
                "name": c.name,
                "proposed": c.proposed,
                "accepted": c.accepted,
                "acceptance": c.acceptance_rate(),
            })).collect::<Vec<_>>(),
            "acceptance_per_shift": { shift.name(): {
                "large": component(LARGE_STEP_COMPONENT),
                "small": component(0),
            }},
            "exchange": {
                "rounds": rounds,
                "attempts": exchange.attempts,
                "accepted": exchange.accepted,
                "rate": exchange.accepted as f64 / exchange.attempts.max(1) as f64,
                "mean_alpha": exchange.alpha_sum / exchange.attempts.max(1) as f64,
                "copies": exchange.copies,
            },
            "solver": {
                "alpha": self.alpha,
                "iterations": developed.alignment.iterations,
                "planned_iterations": self.solver_iterations,
                "initial_residual": developed.alignment.initial_residual,
                "residual": developed.alignment.residual,
            },
            "large_step_samples": large_samples,
            // The uniform draws of the least and the most drawn tile: the
            // start-up draws round the tiles, so a stop in it leaves them
            // at most `START_ROUND` apart.
            "large_step_samples_per_tile": [
                results.sums.iter().map(|t| t.large_samples).min().unwrap_or(0),
                results.sums.iter().map(|t| t.large_samples).max().unwrap_or(0),
            ],
            // No tile stepped (a stop in the start-up): the image is `Ĩ`,
            // the start-up draws' own estimate.
            "image_from_start_up": mutations == 0,
            "seconds_in": {
                "start": start_seconds,
                "steps": profile[0],
                "exchange": profile[1],
                "snapshots": profile[2],
                "final_develop": develop_seconds,
            },
            "samples_per_pixel_max_over_median": if median > 0.0 { max / median } else { f64::NAN },
            "nonfinite_contributions": cs.invalid_density,
            "checkpoint": run.checkpoint.as_ref().map(|ck| {
                ck.statistics("iterations", resumed_from.unwrap_or(0), iterations, &checkpoint_error)
            }),
        });
        // On a cluster, every rank's share (on rank 0; collective).
        let Value::Object(statistics) = crate::cluster::with_ranks(statistics, own) else {
            unreachable!("json! of an object literal is an object")
        };
        Ok(Rendered {
            image: developed.image,
            seconds,
            samples: mutations,
            interrupted,
            statistics,
            nonfinite_dump: None,
            layers: vec![("samples".into(), developed.samples)],
            summary: format!(
                "{iterations} iterations of {n} tiles ({mutations} mutations) in {seconds:.2} s, {:.1}% of tiles started, exchange rate {:.3}, solver residual {:.2e}{}{}",
                100.0 * started as f64 / n as f64,
                exchange.accepted as f64 / exchange.attempts.max(1) as f64,
                developed.alignment.residual,
                if developed.alignment.iterations < self.solver_iterations {
                    format!(
                        " (sweeps cut at {} of {})",
                        developed.alignment.iterations, self.solver_iterations
                    )
                } else {
                    String::new()
                },
                if interrupted { ", stopped early" } else { "" },
            ),
        })
    }
}
