//! Stratified MCMC (Gruson, West and Hachisuka 2020) as seed 003 extends
//! it (spec `seed003-smcmc.md` §8, §11): one Markov chain per pixel,
//! confined to a tile around it ([`tile`]); shift operators that evaluate
//! every pixel of the tile from one primary-sample state ([`TileShift`]:
//! [`random_replay`], [`bdpt_shift`], [`rbdpt_shift`], [`mmlt_shift`],
//! [`guided_shift`]); per-tile estimates aligned by a least-squares solve
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
//! alignment and gives `b⁰_s = Σ_{q∈N_s} lum Ĩ(q)`. The alignment solves
//! once per colour channel by default, each from `b⁰` ([`AlignmentChannels`]:
//! one solve on luminance moved energy between colours).
//!
//! # Reconstruction filter
//!
//! The thesis's `h_j` is the box over pixel `j`; then `b_s G_s(j)` is
//! pixel `j`'s value. Our film defines pixel `j` with the scene's filter,
//! `I(j) = ∫ f(x_j − p)/Z_j L(p) dp` (`crate::film`, the value every other
//! integrator converges to), and a filter wider than the box reaches
//! pixels outside the tile, so `b_s G_s(j)` would miss the light that
//! pixels outside tile `s` spread onto `j` (box-filtering instead moved the
//! tilted Cornell box's mean by +0.38% in blue, 3.9σ, against PT with the
//! scene's Gaussian). Splitting the image by source pixel keeps the
//! estimator exact: `I(j) = Σ_q C(q→j)` with `C(q→j)` the part of pixel
//! `j` made by paths through pixel `q`'s footprint, and every tile
//! containing `q` estimates `C(q→j)` as `b_s F_s(q→j)`, where `F_s`
//! accumulates the same mean-value splats as `G_s` spread by the film's
//! splat weights from the raster position `q + o` ([`FilterSplat`]). The
//! image is `Î(j) = Σ_q (1/n_q) Σ_{s∈N(q)} b_s F_s(q→j)`; the box filter
//! gives `F_s(q→j) = δ_qj G_s(q)`, the formula above. The alignment, `Ĩ`
//! and the sample-count image stay on the box histograms (`b_s` is the
//! integral of the tile target, whatever the filter).

pub mod bdpt_shift;
pub mod checkpoint;
pub mod global_init;
pub mod guided_shift;
pub mod mmlt_shift;
pub mod random_replay;
pub mod rbdpt_shift;
pub mod solver;
pub mod tile;

use crate::color::Rgb;
use crate::film::{Film, Filter};
use crate::sampling::to_unit_f32;
use crate::scene::{FilterKind, Scene};
use glam::Vec2;
use mcmc_core::space::TorusPoint;
use mcmc_core::target::{Evaluation, Target};
use std::sync::Arc;
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

/// The sub-pixel offset's coordinates for shifts that read a state with
/// BDPT's interleaved streams (camera, light, connection): the camera
/// stream's first two numbers (number `i` of stream `k` is coordinate
/// `COUNT·i + k`).
pub fn camera_stream_offset_coordinates() -> [usize; 2] {
    let k = crate::sampling::Stream::Camera as usize;
    [k, crate::sampling::Stream::COUNT + k]
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

impl<S: TileShift> TileTarget<'_, S> {
    /// [`Target::evaluate`] with the values of some slots already known:
    /// `known[k]` is `f` of `state` at slot `k`'s pixel, taken from another
    /// tile holding the same pixel (the partner of a tile exchange), and
    /// only the other slots are traced. A shift's value at a pixel depends on
    /// the state and that pixel alone ([`TileShift::evaluate`]), so the
    /// evaluation is the same, bit for bit, as tracing every slot.
    pub fn evaluate_known(
        &self,
        state: &TorusPoint,
        known: &[Option<Rgb>; MAX_TILE_PIXELS],
    ) -> Evaluation<TileValues> {
        let mut v = TileValues::default();
        let mut pixels = self.pixels;
        for (p, k) in pixels.iter_mut().zip(known) {
            if k.is_some() {
                *p = None;
            }
        }
        self.shift.evaluate(
            self.scene,
            state,
            &pixels[..self.slots],
            &mut v.f[..self.slots],
        );
        for (f, k) in v.f.iter_mut().zip(known) {
            if let Some(k) = k {
                *f = *k;
            }
        }
        v.offset = self
            .shift
            .offset_coordinates()
            .map(|i| to_unit_f32(state.coordinate(i)));
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

impl<S: TileShift> Target<TorusPoint> for TileTarget<'_, S> {
    type Payload = TileValues;

    fn evaluate(&self, state: &TorusPoint) -> Evaluation<TileValues> {
        self.evaluate_known(state, &[None; MAX_TILE_PIXELS])
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

crate::choice! {
    /// What the tile alignment solves on.
    pub enum AlignmentChannels {
        /// One solve on luminance, whose `b_s` scales every channel: it
        /// keeps the image's luminance where `b⁰` put it, not each
        /// channel's (docs/smcmc.md "Session 32").
        Luminance = "luminance",
        /// One solve per colour channel, each with its own `G` and `Ĩ`
        /// (Gruson's code, spec §8.4).
        Rgb = "rgb",
    }
}

/// Luminance of an accumulated RGB triple (the weights of [`Rgb::luminance`]).
pub fn luminance(c: [f64; 3]) -> f64 {
    0.212_671 * c[0] + 0.715_160 * c[1] + 0.072_169 * c[2]
}

/// How a non-box reconstruction filter spreads a slot's value over the
/// film (see the module's "Reconstruction filter"): the film's splat
/// weights `f(x_j − p)/Z_j` around the slot's raster position, stored per
/// slot over the `(2m+1)²` pixels within `m` of the slot's pixel.
pub struct FilterSplat {
    /// A splat-only film of the image, used for its weights only.
    film: Film,
    /// Reach `m` in pixels: `⌊r + ½⌋` for filter radius `r` (a point of
    /// pixel `q` reaches the pixel centres within `r`).
    reach: i64,
}

impl FilterSplat {
    /// The spreading of `scene`'s filter; `None` for the box filter, whose
    /// splats are the box histograms themselves.
    pub fn new(scene: &Scene) -> Option<FilterSplat> {
        if matches!(scene.film.filter, FilterKind::Box) {
            return None;
        }
        let (w, h) = (scene.film.width, scene.film.height);
        let filter = Arc::new(Filter::new(scene.film.filter, w, h));
        let reach = (filter.radius() + 0.5).floor() as i64;
        Some(FilterSplat {
            film: Film::new_splat_only(w, h, filter),
            reach,
        })
    }

    /// Pixels stored per slot.
    pub fn cells(&self) -> usize {
        let side = 2 * self.reach as usize + 1;
        side * side
    }

    /// The cell of pixel `(x, y)` around `q`, if within reach.
    fn cell(&self, q: (u32, u32), x: u32, y: u32) -> Option<usize> {
        let (dx, dy) = (
            i64::from(x) - i64::from(q.0) + self.reach,
            i64::from(y) - i64::from(q.1) + self.reach,
        );
        let side = 2 * self.reach + 1;
        (dx >= 0 && dy >= 0 && dx < side && dy < side).then(|| (dy * side + dx) as usize)
    }

    /// Adds `weight · f` spread from raster position `q + offset` into the
    /// cells `acc` of slot pixel `q`.
    pub fn add(&self, acc: &mut [[f64; 3]], q: (u32, u32), offset: [f32; 2], f: Rgb, weight: f64) {
        if weight == 0.0 || f.is_black() {
            return;
        }
        let p = Vec2::new(q.0 as f32 + offset[0], q.1 as f32 + offset[1]);
        self.film.splat_weights(p, |x, y, w| {
            if let Some(c) = self.cell(q, x, y) {
                let w = weight * f64::from(w);
                acc[c][0] += w * f64::from(f.r);
                acc[c][1] += w * f64::from(f.g);
                acc[c][2] += w * f64::from(f.b);
            }
        });
    }

    /// Calls `visit(pixel index, cell)` for every image pixel within reach
    /// of pixel `q`.
    fn around(&self, q: usize, width: u32, height: u32, mut visit: impl FnMut(usize, usize)) {
        let (qx, qy) = ((q % width as usize) as u32, (q / width as usize) as u32);
        let m = self.reach;
        for y in (i64::from(qy) - m).max(0)..=(i64::from(qy) + m).min(i64::from(height) - 1) {
            for x in (i64::from(qx) - m).max(0)..=(i64::from(qx) + m).min(i64::from(width) - 1) {
                let (x, y) = (x as u32, y as u32);
                let c = self.cell((qx, qy), x, y).expect("within reach");
                visit(y as usize * width as usize + x as usize, c);
            }
        }
    }
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
    /// Under a non-box filter, `F_s(q→j)` unnormalised: the splats of `g`
    /// spread by [`FilterSplat`], `cells` per slot (empty for the box).
    pub filtered: Vec<[f64; 3]>,
}

impl TileSums {
    /// Empty sums, with room for `filter`'s spreading over `slots` slots.
    pub fn new(filter: Option<&FilterSplat>, slots: usize) -> TileSums {
        TileSums {
            filtered: filter.map_or(Vec::new(), |f| vec![[0.0; 3]; slots * f.cells()]),
            ..TileSums::default()
        }
    }

    /// Adds the mean-value splat `weight · f_q` of `values` at every slot
    /// (`pixels[k]`: slot `k`'s pixel) to `g`, and spread by `filter` to
    /// `filtered`.
    pub fn splat(
        &mut self,
        values: &TileValues,
        weight: f64,
        pixels: &[Option<(u32, u32)>],
        filter: Option<&FilterSplat>,
    ) {
        accumulate(&mut self.g, values, weight);
        if let Some(fs) = filter {
            let cells = fs.cells();
            for (k, (q, f)) in pixels.iter().zip(&values.f).enumerate() {
                if let Some(q) = q {
                    let acc = &mut self.filtered[k * cells..(k + 1) * cells];
                    fs.add(acc, *q, values.offset, *f, weight);
                }
            }
        }
    }
}

impl Default for TileSums {
    fn default() -> Self {
        TileSums {
            g: [[0.0; 3]; MAX_TILE_PIXELS],
            samples: 0,
            large: [[0.0; 3]; MAX_TILE_PIXELS],
            large_samples: 0,
            active: false,
            filtered: Vec::new(),
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
    /// `b_s` per colour channel and tile (the same for the three under
    /// [`AlignmentChannels::Luminance`]).
    pub b: [Vec<f64>; 3],
    /// The alignment's sweeps and residuals.
    pub alignment: AlignmentSummary,
}

/// What a develop's alignment did: its sweeps and, for the lane furthest
/// from converged, its residuals (see [`solver::Alignment`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AlignmentSummary {
    /// Sweeps run.
    pub iterations: usize,
    /// `‖r(b⁰)‖/‖c‖` of the worst lane.
    pub initial_residual: f64,
    /// `‖r(b)‖/‖c‖` of the worst lane after the sweeps.
    pub residual: f64,
}

impl<const N: usize> From<&solver::Alignment<N>> for AlignmentSummary {
    fn from(a: &solver::Alignment<N>) -> Self {
        let worst = a.worst_lane();
        AlignmentSummary {
            iterations: a.iterations,
            initial_residual: a.initial_residual[worst],
            residual: a.residual[worst],
        }
    }
}

/// Develops the image from every tile's sums: `Ĩ`, `b⁰`, the alignment
/// with weight `alpha` and `iterations` Jacobi sweeps (fewer where
/// `more_sweeps(i)` is false before sweep `i`: see
/// [`solver::AlignmentProblem::solve_while`]), then `Î(j)` (under
/// `filter`, from the spread sums: see the module's "Reconstruction
/// filter").
pub fn develop(
    tiling: &Tiling,
    tiles: &[TileSums],
    channels: AlignmentChannels,
    alpha: f64,
    (iterations, more_sweeps): (usize, &dyn Fn(usize) -> bool),
    filter: Option<&FilterSplat>,
) -> Developed {
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
    let active: Vec<bool> = tiles.iter().map(|t| t.active && t.samples > 0).collect();
    // `b⁰_s = Σ_{q∈N_s} lum Ĩ(q)`, the integral of the tile's target: the
    // `b_s` of every channel, as `G_s` of every channel is of `f_c/π̃_s`.
    let i_lum: Vec<f64> = i_tilde.iter().map(|&c| luminance(c)).collect();
    let b0: Vec<f64> = (0..pixels)
        .map(|s| tiling.pixels(s).map(|(_, j)| i_lum[j]).sum())
        .collect();
    // The alignment of the tiles' histograms and `Ĩ` in `N` lanes, each
    // a scalar of their RGB values, from `b⁰`.
    let inputs = AlignInputs {
        tiling,
        tiles,
        active: &active,
        i_tilde: &i_tilde,
        b0: &b0,
        alpha,
        sweeps: (iterations, more_sweeps),
    };
    let (b_lanes, alignment): ([Vec<f64>; 3], AlignmentSummary) = match channels {
        AlignmentChannels::Luminance => {
            let a = inputs.align(|v| [luminance(v)]);
            let lane = a.lane(0);
            ([lane.clone(), lane.clone(), lane], (&a).into())
        }
        AlignmentChannels::Rgb => {
            let a = inputs.align(|v| v);
            (std::array::from_fn(|c| a.lane(c)), (&a).into())
        }
    };
    let b: [&[f64]; 3] = std::array::from_fn(|c| b_lanes[c].as_slice());
    let mut image = Vec::with_capacity(pixels);
    let mut samples = Vec::with_capacity(pixels);
    for (j, i_t) in i_tilde.iter().enumerate() {
        let (mut sum, mut n, mut count) = ([0.0; 3], 0u32, 0.0);
        for (s, k) in tiling.covering(j) {
            count += luminance(tiles[s].g[k]);
            if active[s] {
                for (c, (acc, v)) in sum.iter_mut().zip(tiles[s].g[k]).enumerate() {
                    *acc += b[c][s] / tiles[s].samples as f64 * v;
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
    if let Some(fs) = filter {
        image = spread_image(tiling, tiles, &active, b, &i_tilde, fs);
    }
    Developed {
        image,
        samples,
        b: b_lanes,
        alignment,
    }
}

/// What a develop's alignment starts from: the tiles, which take part,
/// `Ĩ`, `b⁰`, the weight `alpha` and `(iterations, more)` sweeps.
struct AlignInputs<'a> {
    tiling: &'a Tiling,
    tiles: &'a [TileSums],
    active: &'a [bool],
    i_tilde: &'a [[f64; 3]],
    b0: &'a [f64],
    alpha: f64,
    sweeps: (usize, &'a dyn Fn(usize) -> bool),
}

impl AlignInputs<'_> {
    /// The alignment of the tiles' histograms `G_s` and of `Ĩ` in the `N`
    /// lanes `lanes(rgb)` of their RGB values, every lane from `b⁰`.
    fn align<const N: usize>(&self, lanes: impl Fn([f64; 3]) -> [f64; N]) -> solver::Alignment<N> {
        let slots = self.tiling.slots();
        let i_lanes: Vec<[f64; N]> = self.i_tilde.iter().map(|&c| lanes(c)).collect();
        let mut g = vec![[0.0; N]; self.tiles.len() * slots];
        for (s, t) in self.tiles.iter().enumerate() {
            if self.active[s] {
                for k in 0..slots {
                    g[s * slots + k] = lanes(t.g[k]).map(|v| v / t.samples as f64);
                }
            }
        }
        let problem = solver::AlignmentProblem {
            tiling: self.tiling,
            g: &g,
            active: self.active,
            i_tilde: &i_lanes,
            alpha: self.alpha,
        };
        let b0: Vec<[f64; N]> = self.b0.iter().map(|&b| [b; N]).collect();
        let (iterations, more) = self.sweeps;
        problem.solve_while(&b0, iterations, more)
    }
}

/// `Î(j) = Σ_q (1/n_q) Σ_{s∈N(q)} b_s F_s(q→j)` over the source pixels
/// `q` (sequentially, in pixel order: the same bits on any thread count).
/// A source pixel none of whose tiles runs falls back on `Ĩ(q)` itself,
/// unspread, as the box image does (spread from the pixel's centre through
/// the filter it lost energy: −1.5% on a stopped 64×48 box, session 34).
/// In a run that stepped, such a pixel's uniform samples were all black (a
/// tile starts at its first lit one), so the fallback is zero; it is the
/// image of a run stopped before any tile stepped.
fn spread_image(
    tiling: &Tiling,
    tiles: &[TileSums],
    active: &[bool],
    b: [&[f64]; 3],
    i_tilde: &[[f64; 3]],
    fs: &FilterSplat,
) -> Vec<Rgb> {
    let (w, h) = (tiling.width, tiling.height);
    let cells = fs.cells();
    let mut out = vec![[0.0f64; 3]; tiling.tiles()];
    for (q, &i_q) in i_tilde.iter().enumerate() {
        let n = tiling.covering(q).filter(|&(s, _)| active[s]).count();
        if n == 0 {
            // Added: active neighbours' spreads may have reached `q`.
            for (o, v) in out[q].iter_mut().zip(i_q) {
                *o += v;
            }
            continue;
        }
        for (s, k) in tiling.covering(q).filter(|&(s, _)| active[s]) {
            let scale: [f64; 3] =
                std::array::from_fn(|c| b[c][s] / (tiles[s].samples as f64 * n as f64));
            let acc = &tiles[s].filtered[k * cells..(k + 1) * cells];
            fs.around(q, w, h, |j, c| {
                for ((o, v), scale) in out[j].iter_mut().zip(acc[c]).zip(scale) {
                    *o += scale * v;
                }
            });
        }
    }
    out.into_iter()
        .map(|v| Rgb::new(v[0] as f32, v[1] as f32, v[2] as f32))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use mcmc_core::rng::{stream_rng, uniform};

    /// Tile sums of a 7×5 image with random histograms and large-step sums
    /// whose colour at every slot is `colour(slot value)`.
    fn sums(tiling: &Tiling, colour: impl Fn(f64, usize) -> [f64; 3]) -> Vec<TileSums> {
        let mut rng = stream_rng(7, 0);
        (0..tiling.tiles())
            .map(|s| {
                let mut t = TileSums::new(None, tiling.slots());
                for (k, _) in tiling.pixels(s) {
                    t.g[k] = colour(0.5 + 3.5 * uniform(&mut rng), s);
                    t.large[k] = colour(0.5 + 3.5 * uniform(&mut rng), s);
                }
                (t.samples, t.large_samples, t.active) = (100, 10, true);
                t
            })
            .collect()
    }

    fn align(tiling: &Tiling, tiles: &[TileSums], channels: AlignmentChannels) -> Developed {
        develop(tiling, tiles, channels, 0.3, (50, &|_| true), None)
    }

    /// The solve is homogeneous (scaling `G` and `Ĩ` by `k` leaves `b`), so
    /// on an image whose channels are multiples of one another each
    /// channel's alignment is the luminance's, to rounding; and on one
    /// where a channel varies apart (the control) it is not.
    #[test]
    fn per_channel_alignment_of_a_grey_image_is_the_luminance_alignment() {
        let tiling = Tiling::new(7, 5, TileShape::Plus);
        let grey = sums(&tiling, |v, _| [0.8 * v, v, 0.3 * v]);
        let lum = align(&tiling, &grey, AlignmentChannels::Luminance);
        let rgb = align(&tiling, &grey, AlignmentChannels::Rgb);
        assert!(
            lum.alignment.iterations == 50
                && lum.alignment.residual < lum.alignment.initial_residual
        );
        for c in 0..3 {
            for (a, b) in lum.b[c].iter().zip(&rgb.b[c]) {
                assert!((a - b).abs() <= 1e-12 * a.abs(), "{a} {b}");
            }
        }
        for (a, b) in lum.image.iter().zip(&rgb.image) {
            for (x, y) in [(a.r, b.r), (a.g, b.g), (a.b, b.b)] {
                assert!((x - y).abs() <= 1e-6 * x.abs(), "{x} {y}");
            }
        }
        // Control: blue brighter in odd tiles; the channels' solves differ.
        let tinted = sums(&tiling, |v, s| [0.8 * v, v, (0.3 + (s % 2) as f64) * v]);
        let lum = align(&tiling, &tinted, AlignmentChannels::Luminance);
        let rgb = align(&tiling, &tinted, AlignmentChannels::Rgb);
        let blue = |d: &Developed| d.image.iter().map(|c| f64::from(c.b)).sum::<f64>();
        assert!((blue(&lum) / blue(&rgb) - 1.0).abs() > 1e-3);
    }
}
