//! Integrators, one file each, in one [`registry`].
//!
//! Each file declares its settings struct (plain data with documented
//! defaults, see [`crate::settings!`]) and implements
//! [`registry::IntegratorSettings`] for it: a name, a one-line description
//! and how to render with those settings. Two drivers do the rendering:
//!
//! - the per-pixel driver ([`crate::render`]) runs the Monte Carlo
//!   integrators (`pt`, `lt`, `bdpt`), one sample at a time through the
//!   per-sample [`Integrator`] interface below (`vcm` runs its own loop of
//!   iterations, each a light pass and a camera pass, see [`vcm`]);
//! - the Markov-chain driver ([`crate::markov`]) runs every Metropolis-type
//!   integrator (`pssmlt`, `mmlt`) from a [`crate::markov::ChainFamily`].
//!
//! Library users render through [`registry::configure`] (or an
//! integrator's settings struct directly) and
//! [`registry::Configured::render`]; `docs/architecture.md` says how to add
//! an integrator.
//!
//! # Order in which random numbers are consumed
//!
//! Every number comes from the [`RandomSource`] passed to
//! [`Integrator::sample`] (or [`Integrator::render_pixels`], which draws
//! the same numbers as that many `sample` calls), in exactly this order. A fixed number of draws
//! per vertex is consumed whether or not a technique applies (e.g. the
//! light-sampling numbers at a specular vertex), so dimension `k` of a
//! primary-sample vector always feeds the same decision.
//!
//! **Path tracing** ([`pt`]):
//! 1. `next_2d`: position inside the pixel (x, then y); for a thin-lens
//!    camera only, `next_2d`: the lens point.
//! 2. For each surface vertex that is not the last one allowed by
//!    `max_depth`, 7 numbers:
//!    - `next_1d`: light selection (next-event estimation);
//!    - `next_2d`: position on the light;
//!    - `next_1d`: BSDF lobe choice;
//!    - `next_2d`: BSDF direction;
//!    - `next_1d`: Russian roulette (always drawn, used from `rr_depth` on).
//!
//! **Light tracing** ([`lt`]):
//! 1. `next_1d`: light selection; `next_2d`: position on the light;
//!    `next_2d`: emitted direction.
//! 2. For each surface vertex from which the path may continue, 4 numbers:
//!    - `next_1d`: BSDF lobe choice; `next_2d`: BSDF direction;
//!    - `next_1d`: Russian roulette.
//!
//!    The connection to the pinhole camera uses no numbers; to a thin lens,
//!    each attempted connection first draws `next_2d` (the lens point).
//!
//! **Bidirectional path tracing** ([`bdpt`]): three streams (camera, light,
//! connection); see the module documentation there.

pub mod bdpt;
pub mod chain_passes;
pub mod erpt;
pub mod fused;
pub mod guided;
pub mod lt;
pub mod mcmc_pg;
pub mod mcmc_vcm;
pub mod mept;
pub mod mlt;
pub mod mmlt;
pub mod path_vertex;
pub mod pssmlt;
pub mod pt;
pub mod registry;
pub mod relt;
pub mod smcmc;
pub mod tempered_mmlt;
pub mod tempered_pssmlt;
pub mod vcm;

use crate::color::Rgb;
use crate::film::Film;
use crate::markov::MltError;
use crate::pss_dump::PssDump;
use crate::sampling::{PixelSource, RandomSource};
use crate::scene::Scene;
use glam::Vec2;
use serde_json::{Map, Value};
use std::time::Duration;

/// The budget and seed of one render, whatever the integrator.
#[derive(Clone, Debug)]
pub struct RunSettings {
    /// Samples per pixel for the per-pixel integrators (light paths per
    /// pixel for `lt`). `None`: until the time budget is spent, or the
    /// scene's `sample_count` without one. (Metropolis integrators take
    /// their budget from their `mutations_per_pixel` setting.)
    pub spp: Option<u32>,
    /// Wall-clock budget.
    pub time_budget: Option<Duration>,
    /// Seed of every random stream.
    pub seed: u64,
    /// Least time between two [`crate::observer::Observer::snapshot`]s of
    /// the Markov-chain driver (the per-pixel driver offers one per pass).
    pub snapshot_every: Duration,
    /// Save progress to, and resume from, a checkpoint (the per-pixel
    /// driver's integrators, [`crate::checkpoint::INTEGRATORS`]).
    pub checkpoint: Option<crate::checkpoint::Checkpoint>,
}

impl RunSettings {
    /// The default time between snapshots (previews).
    pub const DEFAULT_SNAPSHOT_EVERY: Duration = Duration::from_secs(5);

    /// Samples per pixel the run asks for: `spp` when given; `None` when
    /// only the time budget ends the run; otherwise the scene's
    /// `sample_count` (passed in as `scene_sample_count`).
    pub fn samples_per_pixel(&self, scene_sample_count: u32) -> Option<u32> {
        match (self.spp, self.time_budget) {
            (Some(n), _) => Some(n),
            (None, Some(_)) => None,
            (None, None) => Some(scene_sample_count),
        }
    }
}

impl Default for RunSettings {
    fn default() -> Self {
        RunSettings {
            spp: None,
            time_budget: None,
            seed: 0,
            snapshot_every: Self::DEFAULT_SNAPSHOT_EVERY,
            checkpoint: None,
        }
    }
}

/// Why a render could not run.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The settings or the scene do not allow this integrator to run.
    #[error("{0}")]
    Invalid(String),
    /// The Markov-chain driver could not run.
    #[error(transparent)]
    Chain(#[from] MltError),
}

/// What a render produced, whatever the integrator.
#[derive(Clone, Debug)]
pub struct Rendered {
    /// The image, row-major, `scene.film.width × height`.
    pub image: Vec<Rgb>,
    /// Wall-clock seconds, start-up included.
    pub seconds: f64,
    /// Camera samples, light paths or mutations done.
    pub samples: u64,
    /// Stopped (stop flag or time budget) before the requested work.
    pub interrupted: bool,
    /// The integrator's run statistics for the JSON sidecar, in order.
    pub statistics: Map<String, Value>,
    /// The coordinates of the first NaN/inf contribution, for `--replay`.
    pub nonfinite_dump: Option<PssDump>,
    /// Named images beside the main one: partial images that sum to it
    /// (RELT's per-replica images, the tempered levels) or per-pixel
    /// statistics (`smcmc`'s `samples`, the sample count of each pixel);
    /// the CLI writes each as `<out>.NAME.exr`.
    pub layers: Vec<(String, Vec<Rgb>)>,
    /// One line for the terminal.
    pub summary: String,
}

crate::settings! {
    /// Path depth in Mitsuba's semantics, shared by every integrator (and
    /// carried over from a scene's `<integrator>` element of another type).
    pub struct DepthParams {
        /// Longest path in segments: -1 unbounded, 1 emitters seen directly, 2 direct light.
        pub max_depth: i64 = -1, check crate::settings::check::depth;
        /// Depth from which Russian roulette applies.
        pub rr_depth: u32 = 5, check crate::settings::check::positive_count;
    }
}

impl DepthParams {
    /// `max_depth` as the integrators take it (`u32::MAX` unbounded).
    pub fn limit(&self) -> u32 {
        crate::settings::depth_limit(self.max_depth)
    }
}

/// Where an integrator's contributions go.
pub trait FilmSink {
    /// A camera sample at raster position `p` (filter-weighted mean).
    fn add_sample(&mut self, p: Vec2, l: Rgb);
    /// A splat at raster position `p` (divided by paths per pixel at the end).
    fn splat(&mut self, p: Vec2, l: Rgb);
}

impl FilmSink for Film {
    fn add_sample(&mut self, p: Vec2, l: Rgb) {
        Film::add_sample(self, p, l);
    }
    fn splat(&mut self, p: Vec2, l: Rgb) {
        Film::splat(self, p, l);
    }
}

/// How an integrator's samples are organised.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleDomain {
    /// One sample per call for a given pixel (path tracing).
    Pixels,
    /// One light path per call, splatting anywhere (light tracing).
    LightPaths,
    /// One sample per call for a given pixel that may also splat anywhere
    /// (bidirectional path tracing: one light subpath per camera sample).
    PixelsWithSplats,
}

/// Counters an integrator updates while sampling.
#[derive(Clone, Copy, Debug, Default)]
pub struct SampleStats {
    /// Contributions dropped because they were NaN or infinite.
    pub nonfinite: u64,
}

impl SampleStats {
    /// Adds another set of counters.
    pub fn merge(&mut self, o: &SampleStats) {
        self.nonfinite += o.nonfinite;
    }
}

/// A light-transport estimator, evaluated one sample at a time.
pub trait Integrator: Send + Sync {
    /// Short name (`pt`, `lt`).
    fn name(&self) -> &'static str;
    /// How samples are organised.
    fn domain(&self) -> SampleDomain;
    /// Draws one sample: for [`SampleDomain::Pixels`] `pixel` is the pixel
    /// to estimate; for [`SampleDomain::LightPaths`] it is `None`.
    fn sample(
        &self,
        scene: &Scene,
        pixel: Option<(u32, u32)>,
        source: &mut dyn RandomSource,
        film: &mut dyn FilmSink,
        stats: &mut SampleStats,
    );

    /// Draws `spp` samples for every pixel of the tile `[x0, x1) × [y0, y1)`
    /// (rows top to bottom, pixels left to right, the `spp` samples of a
    /// pixel in a row), as that many calls of [`Integrator::sample`] would.
    /// The render driver calls this for [`SampleDomain::Pixels`]; its
    /// source and film have concrete types so that an integrator may
    /// override it with a monomorphised loop (the path tracer does: a
    /// virtual call per random number and per film sample was about a
    /// tenth of a camera sample). Overrides must consume the same numbers
    /// in the same order as the default.
    fn render_pixels(
        &self,
        scene: &Scene,
        (x0, y0, x1, y1): (u32, u32, u32, u32),
        spp: u32,
        source: &mut PixelSource,
        film: &mut Film,
        stats: &mut SampleStats,
    ) {
        for_each_tile_sample((x0, y0, x1, y1), spp, |x, y| {
            self.sample(scene, Some((x, y)), source, film, stats);
        });
    }
}

/// Calls `f(x, y)` `spp` times for every pixel of the tile
/// `[x0, x1) × [y0, y1)`, in the order [`Integrator::render_pixels`]
/// documents (rows top to bottom, pixels left to right).
#[inline(always)]
pub(crate) fn for_each_tile_sample(
    (x0, y0, x1, y1): (u32, u32, u32, u32),
    spp: u32,
    mut f: impl FnMut(u32, u32),
) {
    for y in y0..y1 {
        for x in x0..x1 {
            for _ in 0..spp {
                f(x, y);
            }
        }
    }
}

/// Mitsuba's Russian-roulette continuation probability.
pub(crate) fn rr_probability(throughput: Rgb, eta_scale: f32) -> f32 {
    (throughput.max_channel() * eta_scale).min(0.95)
}

#[cfg(test)]
mod tests {
    use super::pt::PathTracer;
    use super::*;
    use crate::film::Filter;
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;
    use std::collections::HashMap;
    use std::path::Path;
    use std::sync::Arc;

    /// The path tracer's monomorphised `render_pixels` must produce what
    /// the default (one dynamic `sample` call per sample) produces: the same
    /// numbers in the same order and the same film, bit for bit. On a CPU
    /// with `x86-64-v3` features `render_pixels` runs the copy compiled for
    /// them while the `dyn` path is baseline code, so this also checks that
    /// the two copies agree bit for bit.
    #[test]
    fn path_tracer_render_pixels_equals_the_default_loop() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/scenes/cornell-box.xml");
        let defines = HashMap::from([("res".to_string(), "20".to_string())]);
        let scene = Scene::load(&path, &defines).expect("test scene loads");
        let pt = PathTracer {
            max_depth: 8,
            rr_depth: 3,
        };
        let filter = Arc::new(Filter::new(scene.film.filter, 20, 20));
        let tile = (4, 2, 17, 19);
        let spp = 3;

        let mut fast = Film::for_tile(20, 20, 4, 2, 17, 19, filter.clone());
        let mut src = PixelSource::new(Xoshiro256PlusPlus::seed_from_u64(11));
        let mut stats = SampleStats::default();
        pt.render_pixels(&scene, tile, spp, &mut src, &mut fast, &mut stats);

        let mut slow = Film::for_tile(20, 20, 4, 2, 17, 19, filter);
        let mut src_dyn = PixelSource::new(Xoshiro256PlusPlus::seed_from_u64(11));
        let mut stats_dyn = SampleStats::default();
        for y in tile.1..tile.3 {
            for x in tile.0..tile.2 {
                for _ in 0..spp {
                    let source: &mut dyn RandomSource = &mut src_dyn;
                    let film: &mut dyn FilmSink = &mut slow;
                    pt.sample(&scene, Some((x, y)), source, film, &mut stats_dyn);
                }
            }
        }

        let (a, b) = (fast.develop(0.0), slow.develop(0.0));
        assert!(a.iter().any(|p| p.r > 0.0), "the tile saw no light");
        for (i, (p, q)) in a.iter().zip(&b).enumerate() {
            assert_eq!(
                (p.r.to_bits(), p.g.to_bits(), p.b.to_bits()),
                (q.r.to_bits(), q.g.to_bits(), q.b.to_bits()),
                "pixel {i}"
            );
        }
        // Both sources end in the same state: the same count of numbers drawn.
        assert_eq!(src.next_1d().to_bits(), src_dyn.next_1d().to_bits());
        assert_eq!(stats.nonfinite, stats_dyn.nonfinite);
    }
}
