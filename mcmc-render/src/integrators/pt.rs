//! Unidirectional path tracing with next-event estimation and multiple
//! importance sampling (power heuristic), following Mitsuba 3's `path`
//! integrator: depth semantics (`max_depth` counts path segments, 1 =
//! emitters seen directly, 2 = direct light), Russian roulette from
//! `rr_depth` with continuation probability `min(max(throughput)·η², 0.95)`.

use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings};
use super::{FilmSink, Integrator, SampleDomain, SampleStats, rr_probability};
use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::film::Film;
use crate::frame::Frame;
use crate::geometry::Ray;
use crate::observer::Observer;
use crate::sampling::{PixelSource, RandomSource};
use crate::scene::Scene;
use crate::warp::power_heuristic;
use glam::Vec2;
use std::sync::atomic::AtomicBool;

/// Path tracer settings.
#[derive(Clone, Copy, Debug)]
pub struct PathTracer {
    /// Longest path in segments (`u32::MAX` = unbounded).
    pub max_depth: u32,
    /// Depth from which Russian roulette applies.
    pub rr_depth: u32,
}

impl PathTracer {
    /// Radiance arriving along `ray` (numbers consumed as documented in
    /// [`super`]).
    ///
    /// Generic over the source so that the render driver's loop
    /// ([`Integrator::render_pixels`]) draws its numbers without virtual
    /// calls; `S = dyn RandomSource` serves everything else.
    #[inline(always)]
    pub fn li<S: RandomSource + ?Sized>(&self, scene: &Scene, ray: Ray, source: &mut S) -> Rgb {
        // Mitsuba: max_depth 0 renders nothing, not even visible emitters.
        if self.max_depth == 0 {
            return Rgb::BLACK;
        }
        let mut l = Rgb::BLACK;
        let mut beta = Rgb::WHITE;
        let mut eta_scale = 1.0f32;
        let mut ray = ray;
        let mut depth: u32 = 0;
        let mut prev_p = ray.o;
        let mut prev_pdf = 1.0f32;
        let mut prev_delta = true;
        let geometry = &scene.geometry;
        let lights = &scene.lights;
        loop {
            let Some(its) = scene.intersect(&ray) else {
                // The ray left the scene: the environment, MIS-weighted
                // against light sampling as an area emitter is.
                if lights.environment().is_some() {
                    let le = lights.environment_radiance(ray.d);
                    let w = if prev_delta {
                        1.0
                    } else {
                        power_heuristic(prev_pdf, lights.pdf_environment(ray.d))
                    };
                    l += beta * le * w;
                }
                break;
            };
            let sp = its.sp;
            let wo_world = -ray.d;

            // Emission found by the BSDF-sampled ray (or the camera ray).
            if let Some(light) = scene.shapes[sp.shape as usize].light {
                let le = lights.area_radiance(light, &sp, wo_world);
                if !le.is_black() {
                    let w = if prev_delta {
                        1.0
                    } else {
                        power_heuristic(prev_pdf, lights.pdf_direct(light, prev_p, &sp))
                    };
                    l += beta * le * w;
                }
            }
            if depth.saturating_add(1) >= self.max_depth {
                break;
            }

            let bsdf = scene.bsdf_at(&sp);
            let frame = Frame::from_normal(sp.ns);
            let wo = frame.to_local(wo_world);

            // Next-event estimation (numbers drawn even when unused).
            let u_sel = source.next_1d();
            let u_light = source.next_2d();
            if !bsdf.is_delta()
                && let Some(ds) = lights.sample_direct(geometry, sp.p, u_sel, u_light)
            {
                let wi = frame.to_local(ds.wi);
                // One dispatch for both: the glossy models share the half
                // vector, D and G1, and the two-sided mapping is done once.
                let (f, bsdf_pdf) = bsdf.eval_pdf(wo, wi, TransportMode::Radiance);
                if !f.is_black() && scene.light_visible(&sp, &ds) {
                    let w = if ds.is_delta {
                        1.0
                    } else {
                        power_heuristic(ds.pdf, bsdf_pdf)
                    };
                    l += beta * f * ds.le * (wi.z.abs() * w / ds.pdf);
                }
            }

            // BSDF sampling.
            let u_lobe = source.next_1d();
            let u_dir = source.next_2d();
            let u_rr = source.next_1d();
            let Some(bs) = bsdf.sample(wo, u_lobe, u_dir, TransportMode::Radiance) else {
                break;
            };
            if !(bs.pdf > 0.0) || bs.weight.is_black() {
                break;
            }
            let wi_world = frame.to_world(bs.wi);
            beta *= bs.weight;
            eta_scale *= bs.eta * bs.eta;
            prev_p = sp.p;
            prev_pdf = bs.pdf;
            prev_delta = bs.is_delta;
            ray = sp.spawn_ray(wi_world);
            depth += 1;

            if depth >= self.rr_depth {
                let q = rr_probability(beta, eta_scale);
                if !(u_rr < q) {
                    break;
                }
                beta = beta / q;
            }
            if beta.is_black() {
                break;
            }
        }
        l
    }
}

impl PathTracer {
    /// One camera sample for pixel `(px, py)`: [`Integrator::sample`] for
    /// any source and film (monomorphised in [`Integrator::render_pixels`]).
    #[inline(always)]
    fn sample_pixel<S: RandomSource + ?Sized, F: FilmSink + ?Sized>(
        &self,
        scene: &Scene,
        (px, py): (u32, u32),
        source: &mut S,
        film: &mut F,
        stats: &mut SampleStats,
    ) {
        let u = source.next_2d();
        let raster = Vec2::new(px as f32 + u.0, py as f32 + u.1);
        let ray = if scene.camera.has_lens() {
            scene.camera.generate_ray_lens(raster, source.next_2d())
        } else {
            scene.camera.generate_ray(raster)
        };
        let l = self.li(scene, ray, source);
        if l.is_finite() {
            film.add_sample(raster, l);
        } else {
            stats.nonfinite += 1;
        }
    }
}

impl Integrator for PathTracer {
    fn name(&self) -> &'static str {
        "pt"
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
        if let Some(pixel) = pixel {
            self.sample_pixel(scene, pixel, source, film, stats);
        }
    }

    /// On x86-64 CPUs with AVX2, FMA and BMI (`x86-64-v3`, detected once at
    /// run time) the tile runs in a copy of the loop compiled for them, with
    /// the traversal, hit points, light sampling and film inlined into it;
    /// elsewhere in the baseline copy. Rust never fuses or reorders float
    /// operations on its own, so both copies compute the same bits (tested
    /// against the `dyn` path, which is always the baseline code).
    fn render_pixels(
        &self,
        scene: &Scene,
        tile: (u32, u32, u32, u32),
        spp: u32,
        source: &mut PixelSource,
        film: &mut Film,
        stats: &mut SampleStats,
    ) {
        #[cfg(target_arch = "x86_64")]
        if has_x86_64_v3() {
            // SAFETY: the CPU has every feature the function is compiled for.
            unsafe { self.render_pixels_x86_64_v3(scene, tile, spp, source, film, stats) };
            return;
        }
        self.render_pixels_inline(scene, tile, spp, source, film, stats);
    }
}

/// True when the CPU supports the `x86-64-v3` features the fast tile loop
/// is compiled for (checked once; `is_x86_feature_detected!` caches).
#[cfg(target_arch = "x86_64")]
fn has_x86_64_v3() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
        && std::arch::is_x86_feature_detected!("bmi1")
        && std::arch::is_x86_feature_detected!("bmi2")
        && std::arch::is_x86_feature_detected!("lzcnt")
        && std::arch::is_x86_feature_detected!("popcnt")
}

impl PathTracer {
    /// The tile loop, inlined into each of its compiled copies. It is
    /// written out rather than passed as a closure to
    /// [`super::for_each_tile_sample`]: the closure would be one function
    /// shared by both copies, compiled for the baseline.
    #[inline(always)]
    fn render_pixels_inline(
        &self,
        scene: &Scene,
        (x0, y0, x1, y1): (u32, u32, u32, u32),
        spp: u32,
        source: &mut PixelSource,
        film: &mut Film,
        stats: &mut SampleStats,
    ) {
        for y in y0..y1 {
            for x in x0..x1 {
                for _ in 0..spp {
                    self.sample_pixel(scene, (x, y), source, film, stats);
                }
            }
        }
    }

    /// The tile loop compiled for `x86-64-v3` (the hot callees are
    /// `#[inline(always)]`, so they are compiled for it too).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    fn render_pixels_x86_64_v3(
        &self,
        scene: &Scene,
        tile: (u32, u32, u32, u32),
        spp: u32,
        source: &mut PixelSource,
        film: &mut Film,
        stats: &mut SampleStats,
    ) {
        self.render_pixels_inline(scene, tile, spp, source, film, stats);
    }
}

crate::settings! {
    /// Path tracer settings, as the registry fills them.
    pub struct PtSettings {
        flatten {
            /// Path depth.
            pub depth: DepthParams = DepthParams::default();
        }
    }
}

impl PtSettings {
    /// The per-sample integrator these settings describe.
    pub fn integrator(&self) -> PathTracer {
        PathTracer {
            max_depth: self.depth.limit(),
            rr_depth: self.depth.rr_depth,
        }
    }
}

impl IntegratorSettings for PtSettings {
    const NAME: &'static str = "pt";
    const ALIASES: &'static [&'static str] = &["path"];
    const DESCRIPTION: &'static str =
        "Path tracing with next-event estimation and MIS (Mitsuba's `path`).";

    fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError> {
        Ok(crate::render::run_per_pixel(
            scene,
            &self.integrator(),
            run,
            stop,
            observer,
        ))
    }
}
