//! The BDPT shift (spec seed003 §11.1, "SMCMC-BDPT"): one light subpath,
//! traced from the state's light stream, is shared by every pixel of the
//! tile; each pixel gets its own camera subpath by random replay (the same
//! camera numbers, the sub-pixel offset moved to the pixel) and the full
//! BDPT sum over the techniques with `t ≥ 2` camera vertices, whose MIS
//! weights are renormalised over those techniques only
//! (`mis_weight_among` with `min_camera = 2`). Light tracing (`t = 1`)
//! is left out because its samples land on other pixels than the tile's
//! (each tile has its own normalisation, §14.11), so paths that only
//! `t = 1` can sample (a caustic seen through a specular surface, the
//! thesis's Veach-egg region) are missed.
//!
//! Per pixel this is BDPT with the shared light subpath: in primary sample
//! space every pixel's sample is uniform, so the shift's Jacobian is 1 as
//! for random replay, and `Σ_{s, t≥2} w'_{s,t} f/p_{s,t}` is an unbiased
//! estimate of the pixel over the paths some `t ≥ 2` technique samples.
//!
//! Coordinates: three interleaved streams as BDPT's (camera, light,
//! connection); the camera stream starts with the sub-pixel offset; each
//! pixel replays the camera and connection streams from their start.

use super::{Placement, TileShift};
use crate::color::Rgb;
use crate::integrators::bdpt::{
    Bdpt, SubpathBuffers, connect_among, generate_camera_subpath, generate_light_subpath,
};
use crate::pss::PssSource;
use crate::sampling::{RandomSource, Stream};
use crate::scene::Scene;
use glam::Vec2;
use mcmc_core::space::TorusPoint;
use std::cell::RefCell;

thread_local! {
    /// Per-thread subpath storage.
    pub(super) static BUFFERS: RefCell<SubpathBuffers> = RefCell::new(SubpathBuffers::default());
}

/// The BDPT shift over `bdpt`'s depth limits and MIS heuristic.
#[derive(Clone, Copy, Debug)]
pub struct BdptShift {
    /// The bidirectional path tracer.
    pub bdpt: Bdpt,
}

impl BdptShift {
    /// The camera subpath of `point` placed by `place` (random replay of
    /// the camera stream) in `buffers.camera`: its raster position, its
    /// vertex count and the source, switched to the connection stream's
    /// start.
    pub(super) fn camera_subpath<'a>(
        &self,
        scene: &Scene,
        point: &'a TorusPoint,
        place: Placement,
        buffers: &mut SubpathBuffers,
    ) -> (Vec2, usize, PssSource<'a>) {
        let mut source = PssSource::new(point, Stream::COUNT);
        source.set_stream(Stream::Camera);
        let (ox, oy) = source.next_2d();
        let raster = place.raster(ox, oy);
        let nc = generate_camera_subpath(
            scene,
            raster,
            &mut source,
            self.bdpt.max_camera_vertices(),
            Some(self.bdpt.rr_depth),
            &mut buffers.camera,
        );
        source.set_stream(Stream::Connection);
        (raster, nc, source)
    }

    /// Technique `(s, t)` on the subpaths in `buffers` with its MIS weight
    /// renormalised over the techniques with `t ≥ 2` (black when it carries
    /// nothing). The weight is computed once, directly over `t ≥ 2`
    /// (session 24: before, the full BDPT weight was computed, divided out
    /// and replaced by this one: the same value, one weight computation
    /// more).
    pub(super) fn renormalised(
        &self,
        scene: &Scene,
        buffers: &SubpathBuffers,
        s: usize,
        t: usize,
        source: &mut PssSource<'_>,
    ) -> Rgb {
        connect_among(
            scene,
            &buffers.camera,
            &buffers.light,
            s,
            t,
            source,
            self.bdpt.heuristic,
            2,
        )
        .map_or(Rgb::BLACK, |c| c.l)
    }

    /// The raster position of `point` placed by `place` and the
    /// renormalised BDPT sum there, with the light subpath in
    /// `buffers.light`.
    fn pixel(
        &self,
        scene: &Scene,
        point: &TorusPoint,
        place: Placement,
        buffers: &mut SubpathBuffers,
    ) -> (Vec2, Rgb) {
        let (raster, nc, mut source) = self.camera_subpath(scene, point, place, buffers);
        let nl = buffers.light.len();
        let max_depth = self.bdpt.max_depth as usize;
        let mut l = Rgb::BLACK;
        for t in 2..=nc {
            for s in 0..=nl {
                if s + t - 1 <= max_depth {
                    l += self.renormalised(scene, buffers, s, t, &mut source);
                }
            }
        }
        (raster, l)
    }

    /// Traces the light subpath of `point` into `buffers.light`.
    pub(super) fn light_subpath(
        &self,
        scene: &Scene,
        point: &TorusPoint,
        buffers: &mut SubpathBuffers,
    ) {
        let mut source = PssSource::new(point, Stream::COUNT);
        source.set_stream(Stream::Light);
        generate_light_subpath(
            scene,
            &mut source,
            self.bdpt.max_light_vertices(),
            Some(self.bdpt.rr_depth),
            &mut buffers.light,
        );
    }
}

impl TileShift for BdptShift {
    fn name(&self) -> &'static str {
        "bdpt"
    }

    fn evaluate(
        &self,
        scene: &Scene,
        point: &TorusPoint,
        pixels: &[Option<(u32, u32)>],
        out: &mut [Rgb],
    ) {
        BUFFERS.with_borrow_mut(|buffers| {
            self.light_subpath(scene, point, buffers);
            for (q, o) in pixels.iter().zip(out.iter_mut()) {
                *o = q.map_or(Rgb::BLACK, |q| {
                    self.pixel(scene, point, Placement::Pixel(q), buffers).1
                });
            }
        });
    }

    fn evaluate_film(&self, scene: &Scene, point: &TorusPoint) -> (Vec2, Rgb) {
        let film = Placement::Film((scene.film.width, scene.film.height));
        BUFFERS.with_borrow_mut(|buffers| {
            self.light_subpath(scene, point, buffers);
            self.pixel(scene, point, film, buffers)
        })
    }

    fn offset_coordinates(&self) -> [usize; 2] {
        super::camera_stream_offset_coordinates()
    }
}
