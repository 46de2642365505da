//! The random-strategy BDPT shift (spec seed003 §11.2, "rBDPT", after
//! Matrix BDPT): as the BDPT shift ([`super::bdpt_shift`]: one light
//! subpath shared by the tile, per pixel a camera subpath by random
//! replay, techniques with `t ≥ 2` only, MIS renormalised over them), but
//! for each path length `L = 1..=max_depth` (segments) only **one**
//! technique `(s, t = L + 1 − s)`, `s` uniform in `0..L` (`p_tech = 1/L`),
//! is connected, and its weighted contribution is divided by `p_tech`.
//! The selection pmf is uniform within a length, so it cancels in the MIS
//! weights (the renormalised BDPT weights are the one-sample weights).
//!
//! Unbiased: for each `L`, `E[w'_{s,t} C_{s,t}/p_tech] = Σ_s E[w'_{s,t} C_{s,t}]`,
//! the BDPT shift's sum over that length (a technique whose subpaths are too
//! short contributes zero in both); one connection per length instead of
//! `L`, so far fewer visibility tests, at the price of variance where the
//! MIS mass sits on few techniques (dielectrics).
//!
//! Coordinates: as the BDPT shift; the connection stream's first
//! `max_depth` numbers pick the techniques (one per length, read before
//! any connection, so every pixel of the tile makes the same choices).

use super::bdpt_shift::{BUFFERS, BdptShift};
use super::{Placement, TileShift};
use crate::color::Rgb;
use crate::integrators::bdpt::SubpathBuffers;
use crate::sampling::RandomSource;
use crate::scene::Scene;
use glam::Vec2;
use mcmc_core::space::TorusPoint;

/// The rBDPT shift over `bdpt`'s depth limits (a finite `max_depth`) and
/// MIS heuristic.
#[derive(Clone, Copy, Debug)]
pub struct RbdptShift {
    /// The BDPT shift it draws from.
    pub bdpt: BdptShift,
}

impl RbdptShift {
    /// The raster position of `point` placed by `place` and its value
    /// there, with the light subpath in `buffers.light`.
    fn pixel(
        &self,
        scene: &Scene,
        point: &TorusPoint,
        place: Placement,
        buffers: &mut SubpathBuffers,
    ) -> (Vec2, Rgb) {
        let shift = &self.bdpt;
        let (raster, nc, mut source) = shift.camera_subpath(scene, point, place, buffers);
        let lengths = shift.bdpt.max_depth.max(1) as usize;
        // s for each length L = 1..=lengths, uniform in 0..L.
        let choices: Vec<usize> = (1..=lengths)
            .map(|l| ((source.next_1d() * l as f32) as usize).min(l - 1))
            .collect();
        let nl = buffers.light.len();
        let mut value = Rgb::BLACK;
        for (l, &s) in (1..=lengths).zip(&choices) {
            let t = l + 1 - s;
            if t <= nc && s <= nl {
                value += shift.renormalised(scene, buffers, s, t, &mut source) * l as f32;
            }
        }
        (raster, value)
    }
}

impl TileShift for RbdptShift {
    fn name(&self) -> &'static str {
        "rbdpt"
    }

    fn evaluate(
        &self,
        scene: &Scene,
        point: &TorusPoint,
        pixels: &[Option<(u32, u32)>],
        out: &mut [Rgb],
    ) {
        BUFFERS.with_borrow_mut(|buffers| {
            self.bdpt.light_subpath(scene, point, buffers);
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
            self.bdpt.light_subpath(scene, point, buffers);
            self.pixel(scene, point, film, buffers)
        })
    }

    fn offset_coordinates(&self) -> [usize; 2] {
        super::camera_stream_offset_coordinates()
    }
}
