//! Path space on the Markov-chain driver: one target (`I = lum f`), or two
//! with the unconnectable paths apart ([`super::unconnectable_chains`]),
//! the mutation mixture, and start-up candidates drawn by bidirectional
//! techniques.
//!
//! # Start-up candidates and their reference density
//!
//! A candidate picks its length `k` (uniform on `min..=max` segments, or
//! `P(k) = 2^{−(k−min+1)}` when the depth is unbounded; `min` is 1, or 3
//! with `mlt`'s direct-lighting pass), a split `s` uniform over
//! `[s_min, k]` (`s` light-walk vertices, `t = k + 1 − s ≥ 1` camera-walk
//! vertices; `s_min = 1` when no emitter can be hit), grows both walks and
//! connects them: one sample of one BDPT technique. Its reference density
//! is that of the whole procedure, `P(k) · 1/#s · Σ_s p_s(x)` (the sum over
//! every technique that could have drawn the path, as in the bidirectional
//! mutation with everything deleted), so the driver's importance weights
//! `I(x)/p₀(x)` are the one-sample MIS (balance heuristic) estimate of
//! `b = ∫ I dμ`. The driver resamples the chains' start states from these
//! candidates in proportion to the weights.

use super::bdpt_startup::SEARCH_INDEX;
use super::bidirectional::Bidirectional;
use super::caustic_perturbation::{CausticPerturbation, caustic_chain};
use super::independent::IndependentPath;
use super::lens_perturbation::{LensPerturbation, OffsetKernel, lens_chain};
use super::lens_subpath::LensSubpath;
use super::manifold_perturbation::{ManifoldPerturbation, selections as manifold_selections};
use super::multi_chain_perturbation::{MultiChainPerturbation, multi_chain};
use super::proposal_clock::{ProposalClock, Timed};
use super::state::{Path, PathTarget};
use super::walk::{ChainSource, camera_walk, camera_walks_reach_emitters, light_walk};
use crate::markov::{CANDIDATE_STREAM, ChainFamily, ContinuedSearch, MltError, Search, StartupCut};
use crate::pss::PathSample;
use crate::scene::Scene;
use mcmc_core::kernel::{Kernel, Mixture};
use mcmc_core::math::log_sum_exp;
use mcmc_core::rng::{ChainRng, stream_rng, uniform};
use std::sync::Arc;

/// The mutation mixture: one selection weight per mutation type
/// (normalised over the types with non-zero weight). Mitsuba 0.6's `mlt`
/// turns on the bidirectional mutation and the lens, caustic and
/// multi-chain perturbations, which all exist; [`PathMutations::kernel`]
/// refuses a non-zero weight for the mutations not built yet.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathMutations {
    /// Weight of Veach's bidirectional mutation.
    pub bidirectional: f64,
    /// Keep path lengths fixed in the bidirectional mutation (seed 001's
    /// variant) instead of Veach's length-changing move.
    pub fixed_length: bool,
    /// Weight of the lens perturbation ([`LensPerturbation`]).
    pub lens_perturbation: f64,
    /// Weight of the caustic perturbation ([`CausticPerturbation`]).
    pub caustic_perturbation: f64,
    /// Weight of the multi-chain perturbation ([`MultiChainPerturbation`]).
    pub multi_chain_perturbation: f64,
    /// Weight of the manifold perturbation ([`ManifoldPerturbation`]).
    pub manifold_perturbation: f64,
    /// Weight of Veach's lens subpath mutation ([`LensSubpath`]; not in
    /// Mitsuba).
    pub lens_subpath: f64,
    /// Weight of the independent proposal ([`IndependentPath`]: a fresh
    /// start-up candidate; not in Mitsuba).
    pub independent: f64,
    /// Mitsuba 0.6's suitability selection: a mutation whose pattern the
    /// current path does not match is not selected, the weights are
    /// renormalised over the applicable ones, and since the selection
    /// then depends on the path, `ln p_k(y) − ln p_k(x)` enters the
    /// proposal ratio ([`Mixture::state_dependent`]). Off: fixed
    /// probabilities, an inapplicable mutation fails as a pattern mismatch.
    pub suitability: bool,
    /// The perturbations' film-offset sizes (`None`: Mitsuba's for the
    /// path's film).
    pub sizes: PerturbationSizes,
}

/// The film-offset kernels of the perturbations (`r₁`, `r₂` in pixels;
/// `None`: Mitsuba 0.6's, `r₁` = 0.1 and `r₂ = √(0.05 · pixels / π)`).
/// The caustic and multi-chain perturbations derive their angle sizes
/// from theirs.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PerturbationSizes {
    /// The lens perturbation's.
    pub lens: Option<OffsetKernel>,
    /// The caustic perturbation's.
    pub caustic: Option<OffsetKernel>,
    /// The multi-chain perturbation's.
    pub multi_chain: Option<OffsetKernel>,
    /// The manifold perturbation's (when its moved vertex is the camera's).
    pub manifold: Option<OffsetKernel>,
}

impl PerturbationSizes {
    /// The kernel of settings `min`, `max` (pixels): both −1 for
    /// Mitsuba's, or `0 < min < max` (`name` names them in the error).
    pub fn from_setting(name: &str, min: f64, max: f64) -> Result<Option<OffsetKernel>, String> {
        if min == -1.0 && max == -1.0 {
            return Ok(None);
        }
        if !(min.is_finite() && max.is_finite() && min > 0.0 && max > min) {
            return Err(format!(
                "{name}_min = {min} and {name}_max = {max} (pixels) must satisfy 0 < min < max, or both be -1 (Mitsuba's sizes)"
            ));
        }
        Ok(Some(OffsetKernel { r1: min, r2: max }))
    }
}

/// Kernel component of the independent proposal: the mixture always holds
/// the bidirectional mutation's components (the mutation and its six
/// failure reasons) first, then the independent proposal (weight 0 when
/// off), then any later mutation.
pub const INDEPENDENT_COMPONENT: usize = 7;

impl Default for PathMutations {
    /// The bidirectional mutation alone, length-changing.
    fn default() -> Self {
        PathMutations {
            bidirectional: 1.0,
            fixed_length: false,
            lens_perturbation: 0.0,
            caustic_perturbation: 0.0,
            multi_chain_perturbation: 0.0,
            manifold_perturbation: 0.0,
            lens_subpath: 0.0,
            independent: 0.0,
            suitability: false,
            sizes: PerturbationSizes::default(),
        }
    }
}

impl PathMutations {
    /// Checks the weights ([`PathMutations::check_weights`]) and that the
    /// bidirectional mutation is on (ergodicity of long chains).
    pub fn check(&self) -> Result<(), String> {
        self.check_weights()?;
        if !(self.bidirectional > 0.0) {
            // The perturbations keep the path's length and its light end:
            // without the bidirectional mutation the chain is not ergodic.
            return Err(format!(
                "bidirectional_mutation = {} must be positive: the perturbations alone do not reach every path",
                self.bidirectional
            ));
        }
        Ok(())
    }

    /// [`PathMutations::check`] without requiring the bidirectional
    /// mutation: for short chains restarted from independent seeds
    /// (`erpt`), which need not reach every path.
    pub fn check_weights(&self) -> Result<(), String> {
        let weights = [
            ("bidirectional_mutation", self.bidirectional),
            ("independent_mutation", self.independent),
            ("lens_perturbation", self.lens_perturbation),
            ("caustic_perturbation", self.caustic_perturbation),
            ("multi_chain_perturbation", self.multi_chain_perturbation),
            ("lens_subpath_mutation", self.lens_subpath),
            ("manifold_perturbation", self.manifold_perturbation),
        ];
        for (name, w) in weights {
            if !(w.is_finite() && w >= 0.0) {
                return Err(format!("{name} = {w} must be finite and non-negative"));
            }
        }
        Ok(())
    }

    /// The `mcmc-core` kernel for paths of at most `max_segments` segments
    /// (`None`: unbounded): a [`Mixture`] of the enabled mutations.
    pub fn kernel<'s>(
        &self,
        max_segments: Option<usize>,
    ) -> Result<Mixture<Path<'s>, PathSample>, String> {
        self.kernel_between(1, max_segments)
    }

    /// [`PathMutations::kernel`] for paths of `min_segments ..=
    /// max_segments` segments (`mlt`'s direct-lighting pass leaves the
    /// paths of one and two segments to path tracing). Checks the weights
    /// ([`PathMutations::check_weights`]); whether the mixture must be
    /// ergodic ([`PathMutations::check`]) is the integrator's to check.
    pub fn kernel_between<'s>(
        &self,
        min_segments: usize,
        max_segments: Option<usize>,
    ) -> Result<Mixture<Path<'s>, PathSample>, String> {
        self.kernel_timed(min_segments, max_segments, None)
    }

    /// [`PathMutations::kernel_between`] with each mutation type's
    /// proposals counted and sampled into `clock` when given
    /// ([`ProposalClock`]; the chains' random numbers are unchanged).
    pub fn kernel_timed<'s>(
        &self,
        min_segments: usize,
        max_segments: Option<usize>,
        clock: Option<&Arc<ProposalClock>>,
    ) -> Result<Mixture<Path<'s>, PathSample>, String> {
        self.kernel_with(min_segments, max_segments, clock, false)
    }

    /// [`PathMutations::kernel_timed`], its independent proposal drawing
    /// by the camera walk alone when `camera_walks`
    /// ([`IndependentPath::camera_walks`]).
    fn kernel_with<'s>(
        &self,
        min_segments: usize,
        max_segments: Option<usize>,
        clock: Option<&Arc<ProposalClock>>,
        camera_walks: bool,
    ) -> Result<Mixture<Path<'s>, PathSample>, String> {
        self.check_weights()?;
        let bidirectional = part(
            Bidirectional::new(min_segments, max_segments, self.fixed_length),
            clock,
        );
        let independent = part(
            IndependentPath {
                min_segments,
                max_segments,
                camera_walks,
            },
            clock,
        );
        // The independent proposal stays at its component index even with
        // weight 0 (INDEPENDENT_COMPONENT); new mutations come after it.
        let always: Applies = |_| true;
        let mut parts = vec![
            (self.bidirectional, always, bidirectional),
            (self.independent, always, independent),
        ];
        if self.lens_perturbation > 0.0 {
            parts.push((
                self.lens_perturbation,
                |x| lens_chain(x).is_some(),
                part(LensPerturbation::new(self.sizes.lens), clock),
            ));
        }
        if self.caustic_perturbation > 0.0 {
            parts.push((
                self.caustic_perturbation,
                |x| caustic_chain(x).is_some(),
                part(CausticPerturbation::new(self.sizes.caustic), clock),
            ));
        }
        if self.multi_chain_perturbation > 0.0 {
            parts.push((
                self.multi_chain_perturbation,
                |x| multi_chain(x).is_some(),
                part(MultiChainPerturbation::new(self.sizes.multi_chain), clock),
            ));
        }
        if self.lens_subpath > 0.0 {
            parts.push((
                self.lens_subpath,
                |x| lens_chain(x).is_some(),
                part(LensSubpath::default(), clock),
            ));
        }
        if self.manifold_perturbation > 0.0 {
            parts.push((
                self.manifold_perturbation,
                |x| !manifold_selections(x).is_empty(),
                part(
                    ManifoldPerturbation {
                        offsets: self.sizes.manifold,
                        ..ManifoldPerturbation::default()
                    },
                    clock,
                ),
            ));
        }
        if !self.suitability {
            let parts = parts.into_iter().map(|(w, _, k)| (w, k)).collect();
            return Mixture::new(parts).map_err(|e| e.to_string());
        }
        let mut selection = Vec::with_capacity(parts.len());
        let mut kernels = Vec::with_capacity(parts.len());
        for (w, applies, k) in parts {
            selection.push((w, applies));
            kernels.push(k);
        }
        Mixture::state_dependent(kernels, move |x: &Path| suitable_weights(&selection, x))
            .map_err(|e| e.to_string())
    }

    /// The probability that the mixture proposes independently.
    pub fn independent_probability(&self) -> f64 {
        self.independent
            / (self.bidirectional
                + self.independent
                + self.lens_perturbation
                + self.caustic_perturbation
                + self.multi_chain_perturbation
                + self.lens_subpath
                + self.manifold_perturbation)
    }
}

/// Whether a mutation type can move a path (its pattern test).
type Applies = fn(&Path<'_>) -> bool;

/// The suitability selection's weights at `x`: each type's weight where
/// it applies, 0 elsewhere (the mixture normalises them).
pub fn suitable_weights(selection: &[(f64, Applies)], x: &Path<'_>) -> Vec<f64> {
    selection
        .iter()
        .map(|&(w, applies)| if w > 0.0 && applies(x) { w } else { 0.0 })
        .collect()
}

/// `kernel` boxed for a mixture, wrapped in [`Timed`] when `clock` is
/// given.
fn part<'s, K>(
    kernel: K,
    clock: Option<&Arc<ProposalClock>>,
) -> Box<dyn Kernel<Path<'s>, PathSample> + Send>
where
    K: Kernel<Path<'s>, PathSample> + Send + 'static,
{
    match clock {
        Some(c) => {
            let name = kernel.component_names().swap_remove(0);
            Box::new(Timed::new(kernel, name, c.clone()))
        }
        None => Box::new(kernel),
    }
}

/// Path space over one scene as a [`ChainFamily`]: one member, or two with
/// [`PathFamily::with_unconnectable_chains`] (member 1 then samples the
/// unconnectable paths through a non-Dirac vertex, member 0 the rest).
pub struct PathFamily<'s> {
    /// The scene.
    pub scene: &'s Scene,
    /// Longest path in segments (`None`: unbounded).
    pub max_segments: Option<usize>,
    /// Shortest path in segments (≥ 1).
    pub min_segments: usize,
    target: PathTarget,
    hittable_emitters: bool,
    clock: Option<Arc<ProposalClock>>,
    bdpt_startup: u64,
    /// The second member's target and its continued search's draws per
    /// mutation ([`PathFamily::with_unconnectable_chains`]).
    unconnectable: Option<(PathTarget, f64)>,
}

impl<'s> PathFamily<'s> {
    /// The family on `scene` with paths of at most `max_segments` segments.
    pub fn new(scene: &'s Scene, max_segments: Option<usize>) -> Self {
        Self::between(scene, 1, max_segments)
    }

    /// The family on `scene` with paths of `min_segments ..= max_segments`
    /// segments.
    pub fn between(scene: &'s Scene, min_segments: usize, max_segments: Option<usize>) -> Self {
        PathFamily {
            scene,
            max_segments,
            min_segments: min_segments.max(1),
            target: PathTarget::default(),
            hittable_emitters: camera_walks_reach_emitters(scene),
            clock: None,
            bdpt_startup: 0,
            unconnectable: None,
        }
    }

    /// The family with the start-up of [`super::bdpt_startup`]: `draws`
    /// BDPT draws, every technique of each, in place of the driver's
    /// bootstrap. Unchanged (the ordinary start-up) when the depth is
    /// unbounded or longer than [`super::bdpt_startup::MAX_SEARCH_SEGMENTS`]
    /// or `draws` is 0; [`PathFamily::has_bdpt_startup`] tells which.
    pub fn with_bdpt_startup(self, draws: u64) -> Self {
        let bounded = self
            .max_segments
            .is_some_and(|m| m <= super::bdpt_startup::MAX_SEARCH_SEGMENTS);
        PathFamily {
            bdpt_startup: if bounded { draws } else { 0 },
            ..self
        }
    }

    /// Whether the start-up is [`super::bdpt_startup`]'s.
    pub fn has_bdpt_startup(&self) -> bool {
        self.bdpt_startup > 0
    }

    /// The family with the specular chains left out of its target
    /// ([`PathTarget::without_specular_chains`]; `mlt`'s specular-chain
    /// pass renders them).
    pub fn without_specular_chains(self) -> Self {
        PathFamily {
            target: PathTarget {
                without_specular_chains: true,
                ..self.target
            },
            ..self
        }
    }

    /// The family with every unconnectable path left out of its target
    /// ([`PathTarget::without_unconnectable`]; `mlt`'s specular-chain pass
    /// with `unconnectable_pass` renders them).
    pub fn without_unconnectable(self) -> Self {
        PathFamily {
            target: PathTarget {
                without_unconnectable: true,
                ..self.target
            },
            ..self
        }
    }

    /// The family with a second member whose chains sample the
    /// unconnectable paths through a non-Dirac vertex, `L S+ (D S+)* E`
    /// ([`PathTarget::only_unconnectable`]), and member 0 without them:
    /// see [`super::unconnectable_chains`]. `search_rate` is the number of
    /// camera-walk draws per member-1 mutation that refine its `b`
    /// while the chains run. Unchanged when no camera walk can hit an
    /// emitter (there are no such paths then), or when the depth is
    /// unbounded or longer than [`super::bdpt_startup::MAX_SEARCH_SEGMENTS`]
    /// (the draws are the BDPT search's).
    pub fn with_unconnectable_chains(self, search_rate: f64) -> Self {
        let bounded = self
            .max_segments
            .is_some_and(|m| m <= super::bdpt_startup::MAX_SEARCH_SEGMENTS);
        if !self.hittable_emitters || !bounded {
            return self;
        }
        let only = PathTarget {
            only_unconnectable: true,
            ..PathTarget::default()
        };
        PathFamily {
            target: PathTarget {
                without_unconnectable_through_non_dirac: true,
                ..self.target
            },
            unconnectable: Some((only, search_rate)),
            ..self
        }
    }

    /// The family with its chains' proposals timed into `clock` per
    /// mutation type ([`ProposalClock`]).
    pub fn timed(self, clock: Arc<ProposalClock>) -> Self {
        PathFamily {
            clock: Some(clock),
            ..self
        }
    }

    /// `P(k)` of a start-up candidate's length: uniform on `min..=max`,
    /// `2^{−(k − min + 1)}` when unbounded.
    fn length_probability(&self, k: usize) -> f64 {
        let min = self.min_segments;
        match self.max_segments {
            Some(m) if k >= min && k <= m => 1.0 / (m + 1 - min) as f64,
            Some(_) => 0.0,
            None if k >= min => 0.5f64.powi((k + 1 - min).min(1100) as i32),
            None => 0.0,
        }
    }

    /// Smallest split `s` of a candidate.
    pub(super) fn s_min(&self) -> usize {
        usize::from(!self.hittable_emitters)
    }

    /// Draws a start-up candidate with `rng` (see the module docs); a
    /// candidate that failed has zero contribution.
    pub fn draw_candidate(&self, rng: &mut ChainRng) -> Path<'s> {
        let mut path = Path::new(self.scene);
        let Some(k) = self.draw_length(rng) else {
            return path;
        };
        let s_min = self.s_min();
        if s_min > k {
            return path;
        }
        let count = k - s_min + 1;
        let s = s_min + ((uniform(rng) * count as f64) as usize).min(count - 1);
        let t = k + 1 - s;
        let (mut light, mut camera) = (Vec::new(), Vec::new());
        let mut source = ChainSource::new(rng);
        if camera_walk(self.scene, &mut source, t, &mut camera) != t {
            return path;
        }
        if s > 0 && light_walk(self.scene, &mut source, s, &mut light) != s {
            return path;
        }
        path.assign_subpaths(&light, &camera);
        let joined =
            s == 0 || (path.connectible(s - 1) && path.connectible(s) && path.edge_visible(s - 1));
        if !joined {
            path.contribution = crate::color::Rgb::BLACK;
        }
        path
    }

    /// A candidate's length `k` drawn with `rng` (`P(k)`:
    /// [`PathFamily::length_probability`]), `None` when no length is allowed.
    fn draw_length(&self, rng: &mut ChainRng) -> Option<usize> {
        let min = self.min_segments;
        match self.max_segments {
            Some(m) if m < min => None,
            Some(m) => {
                let count = m + 1 - min;
                Some(min + ((uniform(rng) * count as f64) as usize).min(count - 1))
            }
            None => {
                let mut k = min;
                while k < min + 1100 && uniform(rng) < 0.5 {
                    k += 1;
                }
                Some(k)
            }
        }
    }

    /// Draws a candidate as [`PathFamily::draw_candidate`] does with the
    /// split `s = 0`: a length `k`, then a camera walk of `k + 1` vertices
    /// that must end on an emitter. Needs walks that can hit emitters.
    pub fn draw_camera_candidate(&self, rng: &mut ChainRng) -> Path<'s> {
        let mut path = Path::new(self.scene);
        let Some(k) = self.draw_length(rng) else {
            return path;
        };
        let mut camera = Vec::new();
        let mut source = ChainSource::new(rng);
        if camera_walk(self.scene, &mut source, k + 1, &mut camera) != k + 1 {
            return path;
        }
        path.assign_subpaths(&[], &camera);
        path
    }

    /// `ln` of [`PathFamily::draw_camera_candidate`]'s density at `x`:
    /// `ln P(k) + ln p_0(x)`.
    pub fn log_camera_candidate_density(&self, path: &Path<'_>) -> f64 {
        let k = path.segments();
        if path.len() < 2 {
            return f64::NEG_INFINITY;
        }
        self.length_probability(k).ln() + path.log_regrowth_density(0, k, 0)
    }

    /// `ln I(x)` of member `member`'s target.
    pub(super) fn target_log_density(&self, member: usize, path: &Path<'_>) -> f64 {
        self.member_target(member).log_density(path)
    }

    /// Whether `member` is the unconnectable paths' member
    /// ([`PathFamily::with_unconnectable_chains`]).
    fn is_unconnectable_member(&self, member: usize) -> bool {
        member == 1 && self.unconnectable.is_some()
    }

    /// The target of member `member` (1: the unconnectable paths).
    fn member_target(&self, member: usize) -> &PathTarget {
        match (member, &self.unconnectable) {
            (1, Some((only, _))) => only,
            _ => &self.target,
        }
    }

    /// The continued search's draws per mutation of member 1, if the
    /// family has that member.
    pub(super) fn unconnectable_search_rate(&self) -> Option<f64> {
        self.unconnectable.map(|(_, rate)| rate)
    }

    /// `ln Σ_s p_s(x)`: the densities of every start-up technique that
    /// could have drawn `x` (−∞ for none).
    pub(super) fn log_technique_sum(&self, path: &Path<'_>) -> f64 {
        let k = path.segments();
        let s_min = self.s_min();
        if path.len() < 2 || s_min > k {
            return f64::NEG_INFINITY;
        }
        let terms: Vec<f64> = (s_min..=k)
            .map(|s| path.log_regrowth_density(0, k, s))
            .collect();
        log_sum_exp(&terms)
    }

    /// `ln p₀(x)`, the density of [`PathFamily::draw_candidate`] at `x`.
    pub fn log_candidate_density(&self, path: &Path<'_>) -> f64 {
        let k = path.segments();
        let s_min = self.s_min();
        if path.len() < 2 || s_min > k {
            return f64::NEG_INFINITY;
        }
        self.length_probability(k).ln() - ((k - s_min + 1) as f64).ln()
            + self.log_technique_sum(path)
    }
}

impl<'s> ChainFamily for PathFamily<'s> {
    type State = Path<'s>;
    type Target = PathTarget;
    type Mutation = PathMutations;
    type Kernel = Mixture<Path<'s>, PathSample>;

    fn members(&self) -> usize {
        1 + usize::from(self.unconnectable.is_some())
    }
    fn target(&self, member: usize) -> &PathTarget {
        self.member_target(member)
    }
    fn kernel(&self, mutation: &PathMutations, member: usize) -> Result<Self::Kernel, MltError> {
        // Long chains must be ergodic (check), unlike erpt's short ones.
        mutation.check().map_err(MltError::Setting)?;
        // Member 1's paths are drawn by the camera walk alone, so its
        // independent proposal draws by it (#s times as often as a
        // candidate of a random technique).
        let camera_walks = self.is_unconnectable_member(member);
        mutation
            .kernel_with(
                self.min_segments,
                self.max_segments,
                self.clock.as_ref(),
                camera_walks,
            )
            .map_err(MltError::Setting)
    }
    fn independent_probability(&self, mutation: &PathMutations) -> f64 {
        // Without the independent proposal the running normalisation rests
        // on the start-up candidates alone.
        mutation.independent_probability()
    }
    fn is_independent(&self, component: usize) -> bool {
        component == INDEPENDENT_COMPONENT
    }
    fn candidate(&self, seed: u64, index: u64) -> Path<'s> {
        if index >= SEARCH_INDEX {
            return self.search_candidate(seed, index);
        }
        self.draw_candidate(&mut stream_rng(seed, CANDIDATE_STREAM + index))
    }
    fn reference_log_density(&self, state: &Path<'s>) -> f64 {
        self.log_candidate_density(state)
    }
    fn weighed_candidate(&self, member: usize, state: &Path<'s>) -> (f64, PathSample) {
        let e = mcmc_core::target::Target::evaluate(self.member_target(member), state);
        if e.log_density == f64::NEG_INFINITY {
            return (f64::NEG_INFINITY, e.payload);
        }
        let log_p = self.log_candidate_density(state);
        if !log_p.is_finite() {
            // A drawn path whose density rounds to zero: an invalid
            // candidate (counted), not an infinite weight.
            return (f64::NAN, e.payload);
        }
        (e.log_density - log_p, e.payload)
    }
    fn coordinates(&self, _state: &Path<'s>) -> Option<Vec<f64>> {
        None
    }
    fn checkpointable(&self, _mutation: &PathMutations) -> bool {
        // No path-space mutation keeps state from one step to the next:
        // each builds its proposal afresh from the current path and the
        // chain's stream (the bidirectional mutation's record is of the
        // step in flight; `Timed`'s clock holds timings, not draws).
        true
    }
    fn state_words(&self, state: &Path<'s>, out: &mut Vec<u64>) {
        state.to_words(out);
    }
    fn state_from_words(&self, input: &mut &[u64]) -> Option<Path<'s>> {
        let max = self.max_segments.unwrap_or(usize::MAX);
        Path::from_words(self.scene, input)
            .filter(|p| (self.min_segments..=max).contains(&p.segments()))
    }
    fn search(&self, member: usize, seed: u64, cut: &StartupCut) -> Option<Search> {
        (self.bdpt_startup > 0)
            .then(|| self.bdpt_search(member, seed, self.bdpt_startup, cut))
            .flatten()
    }
    fn continued_search(&self, member: usize) -> Option<ContinuedSearch> {
        (member == 1)
            .then(|| self.unconnectable_search_rate())
            .flatten()
            .filter(|&rate| rate > 0.0)
            .map(|per_mutation| ContinuedSearch {
                per_mutation,
                unit: super::unconnectable_chains::SEARCH_UNIT,
                first_index: super::unconnectable_chains::FIRST_CONTINUED_DRAW,
            })
    }
    fn running_is_search_only(&self, member: usize) -> bool {
        // Member 1's independent proposals draw by the camera walk alone
        // (`kernel`), not from the reference measure.
        self.is_unconnectable_member(member)
    }
    fn search_unit(&self, _member: usize, seed: u64, first: u64) -> Vec<f64> {
        self.unconnectable_draws(seed, first)
    }
}
