//! The MMLT shifts (spec seed003 §11.3: uMMLT, lMMLT, qMMLT, cMMLT): per
//! state, one path length `L ∈ 1..=max_depth` (segments) drawn uniformly
//! and one technique `(s, t = L + 1 − s)` with `t ≥ 2` drawn with
//! probability `c_L(s) ∝ (s + 1)^n`, `s = 0..L−1` (`n` = 0, 1, 2, 3 for
//! u, l, q, cMMLT; Eq. 4.6). The light subpath (exactly `s` vertices) is
//! shared by every pixel of the tile; each pixel gets its camera subpath
//! (exactly `t` vertices) by random replay and the one connection.
//!
//! # Estimator and MIS
//!
//! Pixel `q`'s value is `w̃_s C_{s,t} / (p_L c_L(s))`, with `C_{s,t}` the
//! unweighted contribution `f/p_{s,t}` and `w̃_s` the one-sample MIS weight
//! *including the selection pmf* (spec §1, §11.3): technique `s'`'s density
//! is `c_L(s') p_{s',t'}` in the power heuristic, over the techniques with
//! `t' ≥ 2` only (`bdpt::mis_weight_selected`). Those weights sum to one
//! over the techniques the shift uses (`tests/bdpt_mis.rs` checks them
//! against the definition), so `E[value] = Σ_L Σ_s ∫ w̃_s f` is the pixel's
//! value over the paths of at most `max_depth` segments that some `t ≥ 2`
//! technique samples. In primary sample space each pixel's numbers are
//! uniform, so the shift's Jacobian is 1 as for random replay
//! (`tests/smcmc.rs` checks the value at the shifted pixel against a direct
//! path-traced sample there, within its Monte Carlo error).
//!
//! Subpaths have prescribed lengths (no Russian roulette), as in MMLT: a
//! subpath that ends early makes the state black. Heavier light-path
//! weights (`n > 0`) favour long shared light subpaths and short camera
//! subpaths: cheaper per pixel, and the tile's paths more alike.
//!
//! Coordinates: three interleaved streams as BDPT's; the connection
//! stream's first two numbers pick the length and the technique, the
//! camera stream starts with the sub-pixel offset; each pixel replays the
//! camera and connection streams from their start.

use super::{Placement, TileShift};
use crate::color::Rgb;
use crate::integrators::bdpt::{
    Bdpt, SubpathBuffers, connect, generate_camera_subpath, generate_light_subpath,
    mis_weight_selected,
};
use crate::integrators::path_vertex::SceneBsdfs;
use crate::pss::PssSource;
use crate::sampling::{RandomSource, Stream};
use crate::scene::Scene;
use glam::Vec2;
use mcmc_core::space::TorusPoint;
use std::cell::RefCell;

thread_local! {
    /// Per-thread subpath storage.
    static BUFFERS: RefCell<SubpathBuffers> = RefCell::new(SubpathBuffers::default());
}

/// An MMLT shift: technique pmf `∝ (s + 1)^exponent`.
#[derive(Clone, Copy, Debug)]
pub struct MmltShift {
    /// Depth limit (finite) and MIS heuristic; `rr_depth` is not used
    /// (prescribed-length subpaths).
    pub bdpt: Bdpt,
    /// `n` of the technique pmf: 0 uMMLT, 1 lMMLT, 2 qMMLT, 3 cMMLT.
    pub exponent: u32,
}

/// The length and technique a state picked.
#[derive(Clone, Debug)]
pub struct Choice {
    /// Path length in segments.
    pub segments: usize,
    /// Light vertices of the technique.
    pub s: usize,
    /// Camera vertices (`segments + 1 − s ≥ 2`).
    pub t: usize,
    /// `p_L c_L(s)`, the probability of this choice.
    pub probability: f32,
    /// `c_L(s')` for `s' = 0..=segments` (0 for `s' = segments`, `t' = 1`).
    pub select: Vec<f32>,
}

impl MmltShift {
    /// The technique pmf `c_L(s') ∝ (s'+1)^n` of a path of `segments`
    /// segments, indexed by `s' = 0..=segments` (light tracing, the last
    /// entry, gets 0).
    pub fn technique_pmf(&self, segments: usize) -> Vec<f32> {
        let mut pmf: Vec<f64> = (0..=segments)
            .map(|s| {
                if s < segments {
                    ((s + 1) as f64).powi(self.exponent as i32)
                } else {
                    0.0
                }
            })
            .collect();
        let total: f64 = pmf.iter().sum();
        pmf.iter_mut().for_each(|p| *p /= total);
        pmf.into_iter().map(|p| p as f32).collect()
    }

    /// The choice read from the connection stream's first two numbers.
    pub fn choose(&self, source: &mut PssSource<'_>) -> Choice {
        source.set_stream(Stream::Connection);
        let m = self.bdpt.max_depth.max(1) as usize;
        let segments = 1 + ((source.next_1d() * m as f32) as usize).min(m - 1);
        let select = self.technique_pmf(segments);
        let u = source.next_1d();
        let mut s = segments - 1;
        let mut cdf = 0.0;
        for (k, &c) in select[..segments].iter().enumerate() {
            cdf += c;
            if u < cdf {
                s = k;
                break;
            }
        }
        Choice {
            segments,
            s,
            t: segments + 1 - s,
            probability: select[s] / m as f32,
            select,
        }
    }

    /// The raster position of `point` placed by `place` and its value
    /// there, with the choice's light subpath in `buffers.light`.
    fn pixel(
        &self,
        scene: &Scene,
        point: &TorusPoint,
        place: Placement,
        choice: &Choice,
        buffers: &mut SubpathBuffers,
    ) -> (Vec2, Rgb) {
        let mut source = PssSource::new(point, Stream::COUNT);
        source.set_stream(Stream::Camera);
        let (ox, oy) = source.next_2d();
        let raster = place.raster(ox, oy);
        let (s, t) = (choice.s, choice.t);
        if buffers.light.len() != s {
            return (raster, Rgb::BLACK);
        }
        let nc = generate_camera_subpath(scene, raster, &mut source, t, None, &mut buffers.camera);
        if nc != t {
            return (raster, Rgb::BLACK);
        }
        // The connection's numbers follow the two choice numbers.
        source.set_stream(Stream::Connection);
        source.next_2d();
        let heuristic = self.bdpt.heuristic;
        let Some(c) = connect(
            scene,
            &buffers.camera,
            &buffers.light,
            s,
            t,
            &mut source,
            heuristic,
        ) else {
            return (raster, Rgb::BLACK);
        };
        if c.weight <= 0.0 {
            return (raster, Rgb::BLACK);
        }
        let w = mis_weight_selected(
            scene,
            &SceneBsdfs,
            0,
            &buffers.camera,
            &buffers.light,
            s,
            t,
            c.sampled.as_ref(),
            heuristic,
            2,
            &choice.select,
        );
        (raster, c.l * (w / (c.weight * choice.probability)))
    }

    /// The choice of `point` and its light subpath in `buffers.light`.
    fn light_subpath(
        &self,
        scene: &Scene,
        point: &TorusPoint,
        buffers: &mut SubpathBuffers,
    ) -> Choice {
        let mut source = PssSource::new(point, Stream::COUNT);
        let choice = self.choose(&mut source);
        source.set_stream(Stream::Light);
        generate_light_subpath(scene, &mut source, choice.s, None, &mut buffers.light);
        choice
    }
}

impl TileShift for MmltShift {
    fn name(&self) -> &'static str {
        match self.exponent {
            0 => "ummlt",
            1 => "lmmlt",
            2 => "qmmlt",
            3 => "cmmlt",
            _ => "mmlt",
        }
    }

    fn evaluate(
        &self,
        scene: &Scene,
        point: &TorusPoint,
        pixels: &[Option<(u32, u32)>],
        out: &mut [Rgb],
    ) {
        BUFFERS.with_borrow_mut(|buffers| {
            let choice = self.light_subpath(scene, point, buffers);
            for (q, o) in pixels.iter().zip(out.iter_mut()) {
                *o = q.map_or(Rgb::BLACK, |q| {
                    self.pixel(scene, point, Placement::Pixel(q), &choice, buffers)
                        .1
                });
            }
        });
    }

    fn evaluate_film(&self, scene: &Scene, point: &TorusPoint) -> (Vec2, Rgb) {
        let film = Placement::Film((scene.film.width, scene.film.height));
        BUFFERS.with_borrow_mut(|buffers| {
            let choice = self.light_subpath(scene, point, buffers);
            self.pixel(scene, point, film, &choice, buffers)
        })
    }

    fn offset_coordinates(&self) -> [usize; 2] {
        super::camera_stream_offset_coordinates()
    }
}
