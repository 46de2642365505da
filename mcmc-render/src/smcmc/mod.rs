//! Stratified MCMC (Gruson, West and Hachisuka 2020) as seed 003 extends
//! it (spec `seed003-smcmc.md` §8, §11): one Markov chain per pixel,
//! confined to a tile around it ([`tile`]); shift operators that evaluate
//! every pixel of the tile from one primary-sample state ([`TileShift`]:
//! [`random_replay`], [`bdpt_shift`]); per-tile estimates aligned by a least-squares solve
//! ([`solver`]). The driver, with tile replica exchange and the
//! statistics, is `crate::integrators::smcmc`.
//!
//! # Estimator (spec §8.3)
//!
//! Tile `s` targets `π̃_s(u) = Σ_{q∈N_s} lum f(T_q(u))` over primary
//! sample space, whose integral is `b_s = Σ_{q∈N_s} I(q)` (each `f(T_q(u))`
//! with `u` uniform is an unbiased one-sample estimate of pixel `q`). Its
//! chain accumulates, with mean-value substitution,
//! `G_s(j) = (1/N) Σ_k [a f_j(v)/π̃_s(v) + (1−a) f_j(u)/π̃_s(u)]`, so
//! `b_s G_s(j) → I(j)`, and the image is
//! `Î(j) = (1/n_j) Σ_{s∈N(j)} b_s G_s(j)` over the `n_j` initialised tiles
//! containing `j` (a pixel none of whose tiles started falls back on
//! `Ĩ(j)`). Every large-step proposal (and every start-up candidate) is a
//! uniform sample: its `f_q` feed the per-pixel estimate
//! `Ĩ(j) = Σ_{s∈N(j)} Σ f_j / Σ_{s∈N(j)} n_s^large` that anchors the
//! alignment and gives `b⁰_s = Σ_{q∈N_s} lum Ĩ(q)`. Pixels are box-filtered
//! over their footprint (the thesis's `h_j`), whatever the scene's filter.

pub mod bdpt_shift;
pub mod global_init;
pub mod random_replay;
pub mod solver;
pub mod tile;

use crate::color::Rgb;
use crate::scene::Scene;
use glam::Vec2;
use mcmc_core::space::TorusPoint;
use mcmc_core::target::{Evaluation, Target};
pub use tile::{MAX_TILE_PIXELS, TileShape, TileValues, Tiling};

/// A shift operator: evaluates one primary-sample state at every pixel of
/// a tile.
pub trait TileShift: Sync {
    /// Short name for statistics (`rr`).
    fn name(&self) -> &'static str;
    /// Writes `f(T_q(u))` into `out[k]` for each `pixels[k] = Some(q)`
    /// (black for `None`, a slot outside the image).
    fn evaluate(
        &self,
        scene: &Scene,
        point: &TorusPoint,
        pixels: &[Option<(u32, u32)>],
        out: &mut [Rgb],
    );

    /// The state read with its sub-pixel offset `o` taken as a position on
    /// the whole film (`raster = (o_x W, o_y H)`): that raster position and
    /// `f` of the path there (the target of the global start-up chains,
    /// [`global_init`]).
    fn evaluate_film(&self, scene: &Scene, point: &TorusPoint) -> (Vec2, Rgb);

    /// Indices of the two sub-pixel offset numbers among the state's
    /// coordinates.
    fn offset_coordinates(&self) -> [usize; 2];
}

/// Where a shift puts the camera sample of a state whose sub-pixel offset
/// is `(o_x, o_y)`.
#[derive(Clone, Copy, Debug)]
pub enum Placement {
    /// In pixel `(x, y)`: raster `(x + o_x, y + o_y)` (a tile's pixel).
    Pixel((u32, u32)),
    /// Anywhere on a `W × H` film: raster `(o_x W, o_y H)`.
    Film((u32, u32)),
}

impl Placement {
    /// The raster position of offset `(ox, oy)`.
    pub fn raster(self, ox: f32, oy: f32) -> Vec2 {
        match self {
            Placement::Pixel((x, y)) => Vec2::new(x as f32 + ox, y as f32 + oy),
            Placement::Film((w, h)) => Vec2::new(ox * w as f32, oy * h as f32),
        }
    }
}

/// The target `ln π̃_s` of one tile; its payload holds the values at every
/// slot. A zero sum gives `−∞`; a NaN or infinite value gives NaN, which
/// `mcmc-core` rejects and counts.
pub struct TileTarget<'a, S> {
    /// The scene.
    pub scene: &'a Scene,
    /// The shift.
    pub shift: &'a S,
    /// The pixel of each slot, `None` outside the image.
    pub pixels: [Option<(u32, u32)>; MAX_TILE_PIXELS],
    /// Slots in use.
    pub slots: usize,
}

impl<S: TileShift> Target<TorusPoint> for TileTarget<'_, S> {
    type Payload = TileValues;

    fn evaluate(&self, state: &TorusPoint) -> Evaluation<TileValues> {
        let mut v = TileValues::default();
        self.shift.evaluate(
            self.scene,
            state,
            &self.pixels[..self.slots],
            &mut v.f[..self.slots],
        );
        let finite = v.f.iter().all(|c| c.is_finite());
        v.total = v.f.iter().map(|c| f64::from(c.luminance())).sum();
        let log_density = if !finite || !v.total.is_finite() {
            f64::NAN
        } else if v.total > 0.0 {
            v.total.ln()
        } else {
            f64::NEG_INFINITY
        };
        Evaluation::new(log_density, v)
    }
}

/// Adds `weight · f_q` of `values` to `acc` slot by slot.
pub fn accumulate(acc: &mut [[f64; 3]; MAX_TILE_PIXELS], values: &TileValues, weight: f64) {
    for (a, f) in acc.iter_mut().zip(&values.f) {
        a[0] += weight * f64::from(f.r);
        a[1] += weight * f64::from(f.g);
        a[2] += weight * f64::from(f.b);
    }
}

/// Luminance of an accumulated RGB triple (the weights of [`Rgb::luminance`]).
pub fn luminance(c: [f64; 3]) -> f64 {
    0.212_671 * c[0] + 0.715_160 * c[1] + 0.072_169 * c[2]
}

/// What every tile contributes to the image once its chain has run.
#[derive(Clone, Debug)]
pub struct TileSums {
    /// Σ of the expected-value splats `f_q/π̃_s` per slot (RGB).
    pub g: [[f64; 3]; MAX_TILE_PIXELS],
    /// Transitions splatted (the `N` of `G_s = g/N`).
    pub samples: u64,
    /// Σ of `f_q` over the uniform samples (large steps, start-up) per slot.
    pub large: [[f64; 3]; MAX_TILE_PIXELS],
    /// Number of uniform samples.
    pub large_samples: u64,
    /// Whether the chain is running (has a state with `π̃_s > 0`).
    pub active: bool,
}

impl Default for TileSums {
    fn default() -> Self {
        TileSums {
            g: [[0.0; 3]; MAX_TILE_PIXELS],
            samples: 0,
            large: [[0.0; 3]; MAX_TILE_PIXELS],
            large_samples: 0,
            active: false,
        }
    }
}

/// The developed image and what the alignment reported.
#[derive(Clone, Debug)]
pub struct Developed {
    /// The image, row-major.
    pub image: Vec<Rgb>,
    /// The per-pixel sample density: `Σ_{s∈N(j)} lum(g_s(j))`, the number
    /// of chain samples that fell in pixel `j` in expectation (each
    /// transition of tile `s` puts a share `lum f_j/π̃_s` of one sample
    /// on pixel `j`).
    pub samples: Vec<Rgb>,
    /// The alignment.
    pub alignment: solver::Alignment,
}

/// Develops the image from every tile's sums: `Ĩ`, `b⁰`, the alignment
/// with weight `alpha` and `iterations` Jacobi sweeps, then `Î(j)`.
pub fn develop(tiling: &Tiling, tiles: &[TileSums], alpha: f64, iterations: usize) -> Developed {
    let slots = tiling.slots();
    let pixels = tiling.tiles();
    // Ĩ(j) from every uniform sample of the tiles that contain j.
    let i_tilde: Vec<[f64; 3]> = (0..pixels)
        .map(|j| {
            let (mut sum, mut n) = ([0.0; 3], 0u64);
            for (s, k) in tiling.covering(j) {
                for (acc, v) in sum.iter_mut().zip(tiles[s].large[k]) {
                    *acc += v;
                }
                n += tiles[s].large_samples;
            }
            if n > 0 {
                sum.map(|v| v / n as f64)
            } else {
                [0.0; 3]
            }
        })
        .collect();
    let i_lum: Vec<f64> = i_tilde.iter().map(|&c| luminance(c)).collect();
    let active: Vec<bool> = tiles.iter().map(|t| t.active && t.samples > 0).collect();
    let mut g = vec![0.0; pixels * slots];
    for (s, t) in tiles.iter().enumerate() {
        if active[s] {
            for k in 0..slots {
                g[s * slots + k] = luminance(t.g[k]) / t.samples as f64;
            }
        }
    }
    let b0: Vec<f64> = (0..pixels)
        .map(|s| tiling.pixels(s).map(|(_, j)| i_lum[j]).sum())
        .collect();
    let problem = solver::AlignmentProblem {
        tiling,
        g: &g,
        active: &active,
        i_tilde: &i_lum,
        alpha,
    };
    let alignment = problem.solve(&b0, iterations);
    let mut image = Vec::with_capacity(pixels);
    let mut samples = Vec::with_capacity(pixels);
    for (j, i_t) in i_tilde.iter().enumerate() {
        let (mut sum, mut n, mut count) = ([0.0; 3], 0u32, 0.0);
        for (s, k) in tiling.covering(j) {
            count += luminance(tiles[s].g[k]);
            if active[s] {
                let w = alignment.b[s] / tiles[s].samples as f64;
                for (acc, v) in sum.iter_mut().zip(tiles[s].g[k]) {
                    *acc += w * v;
                }
                n += 1;
            }
        }
        let v = if n > 0 {
            sum.map(|v| v / f64::from(n))
        } else {
            *i_t
        };
        image.push(Rgb::new(v[0] as f32, v[1] as f32, v[2] as f32));
        samples.push(Rgb::new(count as f32, count as f32, count as f32));
    }
    Developed {
        image,
        samples,
        alignment,
    }
}
