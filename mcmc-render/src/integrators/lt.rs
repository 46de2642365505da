//! Light tracing: paths start on the emitters and every non-specular
//! vertex is connected to the pinhole camera, splatting its contribution
//! where the connection lands on the film. Depth semantics match
//! [`super::pt`]: a connection closing a path of `k` segments is made only
//! when `k ≤ max_depth`. Shading normals are handled with Veach's adjoint
//! correction, since importance transport is not symmetric under them.

use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings};
use super::{FilmSink, Integrator, SampleDomain, SampleStats, rr_probability};
use crate::bsdf::TransportMode;
use crate::camera::Camera;
use crate::color::Rgb;
use crate::geometry::Ray;
use crate::observer::Observer;
use crate::sampling::RandomSource;
use crate::scene::Scene;
use glam::Vec3;
use std::sync::atomic::AtomicBool;

/// Light tracer settings.
#[derive(Clone, Copy, Debug)]
pub struct LightTracer {
    /// Longest path in segments, camera connection included (`u32::MAX` = unbounded).
    pub max_depth: u32,
    /// Depth from which Russian roulette applies.
    pub rr_depth: u32,
}

/// `|wo·ns| |wi·ng| / (|wo·ng| |wi·ns|)`: the factor that makes importance
/// transport with shading normals adjoint to radiance transport.
fn shading_correction(wo: Vec3, wi: Vec3, ng: Vec3, ns: Vec3) -> f32 {
    let num = wo.dot(ns).abs() * wi.dot(ng).abs();
    let den = wo.dot(ng).abs() * wi.dot(ns).abs();
    if den > 0.0 { num / den } else { 0.0 }
}

/// The lens point's two numbers for a camera connection: drawn only for a
/// thin lens (the pinhole's connections consume none).
fn lens_numbers(camera: &Camera, source: &mut dyn RandomSource) -> (f32, f32) {
    if camera.has_lens() {
        source.next_2d()
    } else {
        (0.5, 0.5)
    }
}

impl Integrator for LightTracer {
    fn name(&self) -> &'static str {
        "lt"
    }

    fn domain(&self) -> SampleDomain {
        SampleDomain::LightPaths
    }

    fn sample(
        &self,
        scene: &Scene,
        _pixel: Option<(u32, u32)>,
        source: &mut dyn RandomSource,
        film: &mut dyn FilmSink,
        stats: &mut SampleStats,
    ) {
        let geometry = &scene.geometry;
        let camera = &scene.camera;
        let u_sel = source.next_1d();
        let u_pos = source.next_2d();
        let u_dir = source.next_2d();
        let Some(es) = scene.lights.sample_emission(geometry, u_sel, u_pos, u_dir) else {
            return;
        };
        let mut splat = |p, c: Rgb, stats: &mut SampleStats| {
            if c.is_finite() {
                film.splat(p, c);
            } else {
                stats.nonfinite += 1;
            }
        };

        // The emitter seen directly (a path of one segment).
        if self.max_depth >= 1 && es.at_infinity {
            // An environment seen by the pinhole along `w`: the camera's
            // response to the radiance arriving along it, i.e. a point at
            // distance 1 along `w` with `le / pdf_dir` as its intensity.
            let w = -es.dir;
            let lens = camera.lens_point(lens_numbers(camera, source));
            if !es.is_delta
                && let Some(cs) = camera.connect(lens, lens + w)
                && let Some((t, k)) = scene.camera_connection(cs.origin, None, w)
                && k < self.max_depth
            {
                let pmf = es.pdf_pos / scene.lights.infinite_disk_pdf();
                let c = es.le * (t * cs.we / (cs.pdf * pmf * es.pdf_dir));
                splat(cs.raster, c, stats);
            }
        } else if self.max_depth >= 1
            && !es.is_delta
            && let Some(cs) = camera.sample_wi_lens(es.p.p, lens_numbers(camera, source))
        {
            let cos_l = es.p.ns.dot(cs.wi);
            if cos_l > 0.0
                && let Some((t, k)) =
                    scene.camera_connection(es.p.spawn_origin(cs.origin), Some(cs.origin), cs.wi)
                && k < self.max_depth
            {
                let c = es.le * (t * cos_l / es.pdf_pos * cs.we / cs.pdf);
                splat(cs.raster, c, stats);
            }
        }

        let mut beta = es.weight;
        let mut ray = if es.is_delta || es.at_infinity {
            Ray::new(es.p.p, es.dir)
        } else {
            es.p.spawn_ray(es.dir)
        };
        // Segments from the light to the current vertex.
        let mut depth: u32 = 1;
        while let Some(its) = scene.intersect(&ray) {
            let sp = its.sp;
            let wo_world = -ray.d;
            let bsdf = scene.bsdf_at(&sp);
            let frame = scene.shading_frame(&sp);
            let wo = frame.to_local(wo_world);

            // Connect to the camera: a path of depth + 1 segments.
            if depth.saturating_add(1) <= self.max_depth
                && !bsdf.is_delta()
                && let Some(cs) = camera.sample_wi_lens(sp.p, lens_numbers(camera, source))
            {
                let wi = frame.to_local(cs.wi);
                let f = bsdf.eval(wo, wi, TransportMode::Importance);
                if !f.is_black()
                    && let Some((t, k)) =
                        scene.camera_connection(sp.spawn_origin(cs.origin), Some(cs.origin), cs.wi)
                    && depth.saturating_add(1 + k) <= self.max_depth
                {
                    let corr = shading_correction(wo_world, cs.wi, sp.ng, sp.ns);
                    let c = beta * f * (t * wi.z.abs() * corr * cs.we / cs.pdf);
                    splat(cs.raster, c, stats);
                }
            }
            if depth.saturating_add(1) >= self.max_depth {
                break;
            }

            let u_lobe = source.next_1d();
            let u_dir = source.next_2d();
            let u_rr = source.next_1d();
            let Some(bs) = bsdf.sample(wo, u_lobe, u_dir, TransportMode::Importance) else {
                break;
            };
            if !(bs.pdf > 0.0) || bs.weight.is_black() {
                break;
            }
            let wi_world = frame.to_world(bs.wi);
            beta *= bs.weight * shading_correction(wo_world, wi_world, sp.ng, sp.ns);
            ray = sp.spawn_ray(wi_world);
            depth += 1;
            if depth >= self.rr_depth {
                let q = rr_probability(beta, 1.0);
                if !(u_rr < q) {
                    break;
                }
                beta = beta / q;
            }
            if beta.is_black() {
                break;
            }
        }
    }
}

crate::settings! {
    /// Light tracer settings, as the registry fills them.
    pub struct LtSettings {
        flatten {
            /// Path depth.
            pub depth: DepthParams = DepthParams::default();
        }
    }
}

impl LtSettings {
    /// The per-sample integrator these settings describe.
    pub fn integrator(&self) -> LightTracer {
        LightTracer {
            max_depth: self.depth.limit(),
            rr_depth: self.depth.rr_depth,
        }
    }
}

impl IntegratorSettings for LtSettings {
    const NAME: &'static str = "lt";
    const ALIASES: &'static [&'static str] = &["ptracer"];
    const DESCRIPTION: &'static str =
        "Light tracing: paths from the emitters connected to the camera (Mitsuba's `ptracer`).";

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
