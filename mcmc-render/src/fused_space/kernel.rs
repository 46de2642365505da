//! The fused chain's kernel (spec seed001 §5.1, Algorithm 1): each step
//! draws one mutation with state-independent probabilities (so selection
//! probabilities cancel in every ratio; a path-space mutation that does
//! not apply to the current path fails and is counted, option (b) of
//! spec seed001 §3):
//!
//! - with probability `1 − p_tc − p_path`, MMLT's primary-sample mutation
//!   (`mcmc-core`'s mixture of a small step and a large step), then the
//!   proposal is traced (Eq. 11: the ratio of the targets);
//! - with probability `p_tc`, a change of technique: the technique number
//!   alone is redrawn (symmetric);
//! - with probability `p_path`, a path-space mutation of the cached path,
//!   mapped back by the inverse path sampler (Eq. 24, see the module docs
//!   of [`crate::fused_space`]).
//!
//! # Deciding before converting (delayed acceptance)
//!
//! A path-space move is decided on the path before anything is mapped
//! back to primary samples, as in the paper, where only accepted proposals
//! are inverted (its conversions take 0.03% of the time). In two stages
//! (Christen & Fox 2005's delayed acceptance):
//!
//! 1. with `π̃` MMLT's target evaluated on the path
//!    ([`super::technique::log_target`], no ray traced), accept with
//!    `α₁ = min(1, π̃(y) T_U(v→u) / (π̃(x) T_U(u→v)))`, the Eq. 24 ratio;
//!    a stage-1 rejection ends the step (no inversion, no re-trace);
//! 2. only then are the current path's and the proposal's round trips
//!    done (below); if either fails the move is rejected; otherwise the
//!    driver accepts the re-traced state `v` with
//!    `α₂ = min(1, π(v) π̃(x) / (π(u) π̃(y)))` (the kernel reports
//!    `ln π̃(x) − ln π̃(y)` as its ratio).
//!
//! `α₂` is 1 up to `f32` rounding (`π̃` is `π` computed another way); it
//! keeps the chain exact for any positive `π̃` that is a function of the
//! state (delayed acceptance's condition), so a slip in `π̃` costs
//! efficiency, not correctness.
//!
//! # Rejecting after the accept draw, and the round trip's bias
//!
//! A path-space proposal `y` is inverted to `v` and `v` re-traced; the
//! proposal is the re-traced state (its cache is exactly `P_t^{-1}(v)`),
//! and it fails when re-tracing gives another technique or nothing
//! (spec seed001 §5.1). The paper checks only the proposal, which makes
//! the chain prefer the set `A` of paths that survive the round trip: a
//! move from `x ∉ A` to `y ∈ A` can be accepted but its reverse never is.
//! Here a path-space move also fails when the *current* path does not
//! survive it; that check is drawn once per state and kept with it (an
//! accepted path-space proposal has just survived its own).
//!
//! Why rejecting *after* the stage-1 accept draw keeps the target: whether
//! a path survives the round trip is a property `c(x) ∈ {0, 1}` of the
//! state (drawn when needed, with probability `a(x)`, kept until the state
//! changes; `a(x) ∈ {0, 1}` except for `f32` ties). Augment the state
//! with `c`, target `π(u) · P(c | x)`: primary-sample moves leave `π`
//! invariant and redraw `c` with the state, so they leave the augmented
//! target invariant. For a path-space move the flux from `(x, 1)` to
//! `(y, 1)` is `π(x) a(x) · T(x→y) α₁(x, y) α₂(x, y) · a(y)`, which is
//! symmetric in `x` and `y` because `π(x) T(x→y) α₁ α₂` is (delayed
//! acceptance's detailed balance); from `c = 0`, or to a proposal whose
//! round trip fails, nothing moves. Testing `c` after the accept draw
//! rather than before only changes which proposals pay for the
//! conversion, not the flux. Path-space moves therefore run inside
//! `A × A` and satisfy detailed balance there; the primary-sample moves
//! cover everything. What remains is `f32` rounding between `y` and its
//! re-trace.

use super::inverse_path::{RoundTripFailure, round_trip, trace};
use super::technique::{log_target, log_technique_density};
use super::{Conversion, FusedMutation, FusedState};
use crate::integrators::path_vertex::VertexKind;
use crate::path_space::Path;
use crate::pss::{MmltDepth, PathSample};
use crate::scene::Scene;
use mcmc_core::kernel::{Kernel, Mixture, Proposal, StepObservation};
use mcmc_core::mh::{accept, mh_log_acceptance};
use mcmc_core::rng::{ChainRng, child_rng, uniform};
use mcmc_core::sample::Sample;
use mcmc_core::space::TorusPoint;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Counters of the conversions between the two spaces, summed over every
/// chain of a render (each kernel adds its counts when it is dropped, so
/// they are complete once the driver has returned). The image does not
/// depend on them; the per-depth tallies decide
/// `path_space_probability=auto` (`integrators::fused`), the timings do
/// not.
#[derive(Debug, Default)]
pub struct FusedCounters {
    /// Path → primary sample inversions (each followed by a re-trace).
    pub inversions: AtomicU64,
    /// Path-space proposals rejected by the first acceptance stage, before
    /// any conversion.
    pub rejected_before_conversion: AtomicU64,
    /// Nanoseconds spent inverting and re-tracing (estimated, [`TIMED_EVERY`]).
    pub conversion_nanos: AtomicU64,
    /// Nanoseconds spent in the kernel's proposals, conversions included (estimated, [`TIMED_EVERY`]).
    pub propose_nanos: AtomicU64,
    /// Of those, in primary-sample moves (small, large, technique change).
    pub pss_nanos: AtomicU64,
    /// Of those, in path-space moves.
    pub path_nanos: AtomicU64,
    /// Lazy conversion: paths mapped back before a primary-sample move
    /// (each also counted in `inversions`).
    pub deferred_conversions: AtomicU64,
    /// Of those, the ones whose round trip failed (the primary-sample
    /// move was then rejected, the chain stayed on the path).
    pub deferred_conversion_failures: AtomicU64,
    /// Per path depth (index = depth), what each kind of move achieved.
    pub per_depth: Vec<MoveTally>,
}

impl FusedCounters {
    /// Zeroed counters with tallies for depths `0..=max_depth`.
    pub fn new(max_depth: usize) -> Self {
        FusedCounters {
            per_depth: (0..=max_depth).map(|_| MoveTally::default()).collect(),
            ..FusedCounters::default()
        }
    }
}

/// One step in this many is timed, and its time counted this many times:
/// reading the clock on every step took 4% of a run (`perf`, glossy-glass
/// box, 1 thread). The timings of the statistics are therefore estimates;
/// counts and tallies are exact.
pub const TIMED_EVERY: u64 = 16;

/// One kernel's counts, kept in the kernel and added to the shared
/// [`FusedCounters`] when it is dropped (at the end of the run): atomic
/// additions on every step, from both threads into the same cache lines,
/// would cost each step a cache-line transfer. Integer sums, so the totals
/// do not depend on the order of the additions.
#[derive(Debug, Default)]
struct LocalCounts {
    steps: u64,
    inversions: u64,
    rejected_before_conversion: u64,
    conversion_nanos: u64,
    propose_nanos: u64,
    pss_nanos: u64,
    path_nanos: u64,
    pss_proposals: u64,
    pss_jump: u64,
    path_proposals: u64,
    path_jump: u64,
    /// Lazy conversion only (in its kernel's words, not in [`LocalCounts::words`]).
    deferred_conversions: u64,
    deferred_conversion_failures: u64,
}

impl LocalCounts {
    /// Words of [`LocalCounts::words`].
    const WORDS: usize = 11;

    /// The counts as words, for checkpoints.
    fn words(&self) -> [u64; Self::WORDS] {
        [
            self.steps,
            self.inversions,
            self.rejected_before_conversion,
            self.conversion_nanos,
            self.propose_nanos,
            self.pss_nanos,
            self.path_nanos,
            self.pss_proposals,
            self.pss_jump,
            self.path_proposals,
            self.path_jump,
        ]
    }

    /// The counts [`LocalCounts::words`] wrote.
    fn from_words(w: &[u64]) -> LocalCounts {
        LocalCounts {
            steps: w[0],
            inversions: w[1],
            rejected_before_conversion: w[2],
            conversion_nanos: w[3],
            propose_nanos: w[4],
            pss_nanos: w[5],
            path_nanos: w[6],
            pss_proposals: w[7],
            pss_jump: w[8],
            path_proposals: w[9],
            path_jump: w[10],
            ..LocalCounts::default()
        }
    }

    /// Adds the counts of a kernel of `depth` to `c`.
    fn flush(&self, c: &FusedCounters, depth: usize) {
        let add = |a: &AtomicU64, v: u64| {
            a.fetch_add(v, Ordering::Relaxed);
        };
        add(&c.inversions, self.inversions);
        add(
            &c.rejected_before_conversion,
            self.rejected_before_conversion,
        );
        add(&c.conversion_nanos, self.conversion_nanos);
        add(&c.propose_nanos, self.propose_nanos);
        add(&c.pss_nanos, self.pss_nanos);
        add(&c.path_nanos, self.path_nanos);
        add(&c.deferred_conversions, self.deferred_conversions);
        add(
            &c.deferred_conversion_failures,
            self.deferred_conversion_failures,
        );
        if let Some(t) = c.per_depth.get(depth) {
            add(&t.pss_proposals, self.pss_proposals);
            add(&t.pss_jump, self.pss_jump);
            add(&t.path_proposals, self.path_proposals);
            add(&t.path_inversions, self.inversions);
            add(&t.path_jump, self.path_jump);
        }
    }
}

/// Fixed-point scale of [`MoveTally`]'s jumps: a squared jump is a
/// fraction of the squared image diagonal, in units of `2⁻³²`, so that
/// the sums are integers and the same whatever order threads add them in
/// (a chain of `10⁹` proposals stays below `2⁶²`).
pub const JUMP_SCALE: f64 = 4_294_967_296.0;

/// What one depth's primary-sample moves and path-space moves achieved:
/// proposals, the expected squared jump of the splat in the image plane
/// (`Σ α · |Δ raster|² / (w² + h²)`, fixed point, [`JUMP_SCALE`]) and
/// the conversions the path-space moves paid for. Integers only, summed
/// atomically: the totals are a function of the chains, not of threads.
#[derive(Debug, Default)]
pub struct MoveTally {
    /// Primary-sample proposals (small, large, technique change).
    pub pss_proposals: AtomicU64,
    /// Their `Σ α · jump²` (fixed point).
    pub pss_jump: AtomicU64,
    /// Path-space proposals (failed ones included).
    pub path_proposals: AtomicU64,
    /// Inversions (each with a re-trace) they made.
    pub path_inversions: AtomicU64,
    /// Their `Σ α · jump²` (fixed point).
    pub path_jump: AtomicU64,
}

/// One depth's [`MoveTally`], read out.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MoveTotals {
    /// Primary-sample proposals.
    pub pss_proposals: u64,
    /// Their `Σ α · jump²` (fraction of the squared diagonal).
    pub pss_jump: f64,
    /// Path-space proposals.
    pub path_proposals: u64,
    /// Their inversions.
    pub path_inversions: u64,
    /// Their `Σ α · jump²` (fraction of the squared diagonal).
    pub path_jump: f64,
}

/// Cost of a path-space proposal's mutation and first-stage test, in
/// primary-sample steps (one trace each). From Session 13's profile
/// (`docs/fused.md`; door, 1 thread, half the steps of each kind): the
/// mutations took 17% and stage 1 8% of the time over 921 k path-space
/// proposals, the primary-sample proposals 27% over as many steps, so
/// `(17 + 8) / 27 ≈ 0.93`.
pub const MUTATION_COST: f64 = 0.93;
/// Cost of one inversion with its re-trace, in primary-sample steps: the
/// round trips took 32% of that profile's time over 525 k inversions,
/// against 27% over 921 k primary-sample steps: `(32/525)/(27/921) ≈ 2.08`.
pub const ROUND_TRIP_COST: f64 = 2.08;

impl MoveTally {
    /// The tallies so far as integers (the jumps in fixed point), in the
    /// order [`MoveTotals::from_words`] reads: integers, so that sums over
    /// ranks equal a single process's tallies bit for bit.
    pub fn words(&self) -> [u64; 5] {
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        [
            get(&self.pss_proposals),
            get(&self.pss_jump),
            get(&self.path_proposals),
            get(&self.path_inversions),
            get(&self.path_jump),
        ]
    }

    /// The totals so far.
    pub fn totals(&self) -> MoveTotals {
        MoveTotals::from_words(self.words())
    }
}

impl MoveTotals {
    /// The totals of tallies given as [`MoveTally::words`].
    pub fn from_words(
        [
            pss_proposals,
            pss_jump,
            path_proposals,
            path_inversions,
            path_jump,
        ]: [u64; 5],
    ) -> MoveTotals {
        MoveTotals {
            pss_proposals,
            pss_jump: pss_jump as f64 / JUMP_SCALE,
            path_proposals,
            path_inversions,
            path_jump: path_jump as f64 / JUMP_SCALE,
        }
    }

    /// Expected squared jump per unit of cost (primary-sample steps) of
    /// the primary-sample moves and of the path-space moves (`NaN` for a
    /// kind without proposals). The cost is a deterministic model
    /// ([`MUTATION_COST`], [`ROUND_TRIP_COST`]), not a clock, so that a
    /// choice made from it is the same on every machine and thread count.
    pub fn efficiencies(&self) -> (f64, f64) {
        let pss = self.pss_jump / self.pss_proposals as f64;
        let cost = MUTATION_COST * self.path_proposals as f64
            + ROUND_TRIP_COST * self.path_inversions as f64;
        (pss, self.path_jump / cost)
    }
}

/// Squared distance between the first splats of two paths in the image
/// plane, as a fraction of the squared image diagonal (0 when either has
/// none: it carries nothing, so the move is not accepted).
fn image_jump(scene: &Scene, a: &PathSample, b: &PathSample) -> f64 {
    match (a.splats.first(), b.splats.first()) {
        (Some(a), Some(b)) => {
            let (w, h) = (scene.film.width as f64, scene.film.height as f64);
            f64::from((a.p - b.p).length_squared()) / (w * w + h * h)
        }
        _ => 0.0,
    }
}

/// Whether two paths hold the same vertices (positions, emitters, kinds;
/// a vertex at infinity is its direction `wo`, its position being 0;
/// other vertices' `wo` is rewritten by [`Path::evaluate`], so not
/// compared). Never for an empty path.
fn same_vertices(a: &Path<'_>, b: &Path<'_>) -> bool {
    a.vertices.len() == b.vertices.len()
        && !a.vertices.is_empty()
        && (a.vertices.iter()).zip(&b.vertices).all(|(a, b)| {
            a.p() == b.p()
                && a.light == b.light
                && a.kind == b.kind
                && (a.kind != VertexKind::Infinite || a.wo == b.wo)
        })
}

/// Probability of a primary-sample (small or large step) mutation.
pub fn pss_probability(m: &FusedMutation) -> f64 {
    (1.0 - m.technique_change - m.path_probability).max(0.0)
}

/// Failure reasons of path-space moves beyond the mutations' own.
const PATH_FAILURES: [&str; 5] = [
    "path: technique cannot produce the proposal",
    "path: proposal not invertible",
    "path: round trip failed",
    "path: current path not invertible",
    "path: current path has no target value",
];

/// The failure of a primary-sample move (or change of technique) whose
/// current path, reached by path-space moves under lazy conversion, does
/// not survive its conversion to primary samples.
pub const CONVERSION_FAILURE: &str = "pss: current path not convertible (lazy)";

/// The fused kernel of one depth (one per chain).
pub struct FusedKernel<'s> {
    scene: &'s Scene,
    depth: MmltDepth,
    pss: Mixture<TorusPoint, PathSample>,
    path: Mixture<Path<'s>, PathSample>,
    p_pss: f64,
    p_tc: f64,
    drop_jacobian: bool,
    /// [`Conversion::Lazy`].
    lazy: bool,
    counters: Arc<FusedCounters>,
    n_pss: usize,
    n_path: usize,
    pss_cur: Option<Sample<TorusPoint, PathSample>>,
    pss_prop: Option<Sample<TorusPoint, PathSample>>,
    path_cur: Option<Sample<Path<'s>, PathSample>>,
    path_prop: Option<Sample<Path<'s>, PathSample>>,
    /// Stage 1's values of the evaluated current path `path_cur` under
    /// technique `s`: `(s, ln p_s(x), ln π̃(x))`, computed by the first
    /// path-space proposal from it that reaches stage 1 and reused by the
    /// next ones while the path stays (cleared when it changes). Pure
    /// functions of the path, so reusing them changes nothing.
    cur_stage1: Option<(usize, f64, f64)>,
    /// Lazy conversion: the same values of the last path-space proposal
    /// `path_prop` that became an unconverted state, for when that state
    /// next takes a path-space move (`None` after any other proposal).
    prop_stage1: Option<(usize, f64, f64)>,
    scratch: Option<FusedState<'s>>,
    /// The state the current path's round trip writes into (reused: a
    /// new one per check allocated its point, path and splats again).
    probe: Option<FusedState<'s>>,
    /// Lazy conversion: the state a stale current state's path is mapped
    /// back into before a primary-sample move (kept for its allocations).
    lifted: Option<FusedState<'s>>,
    /// The path `lifted` was converted from, and whether that round trip
    /// succeeded (`None`: nothing converted yet). Drawn once per state,
    /// as the eager rule's current-path check: a primary-sample move
    /// rejected from an unconverted state leaves it where it was, and the
    /// next one starts from the same conversion (the state is then `v`).
    lifted_from: Option<(Path<'s>, bool)>,
    /// Whether the current state's path survives the round trip (`None`:
    /// not checked since the state last changed).
    current_invertible: Option<bool>,
    /// What `current_invertible` becomes if the last proposal is accepted
    /// (`Some(true)` after a path-space proposal's successful round trip).
    proposal_invertible: Option<bool>,
    /// The last proposal: whether it was a path-space move, and its
    /// squared image jump (0 when it failed), weighted by `α` in `observe`.
    last_move: (bool, f64),
    /// Counts not yet added to `counters`.
    local: LocalCounts,
    /// Whether the current step is timed ([`TIMED_EVERY`]).
    timed: bool,
}

impl Drop for FusedKernel<'_> {
    fn drop(&mut self) {
        self.local.flush(&self.counters, self.depth.depth);
    }
}

impl<'s> FusedKernel<'s> {
    /// The kernel of `depth` with `mutation`'s settings.
    pub fn new(
        scene: &'s Scene,
        depth: MmltDepth,
        mutation: &FusedMutation,
        counters: Arc<FusedCounters>,
    ) -> Result<Self, String> {
        let pss = mutation.pss.kernel().map_err(|e| e.to_string())?;
        let path = mutation
            .path_mutations()
            .kernel_between(depth.depth, Some(depth.depth))?;
        let (n_pss, n_path) = (pss.component_names().len(), path.component_names().len());
        Ok(FusedKernel {
            scene,
            depth,
            pss,
            path,
            p_pss: pss_probability(mutation),
            p_tc: mutation.technique_change,
            drop_jacobian: mutation.drop_jacobian,
            lazy: mutation.conversion == Conversion::Lazy,
            counters,
            n_pss,
            n_path,
            pss_cur: None,
            pss_prop: None,
            path_cur: None,
            path_prop: None,
            cur_stage1: None,
            prop_stage1: None,
            scratch: None,
            probe: None,
            lifted: None,
            lifted_from: None,
            current_invertible: None,
            proposal_invertible: None,
            last_move: (false, 0.0),
            local: LocalCounts::default(),
            timed: false,
        })
    }

    /// Component index of the change of technique.
    fn technique_component(&self) -> usize {
        self.n_pss
    }

    /// Component index of path-space failure reason `i` of [`PATH_FAILURES`].
    fn failure(&self, i: usize) -> usize {
        self.n_pss + 1 + self.n_path + i
    }

    /// Writes the traced state at `point` into `proposal`.
    fn finish(
        &self,
        point: TorusPoint,
        proposal: &mut Sample<FusedState<'s>, PathSample>,
        log_q_ratio: f64,
        component: usize,
    ) -> Proposal {
        proposal.state.point = point;
        self.finish_in_place(proposal, log_q_ratio, component)
    }

    /// Traces the point already in `proposal` and writes the state.
    fn finish_in_place(
        &self,
        proposal: &mut Sample<FusedState<'s>, PathSample>,
        log_q_ratio: f64,
        component: usize,
    ) -> Proposal {
        trace(self.scene, &self.depth, &mut proposal.state);
        proposal.log_density = proposal.state.log_density;
        proposal.payload.clone_from(&proposal.state.sample);
        Proposal {
            log_q_ratio,
            component,
            evaluated: true,
            failed: false,
        }
    }

    /// A small or large step from `point`, the current state's primary
    /// sample, whose target is `log_density`.
    fn propose_pss(
        &mut self,
        point: &TorusPoint,
        log_density: f64,
        proposal: &mut Sample<FusedState<'s>, PathSample>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let cur = self.pss_cur.get_or_insert_with(|| Sample {
            state: point.clone(),
            log_density,
            payload: PathSample::default(),
        });
        cur.state.clone_from(point);
        cur.log_density = log_density;
        let prop = self.pss_prop.get_or_insert_with(|| cur.clone());
        let p = self.pss.propose(cur, prop, rng);
        if p.failed {
            return p;
        }
        // Swap rather than move the point out: the proposal's old point
        // becomes the mixture's next scratch, so neither allocates again
        // (the next small or large step overwrites all of it).
        std::mem::swap(&mut prop.state, &mut proposal.state.point);
        self.finish_in_place(proposal, p.log_q_ratio, p.component)
    }

    /// A change of technique from `point`, the current state's primary sample.
    fn propose_technique(
        &mut self,
        point: &TorusPoint,
        proposal: &mut Sample<FusedState<'s>, PathSample>,
        rng: &mut ChainRng,
    ) -> Proposal {
        // Connection stream, number 0: coordinate 2 of the interleaved layout.
        let mut values = point.materialize();
        if values.len() < 3 {
            values.resize(3, 0.5);
            // Coordinates never read are uniform: draw the missing ones.
            for v in values.iter_mut().skip(point.len()) {
                *v = uniform(rng);
            }
        }
        values[2] = uniform(rng);
        let point = TorusPoint::from_values(&values, child_rng(rng));
        // Redrawing one coordinate uniformly is symmetric.
        self.finish(point, proposal, 0.0, self.technique_component())
    }

    fn propose_path(
        &mut self,
        current: &Sample<FusedState<'s>, PathSample>,
        proposal: &mut Sample<FusedState<'s>, PathSample>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let offset = self.n_pss + 1;
        let fail = [0, 1, 2, 3, 4].map(|i| self.failure(i));
        // The current path: cached, or traced once (a start-up state).
        let scene = self.scene;
        let depth = self.depth;
        let traced;
        let x = if current.state.depth == Some(depth.depth) {
            &current.state
        } else {
            let mut t = FusedState::untraced(scene, current.state.point.clone());
            trace(scene, &depth, &mut t);
            traced = t;
            &traced
        };
        let Some((s, _)) = x.technique else {
            return Proposal::failed(fail[3]);
        };
        // Traces cache the path's vertices only; its densities and
        // contribution are evaluated here, once per current path (a state
        // sees several path-space proposals while it is current). The copy
        // is reused while its vertices are the current path's: a content
        // check ([`same_vertices`]), so nothing depends on how the driver
        // moves states.
        let new_sample = || Sample {
            state: Path::new(scene),
            log_density: f64::NEG_INFINITY,
            payload: PathSample::default(),
        };
        let cur = self.path_cur.get_or_insert_with(new_sample);
        if !same_vertices(&cur.state, &x.path) {
            // Lazy conversion: a state reached by the last path-space
            // proposal is that proposal, evaluated by its mutation, with
            // its stage-1 values: swap it in instead of evaluating again.
            let prop = self.path_prop.get_or_insert_with(new_sample);
            match self.prop_stage1.take() {
                Some(values) if x.point_stale && same_vertices(&prop.state, &x.path) => {
                    std::mem::swap(cur, prop);
                    cur.log_density = cur.state.log_density();
                    self.cur_stage1 = Some(values);
                }
                _ => {
                    cur.state.clone_from(&x.path);
                    cur.state.evaluate();
                    cur.log_density = cur.state.log_density();
                    self.cur_stage1 = None;
                }
            }
        }
        self.prop_stage1 = None;
        let prop = self.path_prop.get_or_insert_with(|| cur.clone());
        let p = self.path.propose(cur, prop, rng);
        if p.failed {
            return Proposal::failed(offset + p.component);
        }
        let x_path = &cur.state;
        let y = &prop.state;
        let log_p_y = log_technique_density(y, s);
        let (log_p_x, log_pi_x) = match self.cur_stage1 {
            Some((cached_s, log_p, log_pi)) if cached_s == s => (log_p, log_pi),
            _ => {
                // ln π̃(x) only where stage 1 needs it (both densities positive).
                let log_p = log_technique_density(x_path, s);
                let log_pi = if log_p > f64::NEG_INFINITY {
                    log_target(&depth, x_path, s)
                } else {
                    f64::NEG_INFINITY
                };
                self.cur_stage1 = Some((s, log_p, log_pi));
                (log_p, log_pi)
            }
        };
        if !(log_p_y > f64::NEG_INFINITY) || !(log_p_x > f64::NEG_INFINITY) {
            return Proposal::failed(fail[0]);
        }
        // Stage 1 (module docs): Eq. 24 on the paths, nothing converted.
        if !log_pi_x.is_finite() {
            return Proposal::failed(fail[4]);
        }
        let log_pi_y = log_target(&depth, y, s);
        let jacobian = if self.drop_jacobian {
            0.0
        } else {
            log_p_y - log_p_x
        };
        let (log_alpha1, _) = mh_log_acceptance(log_pi_x, log_pi_y, p.log_q_ratio + jacobian);
        if !accept(log_alpha1, rng) {
            self.local.rejected_before_conversion += 1;
            // Counted as a rejection of the mutation that proposed.
            return Proposal::failed(offset + p.component);
        }
        if self.lazy {
            // Lazy conversion: the accepted path is the proposal, mapped
            // back only before a primary-sample move needs its point.
            proposal.state.set_unconverted(&depth, y, s);
            proposal.log_density = proposal.state.log_density;
            proposal.payload.clone_from(&proposal.state.sample);
            self.prop_stage1 = Some((s, log_p_y, log_pi_y));
            return Proposal {
                log_q_ratio: log_pi_x - log_pi_y,
                component: offset + p.component,
                evaluated: true,
                failed: false,
            };
        }
        // Stage 2: the current path's round trip (once per state), then the
        // proposal's; either failing rejects the move (module docs).
        let start = self.timed.then(Instant::now);
        let current_ok = match self.current_invertible {
            Some(ok) => ok,
            None => {
                // A fresh point's stream is drawn for every check, as when
                // each check had a new state (the inverse replaces it).
                // `set_values` of nothing makes it `TorusPoint::fresh`.
                let fresh = child_rng(rng);
                let probe = self.probe.get_or_insert_with(|| {
                    FusedState::untraced(scene, TorusPoint::fresh(fresh.clone()))
                });
                probe.point.set_values(&[], fresh);
                let ok = round_trip(scene, &depth, x_path, s, rng, probe).is_ok();
                self.local.inversions += 1;
                self.current_invertible = Some(ok);
                ok
            }
        };
        let outcome = if current_ok {
            let out = self.scratch.get_or_insert_with(|| {
                FusedState::untraced(scene, TorusPoint::fresh(child_rng(rng)))
            });
            let result = round_trip(scene, &depth, y, s, rng, out);
            self.local.inversions += 1;
            match result {
                Err(RoundTripFailure::Inverse(_)) => Some(fail[1]),
                Err(RoundTripFailure::Retrace) => Some(fail[2]),
                Ok(()) => None,
            }
        } else {
            Some(fail[3])
        };
        if let Some(start) = start {
            self.local.conversion_nanos += start.elapsed().as_nanos() as u64 * TIMED_EVERY;
        }
        if let Some(component) = outcome {
            return Proposal::failed(component);
        }
        let out = self.scratch.as_mut().expect("set above");
        std::mem::swap(&mut proposal.state, out);
        proposal.log_density = proposal.state.log_density;
        proposal.payload.clone_from(&proposal.state.sample);
        self.proposal_invertible = Some(true);
        Proposal {
            // The driver's test is stage 2: ln α₂ = ln π(v) − ln π(u) + this.
            log_q_ratio: log_pi_x - log_pi_y,
            component: offset + p.component,
            evaluated: true,
            failed: false,
        }
    }
}

impl<'s> FusedKernel<'s> {
    /// The primary sample a primary-sample move starts from: the current
    /// state's own (`Ok(None)`), or under lazy conversion, when the state
    /// was reached by path-space moves, its path mapped back now (the
    /// round trip: inverted with fresh uniforms where the sampler is
    /// many-to-one, re-traced, same technique and non-zero) into the
    /// returned state; `Err` with the failure's component when the round
    /// trip fails. The caller hands the state back to `self.lifted`.
    fn convert_current(
        &mut self,
        current: &Sample<FusedState<'s>, PathSample>,
        rng: &mut ChainRng,
    ) -> Result<Option<FusedState<'s>>, usize> {
        if !current.state.point_stale {
            return Ok(None);
        }
        let cached = match &self.lifted_from {
            Some((from, ok)) if same_vertices(from, &current.state.path) => Some(*ok),
            _ => None,
        };
        let ok = match cached {
            Some(ok) => ok,
            None => {
                let start = self.timed.then(Instant::now);
                let scene = self.scene;
                let path = &current.state.path;
                let lifted = self.lifted.get_or_insert_with(|| {
                    FusedState::untraced(scene, TorusPoint::fresh(child_rng(rng)))
                });
                let ok = match current.state.technique {
                    Some((s, _)) => round_trip(scene, &self.depth, path, s, rng, lifted).is_ok(),
                    None => false,
                };
                match &mut self.lifted_from {
                    Some((from, was)) => {
                        from.clone_from(path);
                        *was = ok;
                    }
                    None => self.lifted_from = Some((path.clone(), ok)),
                }
                let c = &mut self.local;
                c.inversions += 1;
                c.deferred_conversions += 1;
                c.deferred_conversion_failures += u64::from(!ok);
                if let Some(start) = start {
                    c.conversion_nanos += start.elapsed().as_nanos() as u64 * TIMED_EVERY;
                }
                ok
            }
        };
        if !ok {
            return Err(self.conversion_failure());
        }
        Ok(self.lifted.take())
    }

    /// Lazy conversion's part of the kernel's words (after the mixtures'):
    /// its two counts, then the conversion a primary-sample move last
    /// made of an unconverted state (drawn once per state and reused
    /// while the state stays): 0 none, 1 failed, 2 succeeded; for 1 and 2
    /// the path it was made from ([`Path::to_words`]), for 2 the point it
    /// gave ([`TorusPoint::to_words`]), which the next primary-sample
    /// move from that state starts from. A failed conversion's point is
    /// never read (the next round trip writes all of it).
    fn lazy_words(&self, out: &mut Vec<u64>) {
        out.extend([
            self.local.deferred_conversions,
            self.local.deferred_conversion_failures,
        ]);
        match (&self.lifted_from, &self.lifted) {
            (Some((path, ok)), Some(lifted)) => {
                out.push(if *ok { 2 } else { 1 });
                path.to_words(out);
                if *ok {
                    lifted.point.to_words(out);
                }
            }
            _ => out.push(0),
        }
    }

    /// Reads what [`FusedKernel::lazy_words`] wrote; `false` when the
    /// words are not that (counts beyond a run's, a path that does not
    /// decode in the scene).
    fn restore_lazy_words(&mut self, input: &mut &[u64]) -> bool {
        let Some((&[conversions, failures, outcome], mut words)) = input.split_first_chunk::<3>()
        else {
            return false;
        };
        if conversions > crate::checkpoint::MAX_COUNT || failures > conversions || outcome > 2 {
            return false;
        }
        self.local.deferred_conversions = conversions;
        self.local.deferred_conversion_failures = failures;
        if outcome > 0 {
            let Some(path) = Path::from_words(self.scene, &mut words) else {
                return false;
            };
            let point = match outcome {
                2 => match TorusPoint::from_words(&mut words) {
                    Some(point) => point,
                    None => return false,
                },
                _ => TorusPoint::fresh(mcmc_core::rng::stream_rng(0, 0)),
            };
            self.lifted = Some(FusedState::untraced(self.scene, point));
            self.lifted_from = Some((path, outcome == 2));
        }
        *input = words;
        true
    }

    /// Component index of [`CONVERSION_FAILURE`].
    fn conversion_failure(&self) -> usize {
        self.failure(PATH_FAILURES.len())
    }
}

impl<'s> Kernel<FusedState<'s>, PathSample> for FusedKernel<'s> {
    fn propose(
        &mut self,
        current: &Sample<FusedState<'s>, PathSample>,
        proposal: &mut Sample<FusedState<'s>, PathSample>,
        rng: &mut ChainRng,
    ) -> Proposal {
        self.timed = self.local.steps.is_multiple_of(TIMED_EVERY);
        self.local.steps += 1;
        let start = self.timed.then(Instant::now);
        self.proposal_invertible = None;
        let r = uniform(rng);
        let path_move = r >= self.p_pss + self.p_tc;
        let p = if path_move {
            self.propose_path(current, proposal, rng)
        } else {
            match self.convert_current(current, rng) {
                Err(component) => Proposal::failed(component),
                Ok(lifted) => {
                    let point = lifted.as_ref().map_or(&current.state.point, |l| &l.point);
                    let p = if r < self.p_pss {
                        self.propose_pss(point, current.log_density, proposal, rng)
                    } else {
                        self.propose_technique(point, proposal, rng)
                    };
                    if lifted.is_some() {
                        self.lifted = lifted;
                    }
                    p
                }
            }
        };
        let nanos = start.map_or(0, |s| s.elapsed().as_nanos() as u64 * TIMED_EVERY);
        let c = &mut self.local;
        c.propose_nanos += nanos;
        if path_move {
            c.path_nanos += nanos;
            c.path_proposals += 1;
        } else {
            c.pss_nanos += nanos;
            c.pss_proposals += 1;
        }
        let jump = match p.failed {
            true => 0.0,
            false => image_jump(self.scene, &current.payload, &proposal.payload),
        };
        self.last_move = (path_move, jump);
        p
    }

    fn observe(&mut self, obs: &StepObservation<'_, FusedState<'s>>) {
        if obs.accepted {
            self.current_invertible = self.proposal_invertible;
        }
        let (path_move, jump) = std::mem::take(&mut self.last_move);
        // Rounded per step (not summed in f64 and rounded once), so the
        // totals do not depend on how chains are spread over threads.
        let fixed = (obs.alpha * jump * JUMP_SCALE).round() as u64;
        if path_move {
            self.local.path_jump += fixed;
        } else {
            self.local.pss_jump += fixed;
        }
        if obs.component < self.n_pss {
            self.pss.observe(&StepObservation {
                component: obs.component,
                alpha: obs.alpha,
                accepted: obs.accepted,
                own: obs.own,
                state: &obs.state.point,
            });
        }
    }

    fn freeze(&mut self) {
        self.pss.freeze();
        self.path.freeze();
    }

    /// What a resumed chain needs to step as this one would: the
    /// probabilities of the moves (checked on restore: `auto`'s pilot must
    /// have chosen the same), the current path's round-trip outcome
    /// (drawn once per state), whether the scratch state exists (made with
    /// a draw from the chain's stream on the first round trip), the
    /// counts not yet added to [`FusedCounters`] (so the sidecar's tallies
    /// cover the whole run), then both mixtures' own words (the adaptive
    /// small step's).
    fn state_words(&self, out: &mut Vec<u64>) {
        let invertible = match self.current_invertible {
            None => 0,
            Some(false) => 1,
            Some(true) => 2,
        };
        out.extend([
            self.p_pss.to_bits(),
            self.p_tc.to_bits(),
            invertible,
            u64::from(self.scratch.is_some()),
        ]);
        out.extend(self.local.words());
        self.pss.state_words(out);
        self.path.state_words(out);
        if self.lazy {
            self.lazy_words(out);
        }
    }

    fn restore_words(&mut self, input: &mut &[u64]) -> bool {
        let Some((head, rest)) = input.split_first_chunk::<{ 4 + LocalCounts::WORDS }>() else {
            return false;
        };
        let [p_pss, p_tc, invertible, scratch] = [head[0], head[1], head[2], head[3]];
        if (p_pss, p_tc) != (self.p_pss.to_bits(), self.p_tc.to_bits()) || scratch > 1 {
            return false;
        }
        self.current_invertible = match invertible {
            0 => None,
            1 => Some(false),
            2 => Some(true),
            _ => return false,
        };
        // Its contents are never read (a round trip writes all of it
        // before it is used): only whether it exists changes the draws.
        self.scratch = (scratch == 1).then(|| {
            FusedState::untraced(
                self.scene,
                TorusPoint::fresh(mcmc_core::rng::stream_rng(0, 0)),
            )
        });
        // Beyond what a run reaches: from a forged file only, and they
        // would overflow as the resumed chain counts on.
        let counts = &head[4..];
        let unit_steps = [0, 1, 2, 7, 9].map(|i| counts[i]);
        if counts.iter().any(|&w| w > 1 << 62)
            || unit_steps.iter().any(|&k| k > crate::checkpoint::MAX_COUNT)
        {
            return false;
        }
        self.local = LocalCounts::from_words(counts);
        *input = rest;
        self.pss.restore_words(input)
            && self.path.restore_words(input)
            && (!self.lazy || self.restore_lazy_words(input))
    }

    fn component_names(&self) -> Vec<String> {
        let mut names = self.pss.component_names();
        names.push("technique change".into());
        names.extend(
            self.path
                .component_names()
                .into_iter()
                .map(|n| format!("path: {n}")),
        );
        names.extend(PATH_FAILURES.iter().map(|s| s.to_string()));
        names.push(CONVERSION_FAILURE.into());
        names
    }
}
