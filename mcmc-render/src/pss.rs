//! Primary sample space (PSS) as an `mcmc-core` state space for the renderer.
//!
//! A path is a deterministic function of an infinite vector of uniform
//! numbers. [`PssSource`] reads those numbers from a lazily grown
//! [`TorusPoint`], so the ordinary path samplers (`pt`, later `bdpt`) run
//! unchanged from a primary-sample vector. [`PssTarget`] turns a path
//! sampler into an `mcmc-core` [`Target`]: `ln π(u)` is the log luminance of
//! the path contribution, and the evaluation payload carries the splats
//! (raster position and RGB) so that they stay with the state.
//!
//! The mutations are `mcmc-core` kernels ([`Mutation::kernel`]): a
//! [`Mixture`] of a small step ([`TorusStep`] with Kelemen's or the
//! Gaussian law, or [`AdaptiveTorusStep`]) and an [`Independent`] large
//! step over [`PrimarySampleSpace`]; nothing is re-implemented here.
//!
//! # Coordinate layout
//!
//! With `streams = m`, number `i` of stream `k` is coordinate `m·i + k`
//! (pbrt-v4's `MLTSampler` uses three streams: camera, light, connection).
//! Path tracing uses one stream: coordinates 0 and 1 place the camera sample
//! on the image (uniform over the whole raster), and the path tracer's own
//! numbers follow from coordinate 2 in the order documented in
//! [`crate::integrators`].

use crate::color::Rgb;
use crate::integrators::bdpt::{
    Bdpt, Connection, SubpathBuffers, connect_in, generate_camera_subpath, generate_light_subpath,
};
use crate::integrators::path_vertex::{ConnectionBsdfs, SceneBsdfs};
use crate::integrators::pt::PathTracer;
use crate::markov::{CANDIDATE_STREAM, ChainFamily, ChainSettings, MltError};
use crate::sampling::{RandomSource, Stream, to_unit_f32};
use crate::scene::Scene;
use crate::settings::check;
use glam::Vec2;
use mcmc_core::kernel::{AdaptiveTorusStep, Independent, Kernel, Mixture, TorusStep};
use mcmc_core::rng::stream_rng;
use mcmc_core::space::{PrimarySampleSpace, SmallStep, TorusPoint};
use mcmc_core::target::{Evaluation, Target};
use std::cell::RefCell;

/// A [`RandomSource`] reading a primary-sample vector, stream by stream.
pub struct PssSource<'a> {
    point: &'a TorusPoint,
    streams: usize,
    stream: usize,
    next: [usize; 4],
}

impl<'a> PssSource<'a> {
    /// Reads `point` with `streams` interleaved streams (1 to 4), starting at
    /// stream 0.
    pub fn new(point: &'a TorusPoint, streams: usize) -> Self {
        PssSource {
            point,
            streams: streams.clamp(1, 4),
            stream: 0,
            next: [0; 4],
        }
    }

    /// Switches to stream `k` (numbers continue where that stream stopped).
    pub fn start_stream(&mut self, k: usize) {
        self.stream = k.min(self.streams - 1);
    }

    /// Numbers read so far from stream `k`.
    pub fn consumed(&self, k: usize) -> usize {
        self.next[k.min(3)]
    }
}

impl RandomSource for PssSource<'_> {
    fn set_stream(&mut self, stream: Stream) {
        self.start_stream(stream.index());
    }

    fn next_1d(&mut self) -> f32 {
        let k = self.stream;
        let i = self.next[k];
        self.next[k] += 1;
        to_unit_f32(self.point.coordinate(self.streams * i + k))
    }
}

/// One contribution of a path to the image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Splat {
    /// Raster position.
    pub p: Vec2,
    /// Radiance (RGB).
    pub l: Rgb,
    /// The class of the technique that made it, below [`PATH_CLASSES`]
    /// (RELT's path classes, [`crate::path_classes`]); 0 where a sampler
    /// does not classify.
    pub class: u8,
}

/// Number of path classes a [`Splat`] can carry.
pub const PATH_CLASSES: usize = 6;

/// What evaluating a primary-sample vector produces besides `ln π`.
#[derive(Debug, Default, PartialEq)]
pub struct PathSample {
    /// Contributions to the image (one for path tracing).
    pub splats: Vec<Splat>,
    /// Path depth used for the per-depth statistics (for path tracing: the
    /// number of surface vertices the tracer consumed numbers for).
    pub depth: u32,
}

/// Written out so that `clone_from` reuses the splats' storage (a derived
/// `Clone` replaces it with a fresh allocation): chains copy a proposal's
/// payload on every step.
impl Clone for PathSample {
    fn clone(&self) -> Self {
        PathSample {
            splats: self.splats.clone(),
            depth: self.depth,
        }
    }

    fn clone_from(&mut self, source: &Self) {
        self.splats.clone_from(&source.splats);
        self.depth = source.depth;
    }
}

impl PathSample {
    /// The scalar contribution `I(u)`: the sum of the splats' luminances.
    pub fn luminance(&self) -> f64 {
        self.splats.iter().map(|s| s.l.luminance() as f64).sum()
    }
}

/// A path sampler driven by a primary-sample vector.
pub trait PssPathSampler: Sync {
    /// Number of interleaved streams it reads.
    fn streams(&self) -> usize;
    /// Traces the path of `source`, pushing its contributions into `out`
    /// (cleared by the caller), and returns its depth.
    fn trace(&self, scene: &Scene, source: &mut PssSource<'_>, out: &mut Vec<Splat>) -> u32;
}

/// Numbers the path tracer consumes per surface vertex (see
/// [`crate::integrators`]).
const PT_NUMBERS_PER_VERTEX: usize = 7;

impl PssPathSampler for PathTracer {
    fn streams(&self) -> usize {
        1
    }

    fn trace(&self, scene: &Scene, source: &mut PssSource<'_>, out: &mut Vec<Splat>) -> u32 {
        let (w, h) = (scene.film.width as f32, scene.film.height as f32);
        let (ux, uy) = source.next_2d();
        // Keep the raster position strictly inside the image.
        let p = Vec2::new(
            (ux * w).min(w * (1.0 - f32::EPSILON)),
            (uy * h).min(h * (1.0 - f32::EPSILON)),
        );
        let (ray, lens_numbers) = if scene.camera.has_lens() {
            (scene.camera.generate_ray_lens(p, source.next_2d()), 2)
        } else {
            (scene.camera.generate_ray(p), 0)
        };
        let l = self.li(scene, ray, source);
        out.push(Splat { p, l, class: 0 });
        ((source.consumed(0) - 2 - lens_numbers) / PT_NUMBERS_PER_VERTEX) as u32
    }
}

/// A raster position uniform over the image from two numbers, strictly
/// inside it.
pub(crate) fn raster_of(scene: &Scene, source: &mut PssSource<'_>) -> Vec2 {
    let (w, h) = (scene.film.width as f32, scene.film.height as f32);
    let (ux, uy) = source.next_2d();
    Vec2::new(
        (ux * w).min(w * (1.0 - f32::EPSILON)),
        (uy * h).min(h * (1.0 - f32::EPSILON)),
    )
}

thread_local! {
    /// Per-thread subpath storage for the bidirectional samplers.
    static BUFFERS: RefCell<SubpathBuffers> = RefCell::new(SubpathBuffers::default());
}

/// PSSMLT over BDPT: every technique of one sample ([`Bdpt::sample_all`])
/// is a splat at its raster position (the camera sample is uniform over
/// the image, so `t ≥ 2` contributions are splats too). Depth: the longest
/// technique (segments) that contributed.
impl PssPathSampler for Bdpt {
    fn streams(&self) -> usize {
        Stream::COUNT
    }

    fn trace(&self, scene: &Scene, source: &mut PssSource<'_>, out: &mut Vec<Splat>) -> u32 {
        source.set_stream(Stream::Camera);
        let raster = raster_of(scene, source);
        BUFFERS.with_borrow_mut(|buffers| {
            self.sample_all(scene, raster, source, buffers, |c| {
                out.push(Splat {
                    p: c.raster,
                    l: c.l,
                    class: 0,
                });
            });
            // Longest subpaths built: an upper bound of the depth reached.
            (buffers.camera.len() + buffers.light.len()).saturating_sub(1) as u32
        })
    }
}

/// One depth of multiplexed MLT (Hachisuka et al. 2014): paths of exactly
/// `depth` segments, the technique `(s, t)` (`s + t − 1 = depth`) chosen by
/// the first number of the connection stream among the techniques BDPT
/// runs (`(1, 1)` excluded), the contribution multiplied by their number.
#[derive(Clone, Copy, Debug)]
pub struct MmltDepth {
    /// The BDPT settings (MIS heuristic, depth limits).
    pub bdpt: Bdpt,
    /// Path depth in segments (≥ 1).
    pub depth: usize,
}

impl MmltDepth {
    /// The techniques `(s, t)` of this depth, in order of increasing `s`.
    pub fn techniques(&self) -> Vec<(usize, usize)> {
        self.technique_iter().collect()
    }

    /// The techniques of [`MmltDepth::techniques`] without collecting them
    /// (every sample and every fused path-space move asks for them; a
    /// vector per call was a measurable share of their cost).
    pub fn technique_iter(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        let d = self.depth;
        (0..=d)
            .map(move |s| (s, d + 1 - s))
            .filter(|&(s, t)| t >= 1 && !(s == 1 && t == 1))
            .filter(|&(s, t)| {
                t <= self.bdpt.max_camera_vertices() && s <= self.bdpt.max_light_vertices()
            })
    }

    /// The number of techniques of this depth.
    pub fn technique_count(&self) -> usize {
        self.technique_iter().count()
    }
}

impl MmltDepth {
    /// One MMLT sample from `source` into `buffers`: the technique chosen
    /// by the connection stream's first number, its two subpaths, and the
    /// connection (MIS weight included) with the splat it makes (the
    /// contribution times the number of techniques). `None` when a subpath
    /// falls short or the connection carries nothing. The fused state
    /// space ([`crate::fused_space`]) rebuilds the path from `buffers` and
    /// the connection's sampled endpoint.
    pub fn sample_technique(
        &self,
        scene: &Scene,
        source: &mut PssSource<'_>,
        buffers: &mut SubpathBuffers,
    ) -> Option<(Connection, Splat)> {
        let mut out = [None];
        let (n, raster) =
            self.sample_technique_in(scene, &SceneBsdfs, source, buffers, &mut out)?;
        let c = out[0]?;
        Some((c, technique_splat(&c, n, raster)))
    }

    /// [`MmltDepth::sample_technique`] under every level of `bsdfs` at
    /// once (tempered MMLT): the technique, the subpaths and the
    /// connection's samples and visibility are shared, `out[k]` gets the
    /// connection with level `k`'s BSDFs at the connected vertices
    /// ([`connect_in`]). Returns the number of techniques and the camera
    /// subpath's raster position, or `None` when a subpath falls short.
    pub fn sample_technique_in<B: ConnectionBsdfs>(
        &self,
        scene: &Scene,
        bsdfs: &B,
        source: &mut PssSource<'_>,
        buffers: &mut SubpathBuffers,
        out: &mut [Option<Connection>],
    ) -> Option<(usize, Vec2)> {
        let n = self.technique_count();
        if n == 0 {
            return None;
        }
        source.set_stream(Stream::Connection);
        let k = ((source.next_1d() * n as f32) as usize).min(n - 1);
        let (s, t) = self.technique_iter().nth(k)?;
        source.set_stream(Stream::Camera);
        let raster = raster_of(scene, source);
        let nc = generate_camera_subpath(scene, raster, source, t, None, &mut buffers.camera);
        if nc != t {
            return None;
        }
        source.set_stream(Stream::Light);
        let nl = generate_light_subpath(scene, source, s, None, &mut buffers.light);
        if nl != s {
            return None;
        }
        source.set_stream(Stream::Connection);
        connect_in(
            scene,
            bsdfs,
            &buffers.camera,
            &buffers.light,
            s,
            t,
            source,
            self.bdpt.heuristic,
            out,
        );
        Some((n, raster))
    }
}

/// The splat of an MMLT connection `c` among `techniques` techniques of its
/// depth (the contribution times their number), at the camera subpath's
/// `raster` unless the connection lands elsewhere (`t = 1`).
pub fn technique_splat(c: &Connection, techniques: usize, raster: Vec2) -> Splat {
    Splat {
        p: if c.splat { c.raster } else { raster },
        l: c.l * techniques as f32,
        class: 0,
    }
}

impl PssPathSampler for MmltDepth {
    fn streams(&self) -> usize {
        Stream::COUNT
    }

    fn trace(&self, scene: &Scene, source: &mut PssSource<'_>, out: &mut Vec<Splat>) -> u32 {
        BUFFERS.with_borrow_mut(|b| {
            if let Some((_, splat)) = self.sample_technique(scene, source, b) {
                out.push(splat);
            }
        });
        self.depth as u32
    }
}

/// `ln π(u) = ln I(u)` for a path sampler on a scene.
///
/// `I(u) = 0` gives `−∞` (outside the support); a NaN or infinite
/// contribution gives NaN, which `mcmc-core` rejects and counts.
pub struct PssTarget<'a, F> {
    /// The scene.
    pub scene: &'a Scene,
    /// The path sampler.
    pub sampler: F,
}

impl<F: PssPathSampler> PssTarget<'_, F> {
    /// Traces `point` and returns its evaluation.
    pub fn trace(&self, point: &TorusPoint) -> Evaluation<PathSample> {
        let mut source = PssSource::new(point, self.sampler.streams());
        let mut splats = Vec::with_capacity(1);
        let depth = self.sampler.trace(self.scene, &mut source, &mut splats);
        let sample = PathSample { splats, depth };
        let finite = sample.splats.iter().all(|s| s.l.is_finite());
        let i = sample.luminance();
        let log_density = if !finite || !i.is_finite() {
            f64::NAN
        } else if i > 0.0 {
            i.ln()
        } else {
            f64::NEG_INFINITY
        };
        Evaluation::new(log_density, sample)
    }
}

impl<F: PssPathSampler> Target<TorusPoint> for PssTarget<'_, F> {
    type Payload = PathSample;

    fn evaluate(&self, state: &TorusPoint) -> Evaluation<PathSample> {
        self.trace(state)
    }
}

/// Which small step the chains use.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SmallStepKind {
    /// Kelemen et al. 2002 with step bounds `s1 ≤ |Δ| ≤ s2`.
    Kelemen {
        /// Smallest step (default 1/1024).
        s1: f64,
        /// Largest step (default 1/64).
        s2: f64,
    },
    /// pbrt-v4's Gaussian step.
    Gaussian {
        /// Standard deviation (default 0.01).
        sigma: f64,
    },
    /// Hachisuka & Jensen's adaptive power step (`mcmc-core`'s
    /// [`AdaptiveTorusStep`], θ₀ = 0.5, target acceptance 0.234).
    Adaptive,
    /// The fixed power step of the stratified-MCMC thesis (spec seed003
    /// §4.2, Alg. 1): `|Δ| = ξ^(1/θ + 1)`, sign ±1 with probability ½;
    /// θ = 1 (`|Δ| = ξ²`, mean 1/3) in all its SMCMC experiments.
    Hachisuka {
        /// The thesis's θ (> 0).
        theta: f64,
    },
}

/// The PSS mutation: a small step, and a large step with some probability.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mutation {
    /// The small step.
    pub small: SmallStepKind,
    /// Probability of a large (independent) step.
    pub large_step_probability: f64,
}

impl Default for Mutation {
    /// Kelemen's small step and large steps with probability 0.3.
    fn default() -> Self {
        Mutation {
            small: SmallStepKind::Kelemen {
                s1: 1.0 / 1024.0,
                s2: 1.0 / 64.0,
            },
            large_step_probability: 0.3,
        }
    }
}

/// Index of the large step among the kernel components.
pub const LARGE_STEP_COMPONENT: usize = 1;

impl Mutation {
    /// Builds the `mcmc-core` kernel: component 0 is the small step,
    /// component [`LARGE_STEP_COMPONENT`] the large step.
    pub fn kernel<P: 'static>(&self) -> mcmc_core::Result<Mixture<TorusPoint, P>> {
        let p = self.large_step_probability;
        if !(0.0..=1.0).contains(&p) {
            return Err(mcmc_core::CoreError::InvalidParameter {
                name: "large step probability",
                reason: format!("{p} must lie in [0, 1]"),
            });
        }
        let small: Box<dyn Kernel<TorusPoint, P> + Send> = match self.small {
            SmallStepKind::Kelemen { s1, s2 } => {
                Box::new(TorusStep::new(SmallStep::Kelemen { s1, s2 })?)
            }
            SmallStepKind::Gaussian { sigma } => {
                Box::new(TorusStep::new(SmallStep::Gaussian { sigma })?)
            }
            SmallStepKind::Adaptive => Box::new(AdaptiveTorusStep::standard()),
            // mcmc-core's power step is `|Δ| = v^(1/θ')`: the thesis's
            // exponent 1/θ + 1 is θ' = θ/(θ + 1).
            SmallStepKind::Hachisuka { theta } => Box::new(TorusStep::new(SmallStep::Power {
                theta: theta / (theta + 1.0),
            })?),
        };
        Mixture::new(vec![
            (1.0 - p, small),
            (p, Box::new(Independent::new(PrimarySampleSpace))),
        ])
    }
}

/// The settings of a Markov-chain render in primary sample space.
pub type PssmltSettings = ChainSettings<Mutation>;

/// A family of PSS targets over one scene: one path sampler for PSSMLT,
/// one per path depth for MMLT. Its chains move on the torus with the
/// [`Mutation`] kernel; start-up candidates are fresh uniform points.
pub struct PssFamily<'a, F> {
    /// One target per member.
    pub targets: Vec<PssTarget<'a, F>>,
}

impl<'a, F: PssPathSampler> PssFamily<'a, F> {
    /// The family of `samplers` on `scene`.
    pub fn new(scene: &'a Scene, samplers: Vec<F>) -> Self {
        PssFamily {
            targets: samplers
                .into_iter()
                .map(|sampler| PssTarget { scene, sampler })
                .collect(),
        }
    }
}

/// The primary-sample point of start-up candidate `i` of `seed`.
pub fn bootstrap_point(seed: u64, i: usize) -> TorusPoint {
    TorusPoint::fresh(stream_rng(seed, CANDIDATE_STREAM + i as u64))
}

impl<'a, F: PssPathSampler> ChainFamily for PssFamily<'a, F> {
    type State = TorusPoint;
    type Target = PssTarget<'a, F>;
    type Mutation = Mutation;
    type Kernel = Mixture<TorusPoint, PathSample>;

    fn members(&self) -> usize {
        self.targets.len()
    }
    fn target(&self, member: usize) -> &Self::Target {
        &self.targets[member]
    }
    fn kernel(&self, mutation: &Mutation, _member: usize) -> Result<Self::Kernel, MltError> {
        Ok(mutation.kernel()?)
    }
    fn independent_probability(&self, mutation: &Mutation) -> f64 {
        mutation.large_step_probability
    }
    fn checkpointable(&self, _mutation: &Mutation) -> bool {
        // Independent chains: every small step, the adaptive one's state
        // saved with its chain (`ChainRecord::kernel`).
        true
    }
    crate::primary_sample_space_family!();
}

/// The [`ChainFamily`] methods every family on primary sample space
/// shares, for use inside its `impl ChainFamily` (with `State =
/// TorusPoint` and a [`Mutation`] kernel): the large step
/// ([`LARGE_STEP_COMPONENT`]) is the independent proposal, start-up
/// candidates are [`bootstrap_point`]s, the reference density is uniform,
/// and a state's coordinates reproduce it for `--replay`.
#[macro_export]
macro_rules! primary_sample_space_family {
    () => {
        fn is_independent(&self, component: usize) -> bool {
            component == $crate::pss::LARGE_STEP_COMPONENT
        }
        fn candidate(&self, seed: u64, index: u64) -> Self::State {
            $crate::pss::bootstrap_point(seed, index as usize)
        }
        fn reference_log_density(&self, _state: &Self::State) -> f64 {
            // Uniform on the unit torus.
            0.0
        }
        fn coordinates(&self, state: &Self::State) -> Option<Vec<f64>> {
            Some(state.materialize())
        }
        fn state_words(&self, state: &Self::State, out: &mut Vec<u64>) {
            state.to_words(out);
        }
        fn state_from_words(&self, input: &mut &[u64]) -> Option<Self::State> {
            <Self::State>::from_words(input)
        }
    };
}

crate::choice! {
    /// The small step's law, by name.
    pub enum SmallStepLaw {
        /// Kelemen et al. 2002 (`s1`, `s2`).
        Kelemen = "kelemen",
        /// pbrt-v4's Gaussian (`sigma`).
        Gaussian = "gaussian",
        /// Hachisuka & Jensen's adaptive power step.
        Adaptive = "adaptive",
        /// The stratified-MCMC thesis's fixed power step (`hachisuka_theta`).
        Hachisuka = "hachisuka",
    }
}

crate::settings! {
    /// The PSS mutation's parameters, as integrators expose them.
    pub struct MutationParams {
        /// Small-step law: kelemen (Kelemen et al. 2002), gaussian (pbrt-v4), adaptive, or hachisuka (the SMCMC thesis's |Δ| = ξ^(1/θ+1)).
        pub small_step: SmallStepLaw = SmallStepLaw::Kelemen;
        /// Kelemen's smallest step.
        pub s1: f64 = 1.0 / 1024.0, check check::positive;
        /// Kelemen's largest step.
        pub s2: f64 = 1.0 / 64.0, check check::positive;
        /// Standard deviation of the Gaussian small step.
        pub sigma: f64 = 0.01, check check::positive;
        /// θ of the hachisuka small step (the thesis's 1: |Δ| = ξ²).
        pub hachisuka_theta: f64 = 1.0, check check::positive;
        /// Probability of a large (independent) step.
        pub large_step_probability: f64 = 0.3, check check::probability;
    }
}

impl MutationParams {
    /// pbrt-v4's `mlt` mutation: the Gaussian small step.
    pub fn gaussian() -> Self {
        MutationParams {
            small_step: SmallStepLaw::Gaussian,
            ..MutationParams::default()
        }
    }

    /// The mutation these parameters describe, checked (e.g. `s1 < s2`).
    pub fn mutation(&self) -> Result<Mutation, String> {
        let small = match self.small_step {
            SmallStepLaw::Kelemen => SmallStepKind::Kelemen {
                s1: self.s1,
                s2: self.s2,
            },
            SmallStepLaw::Gaussian => SmallStepKind::Gaussian { sigma: self.sigma },
            SmallStepLaw::Adaptive => SmallStepKind::Adaptive,
            SmallStepLaw::Hachisuka => SmallStepKind::Hachisuka {
                theta: self.hachisuka_theta,
            },
        };
        let mutation = Mutation {
            small,
            large_step_probability: self.large_step_probability,
        };
        mutation
            .kernel::<()>()
            .map_err(|e| format!("MLT mutation: {e}"))?;
        Ok(mutation)
    }
}
