//! Fused state spaces (Otsu et al. 2017, spec seed001): one Markov chain
//! per MMLT path depth whose state is MMLT's multiplexed primary sample
//! `[u, t]` *and* the path `x = P_t^{-1}(u)` it maps to, so that each step
//! may be a primary-sample mutation (Kelemen/Gaussian small step, large
//! step, change of technique) or any path-space mutation of
//! [`crate::path_space::PathMutations`] (the fixed-length bidirectional
//! mutation, the lens perturbation, and whatever else that mixture holds).
//!
//! - [`inverse_path`]: the two maps (`trace`, the MMLT sampler keeping its
//!   path; `invert`, the inverse path sampler) and the round trip.
//! - [`kernel`]: the mixed kernel and its acceptance ratio (Eq. 11 for
//!   primary-sample moves, Eq. 24 for path-space moves).
//! - [`technique`]: MMLT's target and technique density evaluated on a
//!   path, so that a path-space proposal is decided before it is inverted.
//!
//! The target of depth `d` is MMLT's, `π(u, t) = lum(n · w_t · C_t(u))`
//! over primary sample space ([`crate::pss::MmltDepth`]); the chain lives
//! there, so the driver's start-up, normalisation and splatting are
//! MMLT's. A path-space move is a proposal in primary sample space: map
//! `u → x`, mutate `x → y` with the path-space kernel `T_P`, map back
//! `y → v = P_t(y)` (fresh uniforms where the sampler is many-to-one). Its
//! density in `v` is `T_P(x→y) / p_t(y)` (spec seed001 §3), so the kernel
//! reports `ln T_U(v→u) − ln T_U(u→v) = ln T_P(y→x) − ln T_P(x→y) + ln
//! p_t(y) − ln p_t(x)`; with `π(v) = n w_t(y) f(y)/p_t(y)` the Metropolis–
//! Hastings ratio is Eq. 24, `w_t(y) f(y) T_P(y→x) / (w_t(x) f(x) T_P(x→y))`.
//! `p_t` is the path's density under technique `t`'s sampler, the product
//! of its light-walk and camera-walk vertex densities
//! ([`Path::log_regrowth_density`] with every vertex regrown).

pub mod inverse_path;
pub mod kernel;
pub mod technique;

use crate::markov::{ChainFamily, MltError};
use crate::path_space::{Path, PathMutations};
use crate::pss::{MmltDepth, Mutation, PathSample, PssTarget, bootstrap_point};
use crate::scene::Scene;
use inverse_path::{empty_sample, trace};
pub use kernel::{FusedCounters, FusedKernel};
use mcmc_core::space::TorusPoint;
use mcmc_core::target::{Evaluation, Target};
use std::sync::Arc;

/// A state of the fused chain: the multiplexed primary sample and the
/// cached path it maps to under one depth's sampler.
#[derive(Clone, Debug)]
pub struct FusedState<'s> {
    /// The primary sample `[u, t]` (MMLT's coordinate layout).
    pub point: TorusPoint,
    /// `P_t^{-1}(u)`, light to camera (empty when `u` carries nothing or
    /// was not traced). The kernel's traces store its vertices only;
    /// [`FusedState::traced`] also evaluates it ([`Path::evaluate`]).
    pub path: Path<'s>,
    /// The depth the cache was traced for (`None`: not traced yet).
    pub depth: Option<usize>,
    /// The technique `(s, t)` of the cached path.
    pub technique: Option<(usize, usize)>,
    /// MMLT's splat of the cached path.
    pub sample: PathSample,
    /// `ln π(u)` of the cached path (MMLT's target).
    pub log_density: f64,
    /// The state was reached by a path-space move under
    /// [`Conversion::Lazy`] and its path not yet mapped back: `point` is
    /// an earlier state's, not `P_t(path)` (the kernel converts the path
    /// before a primary-sample move reads the point).
    pub point_stale: bool,
}

impl<'s> FusedState<'s> {
    /// A state at `point`, not traced yet.
    pub fn untraced(scene: &'s Scene, point: TorusPoint) -> Self {
        FusedState {
            point,
            path: Path::new(scene),
            depth: None,
            technique: None,
            sample: empty_sample(0),
            log_density: f64::NEG_INFINITY,
            point_stale: false,
        }
    }

    /// Makes this state the evaluated path `y` of technique `s` of
    /// `depth`, not mapped back (lazy conversion): its point stale, its
    /// splat and `ln π` MMLT's computed on the path
    /// ([`technique::splat`], a trace's up to `f32` rounding).
    pub fn set_unconverted(&mut self, depth: &MmltDepth, y: &Path<'s>, s: usize) {
        self.path.clone_from(y);
        self.depth = Some(depth.depth);
        self.technique = Some((s, depth.depth + 1 - s));
        self.point_stale = true;
        self.sample.splats.clear();
        self.sample.depth = depth.depth as u32;
        self.log_density = f64::NEG_INFINITY;
        if let Some(splat) = technique::splat(depth, y, s) {
            self.log_density = inverse_path::log_luminance(splat.l);
            self.sample.splats.push(splat);
        }
    }

    /// The state at `point` traced with `depth`'s sampler, its path
    /// evaluated (densities and contribution).
    pub fn traced(scene: &'s Scene, depth: &MmltDepth, point: TorusPoint) -> Self {
        let mut s = FusedState::untraced(scene, point);
        trace(scene, depth, &mut s);
        s.path.evaluate();
        s
    }
}

/// MMLT's target of one depth, read from a state's cache when the state
/// was traced for this depth (every state the kernel proposes is), traced
/// otherwise (start-up candidates).
///
/// An untraced state is traced *in place*, as MMLT's target does: the
/// coordinates the sampler reads are drawn into the state's own lazy
/// point. Tracing a copy instead left a chain's start state without
/// coordinates, so every small step from it drew all of them fresh (an
/// independent proposal, rarely accepted from a bright start): chains
/// stuck on caustic start paths, lower small-step acceptance than MMLT's
/// and fireflies (`tests/fused_pss_moves.rs`).
pub struct FusedTarget<'s> {
    /// The scene.
    pub scene: &'s Scene,
    /// The depth's sampler.
    pub depth: MmltDepth,
}

impl<'s> Target<FusedState<'s>> for FusedTarget<'s> {
    type Payload = PathSample;

    fn evaluate(&self, state: &FusedState<'s>) -> Evaluation<PathSample> {
        if state.depth == Some(self.depth.depth) {
            return Evaluation::new(state.log_density, state.sample.clone());
        }
        PssTarget {
            scene: self.scene,
            sampler: self.depth,
        }
        .trace(&state.point)
    }
}

crate::choice! {
    /// When an accepted path-space proposal is mapped back to primary
    /// samples (docs/fused.md, "Session 22").
    pub enum Conversion {
        /// At once: every accepted path-space proposal is inverted and
        /// re-traced (its round trip), and the current path's round trip
        /// is checked too, so path-space moves stay among paths that
        /// survive it.
        Eager = "eager",
        /// Only before the next primary-sample move (the paper's): the
        /// accepted path is the state, unconverted, until a primary-sample
        /// move needs its point; a path whose conversion then fails cannot
        /// take that move (rejected, counted).
        Lazy = "lazy"
    }
}

/// The fused chain's mutation settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FusedMutation {
    /// The primary-sample mutation (small and large step).
    pub pss: Mutation,
    /// Probability of a change of technique (the connection stream's first
    /// number redrawn, everything else kept).
    pub technique_change: f64,
    /// The path-space mutations (their relative weights; the bidirectional
    /// one is made fixed-length and the independent proposal is off).
    pub path: PathMutations,
    /// Probability of a path-space mutation.
    pub path_probability: f64,
    /// A control for the tests: leave out the inverse sampler's Jacobian
    /// `p_t(y)/p_t(x)` from the path-space moves' ratio (wrong on purpose).
    pub drop_jacobian: bool,
    /// When accepted path-space proposals are converted.
    pub conversion: Conversion,
}

impl Default for FusedMutation {
    /// The `fused` integrator's defaults: MMLT's Gaussian small step with
    /// large steps at 0.3, path-space moves half of the time (the
    /// fixed-length bidirectional mutation and the lens perturbation with
    /// equal weights), no change of technique.
    fn default() -> Self {
        FusedMutation {
            pss: Mutation {
                small: crate::pss::SmallStepKind::Gaussian { sigma: 0.01 },
                large_step_probability: 0.3,
            },
            technique_change: 0.0,
            path: PathMutations {
                bidirectional: 1.0,
                fixed_length: true,
                lens_perturbation: 1.0,
                ..PathMutations::default()
            },
            path_probability: 0.5,
            drop_jacobian: false,
            conversion: Conversion::Eager,
        }
    }
}

impl FusedMutation {
    /// Checks the probabilities and the path-space mixture.
    pub fn check(&self) -> Result<(), String> {
        let (a, b) = (self.technique_change, self.path_probability);
        if !(a >= 0.0 && b >= 0.0 && a + b <= 1.0) {
            return Err(format!(
                "technique_change_probability {a} and path_space_probability {b} must be non-negative with a sum ≤ 1"
            ));
        }
        self.pss
            .kernel::<()>()
            .map_err(|e| format!("MLT mutation: {e}"))?;
        self.path_mutations().check()
    }

    /// The path-space mixture the kernel uses: fixed-length, no
    /// independent proposal (the large step is the independent move).
    pub fn path_mutations(&self) -> PathMutations {
        PathMutations {
            fixed_length: true,
            independent: 0.0,
            ..self.path
        }
    }
}

/// The fused chains of every depth `1..=max_depth` on one scene.
pub struct FusedFamily<'s> {
    /// The scene.
    pub scene: &'s Scene,
    /// One target per depth.
    pub targets: Vec<FusedTarget<'s>>,
    /// Conversion counters shared by every chain's kernel.
    pub counters: Arc<FusedCounters>,
    /// Per member, the probability of a path-space move, in place of the
    /// mutation's (`path_space_probability=auto`'s choice, fixed before
    /// the chains start); empty: the mutation's for every member.
    pub path_probabilities: Vec<f64>,
}

impl<'s> FusedFamily<'s> {
    /// The family of `depths` (MMLT's, [`crate::integrators::mmlt::Mmlt::depths`]).
    pub fn new(scene: &'s Scene, depths: Vec<MmltDepth>) -> Self {
        let max_depth = depths.iter().map(|d| d.depth).max().unwrap_or(0);
        FusedFamily {
            scene,
            targets: depths
                .into_iter()
                .map(|depth| FusedTarget { scene, depth })
                .collect(),
            counters: Arc::new(FusedCounters::new(max_depth)),
            path_probabilities: Vec::new(),
        }
    }

    /// The mutation of `member`'s chains: `mutation` with the member's own
    /// path-space probability, if it has one (never above what the change
    /// of technique leaves).
    pub fn member_mutation(&self, mutation: &FusedMutation, member: usize) -> FusedMutation {
        let mut m = *mutation;
        if let Some(&p) = self.path_probabilities.get(member) {
            m.path_probability = p.min(1.0 - m.technique_change);
        }
        m
    }
}

impl<'s> ChainFamily for FusedFamily<'s> {
    type State = FusedState<'s>;
    type Target = FusedTarget<'s>;
    type Mutation = FusedMutation;
    type Kernel = FusedKernel<'s>;

    fn members(&self) -> usize {
        self.targets.len()
    }
    fn target(&self, member: usize) -> &FusedTarget<'s> {
        &self.targets[member]
    }
    fn kernel(&self, mutation: &FusedMutation, member: usize) -> Result<Self::Kernel, MltError> {
        let mutation = self.member_mutation(mutation, member);
        mutation.check().map_err(MltError::Setting)?;
        FusedKernel::new(
            self.scene,
            self.targets[member].depth,
            &mutation,
            self.counters.clone(),
        )
        .map_err(MltError::Setting)
    }
    /// One probability for all members: with per-member path-space
    /// probabilities it is not that of every member, so the integrator
    /// refuses Kelemen's MIS (its only user) with them.
    fn independent_probability(&self, mutation: &FusedMutation) -> f64 {
        kernel::pss_probability(mutation) * mutation.pss.large_step_probability
    }
    fn is_independent(&self, component: usize) -> bool {
        component == crate::pss::LARGE_STEP_COMPONENT
    }
    fn candidate(&self, seed: u64, index: u64) -> FusedState<'s> {
        FusedState::untraced(self.scene, bootstrap_point(seed, index as usize))
    }
    fn reference_log_density(&self, _state: &FusedState<'s>) -> f64 {
        // Uniform on the unit torus.
        0.0
    }
    fn coordinates(&self, state: &FusedState<'s>) -> Option<Vec<f64>> {
        // A stale point (lazy conversion) is not the state's.
        (!state.point_stale).then(|| state.point.materialize())
    }
    fn checkpointable(&self, _mutation: &FusedMutation) -> bool {
        // A state is its point (the cached path is re-traced from it), or
        // under lazy conversion, while its point is stale, its path; a
        // kernel's own state (the current path's round-trip outcome, its
        // scratch, its counts, the adaptive small step, a lazy state's
        // conversion) is in its words.
        true
    }
    /// A converted state: the depth the cache was traced for
    /// (`UNTRACED` if none), the point ([`TorusPoint::to_words`]), and
    /// for a traced state its `ln π` (which the re-trace on resume must
    /// reproduce). An unconverted one (lazy conversion, its point stale):
    /// `UNCONVERTED`, the depth, the technique's `s`, the path
    /// ([`Path::to_words`], every field bit for bit) and its `ln π`; the
    /// stale point is not saved (nothing reads it: a primary-sample move
    /// converts the path first).
    fn state_words(&self, state: &FusedState<'s>, out: &mut Vec<u64>) {
        if state.point_stale {
            let depth = state.depth.expect("an unconverted state is evaluated");
            let (s, _) = state
                .technique
                .expect("an unconverted state has a technique");
            out.extend([UNCONVERTED, depth as u64, s as u64]);
            state.path.to_words(out);
            out.push(state.log_density.to_bits());
            return;
        }
        out.push(state.depth.map_or(UNTRACED, |d| d as u64));
        state.point.to_words(out);
        if state.depth.is_some() {
            out.push(state.log_density.to_bits());
        }
    }
    /// The state [`ChainFamily::state_words`] wrote: an untraced state as
    /// it was; a traced one re-traced from its point with its depth's
    /// sampler (a trace is a function of the point), refused unless the
    /// depth is one of the family's, the re-trace reads no coordinate
    /// the point lacks (or had not brought up to date) and reproduces
    /// `ln π` bit for bit; an unconverted one evaluated from its path,
    /// refused unless the path decodes ([`Path::from_words`]: the scene's,
    /// its own evaluation reproducing it), has the depth's length, and
    /// its splat reproduces `ln π` bit for bit — so a forged or foreign
    /// state is refused before a mutation reads it.
    fn state_from_words(&self, input: &mut &[u64]) -> Option<FusedState<'s>> {
        let (&depth, rest) = input.split_first()?;
        if depth == UNCONVERTED {
            return self.unconverted_from_words(input);
        }
        let mut words = rest;
        let point = TorusPoint::from_words(&mut words)?;
        if depth == UNTRACED {
            *input = words;
            return Some(FusedState::untraced(self.scene, point));
        }
        let (&log_density, rest) = words.split_first()?;
        let target = self.target_of_depth(depth)?;
        let mut before = Vec::new();
        point.to_words(&mut before);
        let mut state = FusedState::untraced(self.scene, point);
        inverse_path::trace(self.scene, &target.depth, &mut state);
        let mut after = Vec::new();
        state.point.to_words(&mut after);
        if before != after || state.log_density.to_bits() != log_density {
            return None;
        }
        *input = rest;
        Some(state)
    }
}

impl<'s> FusedFamily<'s> {
    /// The target of path depth `depth`, if the family has it.
    fn target_of_depth(&self, depth: u64) -> Option<&FusedTarget<'s>> {
        self.targets.iter().find(|t| t.depth.depth as u64 == depth)
    }

    /// An unconverted state as [`ChainFamily::state_words`] wrote it
    /// (from its [`UNCONVERTED`] word on).
    fn unconverted_from_words(&self, input: &mut &[u64]) -> Option<FusedState<'s>> {
        let [_, depth, s] = *input.first_chunk::<3>()?;
        let mut words = &input[3..];
        let target = self.target_of_depth(depth)?;
        let depth = &target.depth;
        let s = usize::try_from(s).ok().filter(|&s| s <= depth.depth)?;
        let path = Path::from_words(self.scene, &mut words)?;
        let (&log_density, rest) = words.split_first()?;
        if path.segments() != depth.depth {
            return None;
        }
        // The point is never read while the state is unconverted.
        let stale = TorusPoint::fresh(mcmc_core::rng::stream_rng(0, 0));
        let mut state = FusedState::untraced(self.scene, stale);
        state.set_unconverted(depth, &path, s);
        if state.log_density.to_bits() != log_density {
            return None;
        }
        *input = rest;
        Some(state)
    }
}

/// [`FusedFamily`]'s first state word for a state whose path is not traced.
const UNTRACED: u64 = u64::MAX;

/// [`FusedFamily`]'s first state word for an unconverted state (lazy
/// conversion): its path follows, not its point.
const UNCONVERTED: u64 = u64::MAX - 1;
