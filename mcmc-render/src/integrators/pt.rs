//! Unidirectional path tracing with next-event estimation and multiple
//! importance sampling (power heuristic), following Mitsuba 3's `path`
//! integrator: depth semantics (`max_depth` counts path segments, 1 =
//! emitters seen directly, 2 = direct light), Russian roulette from
//! `rr_depth` with continuation probability `min(max(throughput)·η², 0.95)`.

use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings};
use super::{FilmSink, Integrator, SampleDomain, SampleStats, rr_probability};
use crate::bsdf::TransportMode;
use crate::bsdf::textured::BsdfAt;
use crate::color::Rgb;
use crate::film::Film;
use crate::frame::Frame;
use crate::geometry::{Ray, SurfacePoint};
use crate::observer::Observer;
use crate::sampling::{PixelSource, RandomSource};
use crate::scene::Scene;
use crate::warp::power_heuristic;
use glam::{Vec2, Vec3};
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
        let mut from = ScatterOrigin::CAMERA;
        loop {
            let Some(its) = scene.intersect(&ray) else {
                l += environment_hit(scene, beta, ray.d, &from, true);
                break;
            };
            let sp = its.sp;
            let wo_world = -ray.d;
            l += emitter_hit(scene, beta, &sp, wo_world, &from, true);
            if depth.saturating_add(1) >= self.max_depth {
                break;
            }

            let bsdf = scene.bsdf_at(&sp);
            let frame = scene.shading_frame(&sp);
            let wo = frame.to_local(wo_world);

            // Next-event estimation (numbers drawn even when unused).
            let u_sel = source.next_1d();
            let u_light = source.next_2d();
            l += next_event(
                scene,
                beta,
                &sp,
                &frame,
                &bsdf,
                wo,
                (u_sel, u_light),
                |_, p| p,
            );

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
            from = ScatterOrigin {
                p: sp.p,
                pdf: bs.pdf,
                delta: bs.is_delta,
            };
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

/// Where the ray being traced was scattered, for the MIS weight of the
/// emission it finds (against light sampling from that point).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ScatterOrigin {
    /// The scattering point.
    pub p: Vec3,
    /// Solid-angle density of the ray's direction (the discrete lobe
    /// probability for delta lobes).
    pub pdf: f32,
    /// Sampled from a Dirac lobe (or a camera ray): no light sample could
    /// have produced it, so its emission is weighted 1.
    pub delta: bool,
}

impl ScatterOrigin {
    /// A camera ray (emission seen directly is weighted 1).
    pub const CAMERA: ScatterOrigin = ScatterOrigin {
        p: Vec3::ZERO,
        pdf: 1.0,
        delta: true,
    };
}

/// `beta · Le · w`: the environment seen by a ray leaving the scene in
/// direction `d`, MIS-weighted (power heuristic) against light sampling at
/// `from` when `nee` (next-event estimation also samples it), else 1.
#[inline(always)]
pub(crate) fn environment_hit(
    scene: &Scene,
    beta: Rgb,
    d: Vec3,
    from: &ScatterOrigin,
    nee: bool,
) -> Rgb {
    let lights = &scene.lights;
    if lights.environment().is_none() {
        return Rgb::BLACK;
    }
    let le = lights.environment_radiance(d);
    let w = if from.delta || !nee {
        1.0
    } else {
        power_heuristic(from.pdf, lights.pdf_environment(d))
    };
    beta * le * w
}

/// `beta · Le · w`: the emission of the surface point `sp` towards
/// `wo_world` found by a ray scattered at `from`, weighted as in
/// [`environment_hit`].
#[inline(always)]
pub(crate) fn emitter_hit(
    scene: &Scene,
    beta: Rgb,
    sp: &SurfacePoint,
    wo_world: Vec3,
    from: &ScatterOrigin,
    nee: bool,
) -> Rgb {
    let Some(light) = scene.shapes[sp.shape as usize].light else {
        return Rgb::BLACK;
    };
    let lights = &scene.lights;
    let le = lights.area_radiance(light, sp, wo_world);
    if le.is_black() {
        return Rgb::BLACK;
    }
    let w = if from.delta || !nee {
        1.0
    } else {
        power_heuristic(from.pdf, lights.pdf_direct(light, from.p, sp))
    };
    beta * le * w
}

/// Next-event estimation at `sp`: `beta · f · Le · |cos| · w / p_light`
/// for one light sample drawn with `u = (u_sel, u_light)` (black at
/// purely specular BSDFs, for occluded or zero samples), with the power
/// heuristic against the density with which the path's own direction
/// sampling would have produced the light direction:
/// `direction_pdf(wi_world, bsdf_pdf)` (the BSDF density itself for plain
/// path tracing, a mixture for guided tracing).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn next_event(
    scene: &Scene,
    beta: Rgb,
    sp: &SurfacePoint,
    frame: &Frame,
    bsdf: &BsdfAt<'_>,
    wo: Vec3,
    (u_sel, u_light): (f32, (f32, f32)),
    direction_pdf: impl FnOnce(Vec3, f32) -> f32,
) -> Rgb {
    if bsdf.is_delta() {
        return Rgb::BLACK;
    }
    let Some(ds) = scene
        .lights
        .sample_direct(&scene.geometry, sp.p, u_sel, u_light)
    else {
        return Rgb::BLACK;
    };
    let wi = frame.to_local(ds.wi);
    // One dispatch for both: the glossy models share the half vector, D
    // and G1, and the two-sided mapping is done once.
    let (f, bsdf_pdf) = bsdf.eval_pdf(wo, wi, TransportMode::Radiance);
    if f.is_black() || !scene.light_visible(sp, &ds) {
        return Rgb::BLACK;
    }
    let w = if ds.is_delta {
        1.0
    } else {
        power_heuristic(ds.pdf, direction_pdf(ds.wi, bsdf_pdf))
    };
    beta * f * ds.le * (wi.z.abs() * w / ds.pdf)
}

/// A camera ray through pixel `(px, py)`: `next_2d` for the position in
/// the pixel, then `next_2d` for the lens point of a thin-lens camera.
/// Returns the raster position and the ray.
#[inline(always)]
pub(crate) fn camera_ray<S: RandomSource + ?Sized>(
    scene: &Scene,
    (px, py): (u32, u32),
    source: &mut S,
) -> (Vec2, Ray) {
    let u = source.next_2d();
    let raster = Vec2::new(px as f32 + u.0, py as f32 + u.1);
    let ray = if scene.camera.has_lens() {
        scene.camera.generate_ray_lens(raster, source.next_2d())
    } else {
        scene.camera.generate_ray(raster)
    };
    (raster, ray)
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
        let (raster, ray) = camera_ray(scene, (px, py), source);
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
