//! Emitters at infinity that rays can hit: Mitsuba 3's `envmap` (a lat-long
//! image) and `constant` (the same radiance from every direction).
//!
//! Directions are **towards the emitter** (from the scene outwards). The
//! image lookup is Mitsuba 3's, measured against it (`scenes/tools/
//! mitsuba_envmap_probe.py`): in the emitter's frame a unit direction `d`
//! has `u = atan2(d.x, −d.z) / 2π` (wrapped into [0, 1)) and
//! `v = acos(d.y) / π`; the radiance is bilinear between texels whose
//! centres are at `u = (i + ½)/W` (wrapping around) and rows at
//! `v = j/(H − 1)` (clamped), so the first and last rows are the poles.
//! (Mitsuba 3 itself departs from this for images two rows high; such maps
//! render differently there.)
//!
//! Sampling: a piecewise-constant density over `W × (H − 1)` cells in
//! `(u, v)`, each cell weighted by the largest channel mean of the texels
//! its bilinear patch reads, times `sin θ` at the cell's centre. That
//! weight is positive wherever the radiance is, so sampling covers the
//! whole support; the solid-angle density is `p(u, v) / (2π² sin θ)`.

use crate::color::Rgb;
use crate::distribution::Distribution2d;
use crate::sampling::to_unit_f32;
use crate::warp;
use glam::{Mat3, Vec3};
use std::f32::consts::PI;

/// A lat-long radiance image with its sampling density.
#[derive(Clone, Debug)]
pub struct LatLong {
    width: usize,
    height: usize,
    /// Radiance (scale applied), row-major, row 0 at the +y pole.
    texels: Vec<Rgb>,
    /// Sampling density over `width × max(height − 1, 1)` cells.
    dist: Distribution2d,
}

/// What the environment radiates.
#[derive(Clone, Debug)]
pub enum EnvRadiance {
    /// The same radiance from every direction (`constant`).
    Constant(Rgb),
    /// A lat-long image (`envmap`).
    Map(Box<LatLong>),
}

/// An emitter at infinity, with its frame.
#[derive(Clone, Debug)]
pub struct Environment {
    /// The radiance.
    pub radiance: EnvRadiance,
    /// World to emitter frame (a rotation, possibly mirrored).
    to_local: Mat3,
    /// Emitter frame to world.
    to_world: Mat3,
}

impl LatLong {
    /// Builds the map from `width × height` linear RGB texels (already
    /// scaled). Errors for an empty image, a non-finite or negative texel
    /// or an all-black image (which Mitsuba renders black; we refuse it so
    /// the light selection has something to sample).
    pub fn new(width: usize, height: usize, texels: Vec<Rgb>) -> Result<LatLong, String> {
        if width == 0 || height == 0 || texels.len() != width * height {
            return Err(format!(
                "the environment map is {width}×{height} with {} texels",
                texels.len()
            ));
        }
        if let Some(t) = texels
            .iter()
            .find(|t| !(t.is_finite() && t.r >= 0.0 && t.g >= 0.0 && t.b >= 0.0))
        {
            return Err(format!(
                "the environment map has a negative or non-finite texel {t:?}"
            ));
        }
        let rows = height.saturating_sub(1).max(1);
        let mean = |x: usize, y: usize| {
            let t = texels[y * width + x];
            (t.r + t.g + t.b) / 3.0
        };
        let mut func = Vec::with_capacity(width * rows);
        for j in 0..rows {
            let (y0, y1) = (j, (j + 1).min(height - 1));
            let sin_theta = (PI * (j as f32 + 0.5) / rows as f32).sin();
            for i in 0..width {
                // Column cell i spans x = u·W − ½ ∈ [i − ½, i + ½): texels i−1, i, i+1.
                let mut m = 0.0f32;
                for dx in [width - 1, 0, 1] {
                    let x = (i + dx) % width;
                    m = m.max(mean(x, y0)).max(mean(x, y1));
                }
                func.push(m * sin_theta);
            }
        }
        let dist = Distribution2d::new(&func, width, rows)
            .ok_or("the environment map is black everywhere")?;
        Ok(LatLong {
            width,
            height,
            texels,
            dist,
        })
    }

    /// Bilinear radiance at `(u, v)` (Mitsuba 3's lookup, see the module docs).
    pub fn lookup(&self, u: f32, v: f32) -> Rgb {
        let (w, h) = (self.width, self.height);
        let x = u * w as f32 - 0.5;
        let xf = x.floor();
        let fx = x - xf;
        let x0 = (xf as i64).rem_euclid(w as i64) as usize;
        let x1 = (x0 + 1) % w;
        let y = (v * (h - 1) as f32).clamp(0.0, (h - 1) as f32);
        let y0 = (y.floor() as usize).min(h - 1);
        let y1 = (y0 + 1).min(h - 1);
        let fy = y - y0 as f32;
        let t = |x: usize, y: usize| self.texels[y * w + x];
        (t(x0, y0) * (1.0 - fx) + t(x1, y0) * fx) * (1.0 - fy)
            + (t(x0, y1) * (1.0 - fx) + t(x1, y1) * fx) * fy
    }

    /// `∫ mean(L) dω` over the sphere, for light selection by power.
    fn mean_radiant_integral(&self) -> f64 {
        let (w, h) = (self.width, self.height);
        let mut sum = 0.0f64;
        for y in 0..h {
            let theta = PI * (y as f32 + 0.5) / h as f32;
            let row: f64 = self.texels[y * w..(y + 1) * w]
                .iter()
                .map(|t| f64::from(t.luminance()))
                .sum();
            sum += row * f64::from(theta.sin());
        }
        sum * (2.0 * std::f64::consts::PI / w as f64) * (std::f64::consts::PI / h as f64)
    }
}

/// `(u, v)` of a unit direction in the emitter's frame. `θ` comes from
/// `atan2(sin θ, cos θ)`, which keeps full precision near the poles where
/// `acos(d.y)` would not.
fn direction_to_uv(d: Vec3) -> (f32, f32) {
    let u = d.x.atan2(-d.z) * (0.5 / PI);
    let u = u - u.floor();
    let v = d.x.hypot(d.z).atan2(d.y) / PI;
    (u, v)
}

/// The unit direction (emitter frame) of `(u, v)`, and `sin θ`.
fn uv_to_direction(u: f32, v: f32) -> (Vec3, f32) {
    let (sin_t, cos_t) = (PI * v).sin_cos();
    let (sin_p, cos_p) = (2.0 * PI * u).sin_cos();
    (Vec3::new(sin_t * sin_p, cos_t, -sin_t * cos_p), sin_t)
}

impl Environment {
    /// An environment with the given radiance and emitter-to-world rotation.
    /// Errors when `to_world` is not a rotation (possibly mirrored): the
    /// densities assume directions keep their solid angle.
    pub fn new(radiance: EnvRadiance, to_world: Mat3) -> Result<Environment, String> {
        if !crate::frame::is_rotation(to_world) {
            return Err(
                "an environment emitter's to_world must be a rotation (no scale or shear)".into(),
            );
        }
        Ok(Environment {
            radiance,
            to_local: to_world.transpose(),
            to_world,
        })
    }

    /// Radiance arriving from the unit world direction `d` (pointing
    /// towards the emitter).
    pub fn eval(&self, d: Vec3) -> Rgb {
        match &self.radiance {
            EnvRadiance::Constant(l) => *l,
            EnvRadiance::Map(map) => {
                let (u, v) = direction_to_uv(self.to_local * d);
                map.lookup(u, v)
            }
        }
    }

    /// Samples a world direction towards the emitter: `(d, radiance, pdf)`
    /// with the solid-angle density; `None` where the density vanishes.
    pub fn sample(&self, u: (f32, f32)) -> Option<(Vec3, Rgb, f32)> {
        match &self.radiance {
            EnvRadiance::Constant(l) => Some((warp::uniform_sphere(u), *l, 1.0 / (4.0 * PI))),
            EnvRadiance::Map(map) => {
                let ((cu, cv), pdf_uv) = map.dist.sample(f64::from(u.0), f64::from(u.1));
                let (cu, cv) = (cu as f32, cv as f32);
                let (local, sin_t) = uv_to_direction(cu, cv);
                let pdf = pdf_uv as f32 / (2.0 * PI * PI * sin_t);
                if !(pdf > 0.0 && pdf.is_finite()) {
                    return None;
                }
                let d = (self.to_world * local).normalize();
                Some((d, self.eval(d), pdf))
            }
        }
    }

    /// Inverse of [`Environment::sample`]: the numbers `u` that sample the
    /// unit world direction `d` (towards the emitter), or `None` where the
    /// density vanishes (a zero-mass cell of the map, or a pole, which the
    /// forward map refuses). `constant`: the uniform-sphere inverse;
    /// `envmap`: the lat-long coordinates of `d` through
    /// [`crate::distribution::Distribution2d::invert`] (one-to-one inside
    /// cells of positive mass).
    pub fn invert(&self, d: Vec3) -> Option<(f32, f32)> {
        match &self.radiance {
            EnvRadiance::Constant(_) => Some(crate::inverse::uniform_sphere_to_square(d)),
            EnvRadiance::Map(map) => {
                let local = self.to_local * d;
                let (u, v) = direction_to_uv(local);
                let (u, v) = (f64::from(u), f64::from(v));
                let sin_t = local.x.hypot(local.z);
                if !(sin_t > 0.0 && map.dist.pdf(u, v) > 0.0) {
                    return None;
                }
                let (a, b) = map.dist.invert(u, v);
                Some((
                    to_unit_f32(a.clamp(0.0, 1.0)),
                    to_unit_f32(b.clamp(0.0, 1.0)),
                ))
            }
        }
    }

    /// Solid-angle density with which [`Environment::sample`] returns `d`.
    pub fn pdf(&self, d: Vec3) -> f32 {
        match &self.radiance {
            EnvRadiance::Constant(_) => 1.0 / (4.0 * PI),
            EnvRadiance::Map(map) => {
                let local = self.to_local * d;
                let (u, v) = direction_to_uv(local);
                // Not √(1 − y²): that loses the precision near the poles.
                let sin_t = local.x.hypot(local.z) / local.length();
                if !(sin_t > 0.0) {
                    return 0.0;
                }
                map.dist.pdf(f64::from(u), f64::from(v)) as f32 / (2.0 * PI * PI * sin_t)
            }
        }
    }

    /// `∫ luminance(L) dω` over the sphere (for selection by power).
    pub fn radiant_integral(&self) -> f64 {
        match &self.radiance {
            EnvRadiance::Constant(l) => 4.0 * std::f64::consts::PI * f64::from(l.luminance()),
            EnvRadiance::Map(map) => map.mean_radiant_integral(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 5 × 4 map with a zero texel and distinct values everywhere else.
    fn map() -> Environment {
        let (w, h) = (5, 4);
        let texels = (0..w * h)
            .map(|i| {
                if i == 7 {
                    Rgb::BLACK
                } else {
                    Rgb::new(1.0 + i as f32, 0.5 + (i % 3) as f32, 2.0)
                }
            })
            .collect();
        let rot = Mat3::from_rotation_y(0.7) * Mat3::from_rotation_x(-0.4);
        Environment::new(
            EnvRadiance::Map(Box::new(LatLong::new(w, h, texels).unwrap())),
            rot,
        )
        .unwrap()
    }

    #[test]
    fn uv_round_trip() {
        for &(u, v) in &[(0.1f32, 0.2f32), (0.5, 0.5), (0.9, 0.95), (0.0, 0.01)] {
            let (d, _) = uv_to_direction(u, v);
            let (u2, v2) = direction_to_uv(d);
            assert!(
                (u - u2).abs() < 1e-5 && (v - v2).abs() < 1e-5,
                "{u} {v} {u2} {v2}"
            );
        }
    }

    #[test]
    fn lookup_hits_texel_centres_and_wraps() {
        let Environment {
            radiance: EnvRadiance::Map(m),
            ..
        } = map()
        else {
            unreachable!()
        };
        // Centre of texel (2, 1): u = 2.5/5, v = 1/3 (up to rounding of v).
        let (got, want) = (m.lookup(0.5, 1.0 / 3.0), m.texels[5 + 2]);
        assert!((got.r - want.r).abs() < 1e-5 && (got.g - want.g).abs() < 1e-5);
        // u = 0 is halfway between the last and the first column.
        let mid = (m.texels[4] + m.texels[0]) * 0.5;
        let got = m.lookup(0.0, 0.0);
        assert!((got.r - mid.r).abs() < 1e-5 && (got.g - mid.g).abs() < 1e-5);
        // Beyond the last row: clamped to it.
        let (a, b) = (m.lookup(0.1, 1.0), m.lookup(0.1, 0.99999994));
        assert!(
            (a.r - b.r).abs() < 1e-4 && (a.g - b.g).abs() < 1e-4,
            "{a:?} {b:?}"
        );
    }

    /// The density integrates to one over the sphere and matches the
    /// sampled directions' reported pdf.
    #[test]
    fn pdf_integrates_to_one_and_matches_samples() {
        let env = map();
        // Midpoint rule over (θ, φ) on a fine grid: dω = sin θ dθ dφ.
        let (nt, np) = (800, 1600);
        let mut total = 0.0f64;
        for i in 0..nt {
            let theta = PI * (i as f32 + 0.5) / nt as f32;
            for j in 0..np {
                let phi = 2.0 * PI * (j as f32 + 0.5) / np as f32;
                let d = Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                );
                total += f64::from(env.pdf(d)) * f64::from(theta.sin());
            }
        }
        total *= (PI as f64 / nt as f64) * (2.0 * PI as f64 / np as f64);
        // The density is piecewise constant in (u, v), so the midpoint rule
        // errs only on the cells cut by grid lines: O(1/nt) ≈ 1e-3.
        assert!((total - 1.0).abs() < 3e-3, "∫ pdf dω = {total}");
        for k in 0..200 {
            let u = (
                (k as f32 * 0.618_034) % 1.0,
                (k as f32 * 0.414_213_5 + 0.1) % 1.0,
            );
            let (d, l, pdf) = env.sample(u).unwrap();
            assert!(
                (env.pdf(d) - pdf).abs() <= 1e-3 * pdf,
                "{} vs {pdf}",
                env.pdf(d)
            );
            assert_eq!(l, env.eval(d));
        }
    }

    #[test]
    fn refuses_bad_maps_and_frames() {
        assert!(LatLong::new(2, 2, vec![Rgb::BLACK; 4]).is_err());
        assert!(LatLong::new(2, 2, vec![Rgb::new(f32::NAN, 1.0, 1.0); 4]).is_err());
        assert!(LatLong::new(2, 2, vec![Rgb::WHITE; 3]).is_err());
        let c = EnvRadiance::Constant(Rgb::WHITE);
        assert!(Environment::new(c, Mat3::from_diagonal(Vec3::new(2.0, 1.0, 1.0))).is_err());
    }
}
