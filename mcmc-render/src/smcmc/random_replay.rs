//! The random replay shift (spec seed003 §8.5, Eq. 3.39–3.41): every pixel
//! `q` of a tile is estimated from the same primary-sample vector `u`,
//! with the same sub-pixel offset moved to `q` and the rest of `u`
//! replayed by the path tracer.
//!
//! In primary sample space every pixel's path has density 1, so the
//! Jacobian `p(X)/p(T(X))` of the shift is 1: `f(T_q(u))` is exactly what
//! a path tracer would return for a camera sample at the same raster
//! position in `q` driven by the same numbers (`tests/smcmc.rs` checks it
//! bit for bit against [`PathTracer`]'s own PSS sampler).
//!
//! Coordinate layout (one stream, as [`PathTracer`]'s PSS sampler):
//! coordinates 0 and 1 are the sub-pixel offset, then the lens sample if
//! the camera has one, then the path tracer's numbers.

use super::{Placement, TileShift};
use crate::color::Rgb;
use crate::geometry::Ray;
use crate::integrators::pt::PathTracer;
use crate::pss::PssSource;
use crate::sampling::RandomSource;
use crate::scene::Scene;
use glam::Vec2;
use mcmc_core::space::TorusPoint;

/// Random replay over the path tracer (next-event estimation included).
#[derive(Clone, Copy, Debug)]
pub struct RandomReplay {
    /// The path tracer replayed at every pixel.
    pub pt: PathTracer,
}

impl ReplayTracer for RandomReplay {
    const NAME: &'static str = "rr";

    fn li(&self, scene: &Scene, ray: Ray, source: &mut PssSource<'_>) -> Rgb {
        self.pt.li(scene, ray, source)
    }
}

/// A one-stream unidirectional tracer driven by random replay: every
/// [`ReplayTracer`] is a [`TileShift`] (the path tracer here, the guided
/// tracer in [`super::guided_shift`]), whose value at a pixel is the
/// tracer's own sample at the state's offset moved into that pixel.
pub trait ReplayTracer: Sync {
    /// Short name of the shift (statistics).
    const NAME: &'static str;

    /// `f` of the path from camera ray `ray`, the rest of the state read
    /// from `source`.
    fn li(&self, scene: &Scene, ray: Ray, source: &mut PssSource<'_>) -> Rgb;

    /// `f` of the path of `point` through pixel `(x, y)`.
    fn trace(&self, scene: &Scene, point: &TorusPoint, q: (u32, u32)) -> Rgb {
        self.trace_at(scene, point, Placement::Pixel(q)).1
    }

    /// The raster position of `point` placed by `place`, and `f` of its path.
    fn trace_at(&self, scene: &Scene, point: &TorusPoint, place: Placement) -> (Vec2, Rgb) {
        replay(scene, point, place, |ray, source| {
            self.li(scene, ray, source)
        })
    }
}

/// Random replay of a one-stream unidirectional tracer `li`: the state's
/// first two numbers are the sub-pixel offset, placed by `place`, then the
/// lens sample if the camera has one, then `li` reads the rest. Returns the
/// raster position and `f` of the path.
pub fn replay(
    scene: &Scene,
    point: &TorusPoint,
    place: Placement,
    li: impl FnOnce(Ray, &mut PssSource<'_>) -> Rgb,
) -> (Vec2, Rgb) {
    let mut source = PssSource::new(point, 1);
    let (ox, oy) = source.next_2d();
    let p = place.raster(ox, oy);
    let ray = if scene.camera.has_lens() {
        scene.camera.generate_ray_lens(p, source.next_2d())
    } else {
        scene.camera.generate_ray(p)
    };
    (p, li(ray, &mut source))
}

impl<T: ReplayTracer> TileShift for T {
    fn name(&self) -> &'static str {
        T::NAME
    }

    fn evaluate(
        &self,
        scene: &Scene,
        point: &TorusPoint,
        pixels: &[Option<(u32, u32)>],
        out: &mut [Rgb],
    ) {
        for (q, o) in pixels.iter().zip(out.iter_mut()) {
            *o = q.map_or(Rgb::BLACK, |q| self.trace(scene, point, q));
        }
    }

    fn evaluate_film(&self, scene: &Scene, point: &TorusPoint) -> (Vec2, Rgb) {
        let film = (scene.film.width, scene.film.height);
        self.trace_at(scene, point, Placement::Film(film))
    }

    fn offset_coordinates(&self) -> [usize; 2] {
        [0, 1]
    }
}
