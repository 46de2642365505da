//! Films: pixel accumulation with the scene's reconstruction filter.
//!
//! Two accumulators share one film:
//! - **samples** (camera-driven estimators such as path tracing): each
//!   sample adds `f(x_j − p)·L` and `f(x_j − p)` to the pixels `j` the
//!   filter reaches, and the pixel is the ratio (Mitsuba's weighted mean);
//! - **splats** (light tracing, later BDPT/MLT): a contribution at `p`
//!   adds `f(x_j − p) / Z_j · L`, where `Z_j = ∫_image f(x_j − q) dq`. The
//!   developed value divides by the number of splatting paths per pixel.
//!   With this `Z_j` both accumulators converge to the same image, border
//!   pixels included.
//!
//! A film may cover a sub-rectangle of the image (a tile plus the filter
//! margin) so that work units render into private films which are then
//! added into the main film in a fixed order ([`Film::add_film`]): the
//! result is independent of the number of threads.

use crate::color::Rgb;
use crate::scene::FilterKind;
use glam::{Vec2, Vec4};
use std::sync::Arc;

/// Round to nearest by adding and subtracting 1.5·2²³ (no rounding
/// instruction before SSE4.1).
const EXP_ROUND: f32 = 12_582_912.0;
/// ln 2 split in two (Cody–Waite): the high part has few mantissa bits, so
/// `n · EXP_LN2_HI` is exact for the `n` that occur.
const EXP_LN2_HI: f32 = 0.693_359_4;
/// ln 2 − [`EXP_LN2_HI`].
const EXP_LN2_LO: f32 = -2.121_944_4e-4;
/// Cephes `expf`: e^r ≈ 1 + r + r²·P(r), P's coefficients from the highest degree.
const EXP_P: [f32; 6] = [
    1.987_569_1e-4,
    1.398_199_9e-3,
    8.333_452e-3,
    4.166_579_6e-2,
    1.666_666_5e-1,
    0.5, // Cephes: 5.0000001201e-1, which is 0.5 in f32
];

/// `e^x` for `x ≤ 0` without a libm call, to about one ulp: Cody–Waite
/// reduction `x = n·ln 2 + r`, `|r| ≤ ln 2 / 2`, and Cephes' degree-7
/// polynomial for `e^r` (the coefficients of Cephes `expf`). Arguments below
/// −87 are clamped there (`e^{−87}` ≈ 1.6e-38, far below any filter's cut-off).
/// Plain `f32` arithmetic only, so it gives bit-identical values on every
/// target.
#[inline(always)]
fn exp_neg(x: f32) -> f32 {
    let x = x.clamp(-87.0, 0.0);
    let shifted = x * std::f32::consts::LOG2_E + EXP_ROUND;
    let n = shifted - EXP_ROUND;
    let r = x - n * EXP_LN2_HI - n * EXP_LN2_LO;
    let z = r * r;
    let mut p = EXP_P[0];
    for &k in &EXP_P[1..] {
        p = p * r + k;
    }
    let e = p * z + r + 1.0;
    // 2ⁿ, n ∈ [−126, 0] (a normal number), from the bits of `shifted`:
    // they are those of 1.5·2²³ plus n in the low mantissa bits, and the
    // shift drops everything above them (no float-to-int conversion, which
    // would not vectorise).
    e * f32::from_bits(shifted.to_bits().wrapping_add(127) << 23)
}

/// Entries of Mitsuba's discretized filter table (`MI_FILTER_RESOLUTION`).
const TABLE: usize = 31;

/// A separable reconstruction filter with its border normalisation.
///
/// Gaussian and tent weights are Mitsuba 3's *discretized* filter, which
/// its CPU film uses for every sample (`eval_discretized`; measured with
/// `mi.ImageBlock` in 3.9.1): the exact filter tabulated at `r·i/31`,
/// i < 31, then 0, and looked up at `min(⌊|x|·31/r⌋, 31)`. At 0.8 pixel
/// it differs from the exact Gaussian by 8%, which leaves image means
/// alone but moves pixels at high-contrast edges (the emitter's).
#[derive(Clone, Debug)]
pub struct Filter {
    kind: FilterKind,
    radius: f32,
    alpha: f32,
    bias: f32,
    /// The discretized filter (Gaussian and tent).
    table: [f32; TABLE + 1],
    /// `Z` per column: ∫ over the image width of f(x_col − q).
    norm_x: Vec<f32>,
    /// `Z` per row.
    norm_y: Vec<f32>,
}

impl Filter {
    /// The filter for an image of the given size.
    pub fn new(kind: FilterKind, width: u32, height: u32) -> Filter {
        let (radius, alpha, bias) = match kind {
            FilterKind::Box => (0.5, 0.0, 0.0),
            FilterKind::Tent { radius } => (radius, 0.0, 0.0),
            FilterKind::Gaussian { stddev } => {
                let radius = 4.0 * stddev;
                let alpha = -1.0 / (2.0 * stddev * stddev);
                // The same exponential as the weights, so that the weight
                // at the radius is exactly zero.
                (radius, alpha, exp_neg(alpha * radius * radius))
            }
        };
        let mut f = Filter {
            kind,
            radius,
            alpha,
            bias,
            table: [0.0; TABLE + 1],
            norm_x: Vec::new(),
            norm_y: Vec::new(),
        };
        for i in 0..TABLE {
            f.table[i] = f.eval_exact(radius * i as f32 / TABLE as f32);
        }
        f.norm_x = (0..width).map(|i| f.integral_1d(i, width)).collect();
        f.norm_y = (0..height).map(|j| f.integral_1d(j, height)).collect();
        f
    }

    /// Filter support radius in pixels.
    pub fn radius(&self) -> f32 {
        self.radius
    }

    /// The exact 1D filter.
    fn eval_exact(&self, x: f32) -> f32 {
        match self.kind {
            FilterKind::Box => {
                if x.abs() <= 0.5 {
                    1.0
                } else {
                    0.0
                }
            }
            FilterKind::Gaussian { .. } => (exp_neg(self.alpha * x * x) - self.bias).max(0.0),
            FilterKind::Tent { .. } => (1.0 - x.abs() / self.radius).max(0.0),
        }
    }

    /// The table index of `x`.
    #[inline(always)]
    fn index(&self, x: f32) -> usize {
        ((x.abs() * (TABLE as f32 / self.radius)) as usize).min(TABLE)
    }

    /// 1D filter value: the box exactly, the others as Mitsuba's
    /// discretized table.
    pub fn eval_1d(&self, x: f32) -> f32 {
        match self.kind {
            FilterKind::Box => self.eval_exact(x),
            _ => self.table[self.index(x)],
        }
    }

    /// Gaussian weights at `x0, x0 + 1, x0 + 2, x0 + 3`. Only for
    /// [`FilterKind::Gaussian`].
    #[inline(always)]
    fn gaussian4(&self, x0: f32) -> [f32; 4] {
        [x0, x0 + 1.0, x0 + 2.0, x0 + 3.0].map(|d| self.table[self.index(d)])
    }

    /// ∫_0^t f(x) dx for t ≥ 0 (f even): exact for the box and for the
    /// table's steps of width r/31.
    fn cumulative(&self, t: f32) -> f64 {
        if let FilterKind::Box = self.kind {
            return t.min(0.5) as f64;
        }
        let step = self.radius as f64 / TABLE as f64;
        let a = t as f64 / step;
        let k = (a.floor() as usize).min(TABLE);
        let whole: f64 = self.table[..k].iter().map(|&v| v as f64).sum();
        (whole + (a - k as f64).min(1.0) * self.table[k] as f64) * step
    }

    /// ∫_0^n f(i + 0.5 − q) dq, exactly (the box and the table are
    /// piecewise constant).
    fn integral_1d(&self, i: u32, n: u32) -> f32 {
        let c = i as f64 + 0.5;
        // q from lo to hi is x = c − q from c − hi to c − lo.
        let g = |x: f64| x.signum() * self.cumulative(x.abs() as f32);
        let lo = (c - self.radius as f64).max(0.0);
        let hi = (c + self.radius as f64).min(n as f64);
        (g(c - lo) - g(c - hi)) as f32
    }
}

/// A rectangle of pixels with the two accumulators.
#[derive(Clone, Debug)]
pub struct Film {
    /// Full image width.
    pub width: u32,
    /// Full image height.
    pub height: u32,
    /// First column this film covers.
    pub x0: u32,
    /// First row this film covers.
    pub y0: u32,
    /// Columns covered.
    pub w: u32,
    /// Rows covered.
    pub h: u32,
    filter: Arc<Filter>,
    /// Σ f·L (rgb) and Σ f, per covered pixel.
    samples: Vec<[f32; 4]>,
    /// Σ f/Z·L per covered pixel.
    splats: Vec<[f32; 3]>,
}

impl Film {
    /// A film covering the whole image.
    pub fn new(width: u32, height: u32, filter: Arc<Filter>) -> Film {
        Film::sub(width, height, 0, 0, width, height, filter)
    }

    /// A film covering columns `x0..x0+w` and rows `y0..y0+h`.
    pub fn sub(
        width: u32,
        height: u32,
        x0: u32,
        y0: u32,
        w: u32,
        h: u32,
        filter: Arc<Filter>,
    ) -> Film {
        let n = (w * h) as usize;
        Film {
            width,
            height,
            x0,
            y0,
            w,
            h,
            filter,
            samples: vec![[0.0; 4]; n],
            splats: vec![[0.0; 3]; n],
        }
    }

    /// A whole-image film holding only the splat accumulator (light-path
    /// work units: 12 instead of 28 bytes per pixel); camera samples added
    /// to it are ignored.
    pub fn new_splat_only(width: u32, height: u32, filter: Arc<Filter>) -> Film {
        let mut f = Film::sub(width, height, 0, 0, 0, 0, filter);
        f.w = width;
        f.h = height;
        f.splats = vec![[0.0; 3]; (width * height) as usize];
        f
    }

    /// The film for a tile `[tx0, tx1) × [ty0, ty1)` grown by the filter radius.
    pub fn for_tile(
        width: u32,
        height: u32,
        tx0: u32,
        ty0: u32,
        tx1: u32,
        ty1: u32,
        filter: Arc<Filter>,
    ) -> Film {
        let m = filter.radius().ceil() as u32;
        let x0 = tx0.saturating_sub(m);
        let y0 = ty0.saturating_sub(m);
        let x1 = (tx1 + m).min(width);
        let y1 = (ty1 + m).min(height);
        Film::sub(width, height, x0, y0, x1 - x0, y1 - y0, filter)
    }

    /// The accumulators (camera samples `Σ f·L, Σ f`; splats), as a
    /// distributed run sends them ([`crate::cluster`]).
    pub fn accumulators(&self) -> (&[[f32; 4]], &[[f32; 3]]) {
        (&self.samples, &self.splats)
    }

    /// The film `(width, height, x0, y0, w, h)` with the given
    /// accumulators (from [`Film::accumulators`]; `samples` empty for a
    /// splat-only film), checked against its size.
    pub fn from_accumulators(
        [width, height, x0, y0, w, h]: [u32; 6],
        filter: Arc<Filter>,
        samples: Vec<[f32; 4]>,
        splats: Vec<[f32; 3]>,
    ) -> Result<Film, String> {
        // The window must lie in the image the filter was made for (a
        // forged checkpoint could say otherwise; splats index by both).
        let inside =
            |start: u32, len: u32, full: u32| start.checked_add(len).is_some_and(|e| e <= full);
        if !inside(x0, w, width)
            || !inside(y0, h, height)
            || filter.norm_x.len() != width as usize
            || filter.norm_y.len() != height as usize
        {
            return Err(format!(
                "a {w}×{h} window at ({x0}, {y0}) does not fit a {width}×{height} image filtered for {}×{}",
                filter.norm_x.len(),
                filter.norm_y.len()
            ));
        }
        let n = w as usize * h as usize;
        if splats.len() != n || !(samples.is_empty() || samples.len() == n) {
            return Err(format!(
                "a {w}×{h} film cannot hold {} samples and {} splats",
                samples.len(),
                splats.len()
            ));
        }
        Ok(Film {
            width,
            height,
            x0,
            y0,
            w,
            h,
            filter,
            samples,
            splats,
        })
    }

    /// Zeroes the accumulators.
    pub fn clear(&mut self) {
        self.samples.iter_mut().for_each(|p| *p = [0.0; 4]);
        self.splats.iter_mut().for_each(|p| *p = [0.0; 3]);
    }

    /// Pixel range the filter at `p` reaches, clipped to this film:
    /// columns `ceil(p.x − ½ − r) ..= floor(p.x − ½ + r)`, rows likewise.
    /// The four bounds are rounded as one SIMD vector, the upper ones as
    /// `floor(v) = −ceil(−v)` (exact).
    fn footprint(&self, p: Vec2) -> Option<(u32, u32, u32, u32)> {
        let r = self.filter.radius();
        let (cx, cy) = (p.x - 0.5, p.y - 0.5);
        let v = Vec4::new(cx - r, cy - r, -(cx + r), -(cy + r)).ceil();
        let bounds = Vec4::new(
            self.x0 as f32,
            self.y0 as f32,
            -((self.x0 + self.w) as f32 - 1.0),
            -((self.y0 + self.h) as f32 - 1.0),
        );
        let [lo_x, lo_y, neg_hi_x, neg_hi_y] = v.max(bounds).to_array();
        let (hi_x, hi_y) = (-neg_hi_x, -neg_hi_y);
        if !(lo_x <= hi_x && lo_y <= hi_y) {
            return None;
        }
        Some((lo_x as u32, hi_x as u32, lo_y as u32, hi_y as u32))
    }

    /// Filter weights along one axis for the pixel range `lo..=hi`
    /// (at most 16 pixels: the support of a filter of radius ≤ 7.5).
    fn weights(&self, lo: u32, hi: u32, p: f32, out: &mut [f32; 16]) -> usize {
        let n = ((hi - lo + 1) as usize).min(16);
        let f = &*self.filter;
        let x0 = lo as f32 + 0.5 - p;
        if let FilterKind::Gaussian { .. } = f.kind {
            // Four pixels at a time, one 4-lane exponential each (the
            // common footprint of the default filter, radius 2, is 4 × 4).
            // `out` holds 16 weights, so whole groups of four fit.
            let mut base = x0;
            for group in out.chunks_exact_mut(4).take(n.div_ceil(4)) {
                group.copy_from_slice(&f.gaussian4(base));
                base += 4.0;
            }
        } else {
            for (k, w) in out.iter_mut().take(n).enumerate() {
                *w = f.eval_1d((lo + k as u32) as f32 + 0.5 - p);
            }
        }
        n
    }

    /// Adds a camera sample at raster position `p` with radiance `l`.
    /// Non-finite radiance is dropped (and should be counted by the caller).
    #[inline(always)]
    pub fn add_sample(&mut self, p: Vec2, l: Rgb) {
        if !l.is_finite() || !p.is_finite() {
            return;
        }
        if self.samples.is_empty() {
            return;
        }
        let Some((x0, x1, y0, y1)) = self.footprint(p) else {
            return;
        };
        let stride = self.w as usize;
        let first = (y0 - self.y0) as usize * stride + (x0 - self.x0) as usize;
        let value = Vec4::new(l.r, l.g, l.b, 1.0);
        if x1 - x0 == 3
            && y1 - y0 == 3
            && let FilterKind::Gaussian { .. } = self.filter.kind
        {
            // The default filter's usual footprint, 4 × 4 pixels, unrolled:
            // the same weights and sums as the general loop below, without
            // its loop control (this was a tenth of a camera sample).
            let f = &*self.filter;
            let wx = f.gaussian4(x0 as f32 + 0.5 - p.x);
            let wy = f.gaussian4(y0 as f32 + 0.5 - p.y);
            // One bounds check for the block.
            let block = &mut self.samples[first..first + 3 * stride + 4];
            for (ky, wy) in wy.into_iter().enumerate() {
                let row = &mut block[ky * stride..ky * stride + 4];
                for (px, wx) in row.iter_mut().zip(wx) {
                    *px = (Vec4::from_array(*px) + value * (wy * wx)).to_array();
                }
            }
            return;
        }
        let (mut wx, mut wy) = ([0.0f32; 16], [0.0f32; 16]);
        let nx = self.weights(x0, x1, p.x, &mut wx);
        let ny = self.weights(y0, y1, p.y, &mut wy);
        // Rows of the footprint as slices (one bounds check per row); zero
        // weights add nothing, so the inner loop needs no test.
        // One 4-wide multiply-add per pixel: (Σ f·L, Σ f) += f·(L, 1).
        for (ky, &wy) in wy[..ny].iter().enumerate() {
            if wy == 0.0 {
                continue;
            }
            let row = first + ky * stride;
            for (px, &wx) in self.samples[row..row + nx].iter_mut().zip(&wx[..nx]) {
                *px = (Vec4::from_array(*px) + value * (wy * wx)).to_array();
            }
        }
    }

    /// Splats a contribution `l` at raster position `p`.
    pub fn splat(&mut self, p: Vec2, l: Rgb) {
        if !l.is_finite() || !p.is_finite() {
            return;
        }
        let (x0, y0, w) = (self.x0, self.y0, self.w);
        let mut splats = std::mem::take(&mut self.splats);
        self.splat_weights(p, |x, y, wt| {
            let px = &mut splats[((y - y0) * w + (x - x0)) as usize];
            px[0] += wt * l.r;
            px[1] += wt * l.g;
            px[2] += wt * l.b;
        });
        self.splats = splats;
    }

    /// The weights `f(x_j − p)/Z_j` with which a splat at raster position
    /// `p` reaches the pixels of this film: `visit(column, row, weight)`
    /// for each pixel with a nonzero weight (stratified MCMC spreads its
    /// per-tile estimates with them, `crate::smcmc::FilterSplat`).
    pub fn splat_weights(&self, p: Vec2, mut visit: impl FnMut(u32, u32, f32)) {
        let Some((x0, x1, y0, y1)) = self.footprint(p) else {
            return;
        };
        let (mut wx, mut wy) = ([0.0f32; 16], [0.0f32; 16]);
        let nx = self.weights(x0, x1, p.x, &mut wx);
        let ny = self.weights(y0, y1, p.y, &mut wy);
        let norm_x = &self.filter.norm_x[x0 as usize..x0 as usize + nx];
        for (w, &z) in wx.iter_mut().zip(norm_x) {
            *w = if z > 0.0 { *w / z } else { 0.0 };
        }
        for (ky, &wy) in wy.iter().take(ny).enumerate() {
            let z = self.filter.norm_y[(y0 + ky as u32) as usize];
            if wy == 0.0 || z <= 0.0 {
                continue;
            }
            let wy = wy / z;
            for (kx, &wx) in wx.iter().take(nx).enumerate() {
                let w = wy * wx;
                if w == 0.0 {
                    continue;
                }
                visit(x0 + kx as u32, y0 + ky as u32, w);
            }
        }
    }

    /// Adds another film's accumulators into this one (overlap only).
    pub fn add_film(&mut self, other: &Film) {
        for oy in 0..other.h {
            let y = other.y0 + oy;
            if y < self.y0 || y >= self.y0 + self.h {
                continue;
            }
            for ox in 0..other.w {
                let x = other.x0 + ox;
                if x < self.x0 || x >= self.x0 + self.w {
                    continue;
                }
                let i = ((y - self.y0) * self.w + (x - self.x0)) as usize;
                let j = (oy * other.w + ox) as usize;
                if !other.samples.is_empty() {
                    for c in 0..4 {
                        self.samples[i][c] += other.samples[j][c];
                    }
                }
                for c in 0..3 {
                    self.splats[i][c] += other.splats[j][c];
                }
            }
        }
    }

    /// The image: weighted sample mean plus splats divided by
    /// `splat_paths_per_pixel` (pass 0 when nothing splats). Row-major RGB.
    pub fn develop(&self, splat_paths_per_pixel: f64) -> Vec<Rgb> {
        let inv = if splat_paths_per_pixel > 0.0 {
            (1.0 / splat_paths_per_pixel) as f32
        } else {
            0.0
        };
        self.splats
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let mean = match self.samples.get(i) {
                    Some(s) if s[3] > 0.0 => Rgb::new(s[0] / s[3], s[1] / s[3], s[2] / s[3]),
                    _ => Rgb::BLACK,
                };
                mean + Rgb::new(p[0], p[1], p[2]) * inv
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `exp_neg` against libm's `exp` (in f64) over the range the filters
    /// use, every 1e-4: Cephes' `expf` polynomial is accurate to about one
    /// ulp on the reduced range, and the reduction and scaling add a few
    /// roundings at most, so the bound is 4 ulps (4 · 2⁻²³ relative; the
    /// worst case measured here is 8.0e-8, 0.67 ulp). Below −87 the value is
    /// clamped and must stay tiny and non-negative.
    #[test]
    fn exp_neg_matches_libm() {
        let mut worst = 0.0f64;
        for i in 0..=870_000 {
            let x = -(i as f32) * 1e-4;
            let want = (x as f64).exp();
            let got = exp_neg(x) as f64;
            worst = worst.max(((got - want) / want).abs());
        }
        assert!(
            worst < 4.0 * f32::EPSILON as f64,
            "worst relative error {worst:e}"
        );
        assert_eq!(exp_neg(0.0), 1.0);
        let tiny = exp_neg(-1e4);
        assert!((0.0..1e-37).contains(&tiny), "{tiny:e}");
    }

    /// The unrolled 4 × 4 footprint and the general loop agree: a sample
    /// next to the film's edge (footprint clipped, general loop) and the
    /// same sample on a film with a wider margin (4 × 4 path) leave the
    /// same sums on the pixels both films hold; and the Gaussian weights are
    /// those of `Filter::eval_1d`.
    #[test]
    fn unrolled_footprint_matches_the_general_loop() {
        let filter = Arc::new(Filter::new(FilterKind::Gaussian { stddev: 0.5 }, 16, 16));
        let l = Rgb::new(1.5, 0.25, 3.0);
        for &(px, py) in &[(2.3f32, 7.9f32), (2.75, 2.5), (5.01, 3.99)] {
            let p = Vec2::new(px, py);
            let mut clipped = Film::sub(16, 16, 2, 2, 12, 12, filter.clone());
            let mut whole = Film::new(16, 16, filter.clone());
            clipped.add_sample(p, l);
            whole.add_sample(p, l);
            for y in 2..14u32 {
                for x in 2..14u32 {
                    let a = clipped.samples[((y - 2) * 12 + (x - 2)) as usize];
                    let b = whole.samples[(y * 16 + x) as usize];
                    assert_eq!(a, b, "pixel ({x}, {y}) for p = {p}");
                    let w =
                        filter.eval_1d(x as f32 + 0.5 - px) * filter.eval_1d(y as f32 + 0.5 - py);
                    assert!(
                        (b[3] - w).abs() <= 1e-6 * w.max(1e-30),
                        "weight at ({x}, {y}): {} vs {w}",
                        b[3]
                    );
                }
            }
        }
    }

    /// A constant splat density develops to the same constant as camera
    /// samples of that constant, border pixels included (the per-pixel
    /// normalisation `Z_j` at work), for both filters.
    #[test]
    fn splats_and_samples_develop_to_the_same_constant() {
        for kind in [
            FilterKind::Box,
            FilterKind::Gaussian { stddev: 0.5 },
            FilterKind::Tent { radius: 1.0 },
            FilterKind::Tent { radius: 2.7 },
        ] {
            let (w, h) = (7u32, 5u32);
            let filter = Arc::new(Filter::new(kind, w, h));
            let mut samples = Film::new(w, h, filter.clone());
            let mut splats = Film::new_splat_only(w, h, filter);
            // A fine regular grid over the image: n² points per pixel.
            // With n = 62 the cells' edges fall on the discretized
            // filter's steps (every 2/31 pixel from a pixel centre), so
            // the grid sums of that step function are exact integrals.
            let n = 62;
            for y in 0..h * n {
                for x in 0..w * n {
                    let p = Vec2::new((x as f32 + 0.5) / n as f32, (y as f32 + 0.5) / n as f32);
                    samples.add_sample(p, Rgb::splat(2.0));
                    splats.splat(p, Rgb::splat(2.0));
                }
            }
            let a = samples.develop(0.0);
            // n² splatting "paths" per pixel.
            let b = splats.develop((n * n) as f64);
            for (i, (x, y)) in a.iter().zip(&b).enumerate() {
                assert!(
                    (x.r - 2.0).abs() < 1e-4,
                    "{kind:?} sample pixel {i}: {}",
                    x.r
                );
                assert!(
                    (y.r - 2.0).abs() < 2e-3,
                    "{kind:?} splat pixel {i}: {}",
                    y.r
                );
            }
        }
    }
}
