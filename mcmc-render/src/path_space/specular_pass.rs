//! The specular-chain pass of `mlt`/`mept`: path tracing of the paths
//! whose every interior vertex scatters through a Dirac lobe
//! (`L S* E`: emitters seen directly or through mirrors and glass, the
//! environment included), which
//! the chains then leave out ([`super::PathTarget::without_specular_chains`]).
//!
//! Why: the bidirectional mutation can keep no vertex of such a path (the
//! camera and Dirac vertices cannot start a walk), so its only move away
//! is regrowing the whole path, an independent proposal from the start-up
//! density, under which these paths weigh `(k + 1) / P(k) · L_e`-ish (only
//! the camera-walk technique of the `k + 1` can draw them). A rare one
//! drawn by the bootstrap takes a share of the chains in proportion to
//! that weight and keeps them for the whole run: on the glossy-glass box
//! at depth 8 one path of 5 segments through the glass sphere held 4% of
//! `b`, and its pixel read 344 against 0.23 (relMSE 18, constant in time;
//! `docs/path-space.md`). Path tracing samples these paths with their own
//! density instead (the camera walk, lobes chosen as the BSDF samples
//! them), at a fixed number of samples per pixel, like the direct pass.

use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::integrators::pt::{ScatterOrigin, camera_ray, emitter_hit, environment_hit};
use crate::integrators::{FilmSink, Integrator, SampleDomain, SampleStats};
use crate::sampling::RandomSource;
use crate::scene::Scene;

/// Longest specular chain traced when the depth is unbounded: a ray
/// trapped by total internal reflection in a sphere never leaves it.
pub const UNBOUNDED_CHAIN: u32 = 256;

/// Path tracing of the emitters seen through chains of Dirac vertices
/// (with `through_diffuse`, of every unconnectable path), paths of
/// `min_depth ..= max_depth` segments (see the module docs).
#[derive(Clone, Copy, Debug)]
pub struct SpecularChains {
    /// Shortest path counted, in segments (1: emitters seen directly).
    pub min_depth: u32,
    /// Longest path counted, in segments.
    pub max_depth: u32,
    /// Trace through diffuse and glossy vertices too and count every
    /// unconnectable path ([`super::state::Path::is_unconnectable`]:
    /// `L S+ (D S+)* E` besides `L S* E`), for `mlt`'s
    /// `unconnectable_pass`; false: Dirac vertices only.
    pub through_diffuse: bool,
}

impl SpecularChains {
    /// Radiance along the camera ray of one sample that reaches an
    /// emitter through Dirac vertices only.
    fn li(
        &self,
        scene: &Scene,
        mut ray: crate::geometry::Ray,
        source: &mut dyn RandomSource,
    ) -> Rgb {
        let mut l = Rgb::BLACK;
        let mut beta = Rgb::WHITE;
        // Emission after a camera ray or a Dirac lobe is weighted 1: only
        // this pass counts these paths.
        let from = ScatterOrigin::CAMERA;
        // Whether the last vertex (the camera at first) scattered through a
        // Dirac lobe: an emitter hit after one that did not would end an
        // edge a connection can make (the emitter seen directly excepted).
        let mut last_dirac = false;
        for depth in 1..=self.max_depth.min(UNBOUNDED_CHAIN) {
            let counted = depth >= self.min_depth && (depth == 1 || last_dirac);
            let Some(its) = scene.intersect(&ray) else {
                // The environment seen through the chain (or directly).
                if counted {
                    l += environment_hit(scene, beta, ray.d, &from, false);
                }
                break;
            };
            let sp = its.sp;
            if counted {
                l += emitter_hit(scene, beta, &sp, -ray.d, &from, false);
            }
            if depth == self.max_depth {
                break;
            }
            let frame = scene.shading_frame(&sp);
            let u_lobe = source.next_1d();
            let u_dir = source.next_2d();
            let Some(bs) = scene.bsdf_at(&sp).sample(
                frame.to_local(-ray.d),
                u_lobe,
                u_dir,
                TransportMode::Radiance,
            ) else {
                break;
            };
            if !(bs.pdf > 0.0) || bs.weight.is_black() {
                break;
            }
            // Two non-Dirac vertices in a row: a connectible edge, so no
            // longer path of this prefix is left to the pass.
            if !bs.is_delta && (!self.through_diffuse || !last_dirac) {
                break;
            }
            last_dirac = bs.is_delta;
            beta *= bs.weight;
            ray = sp.spawn_ray(frame.to_world(bs.wi));
        }
        l
    }
}

impl Integrator for SpecularChains {
    fn name(&self) -> &'static str {
        "specular chains"
    }

    fn domain(&self) -> SampleDomain {
        SampleDomain::Pixels
    }

    fn sample(
        &self,
        scene: &Scene,
        pixel: Option<(u32, u32)>,
        source: &mut dyn RandomSource,
        film: &mut dyn FilmSink,
        stats: &mut SampleStats,
    ) {
        let Some(pixel) = pixel else {
            return;
        };
        let (raster, ray) = camera_ray(scene, pixel, source);
        let l = self.li(scene, ray, source);
        if l.is_finite() {
            film.add_sample(raster, l);
        } else {
            stats.nonfinite += 1;
        }
    }
}
